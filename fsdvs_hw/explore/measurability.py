"""Can a task measure an accuracy loss at all? Chance level, degenerate intervals, the clips it needs.

A loss is a difference of two task metrics in the same networks on the same clips
(:func:`fsdvs_hw.explore.scoring.paired_losses`). It measures something only when the networks
do something: a detector at mAP 0 or a classifier at chance scores every kernel alike, and its
losses are zero with a zero-width interval — a number, not a measurement. For every sweep
setting, track and task this module asks, on the stored per-clip evidence:

1. **Above chance?** The reference kernel's metric against a predictor that has learned nothing,
   scored on the same clips (:func:`fsdvs_hw.stats.chance_metric`: the most frequent class for
   top-1 and mIoU, no boxes for mAP), as a paired difference with its bootstrap CI over the same
   (network, clips) clusters as the losses (:func:`fsdvs_hw.stats.difference_ci`). Its lower
   bound must lie above 0.
2. **Do kernels differ?** When every kernel's per-clip evidence is identical the task cannot
   rank kernels.
A task that fails either is "not measurable" with its reason, and its weight in the weighted loss
the verdict ranks by is 0 (:func:`measured_losses`). A single realisation whose every clip gives
the reference's result has a loss interval of zero width, which is no measure of its uncertainty:
it is replaced by the rule-of-three interval (:func:`widen_degenerate`). When half-widths exceed
the design's target, the record says how many clips :func:`fsdvs_hw.explore.sizing.size_test_sets`
asks for.

Examples
--------
>>> from fsdvs_hw.explore.measurability import task_measurability
>>> task_measurability([])
{}
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..records import ScoredPoint
from .scoring import TRACK_PREFIX, sweep_setting, track_record, with_paired_losses

__all__ = ["measured_losses", "task_measurability", "widen_degenerate"]


def _same_evidence(arms: Sequence[Sequence[Any]]) -> bool:
    """Every arm's per-network metric states are equal, array by array."""
    first = [m.state() for m in arms[0]]
    for arm in arms[1:]:
        for a, b in zip(first, (m.state() for m in arm)):
            if a.keys() != b.keys() or not all(np.array_equal(np.asarray(a[k]), np.asarray(b[k])) for k in a):
                return False
    return True


def task_measurability(
    points: Sequence[Mapping[str, Any]],
    *,
    reference: str = "learned",
    confidence: float = 0.95,
    n_resamples: int = 2000,
    rng: int = 0,
) -> dict[str, dict[str, dict[str, dict[str, Any]]]]:
    """Chance level and measurability of every task, per sweep setting and track.

    Parameters
    ----------
    points : sequence of mappings
        Stored points with their per-clip ``evidence`` (before :func:`fsdvs_hw.explore.scoring.
        with_paired_losses` drops it).
    reference : str
        The realisation the losses are measured against (its metric is tested against chance).
    confidence, n_resamples, rng
        Bootstrap settings of the above-chance interval.

    Returns
    -------
    dict
        ``{setting: {track: {task: record}}}``; a record holds ``metric_name``, ``reference_metric``
        (mean over networks), ``chance`` (the chance predictor's metric on the same clips),
        ``chance_method``, ``above_chance`` (estimate, low, high of reference − chance), ``n_clips``,
        ``n_networks``, ``resampled`` (the interval's resampling unit in words), ``measurable``
        and ``reason`` (why not; empty when measurable).
    """
    from .paired import decode_evidence

    groups: dict[str, list[Mapping[str, Any]]] = {}
    for p in points:
        if p.get("status") == "ok":
            groups.setdefault(sweep_setting(p), []).append(p)
    out: dict[str, dict[str, dict[str, dict[str, Any]]]] = {}
    for ctx, group in groups.items():
        ref = next((p for p in group if p.get("realisation") == reference), None)
        if ref is None:
            continue
        tasks = [t for t, v in ((ref.get("result") or {}).get("tasks") or {}).items() if isinstance(v, Mapping)]
        for track in TRACK_PREFIX:
            for task in tasks:
                rrec = track_record(ref, task, track)
                if rrec.get("status") != "ok" or not rrec.get("evidence"):
                    continue
                arm = [decode_evidence(e) for e in rrec["evidence"]]
                nested = rrec.get("test_clips") == "per_network"
                rec: dict[str, Any] = {
                    "metric_name": str(rrec.get("metric_name", "")),
                    "reference_metric": float(np.mean([float(m.weighted(np.ones((1, m.n_clips)))[0]) for m in arm])),
                    "n_clips": int(sum(m.n_clips for m in arm)) if nested else int(arm[0].n_clips),
                    "n_networks": len(arm),
                    "resampled": (
                        f"(network, clips) clusters of {len(arm)} networks"
                        if len(arm) >= 2
                        else "test clips only (one network: the network-to-network spread is not in the interval)"
                    ),
                }
                reasons = _chance_reasons(
                    rec, arm, nested, reference=reference, confidence=confidence, n_resamples=n_resamples, rng=rng
                )
                others = [
                    [decode_evidence(e) for e in track_record(p, task, track)["evidence"]]
                    for p in group
                    if p is not ref
                    and track_record(p, task, track).get("status") == "ok"
                    and len(track_record(p, task, track).get("evidence") or []) == len(arm)
                ]
                if others and _same_evidence([arm, *others]):
                    reasons.append(
                        f"every kernel's per-clip result is identical ({len(others) + 1} kernels): "
                        "the task cannot tell kernels apart"
                    )
                rec["measurable"] = not reasons
                rec["reason"] = "; ".join(reasons)
                out.setdefault(ctx, {}).setdefault(track, {})[task] = rec
    return out


