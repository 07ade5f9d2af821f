"""DSEC's ``events.h5`` layout: read (validated) and written, through h5py and hdf5plugin.

The DSEC driving data set [1]_ stores each event camera's stream as

``events/x``, ``events/y`` (uint16), ``events/t`` (uint32, µs after ``t_offset``), ``events/p`` (uint8, 1 ON / 0 OFF)
    one entry per event, Blosc-compressed (zstd) through the HDF5 filter plugins, which
    ``hdf5plugin`` [2]_ registers with h5py;
``ms_to_idx`` (uint64)
    ``ms_to_idx[m]`` = index of the first event with ``t >= 1000 m`` µs (a millisecond index);
``t_offset`` (int64 scalar)
    µs added to every ``t`` (the recording's start on the data set's clock).

The sensor size is not stored (DSEC's cameras are Prophesee Gen3.1, 640 x 480): the reader takes
``width``/``height`` attributes where a file has them (this writer adds them), else the
arguments, else 640 x 480. :func:`read_dsec` checks the four columns' presence, dtypes and
lengths, times non-decreasing, pixels inside the sensor and ``ms_to_idx`` against the times, and
raises :class:`~fsdvs_hw.errors.InputError` naming the file and the dataset for a foreign,
truncated or inconsistent file.

References
----------
.. [1] M. Gehrig, W. Aarents, D. Gehrig, D. Scaramuzza, "DSEC: A Stereo Event Camera Dataset for
   Driving Scenarios", IEEE RA-L 6(3), 2021; file layout on dsec.ifi.uzh.ch (data format page).
.. [2] hdf5plugin (github.com/silx-kit/hdf5plugin): HDF5 compression filters (Blosc) for h5py.

Examples
--------
>>> import numpy as np, tempfile, os
>>> from fsdvs_hw.sensor.eventfiles.eventfile import EventFile
>>> ev = EventFile(np.array([0, 1500, 2500]), np.array([1, 2, 3]), np.array([4, 5, 6]),
...                np.array([1, -1, 1], dtype=np.int8), 640, 480)
>>> path = os.path.join(tempfile.mkdtemp(), "events.h5")
>>> _ = write_dsec(path, ev)
>>> back = read_dsec(path)
>>> back.t_us.tolist(), back.p.tolist(), back.metadata["ms_to_idx"].tolist()
([0, 1500, 2500], [1, -1, 1], [0, 1, 2])
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError, ToolMissingError
from ...limits import check_allocation
from .eventfile import (
    EVENT_BYTES,
    EventColumnsCheck,
    EventFile,
    checked_columns,
    checked_file,
    checked_side,
    exception_line,
    field_error,
    partial_path,
)

__all__ = ["DSEC_SIZE", "MAX_T_OFFSET_US", "MS_TO_IDX_SLACK", "is_dsec", "read_dsec", "write_dsec"]

#: DSEC's event cameras (Prophesee Gen3.1): width, height in pixels.
DSEC_SIZE = (640, 480)
_COLUMNS = ("x", "y", "t", "p")


def _plugins() -> Any:
    try:
        import hdf5plugin
    except ImportError:
        raise ToolMissingError(
            "DSEC events.h5 files are Blosc-compressed: pip install 'fsdvs_hw[eventfiles]' (or pip install hdf5plugin)"
        ) from None
    return hdf5plugin


def is_dsec(path: str | Path) -> bool:
    """True if ``path`` is an HDF5 file with an ``events`` group (DSEC layout), not v2e's dataset."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return isinstance(f.get("events"), h5py.Group)
    except (OSError, ValueError):
        return False


def ms_to_idx(t_us: np.ndarray) -> np.ndarray:
    """DSEC's millisecond index of non-decreasing times: first event at or after each ms."""
    n_ms = int(t_us[-1]) // 1000 + 1 if t_us.size else 0
    return np.searchsorted(t_us, np.arange(n_ms, dtype=np.int64) * 1000, side="left").astype(np.uint64)


