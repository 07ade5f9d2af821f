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

__all__ = [
    "MEASURE_COLUMNS",
    "VERDICT_COLUMNS",
    "advice",
    "cost_cell",
    "first_question",
    "fits",
    "loss_cell",
    "loss_header",
    "measurability_advice",
    "measurability_table",
    "verdict_table",
]

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


def fits(r: Mapping[str, Any]) -> bool:
    """The row breaks no hard limit (``fits`` of :func:`fsdvs_hw.report.costs.cost_columns`; rows
    without physical costs fit)."""
    return r.get("fits") is not False


def _broken(r: Mapping[str, Any]) -> str:
    """The hard limits a row breaks, in words ("area 108 µm² > 23.6 µm², the pixel's area ...")."""
    import json

    raw = r.get("hard_limits")
    limits = json.loads(raw) if isinstance(raw, str) and raw.strip() else []
    from .costs import cost_text

    return "; ".join(
        f"{lim['figure'].split('_')[0]} {cost_text(_num(lim['value']), lim['figure'])} > "
        f"{cost_text(_num(lim['limit']), lim['figure'])}, {lim['words']} ({lim['key']})"
        for lim in limits
    )


def _verdict_word(r: Mapping[str, Any], best: set[str], leading: set[str]) -> str:
    if is_reference(str(r["realisation"])):
        return "reference (not hardware)"
    if not fits(r):
        return f"does not fit: {_broken(r)}"
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
    front = [r for r in ok if not is_reference(str(r["realisation"])) and r.get("pareto_all") and fits(r)]
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
    out = [*first_question(ok), *measurability_advice(ok)]
    if not hardware:
        return [*out, "No hardware realisation was scored: nothing to recommend."]
    acc, _acc_label = accuracy_axis(rows)
    what = "loss" if acc.endswith("_loss") else "kernel error"

    def phrase(r: Mapping[str, Any]) -> str:
        text = loss_cell(r, acc)[0]
        return text if text.startswith(("no measurable", "0 (")) else f"{what} {text}"

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
            f"Build {' or '.join(parts)}: {how}, within every hard limit. Which is cheapest in power, "
            "area, latency and events, and the assumptions that ranking rests on: below."
        )
    elif any(not fits(r) for r in hardware):
        out.append(
            "Build nothing of these as costed: every realisation on the front breaks a hard limit "
            "(what would make it fit: below)."
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


def first_question(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """Is the kernel worth building at all? Its gain over a plain DVS whose threshold is lowered to
    fire as many events, per measurable task, with its CI (the ``[rate]`` control: the loss
    reference's ``T_gain_over_plain_dvs_at_matched_rate`` columns), said before any ranking.

    Returns one sentence (none when no task ran)."""
    ref = next((r for r in rows if _is_loss_reference(r)), None)
    if ref is None or not any(_is_task_column(k) for k in ref):
        return []
    status = str(ref.get("matched_rate_status", "not requested"))
    if status != "ok":
        return [
            "First question, not answered: does the kernel beat a plain DVS whose threshold is lowered to fire "
            f"as many events? The matched-rate control did not run ({status}); without it a gain over the plain "
            "DVS may be only a lower threshold."
        ]
    measurable = str(ref.get("measurable_tasks", "")).split() if "measurable_tasks" in ref else None
    parts, gains = [], []
    stem = "_gain_over_plain_dvs_at_matched_rate"
    cols = dict.fromkeys(k.removesuffix("_status") for k in ref if k.endswith((stem, f"{stem}_status")))
    for col in cols:  # a refused comparison (status only) is said, not dropped
        task = col[: -len(stem)]
        if measurable is not None and task not in measurable:
            continue
        lo_key = next((k for k in ref if k.startswith(f"{col}_ci") and k.endswith("_low")), None)
        if lo_key is None:
            parts.append(f"{task}: {ref.get(f'{col}_status', 'no comparison')}")
            continue
        est, lo, hi = _num(ref[col]), _num(ref[lo_key]), _num(ref[lo_key[: -len("_low")] + "_high"])
        n = ref.get(f"{task}_n_clips")
        raw = _num(ref.get(f"{col}_raw"))
        parts.append(
            f"{task} {est:+.3f} [{lo:+.3f}, {hi:+.3f}] (plain DVS at threshold "
            f"{_num(ref.get(f'{col}_threshold')):.3g}{f'; same threshold {raw:+.3f}' if not math.isnan(raw) else ''}"
            f"{f'; n = {number(int(n))} clips' if n else ''})"
        )
        gains.append((task, 1 if lo > 0.0 else -1 if hi < 0.0 else 0))
    if not parts:
        return ["First question, not answered: no measurable task has a matched-rate comparison."]
    head = "First question — does the kernel beat a plain DVS at equal event rate? Its gain, 95 % CI: "
    return [head + "; ".join(parts) + ". " + _gain_tail(gains)]


def _gain_tail(gains: Sequence[tuple[str, int]]) -> str:
    """What the gains' intervals say, per task: ``1`` above 0 (the gain holds), ``0`` containing 0
    (not resolved: this measurement cannot tell the kernel from a plain DVS with a lowered
    threshold), ``-1`` below 0 (the plain DVS does better)."""
    held = [t for t, sign in gains if sign > 0]
    open_ = [t for t, sign in gains if sign == 0]
    worse = [t for t, sign in gains if sign < 0]
    if not gains:
        return "No task's comparison could be made, so the question stays open."
    if not held:
        return (
            "None of these gains is resolved above 0: building the filter gains nothing shown over lowering "
            "the threshold of a plain DVS, in this world; the ranking below is what each realisation loses "
            "against the kernel itself."
        )
    if not open_ and not worse:
        return "The filter's gain holds at equal event rate on every measurable task."
    tail = f"The filter's gain holds at equal event rate for {', '.join(held)}"
    if open_:
        tail += (
            f"; for {', '.join(open_)} it is not resolved: the interval contains 0, so these clips cannot tell "
            "the kernel from a plain DVS with a lowered threshold"
        )
    if worse:
        tail += f"; for {', '.join(worse)} a plain DVS with a lowered threshold does better"
    return tail + "."


def measurability_advice(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """Which tasks can measure a loss, and why the others cannot (chance level, degenerate
    intervals: :mod:`fsdvs_hw.explore.measurability`); nothing when every task can."""
    ref = next((r for r in rows if _is_loss_reference(r)), None)
    if ref is None or "measurable_tasks" not in ref:
        return []
    bad = [
        (k[: -len("_not_measurable")], str(ref[k]))
        for k in ref
        if k.endswith("_not_measurable") and not k.startswith("emu_")
    ]
    if not bad:
        return []
    good = str(ref["measurable_tasks"]).split()
    rest = (
        f"the verdict rests on {', '.join(good)} only (the others weigh 0 in the weighted loss)"
        if good
        else "no task can: realisations are ranked by kernel error alone, and no accuracy loss is claimed"
    )
    return ["Not measurable: " + "; ".join(f"{t} — {why}" for t, why in bad) + f". So {rest}."]


#: Columns of :func:`measurability_table`: (key, header).
MEASURE_COLUMNS: tuple[tuple[str, str], ...] = (
    ("task", "task"),
    ("reference", "learned kernel"),
    ("chance", "chance level"),
    ("above", "learned − chance, 95 % CI"),
    ("interval", "intervals resample"),
    ("verdict", "can it measure a loss?"),
)


def measurability_table(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, str]]:
    """One row per task and track: the reference's metric, the chance level on the same clips (how
    it is made), the reference's margin over chance with its CI, what the intervals resample, and
    whether the task can measure a loss (the reason when not; the clips ``sizing`` asks for when
    its intervals are wider than the design's target). Read from the loss reference's
    ``measurability`` (:mod:`fsdvs_hw.explore.measurability`, via the rows' ``_measurability``)."""
    ref = next((r for r in rows if _is_loss_reference(r)), None)
    meas = ref.get("_measurability") if ref is not None else None
    if not isinstance(meas, Mapping):
        return []
    out = []
    for track, per in meas.items():
        for task, rec in (per or {}).items():
            if not isinstance(rec, Mapping):
                continue
            above = rec.get("above_chance") or {}
            a = (
                f"{_num(above.get('estimate')):+.3f} [{_num(above.get('low')):+.3f}, {_num(above.get('high')):+.3f}]"
                if above
                else "–"
            )
            verdict = "yes" if rec.get("measurable") else f"no: {rec.get('reason', '')}"
            if rec.get("measurable") and "clips_needed" in rec:
                need, now = rec.get("clips_needed"), int(rec.get("clips_now") or 0)
                target = number(_num(rec.get("half_width_target")))
                if need is None:
                    verdict += (
                        f"; for ± {target} no number of clips suffices (the network-to-network spread "
                        "alone is wider: `fsdvs-hw sizing` says how many networks)"
                    )
                elif int(need) > now:
                    verdict += (
                        f"; for ± {target} `fsdvs-hw sizing` asks for {number(int(need))} clips per network "
                        f"(now {number(now)})"
                    )
            metric = str(rec.get("metric_name", ""))
            out.append(
                {
                    "task": f"{task}{'' if track == 'simulator' else f' ({track})'}",
                    "reference": f"{metric} {_num(rec.get('reference_metric')):.3f}",
                    "chance": f"{_num(rec.get('chance')):.3f} ({rec.get('chance_method', '')})",
                    "above": a,
                    "interval": f"{rec.get('resampled', '')}; n = {number(int(rec.get('n_clips') or 0))} clips",
                    "verdict": verdict,
                }
            )
    return out


def _is_task_column(k: str) -> bool:
    return k.endswith("_loss") and not k.startswith("cost_")


def loss_header(rows: Sequence[Mapping[str, Any]]) -> str:
    """Header of the verdict table's loss column: the accuracy loss, or the kernel error when no task ran."""
    acc, label = accuracy_axis(rows)
    if acc.endswith("_loss"):
        return dict(VERDICT_COLUMNS)["loss"]
    return "kernel error (no task could measure a loss)" if "no task could" in label else "kernel error (no task ran)"


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
