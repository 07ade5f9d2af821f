"""What building a realisation costs, in units that cross kinds (W, m², s, events/s, dB of SNR).

Every realisation — a resistive mesh, an ASIC filter, a metalens, and the ideal references — gets
one :class:`PhysicalCost` record in SI units from the quantities its fit already reports, under
the assumptions of the design's ``[costs]`` section (:class:`CostAssumptions`: process node,
supplies, clock, array size, readout limit, light level, loss budget), each figure with its
source. The models: :mod:`fsdvs_hw.costs.mesh` (subthreshold bias power, device area, settling),
:mod:`fsdvs_hw.costs.asic` (Horowitz's energies and areas, :mod:`fsdvs_hw.costs.process`),
:mod:`fsdvs_hw.costs.metalens` (photon budget, pedestal dynamic range),
:mod:`fsdvs_hw.costs.readout` (event bandwidth against the readout limit). ``docs/costs.md``
lists the sources and the equations.

Examples
--------
>>> from fsdvs_hw.costs import CROSS_KIND_COSTS
>>> list(CROSS_KIND_COSTS)
['power_w', 'area_m2', 'latency_s', 'event_rate_eps']
"""

from __future__ import annotations

from .assumptions import CostAssumptions
from .physical import COST_MODELS, physical_cost
from .record import CROSS_KIND_COSTS, CostFigure, PhysicalCost

__all__ = ["COST_MODELS", "CROSS_KIND_COSTS", "CostAssumptions", "CostFigure", "PhysicalCost", "physical_cost"]
