"""A design's task checkpoints: entries as lists, glob patterns expanded (bounded), files checked.

``[tasks] checkpoints`` names one checkpoint per task or a list (one network per training seed);
a glob pattern lists every match in natural order (``s2`` before ``s10``) and is walked with a
bound on the directory entries looked at (:data:`MAX_GLOB_ENTRIES`).
"""

from __future__ import annotations

import fnmatch
import glob
import json
import os
import re
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..paths import Confinement
from ..tasks.checkpoints import checkpoint_paths, checkpoint_stem
from .design_paths import resolve_design_path
from .problems import DesignProblems

__all__ = [
    "MAX_GLOB_ENTRIES",
    "bounded_glob",
    "check_checkpoint_entry",
    "checkpoint_entries",
    "expand_checkpoint_patterns",
    "safetensors_problem",
]


def checkpoint_entries(value: Any) -> list[Any]:
    """A checkpoint entry as a list (one path or a list of paths, one per training seed)."""
    return list(value) if isinstance(value, list) else [value]


def _natural_key(path: str) -> list[Any]:
    """Sort key that puts ``s2`` before ``s10``."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path)]


#: Most directory entries one checkpoint glob pattern may look at before it is refused.
MAX_GLOB_ENTRIES = 20000


class _GlobTooWideError(Exception):
    """A pattern's walk looked at more than :data:`MAX_GLOB_ENTRIES` entries."""


def bounded_glob(root: Path, parts: list[str], *, limit: int = MAX_GLOB_ENTRIES) -> list[Path]:
    """Paths under ``root`` matching the pattern components ``parts`` (one level each, like
    :func:`glob.glob` without ``recursive``: ``**`` is ``*``), hidden names only by a pattern that
    starts with ``.``; raises :class:`_GlobTooWideError` after ``limit`` entries are looked at."""
    level = [root]
    seen = 0
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        nxt: list[Path] = []
        for folder in level:
            if not glob.has_magic(part):
                cand = folder / part
                seen += 1
                if cand.exists() if last else cand.is_dir():
                    nxt.append(cand)
                continue
            try:
                with os.scandir(folder) as it:
                    for entry in it:
                        seen += 1
                        if seen > limit:
                            raise _GlobTooWideError
                        if entry.name.startswith(".") and not part.startswith("."):
                            continue
                        if fnmatch.fnmatchcase(entry.name, part) and (last or entry.is_dir()):
                            nxt.append(Path(entry.path))
            except (NotADirectoryError, FileNotFoundError, PermissionError):
                continue
        if seen > limit:
            raise _GlobTooWideError
        level = nxt
    return level


def expand_checkpoint_patterns(
    chk: DesignProblems, data: dict[str, Any], base: Path, confine: Confinement = True
) -> None:
    """Replace glob patterns in ``[tasks] checkpoints`` by the files they match, in natural order.

    ``"networks/detection_*_s*.safetensors"`` lists one network per training seed (``s2`` before
    ``s10``); the expanded list is what the design records, so a stored result names its networks.
    A pattern is matched inside the design's folder only (with ``confine``, always for design
    files): an absolute pattern or one with ``..`` is refused, a match that a link takes out of the
    folder is left out (and not named), and a walk that looks at more than
    :data:`MAX_GLOB_ENTRIES` directory entries is refused.
    """
    ckpts = data["tasks"]["checkpoints"]
    root = base.resolve()
    for task, entry in list(ckpts.items()):
        out: list[Any] = []
        for i, path in enumerate(checkpoint_entries(entry)):
            if not (isinstance(path, str) and glob.has_magic(path)):
                out.append(path)
                continue
            key = f"tasks.checkpoints.{task}" + (f"[{i}]" if isinstance(entry, list) else "")
            pattern = Path(path)
            parts = [p for p in pattern.parts if p not in ("", ".")]
            if "\x00" in path:
                chk.add(key, path, "contains a NUL byte")
                continue
            if confine and (pattern.is_absolute() or ".." in parts):
                chk.add(
                    key,
                    path,
                    f"a glob pattern must stay inside the design's folder {root}; allowed: a "
                    "relative pattern without '..' (e.g. 'networks/det_s*.safetensors')",
                )
                continue
            if pattern.is_absolute():  # confine_paths=False: walk from the pattern's fixed prefix
                n_fixed = next((j for j, p in enumerate(parts) if glob.has_magic(p)), len(parts))
                start, parts = Path(*parts[:n_fixed]), parts[n_fixed:]
            else:
                start = root
            try:
                found = bounded_glob(start, parts, limit=MAX_GLOB_ENTRIES)
            except _GlobTooWideError:
                chk.add(
                    key,
                    path,
                    f"the pattern looks at more than {MAX_GLOB_ENTRIES} files and folders; allowed: "
                    "a narrower pattern (e.g. 'networks/det_s*.safetensors')",
                )
                continue
            inside = [m for m in found if not confine or m.resolve() == root or root in m.resolve().parents]
            matches = sorted(
                ((m.relative_to(root) if start == root else m).as_posix() for m in inside), key=_natural_key
            )
            if not matches:
                left = len(found) - len(inside)
                why = f" ({left} match(es) lead out of the folder through a link and are not used)" if left else ""
                chk.add(key, path, f"the pattern matches no file under {root}{why}")
            out.extend(matches)
        if out != checkpoint_entries(entry):
            ckpts[task] = out


def check_checkpoint_entry(chk: DesignProblems, key: str, path: Any, base: Path, confine: Confinement) -> None:
    """One checkpoint entry: a path string to a readable ``.safetensors`` file (``.json`` or no suffix: its pair)."""
    if not isinstance(path, str):
        chk.add(key, path, "must be a path string to a .safetensors checkpoint")
        return
    try:
        p = resolve_design_path(base, path, what=key, confine=confine)
    except InputError as exc:
        chk.add(key, path, str(exc).split(": ", 1)[-1])
        return
    p = checkpoint_paths(checkpoint_stem(p))["checkpoint"]
    if not p.is_file():
        chk.add(key, path, f"checkpoint file not found (looked for {p})")
    else:
        why = safetensors_problem(p)
        if why is not None:
            chk.add(key, path, f"not a usable checkpoint ({why})")


def safetensors_problem(path: Path) -> str | None:
    """Why ``path`` is not a safetensors file with a ``kernel`` tensor (header only, no torch), or None."""
    try:
        size = path.stat().st_size
        with path.open("rb") as fh:
            head = fh.read(8)
            if len(head) < 8:
                return "shorter than a safetensors header"
            n = int.from_bytes(head, "little")
            if not 2 <= n <= min(size - 8, 100 * 2**20):
                return "not a safetensors file (bad header length)"
            header = json.loads(fh.read(n).decode("utf-8"))
    except OSError as exc:
        return f"cannot read: {exc.strerror}"
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        return "not a safetensors file (header is not JSON)"
    if not isinstance(header, dict) or "kernel" not in header:
        return "no 'kernel' tensor: not written by fsdvs_hw learn"
    return None
