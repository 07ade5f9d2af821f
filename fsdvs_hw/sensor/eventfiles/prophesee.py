"""Prophesee event files: RAW EVT 2.0, RAW EVT 3.0 and DAT (versions 1 and 2); read and written to spec.

Reading decodes all three with vectorised NumPy decoders written to Prophesee's published
descriptions [2]_ (:func:`decode_evt2`, :func:`decode_evt3_all`, :func:`decode_dat`): the
maintained ``expelliarmus`` library [1]_ decodes EVT 2.0 and DAT the same way but returns no
trigger events, reads a time that goes backwards in a DAT file as a clock wrap (30 → 5 µs came
back as 5 + 2**32 µs) and has no DAT version 1; its EVT 3.0 decoder (1.1.12) counts a
time-low wrap on top of the ``EVT_TIME_HIGH`` word that a conforming stream sends with it.
expelliarmus and faery (an independent encoder and decoder) are the cross-checks in the tests.
:func:`read_prophesee` first parses the ASCII header itself (the format, the DAT version, the
sensor geometry, the ``% t0`` time offset), checks that the binary body is a whole number of
words of the format, and refuses a foreign, truncated or malformed file with an
:class:`~fsdvs_hw.errors.InputError` naming the file, the field or byte offset and the format
expected. EVT 2.1 is refused (its 64-bit word order depends on the sensor, which the header
does not name). These formats are streams without an event count: a file cut exactly at a word
boundary reads as a shorter recording, and only a cut inside a word (or inside the header) is
detectable.

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
.. [1] expelliarmus, open-neuromorphic (github.com/open-neuromorphic/expelliarmus), version 1.1;
   faery (github.com/aestream/faery), version 0.7.
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

from ...errors import InputError
from ...limits import check_allocation
from ...paths import write_output
from .eventfile import (
    EVENT_BYTES,
    TRIGGER_DTYPE,
    EventColumnsCheck,
    EventFile,
    checked_columns,
    checked_file,
    field_error,
    no_triggers,
)

__all__ = [
    "ENCODINGS",
    "SIDE_LIMITS",
    "decode_dat",
    "decode_evt2",
    "decode_evt3",
    "decode_evt3_all",
    "read_prophesee",
    "write_prophesee",
]

#: encodings -> file suffix
ENCODINGS: dict[str, str] = {"evt2": ".raw", "evt3": ".raw", "dat": ".dat"}
_WORD_BYTES = {"evt2": 4, "evt3": 2, "dat": 8, "dat1": 8}
_DAT_CD_TYPE, _DAT_CD_SIZE = 0x0C, 8
_DAT_TYPES = (0x00, 0x0C)  # TD (older ATIS files, and expelliarmus's writer) and CD: the same 8-byte event
_DAT_TRIGGER_TYPE = 0x0E  # external triggers (EXT_TRIGGER)
_MAX_T0_US = 1 << 53  # the largest % t0 accepted (µs; 285 years, exact in float64)
_EVT3_TIME_LIMIT_US = 1 << 24
_EVT2_TIME_LIMIT_US = 1 << 34
_MAX_HEADER_BYTES = 1 << 20


# ---------------------------------------------------------------------------- header
def _parse_header(path: Path, data: bytes) -> tuple[dict[str, str], int]:
    """The ``% key value`` header lines of a RAW or DAT file (keys lower-cased) and the body's byte offset."""
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


#: Largest sensor side each encoding can address (pixels): EVT 11-bit addresses, DAT 2 14 bits,
#: DAT 1 9-bit x and 8-bit y.
SIDE_LIMITS: dict[str, tuple[int, int]] = {
    "evt2": (2048, 2048),
    "evt3": (2048, 2048),
    "dat": (16384, 16384),
    "dat1": (512, 256),
}


def _side(path: Path, name: str, value: Any, limit: int, encoding: str, where: str) -> int | None:
    """A declared width/height: None where absent, else an integer in [1, limit] or an InputError."""
    if value is None or value == "":
        return None
    try:
        v = int(str(value).strip())
    except ValueError:
        raise field_error(path, f"{where} {name}", f"{value!r} is not an integer") from None
    if not 1 <= v <= limit:
        raise field_error(
            path, f"{where} {name}", f"{v} pixels outside [1, {limit}], the sides {encoding.upper()} can address"
        )
    return v


