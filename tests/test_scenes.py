"""Synthetic scenes: determinism, ground truth consistency, contrast physics, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.scenes.synthetic import (
    MOTION_CLASSES,
    SHAPE_CLASSES,
    SceneConfig,
    _noise_1f,
    is_sub_threshold,
    make_scenes,
)

SMALL = SceneConfig(height_px=24, width_px=24, radius_px=(3.0, 5.0))


def test_deterministic_by_seed_and_independent_of_count():
    a = make_scenes(SMALL, 6, seed=3)
    b = make_scenes(SMALL, 6, seed=3)
    c = make_scenes(SMALL, 6, seed=4)
    d = make_scenes(SMALL, 2, seed=3)
    assert np.array_equal(a.video, b.video) and np.array_equal(a.masks, b.masks)
    assert not np.array_equal(a.video, c.video)
    assert np.array_equal(a.video[:2], d.video) and np.array_equal(a.boxes[:2], d.boxes, equal_nan=True)


def test_shapes_and_positivity():
    b = make_scenes(SMALL.with_(n_frames=4, n_objects=(2, 3)), 5, seed=0)
    assert b.video.shape == (5, 4, 24, 24) and b.masks.shape == (5, 4, 24, 24)
    assert b.boxes.shape == (5, 4, 3, 4) and b.labels.shape == (5, 3)
    assert np.all(b.video > 0) and np.all(np.isfinite(b.video))
    assert set(np.unique(b.masks)) <= set(range(1 + len(SHAPE_CLASSES)))
    n_obj = (b.labels >= 0).sum(axis=1)
    assert np.all((n_obj >= 2) & (n_obj <= 3))
    np.testing.assert_allclose(b.timestamps_s, np.arange(4) / 100.0)


def test_flat_background_edge_contrast_and_illuminance():
    cfg = SMALL.with_(background="flat", edge_contrast=0.1, contrast_sign="negative", illuminance=2.5, n_objects=(1, 1))
    b = make_scenes(cfg, 3, seed=1)
    v = b.video[:, -1]
    inside = b.masks[:, -1] > 0
    # fully covered pixels have I = L (1 + c); uncovered ones exactly L
    assert np.isclose(v[inside].min(), 2.5 * 0.9)
    far = v[~inside]
    assert np.isclose(np.median(far), 2.5)
    assert np.all(v >= 2.5 * 0.9 - 1e-12) and np.all(v <= 2.5 + 1e-12)
    assert np.allclose(b.contrast[:, 0], -0.1)


def test_boxes_enclose_masks_single_object():
    b = make_scenes(SMALL.with_(background="flat", n_objects=(1, 1)), 4, seed=2)
    for i in range(4):
        for t in range(b.video.shape[1]):
            ys, xs = np.nonzero(b.masks[i, t])
            np.testing.assert_array_equal(b.boxes[i, t, 0], [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1])
            assert b.masks[i, t][ys[0], xs[0]] == b.labels[i, 0] + 1


@pytest.mark.parametrize("motion", ["right", "left", "down", "up", "expand", "contract"])
def test_motion_classes_move_as_named(motion):
    cfg = SMALL.with_(motion="classes", background="flat", speed_px_per_frame=1.5, n_frames=5)
    b = make_scenes(cfg, 40, seed=0)
    k = MOTION_CLASSES.index(motion)
    sel = np.nonzero(b.motion == k)[0]
    assert sel.size > 0
    box = b.boxes[sel[0], :, 0]
    cx, cy = 0.5 * (box[:, 0] + box[:, 2]), 0.5 * (box[:, 1] + box[:, 3])
    width = box[:, 2] - box[:, 0]
    d = {"right": cx, "left": -cx, "down": cy, "up": -cy, "expand": width, "contract": -width}[motion]
    assert d[-1] - d[0] >= 3.0  # 4 frame steps at 1.5 px/frame (boxes are whole pixels)


def test_all_motion_classes_drawn():
    b = make_scenes(SMALL.with_(motion="classes"), 120, seed=0)
    assert set(np.unique(b.motion)) == set(range(len(MOTION_CLASSES)))
    assert np.all(b.labels[:, 0] >= 0)


def test_sub_threshold_edges():
    assert is_sub_threshold(0.15, 0.2)  # log 1.15 = 0.140
    assert not is_sub_threshold(0.25, 0.2)  # log 1.25 = 0.223
    assert not is_sub_threshold(0.2, 0.2)  # dark side: -log 0.8 = 0.223 > 0.2
    assert is_sub_threshold(0.18, 0.2)  # -log 0.82 = 0.198
    with pytest.raises(InputError):
        is_sub_threshold(0.0, 0.2)


def test_noise_1f_spectrum_slope():
    rng = np.random.default_rng(0)
    n = _noise_1f(rng, 128, 128, 1.0)
    assert abs(n.mean()) < 1e-9 and math.isclose(n.std(), 1.0)
    p = np.abs(np.fft.fft2(n)) ** 2
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(128), np.fft.fftfreq(128), indexing="ij"))
    sel = (f > 0.02) & (f < 0.4)
    slope = np.polyfit(np.log(f[sel]), np.log(p[sel]), 1)[0]
    assert -2.2 < slope < -1.8  # power ~ 1/f^(2 alpha)


def test_skimage_background_and_pan():
    cfg = SMALL.with_(background="camera", texture_contrast=0.2, background_speed_px_per_frame=1.0, edge_contrast=0.05)
    b = make_scenes(cfg, 2, seed=0)
    bg = b.masks == 0
    # the camera pans: background pixels change between frames
    diff = np.abs(b.video[:, 0] - b.video[:, -1])[bg[:, 0] & bg[:, -1]]
    assert diff.mean() > 0.01
    static = make_scenes(cfg.with_(background_speed_px_per_frame=0.0), 2, seed=0)
    sbg = (static.masks[:, 0] == 0) & (static.masks[:, -1] == 0)
    # static camera: all background except the objects' anti-aliased rims stays identical
    assert np.mean(static.video[:, 0][sbg] == static.video[:, -1][sbg]) > 0.8
    rel = static.video[:, 0][static.masks[:, 0] == 0]
    assert 0.1 < rel.std() / rel.mean() < 0.3


@pytest.mark.parametrize(
    "change, word",
    [
        ({"height_px": 4}, "height_px"),
        ({"edge_contrast": 0.0}, "edge_contrast"),
        ({"edge_contrast": float("nan")}, "edge_contrast"),
        ({"background": "moon2"}, "background"),
        ({"radius_px": (3.0, 20.0)}, "radius_px"),
        ({"n_objects": (0, 2)}, "n_objects"),
        ({"motion": "spin"}, "motion"),
        ({"edge_contrast": 1.5}, "edge_contrast"),
    ],
)
def test_bad_config(change, word):
    with pytest.raises(InputError, match=word):
        SMALL.with_(**change)


def test_bad_counts_and_roundtrip():
    with pytest.raises(InputError, match="n_clips"):
        make_scenes(SMALL, 0)
    with pytest.raises(InputError, match="seed"):
        make_scenes(SMALL, 1, seed=-1)
    assert SceneConfig.from_dict(SMALL.to_dict()) == SMALL
    with pytest.raises(InputError, match="unknown"):
        SceneConfig.from_dict({"colour": 1})
