"""Paths from untrusted places: confine them to their folder, sanitise names, check output folders.

A design file may come from anyone (a colleague, a downloaded sweep), so every path it names
(kernel file, task checkpoints, datasets and every file a dataset names) must stay inside the
design's own folder, or inside one of the folders its ``[design] data_roots`` allow
(:class:`DataRoots`): ``../`` and absolute paths that leave them, and symbolic links that point
out of them, are refused with an :class:`~fsdvs_hw.errors.InputError`. Names that are not paths (``[design] name``) are turned
into safe file names by :func:`safe_name` before they become part of a path. Output folders and
files given on the command line are checked before any work (exists as a file? writable?) so a
long run never fails at its last step. Files written into an output folder never go through a
symbolic link that sits there (it could point anywhere): :func:`write_output` refuses a link and
writes a temporary file in the same folder that :func:`os.replace` then renames over the name,
which replaces a link (should one appear meanwhile) instead of following it.
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import re
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import InputError
from .fingerprints import text_fingerprint

__all__ = [
    "MAX_NAME_LENGTH",
    "Confinement",
    "DataRoots",
    "confined_path",
    "csv_text",
    "figure_png",
    "npz_bytes",
    "output_dir",
    "output_file",
    "safe_name",
    "write_output",
]

#: Longest file-name stem :func:`safe_name` returns (characters).
MAX_NAME_LENGTH = 64

_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def safe_name(name: str, *, fallback: str = "design") -> str:
    """A file-name stem made from ``name``: letters, digits, ``.``, ``_`` and ``-`` only.

    Anything else (``/``, ``\\``, ``..`` at the start, spaces, control characters) becomes ``_``;
    leading dots are removed so the result is never ``.``, ``..`` or hidden. When the name had to
    change, 8 hex digits of its SHA-1 are appended so that two different names never share a file.

    Examples
    --------
    >>> safe_name("sweep_asic_bits")
    'sweep_asic_bits'
    >>> safe_name("../../etc/x").startswith("etc_x-")
    True
    """
    text = str(name)
    slug = _UNSAFE.sub("_", text).strip("._-")[:MAX_NAME_LENGTH] or fallback
    if slug != text:
        slug = f"{slug}-{text_fingerprint(text, length=8)}"
    return slug


@dataclass(frozen=True)
class DataRoots:
    """The folders besides a design's own that its paths may lie in (``[design] data_roots``).

    Passed where a ``confine`` flag is taken (:data:`Confinement`): it confines like ``True``
    (always truthy) and allows these folders too, so a multi-GB dataset, weights, a ``train.out``
    or a clip cache can stay where it lives (a shared or read-only disk).

    Attributes
    ----------
    folders : tuple of Path
        Absolute, resolved folders (symbolic links followed).

    Examples
    --------
    >>> roots = DataRoots((Path("/data/ucf101"),))
    >>> bool(roots), roots.folders[0].name
    (True, 'ucf101')
    """

    folders: tuple[Path, ...] = ()

    def __bool__(self) -> bool:
        return True


#: How a design's paths are confined: ``False`` not at all (designs built in code), ``True`` to
#: the design's folder, :class:`DataRoots` to the design's folder or one of the roots.
Confinement = bool | DataRoots


def confined_path(base: str | Path, path: str | Path, *, what: str, roots: Sequence[Path] = ()) -> Path:
    """``path`` resolved against ``base``; refused unless it stays inside ``base`` or one of ``roots``.

    Parameters
    ----------
    base : path
        The folder the path must stay in (a design file's folder).
    path : str or Path
        Relative (to ``base``) or absolute path; symbolic links are followed before the check.
    what : str
        Name used in the message (``"kernel.path"``).
    roots : sequence of Path
        Further allowed folders (``[design] data_roots``, resolved).

    Raises
    ------
    InputError
        The path (after ``..`` and links are resolved) lies outside ``base`` and every root, or
        contains a NUL byte. The message names the path, where it resolves to and the fix.

    Examples
    --------
    >>> confined_path("/tmp", "../etc/passwd", what="kernel.path")   # doctest: +SKIP
    Traceback (most recent call last):
    InputError: kernel.path = '../etc/passwd': resolves to /etc/passwd, outside the design's folder /tmp; ...
    """
    text = str(path)
    if "\x00" in text:
        raise InputError(f"{what}: path contains a NUL byte")
    root = Path(base).resolve()
    p = Path(text)
    resolved = (p if p.is_absolute() else root / p).resolve()
    allowed = (root, *(Path(r).resolve() for r in roots))
    if not any(resolved == a or a in resolved.parents for a in allowed):
        where = f"the design's folder {root}" + (
            f" and its data_roots {[str(a) for a in allowed[1:]]}" if len(allowed) > 1 else ""
        )
        raise InputError(
            f"{what} = {text!r}: resolves to {resolved}, outside {where}; paths in a design file must "
            "stay inside its folder or a folder listed in [design] data_roots (add the folder there, "
            "or copy the file)"
        )
    return resolved


def output_dir(path: str | Path, *, flag: str = "--out") -> Path:
    """Create the output folder ``path`` (with parents) and check that files can be written in it.

    Raises
    ------
    InputError
        ``path`` (or a parent) is an existing file, cannot be created, or is not writable; the
        message names the flag, the path and the problem.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{flag} {p}: exists and is not a folder")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{flag} {p}: cannot create the folder ({exc.strerror or type(exc).__name__})") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {p}: folder is not writable")
    return p


