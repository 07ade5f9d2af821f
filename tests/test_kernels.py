"""Kernel container, reference families, file formats and validation errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fsdvs_hw.errors import KernelError
from fsdvs_hw.kernels import (
    DEFAULT_PITCH_M,
    REFERENCE_KERNELS,
    Kernel,
    load_kernel,
    reference_kernel,
)


class PickledObject:
    """An arbitrary class instance: safe loading must refuse to unpickle it."""


def test_taps_are_readonly_float64_copy():
    src = np.eye(3, dtype=np.int32)
    k = Kernel(src)
    assert k.taps.dtype == np.float64
    src[0, 0] = 7
    assert k.taps[0, 0] == 1.0
    with pytest.raises(ValueError):
        k.taps[0, 0] = 2.0


@pytest.mark.parametrize(
    "taps, fragment",
    [
        (np.ones(3), "2-D"),
        (np.ones((3, 3, 1)), "2-D"),
        (np.ones((3, 5)), "square"),
        (np.ones((4, 4)), "odd"),
        (np.full((3, 3), np.nan), "NaN/inf"),
        (np.array([[0, 0, 0], [0, np.inf, 0], [0, 0, 0]]), "row 1, column 1"),
        (np.zeros((5, 5)), "all zeros"),
        (np.ones((65, 65)), "absurd"),
        (np.ones((3, 3)) * 1j, "real"),
        ([["a", "b", "c"]] * 3, "numeric"),
    ],
)
def test_bad_taps_raise_named_errors(taps, fragment):
    with pytest.raises(KernelError, match=fragment):
        Kernel(taps)


@pytest.mark.parametrize("pitch", [0.0, -1e-6, 5.0, float("nan"), "abc", 4.86])
def test_bad_pitch_raises(pitch):
    with pytest.raises(KernelError, match="pitch"):
        Kernel(np.ones((3, 3)), pitch_m=pitch)


def test_reference_families_formulas():
    d = reference_kernel("delta", 5).taps
    assert d[2, 2] == 1 and d.sum() == 1
    g = reference_kernel("gaussian", 7, sigma_px=1.3).taps
    assert g.sum() == pytest.approx(1.0, abs=1e-15)
    # ratio of neighbouring taps follows exp(-(x^2+y^2)/(2 sigma^2))
    assert g[3, 4] / g[3, 3] == pytest.approx(np.exp(-1 / (2 * 1.3**2)), rel=1e-12)
    dog = reference_kernel("dog", 7, sigma_centre_px=0.7, sigma_surround_px=2.0, w_centre=1.0, w_surround=0.8)
    assert dog.dc_gain == pytest.approx(0.2, abs=1e-12)
    assert dog.centre > 0 and dog.taps[0, 3] < 0  # centre-surround
    balanced = reference_kernel("dog", 9, w_surround=1.0)
    assert abs(balanced.dc_gain) < 1e-12
    log = reference_kernel("log", 9, sigma_px=1.2)
    assert abs(log.dc_gain) < 1e-12 and log.centre == pytest.approx(1.0)
    assert set(REFERENCE_KERNELS) == {"delta", "gaussian", "dog", "log"}


@pytest.mark.parametrize("name", sorted(REFERENCE_KERNELS))
def test_reference_kernels_are_8fold_symmetric(name):
    assert reference_kernel(name, 7).asymmetry() < 1e-14


def test_reference_kernel_errors():
    with pytest.raises(KernelError, match="unknown"):
        reference_kernel("mexican", 7)
    with pytest.raises(KernelError, match="odd"):
        reference_kernel("dog", 6)
    with pytest.raises(KernelError, match="sigma_surround_px"):
        reference_kernel("dog", 7, sigma_centre_px=2.0, sigma_surround_px=1.0)
    with pytest.raises(KernelError, match="sigma_px"):
        reference_kernel("gaussian", 7, sigma_px=-1)
    with pytest.raises(KernelError, match="bad parameters"):
        reference_kernel("gaussian", 7, width=3)


@pytest.mark.parametrize("ext", ["npy", "csv", "json", "pt"])
def test_roundtrip_every_format(tmp_path, ext, rng):
    k = Kernel(rng.normal(size=(7, 7)), pitch_m=3.0e-6, name="learned", provenance={"seed": 3})
    path = k.save(tmp_path / f"k.{ext}")
    back = load_kernel(path)
    assert np.array_equal(back.taps, k.taps)  # bit-exact
    if ext != "npy":  # .npy carries taps only
        assert back.pitch_m == 3.0e-6 and back.name == "learned" and back.provenance["seed"] == 3
    else:
        assert back.pitch_m == DEFAULT_PITCH_M
    assert load_kernel(path, pitch_m=2e-6).pitch_m == 2e-6


def test_pt_accepts_conv_weight_and_refuses_pickled_objects(tmp_path):
    import torch

    w = torch.zeros(1, 1, 5, 5, dtype=torch.float32)
    w[0, 0, 2, 2] = 1.0
    torch.save({"weight": w}, tmp_path / "conv.pt")
    assert load_kernel(tmp_path / "conv.pt").taps[2, 2] == 1.0

    torch.save({"taps": torch.ones(3, 3), "obj": PickledObject()}, tmp_path / "evil.pt")
    with pytest.raises(KernelError, match="weights_only"):
        load_kernel(tmp_path / "evil.pt")


def test_file_errors_name_the_file(tmp_path):
    with pytest.raises(KernelError, match="not found"):
        load_kernel(tmp_path / "missing.npy")
    (tmp_path / "k.txt").write_text("1")
    with pytest.raises(KernelError, match=r"k\.txt.*extension"):
        load_kernel(tmp_path / "k.txt")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(KernelError, match=r"bad\.json: invalid JSON"):
        load_kernel(tmp_path / "bad.json")
    (tmp_path / "even.json").write_text(json.dumps({"taps": [[1, 2], [3, 4]]}))
    with pytest.raises(KernelError, match=r"even\.json.*odd"):
        load_kernel(tmp_path / "even.json")
    (tmp_path / "bad.csv").write_text("1,2,x\n")
    with pytest.raises(KernelError, match=r"bad\.csv"):
        load_kernel(tmp_path / "bad.csv")
    np.save(tmp_path / "obj.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(KernelError, match="obj.npy"):
        load_kernel(tmp_path / "obj.npy")


def test_normalisation_modes_and_derived_kernels():
    k = reference_kernel("dog", 7)
    assert np.abs(k.normalised("peak").taps).max() == pytest.approx(1.0)
    assert k.normalised("sum").dc_gain == pytest.approx(1.0)
    assert np.linalg.norm(k.normalised("l2").taps) == pytest.approx(1.0)
    assert k.normalised("centre").centre == pytest.approx(1.0)
    with pytest.raises(KernelError, match="zero DC"):
        reference_kernel("log", 7).normalised("sum")
    p = k.padded(11)
    assert p.size == 11 and p.cropped(7).allclose(k)
    with pytest.raises(KernelError):
        k.padded(8)
    with pytest.raises(KernelError, match="non-zero"):
        k.scaled(0.0)


def test_shipped_demo_kernel_loads():
    from pathlib import Path

    k = load_kernel(Path(__file__).parents[1] / "designs" / "kernels" / "dog_7x7.json")
    assert k.size == 7 and k.provenance.get("reference") == "dog"


def test_as_kernel_and_numpy_conversion_accept_what_users_hold(tmp_path):
    """np.asarray(kernel) is the tap array (it was an empty object array); as_kernel takes a Kernel,
    a path, a tensor or a nested list; analyse_kernel accepts a plain array (it raised AttributeError)."""
    import numpy as np

    from fsdvs_hw import analyse_kernel
    from fsdvs_hw.errors import KernelError
    from fsdvs_hw.kernels import as_kernel, reference_kernel

    k = reference_kernel("dog", 7)
    a = np.asarray(k)
    assert a.shape == (7, 7) and a.dtype == np.float64 and np.array_equal(a, k.taps)
    a[3, 3] = 99.0  # a copy: the kernel is not changed through it
    assert k.centre != 99.0
    assert as_kernel(k) is k
    assert as_kernel(k.taps.tolist(), name="mine").allclose(k.with_taps(k.taps))
    path = k.save(tmp_path / "k.json")
    assert as_kernel(path).allclose(k)
    torch = pytest.importorskip("torch")
    assert as_kernel(torch.tensor(np.asarray(k))).allclose(k)
    via_array = analyse_kernel(np.asarray(k))
    via_kernel = analyse_kernel(k)
    assert via_array.summary == via_kernel.summary
    with pytest.raises(KernelError, match="odd"):
        as_kernel(np.ones((2, 2)))
    with pytest.raises(KernelError, match="expected a Kernel, a kernel file path or a k×k array"):
        as_kernel({"taps": 1})
    with pytest.raises(KernelError, match="pitch"):
        as_kernel(k, pitch_m=1e-6)
