"""Training trajectories of every path through the training engine, pinned to the numbers they gave.

Tiny deterministic runs (16 clips of 16x16, one thread) of :func:`~fsdvs_hw.tasks.learn.learn_kernel`
(staged, joint with a frozen filter, co-designed ASIC), :func:`~fsdvs_hw.tasks.learn.finetune_network`
(frozen kernel, co-designed ASIC), :func:`~fsdvs_hw.tasks.learn.evaluate_kernel` with fine-tuning and
:func:`~fsdvs_hw.tasks.dataset_training.train_on_dataset` (learned, frozen and co-designed kernel):
the learned taps, the per-epoch losses and kernel moves and a checksum of the trained weights
must stay what they were (relative 1e-6), so a change of the random draws, their order, the
optimiser steps or the stages shows here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from test_dataset_training import PolarityClips  # noqa: E402

from fsdvs_hw.errors import InputError  # noqa: E402
from fsdvs_hw.kernels import reference_kernel  # noqa: E402
from fsdvs_hw.realise.registry import fit_realisation  # noqa: E402
from fsdvs_hw.scenes.synthetic import SceneConfig  # noqa: E402
from fsdvs_hw.tasks.checkpoints import load_checkpoint  # noqa: E402
from fsdvs_hw.tasks.dataset_training import disjoint_train_indices, train_on_dataset  # noqa: E402
from fsdvs_hw.tasks.learn import TrainingSettings, evaluate_kernel, finetune_network, learn_kernel  # noqa: E402
from fsdvs_hw.tasks.training import (  # noqa: E402
    TrainingConfig,
    TrainingData,
    adamw_optimizer,
    delta_init,
    train_epochs,
)

REL = 1e-6
REC = SceneConfig(height_px=16, width_px=16, radius_px=(3.0, 4.0), n_frames=4, motion="classes", edge_contrast=0.3)
SEG = SceneConfig(height_px=16, width_px=16, radius_px=(3.0, 4.0), n_frames=4, n_objects=(1, 1))
SETTINGS = TrainingSettings(epochs_frozen=1, epochs_joint=2, batch_size=8, width=4, lr_filter=2e-2)
TOY = "toy_network:make"

#: Recorded with the code before the training engine existed (one thread, CPU): per run, the
#: final taps, per-epoch losses, kernel movement (L1 from the start), stages, a weight checksum and
#: the metrics (tests/data/training_trajectories.json).
PINNED: dict[str, dict] = json.loads((Path(__file__).parent / "data" / "training_trajectories.json").read_text())


def _weights(state: dict) -> float:
    """Sum of the absolute values of every weight (a checksum of a trained network)."""
    return float(sum(v.detach().double().abs().sum() for v in state.values()))


def _trajectory(result, state: dict | None = None) -> dict:
    out = {
        "taps": np.asarray(result.kernel.taps).ravel().tolist(),
        "loss": [h["loss"] for h in result.history],
        "l1": [h.get("kernel_change_l1") for h in result.history],
        "stage": [h["stage"] for h in result.history],
    }
    if state is not None:
        out["weights"] = _weights(state)
    if getattr(result, "metrics", None):
        out["metrics"] = dict(result.metrics)
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("engine")
    got = {}
    rec = learn_kernel("recognition", 3, seed=2, n_train=16, n_test=8, settings=SETTINGS, scene=REC, out=out / "rec")
    got["learn_staged"] = _trajectory(rec, load_checkpoint(out / "rec.safetensors")[1])
    seg = learn_kernel(
        "segmentation",
        3,
        seed=1,
        n_train=16,
        n_test=8,
        settings=SETTINGS,
        scene=SEG,
        learn_filter=False,
        out=out / "seg",
    )
    got["learn_joint_frozen_filter"] = _trajectory(seg, load_checkpoint(out / "seg.safetensors")[1])
    asic = learn_kernel(
        "recognition",
        3,
        seed=0,
        n_train=16,
        n_test=8,
        settings=SETTINGS,
        scene=REC,
        init_kernel=reference_kernel("dog", 3),
        realisation="asic",
        out=out / "asic",
    )
    got["learn_codesign"] = _trajectory(asic, load_checkpoint(out / "asic.safetensors")[1])
    ckpt = out / "rec.safetensors"
    dog = reference_kernel("dog", 3)
    frozen = finetune_network(ckpt, "recognition", kernel=dog, epochs=2, n_train=12, out=out / "ft")
    got["finetune_frozen"] = _trajectory(frozen, load_checkpoint(out / "ft.safetensors")[1])
    fit = fit_realisation("asic", dog)
    codesign = finetune_network(ckpt, "recognition", realisation=fit, epochs=2, n_train=12, out=out / "cd")
    got["finetune_codesign"] = _trajectory(codesign, load_checkpoint(out / "cd.safetensors")[1])
    ev = evaluate_kernel(dog, "recognition", ckpt, n_test=8, finetune_epochs=2)
    got["evaluate_finetuned"] = {"metrics": dict(ev.metrics), "event_rate": ev.event_rate}
    return got


@pytest.fixture(scope="module")
def dataset_runs():
    torch.set_num_threads(1)
    mp = pytest.MonkeyPatch()
    mp.syspath_prepend(str(Path(__file__).parent / "plugins"))
    ds = PolarityClips(16)
    train = disjoint_train_indices(len(ds), ds.draw(4, seed=0), 0, seed=0)
    common = {"train_indices": train, "epochs_frozen": 1}
    got = {}
    try:
        res = train_on_dataset(
            ds, "recognition", TOY, kernel_size=3, epochs_joint=2, batch_size=5, seed=3, lr_kernel=5e-2, **common
        )
        got["dataset_learned"] = _trajectory(res, res.network.state_dict())
        res = train_on_dataset(
            ds, "recognition", TOY, kernel_size=3, epochs_joint=1, batch_size=5, seed=1, learn_filter=False, **common
        )
        got["dataset_frozen"] = _trajectory(res, res.network.state_dict())
        fit = fit_realisation("asic", reference_kernel("dog", 3))
        res = train_on_dataset(
            ds, "recognition", None, epochs_joint=1, batch_size=6, seed=0, realisation=fit, lr_kernel=0.2, **common
        )
        got["dataset_codesign"] = _trajectory(res, res.network.state_dict())
    finally:
        mp.undo()
    return got


def _check(got: dict, want: dict) -> None:
    assert set(got) == set(want)
    for key, value in want.items():
        if key == "stage":
            assert got[key] == value
        elif key == "l1":
            assert got[key] == [None if v is None else pytest.approx(v, rel=REL, abs=1e-12) for v in value]
        elif isinstance(value, dict):
            assert got[key] == {k: pytest.approx(v, rel=REL, abs=1e-12) for k, v in value.items()}
        else:
            assert got[key] == pytest.approx(value, rel=REL, abs=1e-12), key


@pytest.mark.parametrize(
    "path",
    [
        "learn_staged",
        "learn_joint_frozen_filter",
        "learn_codesign",
        "finetune_frozen",
        "finetune_codesign",
        "evaluate_finetuned",
    ],
)
def test_synthetic_training_follows_its_pinned_trajectory(runs, path):
    _check(runs[path], PINNED[path])


@pytest.mark.parametrize("path", ["dataset_learned", "dataset_frozen", "dataset_codesign"])
def test_user_data_training_follows_its_pinned_trajectory(dataset_runs, path):
    _check(dataset_runs[path], PINNED[path])


class _MeanSquare:
    """A stand-in evaluator: the mean square of the network output minus the clips' ``y``."""

    name = "toy"

    def loss(self, output, targets):
        return ((output.squeeze(1) - targets["y"]) ** 2).mean()


