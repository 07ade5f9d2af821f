"""Reports of design explorations: figures, score tables (CSV/JSON) and a self-contained HTML page.

:func:`write_report` is the entry point used by ``fsdvs-hw explore`` and ``fsdvs-hw sweep --report``:
it takes the scored points (:class:`fsdvs_hw.records.ScoredPoint`) and a :class:`ReportInput`
(the design's settings the page states, and the co-design summary);
:func:`write_report_from_scores` redraws a report from the ``scores.json`` of an earlier run.
"""

from __future__ import annotations

from .html import render_html, write_report
from .redraw import write_report_from_scores
from .report_input import CodesignSummary, ReportInput
from .tables import pareto_front, score_rows, write_scores

__all__ = [
    "CodesignSummary",
    "ReportInput",
    "pareto_front",
    "render_html",
    "score_rows",
    "write_report",
    "write_report_from_scores",
    "write_scores",
]
