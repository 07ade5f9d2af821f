"""Metalens realisation: a pixel-scale lens whose PSF is the kernel (pedestal or differential).

Modules
-------
fit
    :class:`LensGeometry`, :class:`MetalensDesign`, :func:`pixel_psf` and :func:`fit_metalens`.
bench
    ``fsdvs-hw bench metalens``.

The shared wave-optics and spectral sampling live one level up (:mod:`fsdvs_hw.realise.optics`,
:mod:`fsdvs_hw.realise.spectral`).
"""

from .fit import (
    DISPERSION_MODELS,
    STRATEGIES,
    LensGeometry,
    MetalensDesign,
    WavelengthPlan,
    fit_metalens,
    local_numerical_aperture,
    pixel_psf,
    plan_wavelength_samples,
)

__all__ = [
    "DISPERSION_MODELS",
    "STRATEGIES",
    "LensGeometry",
    "MetalensDesign",
    "fit_metalens",
    "pixel_psf",
    "local_numerical_aperture",
    "WavelengthPlan",
    "plan_wavelength_samples",
]