def _geometry(path: Path, header: dict[str, str], encoding: str) -> tuple[int | None, int | None]:
    """(width, height) from ``% format ...;width=W;height=H``, ``% geometry WxH`` or DAT's lines,
    each checked against the encoding's address range (0 and larger sides are refused)."""
    fmt = dict(kv.split("=", 1) for kv in header.get("format", "").split(";")[1:] if "=" in kv)
    w, h = fmt.get("width"), fmt.get("height")
    if (w is None or h is None) and "geometry" in header:
        w, _, h = header["geometry"].partition("x")
    w, h = w or header.get("width"), h or header.get("height")
    lw, lh = SIDE_LIMITS[encoding]
    return _side(path, "width", w, lw, encoding, "header"), _side(path, "height", h, lh, encoding, "header")


def _raw_encoding(path: Path, header: dict[str, str]) -> str:
    fmt = header.get("format", "").split(";")[0].strip().upper()
    evt = header.get("evt", "").strip()
    if fmt in ("EVT21", "EVT2.1") or evt.startswith("2.1"):
        raise field_error(
            path,
            "header format",
            "EVT 2.1 is not supported: its 64-bit words are ordered differently by different sensors "
            "(IMX636 and GenX320) and the header does not say which; convert it to EVT 2.0 or 3.0 "
            "(metavision_file_to_raw) or read it with the Metavision SDK",
        )
    if fmt in ("EVT2", "EVT3"):
        return fmt.lower()
    if evt.startswith("2"):
        return "evt2"
    if evt.startswith("3"):
        return "evt3"
    raise field_error(
        path,
        "header",
        "no '% evt 2.0|3.0' or '% format EVT2|EVT3' line: not a Prophesee RAW file (expected EVT 2.0 or EVT 3.0)",
    )


def _dat_version(path: Path, header: dict[str, str]) -> str:
    """``"dat1"`` or ``"dat"`` (version 2) from the ``% Version`` line (absent: version 2)."""
    v = header.get("version", "2").strip()
    if v in ("1", "1.0"):
        return "dat1"
    if v in ("2", "2.0"):
        return "dat"
    raise field_error(path, "header Version", f"unsupported DAT version {v!r}; this reader reads versions 1 and 2")


def _t0(path: Path, header: dict[str, str]) -> int:
    """The ``% t0`` line (µs added to every stored time; 0 without the line)."""
    if "t0" not in header:
        return 0
    try:
        t0 = int(header["t0"])
    except ValueError:
        raise field_error(path, "header t0", f"{header['t0']!r} is not an integer (µs)") from None
    if not 0 <= t0 < _MAX_T0_US:
        raise field_error(path, "header t0", f"{t0} µs outside [0, 2**53) µs")
    return t0


