"""The cross-kind cost front: physical costs in the score rows, their fronts, verdict and section.

Every stored point carries a physical cost record (:attr:`fsdvs_hw.records.ScoredPoint.physical_cost`, attached by
:func:`fsdvs_hw.explore.costing.with_physical_costs`). This module

* flattens it into the score rows (:func:`with_cost_columns`, :func:`cost_columns`): ``power_w`` (array, W),
  ``power_per_pixel_w``, ``area_m2`` (silicon per pixel, m²), ``fill_factor``, ``latency_s``,
  ``event_rate_eps`` (events/s of the array, with ``event_rate_eps_low``/``_high``, its CI),
  ``readout_limit_eps``, ``readout_exceeded``, the kind's own figures (``energy_per_pixel_j``,
  ``photon_snr_change_db``, ``dynamic_range_cost_db``, ...), ``cost_flags`` and ``loss_budget``;
* marks, for each cost of :data:`fsdvs_hw.costs.CROSS_KIND_COSTS`, the hardware points that no
  other dominates beyond the loss CIs in (loss, that cost), across kinds, within each setting of
  the ``costs.*`` sweep axes (``front_power_w``, ...; :func:`mark_cost_fronts`);
* repeats the rows once per setting of the ``costs.*`` sweep axes (:func:`sweep_rows`, from the
  points' ``physical_cost_sweep``), so the fronts and the verdict show where the ranking flips;
* says in words which realisation is cheapest in each cost among those whose loss stays within
  ``costs.loss_budget`` (upper CI bound), and every limit broken, a readout that cannot carry the
  event rate first (:func:`cost_advice`), and renders the report's section (:func:`cost_section`).

Examples
--------
>>> rows = [{"status": "ok", "realisation": "asic", "params": "{}", "kernel_error": 0.01, "power_w": 0.01,
...          "area_m2": 1e-14, "latency_s": 5e-4, "event_rate_eps": 2e9, "readout_limit_eps": 1.066e9,
...          "readout_exceeded": True, "loss_budget": 0.02,
...          "cost_flags": "event rate 2e+09 events/s exceeds the readout limit 1.066e+09 events/s"}]
>>> mark_cost_fronts(rows)
>>> rows[0]["front_power_w"]
True
>>> cost_advice(rows)[-1].startswith("Readout limit exceeded")
True
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

from markupsafe import Markup

from ..costs import CROSS_KIND_COSTS, PhysicalCost
from ..records import ScoredPoint
from .present import number, point_title, si
from .tables import accuracy_axis, is_reference, loss_interval, uncertain_pareto_front
from .templating import render

__all__ = [
    "COST_NAMES",
    "COST_WORDS",
    "cost_advice",
    "cost_columns",
    "cost_section",
    "cost_text",
    "flip_phrases",
    "key_text",
    "mark_cost_fronts",
    "remedy_text",
    "sweep_rows",
    "with_cost_columns",
]

#: How the verdict names the cheapest in each cross-kind cost.
COST_WORDS: Mapping[str, str] = {
    "power_w": "least power",
    "area_m2": "least silicon per pixel",
    "latency_s": "least added latency",
    "event_rate_eps": "fewest events",
}

#: Figures a kind adds to the four cross-kind costs, flattened into the rows when present.
_EXTRA = (
    "power_per_pixel_w",
    "energy_per_pixel_j",
    "array_area_m2",
    "fill_factor",
    "readout_limit_eps",
    "readout_utilisation",
    "photon_snr_change_db",
    "photon_snr_db",
    "photoelectrons",
    "dynamic_range_cost_db",
    "thickness_m",
    "yosys_area_m2",
    "lanes",
    "mismatch_error",
)


def _num(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def cost_columns(pc: PhysicalCost) -> dict[str, Any]:
    """The score-row columns of one point's physical cost record (module docstring; units in the names)."""
    out: dict[str, Any] = {"cost_status": pc.status}
    for name in (*CROSS_KIND_COSTS, *_EXTRA):
        if name in pc.figures:
            out[name] = pc.value(name)
    rate = pc.figures.get("event_rate_eps")
    if rate is not None and not math.isnan(rate.low):
        out["event_rate_eps_low"], out["event_rate_eps_high"] = rate.low, rate.high
    out["readout_exceeded"] = bool(pc.value("event_rate_eps") > pc.value("readout_limit_eps"))
    out["cost_flags"] = " | ".join(pc.flags)
    out["fits"] = pc.fits
    out["hard_limits"] = json.dumps(list(pc.limits)) if pc.limits else ""
    out["loss_budget"] = _num(pc.assumptions.get("loss_budget"))
    return out


