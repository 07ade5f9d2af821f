"""Every explored point's task losses at equal event rate (the ``[rate]`` section of a design).

A realisation that fires more events than the kernel it realises can look better, or lose less,
for the same reason a plain DVS with a lowered threshold looks better: more events, not a better
filter. :func:`with_matched_rates` gives every scored point two comparisons at its **own event
rate**, each with a percentile bootstrap CI over (network, clips) clusters that carries the
uncertainty of both axes (:func:`fsdvs_hw.explore.rate.matched_rate_difference`):

``loss_at_matched_rate`` (reference ``learned``)
    ``metric(learned kernel at the point's event rate) − metric(point)``: the point's accuracy loss
    once the learned kernel's threshold is moved until it fires as many events as the point.
    Beside the raw loss (same threshold) it tells a loss from filtering apart from a loss from
    firing fewer events.
``gain_over_plain_dvs_at_matched_rate`` (reference ``delta``)
    ``metric(point) − metric(plain DVS at the point's event rate)``: does the realisation beat a
    plain DVS (the w/o 1×1 delta) whose threshold is lowered to give the same event rate? The
    paper's bandwidth-matched control, per point.

The reference curves are measured in the same networks, on the same clips and noise draws as the
points (:func:`fsdvs_hw.explore.rate.rate_curve`), at the design's ``[rate] thresholds``; the
points of ``learned`` and ``delta`` at the operating threshold are taken from the exploration
itself. Each curve point is saved under ``OUT/rate_curves/`` as it finishes and reused by a rerun
(resume). A point's rate outside a curve's measured range is refused, never extrapolated
(``status`` says which thresholds to add).

Example
-------
In a design file::

    [rate]
    enabled = true
    thresholds = [0.1, 0.125, 0.15, 0.3]   # besides the operating threshold (0.2)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..design import Design
from ..errors import InputError
from ..fingerprints import text_fingerprint
from ..records import ScoredPoint
from .paired import EVENT_RATE_UNIT, decode_evidence
from .rate import MatchedRateDifference, RateCurve, RatePoint, dataset_rate_curve, matched_rate_difference, rate_curve
from .scoring import DESIGN_SENSOR_FIELDS, sweep_setting

__all__ = [
    "CURVES_DIR",
    "REFERENCES",
    "matched_rate_records",
    "point_rate_curve",
    "reference_curves",
    "with_matched_rates",
]

#: Folder (under the exploration's output) of the saved reference-curve points.
CURVES_DIR = "rate_curves"

#: Reference name → what its comparison is called in a point's record.
REFERENCES: dict[str, str] = {"learned": "loss_at_matched_rate", "delta": "gain_over_plain_dvs_at_matched_rate"}

_TRACK = "simulator"  # the emulation track's display and recapture have no threshold to move


def _track(point: Mapping[str, Any], task: str) -> Mapping[str, Any]:
    entry = ((point.get("result") or {}).get("tasks") or {}).get(task)
    rec = entry.get(_TRACK) if isinstance(entry, Mapping) else None
    return rec if isinstance(rec, Mapping) else {}


def _operating_threshold(rec: Mapping[str, Any]) -> float | None:
    """The ON = OFF threshold a track was scored at (None when ON ≠ OFF or unrecorded)."""
    sensor = rec.get("sensor") or {}
    on, off = sensor.get("threshold_on"), sensor.get("threshold_off")
    if not isinstance(on, (int, float)) or on != off:
        return None
    return float(on)


def point_rate_curve(point: Mapping[str, Any], task: str) -> RateCurve | str:
    """One stored point's simulator-track score as a one-point :class:`~fsdvs_hw.explore.rate.RateCurve`.

    Parameters
    ----------
    point : mapping
        A stored design point (``results.sqlite`` row) whose task record keeps its per-clip
        ``evidence`` and ``clip_event_rates``.
    task : str

    Returns
    -------
    RateCurve or str
        The curve, or why there is none (no per-clip rates stored, ON ≠ OFF thresholds, …).

    Examples
    --------
    >>> point_rate_curve({"key": "k", "result": {"tasks": {}}}, "detection")
    "no 'detection' simulator-track score"
    """
    rec = _track(point, task)
    if rec.get("status") != "ok":
        return f"no {task!r} simulator-track score"
    if not rec.get("evidence") or not rec.get("clip_event_rates"):
        return "no per-clip evidence and event rates stored (points scored before matched rates existed: rerun them)"
    threshold = _operating_threshold(rec)
    if threshold is None:
        return "scored with ON ≠ OFF thresholds (a rate curve moves both together)"
    rates = np.asarray(rec["clip_event_rates"], dtype=np.float64)
    rp = RatePoint(
        threshold=threshold,
        metrics=tuple(decode_evidence(e) for e in rec["evidence"]),
        clip_rates=rates,
        test_seeds=tuple(int(s) for s in rec.get("test_seeds", ())),
        sensor_seeds=tuple(int(s) for s in rec.get("sensor_seeds", ())),
    )
    return RateCurve(
        kernel_name=str(point.get("realisation", "point")),
        task=task,
        metric_name=str(rec.get("metric_name", "")),
        test_clips=str(rec.get("test_clips", "per_network")),
        points=(rp,),
        checkpoints=tuple(Path(c).name for c in rec.get("checkpoints", ())),
    )


def _design_points(design: Design) -> dict[str, Any]:
    from .sweep import expand_points

    return {p.key: p for p in expand_points(design)}


def _reference_kernel(dpoint: Any) -> Any:
    """The kernel a reference point was scored with (``learned``: the target; ``delta``: its delta)."""
    from ..kernels import Kernel
    from .scoring import fit_realisation

    target = Kernel.from_dict(dpoint.target, source="design point target")
    real, _ = fit_realisation(dpoint.realisation, target, {}, seed=dpoint.spec.run.seed)
    return real.kernel()


def reference_curves(
    design: Design, points: Sequence[Mapping[str, Any]], out_dir: str | Path, *, progress: bool | None = None
) -> dict[str, dict[str, dict[str, RateCurve | str]]]:
    """Measure the reference kernels' rate curves of every sweep setting and task.

    Parameters
    ----------
    design : fsdvs_hw.design.Design
        With ``[rate]`` (thresholds, references) and ``[tasks]``.
    points : sequence of mapping
        The exploration's stored points (with per-clip evidence): the references' points at the
        operating threshold are taken from them.
    out_dir : path
        The exploration's output folder; curve points are saved under ``out_dir/rate_curves/``.
    progress : bool, optional
        Progress bars (:mod:`fsdvs_hw.progress`).

    Returns
    -------
    dict
        ``{sweep setting: {task: {reference: RateCurve or the reason there is none}}}``.
    """
    spec = design.spec.rate
    by_key = _design_points(design)
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for p in points:
        if p.get("status") == "ok":
            groups.setdefault(sweep_setting(p), []).append(p)
    out: dict[str, dict[str, dict[str, RateCurve | str]]] = {}
    for ctx, group in groups.items():
        tag = text_fingerprint(ctx, length=10)
        out[ctx] = {}
        tasks = dict.fromkeys(t for p in group for t in ((p.get("result") or {}).get("tasks") or {}) if _track(p, t))
        for task in tasks:
            out[ctx][task] = {}
            for ref in spec.references:
                row = next((p for p in group if p["realisation"] == ref), None)
                if row is None or row["key"] not in by_key:
                    out[ctx][task][ref] = f"no {ref!r} point in this sweep setting (add it to [realisations] include)"
                    continue
                out[ctx][task][ref] = _one_curve(
                    design,
                    by_key[row["key"]],
                    row,
                    task,
                    spec.thresholds,
                    Path(out_dir) / CURVES_DIR / tag / task,
                    progress,
                )
    return out


def _one_curve(
    design: Design,
    dpoint: Any,
    row: Mapping[str, Any],
    task: str,
    thresholds: Sequence[float],
    cache: Path,
    progress: bool | None,
) -> RateCurve | str:
    own = point_rate_curve(row, task)
    rec = _track(row, task)
    t0 = _operating_threshold(rec)
    if t0 is None:
        return own if isinstance(own, str) else "no operating threshold recorded"
    extra = sorted({float(t) for t in thresholds} - {t0})
    if not extra:
        return f"[rate] thresholds add nothing to the operating threshold {t0:g}"
    run = extra if (len(extra) >= 2 and not isinstance(own, str)) else [*extra, t0]
    tasks = dpoint.spec.tasks
    base = Path(dpoint.base_dir)
    user = tasks.datasets.get(task)
    if user is not None:  # a user-data task: the user's network and clips, as the point was scored
        sensor = dpoint.spec.sensor.model_dump()
        fields = {k: sensor[k] for k in DESIGN_SENSOR_FIELDS} if tasks.sensor == "design" else None
        try:
            curve = dataset_rate_curve(
                _reference_kernel(dpoint),
                task,
                user.model_dump(),
                base,
                run,
                design_sensor=fields,
                test_clips=str(rec.get("test_clips", "per_network")),
                label=dpoint.realisation,
                cache_dir=cache,
                progress=progress,
                confine=False,
            )
        except (InputError, FileNotFoundError) as exc:
            return f"unavailable: {exc}"
        return _with_own_point(curve, own, t0)
    entry = tasks.checkpoints.get(task, [])  # resolved as the point was (sweep._fit_and_score)
    ckpts = [Path(c) if Path(c).is_absolute() else base / c for c in (entry if isinstance(entry, list) else [entry])]
    n_test = int(rec.get("n_clips_per_network", 0)) or None
    try:
        curve = rate_curve(
            _reference_kernel(dpoint),
            task,
            ckpts,
            run,
            n_test=n_test,
            design_sensor=dpoint.spec.sensor.model_dump() if tasks.sensor == "design" else None,
            test_clips=str(rec.get("test_clips", "per_network")),
            label=dpoint.realisation,
            cache_dir=cache,
            progress=progress,
        )
    except (InputError, FileNotFoundError) as exc:
        return f"unavailable: {exc}"
    return _with_own_point(curve, own, t0)


def _with_own_point(curve: RateCurve, own: RateCurve | str, t0: float) -> RateCurve:
    """``curve`` plus the point's own score at the operating threshold ``t0`` (when not measured again)."""
    if isinstance(own, RateCurve) and t0 not in curve.thresholds:
        curve = RateCurve(
            kernel_name=curve.kernel_name,
            task=curve.task,
            metric_name=curve.metric_name,
            test_clips=curve.test_clips,
            points=curve.points + own.points,
            checkpoints=curve.checkpoints,
        )
    return curve


