r"""Monte Carlo over device mismatch of a dual resistive mesh: kernel-error distribution and yield.

Every conductance of both meshes (each lateral edge and each vertical element) and each of the
three output gains is drawn independently as :math:`g\,e^{\sigma z}`, :math:`z \sim N(0, 1)`
(log-normal, always positive; for small σ the relative standard deviation is σ). For each draw
the KCL system of a finite open-edge grid is solved with a sparse LU (the conductances vary from
node to node, so the DCT / Green's function forms no longer apply), and the kernel seen by the
centre pixel is read off (by reciprocity the row of the inverse KCL matrix equals its column).
The output stages are calibrated to the nominal g_v, as on a real chip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import InputError
from ..base import kernel_error

__all__ = ["MismatchResult", "mismatch_monte_carlo"]


@dataclass(frozen=True)
class MismatchResult:
    """Outcome of :func:`mismatch_monte_carlo`.

    Attributes
    ----------
    errors : ndarray, shape (n_trials,)
        Relative L2 kernel error of each draw against ``reference``.
    errors_vs_nominal : ndarray, shape (n_trials,)
        Relative L2 difference of each draw from the nominal (mismatch-free) design.
    reference : str
        "target" (the kernel the design was fitted to) or "nominal" (no target known).
    nominal_error : float
        Error of the mismatch-free design against ``reference`` (0 for "nominal").
    yield_fraction : float
        Fraction of draws with ``errors ≤ tolerance``.
    tolerance, sigma, gain_sigma : float
        The settings used.
    half_width : int
        Grid half-width (pixels) of the Monte Carlo model.
    """

    errors: np.ndarray
    errors_vs_nominal: np.ndarray
    reference: str
    nominal_error: float
    yield_fraction: float
    tolerance: float
    sigma: float
    gain_sigma: float
    half_width: int

    def summary(self) -> dict[str, float]:
        """Mean, median, 95th percentile and max of the error, and the yield."""
        e = self.errors
        return {
            "mean": float(e.mean()),
            "median": float(np.median(e)),
            "p95": float(np.percentile(e, 95)),
            "max": float(e.max()),
            "yield": self.yield_fraction,
        }


def mismatch_monte_carlo(
    design: Any,
    *,
    sigma: float = 0.01,
    gain_sigma: float | None = None,
    n_trials: int = 200,
    tolerance: float = 0.05,
    half_width: int | None = None,
    seed: int = 0,
) -> MismatchResult:
    """Kernel-error distribution and yield of ``design`` under random element mismatch.

    Parameters
    ----------
    design : MeshDesign
    sigma : float
        Relative mismatch (log-normal σ) of each conductance, 0 … 0.5.
    gain_sigma : float, optional
        Relative mismatch of the three output gains (default ``sigma``).
    n_trials : int
        Monte Carlo draws (1 … 100000).
    tolerance : float
        Kernel error accepted as working; the yield is the fraction of draws within it.
    half_width : int, optional
        Grid half-width (pixels), default ``r + 3 + ceil(3 λ_wide)`` capped at 60.
    seed : int
        Seed of ``numpy.random.default_rng``.

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw import fit_resistive_mesh, reference_kernel
    >>> from fsdvs_hw.realise.mesh.mismatch import mismatch_monte_carlo
    >>> d = fit_resistive_mesh(reference_kernel("dog", 5))
    >>> mc = mismatch_monte_carlo(d, sigma=0.01, n_trials=20, tolerance=0.5, seed=0)
    >>> mc.errors.shape, mc.yield_fraction  # 1 % mismatch: every draw within 0.5
    ((20,), 1.0)
    >>> bool(abs(np.median(mc.errors) - mc.nominal_error) < 0.05)  # and close to the nominal design
    True
    """
    import scipy.sparse.linalg as spla

    from .response import mesh_kcl_matrix

    gain_sigma, h = _checked_arguments(design, sigma, gain_sigma, tolerance, n_trials, half_width)
    r = design.size // 2
    n = 2 * h + 1
    n_edges = 2 * n * (n - 1)
    centre = h * n + h
    e_c = np.zeros(n * n)
    e_c[centre] = 1.0
    win = slice(h - r, h + r + 1)
    meshes = (
        (design.g_lateral_narrow_s, design.g_vertical_narrow_s),
        (design.g_lateral_wide_s, design.g_vertical_wide_s),
    )

    def kernel(mult_l, mult_v, gains):
        hs = []
        for (gl, gv), ml, mv in zip(meshes, mult_l, mult_v):
            v = spla.spsolve(mesh_kcl_matrix(h, gl * ml, gv * mv), e_c)
            hs.append((gv * v).reshape(n, n)[win, win])  # readout calibrated to the nominal g_v
        k = gains[1] * design.gain_narrow * hs[0] - gains[2] * design.gain_wide * hs[1]
        k[r, r] += gains[0] * design.pixel_weight
        return k

    ones_l, ones_v = [np.ones(n_edges)] * 2, [np.ones(n * n)] * 2
    nominal = kernel(ones_l, ones_v, np.ones(3))
    target = design.target
    reference = "target" if target is not None else "nominal"
    ref = target if target is not None else nominal
    rng = np.random.default_rng(seed)
    errs, errs_nom = np.empty(n_trials), np.empty(n_trials)
    for i in range(n_trials):
        ml = [np.exp(sigma * rng.standard_normal(n_edges)) for _ in meshes]
        mv = [np.exp(sigma * rng.standard_normal(n * n)) for _ in meshes]
        k = kernel(ml, mv, np.exp(gain_sigma * rng.standard_normal(3)))
        errs[i] = kernel_error(k, ref)
        errs_nom[i] = kernel_error(k, nominal)
    return MismatchResult(
        errors=errs,
        errors_vs_nominal=errs_nom,
        reference=reference,
        nominal_error=kernel_error(nominal, ref),
        yield_fraction=float(np.mean(errs <= tolerance)),
        tolerance=float(tolerance),
        sigma=float(sigma),
        gain_sigma=float(gain_sigma),
        half_width=h,
    )


def _checked_arguments(
    design: Any, sigma: Any, gain_sigma: Any, tolerance: Any, n_trials: Any, half_width: Any
) -> tuple[float, int]:
    """The arguments of :func:`mismatch_monte_carlo` checked; returns the gain σ (default: ``sigma``)
    and the grid half-width (pixels; default from the wide mesh's space constant)."""
    from .fit import MeshDesign
    from .response import grid_half_width_for

    if not isinstance(design, MeshDesign):
        raise InputError(f"design: expected a MeshDesign, got {type(design).__name__}")
    gain_sigma = sigma if gain_sigma is None else gain_sigma
    for name, v, hi in (("sigma", sigma, 0.5), ("gain_sigma", gain_sigma, 0.5), ("tolerance", tolerance, 1e6)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= hi):
            raise InputError(f"{name}={v!r} outside the allowed range [0, {hi:g}]")
    if not (isinstance(n_trials, (int, np.integer)) and 1 <= n_trials <= 100000):
        raise InputError(f"n_trials: must be an integer in 1..100000, got {n_trials!r}")
    r = design.size // 2
    if half_width is None:
        half_width = min(60, grid_half_width_for(design.lambda_wide_px, r))
    if not (isinstance(half_width, (int, np.integer)) and r <= half_width <= 200):
        raise InputError(f"half_width: must be an integer in {r}..200, got {half_width!r}")
    return gain_sigma, int(half_width)
