"""The mesh kernel as a differentiable function of its circuit parameters (co-design, issue 16):
it equals the fitted design's response, its gradients match finite differences, and any parameter
values stay inside the bounds with a non-negative whole-circuit DC gain."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from fsdvs_hw.errors import InputError  # noqa: E402
from fsdvs_hw.kernels import load_kernel  # noqa: E402
from fsdvs_hw.realise.mesh import MeshBounds, MeshDesign, fit_resistive_mesh  # noqa: E402
from fsdvs_hw.realise.mesh.differentiable import MeshKernel  # noqa: E402

LEARNED = Path(__file__).resolve().parents[1] / "designs" / "kernels" / "learned_detection_7x7.json"


@pytest.fixture(scope="module")
def design():
    return fit_resistive_mesh(load_kernel(LEARNED))


def test_it_equals_the_fitted_response(design):
    for size in (None, 7):
        mk = MeshKernel(design, size=size)
        np.testing.assert_allclose(mk().detach().numpy(), design.kernel_taps(mk.size), rtol=0, atol=1e-10)
    back = MeshKernel(design).to_design()
    assert back.lambda_narrow_px == pytest.approx(design.lambda_narrow_px, rel=1e-9)
    assert back.gain_wide == pytest.approx(design.gain_wide, rel=1e-9) and back.fit["codesigned"]


def test_gradients_match_central_differences(design):
    mk = MeshKernel(design, size=9)
    w = torch.as_tensor(np.random.default_rng(0).normal(size=(9, 9)))
    (mk() * w).sum().backward()
    for p in (mk.u_narrow, mk.u_wide, mk.u_gain, mk.u_dc):
        g = float(p.grad)
        with torch.no_grad():
            h = 1e-6
            p += h
            up = float((mk() * w).sum())
            p -= 2 * h
            down = float((mk() * w).sum())
            p += h
        assert g == pytest.approx((up - down) / (2 * h), rel=1e-5, abs=1e-9)


def test_any_parameters_stay_in_bounds_with_dc_gain_at_least_zero(design):
    mk = MeshKernel(design, size=7)
    b = MeshBounds()
    rng = np.random.default_rng(1)
    with torch.no_grad():
        for _ in range(50):
            for p in (mk.u_narrow, mk.u_wide, mk.u_gain, mk.u_dc):
                p.fill_(float(rng.normal(0, 8)))  # far into the sigmoids' tails
            ln, lw = (float(v) for v in mk.lambdas())
            a, bb = (float(v) for v in mk.gains())
            assert b.lambda_px[0] <= ln <= b.lambda_px[1] and ln * b.min_lambda_ratio <= lw <= b.lambda_px[1] + 1e-9
            assert b.gain[0] <= a <= b.gain[1] and float(mk.pixel_weight) + a - bb >= -1e-12
            assert np.isfinite(mk().numpy()).all()


def test_bad_input_is_named(design):
    with pytest.raises(InputError, match="expected a MeshDesign"):
        MeshKernel(load_kernel(LEARNED))
    with pytest.raises(InputError, match="size must be a positive odd"):
        MeshKernel(design, size=8)
    assert isinstance(design, MeshDesign)
