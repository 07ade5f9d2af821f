"""Build, load and call the compiled kernels of :mod:`~fsdvs_hw.sensor.simulation.crossings` (``_crossings.c``), the fused
no-grad pixel step of :mod:`.fused` (``_fused.c``) and the event-file message conversion of
:mod:`~fsdvs_hw.sensor.eventfiles.eventfile` (``_eventfile.c``).

The C sources are compiled once per machine with the system C compiler (``$CC``, else ``cc``) into
a per-user cache (``$FSDVS_HW_CACHE``, else ``$XDG_CACHE_HOME/fsdvs_hw``, else
``~/.cache/fsdvs_hw``), keyed by a hash of the source and flags, and loaded with :mod:`ctypes`,
which releases the GIL during each call (so the event pipeline's worker threads run in parallel
with the stepping thread). Without a compiler (or with ``FSDVS_HW_NO_NATIVE`` set)
:func:`available` is False and :mod:`~fsdvs_hw.sensor.simulation.crossings` uses its torch path: same events, slower.

Why C and not numba: the two are equally fast here, but numba's LLVM adds ~125 MB of resident
memory to every process that loads a kernel, a quarter of the streaming simulator's budget.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import subprocess
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

__all__: list[str] = []  # the compiled kernels are called by the simulation, the fused steps and the event files

_SOURCES = [Path(__file__).with_name(n) for n in ("_crossings.c", "_fused.c", "_eventfile.c")]
_HEADERS = [Path(__file__).with_name("_native_clones.h")]  # hashed with the sources
# no FMA contraction and no reassociation: results bit-identical to the torch path
_FLAGS = ["-O3", "-std=c99", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math", "-fno-trapping-math"]
_lib: ctypes.CDLL | None = None
_tried = False
_error = ""

_P = ctypes.c_void_p
_I = ctypes.c_int64
_D = ctypes.c_double


def _cache_dir() -> Path:
    from ...environment import env as _env

    env = _env("FSDVS_HW_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fsdvs_hw"


def _build(extra_flags: tuple[str, ...] = ()) -> Path:
    """Compile the kernels if these sources and flags have not been compiled yet (``extra_flags``:
    for tests, e.g. ``-DFSDVS_NO_CLONES`` for the baseline x86-64 code alone)."""
    src = b"".join(p.read_bytes() for p in (*_SOURCES, *_HEADERS))
    cc = os.environ.get("CC", "cc")
    flags = [*_FLAGS, *extra_flags]
    key = hashlib.sha256(src + " ".join([cc, *flags, platform.machine()]).encode()).hexdigest()[:16]
    out = _cache_dir() / f"crossings-{key}.so"
    if out.exists():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".so", dir=out.parent)
    os.close(fd)
    try:
        res = subprocess.run(
            [cc, *flags, "-o", tmp, *map(str, _SOURCES), "-lm"], capture_output=True, text=True, check=False
        )
        if res.returncode != 0:
            raise OSError(f"{cc} failed: {res.stderr.strip()[-500:]}")
        os.replace(tmp, out)  # atomic: parallel builders (pytest -n) never load a half-written file
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return out


def _declare(lib: ctypes.CDLL) -> None:
    """Argument and result types of every kernel in ``lib``."""
    step = [_P] * 5 + [_P, _I, _P, _I, _P, _P, _P, _I, _I, _P, _D, ctypes.c_int, _P, _P, _P, _P, _P, _P]
    for name in ("fsdvs_step_events_f32", "fsdvs_step_events_f64"):
        getattr(lib, name).argtypes = step
        getattr(lib, name).restype = _I
    for real, name in ((ctypes.c_float, "f32"), (ctypes.c_double, "f64")):
        fn = getattr(lib, f"fsdvs_lowpass_exponent_{name}")
        fn.argtypes, fn.restype = [_P, _I, _I, _P, real, real, real, real, _P], None
        fn = getattr(lib, f"fsdvs_pixel_step_{name}")
        fn.argtypes = [_P] * 4 + [_P, _I, _P, _I, _P, real, real, _I, _I] + [_P] * 5
        fn.restype = None
        fn = getattr(lib, f"fsdvs_linlog_clamp_{name}")
        fn.argtypes, fn.restype = [_P, _I, real, real, _P], None
        fn = getattr(lib, f"fsdvs_linlog_finish_{name}")
        fn.argtypes, fn.restype = [_P, _P, _I, real, real, real, _D, _P], None
        fn = getattr(lib, f"fsdvs_floor_count_{name}")
        fn.argtypes, fn.restype = [_P, _I, real, _P], _I
    lib.fsdvs_sort_interval.argtypes = [_I, _P, _P, _P, _P, _D, _D, _I, _P, _P, _P, _P, _P]
    lib.fsdvs_sort_interval.restype = ctypes.c_int
    lib.fsdvs_write_columns.argtypes = [_P, _P, _P, _I, _I, _I, _P, _P, _P, _P]
    lib.fsdvs_write_columns.restype = None
    lib.fsdvs_sort_interval_columns.argtypes = [_I, _P, _P, _P, _P, _D, _D, _I, _P, _P, _I, _I, _P, _P, _P, _P]
    lib.fsdvs_sort_interval_columns.restype = ctypes.c_int
    lib.fsdvs_event_message.argtypes = [_P, _P, _P, _P, _I, _I, _I, _I, _I, _P, _P, _P, _P]
    lib.fsdvs_event_message.restype = ctypes.c_int


def _load() -> ctypes.CDLL | None:
    global _lib, _tried, _error
    if _tried:
        return _lib
    _tried = True
    from ...environment import env as _env

    if _env("FSDVS_HW_NO_NATIVE"):
        _error = "disabled by FSDVS_HW_NO_NATIVE"
        return None
    try:
        lib = ctypes.CDLL(str(_build()))
    except (OSError, FileNotFoundError) as exc:
        _error = str(exc)
        return None
    _declare(lib)
    _lib = lib
    return lib


def available() -> bool:
    """Whether the compiled kernels could be built and loaded (see :func:`why_unavailable`)."""
    return _load() is not None


def why_unavailable() -> str:
    """The build or load error, '' when the kernels are available."""
    _load()
    return _error


def loaded() -> ctypes.CDLL:
    """The loaded library; every caller checks :func:`available` first."""
    lib = _load()
    assert lib is not None, "compiled kernels unavailable: check available() first"
    return lib


def _ptr(a: np.ndarray | None) -> int | None:
    return None if a is None else a.ctypes.data


def step_events(
    h_on: np.ndarray,
    h_off: np.ndarray,
    sig_a: np.ndarray,
    ref_a: np.ndarray,
    d_b: np.ndarray,
    c_on: np.ndarray,
    c_off: np.ndarray,
    t_a: np.ndarray,
    t_b: np.ndarray,
    dt: np.ndarray,
    hw: int,
    last_t: np.ndarray | None,
    refractory_s: float,
    em_on: np.ndarray | None,
    em_off: np.ndarray | None,
    flat: np.ndarray | None,
    t: np.ndarray | None,
    p: np.ndarray | None,
) -> tuple[int, float]:
    """Events of one comparator step (``_crossings.c``: ``fsdvs_step_events_*``).

    All arrays C-contiguous and 1-D over the B·H·W pixels, ``h_on`` … ``c_off`` and ``em_*`` of one
    floating dtype (float32 or float64); ``c_*`` of 1, H·W or B·H·W values; ``t_a``, ``t_b``, ``dt``
    float64 (B,); ``last_t`` float64 or None (no refractory period); ``flat`` int32, ``t`` float64,
    ``p`` int8 with room for every crossing, or None (counts only). Returns (events written,
    crossings lost to the refractory period).
    """
    lib = loaded()
    fn = lib.fsdvs_step_events_f32 if h_on.dtype == np.float32 else lib.fsdvs_step_events_f64
    lost = ctypes.c_double(0.0)
    n = fn(
        _ptr(h_on),
        _ptr(h_off),
        _ptr(sig_a),
        _ptr(ref_a),
        _ptr(d_b),
        _ptr(c_on),
        len(c_on),
        _ptr(c_off),
        len(c_off),
        _ptr(t_a),
        _ptr(t_b),
        _ptr(dt),
        len(h_on),
        hw,
        _ptr(last_t),
        float(refractory_s),
        int(last_t is not None),
        _ptr(em_on),
        _ptr(em_off),
        _ptr(flat),
        _ptr(t),
        _ptr(p),
        ctypes.byref(lost),
    )
    if n < 0:
        raise MemoryError("step_events: out of memory for the active-pixel list")
    return int(n), float(lost.value)


_scratch = threading.local()  # each thread's bucket counts, reused from interval to interval


def as_numpy(x: Any) -> Any:
    """A CPU torch tensor's NumPy view through its C method (NumPy's ``__array__`` protocol goes
    through Python and took ~3 µs per column); anything else as it is."""
    to_numpy = getattr(x, "numpy", None)
    return to_numpy() if to_numpy is not None else x


def _interval_parts(parts: list) -> tuple[list, int]:
    """Non-empty ``(flat, t, p)`` parts as contiguous int32/float64/int8 arrays, and their total
    length (at most 2**31 - 1: the bucket counts are int32)."""
    parts = [
        (
            np.ascontiguousarray(as_numpy(f), dtype=np.int32),
            np.ascontiguousarray(as_numpy(t), dtype=np.float64),
            np.ascontiguousarray(as_numpy(p), dtype=np.int8),
        )
        for f, t, p in parts
        if len(t)
    ]
    n = sum(len(q[1]) for q in parts)
    if n >= 2**31:
        raise ValueError(f"sort_events: {n} events in one frame interval; at most 2**31 - 1")
    return parts, n


def _bucket_args(parts: list, n: int, lo: float | None, hi: float | None) -> tuple:
    """The leading arguments of the C bucket sorts for the ``n`` events of ``parts`` (from
    :func:`_interval_parts`) with times in ``[lo, hi]`` (default: the times' own range): part
    count, lengths, the three pointer arrays, ``lo``, bucket scale, bucket count (one per event on
    average: measured faster than n/2 and n/4) and this thread's count scratch."""
    if lo is None or hi is None:
        lo = min(float(q[1].min()) for q in parts)
        hi = max(float(q[1].max()) for q in parts)
    nb = n
    scale = nb / (hi - lo) if hi > lo else 0.0
    if not np.isfinite(scale):  # an interval shorter than the float64 spacing allows
        scale = 0.0
    counts = _scratch_array("counts", nb + 1, np.int32)
    k = len(parts)
    arrays = [(ctypes.c_void_p * k)(*(q[i].ctypes.data for q in parts)) for i in range(3)]
    lens = np.array([len(q[1]) for q in parts], dtype=np.int64)
    return (k, lens.ctypes, *arrays, float(lo), float(scale), nb, _ptr(counts))  # .ctypes keeps lens alive


def sort_events(
    parts: list, lo: float | None = None, hi: float | None = None, *, out: tuple | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stable time sort of one frame interval's ``(flat, t, p)`` parts, concatenated in order.

    Equal to concatenating the parts and applying ``argsort(t, kind="stable")``: a counting sort
    into ``n`` buckets spaced evenly over ``[lo, hi]`` (a time's bucket is monotone in the time;
    default: the times' own range), then a stable insertion sort in each bucket (a stable merge
    sort above 32 events, so clustered times cannot make it quadratic), in one C call
    (``fsdvs_sort_interval``: the events are scattered into buckets as 16-byte ``(t, flat, p)``
    records in this thread's reused work array, one cache line per event, not three). ``flat``
    int32 (int64 parts are narrowed: pixel indices of a frame below 2**31), ``t`` float64, ``p``
    int8; into ``out`` (three such arrays of the total length) when given.
    """
    lib = loaded()
    parts, n = _interval_parts(parts)
    if out is not None:
        flat_out, t_out, p_out = out
    else:
        flat_out = np.empty(n, dtype=np.int32)
        t_out = np.empty(n, dtype=np.float64)
        p_out = np.empty(n, dtype=np.int8)
    if n == 0:
        return flat_out, t_out, p_out
    if (
        lib.fsdvs_sort_interval(
            *_bucket_args(parts, n, lo, hi), _ptr(_records(n)), _ptr(flat_out), _ptr(t_out), _ptr(p_out)
        )
        != 0
    ):
        raise MemoryError("sort_events: out of memory sorting a bucket")
    return flat_out, t_out, p_out


def _scratch_array(name: str, n: int, dtype: Any) -> np.ndarray:
    """This thread's reusable work array ``name`` with at least ``n`` entries (a view of ``n``)."""
    a = getattr(_scratch, name, None)
    if a is None or len(a) < n:
        a = np.empty(max(n, 1 << 16), dtype=dtype)
        setattr(_scratch, name, a)
    return a[:n]


def _records(n: int) -> np.ndarray:
    """This thread's work array of ``n`` 16-byte event records (``event_rec`` in ``_crossings.c``)."""
    return _scratch_array("records", 2 * n, np.float64)


def sort_intervals_to_columns(intervals: list, hw: int, w: int) -> tuple[np.ndarray, ...]:
    """A chunk's event columns ``(x, y, t, p)`` from its intervals' unsorted parts.

    ``intervals``: ``(parts, lo, hi)`` per frame interval in time order (parts as for
    :func:`sort_events`). Each interval is bucket-sorted as 16-byte ``(t, flat, p)`` records in
    this thread's reused work array (``fsdvs_sort_interval_columns``: the scatter into buckets
    touches one cache line per event, not three) and written straight into the columns, which are
    allocated once at the chunk's exact size: the same columns as sorting each interval with
    :func:`sort_events` and concatenating (:func:`~fsdvs_hw.sensor.simulation.crossings.to_event_columns`).
    """
    lib = loaded()
    sizes = [sum(len(q[1]) for q in parts) for parts, _, _ in intervals]
    n = sum(sizes)
    x = np.empty(n, dtype=np.int64)
    y = np.empty(n, dtype=np.int64)
    t = np.empty(n, dtype=np.float64)
    p = np.empty(n, dtype=np.int8)
    start = 0
    for parts, lo, hi in intervals:
        prepared, k = _interval_parts(parts)
        parts.clear()
        if (
            k
            and lib.fsdvs_sort_interval_columns(
                *_bucket_args(prepared, k, lo, hi),
                _ptr(_records(k)),
                hw,
                w,
                x.ctypes.data + 8 * start,
                y.ctypes.data + 8 * start,
                t.ctypes.data + 8 * start,
                p.ctypes.data + start,
            )
            != 0
        ):
            raise MemoryError("sort_intervals_to_columns: out of memory sorting a bucket")
        start += k
    return x, y, t, p


def write_columns(
    flat: np.ndarray,
    t: np.ndarray,
    p: np.ndarray,
    hw: int,
    w: int,
    x_out: np.ndarray,
    y_out: np.ndarray,
    t_out: np.ndarray,
    p_out: np.ndarray,
    start: int,
) -> None:
    """One sorted interval (int32 ``flat``) into the int64 ``x``, ``y`` and the ``t``, ``p`` columns
    from ``start``: ``y = (f mod hw) // w``, ``x = (f mod hw) - y w``."""
    n = len(t)
    lib = loaded()
    lib.fsdvs_write_columns(
        _ptr(flat),
        _ptr(t),
        _ptr(p),
        n,
        hw,
        w,
        x_out.ctypes.data + 8 * start,
        y_out.ctypes.data + 8 * start,
        t_out.ctypes.data + 8 * start,
        p_out.ctypes.data + start,
    )


#: Latest time (µs) :func:`event_message` converts itself; later ones go to NumPy's path.
_MESSAGE_T_MAX_US = 2**62


def event_message(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int, last_t_us: int, max_t_us: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Contiguous float64 ``t`` (s), int64 ``x``, ``y`` and int8 ``p`` in the event-file writer's
    message layout, checked in one pass (``fsdvs_event_message``): ``(t_us int64, x int16,
    y int16, p uint8 1 ON / 0 OFF)``, NumPy's ``rint(t * 1e6)`` and casts bit for bit. None where
    a check fails (a negative or non-finite time, a pixel outside ``width`` × ``height``, a
    polarity not ±1, times decreasing from ``last_t_us`` on, a time after ``max_t_us``): the
    caller's NumPy path then words the problem."""
    n = len(t)
    t_us = np.empty(n, dtype=np.int64)
    x16 = np.empty(n, dtype=np.int16)
    y16 = np.empty(n, dtype=np.int16)
    on = np.empty(n, dtype=np.uint8)
    code = loaded().fsdvs_event_message(
        _ptr(t),
        _ptr(x),
        _ptr(y),
        _ptr(p),
        n,
        int(width),
        int(height),
        int(last_t_us),
        min(int(max_t_us), _MESSAGE_T_MAX_US),
        _ptr(t_us),
        _ptr(x16),
        _ptr(y16),
        _ptr(on),
    )
    return (t_us, x16, y16, on) if code == 0 else None
