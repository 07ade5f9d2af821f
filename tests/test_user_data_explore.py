"""``fsdvs-hw explore`` on the user's own datasets and network (``[tasks.datasets.<task>]``).

Tiny datasets in the three layouts (the writers of test_user_datasets: a UCF101 class folder of
real bigbuckbunny clips, frames + COCO JSON, frames + label PNGs with ignore 255) sit under a
design file's folder with the toy network (tests/plugins/toy_network.py) copied beside it; explore
(learned + delta, no emulation, one worker) must write a paired loss with its CI for every task,
and the delta row's loss must be the difference of the two rows' per-clip metrics.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("torch")
imageio = pytest.importorskip("imageio")
from conftest import cheap_design
from test_user_datasets import FPS, PLUGINS, _bbb_frames, _coco_doc, _masks, _write_coco, _write_masks

from fsdvs_hw.design import DesignError, load_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.stats import ConfusionMIoU
from fsdvs_hw.tasks.metrics import segmentation_scores

TASKS = ("recognition", "detection", "segmentation")

DATASETS = """
[tasks.datasets.recognition]
dataset = { format = "video_folder", root = "data/ucf", n_frames = 5 }
network = "toy_network:make"

[tasks.datasets.detection]
dataset = { format = "coco_frames", root = "data/coco", n_frames = 4, clip_stride = 1, fps = 25.0 }
network = "toy_network:make"
network_options = { task = "detection" }

[tasks.datasets.segmentation]
network = "toy_network:make_voxel"
network_options = { task = "segmentation" }
n_clips = 3

