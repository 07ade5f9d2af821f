"""Attach physical cost records to every stored point: under the design's ``[costs]``, and per
setting of its ``costs.*`` sweep axes.

The physical costs (:mod:`fsdvs_hw.costs`) depend on a point's score and on the design's
``[costs]`` assumptions, never the other way round, so a sweep over ``costs.*`` keys needs no
refit and no rescoring: :func:`with_physical_costs` computes each point's ``"physical_cost"``
under the design's own ``[costs]`` values and, when the design sweeps ``costs.*`` keys,
``"physical_cost_sweep"``: one ``{"setting", "physical_cost"}`` per setting of those axes.
``scores.json`` and the report read both from there.

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

from ..costs import CostAssumptions, physical_cost
from ..records import Score
from .design import Design, axis_values

__all__ = ["cost_settings", "with_physical_costs"]


def cost_settings(design: Design) -> list[dict[str, Any]]:
    """Every setting of the design's ``costs.*`` sweep axes (``[{}]`` when it has none)."""
    axes = {k: v for k, v in axis_values(design).items() if k.startswith("costs.")}
    return [dict(zip(axes, vals)) for vals in itertools.product(*axes.values())] if axes else [{}]


def with_physical_costs(points: Sequence[Mapping[str, Any]], design: Design) -> list[dict[str, Any]]:
    """Copies of the stored ``points`` with ``"physical_cost"`` (:func:`fsdvs_hw.costs.physical_cost`).

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
    for p in points:
        q = dict(p)
        if p.get("status") == "ok" and isinstance(p.get("result"), Mapping):
            score = Score.from_dict(p["result"], where=f"point {p.get('key')}")
            q["physical_cost"] = physical_cost(score, design.spec.costs).to_dict()
            if settings != [{}]:
                q["physical_cost_sweep"] = [
                    {"setting": s, "physical_cost": physical_cost(score, a).to_dict()}
                    for s, a in zip(settings, assumptions)
                ]
        out.append(q)
    return out
