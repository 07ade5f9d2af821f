"""Spectra against closed forms: delta, Gaussian, DoG, and unit conversions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import Kernel, reference_kernel
from fsdvs_hw.spectra import (
    cpd_to_cpp,
    cpp_to_cpd,
    frequency_response,
    magnitude_spectrum,
    pixels_per_degree,
    radial_response,
    spectral_summary,
)


@pytest.mark.parametrize("method", ["angular", "fft"])
def test_delta_is_flat(method):
    rr = radial_response(reference_kernel("delta", 7), method=method)
    assert np.allclose(rr.gain, 1.0, atol=1e-12)
    assert spectral_summary(reference_kernel("delta", 7)).kind == "all-pass"


@pytest.mark.parametrize("sigma", [1.0, 1.5, 2.0])
def test_gaussian_matches_continuous_transform(sigma):
    # A sampled Gaussian (window ≥ ±4σ) has |H| ≈ exp(-2π²σ²f²). The residual is the aliasing of
    # the periodic spectrum — the first replica at Nyquist contributes ≈ exp(-π²σ²/2) per axis —
    # plus the ±4σ truncation (< 5e-4). Stated tolerance: 0.5·exp(-π²σ²/2) + 5e-4
    # (3.6e-3 at σ = 1, 5e-4 at σ ≥ 1.5).
    size = 2 * math.ceil(4 * sigma) + 1
    rr = radial_response(reference_kernel("gaussian", size, sigma_px=sigma), n_freq=101)
    expected = np.exp(-2 * np.pi**2 * sigma**2 * rr.f_cpp**2)
    tol = 0.5 * np.exp(-(np.pi**2) * sigma**2 / 2) + 5e-4
    assert np.max(np.abs(rr.gain - expected)) < tol
    # and well inside the pass band the agreement is much tighter
    band = rr.f_cpp < 0.25
    assert np.max(np.abs(rr.gain[band] - expected[band])) < 1e-4


def test_gaussian_half_max_band():
    s = spectral_summary(reference_kernel("gaussian", 11, sigma_px=1.0))
    assert s.kind == "low-pass" and s.peak_frequency_cpp == 0 and s.q == 0
    assert s.band_high_cpp == pytest.approx(math.sqrt(math.log(2) / (2 * math.pi**2)), rel=2e-3)


def test_balanced_dog_has_zero_dc_and_is_band_pass():
    k = reference_kernel("dog", 9, w_surround=1.0)
    rr = radial_response(k)
    assert abs(rr.gain[0]) < 1e-12 and abs(spectral_summary(k).dc_gain) < 1e-12
    s = spectral_summary(k)
    assert s.kind == "band-pass" and 0 < s.band_low_cpp < s.peak_frequency_cpp < s.band_high_cpp < 0.5
    assert s.q == pytest.approx(s.peak_frequency_cpp / (s.band_high_cpp - s.band_low_cpp))


def test_dtft_matches_fft_on_grid(rng):
    k = Kernel(rng.normal(size=(5, 5)))
    f, mag = magnitude_spectrum(k, 16)
    fx, fy = np.meshgrid(f, f, indexing="xy")
    assert np.allclose(np.abs(frequency_response(k, fx, fy)), mag, atol=1e-12)


def test_angular_and_fft_methods_agree():
    k = reference_kernel("log", 9, sigma_px=1.2)
    a = radial_response(k, n_freq=65, n_angles=256)
    b = radial_response(k, n_freq=65, method="fft", n_fft=1024)
    assert np.max(np.abs(a.gain - b.gain)) < 0.02 * a.gain.max()


def test_pixels_per_degree_small_angle_limit():
    # ppd ≈ F / p · π/180 for p << F
    ppd = pixels_per_degree(4.86e-6, 12e-3)
    assert ppd == pytest.approx(12e-3 / 4.86e-6 * math.pi / 180, rel=1e-6)
    assert cpd_to_cpp(cpp_to_cpd(0.25, ppd), ppd) == pytest.approx(0.25)
    assert np.allclose(cpp_to_cpd(np.array([0.1, 0.2]), 10.0), [1.0, 2.0])


@pytest.mark.parametrize("args", [(0, 1e-3), (-1e-6, 1e-3), (5e-6, 0), (5e-6, float("inf"))])
def test_pixels_per_degree_rejects_bad_lengths(args):
    with pytest.raises(InputError):
        pixels_per_degree(*args)


def test_bad_arguments():
    k = reference_kernel("dog", 7)
    with pytest.raises(InputError, match="n_fft"):
        magnitude_spectrum(k, 5)
    with pytest.raises(InputError, match="method"):
        radial_response(k, method="wavelet")
    with pytest.raises(InputError, match="n_freq"):
        radial_response(k, n_freq=1)
