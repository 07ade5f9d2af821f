r"""Metalens realisation: a radially symmetric metasurface whose PSF applies the kernel optically.

A zero-power way to build a FS-DVS kernel: the camera's (meta)lens spreads each scene point over
the k×k pixel neighbourhood, so that the sensor, integrating the point-spread function (PSF)
over each pixel and over the spectrum, applies the kernel before the log stage.

Forward model (:func:`pixel_psf`)
---------------------------------
* **Phase.** :math:`\phi_0(r) = -\frac{2\pi}{\lambda_0}(\sqrt{r^2+f^2}-f) + \sum_{k=1}^{K} c_k (r/a)^{2k}`
  (rad at the design wavelength :math:`\lambda_0`): a hyperbolic focusing term for focal length
  ``f`` plus even polynomial terms, over a circular aperture of radius ``a``.
* **Dispersion** (``dispersion=``): ``"diffractive"`` (default) —
  :math:`\phi(r,\lambda) = \phi_0(r)`: a 2π-wrapped metasurface imposes the same phase in radians
  at every wavelength to first order, so the focal length scales as :math:`f\lambda_0/\lambda`
  (the chromatic behaviour of measured metalenses; Khorasaninejad et al., Science 352, 1190,
  2016); ``"achromatic"`` — :math:`\phi = \phi_0\,\lambda_0/\lambda` (constant optical path: an
  ideal dispersion-engineered metalens, Chen et al., Nat. Nanotechnol. 13, 220, 2018). Unit-cell
  efficiency and polarisation are not modelled (scalar, unit transmission).
* **Propagation** to the sensor at distance ``z = f + δ`` (the defocus δ is a design variable):
  exact scalar angular spectrum via the radial Hankel path
  (:class:`~fsdvs_hw.realise.optics.RadialPropagator`), or the band-limited 2-D angular
  spectrum (:func:`~fsdvs_hw.realise.optics.angular_spectrum_2d`) as the independent check.
* **Sensor integration.** Intensity is integrated over each pixel (box of side ``pitch_m``,
  Gauss–Legendre nodes) and over wavelength with illuminant × response weights from
  colour-science (:mod:`fsdvs_hw.realise.spectral`). Taps are fractions of the power entering
  the aperture.

Signed kernels
--------------
An incoherent PSF is non-negative. ``strategy="pedestal"``: one lens realises :math:`g P \approx
K + c` inside the k×k window (``c ≥ 0`` a uniform pedestal, the gain ``g`` folds into the event
threshold); :meth:`MetalensDesign.kernel` returns :math:`gP` — what the sensor applies — and the
design reports ``c`` and the contrast it costs. ``strategy="differential"``: two lenses (two
photodiodes per pixel) give :math:`g_+P_+ - g_-P_-` subtracted in the pixel *before* the log
(``g_-/g_+`` is a current-mirror ratio); the gains hold the DC gain of the *whole* PSF (all the
light reaching the sensor plane, from Parseval over the propagating modes, not the k×k window) at
the target's, so the log stage sees the intended mean signal.

Every reported error — :attr:`MetalensDesign.error`, ``cost()["kernel_error"]`` and the scorer —
is that of the applied kernel, pedestal included (it is real light before the log); the error
with the pedestal subtracted is :attr:`MetalensDesign.signal_error`, and the pedestal's price is
reported separately as contrast loss (``contrast_factor``, ``cost()["contrast_loss"]``).

Fitting (:func:`fit_metalens`) uses torch autograd in float64 with L-BFGS over the polynomial
coefficients and the defocus, from a few defocus starts; gains and pedestal are solved in closed
form (linear least squares) at every step.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import InputError
from ...kernels import DEFAULT_PITCH_M, Kernel
from ...validation import check_fit_arguments
from ..base import CostItem, kernel_error
from ..optics import (
    RadialPropagator,
    angular_spectrum_2d,
    pixel_nodes_for_bandwidth,
    pixel_quadrature,
    radial_pixel_integrator,
    required_modes,
)
from ..spectral import SpectralSamples, sampled_spectrum
from .lens import DISPERSION_MODELS, LensGeometry, design_phase, local_numerical_aperture
from .options import MetalensOptions

__all__ = [
    "STRATEGIES",
    "MetalensDesign",
    "RadialKernelModel",
    "WavelengthPlan",
    "fit_gains",
    "fit_metalens",
    "pixel_psf",
    "plan_wavelength_samples",
]

#: signed-kernel strategies
STRATEGIES = ("pedestal", "differential")


class RadialKernelModel:
    """Cached forward model: (coefficients, sensor distance) -> pixel-integrated PSF (torch)."""

    def __init__(
        self,
        geometry: LensGeometry,
        *,
        pitch_m: float,
        n_pixels: int,
        spectral: SpectralSamples,
        n_sub: int | None = None,
        n_modes: int | None = None,
        window_pad: float = 2.0,
        na_budget: float | None = None,
        oversample: float = 1.5,
    ):
        import torch

        self.geometry = geometry
        self.spectral = spectral
        self.n_pixels = n_pixels
        a = geometry.radius_m
        half_diag = (n_pixels / 2) * pitch_m * math.sqrt(2)
        # the window must hold the aperture, the pixel window and the diffraction spread of a
        # small aperture (two Airy first-zero radii at the focal distance)
        spread = 1.22 * float(spectral.wavelengths_m.max()) * geometry.focal_length_m / a
        self.window_radius_m = window_pad * max(a, half_diag, spread)
        lam_min = float(spectral.wavelengths_m.min())
        na = na_budget if na_budget is not None else local_numerical_aperture(geometry, [], spectral.wavelengths_m)
        if na >= 1:
            raise InputError(
                f"the lens phase needs a local NA of {na:.3f} ≥ 1 at λ = {lam_min * 1e9:.0f} nm (aperture "
                f"{geometry.aperture_m:.3g} m, focal length {geometry.focal_length_m:.3g} m): evanescent, not buildable; "
                "reduce the aperture or lengthen the focal length"
            )
        R = self.window_radius_m
        needed = required_modes(R, na, lam_min, oversample=1.0)  # lens-plane Nyquist: Δx ≤ λ_min/(2 NA)
        if n_modes is None:
            # oversample the phase, and hold every wave that stays inside the window (band limit at z ≈ f)
            na_window = R / math.hypot(R, geometry.focal_length_m)
            n_modes = max(
                required_modes(R, na, lam_min, oversample=oversample), int(math.ceil(2 * R * na_window / lam_min)) + 16
            )
        elif n_modes < needed:
            raise InputError(
                f"n_modes={n_modes} undersamples the lens plane: Δx = {R / n_modes:.3g} m > "
                f"λ_min/(2·NA) = {lam_min / (2 * na):.3g} m; need n_modes ≥ {needed} (or leave it None)"
            )
        self.n_modes = int(n_modes)
        self.na = na
        self.prop = RadialPropagator(a, self.window_radius_m, self.n_modes)
        self._A = None
        if n_sub is None:
            # pixel quadrature from the intensity's bandwidth 2 NA / λ_min (no cap; at least 6 per
            # side), applied through a radial grid: the field is evaluated at a few hundred radii
            # and interpolated to every node (optics.radial_pixel_integrator)
            cutoff = 2 * na / lam_min
            self.n_sub = max(6, pixel_nodes_for_bandwidth(pitch_m, cutoff, tol=1e-3))
            r_grid, a_mat = radial_pixel_integrator(n_pixels, pitch_m, cutoff)
            self.B = self.prop.evaluation_matrix(r_grid)
            self._A = torch.from_numpy(a_mat)
            self.radial_samples = int(r_grid.size)
        else:  # an explicit per-pixel node count: evaluate the field at every distinct node radius
            self.n_sub = int(n_sub)
            rho, index, weights = pixel_quadrature(n_pixels, pitch_m, self.n_sub)
            self.B = self.prop.evaluation_matrix(rho)
            self.index = torch.from_numpy(index)
            self.weights = torch.from_numpy(weights)
            self.radial_samples = int(rho.size)
        self.p_in = math.pi * a * a
        p = DISPERSION_MODELS[geometry.dispersion]
        self.phase_scale = torch.from_numpy((geometry.design_wavelength_m / spectral.wavelengths_m) ** p)[:, None]
        self.w_lambda = torch.from_numpy(spectral.weights)
        r = self.prop.r_pupil
        self._hyp = torch.from_numpy(design_phase(r, geometry, ()))
        self._powers = torch.from_numpy(np.stack([(r / a) ** (2 * k + 2) for k in range(12)], axis=-1))

    def _pupil(self, coefficients: Any) -> Any:
        import torch

        if not hasattr(coefficients, "detach"):
            coefficients = torch.as_tensor(np.asarray(coefficients, dtype=float))
        return self._pupil_of_phase(self._hyp + self._powers[:, : coefficients.shape[0]] @ coefficients)

    def _pupil_of_phase(self, phi0: Any) -> Any:
        """Pupil field per wavelength from the phase φ0 (rad at λ0) on :attr:`RadialPropagator.r_pupil`."""
        import torch

        phi = phi0[None, :] * self.phase_scale
        return torch.polar(torch.ones_like(phi), phi)

    def psf_of_phase(self, phi0: Any, z_m: Any) -> Any:
        """Pixel taps (n, n) of a tabulated phase φ0 (rad at λ0, torch, on ``self.prop.r_pupil``) at distance ``z_m``.

        The same propagation, spectral weights and pixel integration as :meth:`psf`, for a phase
        profile given as numbers rather than coefficients (a reloaded artifact).
        """
        return self._psf_of_field(self._pupil_of_phase(phi0), z_m)

    def psf_of_field(self, field: Any, z_m: Any) -> Any:
        """Pixel taps (n, n) of a pupil field (L, M) given per wavelength on ``self.prop.r_pupil``
        (complex torch; unit amplitude = a lossless pupil), at distance ``z_m``."""
        return self._psf_of_field(field, z_m)

    def total_of_field(self, field: Any, z_m: Any) -> Any:
        """Whole-PSF sum of a pupil field (L, M): the fraction of the aperture's power reaching the plane."""
        power = self.prop.plane_power(field, self.spectral.wavelengths_m, z_m)
        return (self.w_lambda * power).sum() / self.p_in

    def total(self, coefficients: Any, z_m: Any) -> Any:
        """Whole-PSF sum: the fraction of the aperture's power reaching the sensor plane (all pixels)."""
        power = self.prop.plane_power(self._pupil(coefficients), self.spectral.wavelengths_m, z_m)
        return (self.w_lambda * power).sum() / self.p_in

    def psf(self, coefficients: Any, z_m: Any) -> Any:
        """Pixel taps (n, n): fraction of the aperture's power landing on each pixel."""
        return self._psf_of_field(self._pupil(coefficients), z_m)

    def _psf_of_field(self, field: Any, z_m: Any) -> Any:
        u = self.prop.propagate(field, self.spectral.wavelengths_m, z_m, self.B)  # (L, Q)
        intensity = (self.w_lambda[:, None] * (u.real**2 + u.imag**2)).sum(0)  # (Q,)
        if self._A is not None:
            return (self._A @ intensity).view(self.n_pixels, self.n_pixels) / self.p_in
        return (intensity[self.index] * self.weights).sum(-1) / self.p_in


