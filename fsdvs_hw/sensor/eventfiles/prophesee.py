"""Prophesee event files: RAW EVT 2.0, RAW EVT 3.0 and DAT; read through expelliarmus, written to spec.

Reading decodes EVT 2.0 and DAT through the maintained ``expelliarmus`` library [1]_ (C
decoders). Its EVT 3.0 decoder (1.1.12) counts a time-low wrap on top of the ``EVT_TIME_HIGH``
word that a conforming stream sends with it (events at 4000 and 4100 µs come back at 4000 and
8196 µs), so EVT 3.0 is decoded here by :func:`decode_evt3` (NumPy, vectorised), which follows
the published description [2]_ including vectorised events. expelliarmus does not check a
file's shape, so :func:`read_prophesee` first parses the ASCII header itself (the format, the
sensor geometry), checks that the binary body is a whole number of words of the format, and refuses a foreign or truncated file with an
:class:`~fsdvs_hw.errors.InputError` naming the file, the byte offset and the format expected.
These formats are streams without an event count: a file cut exactly at a word boundary reads as
a shorter recording, and only a cut inside a word (or inside the header) is detectable.

Writing follows Prophesee's published format descriptions [2]_ exactly (expelliarmus 1.1's EVT3
writer emits a single ``EVT_TIME_HIGH`` word, so any gap of 4096 µs or more between consecutive
events comes back 4096 µs early; hence a writer here):

EVT 2.0
    32-bit little-endian words, type in bits 31..28. ``CD_OFF`` (0x0) / ``CD_ON`` (0x1): bits
    27..22 the 6 low bits of the time, 21..11 ``x``, 10..0 ``y``. ``EVT_TIME_HIGH`` (0x8): bits
    27..0 the time's bits 33..6, sent before the first event and whenever they change.
EVT 3.0
    16-bit words, type in bits 15..12. ``EVT_ADDR_Y`` (0x0): ``y`` in 10..0. ``EVT_ADDR_X`` (0x2):
    polarity bit 11, ``x`` in 10..0 (one event at the current y and time). ``EVT_TIME_LOW``
    (0x6) and ``EVT_TIME_HIGH`` (0x8): the time's bits 11..0 and 23..12. Each state word is sent
    when it changes (times are 24-bit: a recording here must be shorter than 16.7 s).
DAT
    ASCII header lines starting with ``%``, then the event type byte (0x0C: CD) and the event size
    byte (8), then per event a ``uint32`` time (µs) and a ``uint32`` with ``x`` in bits 13..0,
    ``y`` in 27..14 and the polarity in 31..28.

References
----------
.. [1] expelliarmus, open-neuromorphic (github.com/open-neuromorphic/expelliarmus), version 1.1.
.. [2] Prophesee, Metavision SDK documentation, "Event Data Formats": EVT 2.0, EVT 3.0 and DAT
   (docs.prophesee.ai, data formats pages).

Examples
--------
>>> import numpy as np, tempfile, os
>>> from fsdvs_hw.sensor.eventfiles.eventfile import EventFile
>>> ev = EventFile(np.array([5, 70, 9000]), np.array([1, 2, 3]), np.array([4, 5, 6]),
...                np.array([1, -1, 1], dtype=np.int8), 1280, 720)
>>> path = os.path.join(tempfile.mkdtemp(), "rec.raw")
>>> _ = write_prophesee(path, ev, encoding="evt3")
>>> back = read_prophesee(path)
>>> back.t_us.tolist(), back.width, back.metadata["format"]
([5, 70, 9000], 1280, 'evt3')
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError, ToolMissingError
from ...limits import check_allocation
from ...paths import write_output
from .eventfile import EVENT_BYTES, EventColumnsCheck, EventFile, checked_columns, field_error

__all__ = ["ENCODINGS", "decode_evt3", "read_prophesee", "write_prophesee"]

#: encodings -> file suffix
ENCODINGS: dict[str, str] = {"evt2": ".raw", "evt3": ".raw", "dat": ".dat"}
_WORD_BYTES = {"evt2": 4, "evt3": 2, "dat": 8}
_DAT_CD_TYPE, _DAT_CD_SIZE = 0x0C, 8
_DAT_TYPES = (0x00, 0x0C)  # TD (older ATIS files, and expelliarmus's writer) and CD: the same 8-byte event
_EVT3_TIME_LIMIT_US = 1 << 24
_EVT2_TIME_LIMIT_US = 1 << 34
_MAX_HEADER_BYTES = 1 << 20


def _wizard(encoding: str) -> Any:
    try:
        from expelliarmus import Wizard  # type: ignore[import-untyped]
    except ImportError:
        raise ToolMissingError(
            "Prophesee RAW/DAT files need expelliarmus: pip install 'fsdvs_hw[eventfiles]' "
            "(or pip install expelliarmus)"
        ) from None
    return Wizard(encoding=encoding)


# ---------------------------------------------------------------------------- header
def _parse_header(path: Path, data: bytes) -> tuple[dict[str, str], int]:
    """The ``% key value`` header lines of a RAW or DAT file and the body's byte offset."""
    header: dict[str, str] = {}
    pos = 0
    while pos < len(data) and data[pos : pos + 1] == b"%":
        end = data.find(b"\n", pos)
        if end < 0 or end > _MAX_HEADER_BYTES:
            raise field_error(path, "header", f"header line at byte {pos} does not end (truncated file?)")
        line = data[pos + 1 : end].decode("ascii", "replace").strip()
        pos = end + 1
        if line == "end":
            break
        key, _, value = line.partition(" ")
        header[key.lower()] = value.strip()
    return header, pos