def _toy_stage(**config):
    torch.manual_seed(0)
    video = torch.randn(10, 3)
    data = TrainingData(video, {"y": video.sum(dim=1)}, None, np.arange(2.0), input_fn=lambda v, k, s, t: v * k)
    network = torch.nn.Linear(3, 1)
    kernel = torch.nn.Parameter(torch.ones(()))
    optimizer = adamw_optimizer(network, 0.0, {"network": 1e-2, "kernel": 1e-2}, kernel)
    return data, network, kernel, optimizer, TrainingConfig(**config)


def test_train_epochs_resumes_at_first_epoch_reports_progress_and_checkpoints_after_each_epoch():
    lines, ends, history = [], [], []
    data, network, kernel, optimizer, config = _toy_stage(
        stage="joint",
        epochs=3,
        batch_size=4,
        first_epoch=1,
        progress=lines.append,
        progress_stage="stage two",
        on_epoch_end=ends.append,
    )
    trained = train_epochs(
        config,
        evaluator=_MeanSquare(),
        network=network,
        kernel=kernel,
        data=data,
        optimizer=optimizer,
        generator=torch.Generator().manual_seed(0),
        history=history,
        kernel_init=torch.ones(()),
    )
    assert trained == 2 and ends == [1, 2]
    assert [(h["stage"], h["epoch"]) for h in history] == [("joint", 1), ("joint", 2)]
    assert history[-1]["kernel_change_l1"] > 0  # the kernel is in the optimiser: it moved
    assert [line.split(":")[0] for line in lines] == [
        "[learn] toy stage two epoch 2/3",
        "[learn] toy stage two epoch 3/3",
    ]


def test_a_frozen_kernel_is_simulated_once_and_a_non_finite_loss_names_stage_and_epoch():
    data, network, kernel, optimizer, config = _toy_stage(stage="finetune", epochs=1, batch_size=10)
    frozen = data.with_frozen_kernel(kernel.detach(), chunk=3)
    torch.testing.assert_close(frozen.cached_inputs, data.video)
    bad = TrainingData(data.video, {"y": data.targets["y"] * float("nan")}, None, data.timestamps_s, data.input_fn)
    with pytest.raises(FloatingPointError, match=r"finetune epoch 0: training loss is not finite"):
        train_epochs(
            config,
            evaluator=_MeanSquare(),
            network=network,
            kernel=kernel,
            data=bad,
            optimizer=optimizer,
            generator=torch.Generator().manual_seed(0),
            history=[],
        )


@pytest.mark.parametrize("field, value", [("epochs", -1), ("batch_size", 0), ("first_epoch", 1.5), ("epochs", True)])
def test_training_config_refuses_counts_out_of_range(field, value):
    with pytest.raises(InputError, match=rf"TrainingConfig.{field} must be an integer"):
        TrainingConfig(**{"stage": "joint", "epochs": 1, "batch_size": 1, field: value})


def test_delta_init_is_a_centred_delta_plus_seeded_noise():
    taps = delta_init(5, 0.1, torch.Generator().manual_seed(0))
    again = delta_init(5, 0.1, torch.Generator().manual_seed(0))
    assert taps.dtype == torch.float64 and taps[2, 2] == 1.0 and torch.equal(taps, again)
    assert 0 < float(taps.abs().sum() - 1.0) < 25 * 0.5