def pixel_psf(
    geometry: LensGeometry,
    coefficients: Sequence[float] = (),
    *,
    sensor_distance_m: float | None = None,
    pitch_m: float = DEFAULT_PITCH_M,
    n_pixels: int = 7,
    illuminant: Any = "D65",
    response: Any = None,
    n_wavelengths: int = 8,
    method: str = "radial",
    n_sub: int | None = None,
    n_modes: int | None = None,
    window_pad: float = 2.0,
    samples_per_pixel: int | None = None,
) -> np.ndarray:
    """The PSF integrated over each pixel and the spectrum, as fractions of the incident power.

    Parameters
    ----------
    geometry : LensGeometry
        Aperture, focal length, design wavelength, dispersion model.
    coefficients : sequence of float
        Polynomial phase coefficients :math:`c_k` (rad at λ0) of (r/a)^2, (r/a)^4, ...
    sensor_distance_m : float, optional
        Lens-to-sensor distance (m); default the focal length (in focus at λ0).
    pitch_m : float
        Pixel pitch (m).
    n_pixels : int
        Odd side of the pixel window centred on the optical axis.
    illuminant, response, n_wavelengths
        Spectral weighting (see :func:`~fsdvs_hw.realise.spectral.spectral_samples`); a float
        illuminant is a single wavelength in metres.
    method : {"radial", "angular_2d"}
        Radial Hankel path (fast) or 2-D band-limited angular spectrum (reference).
    n_sub : int, optional
        Radial path: Gauss–Legendre nodes per pixel side for the box integral; default from the
        intensity's bandwidth 2·NA/λ_min (:func:`~fsdvs_hw.realise.optics.pixel_nodes_for_bandwidth`,
        at least 6, no cap; converged to ≤ 1e-3 of the peak tap against dense integration up to NA 0.95).
    n_modes : int, optional
        Radial path: frequency samples; default from the Nyquist condition (oversampled 1.5×).
        Too few raises :class:`InputError`.
    window_pad : float
        Computational window radius / max(aperture radius, pixel-window half-diagonal).
    samples_per_pixel : int, optional
        2-D path: odd number of grid samples per pixel side (grid step = pitch / this); default
        the smallest odd number meeting Δx ≤ λ_min / (2 NA).

    Returns
    -------
    numpy.ndarray, shape (n_pixels, n_pixels)
    """
    import torch

    spectral = sampled_spectrum(illuminant, response, n_wavelengths)
    z = geometry.focal_length_m if sensor_distance_m is None else float(sensor_distance_m)
    _check_extremes(geometry, spectral, z, pitch_m)
    coeffs = torch.tensor(np.asarray(coefficients, dtype=float), dtype=torch.float64)
    na = local_numerical_aperture(geometry, coefficients, spectral.wavelengths_m)
    if method == "radial":
        model = RadialKernelModel(
            geometry,
            pitch_m=pitch_m,
            n_pixels=n_pixels,
            spectral=spectral,
            n_sub=n_sub,
            n_modes=n_modes,
            window_pad=window_pad,
            na_budget=na,
        )
        with torch.no_grad():
            return model.psf(coeffs, z).numpy()
    if method == "angular_2d":
        return _pixel_psf_2d(geometry, coeffs, z, pitch_m, n_pixels, spectral, na, window_pad, samples_per_pixel)
    raise InputError(f"method {method!r} unknown; allowed: 'radial', 'angular_2d'")


