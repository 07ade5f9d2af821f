"""Read a real camera's recording, whatever its format, into the toolkit's events.

:func:`read_recording` picks the reader from the suffix and, for HDF5, from the layout:

========================  =====================================================  ==========================
suffix                    format                                                 reader
========================  =====================================================  ==========================
``.raw``                  Prophesee RAW, EVT 2.0 or 3.0 (from the header)        :func:`~.prophesee.read_prophesee`
``.dat``                  Prophesee DAT (CD events)                              :func:`~.prophesee.read_prophesee`
``.h5`` / ``.hdf5``       DSEC ``events/{x,y,t,p}`` group, else v2e's dataset    :func:`~.dsec.read_dsec` / :func:`~.eventfile.read_events`
``.aedat4``               iniVation AEDAT 4 (dv-processing)                      :func:`~.eventfile.read_events`
``.npz``                  this toolkit's NumPy archive                           :func:`~.eventfile.read_events`
========================  =====================================================  ==========================

Every reader validates what it reads and raises :class:`~fsdvs_hw.errors.InputError` naming the
file, the field or byte offset and the format it expected.

Examples
--------
>>> import numpy as np, tempfile, os
>>> from fsdvs_hw.sensor.eventfiles.eventfile import EventFile
>>> from fsdvs_hw.sensor.eventfiles.dsec import write_dsec
>>> ev = EventFile(np.array([10, 20]), np.array([1, 2]), np.array([3, 4]), np.array([1, -1], dtype=np.int8), 64, 48)
>>> path = os.path.join(tempfile.mkdtemp(), "events.h5")
>>> _ = write_dsec(path, ev)
>>> rec = read_recording(path)
>>> rec.metadata["format"], len(rec), len(read_recording_events(path))
('dsec', 2, 2)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...errors import InputError
from .eventfile import FORMATS, EventFile, checked_file, read_events

__all__ = ["RECORDING_SUFFIXES", "read_recording", "read_recording_events"]

#: every suffix :func:`read_recording` accepts
RECORDING_SUFFIXES = (".raw", ".dat", *FORMATS)


def read_recording(path: str | Path, *, width: int | None = None, height: int | None = None) -> EventFile:
    """Read a recording (Prophesee RAW/DAT, DSEC h5, v2e h5, AEDAT4, npz) into an :class:`EventFile`.

    Parameters
    ----------
    path : str or Path
        The file; its suffix and (for HDF5) its layout choose the reader.
    width, height : int, optional
        Sensor size (pixels) for formats that may not store it (Prophesee files without geometry,
        DSEC); ignored by formats that store it.

    Returns
    -------
    EventFile
        Times in µs, polarity ±1, sensor size; ``.to_event_list()`` gives the simulator's
        :class:`~fsdvs_hw.sensor.EventList`.

    Raises
    ------
    InputError
        Unknown suffix, missing, foreign or truncated file (the reader's message).
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in RECORDING_SUFFIXES:
        raise InputError(
            f"recording {str(p)!r}: suffix {suffix or '(none)'!r} unknown; allowed: {', '.join(RECORDING_SUFFIXES)}"
        )
    checked_file(p, "recording")
    if suffix in (".raw", ".dat"):
        from .prophesee import read_prophesee

        return read_prophesee(p, width=width, height=height)
    if suffix in (".h5", ".hdf5"):
        from .dsec import is_dsec, read_dsec

        if is_dsec(p):
            return read_dsec(p, width=width, height=height)
    ev = read_events(p)
    ev.metadata.setdefault("format", FORMATS[suffix])
    return ev


def read_recording_events(path: str | Path, **kwargs: Any) -> Any:
    """:func:`read_recording` as the simulator's :class:`~fsdvs_hw.sensor.EventList` (seconds)."""
    return read_recording(path, **kwargs).to_event_list()