def write_dsec(
    path: str | Path, events: Any, *, width: int | None = None, height: int | None = None, t_offset_us: int = 0
) -> Path:
    """Write events in DSEC's ``events.h5`` layout (Blosc zstd), atomically.

    Parameters
    ----------
    path : str or Path
        ``.h5`` file.
    events : EventFile or EventList
        One sensor's events in non-decreasing time, times in [0, 2**32) µs after ``t_offset_us``.
    width, height : int, optional
        Sensor size (stored as attributes); default the EventFile's or DSEC's 640 x 480.
    t_offset_us : int
        ``t_offset`` (µs) stored with the file.

    Returns
    -------
    Path
        ``path``.
    """
    import h5py

    hp = _plugins()
    p = Path(path)
    w = int(width if width is not None else getattr(events, "width", DSEC_SIZE[0]))
    h = int(height if height is not None else getattr(events, "height", DSEC_SIZE[1]))
    t, x, y, pol = checked_columns(events, w, h)
    if t.size and (bool((np.diff(t) < 0).any()) or int(t[-1]) > 2**32 - 1):
        raise InputError("write_dsec: times must be non-decreasing and below 2**32 µs (DSEC stores uint32)")
    tmp = partial_path(p)
    try:
        with h5py.File(tmp, "w") as f:
            comp = hp.Blosc(cname="zstd", clevel=5, shuffle=hp.Blosc.SHUFFLE)
            g = f.create_group("events")
            for name, arr, dt in (
                ("x", x, "<u2"),
                ("y", y, "<u2"),
                ("t", t, "<u4"),
                ("p", (pol > 0).astype(np.uint8), "u1"),
            ):
                g.create_dataset(
                    name, data=arr.astype(dt), chunks=True if arr.size else None, **(comp if arr.size else {})
                )
            f.create_dataset("ms_to_idx", data=ms_to_idx(t))
            f.create_dataset("t_offset", data=np.int64(t_offset_us))
            f.attrs["width"], f.attrs["height"] = w, h
        os.replace(tmp, p)
    finally:
        if tmp.exists():
            tmp.unlink()
    return p


def read_dsec(path: str | Path, *, width: int | None = None, height: int | None = None) -> EventFile:
    """Read a DSEC-layout ``events.h5`` into an :class:`EventFile` (times ``t + t_offset`` µs).

    Parameters
    ----------
    path : str or Path
        The HDF5 file.
    width, height : int, optional
        Sensor size where the file has no ``width``/``height`` attributes (default 640 x 480).

    Returns
    -------
    EventFile
        ``metadata``: ``format`` ("dsec"), ``t_offset`` (µs) and ``ms_to_idx``.

    Raises
    ------
    InputError
        Not HDF5, truncated, no ``events/{x,y,t,p}``, ragged or non-integer columns, times that
        decrease, pixels outside the sensor, or a ``ms_to_idx`` that disagrees with the times.
    """
    import h5py

    _plugins()
    p = checked_file(path)
    try:
        f = h5py.File(p, "r")
    except (OSError, ValueError) as exc:
        raise field_error(
            p, "(file)", f"not a readable HDF5 file, expected DSEC's events.h5 ({exception_line(exc)})"
        ) from None
    with f:
        try:
            return _read_open(p, f, width, height)
        except InputError:
            raise
        except (OSError, ValueError, KeyError, TypeError, RuntimeError, IndexError) as exc:
            raise field_error(p, "events", f"unreadable, truncated or corrupt ({exception_line(exc)})") from None


#: Entries of ``ms_to_idx`` accepted beyond the last event's millisecond (a declared size is
#: checked against the events before anything is allocated).
MS_TO_IDX_SLACK = 100_000
#: Largest ``t_offset`` accepted (µs): 2**53 (285 years), exact in float64 and far from int64's end.
MAX_T_OFFSET_US = 1 << 53


def _check_stored(p: Path, name: str, ds: Any) -> None:
    """Refuse a chunked dataset that declares more chunks than it stores (a huge declared size
    in a small file would be filled with zeros at read time)."""
    import math

    if ds.chunks is None or ds.size == 0:
        return
    want = math.prod(math.ceil(n / c) for n, c in zip(ds.shape, ds.chunks))
    got = ds.id.get_num_chunks()
    if got < want:
        raise field_error(
            p, name, f"declares {ds.shape[0]} entries but stores only {got} of its {want} chunks (truncated file?)"
        )