def _pixel_psf_2d(
    geometry: LensGeometry,
    coeffs: Any,
    z: float,
    pitch_m: float,
    n_pixels: int,
    spectral: SpectralSamples,
    na: float,
    window_pad: float,
    samples_per_pixel: int | None,
) -> np.ndarray:
    import torch

    lam_min = float(spectral.wavelengths_m.min())
    if na >= 1:
        raise InputError(f"the lens phase needs a local NA of {na:.3f} ≥ 1: evanescent, not buildable")
    dx_max = lam_min / (2 * na)
    if samples_per_pixel is None:
        m = int(math.ceil(pitch_m / dx_max))
        m += (m + 1) % 2
    else:
        m = int(samples_per_pixel)
        if m < 1 or m % 2 == 0:
            raise InputError(f"samples_per_pixel must be an odd integer ≥ 1, got {samples_per_pixel!r}")
        if pitch_m / m > dx_max * (1 + 1e-9):
            raise InputError(
                f"samples_per_pixel={m} gives Δx = {pitch_m / m:.3g} m > λ_min/(2·NA) = {dx_max:.3g} m "
                f"(NA {na:.3f}); use ≥ {math.ceil(pitch_m / dx_max)}"
            )
    dx = pitch_m / m
    a = geometry.radius_m
    half_diag = (n_pixels / 2) * pitch_m * math.sqrt(2)
    spread = 1.22 * float(spectral.wavelengths_m.max()) * geometry.focal_length_m / a
    half = window_pad * max(a, half_diag, spread)
    n_half = int(math.ceil(half / dx))
    n = 2 * n_half + 1
    if n > 8193:
        raise InputError(f"2-D angular spectrum grid {n}×{n} is too large; use method='radial' or a coarser grid")
    x = (np.arange(n) - n_half) * dx
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X, Y)
    # area-weighted (anti-aliased) aperture: linear coverage ramp across the edge
    amp = np.clip((a - r) / dx + 0.5, 0.0, 1.0)
    inside = amp > 0
    phi0 = np.zeros_like(r)
    phi0[inside] = design_phase(r[inside], geometry, coeffs.numpy())
    p = DISPERSION_MODELS[geometry.dispersion]
    scale = (geometry.design_wavelength_m / spectral.wavelengths_m) ** p
    field = torch.from_numpy(amp[None] * np.exp(1j * phi0[None] * scale[:, None, None]))
    with torch.no_grad():
        out = angular_spectrum_2d(field, dx, spectral.wavelengths_m, z)
    intensity = np.einsum("l,lij->ij", spectral.weights, (out.abs() ** 2).numpy())
    p_in = float((amp**2).sum()) * dx * dx
    r_pix = n_pixels // 2
    c0 = n_half - r_pix * m - (m - 1) // 2
    block = intensity[c0 : c0 + n_pixels * m, c0 : c0 + n_pixels * m]
    taps = block.reshape(n_pixels, m, n_pixels, m).sum(axis=(1, 3)) * dx * dx
    return taps / p_in


@dataclass(frozen=True)
class WavelengthPlan:
    """How many wavelength samples a lens under a given illuminant needs, and why.

    Attributes
    ----------
    n_wavelengths : int
        Chosen number of equal-weight samples.
    tolerance : float
        Relative L2 change of the pixel PSF allowed between n and 2n samples.
    history : tuple of (int, float)
        (n, relative change from n to 2n) for each doubling tried.
    reason : str
        One line for the printed plan.
    """

    n_wavelengths: int
    tolerance: float
    history: tuple[tuple[int, float], ...]
    reason: str


def plan_wavelength_samples(
    geometry: LensGeometry,
    illuminant: Any = "D65",
    response: Any = None,
    *,
    sensor_distance_m: float | None = None,
    pitch_m: float = DEFAULT_PITCH_M,
    n_pixels: int = 7,
    tolerance: float = 1e-2,
    n_max: int = 64,
) -> WavelengthPlan:
    r"""Choose the number of wavelength samples from the scene's spectrum and the lens's dispersion.

    Doubles the number of equal-weight samples from 1 until the pixel PSF of the nominal lens
    (hyperbolic phase at ``sensor_distance_m``) changes by less than ``tolerance`` (relative
    L2) from n to 2n. A narrow-band source or an achromatic lens stops at 1–2 samples; a
    diffractive lens under a broadband illuminant needs many, because its focal length sweeps
    :math:`f\lambda_0/\lambda` across the band.
    """
    if not (0 < tolerance < 1):
        raise InputError(f"tolerance must be in (0, 1), got {tolerance!r}")
    z = geometry.focal_length_m if sensor_distance_m is None else sensor_distance_m
    if isinstance(illuminant, (int, float)) and not isinstance(illuminant, bool):
        return WavelengthPlan(1, tolerance, (), "monochromatic source: 1 wavelength")
    history: list[tuple[int, float]] = []
    n = 1
    prev = pixel_psf(
        geometry,
        sensor_distance_m=z,
        pitch_m=pitch_m,
        n_pixels=n_pixels,
        illuminant=illuminant,
        response=response,
        n_wavelengths=1,
        n_sub=8,
    )
    while 2 * n <= n_max:
        nxt = pixel_psf(
            geometry,
            sensor_distance_m=z,
            pitch_m=pitch_m,
            n_pixels=n_pixels,
            illuminant=illuminant,
            response=response,
            n_wavelengths=2 * n,
            n_sub=8,
        )
        change = float(np.linalg.norm(nxt - prev) / np.linalg.norm(nxt))
        history.append((n, change))
        if change < tolerance:
            return WavelengthPlan(
                n,
                tolerance,
                tuple(history),
                f"{geometry.dispersion} lens: PSF changes {change:.1e} from {n} to {2 * n} samples "
                f"(< {tolerance:g}): {n} wavelength(s)",
            )
        n, prev = 2 * n, nxt
    return WavelengthPlan(
        n,
        tolerance,
        tuple(history),
        f"{geometry.dispersion} lens: not converged to {tolerance:g} by {n} samples; using {n}",
    )


