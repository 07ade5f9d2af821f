"""Training on user clips (fsdvs_hw.tasks.dataset_training): two stages, decoupled rates, resume.

A tiny in-memory clip dataset whose classes are separable by the event polarity (class 0: the
scene brightens, ON events; class 1: it darkens, OFF events) must be learned well above chance;
stage one must keep the kernel fixed and stage two move it; a rerun must reuse the finished
checkpoint and an interrupted run continue from its last finished epoch.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from fsdvs_hw.errors import InputError
from fsdvs_hw.scenes.datasets import Clip, ClipDataset
from fsdvs_hw.tasks import training
from fsdvs_hw.tasks.dataset_eval import evaluate_on_dataset
from fsdvs_hw.tasks.dataset_training import disjoint_train_indices, train_on_dataset


class PolarityClips(ClipDataset):
    """Recognition clips of 16x16 textured frames that brighten (class 0) or darken (class 1)."""

    task = "recognition"
    num_classes = 2
    class_names = ("brighten", "darken")
    size = (16, 16)
    n_frames = 4

    def __init__(self, n: int = 40) -> None:
        super().__init__()
        self.n = n

    def __len__(self) -> int:
        return self.n

    def _load(self, i: int) -> Clip:
        rng = np.random.default_rng(i)
        base = 0.2 + 0.3 * rng.random((16, 16))
        label = i % 2
        gain = np.array([1.0, 1.5, 2.2, 3.2]) if label == 0 else np.array([1.0, 0.66, 0.45, 0.31])
        return Clip(base[None] * gain[:, None, None], np.arange(4) / 25.0, {"motion": np.int64(label)}, f"clip{i}", i)


TOY = "toy_network:make"


def test_disjoint_draw_is_disjoint_and_seeded():
    test = PolarityClips().draw(10, seed=0)
    a = disjoint_train_indices(40, test, 20, seed=3)
    assert len(a) == 20 and not set(a) & set(test)
    assert a.tolist() == disjoint_train_indices(40, test, 20, seed=3).tolist()
    assert a.tolist() != disjoint_train_indices(40, test, 20, seed=4).tolist()
    with pytest.raises(InputError, match=r"train.n_train = 35: 30 of the 40 clips.*2 to 30"):
        disjoint_train_indices(40, test, 35, seed=0)


def test_training_learns_separable_clips_and_stage_two_moves_the_kernel(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(Path(__file__).parent / "plugins"))
    ds = PolarityClips()
    test = ds.draw(12, seed=0)
    train = disjoint_train_indices(len(ds), test, 0, seed=0)
    before = evaluate_on_dataset(None, "recognition", ds, TOY, n_clips=12, seed=0).value
    res = train_on_dataset(
        ds,
        "recognition",
        TOY,
        train_indices=train,
        kernel_size=3,
        epochs_frozen=3,
        epochs_joint=2,
        lr_network=3e-2,
        lr_kernel=5e-2,
        lr_head=1e-3,
        batch_size=7,
        seed=0,
        out=tmp_path / "rec",
    )
    after = evaluate_on_dataset(res.kernel, "recognition", ds, res.network, n_clips=12, seed=0).value
    assert after >= 11 / 12 and after > before  # chance is 1/2
    stages = [h["stage"] for h in res.history]
    assert stages == ["frozen_filter"] * 3 + ["joint"] * 2
    assert all(h["kernel_change_l1"] == 0.0 for h in res.history[:3])  # stage one: the kernel is fixed
    assert res.history[-1]["kernel_change_l1"] > 1e-3  # stage two: it moves
    assert res.provenance["learning_rates"] == {
        "network_stage_one": 3e-2,
        "kernel": 5e-2,
        "backbone": pytest.approx(5e-2 * 5e-5 / 5e-4),
        "head": 1e-3,
    }
    assert not (tmp_path / "rec.partial.pt").exists() and (tmp_path / "rec.safetensors").is_file()


def test_rerun_reuses_and_interrupted_run_resumes(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(Path(__file__).parent / "plugins"))
    ds = PolarityClips(16)
    train = disjoint_train_indices(len(ds), ds.draw(4, seed=0), 0, seed=0)
    kw = {
        "train_indices": train,
        "kernel_size": 3,
        "epochs_frozen": 1,
        "epochs_joint": 2,
        "batch_size": 6,
        "fingerprint": {"run": 1},
    }
    full = train_on_dataset(ds, "recognition", TOY, **kw)  # reference, no files

    calls = {"n": 0}

    orig = training.train_epoch

    def crash_on_third(*a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return orig(*a, **k)

    monkeypatch.setattr(training, "train_epoch", crash_on_third)
    with pytest.raises(KeyboardInterrupt):
        train_on_dataset(ds, "recognition", TOY, out=tmp_path / "r", **kw)
    assert (tmp_path / "r.partial.pt").is_file()
    monkeypatch.setattr(training, "train_epoch", orig)
    resumed = train_on_dataset(ds, "recognition", TOY, out=tmp_path / "r", **kw)
    assert resumed.epochs_trained == 1  # two of three epochs were done before the interruption
    np.testing.assert_allclose(resumed.kernel.taps, full.kernel.taps, rtol=0, atol=1e-6)
    assert [h["loss"] for h in resumed.history] == pytest.approx([h["loss"] for h in full.history], rel=1e-5)
    again = train_on_dataset(ds, "recognition", TOY, out=tmp_path / "r", **kw)
    assert again.epochs_trained == 0
    np.testing.assert_array_equal(again.kernel.taps, resumed.kernel.taps)
    with pytest.raises(InputError, match=r"r.safetensors: trained with other settings \(differing: run\)"):
        train_on_dataset(ds, "recognition", TOY, out=tmp_path / "r", **{**kw, "fingerprint": {"run": 2}})
