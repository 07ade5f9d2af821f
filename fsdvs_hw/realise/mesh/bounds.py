"""Physical bounds of the dual-mesh fit: the reachable space constants, gains and conductances.

:class:`MeshBounds` is the ``bounds`` option of :func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh`
(a ``[realisations.mesh.bounds]`` table of a design file builds one); :func:`as_mesh_bounds` turns
what a caller passes into one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ...errors import InputError
from .response import LAMBDA_RANGE_PX

__all__ = ["MeshBounds", "as_mesh_bounds"]


@dataclass(frozen=True)
class MeshBounds:
    """Physical bounds of the dual-mesh fit.

    Parameters
    ----------
    lambda_px : (float, float)
        Allowed space constants in pixel pitches (both meshes).
    gain : (float, float)
        Allowed DC gains a, b of the mesh paths and, when free, the pixel weight (dimensionless,
        positive: transconductor / current-mirror ratios).
    min_lambda_ratio : float
        Smallest λ_wide / λ_narrow (≥ 1).
    conductance_s : (float, float)
        Allowed conductances in siemens; with ``g_lateral_s`` fixed this bounds λ as well.

    Examples
    --------
    >>> from fsdvs_hw import MeshBounds
    >>> b = MeshBounds(lambda_px=(0.5, 5.0))
    >>> b.lambda_px, b.min_lambda_ratio
    ((0.5, 5.0), 1.5)
    """

    lambda_px: tuple[float, float] = (0.1, 20.0)
    gain: tuple[float, float] = (1e-4, 10.0)
    min_lambda_ratio: float = 1.5
    conductance_s: tuple[float, float] = (1e-13, 1e-3)

    def __post_init__(self) -> None:
        for name in ("lambda_px", "gain", "conductance_s"):
            v = getattr(self, name)
            try:
                lo, hi = (float(x) for x in v)
            except (TypeError, ValueError):
                raise InputError(f"bounds.{name}: must be a (low, high) pair of numbers, got {v!r}") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
                raise InputError(f"bounds.{name}: need 0 < low < high (finite), got ({lo!r}, {hi!r})")
            object.__setattr__(self, name, (lo, hi))
        lo, hi = self.lambda_px
        if lo < LAMBDA_RANGE_PX[0] or hi > LAMBDA_RANGE_PX[1]:
            raise InputError(f"bounds.lambda_px=({lo:g}, {hi:g}) px exceeds the modelled range {LAMBDA_RANGE_PX} px")
        r = self.min_lambda_ratio
        if not (isinstance(r, (int, float)) and math.isfinite(r) and 1.0 <= r < hi / lo):
            raise InputError(f"bounds.min_lambda_ratio={r!r}: must be ≥ 1 and below lambda_px high/low = {hi / lo:g}")


def as_mesh_bounds(bounds: Any) -> MeshBounds:
    """``bounds`` as a :class:`MeshBounds`: None gives the defaults, a mapping of its fields (a design
    file's ``bounds`` table; lists become pairs) is built, a MeshBounds is returned as is.

    Raises
    ------
    InputError
        An unknown field, a bad value (:class:`MeshBounds` says which), or another type.
    """
    if bounds is None:
        return MeshBounds()
    if isinstance(bounds, Mapping):  # e.g. a [realisations.mesh.bounds] table of a design file
        unknown = set(bounds) - set(MeshBounds.__dataclass_fields__)
        if unknown:
            raise InputError(
                f"bounds: unknown key(s) {sorted(unknown)}; allowed {sorted(MeshBounds.__dataclass_fields__)}"
            )
        fields: dict[str, Any] = {k: (tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in bounds.items()}
        bounds = MeshBounds(**fields)
    if not isinstance(bounds, MeshBounds):
        raise InputError(f"bounds: expected a MeshBounds or a mapping of its fields, got {type(bounds).__name__}")
    return bounds