def _check_extremes(geometry: LensGeometry, spectral: SpectralSamples, z: float, pitch_m: float) -> None:
    lam_max = float(spectral.wavelengths_m.max())
    if geometry.aperture_m < 2 * lam_max:
        raise InputError(
            f"aperture_m={geometry.aperture_m:.3g} m is below 2 λ_max = {2 * lam_max:.3g} m: scalar diffraction "
            "(and a metasurface of a few unit cells) is not valid there"
        )
    if not (math.isfinite(z) and z > 2 * lam_max):
        raise InputError(f"sensor_distance_m must be finite and > 2 λ_max = {2 * lam_max:.3g} m, got {z!r}")
    if not (1e-7 <= pitch_m <= 1e-3):
        raise InputError(f"pitch_m={pitch_m!r} is outside [1e-7, 1e-3] m (micrometres passed as metres?)")


# ---------------------------------------------------------------------------------- design
def _log_contrast_gain(taps: np.ndarray) -> float:
    """max_{f≠0} |K̂(f)| / K̂(0): log-intensity modulation per unit scene modulation (pre-log kernel)."""
    spec = np.abs(np.fft.fft2(taps, s=(64, 64)))
    dc = float(np.real(np.fft.fft2(taps, s=(64, 64))[0, 0]))
    spec[0, 0] = 0.0
    return float(spec.max() / dc) if dc > 0 else float("inf")


