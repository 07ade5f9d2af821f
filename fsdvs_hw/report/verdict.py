"""The report's opening verdict: which realisation to build for which budget, and a short table.

Reads the flat rows of :func:`fsdvs_hw.report.tables.score_rows` (losses with their stored
bootstrap CIs, CSF agreement, each kind's cost on its own axis, the uncertainty-aware Pareto
flags) and says it in a few lines for people: realisation titles, losses as "estimate [95 % CI]"
with n, costs with SI prefixes (:mod:`fsdvs_hw.report.present`). Nothing is re-ranked here: a
loss whose CI contains 0 is "no measurable loss", never ordered by its point estimate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from .present import cost_label, number, point_title, si, title
from .tables import accuracy_axis, is_reference, loss_interval

__all__ = ["VERDICT_COLUMNS", "advice", "cost_cell", "loss_cell", "loss_header", "verdict_table"]

#: Column keys and headers of :func:`verdict_table`.
VERDICT_COLUMNS: tuple[tuple[str, str], ...] = (
    ("realisation", "realisation"),
    ("loss", "accuracy loss, 95 % CI (n)"),
    ("agreement", "CSF agreement r"),
    ("cost", "headline cost"),
    ("verdict", "verdict"),
)


def _num(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def _is_loss_reference(r: Mapping[str, Any]) -> bool:
    return r.get("key") is not None and r.get("key") == r.get("loss_reference")


def loss_cell(r: Mapping[str, Any], column: str) -> tuple[str, str]:
    """``(loss text, n text)`` of a row's accuracy-loss column.

    The loss text is the stored ``<task>_loss_text`` ("0.169 [0.163, 0.175]" or "no measurable
    loss (± 0.001)"); n is "29 696 clips × 32 seeds" from ``<task>_n_clips`` and ``_n_seeds``.
    For the kernel-error axis (no task ran) the number alone.
    """
    if _is_loss_reference(r):
        return "0 (the reference)", ""
    if not column.endswith("_loss"):
        return number(_num(r.get(column))), ""
    base = column[: -len("_loss")]
    text = str(r.get(f"{base}_loss_text") or number(_num(r.get(column))))
    n, seeds = r.get(f"{base}_n_clips"), r.get(f"{base}_n_seeds")
    n_text = f"n = {number(int(n))} clips, {number(int(seeds))} seeds" if n and seeds else ""
    return text, n_text


def cost_cell(r: Mapping[str, Any]) -> str:
    """The headline cost as "label value" with an SI prefix; "– (ideal reference)" for references."""
    name, value, unit = r.get("headline_cost"), _num(r.get("headline_cost_value")), r.get("headline_cost_unit", "")
    if not name or math.isnan(value):
        return "– (ideal reference)" if is_reference(str(r.get("realisation", ""))) else "–"
    return f"{cost_label(str(r['realisation']), str(name))} {si(value, str(unit))}"


def _budget_text(r: Mapping[str, Any]) -> str:
    """The kind's own cost (display unit, as declared in the registry) as text."""
    return f"{r['kind_cost']} {number(_num(r['kind_cost_value']))} {r['kind_cost_unit']}".replace(" count", "")


def _verdict_word(r: Mapping[str, Any], best: set[str], leading: set[str]) -> str:
    if is_reference(str(r["realisation"])):
        return "reference (not hardware)"
    if r["point"] in best:
        return "build"
    if r.get("pareto_all"):
        return "on the front across kinds"
    if r.get("pareto") and str(r["realisation"]) in leading:
        return "a cheaper option of its kind"
    return "not recommended"


def _leading_kinds(rows: Sequence[Mapping[str, Any]]) -> set[str]:
    """Hardware kinds with a point on the across-kinds front."""
    return {str(r["realisation"]) for r in rows if r.get("pareto_all") and not is_reference(str(r["realisation"]))}


def _no_measurable_loss(r: Mapping[str, Any], acc: str) -> bool:
    _, lo, _ = loss_interval(r, acc)
    return acc.endswith("_loss") and not math.isnan(lo) and lo <= 0.0


def _recommended(ok: Sequence[Mapping[str, Any]], acc: str) -> list[Mapping[str, Any]]:
    """Hardware points on the across-kinds front: those with no measurable loss, the cheapest per kind;
    else the front point(s) with the smallest upper loss bound."""
    front = [r for r in ok if not is_reference(str(r["realisation"])) and r.get("pareto_all")]
    clean = [r for r in front if _no_measurable_loss(r, acc)]
    if clean:
        per_kind: dict[str, Mapping[str, Any]] = {}
        for r in clean:
            k = str(r["realisation"])
            c = _num(r.get("kind_cost_value"))
            if k not in per_kind or c < _num(per_kind[k].get("kind_cost_value")):
                per_kind[k] = r
        return list(per_kind.values())
    if not front:
        return []
    top = min(loss_interval(r, acc)[2] for r in front)
    return [r for r in front if loss_interval(r, acc)[1] <= top]


def advice(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The verdict in plain sentences (text, not HTML): what to build, then each kind's budget ladder.

    1. Build: the hardware points on the across-kinds front (loss ↓ with its CI, Mannos–Sakrison
       agreement ↑) with no measurable loss, the cheapest of each kind; if none, the front points
       whose loss CI overlaps the smallest upper bound.
    2. Per hardware kind with two or more points on its own front, the front ordered by its own
       cost: "from C: P, loss ..." (the loss each budget buys).
    3. What is not worth building: points off the across-kinds front, except the cheaper steps of a
       kind that has a point on it (they are in its budget ladder).
    4. Where the points carry physical costs: the cheapest realisation in power, area, latency and
       event rate within the loss budget, and every readout-limit breach
       (:func:`fsdvs_hw.report.costs.cost_advice`).
    """
    ok = [r for r in rows if r.get("status") == "ok"]
    hardware = [r for r in ok if not is_reference(str(r["realisation"]))]
    if not hardware:
        return ["No hardware realisation was scored: nothing to recommend."]
    acc, _acc_label = accuracy_axis(rows)
    what = "loss" if acc.endswith("_loss") else "kernel error"

    def phrase(r: Mapping[str, Any]) -> str:
        text = loss_cell(r, acc)[0]
        return text if text.startswith(("no measurable", "0 (")) else f"{what} {text}"

    out = []
    rec = _recommended(ok, acc)
    if rec:
        parts = []
        for r in rec:
            loss, n = loss_cell(r, acc)
            parts.append(
                f"{point_title(str(r['realisation']), r.get('params'))} ({cost_cell(r)}; {loss}"
                f"{', ' + n if n else ''}; CSF r {number(_num(r.get('csf_fitted_correlation')))})"
            )
        how = (
            "with no measurable accuracy loss and not dominated in CSF agreement"
            if all(_no_measurable_loss(r, acc) for r in rec)
            else f"smallest {what} among the undominated"
        )
        out.append(
            f"Build {' or '.join(parts)}: {how}. Costs of different kinds are in different units; "
            "pick the kind whose budget you have."
        )
    for kind in dict.fromkeys(str(r["realisation"]) for r in hardware):
        g = sorted(
            (r for r in hardware if r["realisation"] == kind and r.get("kind_cost")),
            key=lambda r: _num(r.get("kind_cost_value")),
        )
        front = [r for r in g if r.get("pareto")]
        if len(front) < 2:  # one point: the table says it all
            continue
        steps = "; ".join(f"from {_budget_text(r)}: {point_title(kind, r.get('params'))}, {phrase(r)}" for r in front)
        out.append(f"{title(kind)} by budget ({front[0]['kind_cost']}): {steps}.")
    # not worth building: off the across-kinds front, unless a cheaper step of a kind that has a point on it
    leading = _leading_kinds(hardware)
    best = {str(r["point"]) for r in rec}
    dominated = [r for r in hardware if _verdict_word(r, best, leading) == "not recommended"]
    if dominated:
        out.append(
            "Not recommended (another realisation is better beyond the CIs in "
            f"{what} and CSF agreement): "
            + "; ".join(f"{point_title(str(r['realisation']), r.get('params'))}, {phrase(r)}" for r in dominated)
            + "."
        )
    from .costs import cost_advice

    out.extend(cost_advice(rows))  # cheapest per physical cost within the loss budget; readout breaches
    if not acc.endswith("_loss"):
        out.append(
            "No task evaluator ran (no [tasks] checkpoints): points are ranked by kernel error (relative L2 "
            "against the target), not by accuracy loss."
        )
    return out


def loss_header(rows: Sequence[Mapping[str, Any]]) -> str:
    """Header of the verdict table's loss column: the accuracy loss, or the kernel error when no task ran."""
    acc, _ = accuracy_axis(rows)
    return dict(VERDICT_COLUMNS)["loss"] if acc.endswith("_loss") else "kernel error (no task ran)"


def verdict_table(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, str]]:
    """One row per scored point, cells keyed by :data:`VERDICT_COLUMNS` (display text) plus ``n``
    (the loss's sample size), ``realisation_name`` (registry name, for its colour) and ``front``
    ("1" on a front)."""
    ok = [r for r in rows if r.get("status") == "ok"]
    acc, _ = accuracy_axis(rows)
    best = {str(r["point"]) for r in _recommended(ok, acc)}
    leading = _leading_kinds(ok)
    out = []
    for r in ok:
        loss, n = loss_cell(r, acc)
        out.append(
            {
                "realisation": point_title(str(r["realisation"]), r.get("params")),
                "loss": loss,
                "n": n,
                "agreement": number(_num(r.get("csf_fitted_correlation"))),
                "cost": cost_cell(r),
                "verdict": _verdict_word(r, best, leading),
                "realisation_name": str(r["realisation"]),
                "front": "1" if (r.get("pareto") or r.get("pareto_all")) else "",
            }
        )
    return out
