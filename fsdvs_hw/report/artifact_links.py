"""The report's "Buildable artifacts" section: per hardware point, links to its files and how to check them.

``fsdvs-hw explore`` writes each scored hardware point's files under ``OUT/artifacts/`` and
attaches the index entries to the point (:attr:`fsdvs_hw.records.ScoredPoint.artifacts`, each an
:class:`~fsdvs_hw.records.ArtifactLink`: ``name, file`` relative to the report, ``what, checked_by``
and, for a writer that failed, ``error``;
:mod:`fsdvs_hw.explore.point_artifacts`). :func:`artifacts_html` turns them into one small table.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from markupsafe import Markup

from ..records import ScoredPoint
from .templating import render

__all__ = ["artifacts_html"]


def artifacts_html(points: Sequence[ScoredPoint]) -> Markup | str:
    """An HTML fragment: heading, note and a table (point, files, what, how to check); ``""`` when none.

    Parameters
    ----------
    points : sequence of ScoredPoint
        Design points; those with artifact links are shown.
    """
    rows: list[dict[str, Any]] = []
    for p in points:
        entries = p.artifacts or ()
        if not entries:
            continue
        rows.append(
            {
                "point": entries[0].point or p.realisation,
                "errors": [e.error for e in entries if e.error],
                "files": [e.file for e in entries if e.file],
                "what": [f"{e.name}: {e.what}" for e in entries],
                "checks": [e.checked_by for e in entries if e.checked_by],
            }
        )
    return render("artifacts.html.j2", rows=rows) if rows else ""
