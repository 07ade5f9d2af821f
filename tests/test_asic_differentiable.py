"""The ASIC kernel as a differentiable function of its parameters (co-design, issue 16): it equals
the fitted design's kernel, its gradients are the straight-through ones, and a moved design stays a
valid integer design whose RTL model is the same."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from fsdvs_hw.errors import InputError  # noqa: E402
from fsdvs_hw.kernels import load_kernel, reference_kernel  # noqa: E402
from fsdvs_hw.realise.asic import fit_asic_taps  # noqa: E402
from fsdvs_hw.realise.asic.differentiable import QuantisedAsicKernel  # noqa: E402
from pathlib import Path  # noqa: E402

LEARNED = Path(__file__).resolve().parents[1] / "designs" / "kernels" / "learned_detection_7x7.json"


@pytest.mark.parametrize("scale_mode, bits", [("free", 8), ("pow2", 6), ("free", 3)])
def test_it_equals_the_fitted_kernel(scale_mode, bits):
    design = fit_asic_taps(load_kernel(LEARNED), bits=bits, scale=scale_mode)
    k = QuantisedAsicKernel(design)
    np.testing.assert_allclose(k().detach().numpy(), design.kernel().taps, rtol=0, atol=1e-12)
    assert k.to_design().kernel().allclose(design.kernel(), atol=1e-15)


def test_gradients_are_straight_through_inside_the_range_and_zero_where_clamped():
    design = fit_asic_taps(reference_kernel("dog", 7), bits=4, scale="free", symmetry="8-fold")
    k = QuantisedAsicKernel(design)
    w = torch.as_tensor(np.random.default_rng(0).normal(size=(7, 7)))
    (k() * w).sum().backward()
    labels = design.classes.labels
    s = design.scale
    expected = s * np.bincount(labels.ravel(), weights=w.numpy().ravel())  # d/dθ_c = s Σ_{class c} w
    q = k.latent.detach().numpy()
    inside = (q > k.qmin) & (q < k.qmax)
    np.testing.assert_allclose(k.latent.grad.numpy()[inside], expected[inside], rtol=1e-12)
    # d/d(log s) = Σ K w
    assert float(k.scale_param.grad) == pytest.approx(float((k().detach() * w).sum()), rel=1e-12)
    with torch.no_grad():  # push one coefficient past the top of the range: its gradient is 0
        k.latent[0] = k.qmax + 3
    k.latent.grad = None
    (k() * w).sum().backward()
    assert float(k.latent.grad[0]) == 0.0 and int(k.integer_coefficients()[0]) == int(k.qmax)


def test_a_moved_design_stays_a_valid_integer_design_with_the_same_integer_model():
    design = fit_asic_taps(reference_kernel("dog", 7), bits=6, scale="pow2")
    k = QuantisedAsicKernel(design)
    opt = torch.optim.Adam(k.parameters(), lr=0.5)  # about half an integer step per update
    target = torch.tensor(np.asarray(reference_kernel("dog", 7, sigma_centre_px=1.0, w_surround=0.6)))
    for _ in range(20):
        opt.zero_grad()
        ((k() - target) ** 2).sum().backward()
        opt.step()
    moved = k.to_design(steps=20)
    assert not np.array_equal(moved.taps, design.taps) and moved.fit_info["codesigned"]
    np.testing.assert_allclose(moved.kernel().taps, k().detach().numpy(), rtol=0, atol=1e-15)
    lo, hi = -(2**5), 2**5 - 1
    assert moved.taps.min() >= lo and moved.taps.max() <= hi and moved.scale == 2.0 ** round(np.log2(moved.scale))
    img = np.random.default_rng(1).integers(0, 256, size=(12, 12))
    out = moved.apply(img)  # the integer model the RTL is checked against (tests/test_asic_rtl.py)
    direct = np.array([[np.sum(moved.taps * img[y : y + 7, x : x + 7]) for x in range(6)] for y in range(6)])  # valid
    np.testing.assert_array_equal(np.asarray(out).reshape(direct.shape), direct)


def test_bad_input_is_named():
    with pytest.raises(InputError, match="expected an AsicDesign"):
        QuantisedAsicKernel(reference_kernel("dog", 7))
