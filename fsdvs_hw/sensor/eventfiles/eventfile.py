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
    resizable, chunked 65 536 rows, v2e's ``--dvs_h5`` layout [1]_ (so v2e's readers and analysis
    scripts load it), compressed with HDF5's shuffle + gzip level 1 (v2e: gzip 4; any HDF5 reader
    undoes either; the writer deflates with ISA-L, whose zlib streams every reader's zlib
    decodes); the sensor size and conventions are added as file attributes
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

import contextlib
import errno
import os
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError, ToolMissingError
from ...limits import check_allocation

__all__ = [
    "FORMATS",
    "TRIGGER_DTYPE",
    "EventFile",
    "EventFileWriter",
    "checked_file",
    "event_format",
    "no_triggers",
    "read_events",
    "write_events",
]

#: file suffix -> format name
FORMATS: dict[str, str] = {".h5": "hdf5", ".hdf5": "hdf5", ".aedat4": "aedat4", ".npz": "npz"}
_UINT32_MAX = 2**32 - 1


def event_format(path: str | Path) -> str:
    """The format of an event file from its suffix (``hdf5``, ``aedat4`` or ``npz``)."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise InputError(
            f"event file {str(path)!r}: suffix {suffix or '(none)'!r} unknown; allowed: {', '.join(FORMATS)}"
        )
    return FORMATS[suffix]


def _dv() -> Any:
    try:
        import dv_processing
    except ImportError:
        raise ToolMissingError(
            "AEDAT4 needs dv-processing: pip install 'fsdvs_hw[eventfiles]' (or pip install dv-processing)"
        ) from None
    return dv_processing


#: External trigger events (Prophesee ``EXT_TRIGGER``): time (µs), trigger channel, edge (1 rising, 0 falling).
TRIGGER_DTYPE = np.dtype([("t_us", "<i8"), ("id", "<i2"), ("value", "i1")])


def no_triggers() -> np.ndarray:
    """An empty array of :data:`TRIGGER_DTYPE` (a file without trigger events)."""
    return np.zeros(0, dtype=TRIGGER_DTYPE)


def checked_file(path: str | Path, what: str = "event file") -> Path:
    """``path`` as a :class:`Path` if it is a readable regular file; else an
    :class:`~fsdvs_hw.errors.InputError` that says what it is: missing, a directory, a loop of
    symbolic links, a dangling link, another kind of file, or not readable.

    Examples
    --------
    >>> checked_file(".")
    Traceback (most recent call last):
    ...
    fsdvs_hw.errors.InputError: event file '.': is a directory, not a file
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InputError(f"{what} {str(p)!r}: a loop of symbolic links (it resolves to itself)") from None
        if exc.errno == errno.ENOENT and os.path.islink(p):
            raise InputError(
                f"{what} {str(p)!r}: a symbolic link to {os.readlink(p)!r}, which does not exist"
            ) from None
        if exc.errno == errno.ENOENT:
            raise InputError(f"{what} {str(p)!r} does not exist") from None
        raise InputError(f"{what} {str(p)!r}: cannot be read ({os.strerror(exc.errno or errno.EIO)})") from None
    import stat

    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{what} {str(p)!r}: is a directory, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{what} {str(p)!r}: is not a regular file (a device, pipe or socket)")
    if not os.access(p, os.R_OK):
        raise InputError(f"{what} {str(p)!r}: cannot be read (permission denied)")
    return p


@dataclass
class EventFile:
    """Events read from a file (one sensor).

    Attributes
    ----------
    t_us : numpy.ndarray
        int64, time in microseconds.
    x, y : numpy.ndarray
        int64, column and row (pixels).
    p : numpy.ndarray
        int8, polarity +1 ON / -1 OFF.
    width, height : int
        Sensor size (pixels).
    metadata : dict
        Format-specific attributes.
    triggers : numpy.ndarray
        External trigger events beside the CD events (:data:`TRIGGER_DTYPE`: ``t_us``, ``id``,
        ``value``); empty for formats and files without them.
    """

    t_us: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    width: int
    height: int
    metadata: dict[str, Any] = field(default_factory=dict)
    triggers: np.ndarray = field(default_factory=no_triggers)

    def __len__(self) -> int:
        return int(self.t_us.size)

    def to_event_list(self) -> Any:
        """As a :class:`~fsdvs_hw.sensor.EventList` (batch 0, time in seconds)."""
        import torch

        from ..simulation.events import EventList

        n = len(self)
        return EventList(
            torch.zeros(n, dtype=torch.int64),
            torch.from_numpy(self.x.astype(np.int64)),
            torch.from_numpy(self.y.astype(np.int64)),
            torch.from_numpy(self.t_us.astype(np.float64) * 1e-6),
            torch.from_numpy(self.p.astype(np.int8)),
        )


