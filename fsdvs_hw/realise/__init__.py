"""Physical realisations of a kernel: dual resistive mesh, quantised ASIC taps, metalens PSF.

Each realisation module is imported only when used (casadi, torch and external tools are heavy).
"""

from .base import REALISATION_KINDS, CostItem, Realisation, ReferenceRealisation, kernel_error, realisation_from_dict

__all__ = [
    "CostItem",
    "Realisation",
    "ReferenceRealisation",
    "REALISATION_KINDS",
    "realisation_from_dict",
    "kernel_error",
]
