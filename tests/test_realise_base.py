"""The realisation protocol shared by mesh, ASIC and metalens designs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import Kernel, reference_kernel
from fsdvs_hw.realise import (
    CostItem,
    Realisation,
    ReferenceRealisation,
    kernel_error,
    realisation_from_dict,
)


def test_kernel_error_definition():
    t = reference_kernel("dog", 7)
    assert kernel_error(t, t) == 0.0
    assert kernel_error(t.scaled(1.1), t) == pytest.approx(0.1, rel=1e-12)
    # with a free scale, a scaled copy is a perfect fit
    assert kernel_error(t.scaled(3.0), t, fit_scale=True) == pytest.approx(0.0, abs=1e-14)
    # different sizes are compared after centred zero padding
    assert kernel_error(t.padded(11), t) == pytest.approx(0.0, abs=1e-15)
    d = reference_kernel("delta", 3)
    expected = np.linalg.norm(d.padded(7).taps - t.taps) / np.linalg.norm(t.taps)
    assert kernel_error(d, t) == pytest.approx(expected, rel=1e-12)


def test_reference_realisation_roundtrip():
    r = ReferenceRealisation(reference_kernel("log", 5), label="learned")
    assert isinstance(r, Realisation)
    d = json.loads(json.dumps(r.to_dict()))
    back = realisation_from_dict(d)
    assert isinstance(back, ReferenceRealisation) and back.label == "learned"
    assert back.kernel().allclose(r.kernel(), rtol=0)
    assert r.cost() == {} and "learned" in r.describe()


def test_unknown_kind_is_a_clear_error():
    with pytest.raises(InputError, match="kind"):
        realisation_from_dict({"kind": "fpga"})
    with pytest.raises(InputError, match="all zeros"):
        kernel_error(Kernel(np.eye(3)), np.zeros((3, 3)))


def test_cost_item_to_dict():
    assert CostItem(1e-9, "S", "lateral conductance").to_dict() == {
        "value": 1e-9,
        "unit": "S",
        "description": "lateral conductance",
    }