def _chance_reasons(
    rec: dict[str, Any],
    arm: Sequence[Any],
    nested: bool,
    *,
    reference: str,
    confidence: float,
    n_resamples: int,
    rng: int,
) -> list[str]:
    """Fill ``rec``'s ``chance``, ``chance_method`` and ``above_chance``; the reasons it is not measurable.

    A reference metric that is undefined on its clips (NaN: a mean IoU over clips without a labelled
    pixel) is not measurable for that reason, and no interval is drawn around it.
    """
    from ..stats import chance_metric, difference_ci

    if not math.isfinite(rec["reference_metric"]):
        rec["chance"], rec["chance_method"] = math.nan, "undefined (the metric is undefined on these clips)"
        return [
            f"the {reference} kernel's {rec['metric_name']} is undefined on its {rec['n_clips']} test clips "
            "(nothing to score: no labelled pixels or boxes)"
        ]
    chances = [chance_metric(m) for m in arm]
    if any(c is None for c in chances):
        rec["chance"], rec["chance_method"] = math.nan, "unknown (evidence keeps no ground truth)"
        return []
    cm = [c[0] for c in chances if c is not None]
    rec["chance"] = float(np.mean([float(m.weighted(np.ones((1, m.n_clips)))[0]) for m in cm]))
    rec["chance_method"] = chances[0][1] if chances[0] is not None else ""
    ci = difference_ci(
        arm,
        cm,
        nested_clips=nested,
        confidence=confidence,
        n_resamples=n_resamples,
        rng=rng,
    )
    rec["above_chance"] = {"estimate": ci.estimate, "low": ci.low, "high": ci.high}
    if ci.low > 0.0:
        return []
    return [
        f"the {reference} kernel's {rec['metric_name']} {rec['reference_metric']:.3f} is not above "
        f"chance ({rec['chance']:.3f}: {rec['chance_method']}) beyond its "
        f"{round(100 * confidence)} % CI ({ci.estimate:+.3f} [{ci.low:+.3f}, {ci.high:+.3f}])"
    ]


def widen_degenerate(paired: dict[str, dict[str, Any]], confidence: float = 0.95) -> int:
    """Replace every zero-width task-loss interval by the rule-of-three interval; returns how many.

    A realisation whose every test clip gives the reference's result has a loss of exactly 0 in
    every bootstrap resample: an interval of zero width, which says nothing of its uncertainty.
    Zero changed clips out of ``n`` bound the fraction of clips the realisation changes by
    :math:`B = 1 - (1 - c)^{1/n}` at confidence ``c`` (≈ 3/n at 95 %: the "rule of three",
    J. A. Hanley & A. Lippman-Hand, JAMA 249(13), 1983); for top-1 accuracy that bounds the loss.
    The interval becomes ``[−B, +B]``, marked ``"degenerate": True`` with its text saying so; a
    weighted loss whose interval had zero width gets the weighted mean of its tasks' ``B``.

    Parameters
    ----------
    paired : dict
        :func:`fsdvs_hw.explore.scoring.paired_losses` (modified in place).
    confidence : float
        The intervals' confidence level.

    Examples
    --------
    >>> p = {"k": {"simulator": {"recognition": {"estimate": 0.0, "low": 0.0, "high": 0.0, "n_clips": 300},
    ...                          "weights": {"recognition": 1.0}}}}
    >>> widen_degenerate(p), round(p["k"]["simulator"]["recognition"]["high"], 4)
    (1, 0.0099)
    """
    n_widened = 0
    for rec in paired.values():
        if not isinstance(rec, dict):
            continue
        for per in rec.values():
            if not isinstance(per, dict):
                continue
            bounds: dict[str, float] = {}
            for task, ci in per.items():
                if task == "weighted" or not isinstance(ci, dict) or "low" not in ci or ci["high"] != ci["low"]:
                    continue
                n = int(ci.get("n_clips") or 0)
                if n < 1:
                    continue
                b = 1.0 - (1.0 - confidence) ** (1.0 / n)
                bounds[task] = b
                _widen(ci, b, f"no clip changed (n = {n}): |loss| ≤ {b:.3f} (rule of three)")
                n_widened += 1
            w = per.get("weighted")
            weights = per.get("weights") or {}
            if bounds and isinstance(w, dict) and "low" in w and w["high"] == w["low"]:
                tot = sum(float(weights.get(t, 0.0)) for t in per if t not in ("weighted", "weights"))
                b = sum(float(weights.get(t, 0.0)) * bounds.get(t, 0.0) for t in bounds) / tot if tot > 0 else 0.0
                if b > 0:
                    _widen(w, b, f"no clip changed in any task: |loss| ≤ {b:.3f} (rule of three)")
    return n_widened


