"""Fingerprints: short, stable names for "everything that decides a result".

A store, a cache or a resumable run keys its entries by a fingerprint of the inputs that decide
them, so that a changed input misses the cache and an unchanged one finds it again after a
restart. Every such key in fsdvs_hw is made here, in one way: the SHA-1 of a canonical text.

- :func:`fingerprint` hashes a JSON-able value through its canonical JSON (``sort_keys=True``,
  anything JSON cannot encode written as ``str(value)``), so dict order never changes a key.
- :func:`text_fingerprint` hashes text or bytes as they are (a key built from another key, a
  slug that must stay short, an array's bytes).

Both return lowercase hex, cut to ``length`` characters when given (the store's keys use 16 or
20 characters: 64 or 80 bits, where a collision among a sweep's few thousand entries has odds
below 1e-11). SHA-1 serves here as a content name, not as a security measure. The strings these
functions return are on disk in stores written by earlier versions: they must never change.

Example
-------
>>> from fsdvs_hw.fingerprints import fingerprint, text_fingerprint
>>> fingerprint({"b": 1, "a": [1.0, 2]}, length=16) == fingerprint({"a": [1.0, 2], "b": 1}, length=16)
True
>>> len(text_fingerprint("design.toml", length=8))
8
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

__all__ = ["fingerprint", "text_fingerprint"]


def text_fingerprint(data: str | bytes, *, length: int | None = None) -> str:
    """SHA-1 of text (UTF-8) or bytes, as lowercase hex, cut to ``length`` characters.

    Parameters
    ----------
    data : str or bytes
        What to name. Text is encoded as UTF-8; lone surrogates (from undecodable file names)
        are kept with ``surrogatepass``.
    length : int, optional
        How many hex characters to keep (1–40); the whole 40-character digest when omitted.

    Returns
    -------
    str
        The hex digest, or its first ``length`` characters.

    Raises
    ------
    ValueError
        ``length`` outside 1–40.

    Example
    -------
    >>> text_fingerprint("abc")
    'a9993e364706816aba3e25717850c26c9cd0d89d'
    """
    if length is not None and not 1 <= length <= 40:
        raise ValueError(f"text_fingerprint: length={length}; allowed: 1 to 40 hex characters")
    raw = data if isinstance(data, bytes) else data.encode("utf-8", "surrogatepass")
    return hashlib.sha1(raw).hexdigest()[:length]


def fingerprint(value: Any, *, length: int | None = None) -> str:
    """SHA-1 of a value's canonical JSON, as lowercase hex, cut to ``length`` characters.

    Parameters
    ----------
    value : Any
        A JSON-able value (dicts, lists, numbers, strings, None). Keys are sorted, so key order
        never changes the fingerprint; anything JSON cannot encode (a path, a numpy scalar) is
        written as ``str(value)``.
    length : int, optional
        How many hex characters to keep (1–40); the whole digest when omitted.

    Returns
    -------
    str
        The hex digest of ``json.dumps(value, sort_keys=True, default=str)``, or its first
        ``length`` characters.

    Example
    -------
    >>> fingerprint({"threshold": 0.2, "task": "flow"}, length=16)
    '448a1b4601ed82f9'
    """
    return text_fingerprint(json.dumps(value, sort_keys=True, default=str), length=length)
