r"""Scalar diffraction for rotationally symmetric and general pupils (torch, float64/complex128).

Two propagators of a monochromatic scalar field from a pupil plane to a plane at distance ``z``,
both exact angular-spectrum (Rayleigh–Sommerfeld-equivalent) propagation, valid at any NA
below 1 (no Fresnel approximation):

Radial path (:class:`RadialPropagator`)
    For a pupil field :math:`u_0(r)` that depends on radius only, the angular spectrum is the
    zero-order Hankel transform :math:`U(\nu) = 2\pi\int_0^a u_0(r) J_0(2\pi\nu r)\, r\,dr`.
    It is sampled on the quasi-discrete Hankel transform (QDHT) frequency grid
    :math:`\nu_m = j_m / (2\pi R)` (:math:`j_m` the zeros of :math:`J_0`, :math:`R` the radius of
    the computational window; Guizar-Sicairos & Gutiérrez-Vega 2004), computed with composite
    Gauss–Legendre quadrature over the pupil (so the hard aperture edge is integrated exactly),
    multiplied by the transfer function, and summed back as a Fourier–Bessel series at any radii
    :math:`\rho < R`:
    :math:`u_z(\rho) = \sum_m U(\nu_m) H(\nu_m) J_0(2\pi\nu_m\rho) / (\pi R^2 J_1(j_m)^2)`.
    All matrices are wavelength-independent and cached, so a spectral batch costs two small
    matrix products per evaluation.
2-D path (:func:`angular_spectrum_2d`)
    Band-limited angular spectrum on a Cartesian grid with 2× zero padding (Matsushima &
    Shimobaba 2009); for pupils without symmetry and as the independent check of the radial path.

Transfer function :math:`H(\nu) = \exp(i 2\pi z (\sqrt{\lambda^{-2} - \nu^2} - \lambda^{-1}))`
(the constant phase :math:`e^{ikz}` is dropped), set to 0 beyond the band limit
:math:`\nu_{lim} = \lambda^{-1} / \sqrt{1 + (z / L)^2}` at which its phase is no longer sampled by
the frequency step :math:`1/(2L)` (:math:`L = R` radially, the padded half-width in 2-D), and
for evanescent waves.

Sampling (:func:`required_modes`): a pupil whose phase has local spatial frequency up to
:math:`NA/\lambda` needs a sample spacing :math:`\Delta x \le \lambda_{min} / (2\,NA)`, i.e. a
frequency grid reaching :math:`\nu_{max} = 1 / (2\Delta x)`.

References
----------
M. Guizar-Sicairos and J. C. Gutiérrez-Vega, "Computation of quasi-discrete Hankel transforms of
integer order for propagating optical wave fields," JOSA A 21, 53–58 (2004).
K. Matsushima and T. Shimobaba, "Band-limited angular spectrum method for numerical simulation of
free-space propagation in far and near fields," Opt. Express 17, 19662–19673 (2009).
J. W. Goodman, *Introduction to Fourier Optics*, 3rd ed. (2005), ch. 3–4 (angular spectrum,
Airy pattern).
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = [
    "RadialPropagator",
    "airy_intensity",
    "angular_spectrum_2d",
    "band_limit",
    "pixel_nodes_for_bandwidth",
    "pixel_quadrature",
    "radial_pixel_integrator",
    "required_modes",
    "transfer_function",
]

#: Most radial modes accepted (the evaluation matrices grow as modes × radii).
MAX_MODES = 16384


def _torch() -> Any:
    import torch

    return torch


def band_limit(wavelength_m: Any, z_m: float, half_width_m: float) -> Any:
    r"""Band limit :math:`\nu_{lim} = \lambda^{-1}/\sqrt{1 + (z/L)^2}` in cycles/m (Matsushima–Shimobaba).

    Beyond it the transfer function's phase changes by more than π between frequency samples
    spaced :math:`1/(2L)`: those waves would leave the window of half-width ``L``.
    """
    return (1.0 / wavelength_m) / np.sqrt(1.0 + (np.asarray(z_m, dtype=float) / half_width_m) ** 2)


def transfer_function(nu2: Any, wavelength_m: Any, z_m: Any, nu_limit: Any) -> Any:
    r"""Angular-spectrum transfer function for squared spatial frequency ``nu2`` (cycles²/m²).

    :math:`H = \exp(i 2\pi z(\sqrt{\lambda^{-2}-\nu^2} - \lambda^{-1}))` for
    :math:`\nu < \nu_{lim}`, else 0. Torch tensors broadcast; ``z_m`` may carry gradients.
    """
    torch = _torch()
    inv = 1.0 / wavelength_m
    arg = torch.clamp(inv * inv - nu2, min=0.0)
    kz = torch.sqrt(arg) - inv  # ≤ 0; the dropped constant is exp(i k z)
    mask = (nu2 < nu_limit * nu_limit).to(kz.dtype)
    phase = 2 * math.pi * z_m * kz
    return torch.polar(mask, phase)


def required_modes(
    window_radius_m: float, na: float, wavelength_min_m: float, *, oversample: float = 1.5, minimum: int = 64
) -> int:
    r"""Number of radial modes N so that the frequency grid reaches ``oversample`` × NA/λ_min.

    The QDHT grid reaches :math:`\nu_{max} = j_{N+1}/(2\pi R) \approx (N + 3/4)/(2R)`; the
    lens-plane Nyquist condition :math:`\Delta x = 1/(2\nu_{max}) \le \lambda_{min}/(2\,NA)`
    gives :math:`N \ge 2 R\, NA / \lambda_{min}`.
    """
    if not (0 < na < 1):
        raise InputError(f"numerical aperture must be in (0, 1) for propagating waves, got NA={na:.4g}")
    n = int(math.ceil(oversample * 2 * window_radius_m * na / wavelength_min_m)) + 16
    return max(minimum, n)


@lru_cache(maxsize=16)
def _bessel_zeros(n: int) -> np.ndarray:
    from scipy.special import jn_zeros

    return jn_zeros(0, n + 1)


def _gauss_legendre_panels(a: float, n_panels: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, a, n_panels + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[1:] + edges[:-1])
    nodes = (mid[:, None] + half[:, None] * x[None, :]).ravel()
    weights = (half[:, None] * w[None, :]).ravel()
    return nodes, weights


class RadialPropagator:
    r"""Cached radial (Hankel) angular-spectrum propagator for a circular pupil.

    Parameters
    ----------
    aperture_radius_m : float
        Pupil radius a (m); the pupil field is integrated over [0, a].
    window_radius_m : float
        Radius R (m) of the computational window (≥ a and ≥ the largest output radius, with
        room for the light that spreads): the field is represented as a Fourier–Bessel series
        on [0, R].
    n_modes : int
        Number N of QDHT frequency samples :math:`\nu_m = j_m/(2\pi R)`; see :func:`required_modes`.
    pupil_order : int
        Gauss–Legendre nodes per pupil panel (panels are at most half a period of the highest
        frequency wide).

    Attributes
    ----------
    nu : numpy.ndarray
        Frequencies :math:`\nu_m` (cycles/m).
    r_pupil : numpy.ndarray
        Pupil quadrature radii (m); pupil fields are given at these radii.
    nu_max : float
        Highest represented frequency (cycles/m).
    """

    def __init__(self, aperture_radius_m: float, window_radius_m: float, n_modes: int, *, pupil_order: int = 8):
        if not (0 < aperture_radius_m <= window_radius_m):
            raise InputError(
                f"RadialPropagator: need 0 < aperture radius ({aperture_radius_m:.4g} m) ≤ window radius "
                f"({window_radius_m:.4g} m)"
            )
        if not (8 <= n_modes <= MAX_MODES):
            raise InputError(f"RadialPropagator: n_modes must be in 8..{MAX_MODES}, got {n_modes}")
        torch = _torch()
        from scipy.special import j0, j1

        zeros = _bessel_zeros(int(n_modes))
        jm, s = zeros[:-1], zeros[-1]
        self.aperture_radius_m = float(aperture_radius_m)
        self.window_radius_m = R = float(window_radius_m)
        self.n_modes = int(n_modes)
        self.nu = jm / (2 * math.pi * R)
        self.nu_max = s / (2 * math.pi * R)
        self._series_w = 1.0 / (math.pi * R * R * j1(jm) ** 2)  # Fourier–Bessel coefficients
        # pupil quadrature: panels no wider than half a period of the highest frequency
        n_panels = max(4, int(math.ceil(aperture_radius_m * 2 * self.nu_max * 2)))
        r, w = _gauss_legendre_panels(aperture_radius_m, n_panels, pupil_order)
        self.r_pupil = r
        fwd = 2 * math.pi * (w * r)[None, :] * j0(2 * math.pi * self.nu[:, None] * r[None, :])
        # real matrices (J0 and quadrature weights): complex fields are multiplied part by part,
        # which avoids materialising conjugated complex copies in the backward pass
        self._forward_t = torch.from_numpy(np.ascontiguousarray(fwd.T))  # (M, N), float64
        self._nu2 = torch.from_numpy(self.nu**2)

    def evaluation_matrix(self, rho_m: np.ndarray) -> Any:
        """Matrix B (Q, N) with :math:`u_z(\\rho_q) = B\\,(U H)`; rows for radii ``rho_m`` < R."""
        from scipy.special import j0

        rho = np.asarray(rho_m, dtype=float).ravel()
        if rho.size and rho.max() > self.window_radius_m:
            raise InputError(
                f"output radius {rho.max():.4g} m exceeds the propagation window radius {self.window_radius_m:.4g} m"
            )
        torch = _torch()
        b = j0(2 * math.pi * rho[:, None] * self.nu[None, :]) * self._series_w[None, :]
        return torch.from_numpy(b)  # (Q, N), float64

    def propagate(self, pupil_field: Any, wavelengths_m: np.ndarray, z_m: Any, evaluation: Any) -> Any:
        """Propagate pupil fields to distance ``z_m`` and evaluate them at the radii of ``evaluation``.

        Parameters
        ----------
        pupil_field : torch.Tensor, complex, shape (L, M)
            Field at :attr:`r_pupil` for each of L wavelengths (unit amplitude = unit intensity).
        wavelengths_m : array, shape (L,)
            Wavelengths (m).
        z_m : float or torch.Tensor (scalar)
            Propagation distance (m); may carry a gradient.
        evaluation : torch.Tensor, float64, shape (Q, N)
            From :meth:`evaluation_matrix`.

        Returns
        -------
        torch.Tensor, complex, shape (L, Q)
            Field at the requested radii.
        """
        torch = _torch()
        lam = torch.as_tensor(np.asarray(wavelengths_m, dtype=float))[:, None]
        spectrum = _real_matmul(pupil_field, self._forward_t)  # (L, N)
        nu_lim = torch.as_tensor(band_limit(np.asarray(wavelengths_m, float), _as_float(z_m), self.window_radius_m))[
            :, None
        ]
        h = transfer_function(self._nu2[None, :], lam, z_m, nu_lim)
        return _real_matmul(spectrum * h, evaluation.T)

    def spectrum(self, pupil_field: Any) -> Any:
        """Hankel-transform samples :math:`U(\\nu_m)` (L, N) of pupil fields (L, M)."""
        return _real_matmul(pupil_field, self._forward_t)

    def plane_power(self, pupil_field: Any, wavelengths_m: np.ndarray, z_m: Any) -> Any:
        r"""Power (L,) reaching the plane at ``z_m`` inside the window: Parseval over the propagating modes.

        The transfer function is a pure phase below the band limit and 0 above it, so this is
        :math:`\sum_{\nu_m \le \nu_{lim}} |U(\nu_m)|^2 / (\pi R^2 J_1(j_m)^2)`: the integral of the
        whole PSF over the plane (what a uniform scene sends to the sensor), no pixel window.
        """
        torch = _torch()
        lam = np.asarray(wavelengths_m, dtype=float)
        nu_lim = torch.as_tensor(band_limit(lam, _as_float(z_m), self.window_radius_m))[:, None]
        keep = (self._nu2[None, :] <= nu_lim**2) & (self._nu2[None, :] < torch.as_tensor(lam)[:, None] ** -2)
        w = torch.from_numpy(self._series_w)
        return ((self.spectrum(pupil_field).abs() ** 2) * w * keep).sum(-1)

    def parseval_power(self, pupil_field: Any) -> Any:
        """Power :math:`\\sum_m |U(\\nu_m)|^2 / (\\pi R^2 J_1(j_m)^2)` (W per unit input intensity, m²).

        Equals :math:`2\\pi\\int |u_0|^2 r\\,dr` when the field is represented by the grid
        (discrete Parseval theorem of the Fourier–Bessel series).
        """
        torch = _torch()
        w = torch.from_numpy(self._series_w)
        return (self.spectrum(pupil_field).abs() ** 2 * w).sum(-1)


def _real_matmul(x: Any, m: Any) -> Any:
    """Complex ``x`` times real matrix ``m``, as two real products."""
    torch = _torch()
    return torch.complex(x.real @ m, x.imag @ m)


def _as_float(z: Any) -> float:
    return float(z.detach()) if hasattr(z, "detach") else float(z)


def angular_spectrum_2d(field: Any, dx_m: float, wavelengths_m: np.ndarray, z_m: Any) -> Any:
    """Band-limited angular-spectrum propagation of 2-D fields (Matsushima & Shimobaba 2009).

    Parameters
    ----------
    field : torch.Tensor, complex, shape (L, n, n)
        Input fields on a square grid of spacing ``dx_m`` (one per wavelength).
    dx_m : float
        Sample spacing (m).
    wavelengths_m : array, shape (L,)
        Wavelengths (m).
    z_m : float or torch.Tensor
        Propagation distance (m).

    Returns
    -------
    torch.Tensor, complex, shape (L, n, n)
        Output fields on the same grid (the input is zero-padded to 2n for a linear convolution).
    """
    torch = _torch()
    n = field.shape[-1]
    m = 2 * n
    pad = (m - n) // 2
    big = torch.nn.functional.pad(field, (pad, m - n - pad, pad, m - n - pad))
    f = torch.fft.fftfreq(m, d=dx_m, dtype=torch.float64)
    nu2 = f[:, None] ** 2 + f[None, :] ** 2
    lam = np.asarray(wavelengths_m, dtype=float)
    half_width = 0.5 * m * dx_m
    # Matsushima–Shimobaba: u_lim = 1 / (λ sqrt((2 Δu z)² + 1)), Δu = 1/(m dx); applied per axis
    lim = torch.as_tensor((1.0 / lam) / np.sqrt(1.0 + (_as_float(z_m) / half_width) ** 2))[:, None, None]
    lam_t = torch.as_tensor(lam)[:, None, None]
    h = transfer_function(nu2[None], lam_t, z_m, torch.as_tensor(1.0 / lam)[:, None, None])
    axis_mask = ((f[None, :, None].abs() < lim) & (f[None, None, :].abs() < lim)).to(torch.float64)
    out = torch.fft.ifft2(torch.fft.fft2(big) * h * axis_mask)
    return out[..., pad : pad + n, pad : pad + n]


def airy_intensity(rho_m: np.ndarray, *, wavelength_m: float, na: float) -> np.ndarray:
    r"""Airy pattern normalised to 1 at the centre, in its NA form.

    :math:`I(\rho)/I_0 = [2 J_1(v)/v]^2` with :math:`v = 2\pi\, NA\, \rho/\lambda` (Goodman 2005,
    eq. 4-32 with :math:`a/z = NA`). The peak for an incident power P is
    :math:`I_0 = P\,\pi NA^2/\lambda^2`.
    """
    from scipy.special import j1

    v = 2 * math.pi * na * np.asarray(rho_m, dtype=float) / wavelength_m
    out = np.ones_like(v)
    nz = v != 0
    out[nz] = (2 * j1(v[nz]) / v[nz]) ** 2
    return out


def pixel_nodes_for_bandwidth(
    pitch_m: float, cutoff_cycles_per_m: float, *, tol: float = 1e-5, max_nodes: int = 1024
) -> int:
    r"""Gauss–Legendre order per pixel side that integrates a band-limited intensity over a pixel.

    An incoherent PSF formed with numerical aperture NA has no spatial frequency above
    :math:`f_c = 2\,NA/\lambda` (the OTF cut-off; Goodman 2005, §6.3). Over a pixel of side
    ``pitch_m`` every such component is :math:`\cos(\omega x + \theta)` on :math:`x\in[-1,1]`
    with :math:`\omega \le \pi f_c\,\mathrm{pitch}`; the order returned is the smallest whose
    1-D rule integrates all of them to an absolute error ≤ ``2·tol`` (the integral of 1 is 2),
    checked on a dense grid of ω. The 2-D box rule is the tensor product. There is no fixed cap:
    the order grows with the bandwidth (about ``ω/2 + 10``); ``max_nodes`` only refuses absurd requests.

    Parameters
    ----------
    pitch_m : float
        Pixel side (m).
    cutoff_cycles_per_m : float
        Highest spatial frequency of the intensity (cycles/m), e.g. ``2 * NA / λ_min``.
    tol : float
        Absolute quadrature error of a unit-amplitude component, relative to the pixel area.
    max_nodes : int
        Largest order accepted; beyond it an :class:`InputError` gives the order needed.
    """
    if not (math.isfinite(pitch_m) and pitch_m > 0 and math.isfinite(cutoff_cycles_per_m) and cutoff_cycles_per_m >= 0):
        raise InputError(
            f"pixel_nodes_for_bandwidth: need pitch_m > 0 and a finite cutoff ≥ 0, got {pitch_m!r}, {cutoff_cycles_per_m!r}"
        )
    w_max = math.pi * cutoff_cycles_per_m * pitch_m
    omegas = np.linspace(0.0, w_max, 513)
    exact = 2.0 * np.sinc(omegas / math.pi)
    n = max(2, int(w_max / 2))
    while n <= max_nodes:
        x, w = np.polynomial.legendre.leggauss(n)
        err = np.abs(np.cos(np.outer(omegas, x)) @ w - exact).max()
        if err <= 2.0 * tol:
            return n
        n += 1
    raise InputError(
        f"pixel integration needs more than max_nodes={max_nodes} Gauss–Legendre nodes per side "
        f"(pixel {pitch_m:.3g} m, intensity bandwidth {cutoff_cycles_per_m:.3g} cycles/m)"
    )


def pixel_quadrature(n_pixels: int, pitch_m: float, n_sub: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes for box integration over each pixel of an n×n window centred on the axis.

    Returns
    -------
    rho_unique : numpy.ndarray, shape (Q,)
        Distinct radii (m) of all nodes (8-fold symmetry shares most of them).
    index : numpy.ndarray, shape (n, n, n_sub²)
        For each pixel (row = y, column = x) and node, the position in ``rho_unique``.
    weights : numpy.ndarray, shape (n_sub²,)
        Area weights (m²) of the nodes inside one pixel (they sum to pitch²).
    """
    if n_pixels < 1 or n_pixels % 2 == 0:
        raise InputError(f"pixel window must be odd and ≥ 1, got {n_pixels}")
    if n_sub < 1:
        raise InputError(f"n_sub (quadrature nodes per pixel side) must be ≥ 1, got {n_sub}")
    x, w = np.polynomial.legendre.leggauss(n_sub)
    off = 0.5 * pitch_m * x
    wt = 0.5 * pitch_m * w
    r = n_pixels // 2
    centres = np.arange(-r, r + 1) * pitch_m
    xs = centres[:, None] + off[None, :]  # (n, n_sub)
    X = xs[None, :, None, :]
    Y = xs[:, None, :, None]
    rho = np.sqrt(X**2 + Y**2)  # (n, n, n_sub, n_sub)
    key = np.round(rho / pitch_m, 12)
    uniq, inv = np.unique(key.ravel(), return_inverse=True)
    rho_unique = uniq * pitch_m
    index = inv.reshape(n_pixels, n_pixels, n_sub * n_sub)
    weights = (wt[:, None] * wt[None, :]).ravel()
    return rho_unique, index, weights