@dataclass(frozen=True, eq=False)
class MetalensDesign:
    """A fitted metalens realisation (one lens, or a differential pair).

    Attributes
    ----------
    target : Kernel
        The kernel that was fitted.
    strategy : {"pedestal", "differential"}
        How the sign of the kernel is handled (module docstring).
    geometry : LensGeometry
        Aperture, focal length, design wavelength, dispersion model (shared by both lenses).
    coefficients : tuple of tuple of float
        Per lens, the polynomial phase coefficients c_k (rad at λ0) of (r/a)^2, (r/a)^4, ...
    sensor_distance_m : tuple of float
        Per lens, the lens-to-sensor distance (m); defocus = distance − focal length.
    gains : tuple of float
        Per lens, the gain g (pedestal) or g₊, g₋ (differential) applied to the PSF taps (taps
        are fractions of the aperture's power). ``g₋/g₊`` is the pixel's subtraction ratio.
    pedestal : float
        c, the uniform offset added inside the k×k window (target units; 0 for differential).
    guard_px : int
        Pixels of spill evaluated around the k×k window (the realised kernel is
        (k + 2·guard) square).
    psfs : tuple of numpy.ndarray
        Per lens, the pixel- and spectrum-integrated PSF on the realised window (fractions of
        incident power).
    psf_totals : tuple of float
        Per lens, the whole PSF's sum (the fraction of the aperture's power reaching the sensor
        plane, every pixel): what a uniform scene delivers. Empty for designs stored before it.
    spectral : SpectralSamples
        Wavelengths and weights used.
    fit_info : dict
        Wall time (s), iterations, numerical settings.

    Examples
    --------
    A coarse fit (:func:`fit_metalens`), stored and read back:

    >>> from fsdvs_hw import MetalensDesign, fit_metalens, reference_kernel
    >>> lens = fit_metalens(reference_kernel("dog", 3), n_terms=2, n_wavelengths=2, max_iter=5, n_starts=1,
    ...                     progress=False)
    >>> again = MetalensDesign.from_dict(lens.to_dict())
    >>> again.geometry.focal_length_m, again.kernel_error() == lens.kernel_error()
    (0.0002, True)
    """

    target: Kernel
    strategy: str
    geometry: LensGeometry
    coefficients: tuple[tuple[float, ...], ...]
    sensor_distance_m: tuple[float, ...]
    gains: tuple[float, ...]
    pedestal: float
    guard_px: int
    psfs: tuple[np.ndarray, ...]
    spectral: SpectralSamples
    fit_info: Mapping[str, Any] = field(default_factory=dict)
    psf_totals: tuple[float, ...] = ()
    kind: str = field(default="metalens", init=False)

    # -------------------------------------------------------------- kernels
    def kernel(self) -> Kernel:
        """What the sensor applies: g·P (pedestal: ≈ K + c in the window) or g₊P₊ − g₋P₋."""
        taps = self.gains[0] * self.psfs[0]
        if self.strategy == "differential":
            taps = taps - self.gains[1] * self.psfs[1]
        return self.target.with_taps(
            taps, name=f"metalens[{self.strategy}] {self.target.name}", realisation="metalens", strategy=self.strategy
        )

    def signal_kernel(self) -> Kernel:
        """The applied kernel minus the pedestal c inside the k×k window (comparable with the target)."""
        taps = np.array(self.kernel().taps)
        g, k = self.guard_px, self.target.size
        taps[g : g + k, g : g + k] -= self.pedestal
        return self.kernel().with_taps(taps, name=f"metalens[{self.strategy}] signal {self.target.name}")

    def kernel_error(self, target: Kernel | np.ndarray | None = None, *, fit_scale: bool = False) -> float:
        """Relative L2 error of the applied kernel, pedestal included, against ``target`` (the one definition).

        The pedestal is real light before the log, so it counts; its price in contrast is
        reported separately (:attr:`contrast_factor`, ``cost()["contrast_loss"]``). Spill outside
        the window counts too. ``fit_scale``: with the least-squares gain.
        """
        return kernel_error(self.kernel(), self.target if target is None else target, fit_scale=fit_scale)

    @property
    def error(self) -> float:
        """:meth:`kernel_error` against the design's target: what the fit and the scorer both report."""
        return self.kernel_error()

    @property
    def signal_error(self) -> float:
        """Relative L2 error of :meth:`signal_kernel` (pedestal subtracted) against the target: the shape error."""
        return kernel_error(self.signal_kernel(), self.target)

    @property
    def whole_dc_gain(self) -> float:
        """DC gain of the whole PSF (every pixel): g·T (pedestal) or g₊T₊ − g₋T₋ (differential)."""
        if not self.psf_totals:
            return float(self.kernel().taps.sum())
        signs = (1.0, -1.0)
        return float(sum(s * g * t for s, g, t in zip(signs, self.gains, self.psf_totals)))

    @property
    def optical_efficiency(self) -> tuple[float, ...]:
        """Per lens, the fraction of the aperture's power landing inside the k×k window."""
        g, k = self.guard_px, self.target.size
        return tuple(float(p[g : g + k, g : g + k].sum()) for p in self.psfs)

    @property
    def pedestal_fraction(self) -> float:
        """Share of the light collected in the window that is pedestal: k²c / Σ_window(K + c)."""
        if self.strategy != "pedestal" or self.pedestal == 0:
            return 0.0
        k = self.target.size
        g = self.guard_px
        window = self.kernel().taps[g : g + k, g : g + k]
        return float(k * k * self.pedestal / window.sum())

    @property
    def contrast_factor(self) -> float:
        """Log-contrast gain of the applied kernel relative to the ideal target (≤ 1 means contrast lost).

        Both are :math:`\\max_{f\\ne0}|\\hat K(f)| / \\hat K(0)` (the log-intensity modulation a
        grating of unit modulation produces at the kernel's best frequency). NaN when the target
        has no positive DC gain (it cannot be applied before a log without a pedestal at all).
        """
        t = _log_contrast_gain(self.target.taps)
        return float(_log_contrast_gain(self.kernel().taps) / t) if math.isfinite(t) else float("nan")

    # -------------------------------------------------------------- protocol
    def cost(self) -> dict[str, CostItem]:
        eff = self.optical_efficiency
        out = {
            "aperture_diameter": CostItem(self.geometry.aperture_m, "m", "metalens aperture diameter D"),
            "focal_length": CostItem(self.geometry.focal_length_m, "m", "focal length f of the hyperbolic term at λ0"),
            "lens_count": CostItem(len(self.psfs), "count", "lenses (1 pedestal, 2 differential pair)"),
            "numerical_aperture": CostItem(
                local_numerical_aperture(self.geometry, self.coefficients[0], self.spectral.wavelengths_m),
                "1",
                "largest local NA of the phase (unit cell ≤ λ_min/(2·NA))",
            ),
            "optical_efficiency": CostItem(
                min(eff), "1", "fraction of aperture power inside the kernel window (worst lens)"
            ),
            "pedestal": CostItem(self.pedestal, "1", "uniform offset c added in the window (target units)"),
            "pedestal_fraction": CostItem(self.pedestal_fraction, "1", "share of collected light that is pedestal"),
            "kernel_error": CostItem(
                self.error, "1", "relative L2 error of the applied kernel (pedestal included) vs the target"
            ),
            "signal_error": CostItem(
                self.signal_error, "1", "relative L2 error with the pedestal subtracted (shape only)"
            ),
            "whole_dc_gain": CostItem(self.whole_dc_gain, "1", "DC gain of the whole PSF (uniform scene, every pixel)"),
            "fit_time": CostItem(float(self.fit_info.get("wall_time_s", float("nan"))), "s", "fit wall time"),
        }
        for i, z in enumerate(self.sensor_distance_m):
            tag = "" if len(self.sensor_distance_m) == 1 else ("_plus", "_minus")[i]
            out[f"sensor_distance{tag}"] = CostItem(z, "m", "lens-to-sensor distance")
            out[f"defocus{tag}"] = CostItem(z - self.geometry.focal_length_m, "m", "sensor distance − focal length")
        cf = self.contrast_factor
        if math.isfinite(cf):
            out["contrast_factor"] = CostItem(cf, "1", "log-contrast gain relative to the ideal kernel")
            out["contrast_loss"] = CostItem(1.0 - cf, "1", "log contrast lost to the pedestal (1 - contrast_factor)")
        if self.strategy == "differential":
            out["subtraction_ratio"] = CostItem(self.gains[1] / self.gains[0], "1", "g₋/g₊ current-mirror ratio")
        return out

    def describe(self) -> str:
        g = self.geometry
        lines = [
            f"metalens ({self.strategy}) for {self.target.size}x{self.target.size} '{self.target.name}' at "
            f"{self.target.pitch_m * 1e6:.2f} µm pitch: relative error {self.error:.3f} (applied kernel, pedestal"
            f" included; {self.signal_error:.3f} with the pedestal subtracted); whole-PSF DC gain {self.whole_dc_gain:.4g}"
            f" (target {float(self.target.taps.sum()):.4g})",
            f"  aperture {g.aperture_m * 1e6:.0f} µm, f {g.focal_length_m * 1e6:.0f} µm (NA {g.numerical_aperture:.3f}), "
            f"{g.dispersion} dispersion, λ0 {g.design_wavelength_m * 1e9:.0f} nm; {self.spectral.n} wavelengths "
            f"({self.spectral.illuminant} × {self.spectral.response})",
        ]
        for i, (c, z) in enumerate(zip(self.coefficients, self.sensor_distance_m)):
            lines.append(
                f"  lens {i + 1}: defocus {(z - g.focal_length_m) * 1e6:+.2f} µm, phase coefficients [rad] "
                + ", ".join(f"{v:+.2f}" for v in c)
                + f"; efficiency {self.optical_efficiency[i]:.3f}"
            )
        if self.strategy == "pedestal":
            cf = self.contrast_factor
            lines.append(
                f"  pedestal c = {self.pedestal:.4g} ({100 * self.pedestal_fraction:.1f} % of collected light)"
                + (f"; contrast factor {cf:.3f}" if math.isfinite(cf) else "")
            )
        else:
            lines.append(f"  subtraction ratio g₋/g₊ = {self.gains[1] / self.gains[0]:.4g} (before the log)")
        lines.append(f"  fit {float(self.fit_info.get('wall_time_s', float('nan'))):.1f} s")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "strategy": self.strategy,
            "target": self.target.to_dict(),
            "geometry": self.geometry.to_dict(),
            "coefficients": [list(map(float, c)) for c in self.coefficients],
            "sensor_distance_m": [float(z) for z in self.sensor_distance_m],
            "gains": [float(x) for x in self.gains],
            "pedestal": float(self.pedestal),
            "guard_px": int(self.guard_px),
            "psfs": [p.tolist() for p in self.psfs],
            "spectral": self.spectral.to_dict(),
            "fit_info": dict(self.fit_info),
            "psf_totals": [float(t) for t in self.psf_totals],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MetalensDesign:
        try:
            return cls(
                target=Kernel.from_dict(data["target"], source="metalens.target"),
                strategy=str(data["strategy"]),
                geometry=LensGeometry(**data["geometry"]),
                coefficients=tuple(tuple(float(v) for v in c) for c in data["coefficients"]),
                sensor_distance_m=tuple(float(z) for z in data["sensor_distance_m"]),
                gains=tuple(float(x) for x in data["gains"]),
                pedestal=float(data["pedestal"]),
                guard_px=int(data["guard_px"]),
                psfs=tuple(np.asarray(p, dtype=float) for p in data["psfs"]),
                spectral=SpectralSamples.from_dict(data["spectral"]),
                fit_info=dict(data.get("fit_info", {})),
                psf_totals=tuple(float(t) for t in data.get("psf_totals", ())),
            )
        except KeyError as exc:
            raise InputError(f"metalens design: missing field {exc.args[0]!r}") from None


