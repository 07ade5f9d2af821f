"""Kernel learning and kernel evaluation on tiny settings (seconds, not minutes)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from fsdvs_hw.errors import InputError, KernelError
from fsdvs_hw.kernels import Kernel, load_kernel, reference_kernel
from fsdvs_hw.scenes.synthetic import SceneConfig
from fsdvs_hw.tasks.checkpoints import load_checkpoint
from fsdvs_hw.tasks.evaluators import EVALUATORS, DetectionEvaluator, get_evaluator, register_evaluator
from fsdvs_hw.tasks.learn import TrainingSettings, evaluate_kernel, learn_kernel

TINY = TrainingSettings(epochs_frozen=2, epochs_joint=3, batch_size=16, width=8, lr_filter=2e-2)
TINY_SCENE = {
    "detection": SceneConfig(height_px=16, width_px=16, radius_px=(3.0, 4.0), n_frames=4, n_objects=(1, 1)),
    "recognition": SceneConfig(
        height_px=16, width_px=16, radius_px=(3.0, 4.0), n_frames=4, motion="classes", edge_contrast=0.3
    ),
    "segmentation": SceneConfig(height_px=16, width_px=16, radius_px=(3.0, 4.0), n_frames=4, n_objects=(1, 1)),
}
SHIPPED = Path(__file__).resolve().parents[1] / "designs" / "kernels"


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """One tiny recognition run and one tiny detection run, saved to disk."""
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("ckpt")
    runs = {}
    for task in ("recognition", "detection"):
        runs[task] = learn_kernel(
            task, 5, seed=1, n_train=32, n_test=16, settings=TINY, scene=TINY_SCENE[task], out=out / f"{task}_5x5"
        )
    return runs


def test_training_reduces_the_loss(trained):
    for res in trained.values():
        losses = [h["loss"] for h in res.history]
        assert losses[-1] < losses[0], res.history


def test_protocol_stages(trained):
    det = [h["stage"] for h in trained["detection"].history]
    rec = [h["stage"] for h in trained["recognition"].history]
    assert det == ["frozen_filter"] * 2 + ["joint"] * 3  # the paper's two-stage detection protocol
    # recognition: the paper fine-tunes a pretrained network jointly; the frozen stage is the pretraining
    assert rec == ["frozen_filter"] * 2 + ["joint"] * 3
    # the paper's joint-phase rates: detection 5e-4 / 1e-6 / 1e-5, recognition 5e-4 / 5e-5 / 1e-4
    lrs = trained["detection"].provenance["learning_rates_joint"]
    assert lrs["filter"] / lrs["backbone"] == pytest.approx(500) and lrs["filter"] / lrs["head"] == pytest.approx(50)
    lrs = trained["recognition"].provenance["learning_rates_joint"]
    assert lrs["filter"] / lrs["backbone"] == pytest.approx(10) and lrs["filter"] / lrs["head"] == pytest.approx(5)
    assert lrs["filter"] == TINY.lr_filter


def test_learning_moves_the_kernel_away_from_the_delta(trained):
    for res in trained.values():
        delta = reference_kernel("delta", 5).taps
        dist = np.abs(res.kernel.taps - delta).sum()
        # the delta + N(0, 0.01^2) start is ~0.2 away in L1 (24 taps x 0.008); learning goes further
        assert dist > 0.3, dist
        assert res.history[-1]["kernel_change_l1"] > 0.1


def test_files_and_provenance(trained):
    res = trained["recognition"]
    for key in ("kernel", "checkpoint", "provenance"):
        assert res.paths[key].is_file()
    prov = json.loads(res.paths["provenance"].read_text())
    for key in (
        "task",
        "seed",
        "n_train",
        "n_test",
        "epochs_frozen",
        "epochs_joint",
        "final_metric",
        "sensor",
        "scene",
        "metrics",
    ):
        assert key in prov
    assert prov["final_metric"] == res.value and prov["n_train"] == 32 and prov["seed"] == 1
    k = load_kernel(res.paths["kernel"])
    np.testing.assert_array_equal(k.taps, res.kernel.taps)
    assert k.provenance["task"] == "recognition"


@pytest.mark.parametrize("task", ["recognition", "detection"])
def test_evaluate_kernel_reproduces_the_stored_metric(trained, task):
    res = trained[task]
    ev = evaluate_kernel(res.kernel, task, res.paths["checkpoint"])
    assert ev.metrics == pytest.approx(res.metrics, abs=1e-9)
    # the kernel stored in the JSON file gives the same number
    assert evaluate_kernel(res.paths["kernel"], task, res.paths["checkpoint"]).value == pytest.approx(
        res.value, abs=1e-9
    )


def test_evaluate_other_kernels_and_subsets(trained):
    res = trained["recognition"]
    ckpt = res.paths["checkpoint"]
    wo = evaluate_kernel(None, "recognition", ckpt)
    assert wo.kernel_size == 1 and 0.0 <= wo.value <= 1.0
    big = evaluate_kernel(reference_kernel("dog", 9), "recognition", ckpt, n_test=8)
    assert big.n_test == 8 and big.kernel_size == 9
    assert big.event_rate != wo.event_rate  # a different kernel really changes the events
    tuned = evaluate_kernel(reference_kernel("dog", 5), "recognition", ckpt, finetune_epochs=1)
    assert tuned.finetune_epochs == 1 and 0.0 <= tuned.value <= 1.0


def test_segmentation_transfer_with_frozen_kernel(trained):
    det_kernel = trained["detection"].kernel
    res = learn_kernel(
        "segmentation",
        5,
        seed=0,
        n_train=32,
        n_test=16,
        settings=TINY,
        learn_filter=False,
        init_kernel=det_kernel,
        scene=TINY_SCENE["segmentation"],
    )
    np.testing.assert_array_equal(res.kernel.taps, det_kernel.taps)  # frozen: not retrained
    assert set(res.metrics) == {"miou", "macc", "pixel_accuracy"}
    assert [h["stage"] for h in res.history] == ["joint_frozen_filter"] * 3


def test_bad_input(trained, tmp_path):
    ckpt = trained["recognition"].paths["checkpoint"]
    with pytest.raises(InputError, match="not found"):
        evaluate_kernel(None, "recognition", tmp_path / "nope.safetensors")
    with pytest.raises(InputError, match="trained for task 'recognition'"):
        evaluate_kernel(None, "detection", ckpt)
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"not a safetensors file")
    with pytest.raises(InputError, match="readable"):
        evaluate_kernel(None, "recognition", bad)
    with pytest.raises(InputError, match="does not fit"):
        evaluate_kernel(None, "recognition", _mismatched(trained, tmp_path))
    with pytest.raises(KernelError, match="larger than"):
        evaluate_kernel(np.pad(np.ones((1, 1)), 10), "recognition", ckpt)
    with pytest.raises(InputError, match="n_test"):
        evaluate_kernel(None, "recognition", ckpt, n_test=0)
    with pytest.raises(KernelError, match="init_kernel is 3x3"):
        learn_kernel("recognition", 5, init_kernel=reference_kernel("delta", 3), scene=TINY_SCENE["recognition"])
    with pytest.raises(InputError, match="size"):
        learn_kernel("recognition", 4)
    with pytest.raises(InputError, match="unknown"):
        learn_kernel("tracking", 7)
    with pytest.raises(InputError, match="motion='classes'"):
        learn_kernel("recognition", 3, scene=TINY_SCENE["detection"])


def _mismatched(trained, tmp_path):
    """A recognition checkpoint whose weights were swapped for another width's."""
    from safetensors import safe_open
    from safetensors.torch import load_file, save_file

    src = trained["recognition"].paths["checkpoint"]
    with safe_open(str(src), framework="pt") as f:
        meta = f.metadata()
    tensors = load_file(str(src))
    tensors = {k: (v[:-1] if k.startswith("network.head") and v.ndim else v) for k, v in tensors.items()}
    out = tmp_path / "mismatch.safetensors"
    save_file(tensors, str(out), metadata=meta)
    return out


