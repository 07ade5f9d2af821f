"""Paths a design names, resolved against the design file's folder (and confined to it)."""

from __future__ import annotations

from pathlib import Path

from ..paths import confined_path

__all__ = ["resolve_design_path"]


def resolve_design_path(base: Path, path: str, *, what: str, confine: bool) -> Path:
    """``path`` against the design's folder ``base``; with ``confine`` it must stay inside it.

    Parameters
    ----------
    base : Path
        The design file's folder.
    path : str
        The path as the design gives it (relative to ``base``, or absolute where not confined).
    what : str
        The design key, for messages.
    confine : bool
        Refuse a path that leaves ``base`` (:func:`fsdvs_hw.paths.confined_path`); always for design files.

    Returns
    -------
    Path
        The resolved path.
    """
    if confine:
        return confined_path(base, path, what=what)
    p = Path(path)
    return (p if p.is_absolute() else base / p).resolve()
