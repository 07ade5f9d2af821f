"""A verdict that knows when it cannot answer (issue 38): clips that fail are skipped, counted and
named up to ``max_failed_clip_fraction``; a task that fails is loud (exit status 3, one console line,
the report's first section).

Fixtures are the tiny layouts of test_user_datasets (label PNGs with ignore 255, a UCF101 class
folder of real bigbuckbunny clips) and the toy network of tests/plugins, so every test runs in seconds.
"""

from __future__ import annotations

import json
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
from fsdvs_hw.design.user_data_section import UserTask

#: The mask dataset's table: 6 frames, clips of 3 starting every frame → 4 clips; clip c is scored
#: on the label mask s_00{c+2}.png.
SEG = {
    "format": "mask_frames",
    "root": "seg",
    "frames": "img",
    "masks": "lbl",
    "num_classes": 3,
    "n_frames": 3,
    "clip_stride": 1,
    "fps": 25.0,
}
SEG_TOML = """
[tasks.datasets.segmentation]
network = "toy_network:make_voxel"
network_options = { task = "segmentation" }
max_failed_clip_fraction = 0.25
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
REC_TOML = """
[tasks.datasets.recognition]
network = "toy_network:make"
dataset = { format = "video_folder", root = "ucf", n_frames = 5 }
"""


def _break_mask(folder: Path, name: str) -> None:
    """Label 7 in a mask of a dataset declaring 3 classes: the reader refuses it when its clip is decoded."""
    bad = np.zeros((32, 32), np.uint8)
    bad[5, 5] = 7
    Image.fromarray(bad).save(folder / "seg" / "lbl" / name)


def _seg_folder(root: Path, bad: tuple[str, ...] = ()) -> Path:
    _write_masks(root / "seg", *_masks())
    shutil.copy(PLUGINS / "toy_network.py", root / "toy_network.py")
    for name in bad:
        _break_mask(root, name)
    return root


def _seg_entry(**extra) -> dict:
    return UserTask.model_validate(
        {
            "dataset": SEG,
            "network": "toy_network:make_voxel",
            "network_options": {"task": "segmentation"},
            **extra,
        }
    ).model_dump()


@pytest.fixture()
def toy():
    """The toy network module of tests/plugins, loaded under its own name (design folders import their copies)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("toy_network_for_tests", PLUGINS / "toy_network.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def video_frames() -> list[np.ndarray]:
    return _bbb_frames(start=0, n=24)


def _ucf(root: Path, frames: list[np.ndarray], corrupt: str = "") -> None:
    """Two classes of two 6-frame videos; ``corrupt`` (a file name) is overwritten with bytes that are no video."""
    for c, cls in enumerate(("Jump", "Run")):
        (root / "ucf" / cls).mkdir(parents=True)
        for v in range(2):
            path = root / "ucf" / cls / f"v_{cls}_g0{v}.mp4"
            with imageio.get_writer(
                str(path), fps=FPS, codec="libx264", quality=9, macro_block_size=1, ffmpeg_log_level="error"
            ) as w:
                for f in frames[6 * (2 * c + v) : 6 * (2 * c + v) + 6]:
                    w.append_data(f)
            if path.name == corrupt:
                path.write_bytes(b"\x00\x00\x00\x18ftypisom" + bytes(range(256)) * 8)


def _points(tasks_by_realisation: dict[str, dict]) -> list[dict]:
    return [
        {"key": r, "realisation": r, "params": {}, "status": "ok", "result": {"tasks": t}}
        for r, t in tasks_by_realisation.items()
    ]


def test_a_clip_that_fails_to_read_is_skipped_named_and_the_loss_on_the_rest_stays_paired(tmp_path):
    from fsdvs_hw.explore.scoring import paired_losses, task_scores
    from fsdvs_hw.kernels import reference_kernel

    clean = _seg_folder(tmp_path / "clean")
    broken = _seg_folder(tmp_path / "broken", bad=("s_002.png",))  # clip 0's mask
    dog = reference_kernel("dog", 5)
    entry = _seg_entry(max_failed_clip_fraction=0.25)  # 1 of 4 may fail
    runs = {
        where: {"learned": task_scores(dog, {}, datasets={"segmentation": entry}, base_dir=where)}
        | {"delta": task_scores(None, {}, datasets={"segmentation": entry}, base_dir=where)}
        for where in (clean, broken)
    }
    for r in ("learned", "delta"):
        rec = runs[broken][r]["segmentation"]["simulator"]
        assert rec["status"] == "ok", rec["status"]
        assert rec["n_clips"] == 3 and rec["n_clips_drawn"] == 4 and rec["failed_clips"] == 1
        assert rec["max_failed_clip_fraction"] == 0.25
        assert rec["failed_clip_indices"] == [0]  # the same clip for both kernels: the pairing holds
        (named,) = rec["failed_clip_files"]
        assert Path(named["file"]).name == "s_002.png" and "field 'class id' 7" in named["reason"]
        assert runs[clean][r]["segmentation"]["simulator"]["failed_clips"] == 0
    # the loss is paired on the 3 clips left, and is the difference of the two metrics there
    loss = paired_losses(_points(runs[broken]), n_resamples=200)["delta"]["simulator"]["segmentation"]
    m = {r: runs[broken][r]["segmentation"]["simulator"]["metric"] for r in ("learned", "delta")}
    assert loss["n_clips"] == 3 and loss["paired_clips"]
    assert loss["estimate"] == pytest.approx(m["learned"] - m["delta"], abs=1e-12)
    # a point that skipped other clips is not paired with the reference
    other = json.loads(json.dumps(runs[broken]))
    other["delta"]["segmentation"]["simulator"]["failed_clip_indices"] = [3]
    assert "status" in paired_losses(_points(other), n_resamples=200)["delta"]["simulator"]


def test_a_corrupt_video_among_good_ones_is_skipped_and_named(tmp_path, video_frames):
    from fsdvs_hw.explore.scoring import task_scores

    _ucf(tmp_path, video_frames, corrupt="v_Jump_g01.mp4")
    shutil.copy(PLUGINS / "toy_network.py", tmp_path / "toy_network.py")
    entry = UserTask.model_validate(
        {
            "dataset": {"format": "video_folder", "root": "ucf", "n_frames": 5},
            "network": "toy_network:make",
            "max_failed_clip_fraction": 0.25,
        }
    ).model_dump()
    rec = task_scores(None, {}, datasets={"recognition": entry}, base_dir=tmp_path)["recognition"]["simulator"]
    assert rec["status"] == "ok" and rec["n_clips"] == 3 and rec["failed_clips"] == 1
    (named,) = rec["failed_clip_files"]
    assert (
        Path(named["file"]).name == "v_Jump_g01.mp4" and "field 'frames': the video does not decode" in named["reason"]
    )
    assert rec["failed_clip_indices"] == [1] and rec["event_rate_per_s"]["n_clips"] == 3


def test_skipped_clips_leave_the_other_clips_scores_unchanged(tmp_path, toy):
    """Clip by clip, the clips left score exactly what they score when nothing fails (same noise draws)."""
    from fsdvs_hw.scenes.datasets import MaskFramesDataset
    from fsdvs_hw.tasks.dataset_eval import evaluate_on_dataset

    net = toy.make_voxel(4, 3, task="segmentation")
    kw = {"num_classes": 3, "n_frames": 3, "clip_stride": 1, "fps": 25.0}
    out = {}
    for name, bad in (("clean", ()), ("broken", ("s_003.png",))):  # clip 1's mask
        root = _seg_folder(tmp_path / name, bad=bad) / "seg"
        ds = MaskFramesDataset(root / "img", root / "lbl", **kw)
        out[name] = evaluate_on_dataset(None, "segmentation", ds, net, max_failed_fraction=0.25)
    assert out["broken"].clip_indices.tolist() == [0, 2, 3]
    assert [f.index for f in out["broken"].failures] == [1] and out["clean"].failures == ()
    np.testing.assert_array_equal(out["broken"].per_clip, out["clean"].per_clip[[0, 2, 3]])


def test_failures_beyond_the_fraction_fail_the_task_naming_files_and_reasons(tmp_path):
    from fsdvs_hw.explore.scoring import task_scores

    folder = _seg_folder(tmp_path, bad=("s_002.png", "s_004.png"))  # clips 0 and 2: 2 of 4 > 0.25 x 4
    out = task_scores(None, {}, datasets={"segmentation": _seg_entry(max_failed_clip_fraction=0.25)}, base_dir=folder)
    rec = out["segmentation"]["simulator"]
    assert out["status"] == "partial" and rec["status"].startswith("unavailable: ")
    why = rec["status"]
    assert "tasks.datasets.segmentation.max_failed_clip_fraction = 0.25" in why
    assert "2 of the 4 drawn clips failed to read (at most 1 may be skipped)" in why
    assert "s_002.png" in why and "s_004.png" in why and "field 'class id' 7" in why
    assert rec["failed_clips"] == 2 and rec["failed_clip_indices"] == [0, 2]
    assert [Path(f["file"]).name for f in rec["failed_clip_files"]] == ["s_002.png", "s_004.png"]
    # the default fraction (0.05 of 4 clips: none) refuses a single failed clip
    one = _seg_folder(tmp_path / "one", bad=("s_005.png",))
    out = task_scores(None, {}, datasets={"segmentation": _seg_entry()}, base_dir=one)
    assert "max_failed_clip_fraction = 0.05" in out["segmentation"]["simulator"]["status"]
    assert "1 of the 4 drawn clips" in out["segmentation"]["simulator"]["status"]


def test_problems_of_the_task_fail_it_with_the_key_the_file_and_the_allowed_values(tmp_path):
    from fsdvs_hw.explore.scoring import task_scores
    from fsdvs_hw.scenes.datasets import CocoFramesDataset
    from fsdvs_hw.tasks.dataset_eval import evaluate_on_dataset

    folder = _seg_folder(tmp_path)
    wrong = _seg_entry(network="toy_network:make", network_options={"task": "recognition"})  # (N, C), not masks
    rec = task_scores(None, {}, datasets={"segmentation": wrong}, base_dir=folder)["segmentation"]["simulator"]
    assert rec["status"].startswith("unavailable: tasks.datasets.segmentation.network = 'toy_network:make': ")
    assert "returned (1, 3) for frames of 32x32 px" in rec["status"] and "not of the clips" in rec["status"]
    assert "failed_clips" not in rec  # no clip was blamed
    # an odd frame size for the stride-2 detector: refused with the design, and at run time naming the file
    (tmp_path / "coco").mkdir()
    fdir, js = _write_coco(tmp_path / "coco", *_coco_doc())
    with pytest.raises(InputError) as err:
        evaluate_on_dataset(None, "detection", CocoFramesDataset(fdir, js, n_frames=4, size=(31, 32), fps=25.0))
    assert "field 'size' = [31, 32]; allowed: even H and W, e.g. size = [32, 32]" in str(err.value)
    assert "f003.png" in str(err.value)
    det = '[tasks.datasets.detection]\ndataset = { format = "coco_frames", root = "coco", n_frames = 4, size = [31, 32] }\n'
    for body, want in {
        det: "key 'tasks.datasets.detection.dataset.size' = [31, 32]: the detection network works at stride 2; "
        "allowed: even H and W, e.g. [32, 32]",
        SEG_TOML.replace("0.25", "1.5"): "key 'tasks.datasets.segmentation.max_failed_clip_fraction' = 1.5",
    }.items():
        (tmp_path / "bad.toml").write_text(cheap_design("bad") + body)
        with pytest.raises(DesignError) as err:
            load_design(tmp_path / "bad.toml")
        assert want in str(err.value), str(err.value)


def test_a_failed_task_makes_explore_exit_3_say_why_and_head_the_report(tmp_path, video_frames, capsys):
    from fsdvs_hw.cli import main

    folder = _seg_folder(tmp_path / "d", bad=("s_003.png",))  # segmentation: 1 of 4 skipped (0.25 allowed)
    _ucf(folder, video_frames, corrupt="v_Run_g00.mp4")  # recognition: 1 of 4 fails, the default allows none
    design = folder / "fail.toml"
    design.write_text(cheap_design("fail") + "[scoring]\nn_resamples = 200\n" + SEG_TOML + REC_TOML)
    out = tmp_path / "out"
    assert main(["explore", str(design), "--out", str(out), "--no-progress"]) == 3
    err = capsys.readouterr().err
    (line,) = [x for x in err.splitlines() if "task FAILED" in x]
    assert "recognition (simulator track) on 2 of 2 points" in line
    assert "v_Run_g00.mp4" in line and "does not decode" in line
    assert "segmentation (simulator track): 1 of 4 clips skipped" in err and "s_003.png" in err
    # the work is kept: scores with the segmentation loss measured on the 3 clips left
    blob = json.loads((out / "scores.json").read_text())
    delta = next(r for r in blob["rows"] if r["realisation"] == "delta")
    assert delta["segmentation_n_clips"] == 3 and "segmentation_loss" in delta
    html = (out / "report.html").read_text()
    assert html.index("Tasks that failed") < html.index("id='verdict'")
    assert html.index("Clips skipped") < html.index("id='verdict'")
    section = html[html.index("Tasks that failed") : html.index("id='verdict'")]
    assert "recognition" in section and "v_Run_g00.mp4" in section and "1 of 4" in section
    assert "s_003.png" in section and "field &#39;class id&#39; 7" in section
    assert "<td class='l'>1 of 4</td> <td class='l'>0.25</td>" in " ".join(section.split())  # skipped, allowed


def test_a_report_whose_tasks_all_failed_does_not_say_none_were_requested(tmp_path):
    """Every clip of the only requested task fails: the verdict says the task failed, not that none was asked."""
    from fsdvs_hw.explore.explore import run_exploration

    folder = _seg_folder(tmp_path / "d", bad=("s_002.png", "s_003.png", "s_004.png", "s_005.png"))
    design = folder / "all.toml"
    design.write_text(cheap_design("all") + SEG_TOML)
    html = run_exploration(load_design(design), tmp_path / "out", progress=False).report.read_text()
    assert "Tasks that failed" in html
    assert "4 of the 4 drawn clips failed to read (none is left to score)" in html
    assert "lists no" not in html