# ---------------------------------------------------------------------------------- fitting
def fit_gains(
    psfs: Sequence[np.ndarray],
    target: Kernel,
    *,
    guard_px: int,
    strategy: str,
    totals: Sequence[float] | None = None,
) -> tuple[tuple[float, ...], float]:
    """The closed-form gains and pedestal of :func:`fit_metalens` for given PSFs (target units).

    ``psfs``: per lens, the (k + 2·guard)² taps; ``totals``: their whole-PSF sums (the
    differential pair holds its whole-PSF DC gain at the target's). Returns ``(gains, pedestal)``.
    """
    import torch

    scale = float(np.linalg.norm(target.taps))
    k_pad = torch.from_numpy(np.pad(target.taps / scale, guard_px))
    mask = torch.from_numpy(np.pad(np.ones_like(target.taps), guard_px))
    with torch.no_grad():
        gains, c, _ = _solve_gains(
            [torch.from_numpy(np.asarray(p, dtype=float)) for p in psfs],
            k_pad,
            mask,
            strategy,
            [torch.tensor(float(t), dtype=torch.float64) for t in totals] if totals is not None else None,
        )
    return tuple(float(g) * scale for g in gains), float(c) * scale


def _solve_gains(
    psfs: list[Any], k: Any, m: Any, mode: str, totals: Sequence[Any] | None = None
) -> tuple[list[Any], Any, Any]:
    """Closed-form least squares for the gains (and pedestal); returns (gains, pedestal, residual²).

    ``totals``: the whole-PSF sums (all the light on the sensor plane); the differential pair holds
    its whole-PSF DC gain g₊T₊ − g₋T₋ at the target's (the window sums when not given).
    """
    import torch

    def two(a: Any, b: Any) -> tuple[Any, Any]:
        aa, ab, bb, ak, bk = (a * a).sum(), (a * b).sum(), (b * b).sum(), (a * k).sum(), (b * k).sum()
        det = aa * bb - ab * ab
        return (ak * bb - bk * ab) / det, (bk * aa - ak * ab) / det

    zero = torch.zeros((), dtype=torch.float64)
    p0 = psfs[0]
    g_single = (p0 * k).sum() / (p0 * p0).sum()
    if mode == "single":
        gains, c = [g_single], zero
    elif mode == "pedestal":
        g, c = two(p0, -m)
        if c < 0:  # no negative pedestal: the target is non-negative already
            g, c = g_single, zero
        gains = [g]
    else:  # differential: g+ P+ - g- P-, with the DC gain held at the target's (Σ applied = Σ K)
        p1 = psfs[1]
        s_p, s_m = (p0.sum(), p1.sum()) if totals is None else (totals[0], totals[1])
        s_k = k.sum()
        a = p0 - (s_p / s_m) * p1
        b = (s_k / s_m) * p1
        gp = (a * (k - b)).sum() / (a * a).sum()
        gm = (gp * s_p - s_k) / s_m
        if gm < 0 or gp < 0:
            gp, gm = s_k / s_p, zero
        gains, c = [gp, gm], zero
    model = gains[0] * p0 - (gains[1] * psfs[1] if mode == "differential" else 0) - c * m
    return gains, c, ((model - k) ** 2).sum()


def _lbfgs(x: Any, loss_fn: Any, iters: int, bar: Any = None) -> int:
    """At most ``iters`` L-BFGS iterations on ``x``; returns those run. ``bar`` (tqdm) advances by
    ``iters`` in all: iteration by iteration, the rest at once when it converges early."""
    import torch

    opt = torch.optim.LBFGS(
        [x],
        lr=1.0,
        max_iter=iters,
        history_size=20,
        line_search_fn="strong_wolfe",
        tolerance_grad=1e-10,
        tolerance_change=1e-12,
    )
    shown = 0

    def closure() -> Any:
        nonlocal shown
        if bar is not None:  # torch counts the iteration before its line search evaluates the loss
            n = int(opt.state[opt._params[0]].get("n_iter", 0))
            if n > shown:
                bar.update(n - shown)
                shown = n
        opt.zero_grad()
        loss = loss_fn(x)
        loss.backward()
        return loss

    opt.step(closure)
    if bar is not None:
        bar.update(iters - shown)
    return int(opt.state[opt._params[0]].get("n_iter", iters))


# ---------------------------------------------------------------------------- the fit, in steps
@dataclass(frozen=True, eq=False)
class _MetalensSetup:
    """The fit's options resolved (step 1 of :func:`fit_metalens`): target, lens, spectrum, NA budget."""

    kernel: Kernel
    geometry: LensGeometry
    spectral: SpectralSamples
    plan: WavelengthPlan | None
    budget: float


def _metalens_setup(o: MetalensOptions) -> _MetalensSetup:
    """The lens geometry, the wavelength samples (for ``"auto"`` planned from the target, then put to
    the options' lens rules, :meth:`MetalensOptions.lens_problems`) and the NA budget of the phase."""
    kernel, geometry, plan = o.target, o.lens_geometry, None
    n_wavelengths = o.n_wavelengths
    if n_wavelengths == "auto":
        # nominal lens defocused to blur a point over the kernel radius (geometric optics)
        z_nominal = geometry.focal_length_m * (1 + (kernel.size / 2) * kernel.pitch_m / geometry.radius_m)
        plan = plan_wavelength_samples(
            geometry,
            o.illuminant,
            o.response,
            sensor_distance_m=z_nominal,
            pitch_m=kernel.pitch_m,
            n_pixels=kernel.size,
        )
        n_wavelengths = plan.n_wavelengths
    spectral = o.spectral_samples(n_wavelengths)
    if plan is not None:
        o.refuse(o.lens_problems(spectral))
    na0 = local_numerical_aperture(geometry, [], spectral.wavelengths_m)
    return _MetalensSetup(kernel=kernel, geometry=geometry, spectral=spectral, plan=plan, budget=o.na_budget(na0))