def _as_loss(d: MatchedRateDifference) -> dict[str, Any]:
    """``point − learned at its rate`` turned into a loss ``learned at its rate − point`` (bounds swapped)."""
    rec = d.to_dict()
    for a, lo, hi in (("estimate", "low", "high"), ("raw_estimate", "raw_low", "raw_high")):
        rec[a], rec[lo], rec[hi] = -rec[a], -rec[hi], -rec[lo]
    return rec


def _text(rec: Mapping[str, Any], digits: int = 3) -> str:
    if rec.get("status") != "ok":
        return str(rec.get("status", ""))
    return (
        f"{rec['estimate']:+.{digits}f} [{rec['low']:+.{digits}f}, {rec['high']:+.{digits}f}] "
        f"{rec['metric_name']} at {rec['reference_rate']:.3g} {EVENT_RATE_UNIT} (reference threshold "
        f"{rec['matched_threshold']:.3g}); same threshold {rec['raw_estimate']:+.{digits}f}"
    )


def matched_rate_records(
    points: Sequence[Mapping[str, Any]],
    curves: Mapping[str, Mapping[str, Mapping[str, RateCurve | str]]],
    *,
    confidence: float = 0.95,
    n_resamples: int = 2000,
    rng: int = 0,
) -> dict[str, dict[str, Any]]:
    """Every point's matched-rate comparisons against the reference curves of its sweep setting.

    Parameters
    ----------
    points : sequence of mapping
        Stored points (with per-clip evidence and event rates).
    curves : mapping
        :func:`reference_curves`.
    confidence, n_resamples, rng
        Bootstrap settings (every point shares the draws).

    Returns
    -------
    dict
        ``{point key: {"status", task: {"event_rate_per_s", "point" (its rate and metric with CIs,
        :meth:`~fsdvs_hw.explore.rate.RateCurve.summary`), REFERENCES[ref]: record with
        estimate/low/high/status/text, ..., "curve" (on a reference's own row: its curve summary)}}}``.
    """
    out: dict[str, dict[str, Any]] = {}
    for p in points:
        if p.get("status") != "ok":
            continue
        per_task = curves.get(sweep_setting(p), {})
        rec: dict[str, Any] = {"status": "ok" if per_task else "no reference curves in this sweep setting"}
        for task, refs in per_task.items():
            own = point_rate_curve(p, task)
            entry: dict[str, Any] = {"event_rate_per_s": dict(_track(p, task).get("event_rate_per_s") or {})}
            if not isinstance(own, str):  # the point itself: rate and metric with their CIs (the report's figure)
                entry["point"] = own.summary(confidence=confidence, n_resamples=n_resamples, rng=rng)[0]
            for ref, curve in refs.items():
                name = REFERENCES[ref]
                if isinstance(curve, str) or isinstance(own, str):
                    why = curve if isinstance(curve, str) else str(own)
                    entry[name] = {"status": why if why.startswith("unavailable") else f"unavailable: {why}"}
                    continue
                try:
                    d = matched_rate_difference(
                        curve, own, own.points[0].threshold, confidence=confidence, n_resamples=n_resamples, rng=rng
                    )
                except InputError as exc:
                    entry[name] = {"status": f"unavailable: {exc}"}
                    continue
                one = _as_loss(d) if ref == "learned" else d.to_dict()
                one["text"] = _text(one)
                entry[name] = one
                if p["realisation"] == ref:
                    entry["curve"] = curve.summary(confidence=confidence, n_resamples=n_resamples, rng=rng)
            rec[task] = entry
        comparisons = [e[n] for e in rec.values() if isinstance(e, Mapping) for n in REFERENCES.values() if n in e]
        if comparisons and not any(c.get("status") == "ok" for c in comparisons):
            rec["status"] = f"no comparison: {comparisons[0].get('status')}"
        out[p["key"]] = rec
    return out


