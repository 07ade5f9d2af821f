"""CSF models against published values; agreement metrics' invariances and extremes."""

from __future__ import annotations

import numpy as np
import pytest

from fsdvs_hw.csf import (
    CSF_METHODS,
    Geometry,
    contrast_sensitivity,
    csf_agreement,
    csf_peak,
    daly_1993,
    mannos_sakrison_1974,
    watson_ahumada_2005,
)
from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import Kernel, reference_kernel


def test_mannos_sakrison_published_values():
    f_peak, a_peak = csf_peak("mannos_sakrison_1974")
    assert f_peak == pytest.approx(7.89, abs=0.01)
    assert a_peak == pytest.approx(0.981, abs=0.001)
    assert mannos_sakrison_1974(0.0) == pytest.approx(0.0499, abs=1e-4)
    assert mannos_sakrison_1974(0.0) == pytest.approx(2.6 * 0.0192, rel=1e-12)


def test_barten_delegates_to_colour():
    from colour.contrast import contrast_sensitivity_function_Barten1999

    ours = contrast_sensitivity(4.0, method="barten_1999")
    assert float(ours) == pytest.approx(float(contrast_sensitivity_function_Barten1999(u=4.0)), rel=1e-12)
    assert float(contrast_sensitivity(0.0, method="barten")) == 0.0  # no divide-by-zero at DC


def test_watson_ahumada_closed_form():
    # at f = 0: gain (1 - a)
    assert watson_ahumada_2005(0.0) == pytest.approx(373.08 * (1 - 0.8493))
    f = 4.1726
    assert watson_ahumada_2005(f) == pytest.approx(373.08 * (1 / np.cosh(1.0) - 0.8493 / np.cosh(f / 1.3625)))
    assert np.isfinite(watson_ahumada_2005(np.array([1e4]))).all()


def test_daly_band_pass_and_luminance_dependence():
    f = np.geomspace(0.1, 60, 400)
    s = daly_1993(f)
    assert daly_1993(0.0) == 0.0 and np.all(np.isfinite(s))
    peak = f[np.argmax(s)]
    assert 2 < peak < 8  # Daly's CSF peaks at a few cycles/degree at 100 cd/m²
    # lower adapting luminance lowers sensitivity and moves the peak down
    s_dim = daly_1993(f, luminance_cd_m2=1.0)
    assert s_dim.max() < s.max() and f[np.argmax(s_dim)] < peak


@pytest.mark.parametrize("method", sorted(CSF_METHODS))
def test_every_model_is_band_pass_and_finite(method):
    f = np.geomspace(0.05, 100, 300)
    s = contrast_sensitivity(f, method=method)
    assert np.all(np.isfinite(s)) and np.all(s >= -1e-12)
    i = int(np.argmax(s))
    assert 0 < i < f.size - 1  # interior peak


def test_dispatcher_errors():
    with pytest.raises(InputError, match="unknown"):
        contrast_sensitivity(1.0, method="campbell_robson")
    with pytest.raises(InputError, match="≥ 0"):
        contrast_sensitivity(-1.0)
    with pytest.raises(InputError, match="finite"):
        contrast_sensitivity(np.nan)
    with pytest.raises(InputError, match="eccentricity_deg"):
        daly_1993(1.0, eccentricity_deg=-5.0)  # would divide by zero at -1/0.24 degrees


@pytest.mark.parametrize("method", sorted(CSF_METHODS))
def test_agreement_invariant_to_positive_scaling(method):
    k = reference_kernel("dog", 7)
    a = csf_agreement(k, method=method)
    b = csf_agreement(k.scaled(123.4), method=method)
    for field in ("pixels_per_degree", "peak_ratio", "correlation", "log_rms_error_dec", "rms_error"):
        assert getattr(b, field) == pytest.approx(getattr(a, field), rel=1e-9, abs=1e-12)


def test_zero_dc_kernels_give_finite_log_metrics():
    for k in (reference_kernel("dog", 9, w_surround=1.0), reference_kernel("log", 7)):
        a = csf_agreement(k)
        assert np.isfinite([a.log_rms_error_dec, a.rms_error, a.correlation, a.peak_ratio]).all()
        assert a.log_rms_error_dec < 3.0 + 1e-12  # bounded by the -60 dB floor


