"""Dual resistive mesh realisation: K = w·δ + a·H_narrow − b·H_wide, fitted with casadi/IPOPT.

Modules
-------
fit
    :class:`MeshDesign` and :func:`fit_resistive_mesh`.
bounds
    :class:`MeshBounds`: the reachable space constants, gains and conductances.
response
    Single-mesh responses: exact lattice Green's function, finite grid (DCT), continuum.
dynamics
    Node-capacitance transients: when a moving edge needs a transient model.
mismatch
    Monte-Carlo conductance mismatch.
spice
    SPICE netlist export and ngspice cross-check.
artifacts
    The buildable files an exploration writes: the ngspice deck and its operating point.
bench
    ``fsdvs-hw bench mesh``.
options
    :class:`MeshOptions`: the fit options (type, unit, range, default, help) and their rules.
process_mesh
    ``mesh_process``: the mesh built as subthreshold transistors of a real process (:mod:`fsdvs_hw.process`).

Importing this package registers ``"mesh"`` and ``"mesh_process"`` in :mod:`fsdvs_hw.realise.registry`.
"""

from collections.abc import Mapping as _Mapping
from typing import Any as _Any

from ..registry import CostSpec, RealisationSpec, register_realisation
from . import fit
from .bounds import MeshBounds, as_mesh_bounds
from .fit import (
    GAIN_MODES,
    MESH_MODELS,
    MeshAsymmetryWarning,
    MeshDesign,
    MeshFitWarning,
    fit_resistive_mesh,
    mismatch_sensitivity,
)
from .options import MeshOptions
from .process_mesh import ProcessMeshDesign, ProcessMeshOptions, fit_process_mesh

__all__ = [
    "PROCESS_SPEC",
    "SPEC",
    "MeshBounds",
    "MeshOptions",
    "ProcessMeshDesign",
    "ProcessMeshOptions",
    "as_mesh_bounds",
    "fit_process_mesh",
]
__all__ += fit.__all__  # the fit module's public names, re-exported above


def _conductance_per_pixel(cost: "_Mapping[str, _Mapping[str, _Any]]") -> float | None:
    """Summed conductances of one pixel's two meshes (S): ``2 g_l + g_v`` each (a node shares each
    of its four lateral links with a neighbour); proportional to the static current at a bias."""
    parts: list[_Any] = [
        (cost.get(f"g_{d}_{w}") or {}).get("value") for w in ("narrow", "wide") for d in ("lateral", "vertical")
    ]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in parts):
        return None
    gl_n, gv_n, gl_w, gv_w = (float(v) for v in parts)
    return 2 * gl_n + gv_n + 2 * gl_w + gv_w


#: The registry entry (the mesh's own cost axis: conductance per pixel; headline: the wide mesh's
#: settling time, since its area is fixed at six conductances per pixel).
SPEC = register_realisation(
    RealisationSpec(
        name="mesh",
        differentiable="fsdvs_hw.realise.mesh.differentiable:MeshKernel",
        fit=fit_resistive_mesh,
        options=MeshOptions,
        kind="hardware",
        record_type=MeshDesign,
        costs=(
            CostSpec(
                "conductance_per_pixel",
                "S",
                "conductance per pixel",
                "µS",
                1e6,
                pareto=True,
                derive=_conductance_per_pixel,
            ),
            CostSpec("tau_wide", "s", "wide-mesh settling time", "µs", 1e6, headline=True),
            CostSpec("g_lateral_narrow", "S"),
            CostSpec("g_vertical_narrow", "S"),
            CostSpec("g_lateral_wide", "S"),
            CostSpec("g_vertical_wide", "S"),
            CostSpec("node_capacitance", "F"),
            CostSpec("resistors_per_pixel", "count"),
        ),
        artifacts={
            "spice_netlist": "ngspice deck of both meshes with an impulse current (mesh.cir)",
            "operating_point": "node voltages, ground currents and kernel taps the deck reproduces (CSV)",
        },
        write_artifacts="fsdvs_hw.realise.mesh.artifacts:write_mesh_artifacts",
        colour="#1f77b4",
        title="resistive mesh",
        marker="D",
        in_default_design=True,
        description="dual resistive mesh: K = w·δ + a·H_narrow − b·H_wide (casadi/IPOPT)",
    )
)


#: The process-level mesh (transistors of a registered PDK, corners, temperatures, mismatch).
PROCESS_SPEC = register_realisation(
    RealisationSpec(
        name="mesh_process",
        fit=fit_process_mesh,
        options=ProcessMeshOptions,
        kind="hardware",
        record_type=ProcessMeshDesign,
        costs=(
            CostSpec("mesh_area_m2", "m^2", "mesh area per pixel", "µm²", 1e12, pareto=True),
            CostSpec("kernel_error_worst_corner", "1", "kernel error at the worst corner", headline=True),
            CostSpec("power_w", "W", "mesh power per pixel", "nW", 1e9),
        ),
        artifacts={
            "transistor_deck": "ngspice deck of both meshes as PDK transistors, with the .lib line (mesh_sky130.cir)",
            "process_corners": "conductances and kernel errors per corner and temperature, mismatch mean and CI (CSV)",
        },
        write_artifacts="fsdvs_hw.realise.mesh.process_mesh:write_process_mesh_artifacts",
        colour="#17becf",
        title="mesh in sky130 transistors",
        marker="d",
        description="the dual mesh as subthreshold transistors of a real process, at corners and under mismatch",
    )
)