def _metalens_models(
    setup: _MetalensSetup, *, illuminant: Any, response: Any, guard_px: int, n_sub: int | None, window_pad: float
) -> tuple[RadialKernelModel, RadialKernelModel]:
    """Step 2, the forward models: coarse-to-fine in wavelength (starts and the first refinement on
    ≤ 8 samples, the polish on all); returns ``(coarse, full)`` (the same object when ≤ 8 samples)."""
    spectral, pitch = setup.spectral, setup.kernel.pitch_m
    n_eval = setup.kernel.size + 2 * guard_px
    coarse_spectral = (
        spectral
        if spectral.n <= 8 or isinstance(illuminant, SpectralSamples)
        else sampled_spectrum(illuminant, response, 8)
    )
    coarse = RadialKernelModel(
        setup.geometry,
        pitch_m=pitch,
        n_pixels=n_eval,
        spectral=coarse_spectral,
        n_sub=n_sub,
        window_pad=window_pad,
        na_budget=setup.budget,
    )
    model = (
        coarse
        if coarse_spectral is spectral
        else RadialKernelModel(
            setup.geometry,
            pitch_m=pitch,
            n_pixels=n_eval,
            spectral=spectral,
            n_sub=n_sub,
            window_pad=window_pad,
            na_budget=setup.budget,
        )
    )
    return coarse, model


class _MetalensObjective:
    """Step 3, the objective: window error of the PSFs (closed-form gains) plus the NA and defocus
    penalties, in scaled parameters ``x = (defocus / dz_unit, c / 2π)`` per lens."""

    def __init__(self, setup: _MetalensSetup, *, n_terms: int, guard_px: int) -> None:
        import torch

        kernel, geometry = setup.kernel, setup.geometry
        k_size = kernel.size
        self.budget = setup.budget
        self.scale = float(np.linalg.norm(kernel.taps))
        self.k_pad = torch.from_numpy(np.pad(kernel.taps / self.scale, guard_px))
        self.mask = torch.from_numpy(np.pad(np.ones((k_size, k_size)), guard_px))
        # NA penalty on a radial grid (local frequency of the phase at the shortest scaled wavelength)
        a, f, lam0 = geometry.radius_m, geometry.focal_length_m, geometry.design_wavelength_m
        r_chk = np.linspace(0, a, 129)
        self.d_hyp = torch.from_numpy(-(2 * math.pi / lam0) * r_chk / np.sqrt(r_chk**2 + f * f))
        self.d_pow = torch.from_numpy(
            np.stack([2 * (k + 1) * r_chk ** (2 * k + 1) / a ** (2 * k + 2) for k in range(n_terms)], -1)
            if n_terms
            else np.zeros((r_chk.size, 0))
        )
        p_exp = DISPERSION_MODELS[geometry.dispersion]
        wl = setup.spectral.wavelengths_m
        self.na_scale = float(np.max(wl * (lam0 / wl) ** p_exp)) / (2 * math.pi)
        self.f = f
        self.dz_unit = kernel.pitch_m * f / a  # defocus that blurs a point over one pixel radius (geometric optics)
        self.c_unit = 2 * math.pi
        self._clamp = torch.clamp
        self.dz_bound = float(k_size)  # |defocus| ≤ blur over the kernel diameter (in dz_unit); beyond, light is wasted

    def unpack(self, x: Any) -> tuple[Any, Any]:
        return self.f + x[0] * self.dz_unit, x[1:] * self.c_unit

    def penalty(self, x: Any) -> Any:
        c = x[1:] * self.c_unit
        na = (self.na_scale * (self.d_hyp + self.d_pow @ c).abs()).max()
        return (
            10.0 * self._clamp(na - self.budget, min=0.0) ** 2
            + 10.0 * self._clamp(x[0].abs() - self.dz_bound, min=0.0) ** 2
        )

    def loss(self, targets: Any, mode: str, n_lens: int, fwd: RadialKernelModel) -> Any:
        def loss(x: Any) -> Any:
            psfs, tots, pen = [], [], 0.0
            for i in range(n_lens):
                z, c = self.unpack(x[i])
                psfs.append(fwd.psf(c, z))
                if mode == "differential":  # DC held on the whole PSF, not the window
                    tots.append(fwd.total(c, z))
                pen = pen + self.penalty(x[i])
            return _solve_gains(psfs, targets, self.mask, mode, tots or None)[2] + pen

        return loss


