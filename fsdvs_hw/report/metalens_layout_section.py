"""The report's metalens layout section: what each step from the ideal phase to the layout costs.

:func:`metalens_layout_section` turns the score rows of ``metalens_layout`` points (the lens realised
as a lattice of library pillars, :mod:`fsdvs_hw.realise.metalens.layout_design`) into an HTML
fragment: per point, one table row per step — ideal phase (the fit), library (the chosen pillars'
complex transmission on a continuous radius) and layout (the lattice, the realised kernel) — with
each step's kernel error, and for the layout its CSF agreement, accuracy loss with its 95 % CI (as
scored through the simulator and the task evaluators), window efficiency, the library's mean
power transmission, pillars and radius levels. The ideal step's accuracy loss and CSF agreement are
those of the ``metalens`` point of the same run when there is one (the same fit).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from markupsafe import Markup, escape

from .present import point_title

__all__ = ["LAYOUT_STEP_HEADERS", "metalens_layout_section"]

#: Column headers of the section's table, in order.
LAYOUT_STEP_HEADERS = (
    "point",
    "step",
    "kernel error",
    "CSF agreement",
    "accuracy loss [95 % CI]",
    "window efficiency",
    "library |t|²",
    "pillars",
    "radius levels",
)


def _num(v: Any, fmt: str = ".3f") -> str:
    return (
        format(float(v), fmt) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else "—"
    )


def _loss(row: Mapping[str, Any] | None, column: str) -> str:
    if not row:
        return "—"
    text = row.get(f"{column}_text")
    if text:
        return str(text)
    return _num(row.get(column), ".4f") if column != "kernel_error" else "—"


def metalens_layout_section(rows: Sequence[Mapping[str, Any]], loss_column: str = "weighted_loss") -> Markup | str:
    """The section as an HTML fragment (``""`` when no ``metalens_layout`` point was scored).

    Parameters
    ----------
    rows : sequence of mapping
        Score rows (:func:`fsdvs_hw.report.tables.score_rows` with the cost columns).
    loss_column : str
        The accuracy-loss column (:func:`fsdvs_hw.report.tables.accuracy_axis`).

    Examples
    --------
    >>> rows = [{"realisation": "metalens_layout", "status": "ok", "kernel_error": 0.36, "csf_agreement": 0.9,
    ...          "cost_ideal_kernel_error": 0.30, "cost_library_kernel_error": 0.35, "cost_pillar_count": 87253}]
    >>> html = str(metalens_layout_section(rows))
    >>> "ideal phase" in html and "87253" in html
    True
    """
    layouts = [r for r in rows if r.get("realisation") == "metalens_layout" and r.get("status") == "ok"]
    if not layouts:
        return ""
    ideal = next((r for r in rows if r.get("realisation") == "metalens" and r.get("status") == "ok"), None)
    body = []
    for r in layouts:
        name = point_title("metalens_layout", r.get("params"))
        steps = [
            ("ideal phase", r.get("cost_ideal_kernel_error"), ideal),
            ("library", r.get("cost_library_kernel_error"), None),
            ("layout", r.get("kernel_error"), r),
        ]
        for step, err, scored in steps:
            is_layout = step == "layout"
            cells = [
                name if step == "ideal phase" else "",
                step,
                _num(err),
                _num(scored.get("csf_agreement")) if scored else "—",
                _loss(scored, loss_column),
                _num(r.get("cost_optical_efficiency")) if is_layout else "—",
                _num(r.get("cost_library_transmission")) if is_layout else "—",
                _num(r.get("cost_pillar_count"), ".0f") if is_layout else "—",
                _num(r.get("cost_radius_levels"), ".0f") if is_layout else "—",
            ]
            body.append("<tr>" + "".join(f"<td>{escape(c)}</td>" for c in cells) + "</tr>")
    head = "".join(f"<th>{escape(h)}</th>" for h in LAYOUT_STEP_HEADERS)
    note = (
        "<p>The metalens as it would be fabricated: the ideal-phase lens (the <em>metalens</em> point's fit), "
        "then each lattice site given the library pillar of nearest complex transmission (RCWA, meent), then "
        "the PSF of the lattice itself, over the illuminant's spectrum. Kernel errors are relative L2 against "
        "the target (pedestal included); the layout's accuracy loss is measured through the simulator and "
        "the task networks like every other point; the ideal step's is the <em>metalens</em> point's. "
        "Efficiency is the layout PSF's window fraction of the power on the aperture (library losses "
        "included); the GDS and its KLayout DRC report are under the point's artifacts.</p>"
    )
    return Markup(
        f"<h2 id='metalens-layout'>Metalens layout: ideal phase → library → layout</h2>{note}"
        f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"
    )
