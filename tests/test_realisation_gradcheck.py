"""Float64 ``torch.autograd.gradcheck`` through each differentiable realisation (issue 16, "Must show").

Each realisation's kernel is a torch function of its physical parameters
(:meth:`fsdvs_hw.realise.registry.RealisationSpec.differentiable_kernel`); here its analytical
gradients are checked against float64 finite differences by torch's own ``gradcheck`` on the fitted
design of the shipped learned kernel. The ASIC rounds its coefficients (straight-through by design,
so not a finite-difference gradient: ``test_asic_differentiable`` checks it against its definition);
its gradcheck runs through the continuous scale with the integer coefficients as they are.
"""

from __future__ import annotations

from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from fsdvs_hw.kernels import load_kernel
from fsdvs_hw.realise.registry import fit_realisation, get_realisation

LEARNED = Path(__file__).resolve().parents[1] / "designs" / "kernels" / "learned_detection_7x7.json"


def _as_function(module, names):
    """The module's kernel as a function of the named parameters (all others fixed)."""
    from torch.func import functional_call

    def f(*values):
        return functional_call(module, dict(zip(names, values)), ())

    return f


@pytest.fixture(scope="module")
def target():
    return load_kernel(LEARNED)


@pytest.mark.parametrize(
    "name, options, params",
    [
        ("mesh", {}, None),  # every parameter: λ narrow/wide, gain, DC
        ("asic", {"bits": 8, "scale": "free"}, ["scale_param"]),  # continuous scale (rounding: straight-through)
    ],
)
def test_gradcheck_float64(name, options, params, target):
    module = get_realisation(name).differentiable_kernel(fit_realisation(name, target, options))
    named = dict(module.named_parameters())
    names = params or list(named)
    inputs = tuple(named[n].detach().clone().double().requires_grad_(True) for n in names)
    assert all(x.dtype == torch.float64 for x in inputs)
    assert torch.autograd.gradcheck(_as_function(module, names), inputs, eps=1e-6, atol=1e-6, rtol=1e-4, fast_mode=True)


@pytest.mark.slow
def test_gradcheck_float64_metalens(target):
    """Phase coefficients, defocus and gains of the fitted metalens (a PSF per evaluation: slow)."""
    module = get_realisation("metalens").differentiable_kernel(fit_realisation("metalens", target))
    named = dict(module.named_parameters())
    names = list(named)
    inputs = tuple(named[n].detach().clone().requires_grad_(True) for n in names)
    assert torch.autograd.gradcheck(_as_function(module, names), inputs, eps=1e-6, atol=1e-6, rtol=1e-4, fast_mode=True)


def test_gradcheck_catches_a_wrong_gradient(target):
    """The check has teeth: a kernel whose backward is off by 10 % fails it."""
    module = get_realisation("asic").differentiable_kernel(fit_realisation("asic", target, {"bits": 8}))
    inputs = (module.scale_param.detach().clone().requires_grad_(True),)
    f = _as_function(module, ["scale_param"])

    class Scaled(torch.autograd.Function):
        @staticmethod
        def forward(ctx, x):
            return x.clone()

        @staticmethod
        def backward(ctx, g):
            return 1.1 * g

    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)
    assert not torch.autograd.gradcheck(
        lambda *v: Scaled.apply(f(*v)), inputs, eps=1e-6, atol=1e-6, rtol=1e-4, raise_exception=False
    )
