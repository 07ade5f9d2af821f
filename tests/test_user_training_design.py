"""A design's ``[tasks.datasets.<task>] train = {...}``: ``fsdvs-hw learn --design`` and explore reuse it.

Frames + label masks (12 frames, 10 clips of 3) with the toy voxel network beside the design:
``learn --design`` trains on the clips not scored (seeded, disjoint) and writes the kernel and
network at ``train.out``; a rerun and ``fsdvs-hw explore`` reuse them without training; bad train
keys are refused naming the key, the value and the range.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

pytest.importorskip("torch")
from conftest import cheap_design
from test_user_datasets import PLUGINS, _masks, _write_masks

from fsdvs_hw.design import DesignError, load_design
from fsdvs_hw.design.user_data_inputs import open_dataset

TABLE = """
[tasks.datasets.segmentation]
network = "toy_network:make_voxel"
network_options = {{ task = "segmentation" }}
n_clips = 3
train = {{ {train} }}

[tasks.datasets.segmentation.dataset]
format = "mask_frames"
root = "seg"
frames = "img"
masks = "lbl"
num_classes = 3
n_frames = 3
clip_stride = 1
fps = 25.0
"""
TRAIN = 'out = "nets/seg", kernel_size = 3, epochs_frozen = 1, epochs_joint = 1, batch_size = 4, n_train = 5'


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("usertrain")
    _write_masks(root / "seg", *_masks(12))
    shutil.copy(PLUGINS / "toy_network.py", root / "toy_network.py")
    return root


#: The kernel the training writes (``train.out`` + ``.json``), named before it exists: explore
#: refuses a kernel the network was not trained with (tests/test_user_data_chaining.py).
LEARNED_KERNEL = '[kernel]\nsource = "file"\npath = "nets/seg.json"\n'


def _design(folder: Path, train: str = TRAIN, name: str = "train", n_clips: int = 3, kernel: str = "") -> Path:
    path = folder / f"{name}.toml"
    table = TABLE.format(train=train).replace("n_clips = 3", f"n_clips = {n_clips}")
    path.write_text(cheap_design(name) + kernel + "[scoring]\nn_resamples = 200\n" + table)
    return path


def test_learn_on_design_trains_disjoint_clips_then_reruns_and_explore_reuse(folder, tmp_path, capsys):
    from fsdvs_hw.cli import main

    design = _design(folder, kernel=LEARNED_KERNEL)
    assert main(["learn", "segmentation", "--design", str(design)]) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["epochs_trained_now"] == 2 and first["n_train"] == 5 and first["n_scored"] == 3
    prov = json.loads((folder / "nets" / "seg.provenance.json").read_text())
    entry = load_design(design).data["tasks"]["datasets"]["segmentation"]
    scored = set(open_dataset(entry["dataset"], folder, key="k").draw(3, 0).tolist())
    assert len(prov["train_indices"]) == 5 and not scored & set(prov["train_indices"])
    assert [h["stage"] for h in prov["history"]] == ["frozen_filter", "joint"]
    assert (folder / "nets" / "seg.json").is_file() and not (folder / "nets" / "seg.partial.pt").exists()

    assert main(["learn", "segmentation", "--design", str(design)]) == 0  # reused, nothing trained
    assert json.loads(capsys.readouterr().out)["epochs_trained_now"] == 0

    out = tmp_path / "explore"
    assert main(["explore", str(design), "--out", str(out), "--no-progress"]) == 0
    assert "(0 epochs now;" in capsys.readouterr().err
    blob = json.loads((out / "scores.json").read_text())
    rec = next(p for p in blob["points"] if p["realisation"] == "delta")["result"]["tasks"]["segmentation"]
    assert rec["simulator"]["train"]["out"] == "nets/seg" and rec["simulator"]["n_clips"] == 3


def test_learn_design_refuses_synthetic_options(folder, capsys):
    from fsdvs_hw.cli import main

    assert main(["learn", "segmentation", "--design", str(_design(folder)), "--seed", "1", "--out", "x"]) == 2
    assert "error: --seed --out with --design" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("train", "n_clips", "want"),
    [
        (
            "epochs_joint = -1",
            3,
            "key 'tasks.datasets.segmentation.train.epochs_joint' = -1: out of range; allowed: an integer in [0, 1000]",
        ),
        ("kernel_size = 4", 3, "key 'tasks.datasets.segmentation.train.kernel_size' = 4"),
        ("lr_kernel = 20.0", 3, "key 'tasks.datasets.segmentation.train.lr_kernel' = 20.0"),
        ("n_train = 8", 3, "key 'tasks.datasets.segmentation.train.n_train' = 8: 7 clips are not scored; allowed: 0"),
        ("", 0, "key 'tasks.datasets.segmentation.n_clips' = 0: with tasks.datasets.segmentation.train"),
        ("epoch = 1", 3, "key 'tasks.datasets.segmentation.train.epoch'"),
    ],
)
def test_bad_train_keys_name_file_key_value_and_range(folder, train, n_clips, want):
    with pytest.raises(DesignError) as err:
        load_design(_design(folder, train, name="bad", n_clips=n_clips))
    assert want in str(err.value) and "bad.toml" in str(err.value), str(err.value)


def test_ablation_on_user_data_gives_paired_gains_and_refuses_synthetic_options(folder, tmp_path, capsys):
    from fsdvs_hw.cli import main

    design = str(_design(folder))
    args = [
        "ablation",
        "--design",
        design,
        "--tasks",
        "segmentation",
        "--sizes",
        "1",
        "3",
        "--seeds",
        "0",
        "1",
        "--out",
        str(tmp_path / "abl"),
        "--no-progress",
    ]
    assert main([a for a in args if a != "--no-progress"]) == 0  # verbose: one line per epoch
    err = capsys.readouterr().err  # each run's epoch lines say its kernel size and seed (runs may interleave)
    epochs = [line for line in err.splitlines() if "epoch" in line]
    assert epochs and all(re.match(r"\[segmentation k=[13] s=[01]\] ", line) for line in epochs)
    assert "[segmentation k=3 s=1] " in err
    res = json.loads((tmp_path / "abl" / "ablation.json").read_text())
    wo, k3 = res["rows"]
    assert (wo["label"], k3["label"]) == ("w/o", "3x3") and res["n_clips"] == 3
    assert res["resampled"] == ["clips", "seeds"] and len(k3["per_seed"]) == 2
    assert k3["gain"] == pytest.approx(k3["metric_mean"] - wo["metric_mean"], abs=1e-9)
    assert k3["gain_ci95_low"] <= k3["gain"] <= k3["gain_ci95_high"]
    runs = sorted((tmp_path / "abl" / "runs").glob("*.safetensors"))
    assert len(runs) == 4
    stamps = [p.stat().st_mtime_ns for p in runs]
    assert main(args) == 0  # a rerun reuses the four checkpoints: none is rewritten
    assert [p.stat().st_mtime_ns for p in runs] == stamps
    capsys.readouterr()
    assert main([*args, "--scheduler", "tcp://127.0.0.1:8786", "--transfer", "k.json"]) == 2
    assert "--scheduler --transfer with --design: not supported on user data" in capsys.readouterr().err
    seeds = args.index("--seeds")
    assert main([*args[: seeds + 1], "1", "1", *args[seeds + 3 :]]) == 2  # a repeated seed, before any training
    assert "--seeds [1, 1]: allowed: one or more distinct seeds" in capsys.readouterr().err


@pytest.mark.slow
def test_ablation_on_user_data_with_workers_gives_the_sequential_result(folder, tmp_path):
    from fsdvs_hw.cli import main

    args = [
        "ablation",
        "--design",
        str(_design(folder)),
        "--tasks",
        "segmentation",
        "--sizes",
        "1",
        "3",
        "--seeds",
        "0",
        "1",
        "--no-progress",
    ]
    assert main([*args, "--out", str(tmp_path / "seq")]) == 0
    assert main([*args, "--out", str(tmp_path / "par"), "--workers", "2"]) == 0  # trained in 2 processes
    seq, par = (json.loads((tmp_path / f / "ablation.json").read_text()) for f in ("seq", "par"))
    assert len(list((tmp_path / "par" / "runs").glob("*.safetensors"))) == 4
    for a, b in zip(seq["rows"], par["rows"]):  # 1 torch thread per worker: equal up to summation order
        assert a["label"] == b["label"] and a["per_seed"] == pytest.approx(b["per_seed"], abs=1e-6)
