"""The physical cost record of one realisation: SI figures, each with its source.

A :class:`PhysicalCost` holds the figures that cross kinds — array power (W), power per pixel
(W), silicon area per pixel (m²) and its fill-factor consequence, added event latency (s), event
rate at the array (events/s) against the readout limit, and for optics the photon budget (dB) —
each a :class:`CostFigure` that names where its number comes from (a published table, a stated
``[costs]`` assumption, a fitted quantity, a measurement). Flags say in words when a limit is
broken (the readout cannot carry the events, the mesh does not fit in the pixel).

Examples
--------
>>> from fsdvs_hw.costs.record import CostFigure, PhysicalCost
>>> c = PhysicalCost("mesh", {"power_w": CostFigure(2e-3, "W", "stated")})
>>> c.value("power_w"), PhysicalCost.from_dict(c.to_dict()) == c
(0.002, True)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from ..errors import InputError

__all__ = ["CROSS_KIND_COSTS", "CostFigure", "PhysicalCost"]

#: The costs every realisation reports and the cross-kind fronts use: name → (unit, words).
CROSS_KIND_COSTS: Mapping[str, tuple[str, str]] = MappingProxyType(
    {
        "power_w": ("W", "power of the array"),
        "area_m2": ("m^2", "silicon area per pixel"),
        "latency_s": ("s", "added event latency"),
        "event_rate_eps": ("events/s", "event rate of the array"),
    }
)


def _num(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


@dataclass(frozen=True)
class CostFigure:
    """One cost figure in SI units with its source.

    Parameters
    ----------
    value : float
        The figure in ``unit`` (NaN when it could not be computed; ``source`` says why).
    unit : str
        SI unit (``"W"``, ``"m^2"``, ``"s"``, ``"events/s"``, ``"dB"``, ``"1"``).
    source : str
        A citation (author, venue, year, table), the ``[costs]`` keys it rests on, or the
        fitted / measured quantity it is computed from.
    low, high : float
        Bounds of its confidence interval where it is measured (NaN otherwise).
    """

    value: float
    unit: str
    source: str
    low: float = math.nan
    high: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "value": None if math.isnan(self.value) else float(self.value),
            "unit": self.unit,
            "source": self.source,
        }
        if not math.isnan(self.low):
            out["low"], out["high"] = float(self.low), float(self.high)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "figure") -> CostFigure:
        if not isinstance(data, Mapping) or "unit" not in data:
            raise InputError(f"{where}: a cost figure needs 'value', 'unit' and 'source', got {data!r:.80}")
        return cls(
            _num(data.get("value")),
            str(data["unit"]),
            str(data.get("source", "")),
            _num(data.get("low")),
            _num(data.get("high")),
        )

    def __eq__(self, other: object) -> bool:  # NaN == NaN for round trips
        if not isinstance(other, CostFigure):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash((self.unit, self.source))


@dataclass(frozen=True)
class PhysicalCost:
    """What building one realisation costs, in units that cross kinds.

    Parameters
    ----------
    kind : str
        The realisation's registry name.
    figures : mapping of str to CostFigure
        At least the :data:`CROSS_KIND_COSTS` names; a kind adds its own (``power_per_pixel_w``,
        ``fill_factor``, ``photon_snr_change_db``, ...).
    flags : tuple of str
        Limits broken, in words (empty when none).
    status : str
        ``"ok"``, or why there is no cost model for this kind.
    assumptions : mapping
        The ``[costs]`` values used (:class:`fsdvs_hw.costs.assumptions.CostAssumptions`).
    limits : tuple of mapping
        The hard limits broken (:func:`fsdvs_hw.costs.limits.broken_limits`: ``figure``, ``value``,
        ``limit``, ``key``, ``words``), each with its ``remedies`` (:func:`fsdvs_hw.costs.limits.remedies`);
        a realisation with any is never recommended.
    """

    kind: str
    figures: Mapping[str, CostFigure] = field(default_factory=dict)
    flags: tuple[str, ...] = ()
    status: str = "ok"
    assumptions: Mapping[str, Any] = field(default_factory=dict)
    limits: tuple[Mapping[str, Any], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "figures", MappingProxyType(dict(self.figures)))
        object.__setattr__(self, "assumptions", MappingProxyType(dict(self.assumptions)))
        object.__setattr__(self, "flags", tuple(str(f) for f in self.flags))
        object.__setattr__(self, "limits", tuple(dict(x) for x in self.limits))

    def value(self, name: str) -> float:
        """The figure's value (NaN when absent)."""
        f = self.figures.get(name)
        return f.value if f is not None else math.nan

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "status": self.status,
            "figures": {k: f.to_dict() for k, f in self.figures.items()},
            "flags": list(self.flags),
            "assumptions": dict(self.assumptions),
            "limits": [dict(x) for x in self.limits],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "physical_cost") -> PhysicalCost:
        if not isinstance(data, Mapping) or "kind" not in data:
            raise InputError(f"{where}: not a physical cost record (no 'kind')")
        figs = data.get("figures") or {}
        return cls(
            kind=str(data["kind"]),
            figures={k: CostFigure.from_dict(v, where=f"{where}.figures.{k}") for k, v in figs.items()},
            flags=tuple(data.get("flags") or ()),
            status=str(data.get("status", "ok")),
            assumptions=dict(data.get("assumptions") or {}),
            limits=tuple(x for x in (data.get("limits") or ()) if isinstance(x, Mapping)),
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PhysicalCost):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(self.kind)

    @property
    def fits(self) -> bool:
        """No hard limit broken (:attr:`limits` empty)."""
        return not self.limits
