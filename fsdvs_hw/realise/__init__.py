"""Physical realisations of a kernel: dual resistive mesh, quantised ASIC taps, metalens PSF.

One folder per realisation (:mod:`~fsdvs_hw.realise.mesh`, :mod:`~fsdvs_hw.realise.asic`,
:mod:`~fsdvs_hw.realise.metalens`) beside the shared protocol (:mod:`~fsdvs_hw.realise.base`),
wave optics (:mod:`~fsdvs_hw.realise.optics`), spectral sampling
(:mod:`~fsdvs_hw.realise.spectral`) and the registry every other layer reads
(:mod:`~fsdvs_hw.realise.registry`). Importing this package registers the built-in realisations
(the heavy solvers — casadi, nlopt, yosys — load only inside the fits).
"""

from .base import CostItem, Realisation, ReferenceRealisation, kernel_error, realised_kernel_error
from .registry import (
    REALISATIONS,
    CostSpec,
    RealisationSpec,
    check_realisation_options,
    fit_realisation,
    get_realisation,
    realisation_from_dict,
    realisation_names,
    register_realisation,
    unregister_realisation,
)

# the built-in hardware forms register themselves on import (order = report order)
from . import mesh, asic, metalens  # noqa: E402, F401  isort: skip
from .registry import import_plugins  # noqa: E402  isort: skip

import_plugins()  # realisations registered from outside the package in a parent process

__all__ = [
    "REALISATIONS",
    "CostItem",
    "CostSpec",
    "Realisation",
    "RealisationSpec",
    "ReferenceRealisation",
    "check_realisation_options",
    "fit_realisation",
    "get_realisation",
    "kernel_error",
    "realisation_from_dict",
    "realisation_names",
    "realised_kernel_error",
    "register_realisation",
    "unregister_realisation",
]
