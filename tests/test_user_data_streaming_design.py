"""The streaming / sampling design keys reach training and scoring (fsdvs_hw.explore.user_data).

A design's ``[tasks.datasets.recognition] sampling = {...}`` and ``train = {memory_mb, workers,
val_fraction}``: the table trains streamed, validates per epoch and keeps the best epoch; the
exploration scores several clips per video, one entry per video; the loader's keys (which change
no weight) stay out of the training fingerprint and the exploration's point key.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
imageio = pytest.importorskip("imageio")

from test_user_datasets import PLUGINS  # noqa: E402

from fsdvs_hw.design.user_data_section import UserTask  # noqa: E402
from fsdvs_hw.explore.user_data import dataset_evidence, train_user_task  # noqa: E402


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("streamdesign")
    rng = np.random.default_rng(1)
    for c, cls in enumerate(("Left", "Right")):
        (root / "ucf" / cls).mkdir(parents=True)
        for v in range(4):
            with imageio.get_writer(
                str(root / "ucf" / cls / f"v_{cls}_{v}.mp4"), fps=25, codec="libx264", ffmpeg_log_level="error"
            ) as w:
                x0 = int(rng.integers(40, 200))
                for t in range(20):
                    img = np.full((240, 320, 3), 60, np.uint8)
                    x = x0 + (5 * t if c else -5 * t) % 100
                    img[:, x : x + 20] = 220
                    w.append_data(img)
    shutil.copy(PLUGINS / "toy_network.py", root / "toy_network.py")
    return root


def _entry(**train) -> dict:
    table = {
        "dataset": {"format": "video_folder", "root": "ucf", "n_frames": 4, "size": [32, 32]},
        "network": "toy_network:make",
        "n_clips": 2,
        "seed": 3,
        "sampling": {"clips_per_video": 2, "train_clips_per_video": 1, "seed": 5},
        "train": {"out": "nets/rec", "kernel_size": 3, "epochs_frozen": 0, "epochs_joint": 2, "batch_size": 4, **train},
    }
    return UserTask.model_validate(table).model_dump()


@pytest.mark.slow  # about 20 s: 8 H.264 videos decoded clip by clip
def test_design_keys_train_streamed_with_validation_and_score_per_video(folder):
    entry = _entry(memory_mb=64.0, workers=0, val_fraction=0.34)
    res = train_user_task("recognition", entry, folder)
    rec = res.provenance["streaming"]
    assert rec["memory_mb"] == 64.0 and rec["sampling"]["seed"] == 5 and rec["val_clips"] == 4  # 2 videos x 2
    assert all("val_metric" in h for h in res.history) and rec["best_epoch"] in (0, 1)
    fp = res.provenance["fingerprint"]
    assert fp["sampling"]["clips_per_video"] == 2 and fp["train"]["val_fraction"] == 0.34
    assert "memory_mb" not in fp["train"] and "workers" not in fp["train"] and fp["train"]["streamed"] is True
    # another memory bound changes no weight: the finished checkpoint is reused
    again = train_user_task("recognition", _entry(memory_mb=32.0, workers=1, val_fraction=0.34), folder)
    assert again.epochs_trained == 0
    saved = json.loads((folder / "nets" / "rec.provenance.json").read_text())
    assert saved["streaming"]["best_epoch"] == rec["best_epoch"]
    evidence, _ = dataset_evidence(res.kernel, "recognition", entry, folder, network=res.network)
    assert evidence.n_clips == 2 and evidence.n_drawn == 2  # two videos, each the mean of its 2 clips


def test_sampling_needs_a_video_folder_with_a_size():
    with pytest.raises(ValueError, match=r"dataset\.size"):
        UserTask.model_validate({"dataset": {"format": "video_folder", "root": "u"}, "sampling": {}})
    with pytest.raises(ValueError, match="video_folder"):
        UserTask.model_validate(
            {"dataset": {"format": "mask_frames", "root": "m", "num_classes": 3, "size": [8, 8]}, "sampling": {}}
        )
    with pytest.raises(ValueError, match="val_fraction"):
        UserTask.model_validate({"dataset": {"format": "video_folder", "root": "u"}, "train": {"val_fraction": 0.95}})
    with pytest.raises(ValueError, match="memory_mb"):
        UserTask.model_validate({"dataset": {"format": "video_folder", "root": "u"}, "train": {"memory_mb": 0}})
