"""The report's co-design section (issue 16): fit then swap vs fine-tune vs co-designed, per cell.

:func:`codesign_section` turns the summary that :func:`fsdvs_hw.explore.codesign.run_codesign`
writes to ``codesign.json`` into an HTML fragment: one table row per (realisation, task) cell with
each row's loss and 95 % CI, the fraction of the fit-then-swap loss that fine-tuning the network
and co-design recover (with CIs), the realisation's kernel error before and after co-design (the
hardware's limit) and the Mannos–Sakrison correlation of its kernel before and after (drift
toward or away from the CSF shape), and the verdict.
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["CODESIGN_HEADERS", "codesign_section"]

#: Column headers of the section's table, in order.
CODESIGN_HEADERS = ("realisation", "task", "n (networks × clips)", "fit then swap", "fit then fine-tune",
                    "co-designed", "recovered by fine-tune", "recovered by co-design", "kernel error fit → co-designed",
                    "MS r initial → co-designed", "verdict")


def _ci(rec: Mapping[str, Any] | None, pct: bool = False) -> str:
    if not rec:
        return "—"
    f = (lambda v: f"{v:.0%}") if pct else (lambda v: f"{v:.4f}")
    return f"{f(rec['estimate'])} [{f(rec['low'])}, {f(rec['high'])}]"


def _mean(values: Any) -> str:
    vals = [float(v) for v in (values or []) if v is not None]
    return f"{np.mean(vals):.3f}" if vals else "—"


def codesign_section(summary: Mapping[str, Any]) -> str:
    """The co-design section as an HTML fragment (an ``<h2>``, a note and a table).

    Parameters
    ----------
    summary : mapping
        The content of ``codesign.json`` (:func:`fsdvs_hw.explore.codesign.summarise_codesign`
        plus ``settings``).

    Returns
    -------
    str
        HTML; every value escaped.
    """
    cells = list(summary.get("cells", []))
    st = summary.get("settings", {})
    parts = [
        "<h2>Co-design: fit then swap, fine-tune, co-designed</h2>",
        "<p class='note'>Per hardware realisation and task: the realisation fitted to the kernel and swapped "
        "zero-shot into the networks trained with the kernel (fit then swap); the same networks trained further "
        f"with the fitted kernel frozen (fit then fine-tune); the same networks and the realisation's own "
        f"parameters trained together from the fitted design (co-designed). {html.escape(str(st.get('epochs', '?')))} "
        f"epochs on {html.escape(str(st.get('n_train') or 'all'))} of each network's training clips. Loss = "
        "metric(learned kernel, original network) − metric(row), 95 % CI resampling (network, clips) clusters; "
        "recovered = 1 − loss(row) / loss(swap) with the CI of the same resampling. Kernel error: relative L2 "
        "against the target, gain-free; MS r: correlation of the kernel's response with the Mannos–Sakrison "
        "CSF (mean over networks).</p>",
    ]
    if not cells:
        parts.append("<p class='note'>No co-design cell measured.</p>")
        return "".join(parts)
    parts.append("<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in CODESIGN_HEADERS) + "</tr>")
    for c in cells:
        rows = c["rows"]
        loss = {m: (rows[m]["loss"] if m in rows else None) for m in ("swap", "finetune", "codesign")}
        vals = [c["realisation"], c["task"] + f" ({c['metric_name']})",
                f"{c['n_seeds']} × {c['n_clips_per_network']}",
                _ci(loss["swap"]), _ci(loss["finetune"]), _ci(loss["codesign"]),
                *(_ci(rows.get(m, {}).get("recovered"), pct=True) if c.get("swap_loss_above_zero")
                  else "— (no loss above 0)" for m in ("finetune", "codesign")),
                f"{c['kernel_error_fit_gain_free']:.3f} → {_mean(c.get('kernel_error_codesign_gain_free'))}"
                if c.get("kernel_error_fit_gain_free") is not None else "—",
                f"{_mean(c.get('ms_correlation_initial'))} → {_mean(c.get('ms_correlation_final'))}",
                c["verdict"]]
        parts.append("<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in vals) + "</tr>")
    parts.append("</table>")
    return "".join(parts)