def _t_offset(p: Path, f: Any, t_last: int) -> int:
    """``t_offset`` (µs; 0 without it): one integer in [0, 2**53) with ``t_offset + t`` in range."""
    if "t_offset" not in f:
        return 0
    off_arr = np.asarray(f["t_offset"][()])
    if off_arr.shape not in ((), (1,)) or off_arr.dtype.kind not in "iu":
        raise field_error(p, "t_offset", f"must be one integer (µs), got dtype {off_arr.dtype} shape {off_arr.shape}")
    off = int(off_arr.reshape(-1)[0])
    if not 0 <= off < MAX_T_OFFSET_US - t_last:
        raise field_error(p, "t_offset", f"{off} µs outside [0, 2**53) µs (times would wrap or lose precision)")
    return off


def _read_open(p: Path, f: Any, width: int | None, height: int | None) -> EventFile:
    import h5py

    g = f.get("events")
    if not isinstance(g, h5py.Group):
        raise field_error(p, "events", "no 'events' group: not DSEC's layout (events/x, events/y, events/t, events/p)")
    missing = [c for c in _COLUMNS if not isinstance(g.get(c), h5py.Dataset)]
    if missing:
        raise field_error(
            p, ", ".join(f"events/{c}" for c in missing), "missing datasets (DSEC layout: events/x, y, t, p)"
        )
    names = {c: f"events/{c}" for c in _COLUMNS}
    chk = EventColumnsCheck(p, names, (0, 1))
    chk.dtypes(**{c: g[c].dtype for c in _COLUMNS})
    lengths = {c: g[c].shape for c in _COLUMNS}
    if len(set(lengths.values())) != 1 or len(lengths["t"]) != 1:
        raise field_error(p, "events/x, y, t, p", f"shapes {lengths}; expected four columns of one length")
    n = lengths["t"][0]
    check_allocation(f"event file {str(p)!r}: events ({n} declared events)", n * EVENT_BYTES)
    w = checked_side(p, "attribute width", f.attrs["width"]) if "width" in f.attrs else (width or DSEC_SIZE[0])
    h = checked_side(p, "attribute height", f.attrs["height"]) if "height" in f.attrs else (height or DSEC_SIZE[1])
    for c in _COLUMNS:
        _check_stored(p, f"events/{c}", g[c])
    cols = {c: g[c][()] for c in _COLUMNS}
    chk.check(cols["t"], cols["x"], cols["y"], cols["p"], w, h)
    t = cols["t"].astype(np.int64)
    off = _t_offset(p, f, int(t[-1]) if t.size else 0)
    meta: dict[str, Any] = {"format": "dsec", "t_offset": off}
    if "ms_to_idx" in f:
        want = ms_to_idx(t)
        ds = f["ms_to_idx"]
        if not isinstance(ds, h5py.Dataset) or ds.ndim != 1 or ds.shape[0] > want.size + MS_TO_IDX_SLACK:
            raise field_error(
                p,
                "ms_to_idx",
                f"declares shape {getattr(ds, 'shape', None)}; the events span {want.size} ms "
                f"(at most {MS_TO_IDX_SLACK} more entries accepted)",
            )
        _check_stored(p, "ms_to_idx", ds)
        idx = np.asarray(ds[()])
        if idx.ndim != 1 or idx.size < want.size or not np.array_equal(idx[: want.size].astype(np.int64), want):
            k = (
                int(np.flatnonzero(idx[: want.size].astype(np.int64) != want[: idx.size])[0])
                if idx.ndim == 1
                and min(idx.size, want.size)
                and not np.array_equal(idx[: want.size].astype(np.int64), want[: idx.size])
                else min(idx.size, want.size)
            )
            raise field_error(
                p, "ms_to_idx", f"disagrees with events/t at millisecond {k} (truncated or inconsistent file)"
            )
        meta["ms_to_idx"] = idx
    return EventFile(
        t + off,
        cols["x"].astype(np.int64),
        cols["y"].astype(np.int64),
        np.where(cols["p"] > 0, 1, -1).astype(np.int8),
        w,
        h,
        meta,
    )