def checked_columns(events: Any, width: int, height: int) -> tuple[np.ndarray, ...]:
    """(t_us int64, x int64, y int64, p int8 ±1) of an EventList or EventFile, checked."""
    if isinstance(events, EventFile):
        t_us, x, y, p = events.t_us.astype(np.int64, copy=False), events.x, events.y, events.p
    else:
        b = np.asarray(events.b)
        if b.size and int(b.max()) > 0:
            raise InputError(
                "events: an event file holds one sensor; select one batch element (EventList.select(b)) per file"
            )
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
        if not bool((np.abs(p) == 1).all()):  # one pass (np.isin: ~30x the time); abs(-128) stays -128
            raise InputError("events: polarity must be +1 (ON) or -1 (OFF)")
    return t_us, x, y, p


#: Latest event time (µs) of the formats without v2e's uint32 limit (int64 µs).
_MAX_T_US = 2**63 - 1


def _message_columns(
    events: Any, width: int, height: int, last_t_us: int, max_t_us: int
) -> tuple[np.ndarray, ...] | None:
    """The writer process's message columns (t_us int64, x int16, y int16, ON uint8) of an
    :class:`~fsdvs_hw.sensor.EventList` with the columns a stream yields (contiguous CPU float64
    ``t``, int64 ``x``, ``y``, int8 ``p``, batch 0), converted and checked in one compiled pass
    (:func:`~fsdvs_hw.sensor.native.library.event_message`: the same values as :func:`checked_columns`, 3.4–4.0
    against 11.0–11.4 ns per event; docs/speed.md). None where that does not apply or a check
    failed: :func:`checked_columns` then converts and words the problem."""
    from ..native import library as native

    if isinstance(events, EventFile) or not native.available():
        return None
    cols = []
    for col, dtype in ((events.t, np.float64), (events.x, np.int64), (events.y, np.int64), (events.p, np.int8)):
        try:
            a = native.as_numpy(col)
        except (RuntimeError, TypeError):  # on a GPU, or part of a graph
            return None
        if not isinstance(a, np.ndarray) or a.dtype != dtype or not a.flags.c_contiguous or a.ndim != 1:
            return None
        cols.append(a)
    b = np.asarray(events.b)
    if b.size and int(b.max()) > 0:
        return None
    t, x, y, p = cols
    return native.event_message(t, x, y, p, width, height, last_t_us, max_t_us)


#: Events converted and written per slice by :meth:`EventFileWriter.write` (bounds its memory).
WRITE_SLICE = 1 << 18


def _slice_events(events: Any, start: int, end: int) -> Any:
    """Events ``start:end`` of an EventList or EventFile (views, no copies)."""
    if isinstance(events, EventFile):
        return EventFile(
            events.t_us[start:end],
            events.x[start:end],
            events.y[start:end],
            events.p[start:end],
            events.width,
            events.height,
            events.metadata,
        )
    return type(events)(
        events.b[start:end], events.x[start:end], events.y[start:end], events.t[start:end], events.p[start:end]
    )


def _child_command(mode: str) -> list[str]:
    """The command line of the writer/reader child process (imports only numpy and h5py or dv-processing)."""
    import sys

    return [sys.executable, "-P", str(Path(__file__).with_name("child_process.py")), mode]