def with_matched_rates(
    points: Sequence[ScoredPoint], design: Design, out_dir: str | Path, *, progress: bool | None = None
) -> list[ScoredPoint]:
    """Copies of ``points`` with ``"matched_rate"`` (:func:`matched_rate_records`) in their ``extra``
    when the design's ``[rate] enabled``; otherwise each carries ``{"status": "not requested"}``.

    Parameters
    ----------
    points : sequence of ScoredPoint
        Stored points, before the per-clip evidence is dropped.
    design : fsdvs_hw.design.Design
    out_dir : path
        The exploration's output folder (curve points saved under ``rate_curves/``).
    progress : bool, optional

    Returns
    -------
    list of ScoredPoint
    """
    if not design.spec.rate.enabled:
        off = {"status": "not requested ([rate] enabled = false)"}
        return [p.with_(extra={**p.extra, "matched_rate": off}) for p in points]
    sc = design.spec.scoring
    rows = [p.to_dict() for p in points]
    curves = reference_curves(design, rows, out_dir, progress=progress)
    recs = matched_rate_records(
        rows, curves, confidence=sc.confidence, n_resamples=sc.n_resamples, rng=design.spec.run.seed
    )
    return [p.with_(extra={**p.extra, "matched_rate": recs.get(p.key, {"status": "not scored"})}) for p in points]
