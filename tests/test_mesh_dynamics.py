"""Mesh dynamics (settling, drifting scenes, transient decision, moving edge) and mismatch Monte Carlo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.realise.mesh import MeshDesign
from fsdvs_hw.realise.mesh.dynamics import drift_kernel, mesh_needs_transient, moving_edge_response
from fsdvs_hw.realise.mesh.mismatch import mismatch_monte_carlo


def _design(**kw) -> MeshDesign:
    return MeshDesign.from_space_constants(0.8, 2.5, 1.5, 1.2, size=7, **kw)


def test_time_constant_is_c_over_gv_and_grows_as_lambda_squared():
    d = _design(node_capacitance_f=50e-15, g_lateral_s=2e-8)
    assert d.tau_wide_s == pytest.approx(50e-15 / d.g_vertical_wide_s, rel=1e-14)
    assert d.tau_wide_s / d.tau_narrow_s == pytest.approx((2.5 / 0.8) ** 2, rel=1e-12)
    assert d.tau_wide_s == pytest.approx(50e-15 * 2.5**2 / 2e-8, rel=1e-12)


def test_drift_kernel_is_static_at_rest_and_lags_by_v_tau():
    d = _design()
    assert np.abs(drift_kernel(d, (0.0, 0.0)) - d.kernel_taps(d.size)).max() < 1e-12
    # a single mesh's centroid trails a drifting scene by v·τ pixels (exact in the continuum;
    # the lattice-sampled kernel carries a small Gibbs term from the Nyquist edge, < 2 %)
    single = MeshDesign.from_space_constants(1.5, 3.0, 1.0, 0.0, pixel_weight=0.0, size=61)
    x = np.arange(-30, 31)

    def centroid(v):
        k = drift_kernel(single, (v, 0.0))
        return float((k.sum(axis=0) * x).sum() / k.sum()), k

    c1, k = centroid(2e3)
    c2, _ = centroid(4e3)
    assert c1 == pytest.approx(-2e3 * single.tau_narrow_s, rel=0.02)
    assert c2 / c1 == pytest.approx(2.0, rel=1e-3)
    v = 2e3
    # moving along y only moves the response along y
    ky = drift_kernel(single, (0.0, v))
    assert np.allclose(ky, k.T, atol=1e-15)


def test_transient_decision_scales_with_speed_and_explains_itself():
    d = _design()
    slow = mesh_needs_transient(d, 100.0, tolerance=0.01)
    fast = mesh_needs_transient(d, 1e5, tolerance=0.01)
    assert not slow.needed and fast.needed
    assert slow.kernel_error == pytest.approx(fast.kernel_error / 1000, rel=0.05)  # linear in speed when small
    assert fast.lag_px == pytest.approx(1e5 * d.tau_wide_s)
    assert "skipped" in slow.reason and "modelled" in fast.reason and f"{fast.kernel_error:.3g}" in fast.reason
    # the reason states the lag v·tau in pixels and the time constant (what a reader checks)
    assert f"moves {fast.lag_px:.3g} px per slowest time constant tau = C/g_v = {fast.tau_max_s:.3g} s" in fast.reason
    assert mesh_needs_transient(d, 0.0).kernel_error == 0.0


def test_moving_edge_transient_agrees_with_the_decision():
    d = _design()
    slow = moving_edge_response(d, 100.0)
    fast = moving_edge_response(d, 1e5)
    # the plan's static kernel is within tolerance when the decision skips the transient ...
    assert slow.max_relative_error() < 0.01
    # ... and far off when it asks for it
    assert fast.max_relative_error() > 0.1
    # the time-domain error grows linearly with speed (first-order lag)
    mid = moving_edge_response(d, 1e3)
    assert mid.max_relative_error() / slow.max_relative_error() == pytest.approx(10.0, rel=0.1)
    # long after the edge has passed, uncovered pixels rest at 0 and covered ones reach the DC gain
    assert slow.static_output[-1, 0] == pytest.approx(d.kernel(63).dc_gain, abs=0.05)


def test_moving_edge_time_step_does_not_matter_for_fast_meshes():
    # exponential integration is exact per mode: a mesh much faster than the step is no problem
    d = _design(node_capacitance_f=1e-18)
    r = moving_edge_response(d, 10.0)
    assert np.all(np.isfinite(r.output)) and r.max_relative_error() < 1e-3


def test_dynamics_bad_input():
    d = _design()
    with pytest.raises(InputError, match="edge_speed"):
        mesh_needs_transient(d, -1.0)
    with pytest.raises(InputError, match="tolerance"):
        mesh_needs_transient(d, 1.0, tolerance=0.0)
    with pytest.raises(InputError, match="design"):
        mesh_needs_transient("mesh", 1.0)
    with pytest.raises(InputError, match="velocity"):
        drift_kernel(d, 3.0)
    with pytest.raises(InputError, match="> 0"):
        moving_edge_response(d, 0.0)


# ---------------------------------------------------------------------- mismatch
def test_monte_carlo_without_mismatch_reproduces_the_design():
    d = _design()
    r = mismatch_monte_carlo(d, sigma=0.0, n_trials=2)
    assert np.all(r.errors == 0.0) and r.reference == "nominal" and r.yield_fraction == 1.0
    # the nominal finite-grid kernel matches the infinite lattice within the truncation rule
    assert r.half_width >= 3 + 3 + 7


def test_monte_carlo_error_scales_with_sigma_and_yield_with_tolerance():
    d = _design()
    small = mismatch_monte_carlo(d, sigma=0.005, n_trials=40, seed=3)
    big = mismatch_monte_carlo(d, sigma=0.02, n_trials=40, seed=3)
    # same random draws, 4x sigma: errors 4x (first-order regime)
    assert np.median(big.errors) / np.median(small.errors) == pytest.approx(4.0, rel=0.05)
    tight = mismatch_monte_carlo(d, sigma=0.02, n_trials=40, seed=3, tolerance=float(np.median(big.errors)))
    assert 0.4 <= tight.yield_fraction <= 0.6
    assert big.summary()["p95"] >= big.summary()["median"]


def test_monte_carlo_local_mismatch_is_below_the_die_level_bound():
    from fsdvs_hw.realise.mesh import mismatch_sensitivity

    d = _design()
    r = mismatch_monte_carlo(d, sigma=0.01, n_trials=30, seed=1)
    # independent per-element errors partly average out: rms error below σ·S (all-correlated bound)
    rms = float(np.sqrt(np.mean(r.errors_vs_nominal**2)))
    assert 0.0 < rms < 0.01 * mismatch_sensitivity(d)


@pytest.mark.parametrize("lam_n, lam_w", [(1e-3, 1e-2), (1e2, 1e3)])
def test_monte_carlo_at_extreme_conductance_ratios(lam_n, lam_w):
    d = MeshDesign.from_space_constants(lam_n, lam_w, 1.0, 0.5, size=5)
    r = mismatch_monte_carlo(d, sigma=0.01, n_trials=2, half_width=20)
    assert np.all(np.isfinite(r.errors))


def test_monte_carlo_bad_input():
    d = _design()
    with pytest.raises(InputError, match="sigma"):
        mismatch_monte_carlo(d, sigma=-0.1)
    with pytest.raises(InputError, match="n_trials"):
        mismatch_monte_carlo(d, n_trials=0)
    with pytest.raises(InputError, match="half_width"):
        mismatch_monte_carlo(d, half_width=1)
    assert math.isfinite(mismatch_monte_carlo(d, n_trials=1).errors[0])


def test_step_response_settles_with_tau_equals_c_over_gv():
    from fsdvs_hw.realise.mesh.dynamics import mesh_step_response
    from fsdvs_hw.realise.mesh.response import finite_grid_response

    g_l, g_v, c, h = 1e-8, 1e-8 / 2.5**2, 100e-15, 8
    tau = c / g_v
    t = np.array([0.0, 1e-6 * tau, 0.3 * tau, tau, 3 * tau, 60 * tau])
    v = mesh_step_response(g_l, g_v, c, h, t)
    # the total charge obeys the uniform mode exactly: Σ g_v V = 1 - exp(-t/τ)
    assert np.allclose(v.sum(axis=(1, 2)) * g_v, -np.expm1(-t / tau), rtol=1e-10, atol=1e-15)
    # at first all current charges the centre capacitor: V_c ≈ t / C
    assert v[1, h, h] == pytest.approx(t[1] / c, rel=1e-4)
    # and in the end the node voltages are the static response
    assert np.allclose(v[-1] * g_v, finite_grid_response(2.5, h, h), rtol=1e-12, atol=1e-15)
    with pytest.raises(InputError, match="node_capacitance_f"):
        mesh_step_response(g_l, g_v, 0.0, h, t)
    with pytest.raises(InputError, match="t_s"):
        mesh_step_response(g_l, g_v, c, h, [-1.0])
