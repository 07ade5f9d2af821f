"""Dual resistive mesh realisation: K = w·δ + a·H_narrow − b·H_wide, fitted with casadi/IPOPT.

Modules
-------
fit
    :class:`MeshDesign`, :class:`MeshBounds` and :func:`fit_resistive_mesh`.
response
    Single-mesh responses: exact lattice Green's function, finite grid (DCT), continuum.
dynamics
    Node-capacitance transients: when a moving edge needs a transient model.
mismatch
    Monte-Carlo conductance mismatch.
spice
    SPICE netlist export and ngspice cross-check.
bench
    ``fsdvs-hw bench mesh``.
"""

from .fit import (
    GAIN_MODES,
    MESH_MODELS,
    MeshAsymmetryWarning,
    MeshBounds,
    MeshDesign,
    MeshFitWarning,
    fit_resistive_mesh,
    mismatch_sensitivity,
)

__all__ = [
    "MeshBounds",
    "MeshDesign",
    "MeshAsymmetryWarning",
    "MeshFitWarning",
    "MESH_MODELS",
    "GAIN_MODES",
    "fit_resistive_mesh",
    "mismatch_sensitivity",
]
