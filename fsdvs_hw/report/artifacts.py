"""The report's "Buildable artifacts" section: per hardware point, links to its files and how to check them.

``fsdvs-hw explore`` writes each scored hardware point's files under ``OUT/artifacts/`` and
attaches the index entries to the point (``point["artifacts"]``: ``name, file`` relative to the
report, ``what, checked_by`` and, for a writer that failed, ``error``;
:mod:`fsdvs_hw.explore.artifacts`). :func:`artifacts_html` turns them into one small table.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from typing import Any
from urllib.parse import quote

from ..records import ScoredPoint

__all__ = ["artifacts_html"]


def artifacts_html(points: Sequence[Mapping[str, Any] | ScoredPoint]) -> str:
    """An HTML fragment: heading, note and a table (point, files, what, how to check); ``""`` when none.

    Parameters
    ----------
    points : sequence of mappings
        Design points; those with an ``"artifacts"`` list of index entries are shown.
    """
    rows: list[str] = []
    for p in points:
        listed = p.extra.get("artifacts") if isinstance(p, ScoredPoint) else p.get("artifacts")
        entries = [e for e in (listed or []) if isinstance(e, Mapping)]
        if not entries:
            continue
        name = p.realisation if isinstance(p, ScoredPoint) else p.get("realisation", "")
        point = html.escape(str(entries[0].get("point") or name))
        errors = [e["error"] for e in entries if e.get("error")]
        if errors:
            rows.append(f'<tr><td class="l">{point}</td><td class="l bad" colspan="3">not written: '
                        f'{html.escape("; ".join(map(str, errors)))}</td></tr>')
            continue
        files = "<br>".join(
            f'<a href="{html.escape(quote(str(e["file"])))}">{html.escape(str(e["file"]).rsplit("/", 1)[-1])}</a>'
            for e in entries
            if e.get("file")
        )
        what = "<br>".join(html.escape(f"{e.get('name', '')}: {e.get('what', '')}") for e in entries)
        checks = "<br>".join(f"<code>{html.escape(str(e['checked_by']))}</code>"
                             for e in entries if e.get("checked_by"))
        rows.append(f'<tr><td class="l">{point}</td><td class="l">{files}</td><td class="l">{what}</td>'
                    f'<td class="l">{checks}</td></tr>')
    if not rows:
        return ""
    head = "".join(f'<th class="l">{t}</th>' for t in ("point", "files", "what", "how to check (in the file's folder)"))
    return ("<h2>Buildable artifacts</h2><p class='note'>Files a builder can take to the tools, written by this "
            "run under <code>artifacts/</code> (listed in <code>artifacts/index.json</code>): the mesh as an "
            "ngspice deck with the operating point it must reproduce, the ASIC taps as Verilog with a "
            "self-checking testbench, the metalens phase profile with the PSF it implies. The test suite runs "
            "each check with the real tool.</p>"
            f"<table><tr>{head}</tr>{''.join(rows)}</table>")
