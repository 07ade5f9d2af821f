"""Score tables: flatten stored design points into one row each, write CSV and JSON.

A scored point (:class:`fsdvs_hw.records.ScoredPoint`) carries a :class:`fsdvs_hw.records.Score`
and its paired task losses with bootstrap CIs (:class:`fsdvs_hw.records.PairedLoss`, attached by
the explore layer); the
tables flatten both to named columns with units in the names (``fit_s``, ``cost_area_m2``), give
each kind of realisation its own cost axis in its own unit (declared in its registry entry,
:class:`fsdvs_hw.realise.registry.CostSpec`), and mark the points that no other point
dominates *beyond the uncertainty* of the losses (:func:`uncertain_pareto_front`), within each
kind (loss, CSF agreement, the kind's cost) and across kinds (loss, CSF agreement).

Loss columns, for every task ``T`` (simulator track; the emulation track has the prefix ``emu_``):
``T_loss`` (metric of the learned kernel − metric of the realisation, a fraction; positive =
accuracy lost), ``T_loss_ci95_low``, ``T_loss_ci95_high``, ``T_loss_half_width``, ``T_n_clips``,
``T_n_seeds``, ``T_loss_text`` (``"0.021 [0.012, 0.030]"`` or ``"no measurable loss (± 0.008)"``
when the CI contains 0) and the same for ``weighted_loss`` (``[scoring] task_weights``).
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..paths import write_output
from ..realise.registry import REALISATIONS
from ..records import PairedLoss, ScoredPoint

__all__ = [
    "TRACK_PREFIX",
    "accuracy_axis",
    "headline_cost",
    "is_reference",
    "kind_cost",
    "loss_interval",
    "networks_note",
    "pareto_front",
    "score_rows",
    "summary_markdown",
    "uncertain_pareto_front",
    "verdict_markdown",
    "verdict_rows",
    "write_scores",
]

#: Column prefix of each task track (the simulator track is unprefixed).
TRACK_PREFIX: dict[str, str] = {"simulator": "", "emulation": "emu_"}


def is_reference(name: str) -> bool:
    """Whether the realisation ``name`` is an ideal reference (no cost; never on a front)."""
    return name in REALISATIONS and REALISATIONS[name].kind == "reference"


def headline_cost(cost: Mapping[str, Mapping[str, Any]], kind: str | None = None) -> tuple[str, float, str] | None:
    """``(name, value, unit)`` of the cost item that best summarises a realisation, or None.

    The first of the realisation's declared headline items (:class:`~fsdvs_hw.realise.registry.CostSpec`
    with ``headline=True``) present in ``cost``; else its first item.
    """
    if not cost:
        return None
    spec = REALISATIONS.get(kind) if kind is not None else None
    name = (spec.headline(cost) if spec is not None else None) or next(iter(cost))
    item = cost[name]
    return name, float(item["value"]), str(item.get("unit", ""))


def kind_cost(kind: str, cost: Mapping[str, Mapping[str, Any]]) -> tuple[str, float, str] | None:
    """``(label, value, unit)`` on the kind's own cost axis, in its display unit, or None.

    The first of the realisation's declared Pareto items present in ``cost``
    (:meth:`fsdvs_hw.realise.registry.RealisationSpec.cost_axis`); None for an unregistered kind
    or a reference.
    """
    spec = REALISATIONS.get(kind)
    return spec.cost_axis(cost) if spec is not None else None


def _num(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def score_rows(points: Iterable[ScoredPoint], *, primary_csf: str = "mannos_sakrison_1974") -> list[dict[str, Any]]:
    """One flat dict per stored point (see the module docstring); stable column names.

    Columns: ``point, realisation, params, status, reason, kernel_error, kernel_error_gain_free,
    dc_gain, peak_frequency_cpp, response_kind, csf_<method>_{correlation,peak_ratio,log_rms_dec},
    csf_fitted_{correlation,rms_error,ppd}, metric_<task>/<track>``, the loss columns of the module
    docstring, ``loss_status, emu_event_ratio, emu_signed_correlation, emu_clipped_black,
    cost_<name>, headline_cost, headline_cost_value, headline_cost_unit, kind_cost, kind_cost_value,
    kind_cost_unit, fit_s, analysis_s, tasks_s, emulation_s, point_s, pareto`` (within the kind)
    and ``pareto_all`` (across kinds on loss vs CSF agreement).
    """
    rows: list[dict[str, Any]] = []
    for p in points:
        params = dict(p.params)
        label = p.realisation + (
            "" if not params else " " + ", ".join(f"{k.split('.')[-1]}={v}" for k, v in params.items())
        )
        res = p.score
        row: dict[str, Any] = {
            "point": label,
            "key": p.key,
            "realisation": p.realisation,
            "params": json.dumps(params, sort_keys=True),
            "status": p.status,
            "reason": p.reason,
            "warnings": " | ".join(res.warnings if res is not None else p.failure.get("warnings", [])),
        }
        if p.ok and res is not None:
            row["kernel_error"] = _num(res.kernel_error)
            row["kernel_error_gain_free"] = _num(res.kernel_error_gain_free)
            row["dc_gain"] = _num(res.dc_gain)
            row["peak_frequency_cpp"] = _num(res.spectral.get("peak_frequency_cpp"))
            row["response_kind"] = res.spectral.get("kind", "")
            for method, m in res.csf.items():
                if not isinstance(m, Mapping):
                    continue
                if method == "fitted_scale":
                    row["csf_fitted_correlation"] = _num(m.get("correlation"))
                    row["csf_fitted_rms_error"] = _num(m.get("rms_error"))
                    row["csf_fitted_ppd"] = _num(m.get("pixels_per_degree"))
                    continue
                row[f"csf_{method}_correlation"] = _num(m.get("correlation"))
                row[f"csf_{method}_peak_ratio"] = _num(m.get("peak_ratio"))
                row[f"csf_{method}_log_rms_dec"] = _num(m.get("log_rms_error_dec"))
            row["csf_agreement"] = row.get(f"csf_{primary_csf}_correlation", math.nan)
            row["tasks_status"] = res.tasks.status
            for name, metric in res.tasks.metrics().items():
                row[f"metric_{name}"] = _num(metric)
            _loss_columns(row, p.paired_loss)
            _rate_columns(row, res, p.extra.get("matched_rate") or {})
            _measurability_columns(row, p.extra.get("measurability") or {})
            emu = res.emulation
            row["emulation_status"] = emu.get("status", "")
            if emu.get("status") == "ok":
                row["emu_event_ratio"] = _num(emu.get("event_ratio"))
                row["emu_signed_correlation"] = _num(emu.get("signed_correlation"))
                row["emu_clipped_black"] = _num(emu.get("clipped_black"))
            cost = res.cost.to_dict()
            for name in res.cost.items:
                row[f"cost_{name}"] = res.cost.value(name)
            head = headline_cost(cost, p.realisation)
            row["headline_cost"], row["headline_cost_value"], row["headline_cost_unit"] = head or ("", math.nan, "")
            own = kind_cost(p.realisation, cost)
            row["kind_cost"], row["kind_cost_value"], row["kind_cost_unit"] = own or ("", math.nan, "")
            row["fit_s"] = _num(res.wall.fit_s)
            row["analysis_s"] = _num(res.wall.analysis_s)
            row["tasks_s"] = _num(res.wall.tasks_s)
            row["emulation_s"] = _num(res.wall.emulation_s)
        row["point_s"] = _num(p.wall_s)
        rows.append(row)
    _mark_pareto(rows)
    return rows


def _ci_tag(confidence: float) -> str:
    return f"ci{round(100 * confidence):d}"


def _loss_columns(row: dict[str, Any], paired: PairedLoss | None) -> None:
    """Flatten one point's paired losses into the loss columns (module docstring)."""
    row["loss_status"] = paired.status if paired is not None and paired.status is not None else "not scored"
    if paired is not None and paired.reference:
        row["loss_reference"] = paired.reference
    for track, prefix in TRACK_PREFIX.items():
        per = paired.tracks.get(track) if paired is not None else None
        if not isinstance(per, Mapping):
            continue
        if "status" in per and len(per) == 1:
            row[f"{prefix}loss_status"] = per["status"]
            continue
        for task, ci in per.items():
            if not isinstance(ci, Mapping) or "estimate" not in ci:
                continue
            name = f"{prefix}{task}"
            tag = _ci_tag(float(ci["confidence"]))
            row[f"{name}_loss"] = float(ci["estimate"])
            row[f"{name}_loss_{tag}_low"] = float(ci["low"])
            row[f"{name}_loss_{tag}_high"] = float(ci["high"])
            row[f"{name}_loss_half_width"] = float(ci["half_width"])
            row[f"{name}_n_clips"] = int(ci["n_clips"])
            row[f"{name}_n_seeds"] = int(ci["n_seeds_reference"])
            row[f"{name}_loss_text"] = str(ci.get("text", ""))


