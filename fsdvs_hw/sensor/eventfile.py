"""Event files: HDF5 (v2e's layout), AEDAT4 (iniVation's format) and NumPy ``.npz``; writer and reader.

Conventions (all three formats)
    Timestamps are integer **microseconds** (the simulator's float64 seconds rounded to the
    nearest µs). Pixel ``x`` is the column, ``y`` the row, origin top-left. Polarity: ON (the
    log intensity rose by a threshold) and OFF (fell). In memory (:class:`EventFile`,
    :class:`~fsdvs_hw.sensor.EventList`) polarity is ``+1`` ON / ``-1`` OFF; on disk each format
    keeps its own convention: HDF5 ``1`` ON / ``0`` OFF (as v2e), AEDAT4 ``true`` ON / ``false``
    OFF, npz ``+1`` / ``-1``.

Layouts
    ``.h5`` / ``.hdf5``: dataset ``events``, shape (N, 4), ``uint32``, columns ``[t_us, x, y, p]``,
    gzip-compressed and resizable, exactly v2e's ``--dvs_h5`` output [1]_ (so v2e's readers and
    analysis scripts load it); the sensor size and conventions are added as file attributes
    (``width``, ``height``, ``time_unit``, ``polarity``). uint32 µs limits a file to 4294 s.
    ``.aedat4``: an event stream written and read by iniVation's maintained dv-processing
    library [2]_ (optional dependency: ``pip install fsdvs_hw[eventfiles]``).
    ``.npz``: arrays ``t`` (int64 µs), ``x``, ``y`` (uint16), ``p`` (int8 ±1), ``width``,
    ``height`` (written column by column through temporary files, so memory stays bounded).

Writers take the events chunk by chunk (:meth:`EventFileWriter.write`), so a streamed simulation
(:func:`fsdvs_hw.sensor.simulate`) goes to disk without holding the clip's events.

References
----------
.. [1] Y. Hu, S.-C. Liu, T. Delbruck, v2e (github.com/SensorsINI/v2e), ``v2ecore/emulator.py``:
   HDF5 ``events`` dataset (N, 4) uint32 ``[t_us, x, y, p∈{0,1}]``.
.. [2] iniVation, AEDAT 4.0 file format and dv-processing (dv-processing.inivation.com).
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, ToolMissingError

__all__ = ["FORMATS", "EventFile", "EventFileWriter", "write_events", "read_events", "event_format"]

#: file suffix -> format name
FORMATS: dict[str, str] = {".h5": "hdf5", ".hdf5": "hdf5", ".aedat4": "aedat4", ".npz": "npz"}
_UINT32_MAX = 2 ** 32 - 1


def event_format(path: str | Path) -> str:
    """The format of an event file from its suffix (``hdf5``, ``aedat4`` or ``npz``)."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise InputError(f"event file {str(path)!r}: suffix {suffix or '(none)'!r} unknown; "
                         f"allowed: {', '.join(FORMATS)}")
    return FORMATS[suffix]


def _dv() -> Any:
    try:
        import dv_processing
    except ImportError:
        raise ToolMissingError("AEDAT4 needs dv-processing: pip install 'fsdvs_hw[eventfiles]' "
                               "(or pip install dv-processing)") from None
    return dv_processing


@dataclass
class EventFile:
    """Events read from a file (one sensor).

    Attributes
    ----------
    t_us : numpy.ndarray int64 — time in microseconds; x, y : int64 — column, row;
    p : int8 — polarity +1 ON / -1 OFF; width, height : int — sensor size (pixels);
    metadata : dict — format-specific attributes.
    """

    t_us: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    width: int
    height: int
    metadata: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t_us.size)

    def to_event_list(self) -> Any:
        """As a :class:`~fsdvs_hw.sensor.EventList` (batch 0, time in seconds)."""
        import torch

        from .events import EventList

        n = len(self)
        return EventList(torch.zeros(n, dtype=torch.int64), torch.from_numpy(self.x.astype(np.int64)),
                         torch.from_numpy(self.y.astype(np.int64)),
                         torch.from_numpy(self.t_us.astype(np.float64) * 1e-6),
                         torch.from_numpy(self.p.astype(np.int8)))