def with_cost_columns(rows: Sequence[Mapping[str, Any]], points: Sequence[ScoredPoint]) -> list[dict[str, Any]]:
    """Copies of the score ``rows`` with each point's physical cost columns and ``front_<cost>`` flags.

    Parameters
    ----------
    rows : sequence of mappings
        :func:`fsdvs_hw.report.tables.score_rows` of ``points`` (matched by ``key``).
    points : sequence of ScoredPoint
        Those with a ``physical_cost`` record (:mod:`fsdvs_hw.explore.costing`) give their rows
        :func:`cost_columns`; the others are unchanged.
    """
    records = {p.key: p.physical_cost for p in points if p.physical_cost is not None}
    flips = {p.key: [f.to_dict() for f in p.cost_flips] for p in points if p.cost_flips is not None}
    out = [
        {**r, **cost_columns(records[r["key"]]), "cost_flips": json.dumps(flips.get(r["key"], []))}
        if r.get("key") in records and r.get("status") == "ok"
        else dict(r)
        for r in rows
    ]
    if records:
        mark_cost_fronts(out)
    return out


def sweep_rows(rows: Sequence[Mapping[str, Any]], points: Sequence[ScoredPoint]) -> list[dict[str, Any]]:
    """The score rows once per ``costs.*`` sweep setting, with that setting's cost columns and fronts.

    Parameters
    ----------
    rows : sequence of mappings
        :func:`fsdvs_hw.report.tables.score_rows` of ``points`` (matched by ``key``).
    points : sequence of ScoredPoint
        The stored points; those with ``physical_cost_sweep`` (:mod:`fsdvs_hw.explore.costing`)
        give one row per setting, its values added to ``params``.

    Returns
    -------
    list of dict
        ``rows`` itself (copied) when no point carries a sweep.
    """
    sweeps = {p.key: p.physical_cost_sweep for p in points if p.physical_cost_sweep}
    if not sweeps:
        return [dict(r) for r in rows]
    out: list[dict[str, Any]] = []
    n = max(len(v) for v in sweeps.values())
    for i in range(n):
        for r in rows:
            entries = sweeps.get(str(r.get("key")))
            if not entries or i >= len(entries):
                continue
            base = {k: v for k, v in r.items() if not k.startswith("front_")}
            params = json.loads(r["params"]) if isinstance(r.get("params"), str) else dict(r.get("params") or {})
            out.append(
                {
                    **base,
                    **cost_columns(entries[i].physical_cost),
                    "params": json.dumps({**params, **entries[i].setting}, sort_keys=True),
                }
            )
    mark_cost_fronts(out)
    return out


def _setting(r: Mapping[str, Any]) -> str:
    """The row's ``costs.*`` sweep setting as JSON text (``"{}"`` without cost axes)."""
    params = r.get("params") or {}
    if isinstance(params, str):
        params = json.loads(params) if params.strip() else {}
    return json.dumps({k: v for k, v in params.items() if k.startswith("costs.")}, sort_keys=True)


def _own_params(r: Mapping[str, Any]) -> dict[str, Any]:
    params = r.get("params") or {}
    if isinstance(params, str):
        params = json.loads(params) if params.strip() else {}
    return {k: v for k, v in params.items() if not k.startswith("costs.")}


def _setting_text(setting: Mapping[str, Any]) -> str:
    """``"process_node_m = 45 nm"`` for a ``{"costs.process_node_m": 4.5e-08}`` setting."""
    return ", ".join(f"{k.split('.', 1)[1]} = {cost_text(_num(v), k)}" for k, v in setting.items())


def _name(r: Mapping[str, Any]) -> str:
    """The row's realisation for people, its ``costs.*`` setting after a comma."""
    where = json.loads(_setting(r))
    return point_title(str(r["realisation"]), _own_params(r)) + (f", {_setting_text(where)}" if where else "")


