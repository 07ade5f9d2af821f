"""Fit options of :func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh`: type, unit, range, default, meaning, rules.

The design loader checks a ``[realisations.mesh]`` table against :class:`MeshOptions` and
:func:`fit_resistive_mesh` builds its options object from its arguments at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words, the rules between options and on the target kernel included
(:mod:`fsdvs_hw.realise.fit_options`). The fit's steps read the resolved values from the object
(:attr:`MeshOptions.mesh_bounds`, :attr:`MeshOptions.lambda_range_px`, ...). A ``bounds`` table
of a design file is built by :class:`~fsdvs_hw.realise.mesh.MeshBounds`, which checks its fields.
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Annotated, Any, Literal

from pydantic import Field

from ...errors import InputError
from ...kernels import MAX_KERNEL_SIZE, Kernel
from ...schema import field, structured
from ...validation import PITCH_RANGE_M
from ..fit_options import FitOptions, OptionProblem
from .bounds import MeshBounds, as_mesh_bounds

__all__ = ["MeshOptions"]

#: Largest ``grid_half_width`` of the finite-grid model (pixels).
MAX_GRID_HALF_WIDTH = 60


class MeshOptions(FitOptions):
    """Keyword options of :func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh`, validated, with their rules.

    Attributes
    ----------
    bounds : MeshBounds or mapping, optional
        λ range (px), gain range, minimum λ_wide/λ_narrow, conductance range (S); a mapping of
        :class:`MeshBounds` fields is accepted (design files). With ``gain="free"`` the gain range
        bounds the path gains *relative* to the reference (the fixed pixel weight, or, with a free
        pixel weight, the sum w_p + a + b = 1, so only its low end applies).
    pitch_m : float, optional
        Pixel pitch in metres (default: the kernel's).
    pixel_weight : float, "free" or None
        Fixed weight of the pixel's own signal (1.0: the paper's sketch), or "free" / None
        (default) to fit it (a pure difference of meshes when it reaches its lower bound).
    gain : {"free", "fixed"}
        ``"free"`` (default): the overall gain folds into the event threshold, so the shape is
        fitted (scale-invariant error) and the returned gains are scaled by the least-squares
        overall gain; ``"fixed"``: the target's absolute scale must be met within ``bounds.gain``.
    nonnegative_dc : bool
        Constrain the whole-circuit DC gain w_p + a − b ≥ 0 (default), so a bright uniform scene
        never drives negative pre-log current.
    mismatch_sigma : float
        Relative die-level conductance/gain mismatch σ (0 … 0.5) the design must tolerate.
    max_mismatch_error : float or None
        Constraint σ·S ≤ this (S: :func:`~fsdvs_hw.realise.mesh.mismatch_sensitivity`), the
        first-order kernel error at mismatch σ. It stops the unbuildable near-cancellation of two
        similar meshes with huge opposing gains without biasing fits that are robust anyway (a
        mesh-made target is recovered exactly). None disables it.
    g_lateral_s : float
        Lateral conductance of both meshes, siemens; g_v = g_l / λ².
    node_capacitance_f : float
        Node capacitance (F) of both meshes, for the settling time.
    model : {"lattice", "grid"}
        Single-mesh model: infinite lattice (exact lattice Green's function), or a finite open-edge
        grid of half-width ``grid_half_width`` pixels (exact DCT form).
    grid_half_width : int, optional
        Required with ``model="grid"`` (at least the target's radius).
    fit_size : int, optional
        Fit on an odd window (≥ the target's size) instead of the whole response (the tail
        outside it is then unpriced; ``fit["error"]`` still reports the whole response).
    n_init : int
        λ values per mesh in the initialisation grid (2 … 40): at each (λ_n, λ_w) pair the gains
        are the exact constrained least-squares optimum (a convex QP in ≤ 3 gains).
    n_starts : int
        IPOPT runs from the best distinct grid points (1 … 10); the best result is kept.
    max_iter, tol : int, float
        IPOPT iteration limit and tolerance.

    Notes
    -----
    Rules between options: a fixed ``pixel_weight`` of 0 needs ``gain="fixed"`` (with a free gain
    the pixel path is the gain reference); ``g_lateral_s`` lies within ``bounds.conductance_s``, and
    with it the λ range the bounds allow is wider than ``bounds.min_lambda_ratio``; ``model="grid"``
    needs ``grid_half_width``. Rules on the target: ``fit_size`` is at least its size and
    ``grid_half_width`` (model "grid") at least its radius.
    """

    kernel_name = "target"

    unknown_key = "unknown option of fit_resistive_mesh"

    # a pydantic Annotated type built at run time, which a static checker cannot evaluate
    bounds: structured("fsdvs_hw.realise.mesh.bounds:MeshBounds", "MeshBounds") | None = field(  # type: ignore[valid-type]
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
        None, "px", "half-width of the finite grid (model 'grid'; ≥ kernel radius)", ge=0, le=MAX_GRID_HALF_WIDTH
    )
    fit_size: int | None = field(
        None,
        "px",
        "odd window the error is minimised on (≥ kernel size; None: the whole response)",
        ge=1,
        le=MAX_KERNEL_SIZE,
        odd=True,
    )
    n_init: int = field(16, "", "λ values per mesh in the initialisation grid", ge=2, le=40)
    n_starts: int = field(3, "", "IPOPT runs from the best distinct grid points", ge=1, le=10)
    max_iter: int = field(200, "", "IPOPT iteration limit", ge=1, le=10000)
    tol: float = field(1e-14, "", "IPOPT tolerance", ge=1e-16, le=1e-2)

    # ------------------------------------------------------------------ rules
    def option_problems(self) -> list[OptionProblem]:
        """The rules between options (see Notes)."""
        found: list[OptionProblem] = []
        if self.gain == "free" and not self.free_pixel_weight and self.fixed_pixel_weight == 0.0:
            found.append(
                OptionProblem(
                    "pixel_weight",
                    self.pixel_weight,
                    "with gain='free' the pixel path is the gain reference and cannot be 0; use "
                    "pixel_weight='free' or gain='fixed'",
                )
            )
        if self.model == "grid" and self.grid_half_width is None:
            found.append(OptionProblem("grid_half_width", None, "required with model 'grid'"))
        try:
            bounds = self.mesh_bounds
        except InputError as exc:
            return [*found, OptionProblem("bounds", self.bounds, str(exc))]
        lo, hi = bounds.conductance_s
        if not lo <= self.g_lateral_s <= hi:
            why = f"outside bounds.conductance_s = [{lo:g}, {hi:g}] S"
            return [*found, OptionProblem("g_lateral_s", self.g_lateral_s, why)]
        lam_lo, lam_hi = self.lambda_range_px
        if not lam_hi / lam_lo > bounds.min_lambda_ratio:
            why = (
                f"with g_lateral_s={self.g_lateral_s:g} S and conductance_s={bounds.conductance_s} the feasible "
                f"λ range [{lam_lo:g}, {lam_hi:g}] px is narrower than min_lambda_ratio={bounds.min_lambda_ratio:g}"
            )
            found.append(OptionProblem("bounds", self.bounds, why))
        return found

    def target_problems(self, target: Kernel) -> list[OptionProblem]:
        """``fit_size`` at least the target's size; ``grid_half_width`` (model "grid") at least its radius."""
        found = []
        if self.fit_size is not None and self.fit_size < target.size:
            found.append(
                OptionProblem(
                    "fit_size",
                    self.fit_size,
                    f"must be None (whole response) or odd in {target.size}..{MAX_KERNEL_SIZE} for the "
                    f"{target.size}x{target.size} target",
                )
            )
        if self.model == "grid" and self.grid_half_width is not None and self.grid_half_width < target.radius:
            found.append(
                OptionProblem(
                    "grid_half_width",
                    self.grid_half_width,
                    f"model 'grid' needs an integer in {target.radius}..{MAX_GRID_HALF_WIDTH} for the "
                    f"{target.size}x{target.size} target",
                )
            )
        return found

    def target_of(self, kernel: Any) -> Kernel:
        """The target kernel: ``kernel`` coerced at ``pitch_m`` (None refused with its own words)."""
        if kernel is None:
            raise InputError("kernel: expected a fsdvs_hw Kernel, a kernel file or a 2-D array of taps, got None")
        return super().target_of(kernel)

    # ------------------------------------------------------------------ resolved values
    @cached_property
    def mesh_bounds(self) -> MeshBounds:
        """``bounds`` as a :class:`MeshBounds` (the defaults for None)."""
        return as_mesh_bounds(self.bounds)

    @property
    def gain_free(self) -> bool:
        """The overall gain is free (folds into the event threshold)."""
        return self.gain == "free"

    @property
    def free_pixel_weight(self) -> bool:
        """The pixel weight w_p is fitted (``pixel_weight`` "free" or None)."""
        return self.pixel_weight is None or self.pixel_weight == "free"

    @property
    def fixed_pixel_weight(self) -> float:
        """The fixed pixel weight w_p (0.0 when it is fitted)."""
        weight = self.pixel_weight
        return float(weight) if isinstance(weight, (int, float)) else 0.0

    @property
    def model_half_width(self) -> int | None:
        """``grid_half_width`` of the finite-grid model (pixels); None for the lattice."""
        return self.grid_half_width if self.model == "grid" else None

    @property
    def lambda_range_px(self) -> tuple[float, float]:
        """Feasible space constants (px): the λ bounds within those that keep g_v = g_l / λ² inside
        ``bounds.conductance_s``."""
        bounds = self.mesh_bounds
        gmin, gmax = bounds.conductance_s
        lam_lo = max(bounds.lambda_px[0], math.sqrt(self.g_lateral_s / gmax))
        lam_hi = min(bounds.lambda_px[1], math.sqrt(self.g_lateral_s / gmin))
        return lam_lo, lam_hi