#: Matched-rate comparison (:data:`fsdvs_hw.explore.matched.REFERENCES`) → its column stem.
MATCHED_COLUMNS: dict[str, str] = {
    "loss_at_matched_rate": "loss_at_matched_rate",
    "gain_over_plain_dvs_at_matched_rate": "gain_over_plain_dvs_at_matched_rate",
}


def _rate_columns(row: dict[str, Any], res: Any, matched: Mapping[str, Any]) -> None:
    """Event rate (simulator track, events/pixel/s with its CI) and the matched-rate comparisons.

    Columns per task ``T``: ``T_event_rate_eps_per_px`` with ``_ci95_low``/``_ci95_high``;
    ``T_loss_at_matched_rate`` (learned kernel at the point's event rate − point) and
    ``T_gain_over_plain_dvs_at_matched_rate`` (point − plain DVS at the point's event rate), each
    with ``_ci95_low``, ``_ci95_high``, ``_status``, ``_text`` and the reference's threshold at
    that rate (``_threshold``); ``matched_rate_status`` says why there are none.
    """
    for task, tracks in res.tasks.tracks.items():
        tr = tracks.get("simulator")
        ci = (tr.extra.get("event_rate_per_s") or {}) if tr is not None and tr.ok else {}
        if "mean" in ci:
            tag = _ci_tag(float(ci.get("confidence", 0.95)))
            row[f"{task}_event_rate_eps_per_px"] = float(ci["mean"])
            row[f"{task}_event_rate_eps_per_px_{tag}_low"] = float(ci["low"])
            row[f"{task}_event_rate_eps_per_px_{tag}_high"] = float(ci["high"])
    row["matched_rate_status"] = str(matched.get("status", "not requested"))
    for task, entry in matched.items():
        if not isinstance(entry, Mapping):
            continue
        for name, stem in MATCHED_COLUMNS.items():
            rec = entry.get(name)
            if not isinstance(rec, Mapping):
                continue
            col = f"{task}_{stem}"
            row[f"{col}_status"] = str(rec.get("status", ""))
            if rec.get("status") == "ok":
                tag = _ci_tag(float(rec["confidence"]))
                row[col] = float(rec["estimate"])
                row[f"{col}_{tag}_low"] = float(rec["low"])
                row[f"{col}_{tag}_high"] = float(rec["high"])
                row[f"{col}_threshold"] = float(rec["matched_threshold"])
                if "raw_estimate" in rec:  # the same comparison at the same threshold
                    row[f"{col}_raw"] = float(rec["raw_estimate"])
            row[f"{col}_text"] = str(rec.get("text", rec.get("status", "")))