def _columns(events: Any, width: int, height: int) -> tuple[np.ndarray, ...]:
    """(t_us int64, x int64, y int64, p int8 ±1) of an EventList or EventFile, checked."""
    if isinstance(events, EventFile):
        t_us, x, y, p = events.t_us.astype(np.int64, copy=False), events.x, events.y, events.p
    else:
        b = np.asarray(events.b)
        if b.size and int(b.max()) > 0:
            raise InputError("events: an event file holds one sensor; select one batch element "
                             "(EventList.select(b)) per file")
        t = np.asarray(events.t, dtype=np.float64)
        t_us = np.rint(t * 1e6).astype(np.int64)
        x, y, p = np.asarray(events.x), np.asarray(events.y), np.asarray(events.p)
    # no copies of columns that already have the dtype (a stream's chunks do): memory per event
    x, y, p = x.astype(np.int64, copy=False), y.astype(np.int64, copy=False), p.astype(np.int8, copy=False)
    if t_us.size:
        if int(t_us.min()) < 0:
            raise InputError(f"events: negative time {int(t_us.min())} µs; event files need t >= 0")
        if int(x.min()) < 0 or int(x.max()) >= width or int(y.min()) < 0 or int(y.max()) >= height:
            raise InputError(f"events: pixel outside the {width}x{height} sensor")
        if not bool(np.isin(p, (-1, 1)).all()):
            raise InputError("events: polarity must be +1 (ON) or -1 (OFF)")
    return t_us, x, y, p


#: Events converted and written per slice by :meth:`EventFileWriter.write` (bounds its memory).
WRITE_SLICE = 1 << 18


def _slice_events(events: Any, start: int, end: int) -> Any:
    """Events ``start:end`` of an EventList or EventFile (views, no copies)."""
    if isinstance(events, EventFile):
        return EventFile(events.t_us[start:end], events.x[start:end], events.y[start:end], events.p[start:end],
                         events.width, events.height, events.metadata)
    return type(events)(events.b[start:end], events.x[start:end], events.y[start:end], events.t[start:end],
                        events.p[start:end])


