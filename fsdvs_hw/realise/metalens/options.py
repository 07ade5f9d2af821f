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
from typing import Annotated, Literal

from pydantic import Field

from ...errors import InputError
from ...kernels import Kernel
from ...schema import PyObject, field
from ...validation import PITCH_RANGE_M
from ..fit_options import FitOptions, OptionProblem
from ..spectral import SpectralSamples, sampled_spectrum
from .lens import LensGeometry, local_numerical_aperture

__all__ = ["MetalensOptions"]


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