def radial_pixel_integrator(
    n_pixels: int,
    pitch_m: float,
    cutoff_cycles_per_m: float,
    *,
    tol: float = 1e-3,
    panels_per_period: float = 1.0,
    order: int = 10,
) -> tuple[np.ndarray, np.ndarray]:
    r"""Linear map from a radial function on a 1-D grid to its integrals over each pixel.

    For a rotationally symmetric intensity :math:`I(\rho)` band-limited to ``cutoff_cycles_per_m``,
    the pixel integrals are :math:`\mathrm{taps} = A\,I(r)`: the box rule of
    :func:`pixel_quadrature` with :func:`pixel_nodes_for_bandwidth` nodes per side, each node's
    value interpolated (barycentric Lagrange, ``order`` Gauss–Legendre points per panel,
    ``panels_per_period`` panels per period of the cut-off) from the radial grid ``r``. The
    intensity is then evaluated at a few hundred radii instead of every distinct node radius
    (tens of thousands), which is what makes a converged pixel integration affordable in a fit.

    Returns
    -------
    r_grid : numpy.ndarray, shape (G,)
        Radii (m) at which to evaluate the intensity.
    A : numpy.ndarray, shape (n_pixels², G)
        Pixel areas × interpolation weights (m²); rows in raster order (row = y, column = x).
    """
    n_sub = max(6, pixel_nodes_for_bandwidth(pitch_m, cutoff_cycles_per_m, tol=tol))
    rho, index, weights = pixel_quadrature(n_pixels, pitch_m, n_sub)
    r_max = float(rho.max()) * (1 + 1e-12) + 1e-30
    n_panels = max(1, int(math.ceil(r_max * cutoff_cycles_per_m * panels_per_period)))
    x, _ = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, r_max, n_panels + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[1:] + edges[:-1])
    grid = mid[:, None] + half[:, None] * x[None, :]  # (P, order)
    # barycentric weights of the Legendre points (any common factor cancels)
    bw = np.array([1.0 / np.prod([x[j] - x[k] for k in range(order) if k != j]) for j in range(order)])
    pan = np.minimum((rho / r_max * n_panels).astype(int), n_panels - 1)
    t = (rho - mid[pan]) / half[pan]  # local coordinate in [-1, 1]
    diff = t[:, None] - x[None, :]
    exact = np.isclose(diff, 0.0, atol=1e-14)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = bw[None, :] / diff
    terms = np.where(exact.any(axis=1, keepdims=True), exact.astype(float), terms)
    lag = terms / terms.sum(axis=1, keepdims=True)  # (Q, order): interpolation weights
    G = grid.size
    A = np.zeros((n_pixels * n_pixels, G))
    cols = pan[:, None] * order + np.arange(order)[None, :]  # (Q, order) column of each weight
    flat_index = index.reshape(n_pixels * n_pixels, -1)
    for p in range(n_pixels * n_pixels):
        q = flat_index[p]
        np.add.at(A[p], cols[q].ravel(), (lag[q] * weights[:, None]).ravel())
    return grid.ravel(), A
