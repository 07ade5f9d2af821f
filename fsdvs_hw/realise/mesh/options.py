"""Fit options of :func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh`: type, unit, range, default, meaning.

The design loader checks a ``[realisations.mesh]`` table against :data:`OPTIONS` and
:func:`fit_resistive_mesh` checks its own arguments against it at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words. The ranges are the fit function's own (see its docstring).
"""

from __future__ import annotations

from ...validation import PITCH_RANGE_M, Option, option

__all__ = ["OPTIONS"]

#: option → schema
OPTIONS: dict[str, Option] = {
    "bounds": option("object", None, "", "MeshBounds fields: lambda_px, gain, min_lambda_ratio, conductance_s",
                     nullable=True),
    "pitch_m": option("float", None, "m", "pixel pitch (default: the kernel's)", nullable=True,
                      lo=PITCH_RANGE_M[0], hi=PITCH_RANGE_M[1]),
    "pixel_weight": option("float|str", "free", "", "fixed weight of the pixel's own signal, or 'free'",
                           lo=0.0, hi=1e3, choices=("free",), nullable=True),
    "gain": option("str", "free", "", "overall gain: 'free' (folds into the event threshold) or 'fixed'",
                   choices=("free", "fixed")),
    "nonnegative_dc": option("bool", True, "", "constrain the whole-circuit DC gain w_p + a − b ≥ 0"),
    "mismatch_sigma": option("float", 0.01, "", "relative die-level mismatch σ", lo=0.0, hi=0.5),
    "max_mismatch_error": option("float", 0.05, "", "largest first-order kernel error at mismatch σ (None: off)",
                                 lo=1e-6, hi=10.0, nullable=True),
    "g_lateral_s": option("float", 1e-8, "S", "lateral conductance of both meshes (within bounds.conductance_s)",
                          lo=1e-13, hi=1e-3),
    "node_capacitance_f": option("float", 100e-15, "F", "node capacitance of both meshes", lo=1e-18, hi=1e-6),
    "model": option("str", "lattice", "", "single-mesh model", choices=("lattice", "grid")),
    "grid_half_width": option("int", None, "px", "half-width of the finite grid (model 'grid'; ≥ kernel radius)",
                              lo=0, hi=60, nullable=True),
    "fit_size": option("int", None, "px", "odd window the error is minimised on (≥ kernel size; None: the "
                       "whole response)", lo=1, hi=63, odd=True, nullable=True),
    "n_init": option("int", 16, "", "λ values per mesh in the initialisation grid", lo=2, hi=40),
    "n_starts": option("int", 3, "", "IPOPT runs from the best distinct grid points", lo=1, hi=10),
    "max_iter": option("int", 200, "", "IPOPT iteration limit", lo=1, hi=10000),
    "tol": option("float", 1e-14, "", "IPOPT tolerance", lo=0.0, hi=1.0, lo_open=True),
}