def _measurability_columns(row: dict[str, Any], meas: Mapping[str, Any]) -> None:
    """Per task ``T`` (simulator track; ``emu_T`` for emulation): ``T_chance`` (the metric of a
    predictor that learned nothing, same clips), ``T_reference_metric``, ``T_measurable`` and
    ``T_not_measurable`` (the reason); a task that cannot measure gets ``T_loss_text`` "not
    measurable: …". ``measurable_tasks`` lists the simulator-track tasks that can (space-separated;
    absent when no measurability was assessed)."""
    if not meas:
        return
    for track, prefix in TRACK_PREFIX.items():
        for task, rec in (meas.get(track) or {}).items():
            if not isinstance(rec, Mapping):
                continue
            name = f"{prefix}{task}"
            row[f"{name}_chance"] = _num(rec.get("chance"))
            row[f"{name}_reference_metric"] = _num(rec.get("reference_metric"))
            row[f"{name}_measurable"] = bool(rec.get("measurable"))
            if not rec.get("measurable"):
                row[f"{name}_not_measurable"] = str(rec.get("reason", ""))
                if f"{name}_loss" in row:
                    row[f"{name}_loss_text"] = "not measurable"
    row["_measurability"] = meas  # the whole record, for the report's table (not a CSV column)
    sim = meas.get("simulator") or {}
    row["measurable_tasks"] = " ".join(
        t for t, rec in sim.items() if isinstance(rec, Mapping) and rec.get("measurable")
    )


