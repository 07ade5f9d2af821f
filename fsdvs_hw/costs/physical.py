"""One physical cost record per scored realisation: dispatch to the kind's cost model.

:func:`physical_cost` reads what a score already holds — the realisation's stored cost items
(conductances, adders, optical efficiency, ...), its kernel (size, pitch), its fitted record and
the measured event rates of its task tracks — and returns a :class:`~fsdvs_hw.costs.record.PhysicalCost`
in SI units under the ``[costs]`` assumptions. The cost model of each kind is in
:data:`COST_MODELS` (:mod:`~fsdvs_hw.costs.mesh`, :mod:`~fsdvs_hw.costs.asic`,
:mod:`~fsdvs_hw.costs.metalens`); the ideal references (``learned``, ``delta``) cost nothing
electrical; a kind without a model gets its event rate and the status saying so.

Examples
--------
>>> from fsdvs_hw.costs import CostAssumptions, physical_cost
>>> from fsdvs_hw.kernels import reference_kernel
>>> from fsdvs_hw.records import Score
>>> k = reference_kernel("delta", 3)
>>> s = Score(kind="reference", label="delta", describe="", kernel=k, kernel_error=0.0,
...           kernel_error_gain_free=0.0, dc_gain=1.0, asymmetry=0.0)
>>> physical_cost(s, CostAssumptions()).value("power_w")
0.0
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

from ..records import Score
from .asic import asic_cost
from .assumptions import CostAssumptions
from .mesh import mesh_cost, process_mesh_cost
from .metalens import metalens_cost
from .readout import readout_figures
from .record import CostFigure, PhysicalCost

__all__ = ["COST_MODELS", "event_rates", "physical_cost"]

CostModel = Callable[[Score, CostAssumptions], tuple[dict[str, CostFigure], list[str]]]


def _items(score: Score) -> dict[str, float]:
    return {k: score.cost.value(k) for k in score.cost.items}


def _mesh(score: Score, a: CostAssumptions) -> tuple[dict[str, CostFigure], list[str]]:
    items = _items(score)
    return mesh_cost(
        items, a, pitch_m=score.kernel.pitch_m, transconductors=int(items.get("transconductors_per_pixel", 5))
    )


def _asic(score: Score, a: CostAssumptions) -> tuple[dict[str, CostFigure], list[str]]:
    return asic_cost(
        _items(score),
        a,
        kernel_size=score.kernel.size,
        input_bits=int(score.realisation.get("input_bits", 8)),
        sources={k: c.description for k, c in score.cost.items.items()},
    )


def _mesh_process(score: Score, a: CostAssumptions) -> tuple[dict[str, CostFigure], list[str]]:
    items = _items(score)
    conditions = score.realisation.get("conditions") or [{}]
    g = conditions[0].get("conductances_s") or {}
    nominal = (g["vertical_narrow"], g["vertical_wide"]) if "vertical_narrow" in g and "vertical_wide" in g else None
    return process_mesh_cost(
        items,
        a,
        pitch_m=score.kernel.pitch_m,
        sources={k: c.description for k, c in score.cost.items.items()},
        transconductors=int(items.get("transconductors_per_pixel", 5)),
        nominal_g_vertical_s=nominal,
    )


def _metalens(score: Score, a: CostAssumptions) -> tuple[dict[str, CostFigure], list[str]]:
    return metalens_cost(_items(score), a, pitch_m=score.kernel.pitch_m)


def _reference(score: Score, a: CostAssumptions) -> tuple[dict[str, CostFigure], list[str]]:
    none = "ideal reference: no hardware"
    return {
        "power_w": CostFigure(0.0, "W", none),
        "power_per_pixel_w": CostFigure(0.0, "W", none),
        "area_m2": CostFigure(0.0, "m^2", none),
        "fill_factor": CostFigure(1.0, "1", none),
        "latency_s": CostFigure(0.0, "s", none),
    }, []


#: Cost model of each realisation kind (``Score.kind``).
COST_MODELS: Mapping[str, CostModel] = MappingProxyType(
    {
        "mesh": _mesh,
        "mesh_process": _mesh_process,  # the mesh's figures from the process simulations, with their sources
        "asic": _asic,
        "metalens": _metalens,
        "metalens_layout": _metalens,  # the same photon budget, plus the layout's figures (pillars, library)
        "reference": _reference,
    }
)


def event_rates(score: Score, track: str = "simulator") -> dict[str, Mapping[str, Any]]:
    """Task → the track's ``event_rate_per_s`` (``mean``, ``low``, ``high`` in events/pixel/s)."""
    out = {}
    for task, tracks in score.tasks.tracks.items():
        rec = tracks.get(track)
        rate = rec.extra.get("event_rate_per_s") if rec is not None and rec.ok else None
        if isinstance(rate, Mapping) and "mean" in rate:
            out[task] = rate
    return out


def physical_cost(score: Score, assumptions: CostAssumptions) -> PhysicalCost:
    """The physical cost of a scored realisation (module docstring).

    Parameters
    ----------
    score : Score
        A realisation's score (:func:`fsdvs_hw.explore.scoring.score`), with its ``realisation``
        record where the kind needs it (the ASIC's input width).
    assumptions : CostAssumptions
        The design's ``[costs]`` section.

    Returns
    -------
    PhysicalCost
        ``power_w``, ``area_m2``, ``latency_s``, ``event_rate_eps`` and the kind's own figures,
        each with its source; ``flags`` name every limit the models know (the mesh beyond the
        pixel, the readout); :func:`fsdvs_hw.costs.limits.costed` adds the budgets and what
        would meet each hard limit.
    """
    figs, flags = readout_figures(event_rates(score), assumptions)
    model = COST_MODELS.get(score.kind)
    status = "ok"
    if model is None:
        status = f"no cost model for kind {score.kind!r} (fsdvs_hw.costs.physical.COST_MODELS)"
    else:
        own, own_flags = model(score, assumptions)
        figs = {**own, **figs}
        flags = [*own_flags, *flags]
    return PhysicalCost(
        kind=score.kind,
        figures=figs,
        flags=tuple(flags),
        status=status,
        assumptions=assumptions.model_dump(),
    )