# ---------------------------------------------------------------------------- decoders
_EVT3_DTYPE = np.dtype([("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("p", "u1")])


class _Decoded:
    """Decoded CD events (structured ``t, x, y, p``) and trigger events (:data:`TRIGGER_DTYPE`)."""

    def __init__(self, events: np.ndarray, triggers: np.ndarray) -> None:
        self.events, self.triggers = events, triggers


def _forward_fill(is_set: np.ndarray, values: np.ndarray, initial: int = 0) -> np.ndarray:
    """At each word, the value of the last word (at or before it) where ``is_set``; ``initial`` before any."""
    idx = np.where(is_set, np.arange(is_set.size), -1)
    np.maximum.accumulate(idx, out=idx)
    out = np.where(idx >= 0, values[np.maximum(idx, 0)], initial)
    return out.astype(np.int64)


def _unwrap(path: Path, fld: str, values: np.ndarray, bits: int, offsets: np.ndarray, unit: int) -> np.ndarray:
    """A wrapping counter of ``bits`` bits made monotonic: a fall of more than half its range is a
    wrap (one turn added); a smaller fall is time going backwards, refused naming the byte offset
    (``unit``: µs per count, for the message)."""
    v = values.astype(np.int64)
    if v.size < 2:
        return v
    d = np.diff(v)
    half = 1 << (bits - 1)
    back = np.flatnonzero((d < 0) & (d >= -half))
    if back.size:
        i = int(back[0]) + 1
        raise field_error(
            path,
            fld,
            f"time goes back from {int(v[i - 1]) * unit} to {int(v[i]) * unit} µs at byte offset "
            f"{int(offsets[i])}: times must not decrease (a {bits}-bit clock wrap falls by more than half its range)",
        )
    turns = np.concatenate([[0], np.cumsum(d < -half)])
    return v + (turns << bits)


def _refuse_before(
    path: Path, need: np.ndarray, have: np.ndarray, offsets: np.ndarray, what: str, need_what: str
) -> None:
    """Refuse the first word of ``need`` that comes before any word of ``have`` (``what`` / ``need_what``)."""
    first = int(np.argmax(have)) if have.any() else have.size
    early = np.flatnonzero(need[:first])
    if early.size:
        raise field_error(
            path,
            "(body)",
            f"{what} word at byte offset {int(offsets[early[0]])} before any {need_what}: its "
            "address or time is unknown (a corrupt or cut stream)",
        )


def decode_evt2(words: np.ndarray, *, path: str | Path = "(memory)", offset: int = 0) -> _Decoded:
    """Decode EVT 2.0 words (little-endian uint32) to CD and trigger events.

    ``CD_OFF`` (0x0) / ``CD_ON`` (0x1): time bits 5..0 in 27..22, ``x`` 21..11, ``y`` 10..0;
    ``EVT_TIME_HIGH`` (0x8): time bits 33..6 in 27..0 (a 34-bit µs clock, unwrapped: a fall of
    more than half its range is a wrap, a smaller one an error); ``EXT_TRIGGER`` (0xA): time
    bits 5..0 in 27..22, channel in 12..8, edge in bit 0; ``OTHERS`` (0xE) and ``CONTINUED``
    (0xF) carry no event. Reserved types, and CD or trigger words before the first
    ``EVT_TIME_HIGH``, are refused (:class:`~fsdvs_hw.errors.InputError` naming the byte offset,
    counted from ``offset``).

    Examples
    --------
    >>> w = np.array([0x80000001, 0x10000000 | (5 << 22) | (3 << 11) | 7], dtype="<u4")
    >>> decode_evt2(w).events[["t", "x", "y", "p"]].tolist()
    [(69, 3, 7, 1)]
    """
    p = Path(path)
    w = np.asarray(words, dtype=np.uint32).astype(np.int64)
    typ = w >> 28
    offsets = offset + 4 * np.arange(w.size)
    bad = ~np.isin(typ, (0x0, 0x1, 0x8, 0xA, 0xE, 0xF))
    if bad.any():
        i = int(np.argmax(bad))
        raise field_error(p, "(body)", f"reserved EVT 2.0 word type 0x{int(typ[i]):X} at byte offset {int(offsets[i])}")
    is_th = typ == 0x8
    is_cd, is_trig = typ <= 0x1, typ == 0xA
    _refuse_before(p, is_cd | is_trig, is_th, offsets, "CD or EXT_TRIGGER", "EVT_TIME_HIGH")
    th_vals = _unwrap(p, "EVT_TIME_HIGH", w[is_th] & 0x0FFFFFFF, 28, offsets[is_th], 64)
    th = _forward_fill(is_th, _scatter(w.size, is_th, th_vals))
    t = (th << 6) | ((w >> 22) & 0x3F)
    ev = np.empty(int(is_cd.sum()), dtype=_EVT3_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = t[is_cd], (w[is_cd] >> 11) & 0x7FF, w[is_cd] & 0x7FF, typ[is_cd]
    tr = np.empty(int(is_trig.sum()), dtype=TRIGGER_DTYPE)
    tr["t_us"], tr["id"], tr["value"] = t[is_trig], (w[is_trig] >> 8) & 0x1F, w[is_trig] & 1
    return _Decoded(ev, tr)


def decode_evt3(words: np.ndarray, *, path: str | Path = "(memory)", offset: int = 0) -> np.ndarray:
    """Decode EVT 3.0 words (little-endian uint16) to CD events (structured ``t, x, y, p``).

    :func:`decode_evt3_all` with the trigger events left out.

    Examples
    --------
    >>> w = np.array([0x8001, 0x6004, 0x0007, 0x2805], dtype="<u2")  # t = 4096 + 4, y = 7, ON at x = 5
    >>> decode_evt3(w)[["t", "x", "y", "p"]].tolist()
    [(4100, 5, 7, 1)]
    """
    return decode_evt3_all(words, path=path, offset=offset).events


def decode_evt3_all(words: np.ndarray, *, path: str | Path = "(memory)", offset: int = 0) -> _Decoded:
    """Decode EVT 3.0 words (little-endian uint16) to CD events and trigger events.

    Follows Prophesee's EVT 3.0 description [2]_: ``EVT_ADDR_Y`` (0x0), ``EVT_ADDR_X`` (0x2),
    ``VECT_BASE_X`` (0x3), ``VECT_12`` (0x4), ``VECT_8`` (0x5), ``EVT_TIME_LOW`` (0x6),
    ``EVT_TIME_HIGH`` (0x8), ``EXT_TRIGGER`` (0xA: edge in bit 0, channel in 11..8, at the
    current time); ``CONTINUED_4`` (0x7), ``OTHERS`` (0xE) and ``CONTINUED_12`` (0xF) carry no
    event. Time = ``TIME_HIGH << 12 | TIME_LOW``, 24 bits, unwrapped: a fall of ``TIME_HIGH``
    by more than half its range is a 2**24 µs turn, a smaller fall is time going backwards
    (refused). Refused with an :class:`~fsdvs_hw.errors.InputError` naming the byte offset
    (counted from ``offset``): reserved word types; an event or trigger before the first
    ``EVT_TIME_HIGH``; an event before the first ``EVT_ADDR_Y``; a vector word before any
    ``VECT_BASE_X``; vector events beyond column 2047.
    """
    p = Path(path)
    w = np.asarray(words, dtype=np.uint16).astype(np.int64)
    typ = w >> 12
    val = w & 0xFFF
    offsets = offset + 2 * np.arange(w.size)
    bad = ~np.isin(typ, (0x0, 0x2, 0x3, 0x4, 0x5, 0x6, 0x7, 0x8, 0xA, 0xE, 0xF))
    if bad.any():
        i = int(np.argmax(bad))
        raise field_error(p, "(body)", f"reserved EVT 3.0 word type 0x{int(typ[i]):X} at byte offset {int(offsets[i])}")
    is_th, is_tl, is_y = typ == 0x8, typ == 0x6, typ == 0x0
    is_base, is_vec, is_trig = typ == 0x3, (typ == 0x4) | (typ == 0x5), typ == 0xA
    single = typ == 0x2
    _refuse_before(p, single | is_base | is_vec | is_trig, is_th, offsets, "event or trigger", "EVT_TIME_HIGH")
    _refuse_before(p, single | is_base | is_vec, is_y, offsets, "event", "EVT_ADDR_Y")
    _refuse_before(p, is_vec, is_base, offsets, "VECT_12 / VECT_8", "VECT_BASE_X")
    th_vals = _unwrap(p, "EVT_TIME_HIGH", val[is_th], 12, offsets[is_th], 4096)
    th = _forward_fill(is_th, _scatter(w.size, is_th, th_vals))
    t = (th << 12) | _forward_fill(is_tl, val)
    y = _forward_fill(is_y, val & 0x7FF)
    # vectors: VECT_BASE_X sets x and polarity; each VECT_12 / VECT_8 covers 12 / 8 columns from it
    width = np.where(typ == 0x4, 12, np.where(typ == 0x5, 8, 0))
    base_x = _forward_fill(is_base, val & 0x7FF)
    base_pol = _forward_fill(is_base, (val >> 11) & 1)
    consumed = np.cumsum(width) - width  # columns covered by vectors before this word
    since_base = consumed - _forward_fill(is_base, consumed)
    vi = np.flatnonzero(is_vec)
    bits = np.arange(12)
    mask = ((val[vi, None] >> bits) & 1).astype(bool) & (bits < width[vi, None])
    vec_word, vec_bit = np.nonzero(mask)
    si = np.flatnonzero(single)
    xs = np.concatenate([val[si] & 0x7FF, base_x[vi][vec_word] + since_base[vi][vec_word] + vec_bit])
    ps = np.concatenate([(val[si] >> 11) & 1, base_pol[vi][vec_word]])
    src = np.concatenate([si, vi[vec_word]])
    order = np.lexsort((np.concatenate([np.zeros(si.size, np.int64), vec_bit]), src))
    out = np.empty(order.size, dtype=_EVT3_DTYPE)
    out["t"], out["x"], out["y"], out["p"] = t[src[order]], xs[order], y[src[order]], ps[order]
    if out.size and int(out["x"].max()) > 0x7FF:
        raise field_error(p, "x", f"vector event at column {int(out['x'].max())} beyond EVT 3.0's 2048 columns")
    tr = np.empty(int(is_trig.sum()), dtype=TRIGGER_DTYPE)
    tr["t_us"], tr["id"], tr["value"] = t[is_trig], (val[is_trig] >> 8) & 0xF, val[is_trig] & 1
    return _Decoded(out, tr)


def decode_dat(
    records: np.ndarray, *, version: int = 2, triggers: bool = False, path: str | Path = "(memory)", offset: int = 0
) -> _Decoded:
    """Decode DAT records (little-endian uint32 pairs: time µs, address) to CD or trigger events.

    Version 2: ``x`` in bits 13..0, ``y`` in 27..14, polarity in 31..28; version 1 (older ATIS
    files): ``x`` in 8..0, ``y`` in 16..9, polarity in bit 17. A trigger file (event type 0x0E)
    carries the channel where ``x`` is and the edge where the polarity is (as faery writes
    it). The 32-bit µs time is unwrapped: a fall of more than 2**31 µs is a wrap (+2**32), a
    smaller fall (30 → 5 µs) is time going backwards, refused naming the byte offset.

    Examples
    --------
    >>> r = np.array([[10, 3 | (4 << 14) | (1 << 28)], [4294967290, 1], [6, 2]], dtype="<u4")
    >>> decode_dat(r).events[["t", "x", "p"]].tolist()
    [(10, 3, 1), (4294967290, 1, 0), (4294967302, 2, 0)]
    """
    p = Path(path)
    r = np.asarray(records, dtype=np.uint32).reshape(-1, 2)
    offsets = offset + 8 * np.arange(r.shape[0])
    t = _unwrap(p, "t (µs)", r[:, 0], 32, offsets, 1)
    a = r[:, 1].astype(np.int64)
    if version == 1:
        x, y, pol = a & 0x1FF, (a >> 9) & 0xFF, (a >> 17) & 1
    else:
        x, y, pol = a & 0x3FFF, (a >> 14) & 0x3FFF, (a >> 28) & 0xF
    if triggers:
        tr = np.empty(t.size, dtype=TRIGGER_DTYPE)
        tr["t_us"], tr["id"], tr["value"] = t, x, np.minimum(pol, 1)
        return _Decoded(np.zeros(0, _EVT3_DTYPE), tr)
    ev = np.empty(t.size, dtype=_EVT3_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = t, x, y, pol
    return _Decoded(ev, no_triggers())


def _scatter(n: int, where: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.zeros(n, dtype=np.int64)
    out[np.flatnonzero(where)] = values
    return out


# ---------------------------------------------------------------------------- read
def _dat_body(p: Path, head: bytes, body: int, size: int, header: dict[str, str]) -> tuple[str, bool, int]:
    """(encoding, trigger file, body offset) of a DAT file after its header: the version and the
    event type and size bytes checked."""
    if not header:
        raise field_error(p, "header", "no '%' header lines: not a Prophesee DAT file")
    encoding = _dat_version(p, header)
    if size < body + 2:
        raise field_error(
            p,
            "event type",
            f"file ends at byte {size}, before the event type and size bytes at offset {body} (truncated DAT file)",
        )
    etype, esize = head[body], head[body + 1]
    if etype not in (*_DAT_TYPES, _DAT_TRIGGER_TYPE) or esize != _DAT_CD_SIZE:
        raise field_error(
            p,
            "event type",
            f"type 0x{etype:02X} size {esize} at offset {body}: unsupported; this reader reads CD events "
            f"(type 0x0C, or 0x00 for older TD files) and triggers (0x0E), size {_DAT_CD_SIZE}",
        )
    return encoding, etype == _DAT_TRIGGER_TYPE, body + 2


#: Words decoded at a time: the decoders' temporaries (about 150 B per word, up to ~800 B for a
#: chunk of EVT 3.0 vectors with every bit set) stay bounded whatever the file's size; the state
#: a stream carries (time, row, vector base, clock turns) is handed from chunk to chunk.
CHUNK_WORDS = 1 << 18


def _wraps(raw: np.ndarray, bits: int) -> int:
    """Clock turns in a sequence of raw ``bits``-bit counter values (falls of more than half the range)."""
    return int((np.diff(raw.astype(np.int64)) < -(1 << (bits - 1))).sum()) if raw.size > 1 else 0


def _last(w: np.ndarray, is_type: np.ndarray) -> np.ndarray:
    """The last word of ``w`` where ``is_type`` (empty if none)."""
    i = np.flatnonzero(is_type)
    return w[i[-1:]]


class _Stream:
    """Decodes a Prophesee body chunk by chunk, carrying the stream's state across chunks."""

    def __init__(self, p: Path, encoding: str, trigger_file: bool) -> None:
        self.p, self.encoding, self.trigger_file = p, encoding, trigger_file
        self.prefix = np.zeros(0, dtype={"evt2": "<u4", "evt3": "<u2"}.get(encoding, "<u4"))
        self.t_base = 0  # µs added for the clock turns of earlier chunks
        self.base_beyond = False  # EVT 3.0: the vector base has run past column 2047

    def step(self, chunk: np.ndarray, offset: int) -> _Decoded:
        w = np.concatenate([self.prefix, chunk])
        start = offset - self.prefix.nbytes
        if self.encoding == "evt2":
            dec = decode_evt2(w, path=self.p, offset=start)
            th = _last(w, (w >> 28) == 0x8)
            turns = _wraps(w[(w >> 28) == 0x8] & 0x0FFFFFFF, 28) << 34
            self.prefix = th
        elif self.encoding == "evt3":
            dec = self._evt3(w, start)
            turns = _wraps(w[(w >> 12) == 0x8] & 0xFFF, 12) << 24
        else:
            r = w.reshape(-1, 2)
            dec = decode_dat(
                r, version=1 if self.encoding == "dat1" else 2, triggers=self.trigger_file, path=self.p, offset=start
            )
            if self.prefix.size:  # the carried record was decoded again: drop it
                dec = _Decoded(dec.events[1:], dec.triggers[1:] if self.trigger_file else dec.triggers)
            turns = _wraps(r[:, 0], 32) << 32
            self.prefix = r[-1].copy()
        dec.events["t"] += self.t_base
        dec.triggers["t_us"] += self.t_base
        self.t_base += turns
        return dec

    def _evt3(self, w: np.ndarray, start: int) -> _Decoded:
        typ = w >> 12
        is_base, is_vec = typ == 0x3, (typ == 0x4) | (typ == 0x5)
        if self.base_beyond and is_vec.any() and (not is_base.any() or np.argmax(is_vec) < np.argmax(is_base)):
            i = int(np.argmax(is_vec))
            raise field_error(
                self.p, "x", f"vector word at byte offset {start + 2 * i} runs beyond EVT 3.0's 2048 columns"
            )
        dec = decode_evt3_all(w, path=self.p, offset=start)
        keep = [_last(w, typ == k) for k in (0x8, 0x6, 0x0)]
        self.base_beyond = False
        if is_base.any():
            b = int(np.flatnonzero(is_base)[-1])
            after = typ[b + 1 :]
            x = int(w[b] & 0x7FF) + 12 * int((after == 0x4).sum()) + 8 * int((after == 0x5).sum())
            if x <= 0x7FF:
                keep.append(np.array([(int(w[b]) & 0xF800) | x], dtype="<u2"))
            else:
                self.base_beyond = True
        self.prefix = np.concatenate(keep).astype("<u2")
        return dec


def _decode_body(p: Path, encoding: str, trigger_file: bool, body: int, size: int) -> _Decoded:
    """The whole body decoded chunk by chunk (:data:`CHUNK_WORDS`), the events' memory checked as they grow."""
    word = _WORD_BYTES[encoding]
    n = (size - body) // word
    dtype, per_word = {"evt2": ("<u4", 1), "evt3": ("<u2", 1)}.get(encoding, ("<u4", 2))
    stream = _Stream(p, encoding, trigger_file)
    events, triggers, total = [], [], 0
    for i in range(0, n, CHUNK_WORDS):
        k = min(CHUNK_WORDS, n - i)
        chunk = np.fromfile(p, dtype=dtype, count=k * per_word, offset=body + i * word)
        if chunk.size != k * per_word:
            raise field_error(p, "(body)", f"file shrank while being read (at byte offset {body + i * word})")
        dec = stream.step(chunk, body + i * word)
        total += dec.events.size + dec.triggers.size
        check_allocation(f"event file {str(p)!r}: {total} events decoded so far", total * (EVENT_BYTES + 13))
        events.append(dec.events)
        triggers.append(dec.triggers)
    if not events:
        return _Decoded(np.zeros(0, _EVT3_DTYPE), no_triggers())
    return _Decoded(np.concatenate(events), np.concatenate(triggers))


def read_prophesee(path: str | Path, *, width: int | None = None, height: int | None = None) -> EventFile:
    """Read a Prophesee RAW (EVT 2.0 / 3.0, from the header) or DAT (version 1 or 2) file.

    The header's ``% t0`` line (written by faery and other encoders that store times from the
    first event) is applied: every time comes back as stored + ``t0`` µs, the recording's own
    clock (``metadata["t0_us"]`` says how much was added). Trigger events (``EXT_TRIGGER``; a DAT
    file of event type 0x0E) come back in :attr:`EventFile.triggers`, beside the CD events.

    Parameters
    ----------
    path : str or Path
        ``.raw`` or ``.dat`` file.
    width, height : int, optional
        Sensor size (pixels) where the header has no geometry; the header wins otherwise (a
        mismatch is an error). Without either, the largest pixel + 1.

    Returns
    -------
    EventFile
        Times in µs, polarity ±1, ``metadata`` with ``format`` (``evt2``, ``evt3``, ``dat``,
        ``dat1``), ``t0_us`` and the header's lines; ``triggers``.

    Raises
    ------
    InputError
        Missing file, a directory or a link loop; no Prophesee header; EVT 2.1 or a DAT version
        other than 1 and 2 (unsupported); a declared width/height of 0 or beyond what the
        encoding addresses; a body that is not a whole number of words (truncated: the byte
        offset is named); a reserved word type; events before the stream's time or address;
        time going backwards (told apart from a clock wrap); an event outside the sensor.
    """
    p = checked_file(path)
    suffix = p.suffix.lower()
    if suffix not in (".raw", ".dat"):
        raise InputError(f"event file {str(p)!r}: suffix {suffix!r} is not a Prophesee file (.raw EVT2/EVT3, .dat)")
    with open(p, "rb") as fh:
        head = fh.read(_MAX_HEADER_BYTES + 1)
    header, body = _parse_header(p, head)
    size = p.stat().st_size
    trigger_file = False
    if suffix == ".raw":
        encoding = _raw_encoding(p, header)
    else:
        encoding, trigger_file, body = _dat_body(p, head, body, size, header)
    word = _WORD_BYTES[encoding]
    if (size - body) % word:
        cut = size - (size - body) % word
        raise field_error(
            p,
            "(body)",
            f"{encoding.upper()} body of {size - body} bytes from offset {body} is not a whole "
            f"number of {word}-byte words: the last word at offset {cut} is cut (truncated file)",
        )
    hw, hh = _geometry(p, header, encoding)
    lw, lh = SIDE_LIMITS[encoding]
    width, height = _side(p, "width", width, lw, encoding, "given"), _side(p, "height", height, lh, encoding, "given")
    for name, given, found in (("width", width, hw), ("height", height, hh)):
        if given is not None and found is not None and given != found:
            raise InputError(f"event file {str(p)!r}: {name}={given} given, the header says {found}")
    t0 = _t0(p, header)
    decoded = _decode_body(p, encoding, trigger_file, body, size)
    arr = decoded.events
    t, x, y, pol = (np.ascontiguousarray(arr[k]) for k in ("t", "x", "y", "p"))
    t = t.astype(np.int64) + t0
    w = hw or width or (int(x.max()) + 1 if x.size else 1)
    h = hh or height or (int(y.max()) + 1 if y.size else 1)
    names = {"t": "t (µs)", "x": "x", "y": "y", "p": "polarity"}
    EventColumnsCheck(p, names, (0, 1)).check(t, x, y, pol, w, h)
    triggers = decoded.triggers
    triggers["t_us"] += t0
    return EventFile(
        t,
        x.astype(np.int64),
        y.astype(np.int64),
        np.where(pol > 0, 1, -1).astype(np.int8),
        int(w),
        int(h),
        {"format": encoding, "t0_us": t0, "header": header},
        triggers,
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