def _geometry(path: Path, header: dict[str, str]) -> tuple[int | None, int | None]:
    """(width, height) from ``% format ...;width=W;height=H``, ``% geometry WxH`` or DAT's lines."""
    fmt = dict(kv.split("=", 1) for kv in header.get("format", "").split(";")[1:] if "=" in kv)
    w, h = fmt.get("width"), fmt.get("height")
    if (w is None or h is None) and "geometry" in header:
        w, _, h = header["geometry"].partition("x")
    w, h = w or header.get("width"), h or header.get("height")
    try:
        return (int(w) if w else None), (int(h) if h else None)
    except ValueError:
        raise field_error(path, "header geometry", f"width {w!r} / height {h!r} are not integers") from None


def _raw_encoding(path: Path, header: dict[str, str]) -> str:
    fmt = header.get("format", "").split(";")[0].strip().upper()
    if fmt in ("EVT2", "EVT21", "EVT3"):
        if fmt == "EVT21":
            raise field_error(path, "header format", "EVT 2.1 is not supported; expected EVT2 or EVT3")
        return fmt.lower()
    evt = header.get("evt", "")
    if evt.startswith("2"):
        return "evt2"
    if evt.startswith("3"):
        return "evt3"
    raise field_error(
        path,
        "header",
        "no '% evt 2.0|3.0' or '% format EVT2|EVT3' line: not a Prophesee RAW file (expected EVT 2.0 or EVT 3.0)",
    )


