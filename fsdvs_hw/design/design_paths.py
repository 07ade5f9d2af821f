"""Paths a design names, resolved against the design file's folder (and confined to it and its data roots)."""

from __future__ import annotations

from pathlib import Path

from ..paths import Confinement, DataRoots, confined_path

__all__ = ["resolve_design_path"]


def resolve_design_path(base: Path, path: str, *, what: str, confine: Confinement) -> Path:
    """``path`` against the design's folder ``base``; with ``confine`` it must stay inside it.

    Parameters
    ----------
    base : Path
        The design file's folder.
    path : str
        The path as the design gives it (relative to ``base``, or absolute where not confined).
    what : str
        The design key, for messages.
    confine : bool or DataRoots
        ``True``: refuse a path that leaves ``base`` (:func:`fsdvs_hw.paths.confined_path`; always
        for design files); :class:`~fsdvs_hw.paths.DataRoots`: a path may also lie in one of its
        folders (``[design] data_roots``); ``False``: no check.

    Returns
    -------
    Path
        The resolved path.

    Examples
    --------
    >>> resolve_design_path(Path("/tmp"), "k.json", what="kernel.path", confine=True)
    PosixPath('/tmp/k.json')
    """
    if confine:
        roots = confine.folders if isinstance(confine, DataRoots) else ()
        return confined_path(base, path, what=what, roots=roots)
    p = Path(path)
    return (p if p.is_absolute() else base / p).resolve()
