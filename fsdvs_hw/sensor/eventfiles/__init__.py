"""Event files: the toolkit's HDF5, AEDAT4 and npz files (writer and reader, the writer's child
process), Prophesee RAW/DAT and DSEC recordings, and one reader for any camera's recording.

The public names are exported by :mod:`fsdvs_hw.sensor`; this package imports nothing itself.
"""

__all__: list[str] = []