def _solve_metalens(
    obj: _MetalensObjective,
    coarse: RadialKernelModel,
    model: RadialKernelModel,
    *,
    strategy: str,
    kernel_size: int,
    n_terms: int,
    n_starts: int,
    max_iter: int,
    progress: bool | None = None,
) -> tuple[np.ndarray, int]:
    """Step 4, the solve: L-BFGS from defocus starts on the coarse model, refined, polished on the
    full spectrum; a differential pair from its two single-lens halves. Returns ``(x, iterations)``.
    The progress bar counts the iteration budget (:mod:`fsdvs_hw.progress`)."""
    import torch

    from ...progress import progress_bar

    per_start, polish = max(10, max_iter // 6), (max(10, max_iter // 4) if model is not coarse else 0)

    def budget(n_start_points: int) -> int:
        return n_start_points * per_start + max_iter + polish

    def fit_from(starts: list[np.ndarray], targets: Any, mode: str, bar: Any) -> tuple[np.ndarray, int]:
        n_lens = starts[0].shape[0]
        loss_fn = obj.loss(targets, mode, n_lens, coarse)
        best, best_val, iters = None, float("inf"), 0
        for s in starts:
            x = torch.tensor(s, dtype=torch.float64, requires_grad=True)
            iters += _lbfgs(x, loss_fn, per_start, bar)
            with torch.no_grad():
                val = float(loss_fn(x))
            if math.isfinite(val) and val < best_val:
                best, best_val = x.detach().clone(), val
        if best is None:
            raise InputError(f"fit_metalens: the {mode} loss is not finite at any of the {len(starts)} starts")
        x = best.clone().requires_grad_(True)
        iters += _lbfgs(x, loss_fn, max_iter, bar)
        if model is not coarse:
            iters += _lbfgs(x, obj.loss(targets, mode, n_lens, model), polish, bar)
        return x.detach().numpy(), iters

    radius_px = max(1.0, kernel_size / 2)
    blur = np.linspace(0.5, radius_px, max(1, (n_starts + 1) // 2))
    single_starts = [np.concatenate([[s * b], np.zeros(n_terms)])[None] for b in blur for s in (1, -1)][:n_starts]
    half = single_starts[: max(1, n_starts // 2)]
    total = budget(len(single_starts)) if strategy == "pedestal" else 2 * budget(len(half)) + budget(1)
    with progress_bar(total=total, desc="fit_metalens", unit="iter", progress=progress, leave=False) as bar:
        if strategy == "pedestal":
            return fit_from(single_starts, obj.k_pad, "pedestal", bar)
        kp = torch.clamp(obj.k_pad, min=0.0)
        km = torch.clamp(-obj.k_pad, min=0.0)
        xp, it1 = fit_from(half, kp / kp.norm(), "single", bar)
        xm, it2 = fit_from(half, km / km.norm(), "single", bar)
        x, it3 = fit_from([np.concatenate([xp, xm])], obj.k_pad, "differential", bar)
        return x, it1 + it2 + it3


def fit_metalens(
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
) -> MetalensDesign:
    """Fit a radially symmetric metalens (or a differential pair) whose pixel PSF applies ``kernel``.

    The options are validated once, at entry, into a :class:`~fsdvs_hw.realise.metalens.MetalensOptions`
    (the same model and rules a design file's ``[realisations.metalens]`` table is checked against)
    that the fit reads.

    Parameters
    ----------
    kernel : Kernel or array_like
        Target kernel (signed allowed): a :class:`~fsdvs_hw.kernels.Kernel`, or odd square taps
        (with ``pitch_m``; see :func:`~fsdvs_hw.kernels.as_kernel`). Only its radially symmetric
        part can be realised; the error reports the rest.
    pitch_m, illuminant, response, strategy, aperture_m, focal_length_m, design_wavelength_m, dispersion, \
n_terms, n_wavelengths, guard_px, max_iter, n_starts, n_sub, window_pad, na_max, progress
        The fit's options: each one's type, unit, range, default and meaning, and the rules between
        them, are those of :class:`~fsdvs_hw.realise.metalens.MetalensOptions`.

    Returns
    -------
    MetalensDesign

    Examples
    --------
    A quick, coarse fit (few terms, wavelengths and iterations; the defaults fit far better):

    >>> from fsdvs_hw import fit_metalens, reference_kernel
    >>> lens = fit_metalens(reference_kernel("dog", 3), n_terms=2, n_wavelengths=2, max_iter=5, n_starts=1,
    ...                     progress=False)
    >>> lens.strategy, lens.kernel().size  # 3 taps and guard_px = 2 pixels each side
    ('pedestal', 7)
    >>> bool(0 < lens.kernel_error() < 1), bool(lens.pedestal > 0)
    (True, True)
    """
    o = check_fit_arguments(MetalensOptions, locals())
    t0, c0 = time.perf_counter(), time.process_time()
    setup = _metalens_setup(o)
    coarse, model = _metalens_models(
        setup, illuminant=o.illuminant, response=o.response, guard_px=o.guard_px, n_sub=o.n_sub, window_pad=o.window_pad
    )
    obj = _MetalensObjective(setup, n_terms=o.n_terms, guard_px=o.guard_px)
    x, iters = _solve_metalens(
        obj,
        coarse,
        model,
        strategy=o.strategy,
        kernel_size=setup.kernel.size,
        n_terms=o.n_terms,
        n_starts=o.n_starts,
        max_iter=o.max_iter,
        progress=o.progress,
    )
    return _metalens_design(o, setup, obj, model, x, iterations=iters, started=(t0, c0))


def _metalens_design(
    o: MetalensOptions,
    setup: _MetalensSetup,
    obj: _MetalensObjective,
    model: RadialKernelModel,
    x: np.ndarray,
    *,
    iterations: int,
    started: tuple[float, float],
) -> MetalensDesign:
    """Step 5, the design: the solution's PSFs on the reference model (window_pad ≥ 3), closed-form
    gains, the NA reached and the fit record (``started``: wall and CPU clocks at the fit's start)."""
    import torch

    kernel, geometry, spectral, budget = setup.kernel, setup.geometry, setup.spectral, setup.budget
    xt = torch.from_numpy(x)
    reference = RadialKernelModel(
        geometry,
        pitch_m=kernel.pitch_m,
        n_pixels=kernel.size + 2 * o.guard_px,
        spectral=spectral,
        n_sub=None,
        window_pad=max(o.window_pad, 3.0),
        na_budget=budget,
    )
    with torch.no_grad():
        psfs, totals, zs, cs, model_err = [], [], [], [], 0.0
        for i in range(x.shape[0]):
            z, c = obj.unpack(xt[i])
            fast = model.psf(c, z)
            psfs.append(reference.psf(c, z))
            totals.append(reference.total(c, z))
            model_err = max(model_err, float((fast - psfs[-1]).norm() / psfs[-1].norm()))
            zs.append(float(z))
            cs.append(tuple(float(v) for v in c))
        gains, c, _ = _solve_gains(
            psfs, obj.k_pad, obj.mask, o.strategy, totals if o.strategy == "differential" else None
        )
    na_fit = max(local_numerical_aperture(geometry, cc, spectral.wavelengths_m) for cc in cs)
    info = {
        "wall_time_s": time.perf_counter() - started[0],
        "cpu_time_s": time.process_time() - started[1],  # all threads; under contention wall ≫ cpu / threads
        "iterations": iterations,
        "n_modes": model.n_modes,
        "n_sub": model.n_sub,
        "radial_samples": model.radial_samples,
        "model_error": model_err,
        "window_radius_m": model.window_radius_m,
        "na_budget": budget,
        "na_fit": na_fit,
        "n_terms": o.n_terms,
        "optimiser": "torch L-BFGS (strong Wolfe), float64, closed-form gains",
        "n_wavelengths": spectral.n,
    }
    if setup.plan is not None:
        info["wavelength_plan"] = setup.plan.reason
    if na_fit > budget * 1.02:
        raise InputError(f"fit left the sampling budget (local NA {na_fit:.3f} > na_max {budget:.3f}); raise na_max")
    return MetalensDesign(
        target=kernel,
        strategy=o.strategy,
        geometry=geometry,
        coefficients=tuple(cs),
        sensor_distance_m=tuple(zs),
        gains=tuple(float(g) * obj.scale for g in gains),
        pedestal=float(c) * obj.scale,
        guard_px=o.guard_px,
        psfs=tuple(p.numpy() for p in psfs),
        spectral=spectral,
        fit_info=info,
        psf_totals=tuple(float(t) for t in totals),
    )
