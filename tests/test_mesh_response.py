"""Single resistive mesh: lattice Green's function, finite grid, continuum law, casadi KCL model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.realise.mesh.response import (
    casadi_mesh_model,
    continuum_response,
    finite_grid_response,
    grid_half_width_for,
    lattice_green_function,
    lattice_green_quarter,
    mesh_kcl_matrix,
    space_constant_px,
)


@pytest.mark.parametrize("lam", [0.3, 1.0, 2.5])
def test_green_function_equals_large_finite_grid(lam):
    # independent reference: exact DCT solve on a grid so large that the edge is invisible
    g = lattice_green_function(lam, 4)
    ref = finite_grid_response(lam, 4, 70)
    assert np.abs(g - ref).max() < 1e-13 * g.max() + 1e-16


@pytest.mark.parametrize("lam", [0.5, 1.5, 3.0])
def test_unit_sum_and_second_moment(lam):
    r = int(12 + 25 * lam)
    h = lattice_green_function(lam, r)
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    assert h.sum() == pytest.approx(1.0, abs=1e-9)
    assert (x * x * h).sum() == pytest.approx(2 * lam * lam, rel=1e-6)  # per-axis second moment 2λ²
    assert h.min() > -1e-15 and h[r, r] == h.max()  # positive up to quadrature rounding (~1e-17 absolute)


def test_large_lambda_centre_value_matches_asymptotic_lattice_law():
    # square-lattice Green's function of (L + m²) at the origin: (1/4π) ln(32/m²) + O(m² ln m), m = 1/λ
    errs = []
    for lam in (1e2, 1e3):
        h0 = lattice_green_function(lam, 0)[0, 0]
        errs.append(abs(lam * lam * h0 / (math.log(32 * lam * lam) / (4 * math.pi)) - 1))
    assert errs[0] < 2e-5 and errs[1] < 3e-7
    assert errs[1] < errs[0] / 50  # the correction vanishes like 1/λ² (times a log)


def test_tiny_lambda_is_a_delta():
    h = lattice_green_function(1e-3, 2)
    eps = 1e-6  # λ²: (1 + εL)^-1 = 1 - εL + ε²L² - ..., (L²)_00 = 20, (L²)_01 = -8
    assert h[2, 2] == pytest.approx(1 - 4 * eps + 20 * eps**2, rel=1e-14)
    assert h[2, 3] == pytest.approx(eps - 8 * eps**2, rel=1e-9)


def test_k0_law_away_from_centre_with_lambda_from_conductances():
    errs = {}
    for lam in (4.0, 8.0):
        g_l = 2e-8
        g_v = g_l / lam**2
        lam_c = space_constant_px(g_l, g_v)
        assert lam_c == pytest.approx(lam, rel=1e-14)
        r = int(4 * lam + 1)
        h = lattice_green_function(lam_c, r)
        y, x = np.mgrid[-r : r + 1, -r : r + 1]
        rr = np.hypot(x, y)
        far = (rr >= 2 * lam) & (rr <= 4 * lam)
        errs[lam] = np.abs(h[far] / continuum_response(lam_c, rr[far]) - 1).max()
    assert errs[4.0] < 0.015 and errs[8.0] < 0.004
    # lattice corrections fall as 1/λ²
    assert 3.0 < errs[4.0] / errs[8.0] < 5.0
    # ... while near the centre a small-λ mesh is far from K0 (the lattice function is the reference)
    h = lattice_green_function(1.0, 3)
    y, x = np.mgrid[-3:4, -3:4]
    rr = np.hypot(x, y)
    ring = rr > 0
    assert np.abs(h[ring] / continuum_response(1.0, rr[ring]) - 1).max() > 0.07


def test_derivative_matches_finite_difference():
    lam, eps = 1.7, 1e-6
    _, dq = lattice_green_quarter(lam, 3, derivative=True)
    up = lattice_green_quarter(math.sqrt(lam**2 + eps), 3)
    dn = lattice_green_quarter(math.sqrt(lam**2 - eps), 3)
    assert np.allclose(dq, (up - dn) / (2 * eps), rtol=1e-6, atol=1e-12)
    assert np.all(dq[0, 0] < 0)  # a wider mesh lowers the centre


def test_dct_equals_sparse_and_truncation_rule():
    for lam in (0.5, 2.0):
        h = grid_half_width_for(lam, 3)
        d = finite_grid_response(lam, 3, h)
        s = finite_grid_response(lam, 3, h, method="sparse")
        assert np.abs(d - s).max() < 1e-14
        inf = lattice_green_function(lam, 3)
        assert np.abs(d - inf).max() / np.abs(inf).max() < 1e-3
    # truncation error shrinks as the grid grows
    errs = [np.abs(finite_grid_response(2.0, 3, h) - lattice_green_function(2.0, 3)).max() for h in (4, 8, 16)]
    assert errs[0] > errs[1] > errs[2]


@pytest.mark.parametrize("ratio", [1e-6, 1e-3, 1.0, 1e3, 1e6])
def test_extreme_conductance_ratios_are_finite(ratio):
    g_v = 1e-9
    lam = space_constant_px(ratio * g_v, g_v)
    for h in (
        lattice_green_function(lam, 3),
        finite_grid_response(lam, 3, 10),
        finite_grid_response(lam, 3, 10, method="sparse"),
    ):
        # finite and non-negative up to rounding (the DCT form has ~1e-16 absolute rounding)
        assert np.all(np.isfinite(h)) and h.min() > -1e-14 and h[3, 3] == h.max()
    assert lattice_green_function(lam, 3).sum() <= 1.0 + 1e-12
    # a finite grid holds all the current: its response sums to exactly 1
    assert finite_grid_response(lam, 10, 10).sum() == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize(
    "args",
    [(0.0, 1e-9), (-1e-9, 1e-9), (float("nan"), 1e-9), (1e-9, float("inf")), (1e-9, 1e-27)],
)
def test_bad_conductances_raise(args):
    with pytest.raises(InputError, match="g_|conductance|sqrt"):
        space_constant_px(*args)


def test_bad_arguments_raise():
    with pytest.raises(InputError, match="lambda_px"):
        lattice_green_function(1e5, 3)
    with pytest.raises(InputError, match="radius"):
        lattice_green_function(1.0, -1)
    with pytest.raises(InputError, match="exceeds"):
        finite_grid_response(1.0, 5, 3)
    with pytest.raises(InputError, match="method"):
        finite_grid_response(1.0, 1, 3, method="fft")
    with pytest.raises(InputError, match="r_px"):
        continuum_response(1.0, [0.0, 1.0])


def test_casadi_kcl_model_matches_scipy_and_its_gradients_obey_the_sensitivity_theorem():
    import casadi as ca
    import scipy.sparse.linalg as spla

    h, n = 3, 7
    rng = np.random.default_rng(0)
    ne = 2 * n * (n - 1)
    g_e = 1e-8 * np.exp(0.2 * rng.standard_normal(ne))
    g_v = 3e-9 * np.exp(0.2 * rng.standard_normal(n * n))
    i_in = np.zeros(n * n)
    c = h * n + h
    i_in[c] = 1e-9
    f = casadi_mesh_model(h, per_element=True)
    v = np.array(f(g_e, g_v, i_in)).ravel()
    v_ref = spla.spsolve(mesh_kcl_matrix(h, g_e, g_v), i_in)
    assert np.abs(v - v_ref).max() < 1e-12 * np.abs(v_ref).max()
    # dV_c/dg_e = -(V_a - V_b)^2 / I for a current I injected at c (Tellegen / adjoint network)
    gl = ca.MX.sym("gl", ne)
    jac = ca.Function("j", [gl], [ca.jacobian(f(gl, g_v, i_in)[c], gl)])
    d = np.array(jac(g_e)).ravel()
    idx = np.arange(n * n).reshape(n, n)
    a = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    b = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    expected = -((v_ref[a] - v_ref[b]) ** 2) / 1e-9
    assert np.allclose(d, expected, rtol=1e-8, atol=1e-12 * np.abs(expected).max())
    # the uniform model equals the per-element one with equal conductances
    fu = casadi_mesh_model(h)
    vu = np.array(fu(1e-8, 3e-9, i_in)).ravel()
    vp = np.array(f(np.full(ne, 1e-8), np.full(n * n, 3e-9), i_in)).ravel()
    assert np.abs(vu - vp).max() < 1e-14 * np.abs(vp).max()
    assert np.allclose(vu * 3e-9 / 1e-9, finite_grid_response(math.sqrt(1e-8 / 3e-9), h, h).ravel(), rtol=1e-12)
