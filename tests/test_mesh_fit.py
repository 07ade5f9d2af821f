"""Dual resistive-mesh design and its IPOPT fit: recovery, honest errors, penalties, extremes, errors."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

import fsdvs_hw
from fsdvs_hw.errors import InputError, KernelError
from fsdvs_hw.kernels import Kernel, load_kernel, reference_kernel
from fsdvs_hw.realise.base import Realisation, kernel_error, realisation_from_dict
from fsdvs_hw.realise.mesh import (
    MeshAsymmetryWarning,
    MeshBounds,
    MeshDesign,
    MeshFitWarning,
    _casadi_orbit_response,
    _numpy_orbit_response,
    fit_resistive_mesh,
    mismatch_sensitivity,
)
from fsdvs_hw.realise.mesh_response import lattice_green_function

KNOWN = dict(lambda_narrow_px=0.8, lambda_wide_px=2.5, gain_narrow=1.5, gain_wide=1.2)


def _known_design(**kw) -> MeshDesign:
    args = {**KNOWN, **kw}
    return MeshDesign.from_space_constants(
        args.pop("lambda_narrow_px"), args.pop("lambda_wide_px"), args.pop("gain_narrow"), args.pop("gain_wide"), **args
    )


def test_design_kernel_is_pixel_plus_narrow_minus_wide():
    d = _known_design(size=7)
    k = d.kernel()
    expected = 1.5 * lattice_green_function(0.8, 3) - 1.2 * lattice_green_function(2.5, 3)
    expected[3, 3] += 1.0
    assert np.allclose(k.taps, expected, rtol=1e-14, atol=1e-16)
    # on a window large enough to hold the whole response the DC gain is w_p + a - b
    assert d.kernel(63).dc_gain == pytest.approx(1.0 + 1.5 - 1.2, abs=3e-5)  # tail beyond 12 λ_w: ~1e-5
    assert d.lambda_narrow_px == pytest.approx(0.8, rel=1e-14)
    assert d.g_vertical_wide_s == pytest.approx(1e-8 / 2.5**2, rel=1e-14)


@pytest.mark.parametrize("size", [5, 7])
def test_recovery_of_a_known_dual_mesh(size):
    truth = _known_design(size=size)
    d = fit_resistive_mesh(truth.kernel(), mismatch_sigma=0.0)
    assert d.fit["success"]
    assert d.fit["error"] < 1e-6
    for name in ("lambda_narrow_px", "lambda_wide_px", "gain_narrow", "gain_wide"):
        assert getattr(d, name) == pytest.approx(getattr(truth, name), rel=1e-2), name
    assert d.fit["error"] == pytest.approx(kernel_error(d.kernel(), truth.kernel()), abs=1e-15)


def test_recovery_with_free_pixel_weight_and_on_the_finite_grid_model():
    truth = _known_design(size=7, pixel_weight=0.6, model="grid", grid_half_width=8)
    # a finite chip holds all injected current: the whole-chip kernel sums to w_p + a - b exactly,
    # and there are no taps beyond the chip's edge
    whole = truth.kernel(21).taps
    assert whole.sum() == pytest.approx(0.6 + 1.5 - 1.2, rel=1e-12)
    assert np.all(whole[:2] == 0.0)
    d = fit_resistive_mesh(truth.kernel(), mismatch_sigma=0.0, pixel_weight=None, model="grid", grid_half_width=8)
    assert d.fit["error"] < 1e-6
    for name in ("lambda_narrow_px", "lambda_wide_px", "gain_narrow", "gain_wide", "pixel_weight"):
        assert getattr(d, name) == pytest.approx(getattr(truth, name), rel=1e-2), name


def test_reported_errors_are_honest_for_dog_log_and_shipped_kernels():
    dog = reference_kernel("dog", 7)
    noisy = dog.with_taps(dog.taps + 0.01 * np.random.default_rng(7).standard_normal((7, 7)), name="learned-like")
    targets = [dog, reference_kernel("log", 7, sigma_px=1.0), load_kernel("designs/kernels/dog_7x7.json"), noisy]
    for t in targets:
        for wp in (1.0, None):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", MeshAsymmetryWarning)  # the learned-like kernel is asymmetric
                d = fit_resistive_mesh(t, pixel_weight=wp)
            # the reported error is the error of the kernel the design really applies
            assert d.fit["error"] == pytest.approx(kernel_error(d.kernel(), t), rel=1e-12)
            big = d.fit["error_full_size"]
            assert d.fit["error_full"] == pytest.approx(kernel_error(d.kernel(big), t), rel=1e-12)
            assert d.fit["error_full"] >= d.fit["error"] - 1e-12  # the tail outside the window only adds error
            assert d.fit["objective"] <= d.fit["init_objective"] + 1e-12  # IPOPT never ends worse than its start
    # the paper's sketch (pixel weight fixed at 1) fits a sum-normalised Gaussian DoG far worse
    dog = reference_kernel("dog", 7)
    fixed = fit_resistive_mesh(dog).fit["error"]
    free = fit_resistive_mesh(dog, pixel_weight="free").fit["error"]
    assert fixed > 0.4 and free < 0.3 and free < fixed / 2


def test_larger_fit_window_trades_window_error_for_tail_error():
    t = reference_kernel("dog", 7)
    plain = fit_resistive_mesh(t, pixel_weight=None)
    wide = fit_resistive_mesh(t, pixel_weight=None, fit_size=13)
    assert wide.fit["fit_size"] == 13 and wide.size == 7
    assert wide.fit["error_full"] < plain.fit["error_full"]
    assert wide.fit["error"] >= plain.fit["error"] - 1e-9
    with pytest.raises(InputError, match="fit_size"):
        fit_resistive_mesh(t, fit_size=4)


def test_ipopt_beats_every_least_squares_start_and_respects_bounds():
    t = reference_kernel("log", 7, sigma_px=1.0)
    b = MeshBounds(lambda_px=(0.3, 6.0), gain=(1e-3, 4.0), min_lambda_ratio=2.0)
    d = fit_resistive_mesh(t, bounds=b, pixel_weight=None)
    assert 0.3 * (1 - 1e-9) <= d.lambda_narrow_px <= 6.0 * (1 + 1e-9)
    assert d.lambda_wide_px >= 2.0 * d.lambda_narrow_px * (1 - 1e-9)
    for g in (d.gain_narrow, d.gain_wide, d.pixel_weight):
        assert 1e-3 * (1 - 1e-9) <= g <= 4.0 * (1 + 1e-9)
    # a bounds mapping (design files) gives the same fit
    d2 = fit_resistive_mesh(t, bounds={"lambda_px": [0.3, 6.0], "gain": [1e-3, 4.0], "min_lambda_ratio": 2.0}, pixel_weight=None)
    assert d2.lambda_wide_px == pytest.approx(d.lambda_wide_px, rel=1e-9)


def test_mismatch_penalty_prevents_the_unbuildable_collapse():
    t = reference_kernel("dog", 7)
    loose = MeshBounds(min_lambda_ratio=1.0, gain=(1e-4, 1e3))
    with warnings.catch_warnings():  # the unpenalised problem drifts towards λ_n = λ_w, gains → ∞
        warnings.simplefilter("ignore", MeshFitWarning)  # (IPOPT may stop at max_iter: reported, not hidden)
        collapsed = fit_resistive_mesh(t, bounds=loose, pixel_weight=None, mismatch_sigma=0.0, max_iter=100)
    robust = fit_resistive_mesh(t, bounds=loose, pixel_weight=None, mismatch_sigma=0.01)
    # the unpenalised fit is a near-cancellation of two similar meshes with big gains
    assert collapsed.fit["mismatch_sensitivity"] > 3 * robust.fit["mismatch_sensitivity"]
    assert collapsed.gain_narrow > robust.gain_narrow
    # expected error under 1 % die-level mismatch: sqrt(e² + (σ S)²) is lower for the penalised fit
    exp_c = math.hypot(collapsed.fit["error"], 0.01 * collapsed.fit["mismatch_sensitivity"])
    exp_r = math.hypot(robust.fit["error"], 0.01 * robust.fit["mismatch_sensitivity"])
    assert exp_r < exp_c


def test_mismatch_sensitivity_matches_finite_differences():
    d = _known_design(size=7)
    t = d.kernel()
    base = t.taps
    total = 0.0
    eps = 1e-6
    for field in ("g_lateral_narrow_s", "g_vertical_narrow_s", "g_lateral_wide_s", "g_vertical_wide_s", "gain_narrow", "gain_wide", "pixel_weight"):
        kw = {f: getattr(d, f) for f in d.__dataclass_fields__ if f not in ("kind", "fit", "target")}
        kw[field] = kw[field] * math.exp(eps)
        dk = (MeshDesign(**kw).kernel_taps() - base) / eps
        total += float((dk * dk).sum())
    assert mismatch_sensitivity(d) == pytest.approx(math.sqrt(total / (base * base).sum()), rel=1e-4)


@pytest.mark.parametrize("model", ["lattice", "grid"])
def test_casadi_model_equals_numpy_model_with_its_gradient(model):
    import casadi as ca

    u = ca.SX.sym("u")
    h = 9 if model == "grid" else None
    expr = _casadi_orbit_response(u, 3, model, 20.0, h)
    f = ca.Function("f", [u], [expr, ca.jacobian(expr, u)])
    for lam in (0.4, 1.3, 4.0):
        hv, dv = (np.array(a).ravel() for a in f(2 * math.log(lam)))
        hn, dn = _numpy_orbit_response(lam, 3, model, h)
        assert np.allclose(hv, hn, rtol=1e-10, atol=1e-15)
        assert np.allclose(dv, dn, rtol=1e-5, atol=1e-12)


def test_asymmetric_target_warns_and_fits_its_symmetric_part():
    truth = _known_design(size=7).kernel()
    rng = np.random.default_rng(5)
    bump = rng.standard_normal((7, 7)) * 0.02
    asym = bump - bump.T  # antisymmetric: orthogonal to every D4-symmetric kernel
    t = truth.with_taps(truth.taps + asym)
    with pytest.warns(MeshAsymmetryWarning, match="not D4-symmetric"):
        d = fit_resistive_mesh(t, mismatch_sigma=0.0)
    assert d.fit["error_symmetric_part"] < 1e-6
    assert d.lambda_wide_px == pytest.approx(2.5, rel=1e-2)
    # least squares: the residual is exactly the unrealisable asymmetric part
    assert d.fit["error"] == pytest.approx(np.linalg.norm(asym) / np.linalg.norm(t.taps), rel=1e-5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit_resistive_mesh(truth, mismatch_sigma=0.0)  # a symmetric target does not warn


@pytest.mark.parametrize("scale", [1e-12, 1e12])
def test_target_scale_out_of_reach_warns_and_stays_finite(scale):
    t = reference_kernel("dog", 5).scaled(scale)
    with pytest.warns(MeshFitWarning, match="out of reach"):
        d = fit_resistive_mesh(t, pixel_weight="free")
    assert math.isfinite(d.fit["error"]) and d.fit["error"] >= 0.999
    assert np.all(np.isfinite(d.kernel().taps))


@pytest.mark.parametrize("lam_n, lam_w", [(1e-3, 1e-2), (1e-3, 1e3), (1e2, 1e3)])
def test_designs_at_extreme_conductance_ratios_stay_finite(lam_n, lam_w):
    # g_l / g_v from 1e-6 to 1e6
    d = MeshDesign.from_space_constants(lam_n, lam_w, 1.0, 0.5, size=7)
    k = d.kernel()
    assert np.all(np.isfinite(k.taps))
    for item in d.cost().values():
        assert math.isfinite(item.value)
    assert 0.0 <= d.tail_energy_fraction() <= 1.0


def test_fit_at_extreme_lambda_bounds():
    # λ from 1e-3 to 1e3 px: conductance ratios g_l/g_v from 1e-6 to 1e6
    b = MeshBounds(lambda_px=(1e-3, 1e3), gain=(1e-4, 10.0), min_lambda_ratio=1.5, conductance_s=(1e-16, 1e-2))
    d = fit_resistive_mesh(reference_kernel("dog", 7), bounds=b, pixel_weight=None)
    assert d.fit["success"] and math.isfinite(d.fit["error"]) and d.fit["error"] < 0.3


def test_protocol_round_trip():
    d = fit_resistive_mesh(_known_design(size=5).kernel(), mismatch_sigma=0.0)
    assert isinstance(d, Realisation) and d.kind == "mesh"
    data = json.loads(json.dumps(d.to_dict()))
    back = realisation_from_dict(data)
    assert isinstance(back, MeshDesign)
    assert back.kernel().allclose(d.kernel(), rtol=1e-14)
    assert back.fit["error"] == d.fit["error"] and back.target.allclose(d.target)
    cost = d.cost()
    assert cost["g_vertical_wide"].unit == "S" and cost["tau_wide"].unit == "s" and cost["lambda_wide_m"].unit == "m"
    assert cost["lambda_wide_m"].value == pytest.approx(d.lambda_wide_px * d.pitch_m)
    assert cost["tau_wide"].value == pytest.approx(d.node_capacitance_f / d.g_vertical_wide_s)
    assert "lambda" in d.describe() and "kernel error" in d.describe()
    assert fsdvs_hw.fit_resistive_mesh is fit_resistive_mesh


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"mismatch_sigma": 2.0}, "mismatch_sigma"),
        ({"model": "spice"}, "model"),
        ({"model": "grid"}, "grid_half_width"),
        ({"pixel_weight": -1.0}, "pixel_weight"),
        ({"pixel_weight": "fixed"}, "pixel_weight"),
        ({"g_lateral_s": 1.0}, "g_lateral_s"),
        ({"bounds": {"lambda_px": (5.0, 1.0)}}, "lambda_px"),
        ({"bounds": {"min_lambda_ratio": 0.5}}, "min_lambda_ratio"),
        ({"bounds": {"gain": (0.0, 1.0)}}, "gain"),
        ({"bounds": {"lambda": (1.0, 2.0)}}, "unknown key"),
        ({"bounds": "tight"}, "bounds"),
        ({"n_init": 1}, "n_init"),
    ],
)
def test_bad_options_raise_input_error(kwargs, match):
    with pytest.raises(InputError, match=match):
        fit_resistive_mesh(reference_kernel("dog", 5), **kwargs)


def test_bad_kernels_raise():
    with pytest.raises(KernelError, match="finite"):
        fit_resistive_mesh(np.full((3, 3), np.nan))
    with pytest.raises(KernelError, match="square"):
        fit_resistive_mesh(np.ones((3, 5)))
    with pytest.raises(InputError, match="kernel"):
        fit_resistive_mesh("dog")
    with pytest.raises(InputError, match="gain_narrow"):
        _known_design(gain_narrow=float("nan"))
    with pytest.raises(InputError, match="g_vertical_narrow_s|conductance"):
        MeshDesign(1e-8, 0.0, 1e-8, 1e-9, 1.0, 1.0)
    with pytest.raises(InputError, match="kind 'mesh'"):
        MeshDesign.from_dict({"kind": "asic"})
    assert isinstance(Kernel(np.ones((3, 3))), Kernel)