[tasks.datasets.segmentation.dataset]
format = "mask_frames"
root = "data/seg"
frames = "img"
masks = "lbl"
num_classes = 3
n_frames = 3
clip_stride = 1
fps = 25.0
"""


@pytest.fixture(scope="module")
def user_folder(tmp_path_factory) -> Path:
    """A design folder holding the three datasets and the toy network module."""
    root = tmp_path_factory.mktemp("userdata")
    ucf = root / "data" / "ucf"
    frames = _bbb_frames(start=0, n=66)  # decoded once; video v of class c starts at frame 20 (2c + v)
    for c, cls in enumerate(("Jump", "Run")):
        (ucf / cls).mkdir(parents=True)
        for v in range(2):
            with imageio.get_writer(
                str(ucf / cls / f"v_{cls}_g0{v}.mp4"),
                fps=FPS,
                codec="libx264",
                quality=9,
                macro_block_size=1,
                ffmpeg_log_level="error",
            ) as w:
                for f in frames[20 * (2 * c + v) : 20 * (2 * c + v) + 6]:
                    w.append_data(f)
    (root / "data" / "coco").mkdir(parents=True)
    _write_coco(root / "data" / "coco", *_coco_doc())
    _write_masks(root / "data" / "seg", *_masks())
    shutil.copy(PLUGINS / "toy_network.py", root / "toy_network.py")  # imported from the design's folder
    return root


def _design(folder: Path, extra: str = DATASETS, name: str = "user") -> Path:
    path = folder / f"{name}.toml"
    path.write_text(cheap_design(name) + "[scoring]\nn_resamples = 200\n" + extra)
    return path


def test_explore_on_user_datasets_writes_paired_losses_with_cis(user_folder, tmp_path):
    from fsdvs_hw.cli import main

    out = tmp_path / "out"
    assert main(["explore", str(_design(user_folder)), "--out", str(out), "--no-progress"]) == 0
    blob = json.loads((out / "scores.json").read_text())
    rows = {r["realisation"]: r for r in blob["rows"]}
    points = {p["realisation"]: p for p in blob["points"]}
    n_clips = {"recognition": 4, "detection": 5, "segmentation": 3}
    for task in TASKS:
        d = rows["delta"]
        assert d[f"{task}_n_clips"] == n_clips[task] and d[f"{task}_n_seeds"] == 1
        assert d[f"{task}_loss_ci95_low"] <= d[f"{task}_loss"] <= d[f"{task}_loss_ci95_high"]
        assert rows["learned"][f"{task}_loss"] == 0.0  # the reference against itself
        # the loss is the difference of the two rows' metrics on the same clips
        m = {r: points[r]["result"]["tasks"][task]["simulator"] for r in ("learned", "delta")}
        assert d[f"{task}_loss"] == pytest.approx(m["learned"]["metric"] - m["delta"]["metric"], abs=1e-12)
        rec = m["delta"]
        assert rec["n_seeds"] == 1 and "n_seeds = 1" in rec["ci_note"] and "checkpoints" not in rec
        assert rec["network"]["factory"].startswith("toy_network:make")
        assert rec["event_rate_per_s"]["n_clips"] == n_clips[task] and rec["event_rate_per_s"]["mean"] > 0
    ci = points["delta"]["paired_loss"]["simulator"]["detection"]
    assert ci["seed_variance_included"] is False and ci["resampled"] == ["clips"]
    header = (out / "scores.csv").read_text().splitlines()[0].split(",")
    assert {f"{t}_loss_ci95_high" for t in TASKS} <= set(header)
    assert "segmentation" in (out / "report.html").read_text()
    # issue 38, on real footage (bigbuckbunny, COCO-style frames, label masks) with the untrained toy
    # network: every task is at chance, so no loss is claimed and the verdict ranks by kernel error
    meas = points["learned"]["measurability"]["simulator"]
    assert meas["detection"]["chance"] == 0.0 and meas["detection"]["reference_metric"] == 0.0
    assert meas["recognition"]["chance"] == 0.5 and "most frequent of 2" in meas["recognition"]["chance_method"]
    assert meas["segmentation"]["above_chance"]["high"] < 0  # worse than calling every pixel the commonest class
    for task in TASKS:
        assert meas[task]["measurable"] is False and "is not above chance" in meas[task]["reason"]
        assert rows["delta"][f"{task}_loss_text"] == "not measurable"
    assert rows["learned"]["measurable_tasks"] == ""
    html = " ".join((out / "report.html").read_text().split())
    assert "What each task can measure" in html and "a detector that returns no boxes" in html
    assert (
        "no task can: realisations are ranked by kernel error alone, and no accuracy loss is claimed"
        in html.replace("&#39;", "'")
    )
    assert "test clips only (one network: the network-to-network spread is not in the interval)" in html
    assert "kernel error (no task could measure a loss)" in html and "(no task ran)" not in html


def test_bad_user_data_keys_are_refused_naming_the_key(user_folder):
    cases = {
        'dataset = { format = "video_folder", root = "data/ucf", n_frame = 5 }': "key 'tasks.datasets.recognition.dataset.n_frame'",
        'dataset = { format = "videos", root = "data/ucf" }': "key 'tasks.datasets.recognition.dataset.format' = \"videos\"",
        'dataset = { format = "coco_frames", root = "data/coco" }': "key 'tasks.datasets.recognition.dataset.format' = \"coco_frames\": holds detection targets",
        'dataset = { format = "video_folder", root = "../elsewhere" }': "outside the design's folder",
        'dataset = { format = "video_folder", root = "data/coco" }': "class folder",
        'dataset = { format = "video_folder", root = "data/ucf", n_frames = 1 }': "key 'tasks.datasets.recognition.dataset.n_frames' = 1: out of range; allowed: an integer in [2, 10000]",
        'dataset = { format = "video_folder", root = "data/ucf" }\nn_clips = 9': "key 'tasks.datasets.recognition.n_clips' = 9: the dataset has 4 clips",
        'dataset = { format = "video_folder", root = "data/ucf" }\nnetwork = "toy_network:nope"': "key 'tasks.datasets.recognition.network' = \"toy_network:nope\"",
        'dataset = { format = "video_folder", root = "data/ucf" }\nweights = "missing.pt"': "key 'tasks.datasets.recognition.weights' = \"missing.pt\"",
    }
    for body, want in cases.items():
        with pytest.raises(DesignError) as err:
            load_design(_design(user_folder, "[tasks.datasets.recognition]\n" + body + "\n", name="bad"))
        assert want in str(err.value), (body, str(err.value))
        assert "bad.toml" in str(err.value)


def test_a_clip_that_does_not_decode_is_a_task_status_not_a_traceback(user_folder, tmp_path):
    """Layouts are checked at load; a frame that breaks later surfaces as the task's status."""
    from fsdvs_hw.explore.scoring import task_scores
    from fsdvs_hw.design.user_data_section import UserTask

    folder = tmp_path / "d"
    shutil.copytree(user_folder / "data" / "seg", folder / "seg")
    entry = UserTask.model_validate(
        {
            "dataset": {
                "format": "mask_frames",
                "root": "seg",
                "frames": "img",
                "masks": "lbl",
                "num_classes": 3,
                "n_frames": 3,
            }
        }
    ).model_dump()
    bad = np.zeros((32, 32), np.uint8)
    bad[5, 5] = 7  # a class beyond the declared 3, found when clip 0's last mask is decoded
    Image.fromarray(bad).save(folder / "seg" / "lbl" / "s_002.png")
    out = task_scores(None, {}, datasets={"segmentation": entry}, base_dir=folder)
    status = out["segmentation"]["simulator"]["status"]
    assert out["status"] == "partial" and status.startswith("unavailable: ")
    assert "clip 0" in status and "s_002.png" in status and "field 'class id' 7" in status


def test_confusion_miou_leaves_ignored_pixels_out_as_torchmetrics_does(rng):
    torch = pytest.importorskip("torch")
    target = rng.integers(0, 3, size=(4, 6, 7))
    target[:, 0, :] = 255
    pred = rng.integers(0, 3, size=target.shape)
    pred[:, 0, :] = 2  # predictions on ignored pixels must not count
    got = ConfusionMIoU.from_masks(pred, target, 3, ignore_index=255).weighted(np.ones((1, 4)))[0]
    want = segmentation_scores(torch.from_numpy(pred), torch.from_numpy(target), num_classes=3, ignore_index=255)
    assert got == pytest.approx(want["miou"], abs=1e-6)  # torchmetrics sums in float32
    with pytest.raises(InputError):
        ConfusionMIoU.from_masks(pred, target, 3)  # 255 is no class without ignore_index