def test_plugin_evaluator_registry():
    class Custom(DetectionEvaluator):
        name = "custom_detection_test"

    try:
        register_evaluator(Custom())
        assert get_evaluator("custom_detection_test").primary_metric == "map"
        with pytest.raises(InputError, match="already registered"):
            register_evaluator(Custom())
    finally:
        EVALUATORS.pop("custom_detection_test", None)
    with pytest.raises(InputError, match="TaskEvaluator"):
        register_evaluator(object())


@pytest.mark.parametrize("task", ["detection", "recognition"])
def test_shipped_checkpoints_reproduce_their_metric(task):
    stem = SHIPPED / f"learned_{task}_7x7"
    prov = json.loads(Path(str(stem) + ".provenance.json").read_text())
    kernel = load_kernel(Path(str(stem) + ".json"))
    assert kernel.size == 7 and prov["task"] == task and prov["size"] == 7
    for key in ("seed", "n_train", "n_test", "epochs_frozen", "epochs_joint", "sensor", "scene", "final_metric"):
        assert key in prov
    ev = evaluate_kernel(kernel, task, Path(str(stem) + ".safetensors"))
    assert ev.value == pytest.approx(prov["final_metric"], abs=1e-9)
    # the learned kernel is not the delta it started from
    assert np.abs(kernel.taps - reference_kernel("delta", 7).taps).sum() > 0.2
