"""A bounded disk cache of decoded clips: decode a video or frame sequence once, read it back after.

Decoding dominates the cost of a user dataset's clip (an ffmpeg process per video, a PNG decode
per frame; ``docs/your_data.md``), and an exploration decodes every scored clip once per
realisation and task, training once per run. A :class:`ClipDiskCache` keeps the decoded arrays
(linear-luminance frames, a resized label mask, the container's frame rate) in one folder so a
second pass reads them instead.

Key
    SHA-256 of the clip's source files — each one's resolved path, size in bytes and modification
    time in ns — and every decode option (reader, frames per clip, stride, start frame, size,
    frame rate, transfer function, classes, …) plus :data:`CACHE_FORMAT`. A file that changes
    (new size or mtime) or another option gives another key, so a stale entry is never read;
    it ages out.
Entries
    ``<key>.clip``: a header line ``fsdvs-clip-cache <CACHE_FORMAT> <sha256 of the payload>``
    followed by an uncompressed ``.npz`` payload (float64 arrays as decoded: a hit returns
    bit-identical arrays) that also holds its key. Written atomically (a temporary file in the
    folder renamed over the name, :func:`fsdvs_hw.paths.write_output`), so a reader never sees a
    partial entry; an entry that is not exactly what was written (a wrong digest, a truncated or
    garbled payload, another key, a symbolic link) is never trusted: it is deleted, counted in
    :attr:`ClipDiskCache.rejected` and the clip decoded and written again.
Bound
    After every write the folder's entries are summed and the least recently used (oldest
    modification time; a hit touches its entry) are deleted until the total is at most
    ``max_mb``. An entry larger than the whole cap is not written. Only files named like an
    entry (64 hex digits + ``.clip``) and this module's temporary files older than an hour are
    ever deleted, whatever else the folder holds. Several processes (exploration workers) may
    share one folder: writes are atomic and a file deleted while another process reads it stays
    readable to that process (POSIX).

Example
-------
>>> import tempfile, numpy as np
>>> cache = ClipDiskCache(tempfile.mkdtemp(), max_mb=1.0)
>>> key = cache.key([], {"reader": "demo", "size": [2, 2]})
>>> calls = []
>>> def decode():
...     calls.append(1)
...     return {"frames": np.ones((2, 2, 2))}
>>> a = cache.decoded(key, decode); b = cache.decoded(key, decode)
>>> len(calls), bool((a["frames"] == b["frames"]).all()), cache.hits
(1, True, 1)
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import re
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..paths import npz_bytes, write_output

__all__ = ["CACHE_FORMAT", "ENTRY_SUFFIX", "ClipDiskCache"]

#: Version of the entry layout and of the decoders' output; part of every key (a change re-decodes).
CACHE_FORMAT: int = 1
#: File ending of a cache entry.
ENTRY_SUFFIX: str = ".clip"

_ENTRY = re.compile(r"^[0-9a-f]{64}" + re.escape(ENTRY_SUFFIX) + "$")
_TEMP = re.compile(r"^\.[0-9a-f]{40}\..+\.tmp$")  # write_output's temporary names of an entry
_STALE_TEMP_S = 3600.0
_MAGIC = b"fsdvs-clip-cache"
_KEY_ARRAY = "__key__"


class ClipDiskCache:
    """Decoded clips on disk, keyed on their source files and decode options, bounded in size (LRU).

    Parameters
    ----------
    folder : path
        Where the entries live (created if missing). May be shared by datasets and processes:
        the bound applies to the folder's total.
    max_mb : float
        Most megabytes (10**6 bytes) of entries kept, > 0.

    Attributes
    ----------
    hits, misses, rejected, evicted : int
        This object's counts: entries read, keys not found (decoded), entries refused as corrupt
        (then decoded again), entries deleted to keep the bound.

    Raises
    ------
    InputError
        ``max_mb`` not a positive finite number, or a folder that cannot be created or written.

    References
    ----------
    Belady, "A study of replacement algorithms for a virtual-storage computer", IBM Systems
    Journal 5(2) (1966) — least-recently-used replacement.

    Examples
    --------
    >>> import tempfile
    >>> ClipDiskCache(tempfile.mkdtemp(), max_mb=512).max_bytes
    512000000
    """

    def __init__(self, folder: str | Path, max_mb: float) -> None:
        if isinstance(max_mb, bool) or not isinstance(max_mb, (int, float)) or not 0 < float(max_mb) <= 1e9:
            raise InputError(f"ClipDiskCache: max_mb={max_mb!r}; allowed: a size in (0, 1e9] MB")
        self.folder = Path(folder)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(
                f"ClipDiskCache: folder {str(self.folder)!r} cannot be created ({exc.strerror or type(exc).__name__})"
            ) from None
        if not os.access(self.folder, os.W_OK | os.X_OK):
            raise InputError(f"ClipDiskCache: folder {str(self.folder)!r} is not writable")
        self.max_bytes = int(float(max_mb) * 1e6)
        self.hits = self.misses = self.rejected = self.evicted = 0

    # ------------------------------------------------------------------ keys
    @staticmethod
    def key(files: Iterable[str | Path], options: Mapping[str, Any]) -> str:
        """The entry key of a clip: its source files (path, size, mtime) and decode options.

        Parameters
        ----------
        files : iterable of path
            Every file the clip's arrays are decoded from (a missing one raises).
        options : mapping
            Every setting that changes the decoded arrays (JSON-serialisable; tuples become lists).

        Returns
        -------
        str
            64 hex digits.

        Raises
        ------
        InputError
            A source file that does not exist.
        """
        stamps = []
        for f in files:
            p = Path(f).resolve()
            try:
                st = p.stat()
            except OSError:
                raise InputError(f"ClipDiskCache: source file {str(p)!r} does not exist") from None
            stamps.append([str(p), st.st_size, st.st_mtime_ns])
        blob = json.dumps(
            {"format": CACHE_FORMAT, "files": stamps, "options": dict(options)}, sort_keys=True, default=str
        )
        return hashlib.sha256(blob.encode("utf-8")).hexdigest()

    def path(self, key: str) -> Path:
        """The entry file of ``key``."""
        return self.folder / f"{key}{ENTRY_SUFFIX}"

    # ------------------------------------------------------------------ read / write
    def load(self, key: str) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``key``, or None (not there, or rejected and deleted)."""
        p = self.path(key)
        if p.is_symlink():
            self._reject(p)
            return None
        try:
            blob = p.read_bytes()
        except FileNotFoundError:
            return None
        except OSError:
            self._reject(p)
            return None
        arrays = _decode_entry(blob, key)
        if arrays is None:
            self._reject(p)
            return None
        with contextlib.suppress(OSError):
            os.utime(p)  # most recently used
        return arrays

    def store(self, key: str, arrays: Mapping[str, np.ndarray]) -> bool:
        """Write ``arrays`` under ``key`` (atomically), then evict down to the bound.

        Returns
        -------
        bool
            False when the entry alone exceeds the bound (not written).
        """
        payload = npz_bytes(**{k: np.asarray(v) for k, v in arrays.items()}, **{_KEY_ARRAY: np.asarray(key)})
        blob = b"%s %d %s\n" % (_MAGIC, CACHE_FORMAT, hashlib.sha256(payload).hexdigest().encode()) + payload
        if len(blob) > self.max_bytes:
            return False
        write_output(self.path(key), blob, flag=f"clip cache {self.folder}")
        self.evict()
        return True

    def decoded(self, key: str, decode: Callable[[], Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """The arrays of ``key``: read from the cache, else returned by ``decode()`` and stored.

        Examples
        --------
        >>> arrays = cache.decoded(cache.key(files, options), lambda: {"frames": read_frames()})  # doctest: +SKIP
        """
        hit = self.load(key)
        if hit is not None:
            self.hits += 1
            return hit
        self.misses += 1
        arrays = {k: np.asarray(v) for k, v in decode().items()}
        self.store(key, arrays)
        return arrays

    # ------------------------------------------------------------------ bound
    def entries(self) -> list[tuple[float, int, Path]]:
        """``(mtime, bytes, path)`` of every entry in the folder, least recently used first."""
        out = []
        now = time.time()
        with os.scandir(self.folder) as it:
            for e in it:
                try:
                    if _ENTRY.match(e.name) and e.is_file(follow_symlinks=False):
                        st = e.stat(follow_symlinks=False)
                        out.append((st.st_mtime, st.st_size, Path(e.path)))
                    elif _TEMP.match(e.name) and now - e.stat(follow_symlinks=False).st_mtime > _STALE_TEMP_S:
                        os.unlink(e.path)  # left by a killed writer
                except FileNotFoundError:  # deleted by another process meanwhile
                    continue
        return sorted(out)

    def usage_bytes(self) -> int:
        """Bytes held by the folder's entries."""
        return sum(size for _, size, _ in self.entries())

    def evict(self) -> int:
        """Delete least recently used entries until the total is at most the bound; returns how many."""
        entries = self.entries()
        total = sum(size for _, size, _ in entries)
        n = 0
        for _, size, p in entries:
            if total <= self.max_bytes:
                break
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
                n += 1
            total -= size
        self.evicted += n
        return n

    def _reject(self, p: Path) -> None:
        self.rejected += 1
        with contextlib.suppress(FileNotFoundError):
            p.unlink()


def _decode_entry(blob: bytes, key: str) -> dict[str, np.ndarray] | None:
    """An entry's arrays if its header, digest, payload and key all check out, else None."""
    head, sep, payload = blob.partition(b"\n")
    parts = head.split(b" ")
    if not sep or len(parts) != 3 or parts[0] != _MAGIC or parts[1] != str(CACHE_FORMAT).encode():
        return None
    if hashlib.sha256(payload).hexdigest().encode() != parts[2]:
        return None
    try:
        with np.load(io.BytesIO(payload), allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception:  # a payload that passed the digest but is no npz: written by something else
        return None
    if str(arrays.pop(_KEY_ARRAY, "")) != key:
        return None
    return arrays