def _writer_environment() -> dict[str, str]:
    """The writer process's environment: this one's, with OpenBLAS held to one thread. The writer
    makes no linear algebra, and OpenBLAS's idle worker spun for 0.13 CPU s of the 0.23 that
    importing NumPy took (``perf stat``, 3 runs each), at start-up, beside torch's import."""
    return {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


def _widen_pipe(pipe: Any) -> None:
    """Give the pipe to the writer child a 1 MiB buffer (Linux ``F_SETPIPE_SZ``; default 64 KiB).

    The simulation keeps both cores busy, so every time the pipe fills the parent waits for the
    child to be scheduled: with 64 KiB that is ~3 400 hand-offs for bikes' 17.3 M events, and the
    parent spent about 0.9 s of a 5.8 s command blocked in ``write`` (py-spy). Where the call is
    refused (another OS, a lower ``/proc/sys/fs/pipe-max-size``) the pipe keeps its size."""
    try:
        import fcntl

        fcntl.fcntl(pipe.fileno(), fcntl.F_SETPIPE_SZ, 1 << 20)
    except (ImportError, AttributeError, OSError):
        pass


def partial_path(path: Path) -> Path:
    """The hidden temporary file a writer fills before renaming it onto ``path``; it keeps the
    suffix (dv-processing aborts on an AEDAT4 file name without ``.aedat4``)."""
    return path.parent / f".{path.stem}.partial-{os.getpid()}{path.suffix}"


def _fsync(path: Path, *, directory: bool = False) -> None:
    fd = os.open(path, os.O_RDONLY | (os.O_DIRECTORY if directory else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def exception_line(exc: BaseException, limit: int = 200) -> str:
    """``str(exc)`` on one line (its type's name where empty), cut to ``limit`` characters, for a message."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


class EventFileWriter:
    """Write events to ``path`` chunk by chunk; the format follows the suffix (see module doc).

    Use as a context manager: ``with EventFileWriter(path, width, height) as w: w.write(events)``.
    Events must arrive in non-decreasing time (as a stream's chunks do).

    The file appears at ``path`` only when it is complete: the events go to a hidden temporary
    file in the same folder (``.STEM.partial-PID.SUFFIX``), which :meth:`close` flushes, fsyncs and
    renames onto ``path`` (``os.replace``, atomic). A failure (full disk, an exception, Ctrl-C
    inside the ``with`` block) or :meth:`abort` removes the temporary file and leaves a previous
    file at ``path`` untouched; a killed process leaves at most the hidden temporary file. The
    HDF5 and AEDAT4 writers (h5py, dv-processing: C/C++) run in a child process fed through a
    pipe, so a crash inside the library (dv-processing aborts; h5py segfaulted after a write
    failed on a full disk) is reported as an :class:`OSError` naming the file and the reason or
    signal instead of ending this process.
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
        self._tmp_path = partial_path(self.path)
        self._cols_dir: Path | None = None
        self._child: Any = None
        try:
            self._open()
        except BaseException as exc:
            self._discard()
            if isinstance(exc, OSError) and not isinstance(exc, FileNotFoundError):
                raise self._os_error(exc) from exc
            raise

    def _open(self) -> None:
        if self.format in ("hdf5", "aedat4"):
            import importlib.util
            import json
            import subprocess

            module = "h5py" if self.format == "hdf5" else "dv_processing"
            if importlib.util.find_spec(module) is None:
                if self.format == "aedat4":
                    _dv()  # raises ToolMissingError with the install hint
                raise ToolMissingError("HDF5 event files need h5py: pip install h5py")
            meta = json.dumps(self.metadata, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
            self._err = tempfile.TemporaryFile()  # noqa: SIM115  the child's stderr, read if it fails
            self._child = subprocess.Popen(
                [*_child_command("write"), self.format, str(self._tmp_path), str(self.width), str(self.height), meta],
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=self._err,
                process_group=0,
                env=_writer_environment(),
            )
            _widen_pipe(self._child.stdin)
        else:
            self._cols_dir = self.path.parent / f"{self._tmp_path.name}.cols"
            self._cols_dir.mkdir()
            self._cols = {k: open(self._cols_dir / k, "wb") for k in ("t", "x", "y", "p")}  # noqa: SIM115

    def _os_error(self, exc: BaseException) -> OSError:
        """A one-line :class:`OSError` naming the target file (nothing was written to it)."""
        code = getattr(exc, "errno", None) or errno.EIO
        why = os.strerror(code) if getattr(exc, "errno", None) else exception_line(exc)
        return OSError(
            code,
            f"writing the {self.format} event file failed ({why}); nothing was written there (a previous file is kept)",
            str(self.path),
        )

    def _child_failed(self) -> OSError:
        """The writer child died or failed: an OSError naming the file and its error or signal."""
        import signal

        try:
            rc = self._child.wait(timeout=30)
        except Exception:  # noqa: BLE001  still running after its pipe broke: end it
            self._child.kill()
            rc = self._child.wait()
        how = f"was killed by {signal.Signals(-rc).name}" if rc < 0 else f"failed (status {rc})"
        self._err.seek(0)
        lines = [ln for ln in self._err.read().decode("utf-8", "replace").splitlines() if ln.strip()]
        detail = f": {' '.join(lines[-1].split())[:200]}" if lines else ""
        lib = "h5py" if self.format == "hdf5" else "dv-processing"
        hint = " (full disk?)" if rc < 0 or "errno" not in detail.lower() else ""
        return OSError(
            errno.EIO,
            f"the {self.format} writer ({lib}, child process) {how}{detail}{hint}; "
            "nothing was written there (a previous file is kept)",
            str(self.path),
        )

    def write(self, events: Any) -> None:
        """Append an :class:`~fsdvs_hw.sensor.EventList` (batch 0) or :class:`EventFile`.

        Written in slices of :data:`WRITE_SLICE` events, so the conversion's temporaries (µs times,
        the file's row layout: ~50 B per event) are bounded whatever the size of ``events``.

        Raises
        ------
        InputError
            Events outside the sensor, with bad polarity, or out of time order (nothing of that
            slice written).
        OSError
            The file could not be written (full disk, the AEDAT4 writer died); the writer is
            aborted (temporary file removed) and the message names ``path``.
        """
        if self._closed:
            raise InputError(f"event file {str(self.path)!r}: already closed")
        n = len(events)
        for start in range(0, n, WRITE_SLICE):
            self._write_slice(_slice_events(events, start, min(start + WRITE_SLICE, n)))

    def _write_slice(self, events: Any) -> None:
        max_t_us = _UINT32_MAX if self.format == "hdf5" else _MAX_T_US
        message = None
        if self._child is not None:
            message = _message_columns(events, self.width, self.height, self._last_t, max_t_us)
        if message is not None:  # converted and checked in one compiled pass
            t_us = message[0]
        else:
            t_us, x, y, p = checked_columns(events, self.width, self.height)
            if not t_us.size:
                return
            if int(t_us[0]) < self._last_t or bool((np.diff(t_us) < 0).any()):
                raise InputError("events: must be written in non-decreasing time")
            if int(t_us[-1]) > max_t_us:
                raise InputError(
                    f"events: time {int(t_us[-1])} µs exceeds the uint32 µs range of v2e's HDF5 "
                    "layout (4294 s); use .aedat4 or .npz"
                )
        if not t_us.size:
            return
        try:
            if message is not None:
                self._send(*message)
            else:
                self._write_columns(t_us, x, y, p)
        except (OSError, RuntimeError) as exc:  # full disk, a dead child: nothing half-written stays
            failed = self._child_failed() if self._child is not None else self._os_error(exc)
            self._discard()
            raise failed from exc
        except BaseException:
            self._discard()
            raise
        self._last_t = int(t_us[-1])
        self.count += t_us.size

    def _write_columns(self, t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> None:
        if self._child is not None:
            self._send(t_us, x, y, p > 0)
        else:
            for k, arr in (("t", t_us), ("x", x.astype(np.uint16)), ("y", y.astype(np.uint16)), ("p", p)):
                self._cols[k].write(np.ascontiguousarray(arr).tobytes())

    def _send(self, t_us: np.ndarray, x: np.ndarray, y: np.ndarray, on: np.ndarray) -> None:
        """One message to the writer process (layout in :mod:`.child_process`): the count, then the
        µs times, x, y and ON flags in the message's dtypes (converted here where they differ)."""
        pipe = self._child.stdin
        pipe.write(np.int64(t_us.size).astype("<i8").tobytes())
        for arr, dt in ((t_us, "<i8"), (x, "<i2"), (y, "<i2"), (on, "u1")):
            pipe.write(np.ascontiguousarray(arr, dtype=dt).data.cast("B"))  # no bytes copy
        pipe.flush()

    def close(self) -> None:
        """Finish the file and rename it onto ``path`` (idempotent; a no-op after :meth:`abort`).

        Raises
        ------
        OSError
            The file could not be finished (full disk, the AEDAT4 writer died): the temporary
            file is removed, a previous file at ``path`` is kept, the message names ``path``.
        """
        if self._closed:
            return
        try:
            self._finish()
            _fsync(self._tmp_path)
            os.replace(self._tmp_path, self.path)
            _fsync(self.path.parent if str(self.path.parent) else Path("."), directory=True)
        except (OSError, RuntimeError) as exc:
            failed = (
                self._child_failed()
                if self._child is not None and self._child.poll() not in (None, 0)
                else self._os_error(exc)
            )
            self._discard()
            raise failed from exc
        except BaseException:
            self._discard()
            raise
        finally:
            self._closed = True

    def _finish(self) -> None:
        if self._child is not None:
            self._child.stdin.write(np.int64(-1).astype("<i8").tobytes())
            self._child.stdin.close()
            if self._child.wait() != 0:
                raise RuntimeError(f"{self.format} writer failed")
            self._err.close()
        else:
            assert self._cols_dir is not None
            dtypes = {"t": np.int64, "x": np.uint16, "y": np.uint16, "p": np.int8}
            for f in self._cols.values():
                f.close()
            with zipfile.ZipFile(self._tmp_path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as z:
                for k, dt in dtypes.items():
                    with z.open(f"{k}.npy", "w", force_zip64=True) as out:
                        np.lib.format.write_array_header_1_0(
                            out,
                            {
                                "descr": np.lib.format.dtype_to_descr(np.dtype(dt)),
                                "fortran_order": False,
                                "shape": (self.count,),
                            },
                        )
                        with open(self._cols_dir / k, "rb") as src:
                            while block := src.read(1 << 22):
                                out.write(block)
                for k, v in (("width", self.width), ("height", self.height)):
                    with z.open(f"{k}.npy", "w") as out:
                        np.lib.format.write_array(out, np.asarray(v, dtype=np.int64))
            self._remove_cols()

    def _remove_cols(self) -> None:
        if self._cols_dir is None:
            return
        for f in getattr(self, "_cols", {}).values():
            f.close()
        for k in ("t", "x", "y", "p"):
            (self._cols_dir / k).unlink(missing_ok=True)
        with contextlib.suppress(OSError):
            self._cols_dir.rmdir()
        self._cols_dir = None

    def _discard(self) -> None:
        """Close everything quietly and remove the temporary files (the target is never touched)."""
        self._closed = True
        if self._child is not None:
            if self._child.poll() is None:
                self._child.kill()
            with contextlib.suppress(Exception):
                self._child.stdin.close()
            self._child.wait()
            with contextlib.suppress(Exception):
                self._err.close()
        self._remove_cols()
        self._tmp_path.unlink(missing_ok=True)

    def abort(self) -> None:
        """Give up: remove the temporary file; nothing appears at ``path`` (idempotent)."""
        if not self._closed:
            self._discard()

    def __enter__(self) -> EventFileWriter:
        return self

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self) -> None:  # a writer dropped without close(): leave no temporary file
        with contextlib.suppress(Exception):
            self.abort()


def write_events(
    path: str | Path, events: Any, width: int, height: int, *, metadata: dict[str, Any] | None = None
) -> int:
    """Write one :class:`~fsdvs_hw.sensor.EventList` (batch 0) to ``path``; returns the count."""
    with EventFileWriter(path, width, height, metadata=metadata) as w:
        w.write(events)
        return w.count


#: Seconds the AEDAT4 reader waits for dv-processing's next batch before it refuses the file
#: (a corrupt file can make the library loop forever); counted once the reader process has
#: started (its imports can take longer on a busy machine: :data:`AEDAT4_START_TIMEOUT_S`).
#: A batch of a valid file takes milliseconds.
AEDAT4_READ_TIMEOUT_S = 5.0
#: Seconds the AEDAT4 reader process may take to start (Python and dv-processing's imports).
AEDAT4_START_TIMEOUT_S = 120.0
#: The first bytes of an AEDAT 4 file.
AEDAT4_MAGIC = b"#!AER-DAT4.0"
#: Events read and checked per slice from an HDF5 file (bounds the reader's temporaries).
READ_SLICE = 1 << 20
#: Bytes of memory per event read: int64 time, x, y, int8 polarity, plus the file's own row.
EVENT_BYTES = 41
#: Largest sensor side accepted (pixels): the writers' limit, and AEDAT4's int16 coordinates.
_MAX_SIDE = 32767


def field_error(path: Path, fld: str, what: str) -> InputError:
    """The :class:`~fsdvs_hw.errors.InputError` of a bad field ``fld`` of the event file ``path``: ``what`` is wrong."""
    return InputError(f"event file {str(path)!r}: {fld}: {what}")


def checked_side(path: Path, fld: str, v: Any) -> int:
    """A sensor width/height read from a file: an integer in [1, 32767]."""
    arr = np.asarray(v)
    if arr.shape not in ((), (1,)) or arr.dtype.kind not in "iu" or not 1 <= int(arr.reshape(-1)[0]) <= _MAX_SIDE:
        raise field_error(path, fld, f"must be an integer in [1, {_MAX_SIDE}] pixels, got {np.array2string(arr)[:40]}")
    return int(arr.reshape(-1)[0])


class EventColumnsCheck:
    """Checks the columns of an event file slice by slice (dtype, ranges, time order)."""

    def __init__(self, path: Path, names: dict[str, str], polarities: tuple[int, ...]) -> None:
        self.path, self.names, self.polarities = path, names, polarities
        self.last_t = 0
        self.seen = 0

    def dtypes(self, **cols: np.dtype) -> None:
        for k, dt in cols.items():
            if np.dtype(dt).kind not in "iu":
                hint = " (times must be integer microseconds; float times look like seconds)" if k == "t" else ""
                raise field_error(self.path, self.names[k], f"dtype {np.dtype(dt)} is not an integer type{hint}")

    def check(
        self, t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int | None, height: int | None
    ) -> None:
        self.dtypes(t=t.dtype, x=x.dtype, y=y.dtype, p=p.dtype)
        t = t.astype(np.int64, copy=False)  # unsigned columns: np.diff would wrap around
        n = t.size
        if n:
            if int(t.min()) < 0:
                raise field_error(self.path, self.names["t"], f"negative time {int(t.min())} µs; times must be >= 0")
            back = np.flatnonzero(np.diff(t) < 0)
            if int(t[0]) < self.last_t or back.size:
                i = self.seen + (int(back[0]) + 1 if not int(t[0]) < self.last_t else 0)
                raise field_error(
                    self.path, self.names["t"], f"times decrease at event {i}; they must be non-decreasing µs"
                )
            self.last_t = int(t[-1])
            for k, arr, hi in (("x", x, width), ("y", y, height)):
                lo_v, hi_v = int(arr.min()), int(arr.max())
                if lo_v < 0 or (hi is not None and hi_v >= hi):
                    raise field_error(
                        self.path,
                        self.names[k],
                        f"value {lo_v if lo_v < 0 else hi_v} outside [0, {hi}) of the {width}x{height} sensor",
                    )
            bad = ~np.isin(p, self.polarities)
            if bad.any():
                raise field_error(
                    self.path,
                    self.names["p"],
                    f"polarity {int(p[bad][0])}; this format allows {' / '.join(str(v) for v in self.polarities)}",
                )
        self.seen += n


def read_events(path: str | Path) -> EventFile:
    """Read an event file written by :class:`EventFileWriter` (or by v2e / DV for HDF5 / AEDAT4).

    The file is checked before its events are allocated, and the events while they are read (in
    slices): the expected datasets/arrays (a dataset, not a group), integer column dtypes (float
    times are refused: they look like seconds; times are µs), equal column lengths, the declared
    event count against the data present, ``0 <= x < width``, ``0 <= y < height``, polarity in
    the format's on-disk convention, times >= 0 and non-decreasing, and the memory needed
    against :func:`fsdvs_hw.limits.check_allocation`. AEDAT4 is read by dv-processing in a child
    process (a corrupt file can abort it or make it loop; :data:`AEDAT4_READ_TIMEOUT_S`).

    Raises
    ------
    InputError
        Missing, truncated or corrupt file, unknown suffix, or any check above; one line naming
        the file and the field.
    """
    p = Path(path)
    fmt = event_format(p)
    checked_file(p)
    if fmt == "hdf5":
        return _read_hdf5(p)
    if fmt == "aedat4":
        return _read_aedat4(p)
    return _read_npz(p)


def _read_hdf5(p: Path) -> EventFile:
    import h5py

    try:
        f = h5py.File(p, "r")
    except (OSError, ValueError) as exc:
        raise field_error(p, "(file)", f"not a readable HDF5 file ({exception_line(exc)})") from None
    with f:
        try:
            return _read_hdf5_open(p, f)
        except InputError:
            raise
        except (OSError, ValueError, KeyError, TypeError, RuntimeError, IndexError) as exc:
            raise field_error(p, "events", f"unreadable, truncated or corrupt ({exception_line(exc)})") from None


def _read_hdf5_open(p: Path, f: Any) -> EventFile:
    import math

    import h5py

    ds = f.get("events")
    if ds is None:
        raise field_error(p, "events", "no 'events' dataset (v2e layout: (N, 4) [t_us, x, y, p])")
    if not isinstance(ds, h5py.Dataset):
        raise field_error(p, "events", f"is a {type(ds).__name__}, expected an (N, 4) dataset (v2e layout)")
    if ds.ndim != 2 or ds.shape[1] != 4:
        raise field_error(p, "events", f"shape {ds.shape}, expected (N, 4) [t_us, x, y, p] (v2e layout)")
    names = {"t": "events[:, 0] (t_us)", "x": "events[:, 1] (x)", "y": "events[:, 2] (y)", "p": "events[:, 3] (p)"}
    chk = EventColumnsCheck(p, names, (0, 1))
    chk.dtypes(t=ds.dtype)
    attrs: dict[str, Any] = {}
    for k in f.attrs:
        try:
            v = f.attrs[k]
        except (OSError, TypeError, ValueError):
            continue  # an attribute h5py cannot decode is not needed to read events
        attrs[k] = v.item() if isinstance(v, np.generic) else v
    w = checked_side(p, "attribute width", f.attrs["width"]) if "width" in f.attrs else None
    h = checked_side(p, "attribute height", f.attrs["height"]) if "height" in f.attrs else None
    n = int(ds.shape[0])
    check_allocation(f"event file {str(p)!r}: events ({n} declared events)", n * EVENT_BYTES)
    if n:
        if ds.chunks is not None:
            want = math.ceil(n / ds.chunks[0]) * math.ceil(4 / ds.chunks[1])
            got = ds.id.get_num_chunks()
            if got < want:
                raise field_error(
                    p,
                    "events",
                    f"declares {n} events but only {got} of its {want} chunks are stored "
                    "(truncated or unfinished file)",
                )
        elif ds.id.get_storage_size() < ds.size * ds.dtype.itemsize:
            raise field_error(
                p,
                "events",
                f"declares {n} events but stores only {ds.id.get_storage_size()} bytes (truncated or unfinished file)",
            )
    t, x, y = (np.empty(n, dtype=np.int64) for _ in range(3))
    pol = np.empty(n, dtype=np.int8)
    for i in range(0, n, READ_SLICE):
        a = ds[i : i + READ_SLICE]
        chk.check(a[:, 0], a[:, 1], a[:, 2], a[:, 3], w, h)
        sl = slice(i, i + a.shape[0])
        t[sl], x[sl], y[sl] = a[:, 0], a[:, 1], a[:, 2]
        pol[sl] = np.where(a[:, 3] > 0, 1, -1)
    w = w if w is not None else (int(x.max()) + 1 if n else 1)
    h = h if h is not None else (int(y.max()) + 1 if n else 1)
    if max(w, h) > _MAX_SIDE:
        raise field_error(
            p,
            "events[:, 1:3] (x, y)",
            f"pixels up to {w - 1}, {h - 1}: beyond {_MAX_SIDE} (no width/height attributes)",
        )
    return EventFile(t, x, y, pol, w, h, attrs)


def _npy_header(p: Path, z: Any, k: str) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype of array ``k`` of an open npz, from its header (nothing else is read)."""
    with z.zip.open(f"{k}.npy") as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise field_error(p, k, f"unsupported .npy format version {version}")
    return tuple(shape), np.dtype(dtype)


def _read_npz(p: Path) -> EventFile:
    import zlib

    errors = (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error, NotImplementedError)
    try:
        z = np.load(p, allow_pickle=False)
    except errors as exc:
        raise field_error(p, "(file)", f"not a readable npz file ({exception_line(exc)})") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise field_error(p, "(file)", "holds a single .npy array, not an npz archive of t, x, y, p, width, height")
    with z:
        missing = {"t", "x", "y", "p", "width", "height"} - set(z.files)
        if missing:
            raise field_error(
                p, ", ".join(sorted(missing)), "missing arrays (an event npz holds t, x, y, p, width, height)"
            )
        chk = EventColumnsCheck(p, {k: k for k in "txyp"}, (-1, 1))
        k = "(file)"
        try:
            headers = {}
            for k in ("t", "x", "y", "p"):
                headers[k] = _npy_header(p, z, k)
                if len(headers[k][0]) != 1:
                    raise field_error(p, k, f"shape {headers[k][0]}, expected one column (N,)")
            chk.dtypes(**{k: hd[1] for k, hd in headers.items()})
            lengths = {k: hd[0][0] for k, hd in headers.items()}
            if len(set(lengths.values())) > 1:
                raise field_error(p, "t, x, y, p", f"columns of different lengths {lengths} (ragged)")
            n = lengths["t"]
            check_allocation(f"event file {str(p)!r}: t, x, y, p ({n} declared events)", n * EVENT_BYTES)
            k = "width"
            w = checked_side(p, "width", z["width"])
            k = "height"
            h = checked_side(p, "height", z["height"])
            cols = {}
            for k in ("t", "x", "y", "p"):
                cols[k] = z[k]
                if cols[k].shape != (n,):
                    raise field_error(p, k, f"holds {cols[k].size} values, its header declares {n} (truncated?)")
        except InputError:
            raise
        except errors as exc:
            raise field_error(p, k, f"unreadable, truncated or corrupt ({exception_line(exc)})") from None
    chk.check(cols["t"], cols["x"], cols["y"], cols["p"], w, h)
    return EventFile(
        cols["t"].astype(np.int64),
        cols["x"].astype(np.int64),
        cols["y"].astype(np.int64),
        cols["p"].astype(np.int8),
        w,
        h,
    )


class _ChildPipe:
    """Reads exact byte counts from a child's stdout, giving up after ``timeout`` s without data."""

    def __init__(self, stream: Any, timeout: float, path: Path) -> None:
        self.fd, self.timeout, self.path = stream.fileno(), timeout, path

    def read(self, n: int) -> bytes:
        import select

        buf = bytearray()
        while len(buf) < n:
            ready, _, _ = select.select([self.fd], [], [], self.timeout)
            if not ready:
                raise field_error(
                    self.path,
                    "(file)",
                    f"dv-processing made no progress for {self.timeout:g} s reading it (corrupt AEDAT4 file?)",
                )
            block = os.read(self.fd, min(n - len(buf), 1 << 22))
            if not block:
                raise EOFError
            buf += block
        return bytes(buf)

    def ints(self, n: int, dtype: str) -> np.ndarray:
        return np.frombuffer(self.read(n * np.dtype(dtype).itemsize), dtype=dtype)


def _read_aedat4(p: Path) -> EventFile:
    import importlib.util
    import signal
    import subprocess

    if importlib.util.find_spec("dv_processing") is None:
        _dv()  # raises ToolMissingError with the install hint
    with open(p, "rb") as fh:
        magic = fh.read(len(AEDAT4_MAGIC))
    if magic != AEDAT4_MAGIC:
        raise field_error(p, "(file)", f"starts with {magic[:12]!r}, not {AEDAT4_MAGIC!r}: not an AEDAT 4 file")
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(
            [*_child_command("read"), str(p)],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=err,
            process_group=0,
        )
        assert proc.stdout is not None  # stdout=PIPE
        try:
            pipe = _ChildPipe(proc.stdout, AEDAT4_START_TIMEOUT_S, p)
            chk = EventColumnsCheck(p, {"t": "timestamp", "x": "x", "y": "y", "p": "polarity"}, (0, 1))
            try:
                pipe.read(1)  # the reader has started
                pipe.timeout = AEDAT4_READ_TIMEOUT_S
                w_raw, h_raw, name_len = (int(v) for v in pipe.ints(3, "<i8"))
                w, h = (
                    checked_side(p, "event resolution width", w_raw),
                    checked_side(p, "event resolution height", h_raw),
                )
                if not 0 <= name_len <= 4096:
                    raise field_error(p, "camera name", f"length {name_len} out of range")
                camera = pipe.read(name_len).decode("utf-8", "replace")
                parts: list[tuple[np.ndarray, ...]] = []
                total = 0
                while (n := int(pipe.ints(1, "<i8")[0])) != -1:
                    total += n
                    check_allocation(f"event file {str(p)!r}: events ({total} events so far)", total * EVENT_BYTES)
                    t, x, y, pol = (pipe.ints(n, dt) for dt in ("<i8", "<i2", "<i2", "u1"))
                    chk.check(t, x, y, pol, w, h)
                    parts.append((t, x, y, pol))
            except EOFError:
                rc = proc.wait()
                err.seek(0)
                msg = " ".join(err.read().decode("utf-8", "replace").split())[:200]
                how = (
                    f"dv-processing was killed by {signal.Signals(-rc).name}"
                    if rc < 0
                    else f"not a readable AEDAT4 file ({msg or f'reader exit status {rc}'})"
                )
                raise field_error(p, "(file)", how) from None
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            proc.stdout.close()
    cols = [
        np.concatenate([part[i] for part in parts]) if parts else np.zeros(0, dt)
        for i, dt in enumerate(("<i8", "<i2", "<i2", "u1"))
    ]
    return EventFile(
        cols[0].astype(np.int64),
        cols[1].astype(np.int64),
        cols[2].astype(np.int64),
        np.where(cols[3] > 0, 1, -1).astype(np.int8),
        w,
        h,
        {"camera": camera},
    )
