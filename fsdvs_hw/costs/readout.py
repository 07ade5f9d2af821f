"""Event bandwidth: the array's measured event rate against the readout's limit.

The task evaluators measure each kernel's event rate per pixel on their test clips, in
events/pixel/s with a 95 % bootstrap CI over networks × clips (``event_rate_per_s`` of each
simulator track, :func:`fsdvs_hw.explore.paired.event_rate_ci`). The readout must carry the
busiest task's scenes, so the array rate is the largest task mean times the pixel count of
``costs.array_resolution`` (the per-pixel rate measured on the simulated clips is taken as
spatially stationary). It is compared with ``costs.readout_limit_eps`` (the IMX636's 1.066 Geps,
Finateu et al., ISSCC 2020) and flagged when it exceeds it.

Examples
--------
>>> from fsdvs_hw.costs.assumptions import CostAssumptions
>>> from fsdvs_hw.costs.readout import readout_figures
>>> figs, flags = readout_figures({"detection": {"mean": 1000.0, "low": 900.0, "high": 1100.0}},
...                               CostAssumptions())
>>> figs["event_rate_eps"].value, bool(flags)
(921600000.0, False)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from .assumptions import CostAssumptions
from .record import CostFigure

__all__ = ["READOUT_SOURCE", "readout_figures"]

READOUT_SOURCE = "Finateu et al., ISSCC 2020 (IMX636, 1280x720, 1.066 Geps)"


def _num(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def readout_figures(
    rates: Mapping[str, Mapping[str, Any]], a: CostAssumptions
) -> tuple[dict[str, CostFigure], list[str]]:
    """Array event rate, readout limit and utilisation, and a flag when the limit is exceeded.

    Parameters
    ----------
    rates : mapping
        Task → ``{"mean", "low", "high"}`` in events/pixel/s (the simulator track's
        ``event_rate_per_s``); empty when no task ran.
    a : CostAssumptions
        The ``[costs]`` section (``array_resolution``, ``readout_limit_eps``).

    Returns
    -------
    figures, flags
        ``event_rate_eps`` (with its CI), ``readout_limit_eps``, ``readout_utilisation``; a flag
        when ``event_rate_eps`` exceeds the limit.
    """
    n = a.array_resolution[0] * a.array_resolution[1]
    limit = CostFigure(a.readout_limit_eps, "events/s", f"costs.readout_limit_eps (default: {READOUT_SOURCE})")
    good = {t: r for t, r in rates.items() if isinstance(r, Mapping) and math.isfinite(_num(r.get("mean")))}
    if not good:
        none = CostFigure(math.nan, "events/s", "not measured: no task evaluator ran (the [tasks] event rates)")
        return {
            "event_rate_eps": none,
            "readout_limit_eps": limit,
            "readout_utilisation": CostFigure(math.nan, "1", none.source),
        }, []
    task = max(good, key=lambda t: _num(good[t]["mean"]))
    r = good[task]
    rate = CostFigure(
        _num(r["mean"]) * n,
        "events/s",
        f"measured: {task} (busiest task) events/pixel/s x {n} pixels (costs.array_resolution)",
        low=_num(r.get("low")) * n,
        high=_num(r.get("high")) * n,
    )
    figs = {
        "event_rate_eps": rate,
        "readout_limit_eps": limit,
        "readout_utilisation": CostFigure(rate.value / a.readout_limit_eps, "1", "event rate / readout limit"),
    }
    flags = []
    if rate.value > a.readout_limit_eps:
        flags.append(
            f"event rate {rate.value:.3g} events/s exceeds the readout limit {a.readout_limit_eps:.4g} "
            f"events/s (costs.readout_limit_eps)"
        )
    return figs, flags
