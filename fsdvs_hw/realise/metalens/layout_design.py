r"""The metalens as it would be fabricated: the ``metalens_layout`` realisation ("metalens, layout").

:func:`fit_metalens_layout` fits the ideal-phase lens (:func:`~fsdvs_hw.realise.metalens.fit_metalens`,
the same options and result as the ``metalens`` point), then

1. loads the meta-atom library of its options (:mod:`~fsdvs_hw.realise.metalens.meta_atoms`: the
   committed cache when the fingerprint matches, else RCWA) and keeps the usable radii;
2. places the lattice sites in the aperture and gives each the radius of nearest complex
   transmission (:mod:`~fsdvs_hw.realise.metalens.layout`);
3. computes two PSFs (:mod:`~fsdvs_hw.realise.metalens.layout_psf`): the **library** step (radial,
   the chosen pillars' transmission on a continuous radius) and the **layout** (the lattice of
   sites, 2-D), each over the illuminant's spectrum with the library's own dispersion, and refits
   the closed-form gains and pedestal (:func:`~fsdvs_hw.realise.metalens.fit.fit_gains`) to each.

The realised kernel is the layout's. The record keeps all three steps (ideal phase → library →
layout) so the report shows what each costs; efficiency and the photon budget come from the layout
PSF, whose taps are fractions of the power on the ideal aperture, and the mean library power
transmission over the used sites is reported beside it.

Example
-------
A small lens (20 µm aperture, a few RCWA orders and radii; the defaults use the committed library):

>>> from fsdvs_hw import reference_kernel
>>> from fsdvs_hw.realise.metalens.layout_design import fit_metalens_layout
>>> d = fit_metalens_layout(reference_kernel("dog", 3, pitch_m=2e-6), aperture_m=20e-6, focal_length_m=60e-6,
...                         illuminant=555e-9, n_wavelengths=1, n_terms=1, max_iter=5, n_starts=1,
...                         library_wavelengths_m=[555e-9], n_radii=12, fourier_orders=2, check_orders=1,
...                         drc=False, progress=False)  # doctest: +SKIP
>>> d.cost()["pillar_count"].value > 0  # doctest: +SKIP
True
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import InputError
from ...kernels import Kernel
from ...validation import check_fit_arguments
from ..base import CostItem, kernel_error
from .fit import MetalensDesign, RadialKernelModel, fit_gains, fit_metalens
from .layout import assign_levels, lattice_sites
from .layout_psf import layout_psf, library_psf
from .lens import design_phase
from .meta_atoms import MetaAtomLibrary, load_library
from .options import MetalensLayoutOptions, MetalensOptions

__all__ = ["LensLayout", "MetalensLayoutDesign", "build_layout", "fit_metalens_layout", "step_psfs"]

#: Options of the layout beyond the lens's own (MetalensOptions).
LAYOUT_KEYS = tuple(k for k in MetalensLayoutOptions.model_fields if k not in MetalensOptions.model_fields)

#: Gap between the two lenses of a differential pair in the GDS (m).
PAIR_GAP_M = 10e-6


@dataclass(frozen=True)
class LensLayout:
    """The layout of one lens.

    Attributes
    ----------
    sites : numpy.ndarray, shape (N, 2)
        Site centres (m).
    levels : numpy.ndarray of int, shape (N,)
        Per site, the index of its radius in the library's radii.
    theta : float
        Global phase offset (rad) of the level assignment.
    """

    sites: np.ndarray
    levels: np.ndarray
    theta: float


def _usable(library: MetaAtomLibrary, o: Mapping[str, Any], wavelength_m: float) -> np.ndarray:
    mask = library.usable(
        wavelength_m, transmission_min=float(o["transmission_min"]), phase_tolerance_rad=float(o["phase_tolerance_rad"])
    )
    if mask.sum() < 2:
        raise InputError(
            f"meta-atom library {library.spec.fingerprint}: {int(mask.sum())} usable radii (transmission_min="
            f"{o['transmission_min']}, phase_tolerance_rad={o['phase_tolerance_rad']}); widen the radius range or relax them"
        )
    return np.flatnonzero(mask)


def build_layout(ideal: MetalensDesign, options: Mapping[str, Any], library: MetaAtomLibrary) -> list[LensLayout]:
    """Sites and radius levels of each lens of ``ideal`` (deterministic: the artifacts rebuild it)."""
    g = ideal.geometry
    i0 = library.index_of_wavelength(g.design_wavelength_m)
    usable = _usable(library, options, g.design_wavelength_m)
    t0 = library.transmission[i0, usable]
    sites = lattice_sites(g.radius_m, float(options["period_m"]), str(options["lattice"]))
    out = []
    for coeffs in ideal.coefficients:
        phase = design_phase(np.hypot(sites[:, 0], sites[:, 1]), g, np.asarray(coeffs, dtype=float))
        lv, theta = assign_levels(phase, t0)
        out.append(LensLayout(sites, usable[lv].astype(np.int32), theta))
    return out


@dataclass(frozen=True, eq=False)
class MetalensLayoutDesign:
    """A metalens as a layout: the ideal-phase fit, the library step and the layout, with their PSFs.

    Attributes
    ----------
    ideal : MetalensDesign
        The ideal-phase lens (what the ``metalens`` point realises).
    library_step : MetalensDesign
        The same lens with the library's transmission on a continuous radius (radial PSF, gains refit).
    layout : MetalensDesign
        The lattice of pillars (2-D PSF, gains refit): what this realisation applies.
    options : dict
        The layout options (material, period, lattice, radii, rules, GDS layer, …).
    layout_info : dict
        Library fingerprint and provenance, sites, levels, transmission, timings.

    Examples
    --------
    >>> from fsdvs_hw.realise.metalens.layout_design import MetalensLayoutDesign
    >>> MetalensLayoutDesign.__name__
    'MetalensLayoutDesign'
    """

    ideal: MetalensDesign
    library_step: MetalensDesign
    layout: MetalensDesign
    options: Mapping[str, Any]
    layout_info: Mapping[str, Any] = field(default_factory=dict)
    kind: str = field(default="metalens_layout", init=False)

    @property
    def target(self) -> Kernel:
        return self.ideal.target

    def kernel(self) -> Kernel:
        """What the sensor applies through the layout (g·P_layout, or the differential pair's difference)."""
        k = self.layout.kernel()
        return k.with_taps(
            k.taps, name=f"metalens layout[{self.layout.strategy}] {self.target.name}", realisation="metalens_layout"
        )

    def kernel_error(self, target: Kernel | np.ndarray | None = None, *, fit_scale: bool = False) -> float:
        """Relative L2 error of the layout's applied kernel against ``target`` (default the design's)."""
        return kernel_error(self.kernel(), self.target if target is None else target, fit_scale=fit_scale)

    @property
    def error(self) -> float:
        return self.kernel_error()

    def cost(self) -> dict[str, CostItem]:
        info = self.layout_info
        out = dict(self.layout.cost())
        out["fit_time"] = CostItem(
            float(info.get("wall_time_s", math.nan)), "s", "ideal fit + library + layout + PSFs wall time"
        )
        out["ideal_kernel_error"] = CostItem(self.ideal.error, "1", "kernel error of the ideal-phase lens (step 0)")
        out["library_kernel_error"] = CostItem(
            self.library_step.error, "1", "kernel error with the library's pillars on a continuous radius (step 1)"
        )
        out["pillar_count"] = CostItem(int(info["pillars"]), "count", "pillars in the GDS (all lenses)")
        out["radius_levels"] = CostItem(int(info["radius_levels"]), "count", "distinct pillar radii used")
        out["library_transmission"] = CostItem(
            float(info["library_transmission"]),
            "1",
            "mean library power transmission |t|² over the used sites and the spectrum",
        )
        out["pillar_height"] = CostItem(
            float(self.options["pillar_height_m"]), "m", "pillar height (meta-atom library)"
        )
        out["lattice_period"] = CostItem(float(self.options["period_m"]), "m", "lattice period (meta-atom library)")
        return out

    def describe(self) -> str:
        info, o = self.layout_info, self.options
        return "\n".join(
            [
                f"metalens layout: {info['pillars']} {o['material']} pillars ({o['pillar_height_m'] * 1e9:.0f} nm high, "
                f"{o['lattice']} lattice, {o['period_m'] * 1e9:.0f} nm period) on {o['substrate']}, "
                f"{info['radius_levels']} radius levels of {info['usable_radii']} usable",
                f"  kernel error: ideal phase {self.ideal.error:.3f} → library {self.library_step.error:.3f} → "
                f"layout {self.layout.error:.3f}; window efficiency {min(self.layout.optical_efficiency):.3f} "
                f"(ideal {min(self.ideal.optical_efficiency):.3f}); library |t|² {info['library_transmission']:.3f}",
                f"  library {info['library_fingerprint']} ({info['library_solver']}, {info['harmonics']} harmonics)",
            ]
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "ideal": self.ideal.to_dict(),
            "library_step": self.library_step.to_dict(),
            "layout": self.layout.to_dict(),
            "options": dict(self.options),
            "layout_info": dict(self.layout_info),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MetalensLayoutDesign:
        try:
            return cls(
                ideal=MetalensDesign.from_dict(data["ideal"]),
                library_step=MetalensDesign.from_dict(data["library_step"]),
                layout=MetalensDesign.from_dict(data["layout"]),
                options=dict(data["options"]),
                layout_info=dict(data.get("layout_info", {})),
            )
        except KeyError as exc:
            raise InputError(f"metalens layout design: missing field {exc.args[0]!r}") from None


def _step_design(
    ideal: MetalensDesign, psfs: list[np.ndarray], totals: list[float], step: str, info: dict[str, Any]
) -> MetalensDesign:
    """``ideal`` with other PSFs and the closed-form gains and pedestal refitted to them."""
    gains, pedestal = fit_gains(psfs, ideal.target, guard_px=ideal.guard_px, strategy=ideal.strategy, totals=totals)
    return dataclasses.replace(
        ideal,
        psfs=tuple(psfs),
        psf_totals=tuple(totals),
        gains=gains,
        pedestal=pedestal,
        fit_info={**dict(ideal.fit_info), "step": step, **info},
    )


def step_psfs(
    ideal: MetalensDesign, lenses: list[LensLayout], library: MetaAtomLibrary, options: Mapping[str, Any]
) -> tuple[list[tuple[np.ndarray, float]], list[tuple[np.ndarray, float]], np.ndarray]:
    """Library-step and layout PSFs (taps, total) per lens, and t (L, radii) at the spectral samples."""
    g, spectral, k = ideal.geometry, ideal.spectral, ideal.target
    n_pix = k.size + 2 * ideal.guard_px
    t_spec = library.at_wavelengths(spectral.wavelengths_m)
    i0 = library.index_of_wavelength(g.design_wavelength_m)
    usable = _usable(library, options, g.design_wavelength_m)
    model = RadialKernelModel(
        g,
        pitch_m=k.pitch_m,
        n_pixels=n_pix,
        spectral=spectral,
        window_pad=3.0,
        na_budget=float(ideal.fit_info.get("na_budget", 0.0)) or None,
    )
    lib_out, lay_out = [], []
    for coeffs, z, lens in zip(ideal.coefficients, ideal.sensor_distance_m, lenses):
        phase = design_phase(model.prop.r_pupil, g, np.asarray(coeffs, dtype=float))
        lv, _ = assign_levels(phase, library.transmission[i0, usable], theta=lens.theta)
        lib_out.append(library_psf(model, t_spec[:, usable[lv]], z))
        lay_out.append(
            layout_psf(
                lens.sites,
                t_spec[:, lens.levels],
                period_m=float(options["period_m"]),
                lattice=str(options["lattice"]),
                aperture_radius_m=g.radius_m,
                spectral=spectral,
                sensor_distance_m=z,
                pitch_m=k.pitch_m,
                n_pixels=n_pix,
                focal_length_m=g.focal_length_m,
            )
        )
    return lib_out, lay_out, t_spec


def _layout_info(
    lenses: list[LensLayout],
    library: MetaAtomLibrary,
    t_spec: np.ndarray,
    weights: np.ndarray,
    options: Mapping[str, Any],
    lam0: float,
) -> dict[str, Any]:
    levels = np.concatenate([lens.levels for lens in lenses])
    power = np.abs(t_spec[:, levels]) ** 2  # (L, sites)
    i0 = library.index_of_wavelength(lam0)
    usable = _usable(library, options, lam0)
    phase = np.unwrap(np.angle(library.transmission[i0, usable]))
    return {
        "pillars": int(levels.size),
        "sites_per_lens": [int(lens.levels.size) for lens in lenses],
        "radius_levels": int(np.unique(levels).size),
        "usable_radii": int(usable.size),
        "library_radii": int(library.radii_m.size),
        "library_transmission": float(weights @ power.mean(axis=1)),
        "library_transmission_design": float((np.abs(library.transmission[i0, levels]) ** 2).mean()),
        "usable_phase_span_rad": float(phase.max() - phase.min()),
        "max_phase_change_rad": float(library.phase_change(lam0)[usable].max()),
        "theta_rad": [lens.theta for lens in lenses],
        "library_fingerprint": library.spec.fingerprint,
        "library_solver": str(library.provenance.get("solver", "")),
        "harmonics": int((2 * library.spec.fourier_orders + 1) ** 2),
    }


def fit_metalens_layout(
    kernel: Kernel,
    *,
    pitch_m: float | None = None,
    illuminant: Any = "D65",
    response: Any = None,
    strategy: str = "pedestal",
    aperture_m: float | None = 100e-6,
    focal_length_m: float | None = 200e-6,
    design_wavelength_m: float = 555e-9,
    dispersion: str = "diffractive",
    n_terms: int = 4,
    n_wavelengths: int | str = 24,
    guard_px: int = 2,
    max_iter: int = 150,
    n_starts: int = 6,
    n_sub: int | None = None,
    window_pad: float = 2.0,
    na_max: float | None = None,
    progress: bool | None = None,
    material: str | float = "TiO2_siefke",
    substrate: str | float = "SiO2_malitson",
    pillar_height_m: float = 600e-9,
    period_m: float = 300e-9,
    lattice: str = "square",
    min_radius_m: float = 40e-9,
    max_radius_m: float = 125e-9,
    n_radii: int = 44,
    library_wavelengths_m: list[float] | None = None,
    fourier_orders: int = 7,
    check_orders: int = 5,
    transmission_min: float = 0.5,
    phase_tolerance_rad: float = 0.1,
    min_width_m: float = 70e-9,
    min_space_m: float = 40e-9,
    gds_layer: int = 1,
    gds_datatype: int = 0,
    drc: bool = True,
    compute_library: bool = True,
) -> MetalensLayoutDesign:
    """Fit the ideal-phase metalens, then realise it as a lattice of library pillars (module docstring).

    Parameters
    ----------
    kernel : Kernel or array_like
        Target kernel (as :func:`~fsdvs_hw.realise.metalens.fit_metalens`).
    pitch_m, illuminant, response, strategy, aperture_m, focal_length_m, design_wavelength_m, dispersion, \
n_terms, n_wavelengths, guard_px, max_iter, n_starts, n_sub, window_pad, na_max, progress
        The lens's options (:class:`~fsdvs_hw.realise.metalens.MetalensOptions`).
    material, substrate, pillar_height_m, period_m, lattice, min_radius_m, max_radius_m, n_radii, \
library_wavelengths_m, fourier_orders, check_orders, transmission_min, phase_tolerance_rad, min_width_m, \
min_space_m, gds_layer, gds_datatype, drc, compute_library
        The layout's options (:class:`~fsdvs_hw.realise.metalens.options.MetalensLayoutOptions`).

    Returns
    -------
    MetalensLayoutDesign
    """
    o = check_fit_arguments(MetalensLayoutOptions, locals())
    t0 = time.perf_counter()
    ideal = fit_metalens(o.target, **{k: getattr(o, k) for k in MetalensOptions.model_fields})
    options = {k: getattr(o, k) for k in LAYOUT_KEYS}
    library = load_library(o.meta_atom_spec(), compute=o.compute_library, progress=o.progress)
    t1 = time.perf_counter()
    lenses = build_layout(ideal, options, library)
    lib_psfs, lay_psfs, t_spec = step_psfs(ideal, lenses, library, options)
    info = _layout_info(lenses, library, t_spec, ideal.spectral.weights, options, ideal.geometry.design_wavelength_m)
    info["layout_time_s"] = time.perf_counter() - t1
    info["wall_time_s"] = time.perf_counter() - t0
    lib_step = _step_design(ideal, [p for p, _ in lib_psfs], [t for _, t in lib_psfs], "library", {})
    layout = _step_design(ideal, [p for p, _ in lay_psfs], [t for _, t in lay_psfs], "layout", {})
    return MetalensLayoutDesign(ideal=ideal, library_step=lib_step, layout=layout, options=options, layout_info=info)
