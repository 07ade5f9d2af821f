"""Fit options of :func:`~fsdvs_hw.realise.metalens.fit_metalens`: type, unit, range, default, meaning, rules.

The design loader checks a ``[realisations.metalens]`` table against :class:`MetalensOptions` and
:func:`fit_metalens` builds its options object from its arguments at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words, the rules between options and on the target kernel included
(:mod:`fsdvs_hw.realise.fit_options`). With ``n_wavelengths = "auto"`` the spectral samples are
planned from the target by the fit (:func:`~fsdvs_hw.realise.metalens.plan_wavelength_samples`),
which then puts them to the same lens rules (:meth:`MetalensOptions.lens_problems`).
"""

from __future__ import annotations

from functools import cached_property
from typing import Annotated, Any, Literal

from pydantic import Field

from ...errors import InputError
from ...kernels import Kernel
from ...schema import PyObject, field
from ...validation import PITCH_RANGE_M
from ..fit_options import FitOptions, OptionProblem
from ..spectral import SpectralSamples, sampled_spectrum
from .lens import LensGeometry, local_numerical_aperture

__all__ = ["DEFAULT_LIBRARY_WAVELENGTHS_M", "MetalensLayoutOptions", "MetalensOptions"]

#: The library's wavelengths when a design does not say (m): they span D65 × V(λ)'s samples (468–647 nm).
DEFAULT_LIBRARY_WAVELENGTHS_M: tuple[float, ...] = (460e-9, 510e-9, 600e-9, 650e-9)


