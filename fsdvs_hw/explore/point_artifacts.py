"""Buildable artifacts of an exploration: every scored hardware point's files, and their index.

:func:`write_exploration_artifacts` (called by :func:`fsdvs_hw.explore.explore.run_exploration`)
rebuilds each scored point's fitted realisation from its stored record and calls its registered
writer (:meth:`fsdvs_hw.realise.registry.RealisationSpec.write_artifacts_of`) into
``OUT/artifacts/<point>/`` — ``<point>`` is the realisation's name, followed by the swept
settings when the design sweeps it (``asic__bits-6``). ``OUT/artifacts/index.json`` lists every
file: ``point, realisation, name, file`` (relative to ``OUT/artifacts``), ``what`` and
``checked_by`` (the tool command that checks it). A writer that fails leaves an entry with its
``error`` and does not stop the others; realisations without a writer (the ideal references)
write nothing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..paths import safe_name
from ..realise.artifacts import write_index
from ..realise.registry import REALISATIONS, realisation_from_dict
from ..records import ArtifactLink, ScoredPoint

__all__ = ["ARTIFACTS_DIR", "point_folder_name", "with_point_artifacts", "write_exploration_artifacts"]

#: Folder under the exploration's output that holds the artifacts and ``index.json``.
ARTIFACTS_DIR: str = "artifacts"


def point_folder_name(realisation: str, params: Mapping[str, Any]) -> str:
    """Folder name of a point: the realisation, then ``__<option>-<value>`` per swept setting."""
    parts = [realisation] + [f"{str(k).split('.')[-1]}-{v}" for k, v in sorted(params.items())]
    return safe_name("__".join(parts), fallback=realisation)


def write_exploration_artifacts(
    points: Sequence[ScoredPoint], out_dir: str | Path, *, resolution: tuple[int, int] | None = None
) -> tuple[Path, list[dict[str, Any]]]:
    """Write every scored point's artifacts under ``out_dir/artifacts`` and its ``index.json``.

    Parameters
    ----------
    points : sequence of ScoredPoint
        Stored design points (their realisation, params, status and the fitted realisation's record).
    out_dir : path
        The exploration's output folder.
    resolution : (int, int), optional
        The sensor's (H, W) in pixels, passed to the writers (the ASIC's frame size).

    Returns
    -------
    (Path, list of dict)
        ``index.json``'s path and its entries.
    """
    root = Path(out_dir) / ARTIFACTS_DIR
    entries: list[dict[str, Any]] = []
    used: set[str] = set()
    for p in points:
        spec = REALISATIONS.get(p.realisation)
        record = p.score.realisation if p.score is not None and p.status == "ok" else None
        if spec is None or not spec.write_artifacts or not record:
            continue
        name = point_folder_name(spec.name, p.params)
        while name in used:
            name += "_"
        used.add(name)
        try:
            written = spec.write_artifacts_of(realisation_from_dict(record), root / name, resolution=resolution)
        except Exception as exc:  # noqa: BLE001 - one writer failing must not lose the exploration's report
            entries.append(
                {
                    "point": name,
                    "realisation": spec.name,
                    "name": "",
                    "file": "",
                    "what": "",
                    "checked_by": "",
                    "error": f"{type(exc).__name__}: {exc}"[:500],
                }
            )
            continue
        entries += [a.entry(root, point=name, realisation=spec.name) for a in written]
    return write_index(entries, root / "index.json"), entries


def with_point_artifacts(
    points: Sequence[ScoredPoint], out_dir: str | Path, *, resolution: tuple[int, int] | None = None
) -> tuple[Path, list[ScoredPoint]]:
    """Write every scored point's artifacts (:func:`write_exploration_artifacts`) and link each point to its files.

    Parameters
    ----------
    points : sequence of ScoredPoint
        Stored design points.
    out_dir : path
        The exploration's output folder.
    resolution : (int, int), optional
        The sensor's (H, W) in pixels, passed to the writers.

    Returns
    -------
    (Path, list of ScoredPoint)
        ``index.json``'s path, and the points, each with its :class:`~fsdvs_hw.records.ArtifactLink`
        list (paths relative to ``out_dir``, for the report's links; empty for a point without files).
    """
    index, entries = write_exploration_artifacts(points, out_dir, resolution=resolution)
    linked = []
    for p in points:
        name = point_folder_name(p.realisation, p.params)
        links = [
            ArtifactLink.from_dict({**e, "file": f"{ARTIFACTS_DIR}/{e['file']}" if e.get("file") else ""})
            for e in entries
            if e["point"] == name
        ]
        linked.append(p.with_(artifacts=tuple(links)))
    return index, linked
