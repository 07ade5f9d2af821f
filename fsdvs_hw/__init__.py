"""fsdvs_hw — design frequency-selective event cameras (FS-DVS).

Bring a learned spatial kernel; fit it to physically realisable forms (dual resistive mesh,
quantised ASIC taps, metalens PSF); push each realisation back through a differentiable event
simulator and task evaluators; score accuracy loss against agreement with the human contrast
sensitivity function (CSF) and against hardware cost.

The public names below are imported lazily, so ``import fsdvs_hw`` stays fast and heavy
dependencies (torch, casadi) load only when used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._lazy import lazy_exports

__version__ = "0.1.0"

# public name -> module that defines it
_LAZY: dict[str, str] = {
    # core
    "Kernel": "fsdvs_hw.kernels",
    "load_kernel": "fsdvs_hw.kernels",
    "as_kernel": "fsdvs_hw.kernels",
    "reference_kernel": "fsdvs_hw.kernels",
    "InputError": "fsdvs_hw.errors",
    "KernelError": "fsdvs_hw.errors",
    "radial_response": "fsdvs_hw.spectra",
    "spectral_summary": "fsdvs_hw.spectra",
    "pixels_per_degree": "fsdvs_hw.spectra",
    "Geometry": "fsdvs_hw.csf",
    "contrast_sensitivity": "fsdvs_hw.csf",
    "csf_agreement": "fsdvs_hw.csf",
    "analyse_kernel": "fsdvs_hw.analysis",
    # sensor (event simulator)
    "SensorConfig": "fsdvs_hw.sensor",
    "event_frames": "fsdvs_hw.sensor",
    "event_list": "fsdvs_hw.sensor",
    "voxel_grid": "fsdvs_hw.sensor",
    "EventSimulator": "fsdvs_hw.sensor",
    "plan_model": "fsdvs_hw.sensor",
    # realisations
    "kernel_error": "fsdvs_hw.realise.base",
    "RealisationSpec": "fsdvs_hw.realise.registry",
    "CostSpec": "fsdvs_hw.realise.registry",
    "register_realisation": "fsdvs_hw.realise.registry",
    "get_realisation": "fsdvs_hw.realise.registry",
    "realisation_names": "fsdvs_hw.realise.registry",
    "fit_resistive_mesh": "fsdvs_hw.realise.mesh",
    "MeshDesign": "fsdvs_hw.realise.mesh",
    "MeshBounds": "fsdvs_hw.realise.mesh",
    "to_spice_netlist": "fsdvs_hw.realise.mesh.spice",
    "mesh_needs_transient": "fsdvs_hw.realise.mesh.dynamics",
    "mismatch_monte_carlo": "fsdvs_hw.realise.mesh.mismatch",
    "fit_asic_taps": "fsdvs_hw.realise.asic",
    "AsicDesign": "fsdvs_hw.realise.asic",
    "fit_metalens": "fsdvs_hw.realise.metalens",
    "MetalensDesign": "fsdvs_hw.realise.metalens",
    # tasks
    "learn_kernel": "fsdvs_hw.tasks.learn",
    "evaluate_kernel": "fsdvs_hw.tasks.learn",
    # design files
    "Design": "fsdvs_hw.design",
    "DesignError": "fsdvs_hw.design",
    "load_design": "fsdvs_hw.design",
    "parse_design": "fsdvs_hw.design",
    # exploration
    "run_exploration": "fsdvs_hw.explore.explore",
    "ResultsStore": "fsdvs_hw.explore.store",
    "write_report": "fsdvs_hw.report",
}

__all__, __getattr__, __dir__ = lazy_exports("fsdvs_hw", _LAZY, globals(), extra=("__version__",))

if TYPE_CHECKING:  # the same names, visible to IDEs and type checkers
    from .analysis import analyse_kernel
    from .csf import Geometry, contrast_sensitivity, csf_agreement
    from .design import Design, DesignError, load_design, parse_design
    from .errors import InputError, KernelError
    from .explore.explore import run_exploration
    from .explore.store import ResultsStore
    from .kernels import Kernel, as_kernel, load_kernel, reference_kernel
    from .realise.asic import AsicDesign, fit_asic_taps
    from .realise.base import kernel_error
    from .realise.mesh import MeshBounds, MeshDesign, fit_resistive_mesh
    from .realise.mesh.dynamics import mesh_needs_transient
    from .realise.mesh.mismatch import mismatch_monte_carlo
    from .realise.mesh.spice import to_spice_netlist
    from .realise.metalens import MetalensDesign, fit_metalens
    from .realise.registry import CostSpec, RealisationSpec, get_realisation, realisation_names, register_realisation
    from .report import write_report
    from .sensor import EventSimulator, SensorConfig, event_frames, event_list, plan_model, voxel_grid
    from .spectra import pixels_per_degree, radial_response, spectral_summary
    from .tasks.learn import evaluate_kernel, learn_kernel