def _widen(ci: dict[str, Any], b: float, text: str) -> None:
    """Give a zero-width interval record the bound ``± b`` around its estimate, marked degenerate."""
    est = float(ci["estimate"])
    ci.update(low=est - b, high=est + b, half_width=b, contains_zero=True, degenerate=True, text=text)


def measured_losses(
    points: Sequence[ScoredPoint],
    *,
    task_weights: Mapping[str, float] | None = None,
    n_resamples: int = 2000,
    confidence: float = 0.95,
    rng: int = 0,
    target_half_width: float | None = None,
) -> list[ScoredPoint]:
    """:func:`fsdvs_hw.explore.scoring.with_paired_losses`, with the tasks that cannot measure a loss
    weighted 0 and every point carrying its setting's ``"measurability"`` record.

    Parameters
    ----------
    points : sequence of ScoredPoint
        Stored points with their per-clip evidence.
    task_weights : mapping, optional
        The design's ``[scoring] task_weights`` (default: equal).
    n_resamples, confidence, rng
        Bootstrap settings.
    target_half_width : float, optional
        The design's ``[scoring] target_half_width``: where a measurable task's loss intervals are
        wider, its record gets ``clips_needed`` per network from
        :func:`fsdvs_hw.explore.sizing.size_test_sets`.

    Returns
    -------
    list of ScoredPoint
        The points with their paired losses (evidence dropped) and, in ``extra``, ``"measurability"``:
        ``{track: {task: record}}`` of :func:`task_measurability` for the point's sweep setting.
    """
    rows = [p.to_dict() for p in points]
    meas = task_measurability(rows, confidence=confidence, n_resamples=n_resamples, rng=rng)
    tasks = {t for per_track in meas.values() for per_task in per_track.values() for t in per_task}

    def weights() -> dict[str, float]:
        w = {t: float((task_weights or {}).get(t, 0.0 if task_weights else 1.0)) for t in tasks}
        for per_track in meas.values():
            for task, rec in per_track.get("simulator", {}).items():
                if not rec["measurable"]:
                    w[task] = 0.0
        return w

    w = weights() if tasks else dict(task_weights or {})
    if tasks and not any(v > 0 for v in w.values()):
        w = {}  # nothing measurable: paired_losses weighs all; the verdict ranks by kernel error
    lean = with_paired_losses(points, task_weights=w or None, n_resamples=n_resamples, confidence=confidence, rng=rng)
    out = [q.to_dict() for q in lean]
    for q in out:  # the reference against itself is 0 by construction, not a degenerate measurement
        if q["paired_loss"].get("reference") != q["key"]:
            widen_degenerate({q["key"]: q["paired_loss"]}, confidence)
    if target_half_width is not None and _widest({q["key"]: q["paired_loss"] for q in out}) > target_half_width:
        _clips_needed(rows, meas, target_half_width, confidence)
    measured = [ScoredPoint.from_dict(q) for q in out]
    return [p.with_(extra={**p.extra, "measurability": meas.get(sweep_setting(q), {})}) for p, q in zip(measured, out)]


def _widest(paired: Mapping[str, Mapping[str, Any]]) -> float:
    """The largest task-loss half-width among ``paired`` (0 when none)."""
    widths = [
        float(ci["half_width"])
        for rec in paired.values()
        if isinstance(rec, Mapping)
        for per in rec.values()
        if isinstance(per, Mapping)
        for task, ci in per.items()
        if task != "weighted" and isinstance(ci, Mapping) and "half_width" in ci
    ]
    return max(widths, default=0.0)


def _clips_needed(
    points: Sequence[Mapping[str, Any]],
    meas: Mapping[str, Mapping[str, Mapping[str, dict[str, Any]]]],
    target: float,
    confidence: float,
) -> None:
    """Add ``clips_needed`` (per network, from :func:`fsdvs_hw.explore.sizing.size_test_sets`) and
    ``half_width_target`` to the measurable tasks of a design without sweep settings."""
    from ..errors import InputError
    from .sizing import size_test_sets

    if len(meas) != 1:
        return  # a sweep: `fsdvs-hw sizing` sizes each setting
    try:
        budgets = size_test_sets(points, target_half_width=target, confidence=confidence, n_resamples=500)
    except InputError:
        return
    per_track = next(iter(meas.values()))
    for b in budgets:
        rec = per_track.get(b.track, {}).get(b.task)
        if rec is not None and rec["measurable"]:
            rec["half_width_target"] = target
            rec["clips_needed"] = b.n_clips
            rec["clips_now"] = b.n_pilot
