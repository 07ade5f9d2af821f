"""The report's co-design section: fit then swap vs fine-tune vs co-designed, per cell.

:func:`codesign_section` turns the summary that :func:`fsdvs_hw.explore.codesign.run_codesign`
returns (and writes to ``codesign.json``), as a :class:`~fsdvs_hw.report.report_input.CodesignSummary`,
into an HTML fragment: one table row per (realisation, task) cell with
each row's loss and 95 % CI, the fraction of the fit-then-swap loss that fine-tuning the network
and co-design recover (with CIs), the realisation's kernel error before and after co-design (the
hardware's limit) and the Mannos–Sakrison correlation of its kernel before and after (drift
toward or away from the CSF shape), and the verdict.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from markupsafe import Markup

from .report_input import CodesignSummary
from .templating import render

__all__ = ["CODESIGN_HEADERS", "codesign_section"]

#: Column headers of the section's table, in order.
CODESIGN_HEADERS = (
    "realisation",
    "task",
    "n (networks × clips)",
    "fit then swap",
    "fit then fine-tune",
    "co-designed",
    "recovered by fine-tune",
    "recovered by co-design",
    "kernel error fit → co-designed",
    "MS r initial → co-designed",
    "verdict",
)


def _ci(rec: Mapping[str, Any] | None, pct: bool = False) -> str:
    if not rec:
        return "—"
    f = (lambda v: f"{v:.0%}") if pct else (lambda v: f"{v:.4f}")
    return f"{f(rec['estimate'])} [{f(rec['low'])}, {f(rec['high'])}]"


def _mean(values: Any) -> str:
    vals = [float(v) for v in (values or []) if v is not None]
    return f"{np.mean(vals):.3f}" if vals else "—"


def codesign_section(summary: CodesignSummary) -> Markup:
    """The co-design section as an HTML fragment (an ``<h2>``, a note and a table).

    Parameters
    ----------
    summary : CodesignSummary
        The co-design comparison (``codesign.json``: :func:`fsdvs_hw.explore.codesign.summarise_codesign`
        plus ``settings``).

    Returns
    -------
    str
        HTML (:class:`markupsafe.Markup`, a ``str``); every value escaped by the template.
    """
    cells = list(summary.cells)
    st = summary.settings
    rows = []
    for c in cells:
        rows_of = c["rows"]
        loss = {m: (rows_of[m]["loss"] if m in rows_of else None) for m in ("swap", "finetune", "codesign")}
        rows.append(
            [
                c["realisation"],
                c["task"] + f" ({c['metric_name']})",
                f"{c['n_seeds']} × {c['n_clips_per_network']}",
                _ci(loss["swap"]),
                _ci(loss["finetune"]),
                _ci(loss["codesign"]),
                *(
                    _ci(rows_of.get(m, {}).get("recovered"), pct=True)
                    if c.get("swap_loss_above_zero")
                    else "— (no loss above 0)"
                    for m in ("finetune", "codesign")
                ),
                f"{c['kernel_error_fit_gain_free']:.3f} → {_mean(c.get('kernel_error_codesign_gain_free'))}"
                if c.get("kernel_error_fit_gain_free") is not None
                else "—",
                f"{_mean(c.get('ms_correlation_initial'))} → {_mean(c.get('ms_correlation_final'))}",
                c["verdict"] + (f" ({c['ci_note']})" if c.get("ci_note") else ""),
            ]
        )
    return render(
        "codesign.html.j2",
        epochs=str(st.get("epochs", "?")),
        n_train=str(st.get("n_train") or "all"),
        headers=CODESIGN_HEADERS,
        rows=rows,
    )
