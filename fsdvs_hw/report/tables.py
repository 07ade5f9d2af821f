"""Score tables: flatten stored design points into one row each, write CSV and JSON.

A stored point's ``result`` is a nested :func:`fsdvs_hw.explore.scoring.score` record; the tables
flatten it to named columns with units in the names (``fit_s``, ``cost_area_m2``), add the task
accuracy loss against the learned kernel, and mark the Pareto-optimal points.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["score_rows", "pareto_front", "headline_cost", "accuracy_axis", "summary_markdown", "write_scores",
           "HEADLINE_COSTS"]

#: Cost items preferred as a realisation's single headline cost, in order (else its first item):
#: ASIC silicon (area, cells, adders); mesh settling time of the wide mesh (its area is fixed at
#: six conductances per pixel, so speed is what a design pays); metalens aperture diameter.
HEADLINE_COSTS: tuple[str, ...] = ("area_m2", "yosys_cells", "adders", "tau_wide", "aperture_diameter", "power_w")


def headline_cost(cost: Mapping[str, Mapping[str, Any]]) -> tuple[str, float, str] | None:
    """``(name, value, unit)`` of the cost item that best summarises a realisation, or None."""
    if not cost:
        return None
    name = next((n for n in HEADLINE_COSTS if n in cost), next(iter(cost)))
    item = cost[name]
    return name, float(item["value"]), str(item.get("unit", ""))


def _num(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def score_rows(points: Iterable[Mapping[str, Any]], *, primary_csf: str = "mannos_sakrison_1974") -> list[dict[str, Any]]:
    """One flat dict per stored point (see the module docstring); stable column names.

    Columns: ``point, realisation, params, status, reason, kernel_error, kernel_error_gain_free,
    dc_gain, peak_frequency_cpp, response_kind, csf_<method>_{correlation,peak_ratio,log_rms_dec},
    csf_fitted_{correlation,rms_error,ppd}, metric_<task>/<track>, loss_<task>/<track>,
    emu_event_ratio, emu_signed_correlation, emu_clipped_black, cost_<name>, headline_cost,
    headline_cost_value, headline_cost_unit, fit_s, analysis_s, tasks_s, emulation_s, point_s, pareto``.
    """
    from ..explore.scoring import accuracy_losses

    points = list(points)
    losses = accuracy_losses(points)
    rows: list[dict[str, Any]] = []
    for p in points:
        res = p.get("result") or {}
        params = p.get("params") or {}
        label = p["realisation"] + ("" if not params else " " + ", ".join(f"{k.split('.')[-1]}={v}" for k, v in params.items()))
        row: dict[str, Any] = {"point": label, "key": p["key"], "realisation": p["realisation"],
                               "params": json.dumps(params, sort_keys=True), "status": p["status"],
                               "reason": res.get("reason", ""), "warnings": " | ".join(res.get("warnings", []))}
        if p["status"] == "ok":
            row["kernel_error"] = _num(res.get("kernel_error"))
            row["kernel_error_gain_free"] = _num(res.get("kernel_error_gain_free"))
            row["dc_gain"] = _num(res.get("dc_gain"))
            spec = res.get("spectral") or {}
            row["peak_frequency_cpp"] = _num(spec.get("peak_frequency_cpp"))
            row["response_kind"] = spec.get("kind", "")
            csf = res.get("csf") or {}
            for method, m in csf.items():
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
            tasks = res.get("tasks") or {}
            row["tasks_status"] = tasks.get("status", "")
            for task, tracks in tasks.items():
                if isinstance(tracks, Mapping):
                    for track, r in tracks.items():
                        if isinstance(r, Mapping) and "metric" in r:
                            row[f"metric_{task}/{track}"] = _num(r["metric"])
            for k, v in losses.get(p["key"], {}).items():
                row[f"loss_{k}"] = v
            emu = res.get("emulation") or {}
            row["emulation_status"] = emu.get("status", "")
            if emu.get("status") == "ok":
                row["emu_event_ratio"] = _num(emu.get("event_ratio"))
                row["emu_signed_correlation"] = _num(emu.get("signed_correlation"))
                row["emu_clipped_black"] = _num(emu.get("clipped_black"))
            cost = res.get("cost") or {}
            for name, item in cost.items():
                row[f"cost_{name}"] = _num(item.get("value"))
            head = headline_cost(cost)
            row["headline_cost"], row["headline_cost_value"], row["headline_cost_unit"] = head or ("", math.nan, "")
            wall = res.get("wall_s") or {}
            row["fit_s"] = _num(wall.get("fit"))
            row["analysis_s"] = _num(wall.get("analysis"))
            row["tasks_s"] = _num(wall.get("tasks"))
            row["emulation_s"] = _num(wall.get("emulation"))
        row["point_s"] = _num(p.get("wall_s"))
        rows.append(row)
    _mark_pareto(rows)
    return rows


def accuracy_axis(rows: Sequence[Mapping[str, Any]]) -> tuple[str, str]:
    """The column used as 'accuracy loss' (first task loss), or kernel error when no task ran."""
    for r in rows:
        for k in r:
            if k.startswith("loss_"):
                return k, f"accuracy loss ({k[5:]}, learned − realised)"
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
            j != i and not any(math.isnan(x) for x in b) and all(x <= y for x, y in zip(b, a)) and any(x < y for x, y in zip(b, a))
            for j, b in enumerate(vals)
        )
        flags.append(not dominated)
    return flags


def _mark_pareto(rows: list[dict[str, Any]]) -> None:
    """Mark points non-dominated in (accuracy loss ↓, CSF agreement ↑, headline cost ↓) within each realisation kind.

    Costs of different kinds have different units (siemens, adders, m²), so the three-way front is
    taken per kind; ideal references (no cost) are compared with cost 0.
    """
    acc, _ = accuracy_axis(rows)
    for r in rows:
        r["pareto"] = False
    kinds = {r["realisation"] for r in rows if r["status"] == "ok"}
    for kind in kinds:
        group = [r for r in rows if r["status"] == "ok" and r["realisation"] == kind]
        objs = [(r.get(acc, math.nan), -r.get("csf_agreement", math.nan),
                 0.0 if math.isnan(r.get("headline_cost_value", math.nan)) else r["headline_cost_value"]) for r in group]
        for r, f in zip(group, pareto_front(objs)):
            r["pareto"] = f


def write_scores(rows: Sequence[Mapping[str, Any]], out_dir: str | Path, *, stem: str = "scores",
                 full: Sequence[Mapping[str, Any]] | None = None) -> tuple[Path, Path]:
    """Write ``<stem>.csv`` (flat rows) and ``<stem>.json`` (flat rows plus full records) to ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    columns: list[str] = []
    for r in rows:
        columns.extend(k for k in r if k not in columns)
    csv_path = out / f"{stem}.csv"
    with csv_path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=columns, restval="")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()})
    json_path = out / f"{stem}.json"
    clean = [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()} for r in rows]
    json_path.write_text(json.dumps({"rows": clean, "points": list(full or [])}, indent=1, default=str) + "\n")
    return csv_path, json_path


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else ""
    if isinstance(v, float):
        return "–" if math.isnan(v) else f"{v:.3g}"
    return str(v)


def summary_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """The headline columns of :func:`score_rows` as a Markdown table (what ``explore`` prints)."""
    cols = [("point", "point"), ("status", "status"), ("kernel_error", "kernel error"),
            ("csf_agreement", "r MS"), ("csf_fitted_correlation", "r MS fitted")]
    extra = list(dict.fromkeys(c for r in rows for c in r if c.startswith("loss_")))
    cols += [(c, c[5:] + " loss") for c in extra]
    if any("emu_event_ratio" in r for r in rows):
        cols += [("emu_event_ratio", "emul. events ratio"), ("emu_signed_correlation", "emul. r")]
    cols += [("headline_cost", "cost"), ("headline_cost_value", "value"), ("headline_cost_unit", "unit"),
             ("fit_s", "fit (s)"), ("point_s", "point (s)")]
    lines = ["| " + " | ".join(t for _, t in cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(c, "")) for c, _ in cols) + " |")
    return "\n".join(lines)
