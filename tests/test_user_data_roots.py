"""Data where it lives: ``[design] data_roots`` and the confinement of every file a dataset names.

A design's paths must stay inside its folder or a folder its ``data_roots`` list; the same rule
applies to every file a dataset names after links are followed: a COCO ``file_name`` with
``../``, a frame file or a class folder inside a root that links out of it. Each is refused at
load with one error naming the file; a dataset in a listed root loads, and a design without
``data_roots`` is read exactly as before.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest
from conftest import cheap_design
from PIL import Image

from fsdvs_hw.design import DesignError, load_design, parse_design
from fsdvs_hw.design.design_paths import resolve_design_path
from fsdvs_hw.errors import InputError
from fsdvs_hw.paths import DataRoots, confined_path

SIDE = 16


def _coco(root: Path, n: int = 4, file_names: list[str] | None = None) -> Path:
    """A COCO-JSON detection set of ``n`` 16x16 frames (one 4x4 box each) under ``root``."""
    frames = root / "frames"
    frames.mkdir(parents=True, exist_ok=True)
    names = file_names or [f"f{t}.png" for t in range(n)]
    images, anns = [], []
    for t, name in enumerate(names):
        img = np.full((SIDE, SIDE), 50, np.uint8)
        img[4:8, 2 + t : 6 + t] = 200
        if not (frames / name).exists():
            (frames / name).parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(img).save(frames / name)
        images.append({"id": t, "file_name": name, "width": SIDE, "height": SIDE})
        anns.append({"id": t, "image_id": t, "category_id": 1, "bbox": [2 + t, 4, 4, 4]})
    doc = {"images": images, "annotations": anns, "categories": [{"id": 1, "name": "box"}]}
    (root / "instances.json").write_text(json.dumps(doc))
    return root


def _write_design(folder: Path, root: str, data_roots: list[str] | None = None, extra: str = "") -> Path:
    text = cheap_design("roots")
    if data_roots is not None:
        text = text.replace("name = 'roots'\n", f"name = 'roots'\ndata_roots = {json.dumps(data_roots)}\n")
    text += (
        "[tasks.datasets.detection]\n"
        f'dataset = {{ format = "coco_frames", root = {json.dumps(root)}, n_frames = 2, clip_stride = 1 }}\n' + extra
    )
    path = folder / "design.toml"
    path.write_text(text)
    return path


@pytest.fixture()
def places(tmp_path) -> tuple[Path, Path, Path]:
    """A design folder, a data disk beside it and a folder outside both."""
    design, disk, outside = tmp_path / "design", tmp_path / "disk", tmp_path / "outside"
    for p in (design, disk, outside):
        p.mkdir()
    return design, disk, outside


def test_a_dataset_outside_the_design_folder_needs_a_data_root(places):
    design, disk, _ = places
    _coco(disk / "coco")
    with pytest.raises(DesignError, match=r"tasks\.datasets\.detection\.dataset.*outside the design's folder"):
        load_design(_write_design(design, str(disk / "coco")))
    for roots, folder in (([str(disk)], disk), (["../disk"], disk), ([str(disk / "coco")], disk / "coco")):
        d = load_design(_write_design(design, str(disk / "coco"), roots))  # absolute, relative to the design file
        assert d.confine_paths == DataRoots((folder.resolve(),))
        assert d.spec.design.data_roots == roots


def test_a_dataset_inside_the_design_folder_loads_without_data_roots(places):
    design, _, _ = places
    _coco(design / "data" / "coco")
    d = load_design(_write_design(design, "data/coco"))
    assert d.confine_paths is True
    assert "data_roots" not in d.data["design"]  # a design without the key keeps its content (and fingerprint)


def test_a_data_root_that_is_not_a_folder_is_refused(places):
    design = places[0]
    _coco(design / "data" / "coco")
    with pytest.raises(DesignError, match=r"design\.data_roots\[0\]' = \"\.\./nowhere\": not a folder"):
        load_design(_write_design(design, "data/coco", ["../nowhere"]))


def test_coco_file_name_with_dotdot_out_of_every_root_is_refused_naming_the_file(places):
    design, disk, outside = places
    Image.fromarray(np.zeros((SIDE, SIDE), np.uint8)).save(outside / "f.png")
    _coco(disk / "coco", file_names=["f0.png", "f1.png", "../../../outside/f.png"])
    with pytest.raises(DesignError) as err:
        load_design(_write_design(design, str(disk / "coco"), [str(disk)]))
    msg = str(err.value)
    assert "/../../../outside/f.png'" in msg and f"resolves to {(outside / 'f.png').resolve()}," in msg
    assert "outside the design's folder" in msg and "data_roots" in msg
    # the same file_name inside the design folder's own dataset (no data_roots) is refused as well
    _coco(design / "coco", file_names=["f0.png", "f1.png", "../../../outside/f.png"])
    with pytest.raises(DesignError, match=r"outside/f\.png"):
        load_design(_write_design(design, "coco"))
    # ... and a '../' that stays inside the root is fine
    _coco(disk / "coco2", file_names=["f0.png", "sub/../f1.png", "f2.png"])
    load_design(_write_design(design, str(disk / "coco2"), [str(disk)]))


def test_a_frame_inside_a_root_that_links_out_of_it_is_refused(places):
    design, disk, outside = places
    _coco(disk / "coco", n=3)
    Image.fromarray(np.zeros((SIDE, SIDE), np.uint8)).save(outside / "secret.png")
    os.unlink(disk / "coco" / "frames" / "f1.png")
    os.symlink(outside / "secret.png", disk / "coco" / "frames" / "f1.png")
    with pytest.raises(DesignError, match=r"clip 0: file = .*f1\.png.*resolves to .*secret\.png.*outside"):
        load_design(_write_design(design, str(disk / "coco"), [str(disk)]))
    # listing the link's target folder as a root allows it
    load_design(_write_design(design, str(disk / "coco"), [str(disk), str(outside)]))


def _video(path: Path, seed: int) -> None:
    frames = np.random.default_rng(seed).integers(0, 255, (4, SIDE, SIDE, 3), dtype=np.uint8)
    with imageio.get_writer(str(path), fps=25, codec="libx264", macro_block_size=1, ffmpeg_log_level="error") as w:
        for f in frames:
            w.append_data(f)


def test_a_class_folder_that_links_out_of_the_root_is_refused(places):
    design, disk, outside = places
    (disk / "ucf" / "Jump").mkdir(parents=True)
    (outside / "Run").mkdir()
    _video(disk / "ucf" / "Jump" / "v_Jump_g01.mp4", 0)
    _video(outside / "Run" / "v_Run_g01.mp4", 1)
    os.symlink(outside / "Run", disk / "ucf" / "Run", target_is_directory=True)
    text = cheap_design("ucf").replace("name = 'ucf'\n", f"name = 'ucf'\ndata_roots = [{json.dumps(str(disk))}]\n")
    text += '[tasks.datasets.recognition]\ndataset = { format = "video_folder", root = "../disk/ucf", n_frames = 3 }\n'
    (design / "ucf.toml").write_text(text)
    with pytest.raises(DesignError, match=r"recognition\.dataset: clip 1: file = .*Run/v_Run_g01\.mp4.*outside"):
        load_design(design / "ucf.toml")


def test_weights_kernel_and_outputs_may_live_in_a_data_root(places):
    design, disk, outside = places
    _coco(design / "coco")
    (disk / "kernels").mkdir()
    kernel = {"taps": np.eye(3).tolist(), "pitch_m": 4.86e-6}
    (disk / "kernels" / "k.json").write_text(json.dumps(kernel))
    (outside / "k.json").write_text(json.dumps(kernel))
    base = {"design": {"data_roots": [str(disk)]}, "kernel": {"source": "file", "path": str(disk / "kernels/k.json")}}
    d = parse_design(base, base_dir=design)
    assert d.target.size == 3
    with pytest.raises(DesignError, match=r"kernel\.path.*outside"):
        parse_design({**base, "kernel": {"source": "file", "path": str(outside / "k.json")}}, base_dir=design)
    out = resolve_design_path(design, str(disk / "trained" / "det"), what="train.out", confine=d.confine_paths)
    assert out == (disk / "trained" / "det").resolve()
    with pytest.raises(InputError, match=r"train\.out = .*outside the design's folder .* and its data_roots"):
        resolve_design_path(design, str(outside / "det"), what="train.out", confine=d.confine_paths)


def test_confined_path_at_the_edges(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "ab").mkdir()
    assert confined_path(tmp_path / "a", ".", what="x") == (tmp_path / "a").resolve()
    with pytest.raises(InputError):  # a sibling whose name starts like the root is not inside it
        confined_path(tmp_path / "a", "../ab/f", what="x")
    assert confined_path(tmp_path / "a", "../ab/f", what="x", roots=[tmp_path / "ab"]) == (tmp_path / "ab/f").resolve()
    with pytest.raises(InputError, match="NUL"):
        confined_path(tmp_path, "a\x00b", what="x")


# --------------------------------------------------------------------------- --set inside dataset tables
def test_set_reaches_keys_inside_a_dataset_table(places):
    from fsdvs_hw.cli.explore import parse_overrides
    from fsdvs_hw.design import check_key

    design, disk, _ = places
    _coco(design / "coco", n=4)
    _coco(disk / "coco", n=6)
    d = load_design(_write_design(design, "coco", [str(disk)]))
    assert check_key("tasks.datasets.detection.root") == "tasks.datasets.detection.dataset.root"
    moved = d.with_overrides(
        parse_overrides(
            [
                f"tasks.datasets.detection.root={json.dumps(str(disk / 'coco'))}",  # short for .dataset.root
                "tasks.datasets.detection.dataset.n_frames=3",
                "tasks.datasets.detection.train.epochs_joint=5",
                "tasks.datasets.detection.n_clips=2",
            ]
        )
    )
    table = moved.spec.tasks.datasets["detection"]
    assert table.dataset.root == str(disk / "coco") and table.dataset.n_frames == 3 and table.n_clips == 2
    assert table.train is not None and table.train.epochs_joint == 5 and table.train.epochs_frozen == 2
    assert d.spec.tasks.datasets["detection"].dataset.root == "coco"  # the design itself is unchanged
    # a value out of range is refused by the schema, naming the full key
    with pytest.raises(DesignError, match=r"tasks\.datasets\.detection\.dataset\.n_frames' = 1"):
        d.with_overrides({"tasks.datasets.detection.n_frames": 1})


@pytest.mark.parametrize(
    ("key", "why"),
    [
        ("tasks.datasets.recognition.rooot", "did you mean root"),
        ("tasks.datasets.recognition.train.epoch", "unknown key 'epoch' of train; allowed: batch_size, epochs_frozen"),
        ("tasks.datasets.recognition.n_clips.x", "n_clips is a single value"),
        ("tasks.datasets.recognition.dataset.root.x", "dataset.root is a single value"),
    ],
)
def test_set_refuses_a_key_a_dataset_table_does_not_have(key, why):
    from fsdvs_hw.design import check_key

    with pytest.raises(DesignError, match=why):
        check_key(key)


def test_learn_set_needs_a_design(capsys):
    from fsdvs_hw.cli import main

    assert main(["learn", "recognition", "--set", "tasks.datasets.recognition.n_clips=2"]) == 2
    assert "--set without --design" in capsys.readouterr().err
