"""fsdvs_hw — design frequency-selective event cameras (FS-DVS).

Bring a learned spatial kernel; fit it to physically realisable forms (dual resistive mesh,
quantised ASIC taps, metalens PSF); push each realisation back through a differentiable event
simulator and task evaluators; score accuracy loss against agreement with the human contrast
sensitivity function (CSF) and against hardware cost.

The public names below are imported lazily, so ``import fsdvs_hw`` stays fast and heavy
dependencies (torch, casadi) load only when used.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

# public name -> module that defines it
_LAZY: dict[str, str] = {
    # core
    "Kernel": "fsdvs_hw.kernels",
    "load_kernel": "fsdvs_hw.kernels",
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
    # exploration
    "load_design": "fsdvs_hw.explore.design",
    "run_exploration": "fsdvs_hw.explore.explore",
    "ResultsStore": "fsdvs_hw.explore.store",
    "write_report": "fsdvs_hw.report",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'fsdvs_hw' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