def loss_interval(row: Mapping[str, Any], column: str) -> tuple[float, float, float]:
    """``(estimate, low, high)`` of a loss column (low = high = estimate where it has no CI)."""
    v = _num(row.get(column))
    base = column[: -len("_loss")] if column.endswith("_loss") else column
    lows = [k for k in row if k.startswith(f"{base}_loss_ci") and k.endswith("_low")]
    if not lows:
        return v, v, v
    return v, _num(row[lows[0]]), _num(row[lows[0][: -len("_low")] + "_high"])


def _is_task_loss(column: str) -> bool:
    """A task-loss column (``detection_loss``, ``emu_weighted_loss``), not a hardware cost item
    whose name ends in ``_loss`` (flattened as ``cost_<name>``, e.g. the metalens pedestal's
    ``cost_contrast_loss``)."""
    return column.endswith("_loss") and not column.startswith("cost_")


def accuracy_axis(rows: Sequence[Mapping[str, Any]]) -> tuple[str, str]:
    """The column used as 'accuracy loss': the weighted task loss (simulator), else the first task
    loss, else kernel error when no task ran."""
    keys = list(dict.fromkeys(k for r in rows for k in r))
    assessed = [r for r in rows if "measurable_tasks" in r]
    if assessed and not any(str(r["measurable_tasks"]).strip() for r in assessed):
        return "kernel_error", "kernel error (relative L2; no task could measure an accuracy loss)"
    if "weighted_loss" in keys:
        return "weighted_loss", "weighted task loss (learned − realised, simulator)"
    for k in keys:
        if _is_task_loss(k) and not k.startswith("emu_"):
            return k, f"accuracy loss ({k[:-5]}, learned − realised)"
    return "kernel_error", "kernel error (relative L2; no task evaluator ran)"


def pareto_front(values: Sequence[Sequence[float]]) -> list[bool]:
    """Non-dominated flags for points given as tuples to *minimise* (NaN rows are never optimal).

    A point is dominated when another is no worse in every objective and better in one.
    """
    vals = [tuple(float(v) for v in row) for row in values]
    flags = []
    for i, a in enumerate(vals):
        if any(math.isnan(x) for x in a):
            flags.append(False)
            continue
        dominated = any(
            j != i
            and not any(math.isnan(x) for x in b)
            and all(x <= y for x, y in zip(b, a))
            and any(x < y for x, y in zip(b, a))
            for j, b in enumerate(vals)
        )
        flags.append(not dominated)
    return flags


def uncertain_pareto_front(objectives: Sequence[Sequence[tuple[float, float, float]]]) -> list[bool]:
    """Non-dominated flags where objectives (to *minimise*) carry confidence intervals.

    Each point is a sequence of ``(estimate, low, high)`` per objective (``low = high = estimate``
    for an exact objective such as a cost). Point ``b`` dominates ``a`` only *beyond the
    uncertainty*: in every objective ``b`` is at least as good as ``a`` even at the unfavourable
    ends of both intervals (``b.high <= a.low``), and strictly better in one (``b.high < a.low``).
    For exact objectives this is the usual Pareto dominance. Two realisations whose loss intervals
    overlap are never ranked by their point estimates: neither dominates the other on loss, so both
    stay unless something else decides; a wide interval protects its point and dominates nothing.
    Rows with a NaN are never optimal and dominate nothing.
    """
    pts = [[(float(e), float(lo), float(hi)) for e, lo, hi in row] for row in objectives]
    bad = [any(math.isnan(x) for o in row for x in o) for row in pts]

    def dominates(b: list[tuple[float, float, float]], a: list[tuple[float, float, float]]) -> bool:
        no_worse = all(ob[2] <= oa[1] for ob, oa in zip(b, a))
        better = any(ob[2] < oa[1] for ob, oa in zip(b, a))
        return no_worse and better

    return [
        not bad[i] and not any(j != i and not bad[j] and dominates(pts[j], pts[i]) for j in range(len(pts)))
        for i in range(len(pts))
    ]