def test_geometry_ties_axes_and_peak_ratio():
    k = reference_kernel("dog", 7)
    fp_cpp = 0.18993  # this kernel's radial peak
    # choose the focal length that puts the kernel's peak on the CSF's 7.89 cpd
    ppd = 7.8909 / fp_cpp
    import math

    focal = k.pitch_m / (2 * math.tan(math.radians(1 / ppd) / 2))
    a = csf_agreement(k, geometry=Geometry(k.pitch_m, focal))
    assert not a.scale_fitted and a.pixels_per_degree == pytest.approx(ppd, rel=1e-9)
    assert a.peak_ratio == pytest.approx(1.0, abs=0.01)
    far = csf_agreement(k, geometry=Geometry(k.pitch_m, focal * 4))
    assert far.peak_ratio == pytest.approx(4.0, rel=0.01)
    assert far.rms_error > a.rms_error


def test_fitted_scale_is_at_least_as_good_as_any_geometry():
    k = reference_kernel("dog", 7)
    fit = csf_agreement(k)
    assert fit.scale_fitted and fit.implied_focal_length_m > 0
    for focal in (4e-3, 8e-3, 16e-3, 30e-3):
        g = csf_agreement(k, geometry=Geometry(k.pitch_m, focal))
        assert fit.rms_error <= g.rms_error + 1e-9
    # implied focal length reproduces the fitted scale
    again = csf_agreement(k, geometry=Geometry(k.pitch_m, fit.implied_focal_length_m))
    assert again.pixels_per_degree == pytest.approx(fit.pixels_per_degree, rel=1e-9)


def test_band_pass_agrees_better_than_low_pass():
    dog = csf_agreement(reference_kernel("dog", 7))
    gauss = csf_agreement(reference_kernel("gaussian", 7, sigma_px=1.0))
    delta = csf_agreement(reference_kernel("delta", 7))
    assert dog.correlation > 0.85 and dog.peak_ratio > 0
    assert gauss.peak_ratio == 0 and delta.peak_ratio == 0
    assert delta.correlation == 0.0  # flat response: correlation undefined -> 0, documented
    assert dog.rms_error < gauss.rms_error and dog.rms_error < delta.rms_error


def test_agreement_argument_errors():
    k = Kernel(np.eye(3))
    with pytest.raises(InputError, match="f_low_cpp"):
        csf_agreement(k, f_low_cpp=0.4)
    with pytest.raises(InputError, match="floor"):
        csf_agreement(k, floor=0)
    with pytest.raises(InputError, match="focal_length_m"):
        Geometry(5e-6, -1.0)


@pytest.mark.parametrize("exponent", [-300, -150, 0, 150, 300])
def test_agreement_stable_for_extreme_tap_magnitudes(exponent):
    k = reference_kernel("dog", 7)
    a = csf_agreement(k)
    b = csf_agreement(k.scaled(10.0**exponent))
    assert np.isfinite([b.rms_error, b.log_rms_error_dec, b.correlation]).all()
    assert b.rms_error == pytest.approx(a.rms_error, rel=1e-9)


def test_property_random_kernels_give_bounded_metrics():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=12, deadline=None)
    @given(size=st.sampled_from([1, 3, 5, 7, 9]), seed=st.integers(0, 2**31 - 1), one_hot=st.booleans())
    def check(size, seed, one_hot):
        r = np.random.default_rng(seed)
        taps = np.zeros((size, size))
        if one_hot:  # a single non-zero tap anywhere: |H| is flat
            taps[r.integers(size), r.integers(size)] = r.choice([-1.0, 1.0]) * 10 ** r.uniform(-8, 8)
        else:
            taps = r.normal(size=(size, size))
        a = csf_agreement(Kernel(taps))
        assert 0 <= a.rms_error <= 1 + 1e-12
        assert 0 <= a.log_rms_error_dec <= 3 + 1e-12
        assert -1 - 1e-12 <= a.correlation <= 1 + 1e-12
        assert np.isfinite(a.pixels_per_degree) and a.pixels_per_degree > 0

    check()