def output_file(path: str | Path, *, flag: str) -> Path:
    """Check an output file path: its folder is created and writable, it is not a folder itself,
    and it is not a symbolic link (writing would change the file the link points to)."""
    p = Path(path)
    if p.is_symlink():
        raise InputError(
            f"{flag} {p}: is a symbolic link; refusing to write through it (remove the link or name another file)"
        )
    if p.is_dir():
        raise InputError(f"{flag} {p}: is a folder, expected a file path")
    output_dir(p.parent if str(p.parent) else Path("."), flag=flag)
    if p.exists() and not os.access(p, os.W_OK):
        raise InputError(f"{flag} {p}: file is not writable")
    return p


def write_output(path: str | Path, data: str | bytes, *, flag: str = "--out") -> Path:
    """Write ``data`` to ``path`` atomically, never through a symbolic link.

    The data goes to a temporary file in ``path``'s folder, which :func:`os.replace` then renames
    to ``path``: a reader sees the old file or the whole new one, and the rename replaces the name
    itself (a link there is replaced, its target untouched). A link already at ``path`` is refused.

    Parameters
    ----------
    path : str or Path
        The file to write (its folder must exist).
    data : str or bytes
        The content; text is written as UTF-8.
    flag : str
        The option that named the folder, for messages (``"--out"``).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        ``path`` is a symbolic link or a folder.
    """
    p = Path(path)
    if p.is_symlink():
        raise InputError(f"{flag}: {p} is a symbolic link; refusing to write through it (remove the link)")
    if p.is_dir():
        raise InputError(f"{flag}: {p} is a folder, expected a file path")
    blob = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name[:40]}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(blob)
        os.chmod(tmp, 0o644)
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    return p


def csv_text(rows: Iterable[Sequence[Any]]) -> str:
    """Rows as CSV text (``csv.writer``'s dialect, ``\\r\\n`` line ends), for :func:`write_output`.

    Example
    -------
    >>> csv_text([["x", "y"], [1, 2.5]])
    'x,y\\r\\n1,2.5\\r\\n'
    """
    buf = io.StringIO(newline="")
    csv.writer(buf).writerows(rows)
    return buf.getvalue()


def npz_bytes(**arrays: Any) -> bytes:
    """An uncompressed ``.npz`` archive of ``arrays`` (:func:`numpy.savez`) as bytes, for :func:`write_output`."""
    import numpy as np

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def figure_png(fig: Any, **savefig: Any) -> bytes:
    """A matplotlib figure as PNG bytes (``fig.savefig(..., format="png")``), for :func:`write_output`."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", **savefig)
    return buf.getvalue()
