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
    :class:`MetalensOptions`: the fit options (type, unit, range, default, help) and their rules;
    :class:`MetalensLayoutOptions` adds the meta-atoms, the layout and its design rules.
meta_atoms
    The meta-atom library: complex transmission of pillars vs radius by RCWA (meent), cached.
layout
    Lattice sites, the radius of nearest complex transmission per site, the GDSII file (gdstk).
drc
    KLayout's width and space check of the GDS, in a separate process.
layout_psf
    The PSF of the library step and of the layout (per-site transmission, 2-D propagation).
layout_design
    :class:`MetalensLayoutDesign` and :func:`fit_metalens_layout`: the ``metalens_layout`` realisation.
layout_artifacts
    The GDS, its DRC report, the library and the step PSFs an exploration writes.

The shared wave-optics and spectral sampling live one level up (:mod:`fsdvs_hw.realise.optics`,
:mod:`fsdvs_hw.realise.spectral`). Importing this package registers ``"metalens"`` and ``"metalens_layout"`` in
:mod:`fsdvs_hw.realise.registry`.
"""

from ..registry import CostSpec, RealisationSpec, register_realisation
from . import fit
from .fit import (
    STRATEGIES,
    MetalensDesign,
    RadialKernelModel,
    WavelengthPlan,
    fit_gains,
    fit_metalens,
    pixel_psf,
    plan_wavelength_samples,
)
from .layout_design import MetalensLayoutDesign, fit_metalens_layout
from .lens import DISPERSION_MODELS, LensGeometry, design_phase, local_numerical_aperture
from .options import MetalensLayoutOptions, MetalensOptions

__all__ = [
    "DISPERSION_MODELS",
    "LAYOUT_SPEC",
    "SPEC",
    "LensGeometry",
    "MetalensLayoutDesign",
    "MetalensLayoutOptions",
    "MetalensOptions",
    "design_phase",
    "fit_metalens_layout",
    "local_numerical_aperture",
]
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

#: The layout's registry entry ("metalens, layout"): the ideal lens realised as a lattice of library pillars.
LAYOUT_SPEC = register_realisation(
    RealisationSpec(
        name="metalens_layout",
        fit=fit_metalens_layout,
        options=MetalensLayoutOptions,
        kind="hardware",
        record_type=MetalensLayoutDesign,
        costs=(
            CostSpec("aperture_diameter", "m", "aperture", "µm", 1e6, pareto=True, headline=True),
            CostSpec("pillar_count", "count", "pillars"),
            CostSpec("radius_levels", "count", "radius levels"),
            CostSpec("optical_efficiency", "1", "optical efficiency"),
            CostSpec("library_transmission", "1", "library transmission"),
            CostSpec("ideal_kernel_error", "1", "kernel error, ideal phase"),
            CostSpec("library_kernel_error", "1", "kernel error, library"),
            CostSpec("kernel_error", "1"),
            CostSpec("pillar_height", "m", "pillar height", "nm", 1e9),
            CostSpec("lattice_period", "m", "lattice period", "nm", 1e9),
            CostSpec("focal_length", "m"),
            CostSpec("lens_count", "count"),
        ),
        artifacts={
            "gds": "the layout as GDSII: one cell per radius level, one reference per pillar (metalens.gds)",
            "drc": "pillar count read back by gdstk and KLayout's width/space check (drc.json)",
            "meta_atoms": "the meta-atom library used, with its provenance (meta_atoms.json)",
            "layout_psf": "PSFs and kernels of the steps ideal phase → library → layout (layout_psf.npz)",
        },
        write_artifacts="fsdvs_hw.realise.metalens.layout_artifacts:write_layout_artifacts",
        colour="#98df8a",
        title="metalens, layout",
        marker="P",
        in_default_design=False,
        description="the metalens as fabricated: library pillars on a lattice, its PSF from the layout (GDSII, DRC)",
    )
)
