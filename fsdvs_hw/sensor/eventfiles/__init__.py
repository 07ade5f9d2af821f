"""Event files: the toolkit's HDF5, AEDAT4 and npz files (writer and reader, the writer's child
process), Prophesee RAW/DAT and DSEC recordings, and one reader for any camera's recording.

Of its public names :mod:`fsdvs_hw.sensor` exports :func:`~.recordings.read_recording`; the others are
imported from their modules (e.g. :mod:`.eventfile`). This package imports nothing itself.
"""

__all__: list[str] = []
