"""Attach physical cost records to every stored point: under the design's ``[costs]``, and per
setting of its ``costs.*`` sweep axes.

The physical costs (:mod:`fsdvs_hw.costs`) depend on a point's score and on the design's
``[costs]`` assumptions, never the other way round, so a sweep over ``costs.*`` keys needs no
refit and no rescoring: :func:`with_physical_costs` computes each point's physical cost
(:attr:`fsdvs_hw.records.ScoredPoint.physical_cost`) under the design's own ``[costs]`` values and,
when the design sweeps ``costs.*`` keys, one :class:`~fsdvs_hw.records.CostSetting` per setting of
those axes (``physical_cost_sweep``). ``scores.json`` and the report read both from there. Each
point also carries its :class:`~fsdvs_hw.records.CostFlip` records (``cost_flips``):
for every other hardware kind in its sweep setting and each cost that can reorder them (power,
area, latency), the ``[costs]`` keys (and the mesh's conductance) whose change within their
range reverses which is cheaper, with the value at which it does
(:func:`fsdvs_hw.costs.limits.cost_flips`), so the verdict's "cheapest" sentences can name the
assumptions they rest on.

Examples
--------
>>> from fsdvs_hw.design import parse_design
>>> d = parse_design({"realisations": {"include": ["learned"]},
...                   "sweep": {"axes": {"costs.process_node_m": [45e-9, 180e-9]}}})
>>> cost_settings(d)
[{'costs.process_node_m': 4.5e-08}, {'costs.process_node_m': 1.8e-07}]
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

from ..costs import CostAssumptions, PhysicalCost
from ..costs.limits import costed
from ..design.design import Design, axis_values
from ..records import CostFlip, CostSetting, ScoredPoint
from .scoring import sweep_setting

__all__ = ["cost_settings", "with_physical_costs"]


def cost_settings(design: Design) -> list[dict[str, Any]]:
    """Every setting of the design's ``costs.*`` sweep axes (``[{}]`` when it has none)."""
    axes = {k: v for k, v in axis_values(design).items() if k.startswith("costs.")}
    return [dict(zip(axes, vals)) for vals in itertools.product(*axes.values())] if axes else [{}]


def with_physical_costs(points: Sequence[ScoredPoint], design: Design) -> list[ScoredPoint]:
    """Copies of ``points`` with their physical cost (:func:`fsdvs_hw.costs.limits.costed`: the cost
    record with its hard limits and remedies), per ``costs.*`` sweep setting, and their cost flips.

    Parameters
    ----------
    points : sequence of ScoredPoint
        Stored points.
    design : Design
        The design they came from: its ``[costs]`` section, and its ``costs.*`` sweep axes.

    Returns
    -------
    list of ScoredPoint
        The points, each ``ok`` one with :attr:`~fsdvs_hw.records.ScoredPoint.physical_cost`, its
        :attr:`~fsdvs_hw.records.ScoredPoint.cost_flips` and, with ``costs.*`` sweep axes,
        :attr:`~fsdvs_hw.records.ScoredPoint.physical_cost_sweep` (each setting's values by dotted
        key, and the record under it). Each record is kept as ``scores.json`` holds it.
    """
    base = design.spec.costs.model_dump()
    settings = cost_settings(design)
    assumptions = [
        CostAssumptions.model_validate({**base, **{k.split(".", 1)[1]: v for k, v in s.items()}}) for s in settings
    ]
    scored = [p for p in points if p.ok and p.score is not None]
    flips = _flips(scored, design.spec.costs)
    out = []
    for p in points:
        if p.score is None or not p.ok:
            out.append(p)
            continue
        sweep = (
            []
            if settings == [{}]
            else [CostSetting(s, _as_stored(costed(p.score, a))) for s, a in zip(settings, assumptions)]
        )
        out.append(
            p.with_(
                physical_cost=_as_stored(costed(p.score, design.spec.costs)),
                physical_cost_sweep=tuple(sweep),
                cost_flips=tuple(CostFlip.from_dict(f) for f in flips.get(p.key, [])),
            )
        )
    return out


def _as_stored(cost: PhysicalCost) -> PhysicalCost:
    """The record as ``scores.json`` holds it (plain floats, NaN figures as absent values)."""
    return PhysicalCost.from_dict(cost.to_dict())


def _flips(points: Sequence[ScoredPoint], a: CostAssumptions) -> dict[str, list[dict[str, Any]]]:
    """Point key → its :func:`~fsdvs_hw.costs.limits.cost_flips` against every other hardware kind
    of its sweep setting (``{"cost", "key", "value", "now", "other", "cheaper"}``, ``cheaper`` the
    key of the point that is cheaper at the present value)."""
    from ..costs.limits import FLIP_KEYS, cost_flips

    scores = {p.key: p.score for p in points if p.score is not None and p.score.kind != "reference"}
    hardware = [p for p in points if p.key in scores]
    setting = {p.key: sweep_setting({"params": p.params}) for p in hardware}
    out: dict[str, list[dict[str, Any]]] = {}
    for i, p in enumerate(hardware):
        for q in hardware[i + 1 :]:
            if p.realisation == q.realisation or setting[p.key] != setting[q.key]:
                continue
            kp, kq = p.key, q.key
            for cost in FLIP_KEYS:
                for f in cost_flips(scores[kp], scores[kq], a, cost):
                    rec = {"cost": cost, "key": f["key"], "value": f["value"], "now": f["now"]}
                    cheaper = kp if f["cheaper_now"] == 0 else kq
                    out.setdefault(kp, []).append({**rec, "other": kq, "cheaper": cheaper})
                    out.setdefault(kq, []).append({**rec, "other": kp, "cheaper": cheaper})
    return out