class EventFileWriter:
    """Write events to ``path`` chunk by chunk; the format follows the suffix (see module doc).

    Use as a context manager: ``with EventFileWriter(path, width, height) as w: w.write(events)``.
    Events must arrive in non-decreasing time (as a stream's chunks do).
    """

    def __init__(self, path: str | Path, width: int, height: int, *, metadata: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.format = event_format(self.path)
        for name, v in (("width", width), ("height", height)):
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or not 1 <= int(v) <= 32767:
                raise InputError(f"{name}: must be an integer in [1, 32767] pixels, got {v!r}")
        self.width, self.height = int(width), int(height)
        self.metadata = dict(metadata or {})
        self.count = 0
        self._last_t = -1
        self._closed = False
        if self.format == "hdf5":
            import h5py

            self._h5 = h5py.File(self.path, "w")
            self._ds = self._h5.create_dataset("events", shape=(0, 4), maxshape=(None, 4), dtype="uint32",
                                               chunks=(65536, 4), compression="gzip")
            attrs = {"width": self.width, "height": self.height, "time_unit": "us",
                     "polarity": "1 = ON, 0 = OFF (v2e)", "columns": "t_us, x, y, p", **self.metadata}
            for k, v in attrs.items():
                self._h5.attrs[k] = v
        elif self.format == "aedat4":
            dv = _dv()
            cfg = dv.io.MonoCameraWriter.EventOnlyConfig("fsdvs_hw", (self.width, self.height))
            self._dvw = dv.io.MonoCameraWriter(str(self.path), cfg)
            self._dv = dv
        else:
            self._tmp = Path(tempfile.mkdtemp(prefix="fsdvs_npz_", dir=self.path.parent if self.path.parent.exists() else None))
            self._cols = {k: open(self._tmp / k, "wb") for k in ("t", "x", "y", "p")}  # noqa: SIM115

    def write(self, events: Any) -> None:
        """Append an :class:`~fsdvs_hw.sensor.EventList` (batch 0) or :class:`EventFile`.

        Written in slices of :data:`WRITE_SLICE` events, so the conversion's temporaries (µs times,
        the file's row layout: ~50 B per event) are bounded whatever the size of ``events``.
        """
        if self._closed:
            raise InputError(f"event file {str(self.path)!r}: already closed")
        n = len(events)
        for start in range(0, n, WRITE_SLICE):
            self._write_slice(_slice_events(events, start, min(start + WRITE_SLICE, n)))

    def _write_slice(self, events: Any) -> None:
        t_us, x, y, p = _columns(events, self.width, self.height)
        if not t_us.size:
            return
        if int(t_us[0]) < self._last_t or bool((np.diff(t_us) < 0).any()):
            raise InputError("events: must be written in non-decreasing time")
        self._last_t = int(t_us[-1])
        n = t_us.size
        if self.format == "hdf5":
            if int(t_us[-1]) > _UINT32_MAX:
                raise InputError(f"events: time {int(t_us[-1])} µs exceeds the uint32 µs range of v2e's HDF5 "
                                 "layout (4294 s); use .aedat4 or .npz")
            block = np.empty((n, 4), dtype=np.uint32)  # filled column by column: no int64 copy
            block[:, 0], block[:, 1], block[:, 2], block[:, 3] = t_us, x, y, p > 0
            self._ds.resize(self.count + n, axis=0)
            self._ds[self.count:] = block
        elif self.format == "aedat4":
            on = p > 0
            for i in range(0, n, 1 << 16):  # slices: bounded Python lists (dv-processing has no bulk numpy input)
                store = self._dv.EventStore()
                push = store.push_back
                sl = slice(i, i + (1 << 16))
                for a, b, c, d in zip(t_us[sl].tolist(), x[sl].tolist(), y[sl].tolist(), on[sl].tolist()):
                    push(a, b, c, d)
                self._dvw.writeEvents(store)
        else:
            for k, arr in (("t", t_us), ("x", x.astype(np.uint16)), ("y", y.astype(np.uint16)), ("p", p)):
                self._cols[k].write(np.ascontiguousarray(arr).tobytes())
        self.count += n

    def close(self) -> None:
        """Finish the file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self.format == "hdf5":
            self._h5.close()
        elif self.format == "aedat4":
            del self._dvw  # the writer flushes and closes on destruction
        else:
            dtypes = {"t": np.int64, "x": np.uint16, "y": np.uint16, "p": np.int8}
            try:
                for f in self._cols.values():
                    f.close()
                with zipfile.ZipFile(self.path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as z:
                    for k, dt in dtypes.items():
                        with z.open(f"{k}.npy", "w", force_zip64=True) as out:
                            np.lib.format.write_array_header_1_0(
                                out, {"descr": np.lib.format.dtype_to_descr(np.dtype(dt)),
                                      "fortran_order": False, "shape": (self.count,)})
                            with open(self._tmp / k, "rb") as src:
                                while block := src.read(1 << 22):
                                    out.write(block)
                    for k, v in (("width", self.width), ("height", self.height)):
                        with z.open(f"{k}.npy", "w") as out:
                            np.lib.format.write_array(out, np.asarray(v, dtype=np.int64))
            finally:
                for k in self._cols:
                    (self._tmp / k).unlink(missing_ok=True)
                os.rmdir(self._tmp)

    def __enter__(self) -> EventFileWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def write_events(path: str | Path, events: Any, width: int, height: int, *,
                 metadata: dict[str, Any] | None = None) -> int:
    """Write one :class:`~fsdvs_hw.sensor.EventList` (batch 0) to ``path``; returns the count."""
    with EventFileWriter(path, width, height, metadata=metadata) as w:
        w.write(events)
        return w.count


def read_events(path: str | Path) -> EventFile:
    """Read an event file written by :class:`EventFileWriter` (or by v2e / DV for HDF5 / AEDAT4).

    Raises
    ------
    InputError
        Missing file, unknown suffix, or a file without the expected datasets/streams.
    """
    p = Path(path)
    fmt = event_format(p)
    if not p.is_file():
        raise InputError(f"event file {str(p)!r} does not exist")
    if fmt == "hdf5":
        import h5py

        with h5py.File(p, "r") as f:
            if "events" not in f or f["events"].ndim != 2 or f["events"].shape[1] != 4:
                raise InputError(f"event file {str(p)!r}: no (N, 4) 'events' dataset (v2e layout)")
            a = f["events"][()]
            attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in f.attrs.items()}
        x, y = a[:, 1].astype(np.int64), a[:, 2].astype(np.int64)
        w = int(attrs.get("width", int(x.max()) + 1 if x.size else 1))
        h = int(attrs.get("height", int(y.max()) + 1 if y.size else 1))
        return EventFile(a[:, 0].astype(np.int64), x, y, np.where(a[:, 3] > 0, 1, -1).astype(np.int8), w, h, attrs)
    if fmt == "aedat4":
        dv = _dv()
        try:
            rec = dv.io.MonoCameraRecording(str(p))
        except RuntimeError as exc:
            raise InputError(f"event file {str(p)!r}: not a readable AEDAT4 file ({exc})") from None
        if not rec.isEventStreamAvailable():
            raise InputError(f"event file {str(p)!r}: has no event stream")
        parts = []
        while rec.isRunning():
            batch = rec.getNextEventBatch()
            if batch is None:
                break
            parts.append(batch.numpy())
        a = np.concatenate(parts) if parts else np.zeros(0, dtype=[("timestamp", "<i8"), ("x", "<i2"),
                                                                      ("y", "<i2"), ("polarity", "i1")])
        w, h = rec.getEventResolution()
        return EventFile(a["timestamp"].astype(np.int64), a["x"].astype(np.int64), a["y"].astype(np.int64),
                         np.where(a["polarity"] > 0, 1, -1).astype(np.int8), int(w), int(h),
                         {"camera": rec.getCameraName()})
    with np.load(p) as z:
        missing = {"t", "x", "y", "p", "width", "height"} - set(z.files)
        if missing:
            raise InputError(f"event file {str(p)!r}: missing arrays {sorted(missing)}")
        return EventFile(z["t"].astype(np.int64), z["x"].astype(np.int64), z["y"].astype(np.int64),
                         z["p"].astype(np.int8), int(z["width"]), int(z["height"]))