class MetalensOptions(FitOptions):
    """Keyword options of :func:`~fsdvs_hw.realise.metalens.fit_metalens`, validated, with their rules.

    Attributes
    ----------
    pitch_m : float, optional
        Pixel pitch (m); default the kernel's own pitch (an array's: :data:`~fsdvs_hw.kernels.DEFAULT_PITCH_M`).
    illuminant, response : see :func:`~fsdvs_hw.realise.spectral.spectral_samples`
        Default D65 × CIE 1924 photopic V(λ); a float illuminant is one wavelength (m).
    strategy : {"pedestal", "differential"}
        Signed-kernel strategy (:mod:`fsdvs_hw.realise.metalens.fit`).
    aperture_m, focal_length_m, design_wavelength_m, dispersion
        Fixed lens geometry (:class:`~fsdvs_hw.realise.metalens.LensGeometry`); ``None`` means the
        default (100 µm, 200 µm).
    n_terms : int
        Polynomial phase terms (r/a)^2 … (r/a)^(2·n_terms), 0…12.
    n_wavelengths : int or "auto"
        Spectral samples (equal-weight bins); ``"auto"`` chooses them with
        :func:`~fsdvs_hw.realise.metalens.plan_wavelength_samples` (recorded in
        ``fit_info["wavelength_plan"]``). The multi-start search and the first refinement use at
        most 8; the final polish and the returned PSFs use all of them.
    guard_px : int
        Ring of pixels around the window where spilled light is counted as error.
    max_iter : int
        L-BFGS iterations of the final refinement (each start gets max_iter // 6).
    n_starts : int
        Defocus starting points (blur radii spread over the kernel radius, both signs).
    n_sub, window_pad
        Numerical settings of the radial model used while fitting
        (:func:`~fsdvs_hw.realise.metalens.pixel_psf`). ``n_sub`` None (default) chooses the pixel
        quadrature from the PSF's bandwidth 2·NA/λ_min at the NA budget — the same rule in the fit
        and in the returned PSFs; the returned PSFs are re-evaluated with window_pad ≥ 3 and
        ``fit_info["model_error"]`` says how far the two differ.
    na_max : float, optional
        Largest local NA the phase may use (sets the sampling; penalised in the fit); default
        ``min(0.9, max(1.5 NA, NA + 0.1))`` of the hyperbolic term.
    progress : bool, optional
        A progress bar of the L-BFGS iteration budget on stderr: True, False, or None (default)
        when stderr is a terminal (:func:`fsdvs_hw.progress.progress_enabled`).

    Notes
    -----
    Rules between options (:meth:`lens_problems`, on the spectral samples of ``illuminant``,
    ``response`` and ``n_wavelengths``): the illuminant and response can be sampled; the aperture
    and the focal length exceed 2 λ_max; the NA of the focusing term is at most the NA budget
    (``na_max``), which is below 1. Rule on the target: the strategy "differential" needs both
    negative and positive taps.
    """

    unknown_key = "unknown option of fit_metalens"

    pitch_m: float | None = field(
        None, "m", "pixel pitch (default: the kernel's)", ge=PITCH_RANGE_M[0], le=PITCH_RANGE_M[1]
    )
    illuminant: str | Annotated[float, Field(ge=1e-7, le=2e-5)] | PyObject = field(
        "D65", "m", "colour illuminant name, a spectral distribution, or one wavelength in metres"
    )
    response: str | PyObject | None = field(None, "", "sensor spectral response (default photopic V(λ))")
    strategy: Literal["pedestal", "differential"] = field("pedestal", "", "signed-kernel strategy")
    aperture_m: float | None = field(100e-6, "m", "lens aperture diameter", gt=1e-7, le=1e-1)
    focal_length_m: float | None = field(200e-6, "m", "lens focal length", ge=1e-7, le=1.0)
    design_wavelength_m: float = field(555e-9, "m", "design wavelength", ge=1e-7, le=2e-5)
    dispersion: Literal["diffractive", "achromatic"] = field("diffractive", "", "dispersion model")
    n_terms: int = field(4, "", "polynomial phase terms", ge=0, le=12)
    n_wavelengths: Annotated[int, Field(ge=1, le=200)] | Literal["auto"] = field(24, "", "spectral samples, or 'auto'")
    guard_px: int = field(2, "px", "ring of pixels where spilled light counts as error", ge=0, le=8)
    max_iter: int = field(150, "", "L-BFGS iterations of the final refinement", ge=1, le=100000)
    n_starts: int = field(6, "", "defocus starting points", ge=1, le=1000)
    n_sub: int | None = field(
        None, "", "pixel-integration nodes per axis (None: from the PSF's bandwidth)", ge=1, le=4096
    )
    window_pad: float = field(2.0, "", "radial-model window padding factor", ge=1.0, le=16.0)
    na_max: float | None = field(None, "", "largest local numerical aperture of the phase", gt=0.0, lt=1.0)
    progress: bool | None = field(None, "", "progress bar of the fit's iterations (None: when stderr is a terminal)")

    # ------------------------------------------------------------------ rules
    def option_problems(self) -> list[OptionProblem]:
        """The lens rules on the spectral samples (for ``n_wavelengths="auto"``: the fit's plan)."""
        if self.n_wavelengths == "auto":
            return []
        try:
            spectral = self.spectral_samples(self.n_wavelengths)
        except InputError as exc:
            option = "response" if str(exc).startswith("response") else "illuminant"
            return [OptionProblem(option, getattr(self, option), str(exc))]
        return self.lens_problems(spectral)

    def lens_problems(self, spectral: SpectralSamples) -> list[OptionProblem]:
        """The lens rules on ``spectral``: aperture and focal length above 2 λ_max, and the NA of the
        focusing term within the NA budget (:meth:`na_budget`), itself below 1."""
        lam_max = float(spectral.wavelengths_m.max())
        geometry = self.lens_geometry
        found = []
        if geometry.aperture_m < 2 * lam_max:
            why = (
                f"aperture_m={geometry.aperture_m:.3g} m is below 2 λ_max = {2 * lam_max:.3g} m: scalar diffraction "
                "(and a metasurface of a few unit cells) is not valid there"
            )
            found.append(OptionProblem("aperture_m", self.aperture_m, why))
        if not geometry.focal_length_m > 2 * lam_max:
            why = (
                f"focal_length_m={geometry.focal_length_m:.3g} m is not above 2 λ_max = {2 * lam_max:.3g} m: scalar "
                "diffraction is not valid there"
            )
            found.append(OptionProblem("focal_length_m", self.focal_length_m, why))
        na0 = local_numerical_aperture(geometry, [], spectral.wavelengths_m)
        budget = self.na_budget(na0)
        if not na0 <= budget < 1:
            why = f"na_max={budget:.3g} must be in [NA of the focusing term {na0:.3g}, 1)"
            option = "na_max" if self.na_max is not None else "aperture_m"  # the default budget: the aperture's NA
            found.append(OptionProblem(option, getattr(self, option), why))
        return found

    def target_problems(self, target: Kernel) -> list[OptionProblem]:
        """The strategy "differential" needs negative and positive taps."""
        if self.strategy != "differential":
            return []
        if not (target.taps < 0).any():
            why = "strategy='differential' needs a kernel with negative taps; use 'pedestal' (c = 0)"
            return [OptionProblem("strategy", self.strategy, why)]
        if not (target.taps > 0).any():  # its positive lens would fit nothing
            why = f"strategy='differential' needs a kernel with positive taps; all {target.taps.size} are <= 0"
            return [OptionProblem("strategy", self.strategy, why)]
        return []

    # ------------------------------------------------------------------ resolved values
    @cached_property
    def lens_geometry(self) -> LensGeometry:
        """The fixed lens (:class:`LensGeometry`; None aperture or focal length: its defaults)."""
        defaults = LensGeometry()
        return LensGeometry(
            defaults.aperture_m if self.aperture_m is None else self.aperture_m,
            defaults.focal_length_m if self.focal_length_m is None else self.focal_length_m,
            self.design_wavelength_m,
            self.dispersion,
        )

    def spectral_samples(self, n_wavelengths: int) -> SpectralSamples:
        """``n_wavelengths`` spectral samples of the illuminant and response (the illuminant itself
        when it is already :class:`SpectralSamples`)."""
        return sampled_spectrum(self.illuminant, self.response, n_wavelengths)

    def na_budget(self, na0: float) -> float:
        """Largest local NA the phase may use: ``na_max``, or ``min(0.9, max(1.5 na0, na0 + 0.1))``
        from the focusing term's NA ``na0``."""
        return float(self.na_max) if self.na_max is not None else min(0.9, max(1.5 * na0, na0 + 0.1))


