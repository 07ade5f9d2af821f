"""Attach physical cost records to every stored point: under the design's ``[costs]``, and per
setting of its ``costs.*`` sweep axes.

The physical costs (:mod:`fsdvs_hw.costs`) depend on a point's score and on the design's
``[costs]`` assumptions, never the other way round, so a sweep over ``costs.*`` keys needs no
refit and no rescoring: :func:`with_physical_costs` computes each point's ``"physical_cost"``
under the design's own ``[costs]`` values and, when the design sweeps ``costs.*`` keys,
``"physical_cost_sweep"``: one ``{"setting", "physical_cost"}`` per setting of those axes.
``scores.json`` and the report read both from there. Each point also carries ``"cost_flips"``:
for every other hardware kind in its sweep setting and each cost that can reorder them (power,
area, latency), the ``[costs]`` keys (and the mesh's conductance) whose change within their
range reverses which is cheaper, with the value at which it does
(:func:`fsdvs_hw.costs.limits.cost_flips`), so the verdict's "cheapest" sentences can name the
assumptions they rest on.

Examples
--------
>>> from fsdvs_hw.explore.design import parse_design
>>> d = parse_design({"realisations": {"include": ["learned"]},
...                   "sweep": {"axes": {"costs.process_node_m": [45e-9, 180e-9]}}})
>>> cost_settings(d)
[{'costs.process_node_m': 4.5e-08}, {'costs.process_node_m': 1.8e-07}]
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import Any

from ..costs import CostAssumptions
from ..costs.limits import costed
from ..records import Score
from .design import Design, axis_values
from .scoring import sweep_setting

__all__ = ["cost_settings", "with_physical_costs"]


def cost_settings(design: Design) -> list[dict[str, Any]]:
    """Every setting of the design's ``costs.*`` sweep axes (``[{}]`` when it has none)."""
    axes = {k: v for k, v in axis_values(design).items() if k.startswith("costs.")}
    return [dict(zip(axes, vals)) for vals in itertools.product(*axes.values())] if axes else [{}]


def with_physical_costs(points: Sequence[Mapping[str, Any]], design: Design) -> list[dict[str, Any]]:
    """Copies of the stored ``points`` with ``"physical_cost"`` (:func:`fsdvs_hw.costs.limits.costed`:
    the cost record with its hard limits and remedies).

    Parameters
    ----------
    points : sequence of mappings
        Stored points (``key``, ``realisation``, ``params``, ``status``, ``result``).
    design : Design
        The design they came from: its ``[costs]`` section, and its ``costs.*`` sweep axes.

    Returns
    -------
    list of dict
        The points, each ``ok`` one with ``"physical_cost"`` and, with ``costs.*`` sweep axes,
        ``"physical_cost_sweep"`` (the setting's values by dotted key, and the record under it).
    """
    base = design.spec.costs.model_dump()
    settings = cost_settings(design)
    assumptions = [
        CostAssumptions.model_validate({**base, **{k.split(".", 1)[1]: v for k, v in s.items()}}) for s in settings
    ]
    out = []
    scores: dict[str, Score] = {}
    for p in points:
        q = dict(p)
        if p.get("status") == "ok" and isinstance(p.get("result"), Mapping):
            score = Score.from_dict(p["result"], where=f"point {p.get('key')}")
            scores[str(p["key"])] = score
            q["physical_cost"] = costed(score, design.spec.costs).to_dict()
            if settings != [{}]:
                q["physical_cost_sweep"] = [
                    {"setting": s, "physical_cost": costed(score, a).to_dict()} for s, a in zip(settings, assumptions)
                ]
        out.append(q)
    flips = _flips(out, scores, design.spec.costs)
    for q in out:
        if str(q.get("key")) in scores:
            q["cost_flips"] = flips.get(str(q["key"]), [])
    return out


def _flips(
    points: Sequence[Mapping[str, Any]], scores: Mapping[str, Score], a: CostAssumptions
) -> dict[str, list[dict[str, Any]]]:
    """Point key → its :func:`~fsdvs_hw.costs.limits.cost_flips` against every other hardware kind
    of its sweep setting (``{"other", "cost", "key", "value", "now", "cheaper"}``, ``cheaper`` the
    key of the point that is cheaper at the present value)."""
    from ..costs.limits import FLIP_KEYS, cost_flips

    hardware = [p for p in points if str(p.get("key")) in scores and scores[str(p["key"])].kind != "reference"]
    out: dict[str, list[dict[str, Any]]] = {}
    for i, p in enumerate(hardware):
        for q in hardware[i + 1 :]:
            if p["realisation"] == q["realisation"] or sweep_setting(p) != sweep_setting(q):
                continue
            kp, kq = str(p["key"]), str(q["key"])
            for cost in FLIP_KEYS:
                for f in cost_flips(scores[kp], scores[kq], a, cost):
                    rec = {"cost": cost, "key": f["key"], "value": f["value"], "now": f["now"]}
                    cheaper = kp if f["cheaper_now"] == 0 else kq
                    out.setdefault(kp, []).append({**rec, "other": kq, "cheaper": cheaper})
                    out.setdefault(kq, []).append({**rec, "other": kp, "cheaper": cheaper})
    return out
