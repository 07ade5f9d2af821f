"""Metalens realisation: a pixel-scale lens whose PSF is the kernel (pedestal or differential).

Modules
-------
lens
    :class:`LensGeometry`, the phase profile and the local numerical aperture.
fit
    :class:`MetalensDesign`, :func:`pixel_psf` and :func:`fit_metalens`.
artifacts
    The buildable files an exploration writes: phase profile (CSV/NPZ), PSF and plot.
bench
    ``fsdvs-hw bench metalens``.
options
    :class:`MetalensOptions`: the fit options (type, unit, range, default, help) and their rules.

The shared wave-optics and spectral sampling live one level up (:mod:`fsdvs_hw.realise.optics`,
:mod:`fsdvs_hw.realise.spectral`). Importing this package registers ``"metalens"`` in
:mod:`fsdvs_hw.realise.registry`.
"""

from ..registry import CostSpec, RealisationSpec, register_realisation
from . import fit
from .fit import (
    STRATEGIES,
    MetalensDesign,
    WavelengthPlan,
    fit_metalens,
    pixel_psf,
    plan_wavelength_samples,
)
from .lens import DISPERSION_MODELS, LensGeometry, design_phase, local_numerical_aperture
from .options import MetalensOptions

__all__ = ["DISPERSION_MODELS", "SPEC", "LensGeometry", "MetalensOptions", "design_phase", "local_numerical_aperture"]
__all__ += fit.__all__  # the fit module's public names, re-exported above

#: The registry entry (own cost axis and headline: the aperture diameter).
SPEC = register_realisation(
    RealisationSpec(
        name="metalens",
        differentiable="fsdvs_hw.realise.metalens.differentiable:MetalensKernel",
        fit=fit_metalens,
        options=MetalensOptions,
        kind="hardware",
        record_type=MetalensDesign,
        costs=(
            CostSpec("aperture_diameter", "m", "aperture", "µm", 1e6, pareto=True, headline=True),
            CostSpec("focal_length", "m"),
            CostSpec("optical_efficiency", "1", "optical efficiency"),
            CostSpec("lens_count", "count"),
            CostSpec("kernel_error", "1"),
        ),
        artifacts={
            "phase_profile_csv": "phase vs radius per lens, SI columns (phase_profile.csv)",
            "phase_profile_npz": "the profile with wavelengths, focal length, NA, pitch (phase_profile.npz)",
            "psf": "pixel-integrated PSF per lens and the applied kernel (psf.npz)",
            "plot": "phase profile and PSF (phase_psf.png)",
        },
        write_artifacts="fsdvs_hw.realise.metalens.artifacts:write_metalens_artifacts",
        colour="#2ca02c",
        title="metalens",
        marker="v",
        in_default_design=True,
        description="metalens whose pixel-integrated PSF is the kernel (pedestal or differential pair)",
    )
)