class MetalensLayoutOptions(MetalensOptions):
    """Options of :func:`~fsdvs_hw.realise.metalens.layout_design.fit_metalens_layout`: the lens's
    (:class:`MetalensOptions`, the same fit) plus the meta-atoms, the layout and its design rules.

    Attributes
    ----------
    material, substrate : str or float
        Pillar and substrate (meent's cited tables, e.g. ``"TiO2_siefke"``, ``"SiO2_malitson"``,
        ``"Si3N4_luke"``, or a constant index); :mod:`fsdvs_hw.realise.metalens.meta_atoms`.
    pillar_height_m, period_m : float
        Pillar height and lattice period (m).
    lattice : {"square", "hexagonal"}
        Lattice of the pillar sites.
    min_radius_m, max_radius_m, n_radii
        The library's radii: ``n_radii`` equal steps from ``min_radius_m`` to ``max_radius_m``.
    library_wavelengths_m : list of float, optional
        Wavelengths (m) the library is computed at (the design wavelength is added); they must
        span the illuminant's spectral samples. Default :data:`DEFAULT_LIBRARY_WAVELENGTHS_M`.
    fourier_orders, check_orders : int
        RCWA truncation orders per axis of the library and of its convergence check.
    transmission_min, phase_tolerance_rad : float
        A radius is used when its power transmission at the design wavelength is at least
        ``transmission_min`` and its phase moves by at most ``phase_tolerance_rad`` between the
        two truncation orders.
    min_width_m, min_space_m : float
        Design rules: smallest pillar diameter and smallest gap between pillars (m).
    gds_layer, gds_datatype : int
        GDSII layer and datatype of the pillars.
    drc : bool
        Run KLayout's DRC on the written GDS (a separate process; skipped with a message when
        the ``klayout`` package is absent).
    compute_library : bool
        Compute the library by RCWA when no cached one matches (else refuse).

    Notes
    -----
    Rules: ``2·min_radius_m ≥ min_width_m + 2 nm`` and ``period_m − 2·max_radius_m ≥ min_space_m +
    2 nm`` (the 2 nm cover the 1 nm grid of the GDS polygons); the period at most λ_min/n_substrate
    (:class:`~fsdvs_hw.realise.metalens.meta_atoms.MetaAtomSpec`).
    """

    unknown_key = "unknown option of fit_metalens_layout"

    material: str | float = field("TiO2_siefke", "", "pillar material (meent table name) or a constant index")
    substrate: str | float = field("SiO2_malitson", "", "substrate material (meent table name) or a constant index")
    pillar_height_m: float = field(600e-9, "m", "pillar height", gt=1e-8, le=2e-5)
    period_m: float = field(300e-9, "m", "lattice period", gt=1e-8, le=2e-5)
    lattice: Literal["square", "hexagonal"] = field("square", "", "lattice of the pillar sites")
    min_radius_m: float = field(40e-9, "m", "smallest pillar radius of the library", gt=1e-9, le=1e-5)
    max_radius_m: float = field(125e-9, "m", "largest pillar radius of the library", gt=1e-9, le=1e-5)
    n_radii: int = field(44, "", "library radii (equal steps)", ge=2, le=2000)
    library_wavelengths_m: list[Annotated[float, Field(ge=1e-7, le=2e-5)]] | None = field(
        None, "m", "library wavelengths; None: 460, 510, 600, 650 nm (the design wavelength is added)", min_length=1
    )
    fourier_orders: int = field(7, "", "RCWA truncation order per axis ((2N+1)² harmonics)", ge=1, le=20)
    check_orders: int = field(5, "", "truncation order of the convergence check", ge=1, le=19)
    transmission_min: float = field(0.5, "", "least power transmission of a used radius", ge=0.0, le=1.0)
    phase_tolerance_rad: float = field(0.1, "", "largest phase change between truncation orders", gt=0.0, le=3.2)
    min_width_m: float = field(70e-9, "m", "design rule: smallest pillar diameter", ge=0.0, le=1e-5)
    min_space_m: float = field(40e-9, "m", "design rule: smallest gap between pillars", ge=0.0, le=1e-5)
    gds_layer: int = field(1, "", "GDSII layer of the pillars", ge=0, le=65535)
    gds_datatype: int = field(0, "", "GDSII datatype of the pillars", ge=0, le=65535)
    drc: bool = field(True, "", "run KLayout DRC on the written GDS")
    compute_library: bool = field(True, "", "compute the library by RCWA when no cached one matches")

    def option_problems(self) -> list[OptionProblem]:
        """The lens rules, the design rules and the library's own (period rule, orders)."""
        found = super().option_problems()
        grid = 2e-9
        if self.min_radius_m >= self.max_radius_m:
            found.append(
                OptionProblem("max_radius_m", self.max_radius_m, f"must exceed min_radius_m={self.min_radius_m:.4g} m")
            )
        if 2 * self.min_radius_m < self.min_width_m + grid:
            why = f"2·min_radius_m = {2 * self.min_radius_m:.4g} m is below min_width_m + 2 nm = {self.min_width_m + grid:.4g} m"
            found.append(OptionProblem("min_radius_m", self.min_radius_m, why))
        if self.period_m - 2 * self.max_radius_m < self.min_space_m + grid:
            why = (
                f"period_m − 2·max_radius_m = {self.period_m - 2 * self.max_radius_m:.4g} m is below min_space_m + 2 nm = "
                f"{self.min_space_m + grid:.4g} m"
            )
            found.append(OptionProblem("max_radius_m", self.max_radius_m, why))
        if self.check_orders >= self.fourier_orders:
            found.append(
                OptionProblem("check_orders", self.check_orders, f"must be below fourier_orders={self.fourier_orders}")
            )
        if not found:
            found += self._library_problems()
        return found

    def _library_problems(self) -> list[OptionProblem]:
        """Unknown materials (on their own keys), then the library's own rules (the period rule)."""
        from .meta_atoms import refractive_index

        for key in ("material", "substrate"):
            try:
                refractive_index(getattr(self, key), self.design_wavelength_m)
            except InputError as exc:
                return [OptionProblem(key, getattr(self, key), str(exc))]
        try:
            self.meta_atom_spec()
        except InputError as exc:
            return [OptionProblem("period_m", self.period_m, str(exc))]
        return []

    def meta_atom_spec(self) -> Any:
        """The :class:`~fsdvs_hw.realise.metalens.meta_atoms.MetaAtomSpec` these options ask for."""
        import numpy as np

        from .meta_atoms import MetaAtomSpec

        given = DEFAULT_LIBRARY_WAVELENGTHS_M if self.library_wavelengths_m is None else self.library_wavelengths_m
        lam = sorted({round(float(v), 12) for v in [*given, self.design_wavelength_m]})
        radii = np.round(np.linspace(self.min_radius_m, self.max_radius_m, self.n_radii), 12)
        return MetaAtomSpec(
            material=self.material,
            substrate=self.substrate,
            height_m=self.pillar_height_m,
            period_m=self.period_m,
            lattice=self.lattice,
            radii_m=tuple(float(r) for r in radii),
            wavelengths_m=tuple(lam),
            fourier_orders=self.fourier_orders,
            check_orders=self.check_orders,
        )