def _cost_interval(r: Mapping[str, Any], cost: str) -> tuple[float, float, float]:
    v = _num(r.get(cost))
    lo, hi = _num(r.get(f"{cost}_low")), _num(r.get(f"{cost}_high"))
    return (v, lo, hi) if not (math.isnan(lo) or math.isnan(hi)) else (v, v, v)


_Row = TypeVar("_Row", bound=Mapping[str, Any])


def _groups(rows: Sequence[_Row]) -> dict[str, list[_Row]]:
    out: dict[str, list[_Row]] = {}
    for r in rows:
        if r.get("status") == "ok" and "power_w" in r:
            out.setdefault(_setting(r), []).append(r)
    return out


def mark_cost_fronts(rows: Sequence[dict[str, Any]]) -> None:
    """Set ``front_<cost>`` on every row: not dominated beyond the CIs in (accuracy loss, cost).

    Within each ``costs.*`` setting, across every hardware kind (the ideal references are shown,
    never on a front); a cost that is NaN (an event rate without tasks) keeps the point off that
    front (:func:`fsdvs_hw.report.tables.uncertain_pareto_front`).
    """
    acc, _ = accuracy_axis(rows)
    for r in rows:
        for cost in CROSS_KIND_COSTS:
            r[f"front_{cost}"] = False
    for group in _groups(rows).values():
        hardware = [r for r in group if not is_reference(str(r["realisation"]))]
        for cost in CROSS_KIND_COSTS:
            flags = uncertain_pareto_front([(loss_interval(r, acc), _cost_interval(r, cost)) for r in hardware])
            for r, f in zip(hardware, flags):
                r[f"front_{cost}"] = f


def _eps(v: float) -> str:
    text = si(v, "Hz")
    if text == "–":
        return text
    num, _, unit = text.rpartition(" ")
    return f"{num} {unit[:-2]}eps"


def cost_text(value: float, cost: str) -> str:
    """A cost figure for people: ``"11.4 mW"``, ``"0.0283 µm²"``, ``"1.07 Geps"``."""
    if cost.endswith("_eps"):
        return _eps(value)
    if cost.endswith("_db"):
        return f"{number(value)} dB"
    unit = {"_w": "W", "_m2": "m^2", "_s": "s", "_j": "J", "_m": "m"}
    return si(value, next((u for s, u in unit.items() if cost.endswith(s)), "1"))


