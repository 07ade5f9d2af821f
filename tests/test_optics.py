"""Physics tests of the scalar-diffraction propagators (fsdvs_hw.realise.optics)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import j0, j1

torch = pytest.importorskip("torch")

from fsdvs_hw.errors import InputError
from fsdvs_hw.realise.optics import (
    RadialPropagator,
    airy_intensity,
    angular_spectrum_2d,
    band_limit,
    pixel_quadrature,
    required_modes,
)

LAM = 0.55e-6


def _perfect_lens(r: np.ndarray, f: float, lam: float = LAM) -> np.ndarray:
    """Hyperbolic (aberration-free) lens phase: a converging spherical wave to the focus at f."""
    return np.exp(-1j * 2 * math.pi / lam * (np.sqrt(r * r + f * f) - f))


def _focal_field(
    a: float, f: float, window: float, n_modes: int, rho: np.ndarray
) -> tuple[np.ndarray, RadialPropagator]:
    prop = RadialPropagator(a, window, n_modes)
    u0 = torch.from_numpy(_perfect_lens(prop.r_pupil, f))[None]
    u = prop.propagate(u0, np.array([LAM]), f, prop.evaluation_matrix(rho))[0]
    return u.numpy(), prop


@pytest.mark.parametrize("a,f", [(250e-6, 5e-3), (500e-6, 25e-3)])
def test_perfect_lens_matches_airy_pattern_at_low_na(a, f):
    na = a / math.hypot(a, f)
    rho = np.linspace(0, 4 * 0.61 * LAM / na, 241)  # out to the fourth dark ring
    u, _ = _focal_field(a, f, 4 * a, 1024, rho)
    intensity = np.abs(u) ** 2
    airy = airy_intensity(rho, wavelength_m=LAM, na=na)
    assert np.max(np.abs(intensity / intensity[0] - airy)) <= 1e-3
    # absolute peak: I0 = P π NA² / λ² with P = π a² (unit input intensity)
    peak = math.pi * a * a * math.pi * na * na / LAM**2
    assert intensity[0] / peak == pytest.approx(1.0, abs=2e-3)


def test_airy_check_can_fail_with_the_wrong_na():
    a, f = 250e-6, 5e-3
    na = a / math.hypot(a, f)
    rho = np.linspace(0, 4 * 0.61 * LAM / na, 241)
    u, _ = _focal_field(a, f, 4 * a, 1024, rho)
    i = np.abs(u) ** 2
    assert np.max(np.abs(i / i[0] - airy_intensity(rho, wavelength_m=LAM, na=1.02 * na))) > 1e-2


def test_encircled_energy_matches_rayleigh_formula():
    """Absolute energy: power inside radius ρ at focus = πa² (1 − J0²(v) − J1²(v)), v = 2π NA ρ/λ."""
    a, f = 250e-6, 5e-3
    na = a / math.hypot(a, f)
    ring = 0.61 * LAM / na
    edges = np.array([0.0, 2.5, 5.0, 10.0]) * ring
    x, w = np.polynomial.legendre.leggauss(160)
    rho = np.concatenate([0.5 * (lo + hi) + 0.5 * (hi - lo) * x for lo, hi in zip(edges[:-1], edges[1:])])
    wts = np.concatenate([0.5 * (hi - lo) * w for lo, hi in zip(edges[:-1], edges[1:])])
    u, _ = _focal_field(a, f, 4 * a, 1024, rho)
    seg = (wts * np.abs(u) ** 2 * 2 * math.pi * rho).reshape(3, -1).sum(1)
    v = 2 * math.pi * na * edges[1:] / LAM
    expected = 1 - j0(v) ** 2 - j1(v) ** 2
    np.testing.assert_allclose(np.cumsum(seg) / (math.pi * a * a), expected, atol=1e-3)


def test_radial_energy_is_conserved_in_the_sensor_plane():
    """Power over the whole output window equals the power through the aperture within 1e-3."""
    a, f = 150e-6, 600e-6
    window = 4 * a
    prop = RadialPropagator(a, window, 1700)
    assert prop.nu_max > band_limit(LAM, f, window)  # the grid holds every wave that stays in the window
    u0 = torch.from_numpy(_perfect_lens(prop.r_pupil, f, LAM))[None]
    pupil_power = float(prop.parseval_power(u0)[0])
    assert pupil_power / (math.pi * a * a) == pytest.approx(1.0, abs=1e-3)
    x, w = np.polynomial.legendre.leggauss(16)
    edges = np.linspace(0, window, 301)
    rho = (0.5 * (edges[1:] + edges[:-1])[:, None] + 0.5 * np.diff(edges)[:, None] * x).ravel()
    wr = (0.5 * np.diff(edges)[:, None] * w).ravel()
    for z in (0.5 * f, f):
        u = prop.propagate(u0, np.array([LAM]), z, prop.evaluation_matrix(rho))[0].numpy()
        out = float(np.sum(wr * np.abs(u) ** 2 * 2 * math.pi * rho))
        assert out / (math.pi * a * a) == pytest.approx(1.0, abs=1e-3)


def _gaussian_on_axis(z: float, w0: float) -> float:
    """Paraxial Gaussian beam: I(0, z)/I(0, 0) = 1/(1 + (z/z_R)²), z_R = π w0²/λ."""
    zr = math.pi * w0 * w0 / LAM
    return 1 / (1 + (z / zr) ** 2)


def test_angular_spectrum_2d_conserves_energy_and_matches_gaussian_beam():
    w0, dx, n = 8e-6, 0.5e-6, 257
    x = (np.arange(n) - n // 2) * dx
    X, Y = np.meshgrid(x, x)
    field = torch.from_numpy(np.exp(-(X**2 + Y**2) / w0**2)[None].astype(complex))
    p_in = float((field.abs() ** 2).sum())
    for z in (100e-6, math.pi * w0 * w0 / LAM):
        out = angular_spectrum_2d(field, dx, np.array([LAM]), z)[0]
        assert float((out.abs() ** 2).sum()) / p_in == pytest.approx(1.0, abs=1e-3)
        assert float(out[n // 2, n // 2].abs() ** 2) == pytest.approx(_gaussian_on_axis(z, w0), rel=2e-3)


def test_radial_path_matches_gaussian_beam():
    w0 = 8e-6
    prop = RadialPropagator(6 * w0, 8 * w0, 256)
    u0 = torch.from_numpy(np.exp(-(prop.r_pupil**2) / w0**2).astype(complex))[None]
    for z in (100e-6, math.pi * w0 * w0 / LAM):
        u = prop.propagate(u0, np.array([LAM]), z, prop.evaluation_matrix(np.array([0.0])))[0, 0]
        assert float(abs(u) ** 2) == pytest.approx(_gaussian_on_axis(z, w0), rel=2e-3)


def test_angular_spectrum_2d_perfect_lens_matches_airy_shape():
    a, f, dx = 40e-6, 400e-6, 0.5e-6
    n = 321
    x = (np.arange(n) - n // 2) * dx
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X, Y)
    amp = np.clip((a - r) / dx + 0.5, 0, 1)
    out = angular_spectrum_2d(torch.from_numpy((amp * _perfect_lens(r, f))[None]), dx, np.array([LAM]), f)[0].numpy()
    na = a / math.hypot(a, f)
    row = np.abs(out[n // 2, n // 2 :]) ** 2
    airy = airy_intensity(x[n // 2 :], wavelength_m=LAM, na=na)
    sel = x[n // 2 :] < 3 * 0.61 * LAM / na
    assert np.max(np.abs(row[sel] / row[0] - airy[sel])) < 1e-2  # NA 0.1, Fresnel number 7: shape agrees


def test_radial_and_2d_paths_agree_on_the_same_field():
    a, f, z, dx = 30e-6, 300e-6, 330e-6, 0.25e-6
    n = 481
    x = (np.arange(n) - n // 2) * dx
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X, Y)
    amp = np.clip((a - r) / dx + 0.5, 0, 1)
    out2 = angular_spectrum_2d(torch.from_numpy((amp * _perfect_lens(r, f))[None]), dx, np.array([LAM]), z)[0].numpy()
    prop = RadialPropagator(a, n * dx, 1024)  # same half-width as the zero-padded 2-D grid
    u0 = torch.from_numpy(_perfect_lens(prop.r_pupil, f))[None]
    rho = x[n // 2 : n // 2 + 120]
    ur = prop.propagate(u0, np.array([LAM]), z, prop.evaluation_matrix(rho))[0].numpy()
    i2 = np.abs(out2[n // 2, n // 2 : n // 2 + 120]) ** 2
    ir = np.abs(ur) ** 2
    assert np.linalg.norm(i2 - ir) / np.linalg.norm(ir) < 5e-3


def test_band_limit_formula_and_required_modes():
    # ν_lim = 1/(λ√(1+(z/L)²)): z = L gives 1/(λ√2)
    assert band_limit(LAM, 1.0, 1.0) == pytest.approx(1 / (LAM * math.sqrt(2)))
    n = required_modes(100e-6, 0.25, 0.5e-6, oversample=1.0, minimum=1)
    # Nyquist: grid frequency (n + 3/4)/(2R) must reach NA/λ
    assert (n + 0.75) / (2 * 100e-6) >= 0.25 / 0.5e-6
    with pytest.raises(InputError, match="numerical aperture"):
        required_modes(100e-6, 1.2, 0.5e-6)


def test_propagator_rejects_bad_geometry():
    with pytest.raises(InputError, match="aperture radius"):
        RadialPropagator(2e-4, 1e-4, 128)
    with pytest.raises(InputError, match="n_modes"):
        RadialPropagator(1e-4, 2e-4, 4)
    prop = RadialPropagator(1e-4, 2e-4, 64)
    with pytest.raises(InputError, match="exceeds the propagation window"):
        prop.evaluation_matrix(np.array([3e-4]))


def test_pixel_quadrature_weights_and_symmetry():
    rho, index, weights = pixel_quadrature(5, 4e-6, 6)
    assert weights.sum() == pytest.approx((4e-6) ** 2)
    # integrating ρ² over the 5×5 window: ∫∫ x² + y² = 2 · (5p) · ∫ x² dx over [-2.5p, 2.5p]
    p = 4e-6
    total = float((rho[index] ** 2 * weights).sum())
    assert total == pytest.approx(2 * 5 * p * (2 * (2.5 * p) ** 3 / 3), rel=1e-10)
    assert index.shape == (5, 5, 36)
    np.testing.assert_array_equal(np.sort(index[0, 1]), np.sort(index[1, 0]))
    with pytest.raises(InputError):
        pixel_quadrature(4, p, 6)
