"""The report's "Buildable artifacts" section: per hardware point, links to its files and how to check them.

``fsdvs-hw explore`` writes each scored hardware point's files under ``OUT/artifacts/`` and
attaches the index entries to the point (``point["artifacts"]``: ``name, file`` relative to the
report, ``what, checked_by`` and, for a writer that failed, ``error``;
:mod:`fsdvs_hw.explore.point_artifacts`). :func:`artifacts_html` turns them into one small table.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from markupsafe import Markup

from ..records import ScoredPoint
from .templating import render

__all__ = ["artifacts_html"]


def artifacts_html(points: Sequence[Mapping[str, Any] | ScoredPoint]) -> Markup | str:
    """An HTML fragment: heading, note and a table (point, files, what, how to check); ``""`` when none.

    Parameters
    ----------
    points : sequence of mappings
        Design points; those with an ``"artifacts"`` list of index entries are shown.
    """
    rows: list[dict[str, Any]] = []
    for p in points:
        listed = p.extra.get("artifacts") if isinstance(p, ScoredPoint) else p.get("artifacts")
        entries = [e for e in (listed or []) if isinstance(e, Mapping)]
        if not entries:
            continue
        name = p.realisation if isinstance(p, ScoredPoint) else p.get("realisation", "")
        rows.append(
            {
                "point": str(entries[0].get("point") or name),
                "errors": [str(e["error"]) for e in entries if e.get("error")],
                "files": [str(e["file"]) for e in entries if e.get("file")],
                "what": [f"{e.get('name', '')}: {e.get('what', '')}" for e in entries],
                "checks": [str(e["checked_by"]) for e in entries if e.get("checked_by")],
            }
        )
    return render("artifacts.html.j2", rows=rows) if rows else ""