def cost_advice(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The cost verdict in sentences: per ``costs.*`` setting, the cheapest realisation in each cost
    whose loss's upper CI bound is within ``costs.loss_budget`` (with every other whose cost CI
    reaches below the cheapest's upper bound: a measured event rate is not ranked inside its CI);
    then every limit broken (a readout that cannot carry the event rate first)."""
    acc, _ = accuracy_axis(rows)
    what = "loss" if acc.endswith("_loss") else "kernel error"
    groups = _groups(rows)
    out = []
    for setting, group in groups.items():
        hardware = [r for r in group if not is_reference(str(r["realisation"]))]
        if not hardware:
            continue
        budget = _num(group[0].get("loss_budget"))
        within = [r for r in hardware if loss_interval(r, acc)[2] <= budget and r.get("fits") is not False]
        where = json.loads(setting)
        head = f"At {_setting_text(where)}: " if where else ""
        if not within:
            best = min(hardware, key=lambda r: loss_interval(r, acc)[2])
            out.append(
                f"{head}No hardware realisation within the hard limits keeps its {what} within the loss budget "
                f"{number(budget)} (costs.loss_budget, upper CI bound); the smallest upper bound is "
                f"{point_title(best['realisation'], _own_params(best))}'s {number(loss_interval(best, acc)[2])}."
            )
            continue
        parts = []
        for cost, words in COST_WORDS.items():
            known = [r for r in within if not math.isnan(_num(r.get(cost)))]
            if not known:
                parts.append(f"{words}: not measured (no task ran)" if cost == "event_rate_eps" else f"{words}: –")
                continue
            best = min(known, key=lambda r: _num(r[cost]))
            top = _cost_interval(best, cost)[2]  # a measured cost (event rate) ties within its CI
            cheapest = [r for r in known if _cost_interval(r, cost)[1] <= top]
            parts.append(
                f"{words}: "
                + " and ".join(
                    f"{point_title(r['realisation'], _own_params(r))} ({cost_text(_num(r[cost]), cost)})"
                    for r in cheapest
                )
                + _flip_text(cheapest, [r for r in known if r not in cheapest], cost)
            )
        out.append(
            f"{head}Cheapest within the loss budget ({what} ≤ {number(budget)} at the upper CI bound, "
            f"costs.loss_budget) and the hard limits: " + "; ".join(parts) + "."
        )
    flagged = [r for g in groups.values() for r in g if r.get("cost_flags")]
    readout = [r for r in flagged if r.get("readout_exceeded")]
    if readout:
        out.append(
            "Readout limit exceeded: "
            + "; ".join(
                f"{_name(r)} fires {_eps(_num(r.get('event_rate_eps')))}, more than "
                f"the {_eps(_num(r.get('readout_limit_eps')))} the readout carries (costs.readout_limit_eps)"
                for r in readout
            )
            + "."
        )
    others = [
        (r, f) for r in flagged for f in str(r["cost_flags"]).split(" | ") if f and not f.startswith("event rate")
    ]
    if others:
        out.append("Cost limits broken: " + "; ".join(f"{_name(r)}: {f}" for r, f in others) + ".")
    for r in [r for g in groups.values() for r in g if r.get("hard_limits")]:
        fixes = [remedy_text(x) for lim in json.loads(str(r["hard_limits"])) for x in lim.get("remedies", [])]
        if fixes:
            out.append(f"What would make {_name(r)} fit (from its cost model): " + "; or ".join(fixes) + ".")
    return out


def _flips_of(r: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    raw = r.get("cost_flips")
    if isinstance(raw, str):
        raw = json.loads(raw) if raw.strip() else []
    return [f for f in raw or [] if isinstance(f, Mapping)]


#: Units of the keys the limits and flips name (:mod:`fsdvs_hw.costs.limits`).
_KEY_UNITS: Mapping[str, str] = {
    "costs.sample_rate_hz": "Hz",
    "costs.clock_hz": "Hz",
    "costs.process_node_m": "m",
    "costs.digital_supply_v": "V",
    "costs.analog_supply_v": "V",
    "sensor.pitch_m": "m",
    "realisations.mesh.g_lateral_s": "S",
    "costs.capacitor_density_f_m2": "F/m²",
    "costs.transistor_area_f2": "F²",
    "costs.sram_cell_area_f2": "F²",
}

#: Short names of the figures a remedy's effects list.
COST_NAMES: Mapping[str, str] = {"latency_s": "added latency", "power_w": "array power", "area_m2": "per pixel"}


def key_text(value: float, key: str) -> str:
    """A key's value for people with its unit: ``key_text(2155.1, "costs.sample_rate_hz")`` → ``"2.16 kHz"``."""
    unit = _KEY_UNITS.get(key, "")
    if unit in ("Hz", "m", "V", "S"):
        return si(value, unit)
    return f"{number(value)} {unit}".strip()


def remedy_text(rem: Mapping[str, Any]) -> str:
    """One remedy (:class:`fsdvs_hw.costs.limits.Remedy` as a dict) in words, with its side effects."""
    key, value, now = str(rem.get("key")), _num(rem.get("value")), _num(rem.get("now"))
    effects = rem.get("effects") or {}
    if key == "sensor.pitch_m":
        return f"a pixel pitch of at least {key_text(value, key)} (now {key_text(now, key)})"
    if key == "placement.shared_node":
        k = int(value)
        return (
            f"one mesh node shared by {k} × {k} pixels ({cost_text(_num(effects.get('area_m2')), 'area_m2')} per "
            f"pixel), at a kernel error of at least {_num(rem.get('kernel_error')):.2f} (the best filter on a "
            f"{k}× coarser node lattice)"
        )
    side = "above" if value > now else "below"
    there = ", ".join(f"{cost_text(_num(v), f)} {COST_NAMES.get(f, f)}" for f, v in effects.items())
    return f"{key} {side} {key_text(value, key)} (now {key_text(now, key)})" + (f"; there: {there}" if there else "")


def flip_phrases(r: Mapping[str, Any], other: Mapping[str, Any], cost: str) -> list[str]:
    """Why ``r`` is cheaper than ``other`` in ``cost``, in words: each assumption key whose change
    reverses the order (:func:`fsdvs_hw.costs.limits.cost_flips`, stored by
    :func:`fsdvs_hw.explore.costing.with_physical_costs` as the row's ``cost_flips``) and the value
    at which it does ("while costs.sample_rate_hz stays below 2.16 kHz (now 1 kHz)")."""
    out = []
    for f in _flips_of(r):
        if f.get("cost") != cost or f.get("other") != other.get("key") or f.get("cheaper") != r.get("key"):
            continue
        value, now, key = _num(f.get("value")), _num(f.get("now")), str(f.get("key"))
        side = "below" if value > now else "above"
        out.append(f"while {key} stays {side} {key_text(value, key)} (now {key_text(now, key)})")
    return out


def _flip_text(cheapest: Sequence[Mapping[str, Any]], others: Sequence[Mapping[str, Any]], cost: str) -> str:
    """ " — rests on: ..." for the cheapest against the next cheapest of another kind (empty if none flips)."""
    if len(cheapest) != 1 or not others:
        return ""
    r = cheapest[0]
    rivals = sorted((o for o in others if o["realisation"] != r["realisation"]), key=lambda o: _num(o.get(cost)))
    if not rivals:
        return ""
    phrases = flip_phrases(r, rivals[0], cost)
    if not phrases:
        return ""
    return f" — cheaper than {point_title(rivals[0]['realisation'], _own_params(rivals[0]))} only " + ", and ".join(
        phrases
    )


#: Columns of the section's table: (row key, header).
_TABLE = (
    ("name", "realisation"),
    ("power_w", "power, array"),
    ("power_per_pixel_w", "power per pixel"),
    ("area_m2", "silicon per pixel"),
    ("fill_factor", "fill factor"),
    ("latency_s", "added latency"),
    ("event_rate_eps", "event rate, array"),
    ("readout_utilisation", "of the readout limit"),
    ("photon_snr_change_db", "shot-noise SNR change"),
    ("dynamic_range_cost_db", "pedestal's range"),
    ("cost_flags", "limits broken"),
)


def cost_section(
    rows: Sequence[Mapping[str, Any]], points: Sequence[ScoredPoint] = (), figure: Callable[..., str] | None = None
) -> str:
    """The report's "What building it costs" section (HTML): verdict sentences, table and figure.

    ``rows`` are the score rows of ``points`` (:class:`~fsdvs_hw.records.ScoredPoint`), repeated
    here once per ``costs.*`` sweep setting (:func:`sweep_rows`). ``figure(fig, alt, caption,
    fig_id=...)`` embeds a Matplotlib figure (the report's own helper); without it the section has
    no figure.
    """
    rows = sweep_rows(rows, points)
    groups = _groups(rows)
    if not groups:
        return ""
    shown = [r for g in groups.values() for r in g]
    cells = []
    for r in shown:
        c = {"name": _name(r)}
        for key, _ in _TABLE[1:]:
            v = r.get(key)
            if key == "cost_flags":
                c[key] = str(v or "")
            elif key in ("fill_factor", "readout_utilisation"):
                c[key] = number(_num(v))
            else:
                c[key] = cost_text(_num(v), key) if key in r else "–"
        if "event_rate_eps_low" in r:
            c["event_rate_eps"] += f" [{_eps(_num(r['event_rate_eps_low']))}, {_eps(_num(r['event_rate_eps_high']))}]"
        front = any(r.get(f"front_{k}") for k in CROSS_KIND_COSTS)
        cells.append((front, c))
    fig = None
    if figure is not None:
        from .figures import fig_cost_fronts

        fig = figure(
            fig_cost_fronts(rows),
            "Scatter plots of accuracy loss with confidence bars against array power, silicon area per "
            "pixel, added latency and event rate, every realisation kind on the same axes.",
            "<b>Accuracy loss vs each physical cost, across kinds.</b> Bars: the loss CIs; rings: not "
            "dominated beyond the CIs in (loss, that cost). Zero costs (optics, ideal references) sit at "
            "the left edge of the symmetric-log axis.",
            fig_id="fig-costs",
        )
    return render(
        "costs.html.j2",
        advice=cost_advice(rows),
        columns=_TABLE,
        rows=cells,
        figure=None if fig is None else Markup(fig),
        loss_budget=number(_num(shown[0].get("loss_budget"))),
    )