# ---------------------------------------------------------------------------- EVT 3.0 decoder
_EVT3_DTYPE = np.dtype([("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("p", "u1")])


def _forward_fill(is_set: np.ndarray, values: np.ndarray, initial: int = 0) -> np.ndarray:
    """At each word, the value of the last word (at or before it) where ``is_set``; ``initial`` before any."""
    idx = np.where(is_set, np.arange(is_set.size), -1)
    np.maximum.accumulate(idx, out=idx)
    out = np.where(idx >= 0, values[np.maximum(idx, 0)], initial)
    return out.astype(np.int64)


def decode_evt3(words: np.ndarray, *, path: str | Path = "(memory)") -> np.ndarray:
    """Decode EVT 3.0 words (little-endian uint16) to events (structured ``t, x, y, p``).

    Follows Prophesee's EVT 3.0 description [2]_: ``EVT_ADDR_Y`` (0x0), ``EVT_ADDR_X`` (0x2),
    ``VECT_BASE_X`` (0x3), ``VECT_12`` (0x4), ``VECT_8`` (0x5), ``EVT_TIME_LOW`` (0x6),
    ``EVT_TIME_HIGH`` (0x8); other types (triggers, ``OTHERS``, ``CONTINUED``) carry no CD event
    and are skipped. Time = ``TIME_HIGH << 12 | TIME_LOW``, 24 bits, unwrapped (+2**24) where
    ``TIME_HIGH`` decreases. Events before the first ``TIME_HIGH`` or ``ADDR_Y`` word are dropped
    (a stream starts with them).

    Examples
    --------
    >>> w = np.array([0x8001, 0x6004, 0x0007, 0x2805], dtype="<u2")  # t = 4096 + 4, y = 7, ON at x = 5
    >>> decode_evt3(w)[["t", "x", "y", "p"]].tolist()
    [(4100, 5, 7, 1)]
    """
    w = np.asarray(words, dtype=np.uint16).astype(np.int64)
    typ = w >> 12
    val = w & 0xFFF
    is_th, is_tl, is_y = typ == 0x8, typ == 0x6, typ == 0x0
    th = _forward_fill(is_th, val, -1)
    tl = _forward_fill(is_tl, val)
    # unwrap the 24-bit clock: each decrease of TIME_HIGH is one 2**24 µs turn
    th_seq = val[is_th]
    turns = np.zeros(th_seq.size, dtype=np.int64)
    if th_seq.size > 1:
        turns[1:] = np.cumsum(np.diff(th_seq) < 0)
    turn = _forward_fill(is_th, _scatter(w.size, is_th, turns))
    t = (turn << 24) | (np.maximum(th, 0) << 12) | tl
    y = _forward_fill(is_y, val & 0x7FF, -1)
    valid = (th >= 0) & (y >= 0)
    # single events
    single = (typ == 0x2) & valid
    # vectors: VECT_BASE_X sets x and polarity; each VECT_12 / VECT_8 covers 12 / 8 columns from it
    is_base = typ == 0x3
    is_vec = (typ == 0x4) | (typ == 0x5)
    width = np.where(typ == 0x4, 12, np.where(typ == 0x5, 8, 0))
    base_x = _forward_fill(is_base, val & 0x7FF, -1)
    base_pol = _forward_fill(is_base, (val >> 11) & 1)
    consumed = np.cumsum(width) - width  # columns covered by vectors before this word
    since_base = consumed - _forward_fill(is_base, consumed)
    vec = is_vec & valid & (base_x >= 0)
    vi = np.flatnonzero(vec)
    bits = np.arange(12)
    mask = ((val[vi, None] >> bits) & 1).astype(bool) & (bits < width[vi, None])
    vec_word, vec_bit = np.nonzero(mask)
    si = np.flatnonzero(single)
    order_word = np.concatenate([si, vi[vec_word]])
    order_bit = np.concatenate([np.zeros(si.size, np.int64), vec_bit])
    xs = np.concatenate([val[si] & 0x7FF, base_x[vi][vec_word] + since_base[vi][vec_word] + vec_bit])
    ps = np.concatenate([(val[si] >> 11) & 1, base_pol[vi][vec_word]])
    src = np.concatenate([si, vi[vec_word]])
    order = np.lexsort((order_bit, order_word))
    out = np.empty(order.size, dtype=_EVT3_DTYPE)
    out["t"] = t[src[order]]
    out["x"] = xs[order]
    out["y"] = y[src[order]]
    out["p"] = ps[order]
    if out.size and int(out["x"].max()) > 0x7FF:
        raise field_error(
            Path(path), "x", f"vector event at column {int(out['x'].max())} beyond EVT 3.0's 2048 columns"
        )
    return out


def _scatter(n: int, where: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.zeros(n, dtype=np.int64)
    out[np.flatnonzero(where)] = values
    return out


# ---------------------------------------------------------------------------- read
def read_prophesee(path: str | Path, *, width: int | None = None, height: int | None = None) -> EventFile:
    """Read a Prophesee RAW (EVT 2.0 / 3.0, from the header) or DAT file into an :class:`EventFile`.

    Parameters
    ----------
    path : str or Path
        ``.raw`` or ``.dat`` file.
    width, height : int, optional
        Sensor size (pixels) where the header has no geometry; the header wins otherwise (a
        mismatch is an error).

    Returns
    -------
    EventFile
        Times in µs, polarity ±1, ``metadata`` with ``format`` and the header's lines.

    Raises
    ------
    InputError
        Missing file, no Prophesee header, a body that is not a whole number of words (truncated:
        the byte offset is named), an event outside the sensor or times that decrease.
    ToolMissingError
        expelliarmus is not installed.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"event file {str(p)!r} does not exist")
    suffix = p.suffix.lower()
    if suffix not in (".raw", ".dat"):
        raise InputError(f"event file {str(p)!r}: suffix {suffix!r} is not a Prophesee file (.raw EVT2/EVT3, .dat)")
    with open(p, "rb") as fh:
        head = fh.read(_MAX_HEADER_BYTES + 1)
    header, body = _parse_header(p, head)
    size = p.stat().st_size
    if suffix == ".raw":
        encoding = _raw_encoding(p, header)
    else:
        encoding = "dat"
        if not header:
            raise field_error(p, "header", "no '%' header lines: not a Prophesee DAT file")
        if size < body + 2:
            raise field_error(
                p,
                "event type",
                f"file ends at byte {size}, before the event type and size bytes at offset {body} (truncated DAT file)",
            )
        etype, esize = head[body], head[body + 1]
        if etype not in _DAT_TYPES or esize != _DAT_CD_SIZE:
            raise field_error(
                p,
                "event type",
                f"type 0x{etype:02X} size {esize} at offset {body}; expected CD events "
                f"(type 0x0C, or 0x00 for older TD files, size {_DAT_CD_SIZE})",
            )
        body += 2
    word = _WORD_BYTES[encoding]
    if (size - body) % word:
        cut = size - (size - body) % word
        raise field_error(
            p,
            "(body)",
            f"{encoding.upper()} body of {size - body} bytes from offset {body} is not a whole "
            f"number of {word}-byte words: the last word at offset {cut} is cut (truncated file)",
        )
    hw, hh = _geometry(p, header)
    for name, given, found in (("width", width, hw), ("height", height, hh)):
        if given is not None and found is not None and int(given) != found:
            raise InputError(f"event file {str(p)!r}: {name}={given} given, the header says {found}")
    w, h = hw or width, hh or height
    n_max = (size - body) // word
    check_allocation(f"event file {str(p)!r}: up to {n_max} events", n_max * (EVENT_BYTES + 16))
    arr: np.ndarray | None
    if encoding == "evt3":
        arr = decode_evt3(np.fromfile(p, dtype="<u2", offset=body), path=p)
    else:
        arr = _wizard(encoding).read(p) if n_max else None
    if arr is None:
        if n_max:
            raise field_error(
                p,
                "(body)",
                f"expelliarmus could not decode the {encoding.upper()} body at offset {body} (corrupt or foreign file)",
            )
        arr = np.zeros(0, dtype=[("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("p", "u1")])
    t, x, y, pol = (np.ascontiguousarray(arr[k]) for k in ("t", "x", "y", "p"))
    if w is None:
        w = int(x.max()) + 1 if x.size else 1
    if h is None:
        h = int(y.max()) + 1 if y.size else 1
    names = {"t": "t (µs)", "x": "x", "y": "y", "p": "polarity"}
    EventColumnsCheck(p, names, (0, 1)).check(t, x, y, pol, w, h)
    return EventFile(
        t.astype(np.int64),
        x.astype(np.int64),
        y.astype(np.int64),
        np.where(pol > 0, 1, -1).astype(np.int8),
        int(w),
        int(h),
        {"format": encoding, "header": header},
    )


# ---------------------------------------------------------------------------- write
def _interleave(words: list[np.ndarray], keep: list[np.ndarray], dtype: str) -> np.ndarray:
    """Per event, the words whose ``keep`` flag is set, in list order (event-major)."""
    n = words[0].size
    mask = np.stack([np.broadcast_to(k, (n,)) for k in keep], axis=1)
    stacked = np.stack([w.astype(dtype) for w in words], axis=1)
    return stacked[mask]


def _changes(v: np.ndarray) -> np.ndarray:
    out = np.ones(v.size, dtype=bool)
    out[1:] = v[1:] != v[:-1]
    return out


def _encode_evt2(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> np.ndarray:
    th = t >> 6
    time_high = (np.uint64(0x8) << np.uint64(28)) | (th.astype(np.uint64) & np.uint64(0x0FFFFFFF))
    cd = (
        (np.where(p > 0, 1, 0).astype(np.uint64) << np.uint64(28))
        | ((t & 63).astype(np.uint64) << np.uint64(22))
        | (x.astype(np.uint64) << np.uint64(11))
        | y.astype(np.uint64)
    )
    return _interleave([time_high, cd], [_changes(th), np.ones(t.size, bool)], "<u4")


def _encode_evt3(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> np.ndarray:
    th, tl = (t >> 12) & 0xFFF, t & 0xFFF
    new_th = _changes(th)
    words = [0x8000 | th, 0x6000 | tl, 0x0000 | y, 0x2000 | (np.where(p > 0, 1, 0) << 11) | x]
    keep = [new_th, new_th | _changes(tl), _changes(y), np.ones(t.size, bool)]
    return _interleave(words, keep, "<u2")


def _encode_dat(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> np.ndarray:
    out = np.empty((t.size, 2), dtype="<u4")
    out[:, 0] = t
    out[:, 1] = x.astype(np.uint32) | (y.astype(np.uint32) << 14) | (np.where(p > 0, 1, 0).astype(np.uint32) << 28)
    return out.reshape(-1)


def write_prophesee(
    path: str | Path, events: Any, *, encoding: str | None = None, width: int | None = None, height: int | None = None
) -> Path:
    """Write events as a Prophesee EVT 2.0 / EVT 3.0 RAW file or a DAT file (atomically).

    Parameters
    ----------
    path : str or Path
        ``.raw`` (EVT2 or EVT3) or ``.dat``.
    events : EventFile or EventList
        One sensor's events in non-decreasing time (an EventList's seconds are rounded to µs).
    encoding : {"evt2", "evt3", "dat"}, optional
        Default: ``"evt3"`` for ``.raw`` (the EVK4's format), ``"dat"`` for ``.dat``.
    width, height : int, optional
        Sensor size (pixels) written to the header; default the EventFile's, required for an EventList.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        Unknown encoding or suffix, pixels beyond the format's address bits (EVT 11 bits, DAT 14),
        times beyond its clock (EVT3 2**24 µs, EVT2 2**34 µs, DAT 2**32 µs) or decreasing.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    encoding = encoding or {".raw": "evt3", ".dat": "dat"}.get(suffix)
    if encoding not in ENCODINGS or ENCODINGS[encoding] != suffix:
        raise InputError(
            f"event file {str(p)!r}: encoding {encoding!r} with suffix {suffix!r}; allowed: "
            + ", ".join(f"{k} ({v})" for k, v in ENCODINGS.items())
        )
    w = width if width is not None else getattr(events, "width", None)
    h = height if height is not None else getattr(events, "height", None)
    if w is None or h is None:
        raise InputError("write_prophesee: width and height are required for an EventList")
    t, x, y, pol = checked_columns(events, int(w), int(h))
    if t.size and bool((np.diff(t) < 0).any()):
        raise InputError("write_prophesee: events must be in non-decreasing time")
    addr_limit = 1 << (14 if encoding == "dat" else 11)
    if max(int(w), int(h)) > addr_limit:
        raise InputError(f"write_prophesee: a {w}x{h} sensor exceeds {encoding.upper()}'s {addr_limit}-pixel addresses")
    t_limit = {"evt2": _EVT2_TIME_LIMIT_US, "evt3": _EVT3_TIME_LIMIT_US, "dat": 1 << 32}[encoding]
    if t.size and int(t[-1]) >= t_limit:
        raise InputError(
            f"write_prophesee: time {int(t[-1])} µs beyond {encoding.upper()}'s clock "
            f"({t_limit} µs without wrap-around)"
        )
    stamp = "1970-01-01 00:00:00"  # a fixed date: the same events give the same bytes
    if encoding == "dat":
        head = (f"% Date {stamp}\n% Version 2\n% Height {h}\n% Width {w}\n").encode() + bytes(
            [_DAT_CD_TYPE, _DAT_CD_SIZE]
        )
        body = _encode_dat(t, x, y, pol)
    else:
        fmt = encoding.upper()
        head = (
            f"% date {stamp}\n% evt {encoding[-1]}.0\n% format {fmt};height={h};width={w}\n"
            f"% geometry {w}x{h}\n% integrator_name fsdvs_hw\n% end\n"
        ).encode()
        body = (_encode_evt2 if encoding == "evt2" else _encode_evt3)(t, x, y, pol)
    return write_output(p, head + body.tobytes(), flag="path")