def _seg_dataset(folder: Path, monkeypatch):
    """The segmentation set and the toy voxel network (from tests/plugins) for it."""
    from fsdvs_hw.scenes.datasets import MaskFramesDataset
    from fsdvs_hw.tasks.user_networks import load_network_factory

    monkeypatch.syspath_prepend(str(PLUGINS))
    seg = folder / "data" / "seg"
    ds = MaskFramesDataset(seg / "img", seg / "lbl", num_classes=3, n_frames=3, clip_stride=1, fps=FPS)
    return ds, load_network_factory("toy_network:make_voxel", in_channels=4, num_classes=3, task="segmentation")


def test_device_cpu_is_the_default_and_an_absent_cuda_is_refused(user_folder, monkeypatch):
    import torch

    from fsdvs_hw.cli.explore import with_device
    from fsdvs_hw.tasks.dataset_eval import evaluate_on_dataset

    ds, net = _seg_dataset(user_folder, monkeypatch)
    a = evaluate_on_dataset(None, "segmentation", ds, net)
    b = evaluate_on_dataset(None, "segmentation", ds, net, device="cpu")
    np.testing.assert_array_equal(a.per_clip, b.per_clip)
    np.testing.assert_array_equal(a.event_counts, b.event_counts)
    with pytest.raises(InputError, match=re.escape("device='gpu'; allowed: 'cpu', 'cuda'")):
        evaluate_on_dataset(None, "segmentation", ds, device="gpu")
    with pytest.raises(InputError, match=re.escape("has no [tasks.datasets.<task>] table")):
        with_device(load_design(_design(user_folder, "", name="plain")), "cpu")
    on_cpu = with_device(load_design(_design(user_folder)), "cpu")
    assert {e["device"] for e in on_cpu.data["tasks"]["datasets"].values()} == {"cpu"}
    if torch.cuda.is_available():
        return
    with pytest.raises(InputError, match="CUDA is not available"):
        evaluate_on_dataset(None, "segmentation", ds, device="cuda")
    body = '[tasks.datasets.recognition]\ndataset = { format = "video_folder", root = "data/ucf" }\ndevice = "cuda"\n'
    with pytest.raises(
        DesignError, match=re.escape("key 'tasks.datasets.recognition.device' = \"cuda\": CUDA is not available")
    ):
        load_design(_design(user_folder, body, name="gpu"))


@pytest.mark.skipif(not __import__("torch").cuda.is_available(), reason="needs a CUDA GPU")
def test_cuda_gives_the_cpu_events_and_metric_on_a_noise_free_sensor(user_folder, monkeypatch):
    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.sensor import SensorConfig
    from fsdvs_hw.tasks.dataset_eval import evaluate_on_dataset

    ds, net = _seg_dataset(user_folder, monkeypatch)
    sensor = SensorConfig.ideal(threshold=0.2, frame_rate_hz=FPS)  # no random stream: CPU and CUDA agree
    runs = [
        evaluate_on_dataset(reference_kernel("dog", 7), "segmentation", ds, net, sensor=sensor, device=d)
        for d in ("cpu", "cuda")
    ]
    np.testing.assert_allclose(runs[1].event_counts, runs[0].event_counts, rtol=1e-6)
    np.testing.assert_allclose(runs[1].per_clip, runs[0].per_clip, atol=1e-6)


def test_design_sensor_thresholds_reach_user_data_tasks(user_folder):
    """``tasks.sensor = "design"``: the design's thresholds replace the default's; a higher one fires less."""
    from fsdvs_hw.explore.scoring import task_scores
    from fsdvs_hw.design.user_data_section import UserTask

    entry = UserTask.model_validate(
        {
            "dataset": {
                "format": "mask_frames",
                "root": "data/seg",
                "frames": "img",
                "masks": "lbl",
                "num_classes": 3,
                "n_frames": 3,
            }
        }
    ).model_dump()
    sensor = {
        "threshold_on": 0.5,
        "threshold_off": 0.5,
        "threshold_sigma": 0.0,
        "placement": "pre_log",
        "positivity": "pedestal",
    }
    recs = [
        task_scores(None, {}, datasets={"segmentation": entry}, base_dir=user_folder, design_sensor=s)["segmentation"][
            "simulator"
        ]
        for s in (None, sensor)
    ]
    assert recs[0]["sensor"]["source"] == "default" and recs[0]["sensor"]["threshold_on"] == 0.2
    assert recs[1]["sensor"] == {"source": "design", **sensor}
    assert 0 < recs[1]["event_rate"] < recs[0]["event_rate"]