def _mark_pareto(rows: list[dict[str, Any]]) -> None:
    """Mark the uncertainty-aware fronts (:func:`uncertain_pareto_front`).

    ``pareto``: within each hardware kind over (accuracy loss ↓ with its CI, Mannos–Sakrison
    agreement at the fitted scale ↑, the kind's own cost ↓ in its own unit: :func:`kind_cost`);
    ideal references (learned, delta) have no cost and are not on a per-kind front.
    ``pareto_all``: across every hardware realisation over (accuracy loss ↓, agreement ↑); costs of
    different kinds never share an axis. The ideal references (:func:`is_reference`) are shown
    for comparison and are on neither front.
    """
    acc, _ = accuracy_axis(rows)
    for r in rows:
        r["pareto"] = False
        r["pareto_all"] = False
    ok = [r for r in rows if r["status"] == "ok"]

    def agreement(r: Mapping[str, Any]) -> tuple[float, float, float]:
        v = -_num(r.get("csf_fitted_correlation", r.get("csf_agreement")))
        return v, v, v

    hardware = [r for r in ok if not is_reference(r["realisation"])]
    for r, f in zip(hardware, uncertain_pareto_front([(loss_interval(r, acc), agreement(r)) for r in hardware])):
        r["pareto_all"] = f
    for kind in dict.fromkeys(r["realisation"] for r in ok):
        group = [r for r in ok if r["realisation"] == kind and not math.isnan(_num(r.get("kind_cost_value")))]
        objs = [(loss_interval(r, acc), agreement(r), (r["kind_cost_value"],) * 3) for r in group]
        for r, f in zip(group, uncertain_pareto_front(objs)):
            r["pareto"] = f


