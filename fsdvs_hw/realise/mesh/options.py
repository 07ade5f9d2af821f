"""Fit options of :func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh`: type, unit, range, default, meaning.

The design loader checks a ``[realisations.mesh]`` table against :class:`MeshOptions` and
:func:`fit_resistive_mesh` checks its own arguments against it at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words. The ranges are the fit function's own (see its docstring). A ``bounds`` table of a design
file is built by :class:`~fsdvs_hw.realise.mesh.MeshBounds`, which checks its fields.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from ...schema import StrictModel, field, structured
from ...validation import PITCH_RANGE_M

__all__ = ["MeshOptions"]


class MeshOptions(StrictModel):
    """Keyword options of :func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh`."""

    unknown_key = "unknown option of fit_resistive_mesh"

    # a pydantic Annotated type built at run time, which a static checker cannot evaluate
    bounds: structured("fsdvs_hw.realise.mesh.fit:MeshBounds", "MeshBounds") | None = field(  # type: ignore[valid-type]
        None, "", "MeshBounds fields: lambda_px, gain, min_lambda_ratio, conductance_s"
    )
    pitch_m: float | None = field(
        None, "m", "pixel pitch (default: the kernel's)", ge=PITCH_RANGE_M[0], le=PITCH_RANGE_M[1]
    )
    pixel_weight: Annotated[float, Field(ge=0.0, le=1000.0)] | Literal["free"] | None = field(
        "free", "", "fixed weight of the pixel's own signal, or 'free'"
    )
    gain: Literal["free", "fixed"] = field(
        "free", "", "overall gain: 'free' (folds into the event threshold) or 'fixed'"
    )
    nonnegative_dc: bool = field(True, "", "constrain the whole-circuit DC gain w_p + a − b ≥ 0")
    mismatch_sigma: float = field(0.01, "", "relative die-level mismatch σ", ge=0.0, le=0.5)
    max_mismatch_error: float | None = field(
        0.05, "", "largest first-order kernel error at mismatch σ (None: off)", ge=1e-6, le=10.0
    )
    g_lateral_s: float = field(
        1e-8, "S", "lateral conductance of both meshes (within bounds.conductance_s)", ge=1e-13, le=1e-3
    )
    node_capacitance_f: float = field(100e-15, "F", "node capacitance of both meshes", ge=1e-18, le=1e-6)
    model: Literal["lattice", "grid"] = field("lattice", "", "single-mesh model")
    grid_half_width: int | None = field(
        None, "px", "half-width of the finite grid (model 'grid'; ≥ kernel radius)", ge=0, le=60
    )
    fit_size: int | None = field(
        None,
        "px",
        "odd window the error is minimised on (≥ kernel size; None: the whole response)",
        ge=1,
        le=63,
        odd=True,
    )
    n_init: int = field(16, "", "λ values per mesh in the initialisation grid", ge=2, le=40)
    n_starts: int = field(3, "", "IPOPT runs from the best distinct grid points", ge=1, le=10)
    max_iter: int = field(200, "", "IPOPT iteration limit", ge=1, le=10000)
    tol: float = field(1e-14, "", "IPOPT tolerance", ge=1e-16, le=1e-2)
