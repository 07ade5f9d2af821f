"""The metalens kernel as a differentiable function of its phase, distance and gains (co-design,
issue 16): it reproduces the fitted design's PSFs and kernel, gradients reach every parameter,
and the NA penalty agrees with the fit's own local-NA measure."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from fsdvs_hw.errors import InputError  # noqa: E402
from fsdvs_hw.kernels import reference_kernel  # noqa: E402
from fsdvs_hw.realise.metalens import fit_metalens, local_numerical_aperture  # noqa: E402
from fsdvs_hw.realise.metalens.differentiable import MetalensKernel  # noqa: E402


@pytest.fixture(scope="module")
def design():
    return fit_metalens(reference_kernel("dog", 5), n_wavelengths=3, max_iter=20, n_starts=1)


def test_it_reproduces_the_fitted_psfs_and_kernel(design):
    mk = MetalensKernel(design)
    for p, ref in zip(mk.psfs(), design.psfs):
        np.testing.assert_allclose(p.detach().numpy(), ref, rtol=0, atol=1e-12 * float(np.abs(ref).max()))
    np.testing.assert_allclose(mk().detach().numpy(), design.kernel().taps, rtol=1e-10, atol=1e-14)
    back = mk.to_design()
    assert back.fit_info["codesigned"] and back.kernel().allclose(design.kernel(), rtol=1e-10, atol=1e-14)


def test_a_differential_pair_is_reproduced_lens_by_lens():
    """g₊P₊ − g₋P₋: each lens's PSF and gain enter with its own sign (a swapped index would not)."""
    pair = fit_metalens(reference_kernel("dog", 5), strategy="differential", n_wavelengths=3, max_iter=15, n_starts=1)
    mk = MetalensKernel(pair)
    assert len(mk.psfs()) == 2
    np.testing.assert_allclose(
        mk().detach().numpy(), pair.kernel().taps, rtol=1e-10, atol=1e-12 * float(np.abs(pair.kernel().taps).max())
    )


def test_gradients_reach_phase_distance_and_gain(design):
    mk = MetalensKernel(design)
    w = torch.as_tensor(np.random.default_rng(0).normal(size=tuple(design.kernel().taps.shape)))
    (mk() * w).sum().backward()
    assert all(float(c.grad.abs().sum()) > 0 for c in mk.coefficients)
    assert bool((mk.defocus_um.grad.abs() > 0).all())
    # d/d(log g) of g·P·w is exactly g·P·w summed (pedestal: one lens)
    assert float(mk.log_gains.grad[0]) == pytest.approx(float((mk().detach() * w).sum()), rel=1e-10)
    # finite difference in the sensor distance (1 nm = 1e-3 µm)
    d = mk.defocus_um
    with torch.no_grad():
        d[0] += 1e-3
        up = float((mk() * w).sum())
        d[0] -= 2e-3
        down = float((mk() * w).sum())
        d[0] += 1e-3
    assert float(d.grad[0]) == pytest.approx((up - down) / 2e-3, rel=1e-4)
    assert float(mk.distance_m()[0]) == pytest.approx(design.sensor_distance_m[0], rel=1e-12)


def test_local_na_matches_the_fit_and_the_penalty_is_zero_when_buildable(design):
    mk = MetalensKernel(design)
    ref = local_numerical_aperture(design.geometry, design.coefficients[0], design.spectral.wavelengths_m)
    assert float(mk.local_na().detach()) == pytest.approx(ref, rel=1e-3)  # finite differences on the pupil radii
    assert float(mk.local_na().detach()) < mk.na_budget and float(mk.na_excess().detach()) == 0.0  # buildable
    with torch.no_grad():  # a strongly curved extra phase exceeds the NA budget: positive, differentiable penalty
        mk.coefficients[0][0] += 400.0
    pen = mk.na_excess()
    assert float(pen.detach()) > 0
    pen.backward()
    assert float(mk.coefficients[0].grad.abs().sum()) > 0


def test_bad_input_is_named():
    with pytest.raises(InputError, match="expected a MetalensDesign"):
        MetalensKernel(reference_kernel("dog", 5))