def write_scores(
    rows: Sequence[Mapping[str, Any]],
    out_dir: str | Path,
    *,
    stem: str = "scores",
    full: Sequence[Mapping[str, Any]] | None = None,
    design: Mapping[str, Any] | None = None,
) -> tuple[Path, Path]:
    """Write ``<stem>.csv`` (flat rows) and ``<stem>.json`` (flat rows plus full records) to ``out_dir``.

    ``design`` (``{"name", "fingerprint", "data"}`` of the design the points came from) is kept in
    the JSON file so that a report redrawn later can refuse another design. Both files are written
    atomically and never through a symbolic link (:func:`fsdvs_hw.paths.write_output`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]  # "_x": the report's own
    columns: list[str] = []
    for r in rows:
        columns.extend(k for k in r if k not in columns)
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=columns, restval="")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()})
    # atomically, never through a symbolic link planted in the folder (fsdvs_hw.paths.write_output)
    csv_path = write_output(out / f"{stem}.csv", buf.getvalue())
    clean = [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()} for r in rows]
    blob: dict[str, Any] = {"rows": clean, "points": list(full or [])}
    if design is not None:
        blob["design"] = dict(design)
    json_path = write_output(out / f"{stem}.json", json.dumps(blob, indent=1, default=str) + "\n")
    return csv_path, json_path


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else ""
    if isinstance(v, float):
        return "–" if math.isnan(v) else f"{v:.3g}"
    return str(v)


def _loss_tasks(rows: Sequence[Mapping[str, Any]], prefix: str = "") -> list[str]:
    """Task names with a loss column on a track (``weighted`` last)."""
    names = [
        k[len(prefix) : -len("_loss")]
        for r in rows
        for k in r
        if _is_task_loss(k) and k.startswith(prefix) and (prefix or not k.startswith("emu_"))
    ]
    names = list(dict.fromkeys(names))
    return [n for n in names if n != "weighted"] + (["weighted"] if "weighted" in names else [])


def verdict_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, str]]:
    """The verdict table: one row per scored realisation, every cell a display string.

    Columns: ``realisation``; per task (simulator track) the loss with its CI, or "no measurable
    loss (± h)" when the CI contains 0; the weighted task loss; the emulation track's weighted loss;
    Mannos–Sakrison agreement at the fitted viewing scale (the headline) and at the design's
    geometry (labelled); the cost on the kind's own axis in its own unit; the fronts it is on.
    """
    ok = [r for r in rows if r["status"] == "ok"]
    tasks = _loss_tasks(ok)
    emu = "emu_weighted_loss_text" if any("emu_weighted_loss_text" in r for r in ok) else None
    out = []
    for r in ok:
        v: dict[str, str] = {"realisation": str(r["point"])}
        is_ref = r.get("key") is not None and r.get("key") == r.get("loss_reference")
        for t in tasks:
            if is_ref:
                v[f"{t} loss"] = "0 (the reference)"
                continue
            n = r.get(f"{t}_n_clips")
            v[f"{t} loss"] = str(r.get(f"{t}_loss_text", "–"))
            if t != "weighted" and n:
                v[f"{t} loss"] += f" (n={n}, seeds={r.get(f'{t}_n_seeds')})"
        if emu:
            v["emulation weighted loss"] = "0 (the reference)" if is_ref else str(r.get(emu, "–"))
        v["MS agreement, fitted scale"] = _fmt(_num(r.get("csf_fitted_correlation")))
        v["MS agreement, design geometry"] = _fmt(_num(r.get("csf_agreement")))
        if r.get("kind_cost"):
            v["cost (own unit)"] = f"{r['kind_cost']} {_num(r['kind_cost_value']):.4g} {r['kind_cost_unit']}"
        else:
            v["cost (own unit)"] = "– (ideal reference)"
        if is_reference(r["realisation"]):
            v["Pareto"] = "reference"
        else:
            fronts = [
                name for name, flag in (("within kind", r.get("pareto")), ("across kinds", r.get("pareto_all"))) if flag
            ]
            v["Pareto"] = ", ".join(fronts) if fronts else "dominated"
        out.append(v)
    return out


def verdict_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """:func:`verdict_rows` as a Markdown table."""
    vr = verdict_rows(rows)
    if not vr:
        return "(no scored realisation)"
    cols = list(dict.fromkeys(k for r in vr for k in r))
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(r.get(c, "–") for c in cols) + " |" for r in vr]
    return "\n".join(lines)


def summary_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """What ``explore`` prints: the verdict table, then points that were not scored."""
    text = verdict_markdown(rows)
    missing = [r for r in rows if r["status"] != "ok"]
    if missing:
        text += "\n\nnot scored: " + "; ".join(f"{r['point']} ({r['status']}: {r.get('reason', '')})" for r in missing)
    return text


def networks_note(points: Sequence[ScoredPoint]) -> str:
    """Which networks each task's loss is measured in, as one sentence per task.

    ``"detection: 3 networks (training seeds 0, 1, 2) trained with the kernel being realised (kernel
    frozen while training); ..."``, read from the ``networks`` records of the stored points.
    """
    seen: dict[str, list[Mapping[str, Any]]] = {}
    for p in points:
        if p.score is None:
            continue
        for task, tracks in p.score.tasks.tracks.items():
            if task in seen:
                continue
            for rec in tracks.values():
                if isinstance(rec.extra.get("networks"), list):
                    seen[task] = rec.extra["networks"]
                    break
    parts = []
    for task, nets in seen.items():
        good = [n for n in nets if "checkpoint" in n]
        if not good:
            continue
        same = {n.get("trained_with_target") for n in good}
        how = (
            "trained with the kernel being realised"
            if same == {True}
            else "NOT trained with the kernel being realised (trained with: "
            + ", ".join(sorted({str(n.get("training_kernel")) for n in good}))
            + ")"
            if same == {False}
            else "some trained with the kernel being realised, some not"
        )
        frozen = {n.get("learn_filter") for n in good}
        mode = (
            " (kernel frozen while training)"
            if frozen == {False}
            else " (kernel learned jointly)"
            if frozen == {True}
            else ""
        )
        seeds = ", ".join(str(n.get("seed")) for n in good)
        parts.append(f"{task}: {len(good)} network{'s' if len(good) > 1 else ''} (training seeds {seeds}) {how}{mode}")
    return "; ".join(parts)
