"""Clip sampling as the field does it (fsdvs_hw.tasks.clip_sampling): start frames, aspect-preserving crop, flip.

The aspect test uses a known pattern: a disk drawn on a 320 x 240 frame must stay a disk (as
wide as high) when the frame becomes 64 x 64 through the aspect-preserving resize and centre
crop, where the plain resize squashes it to an ellipse 0.75 as wide as high. The video tests
write a real H.264 clip whose brightness encodes the frame index, so the start frame of each
decoded clip can be read back from its pixels.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.tasks.clip_sampling import (
    SampledVideoClips,
    SamplingSpec,
    crop_offset,
    even_starts,
    random_starts,
    resize_crop,
    short_side_size,
)

imageio = pytest.importorskip("imageio")

N_VIDEO_FRAMES = 40


def _disk_frame(h: int = 240, w: int = 320, radius: float = 80.0) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w]
    return ((yy - (h - 1) / 2) ** 2 + (xx - (w - 1) / 2) ** 2 <= radius**2).astype(np.float64)


def _extent(mask: np.ndarray) -> tuple[int, int]:
    """(rows, columns) covered by the pixels above one half."""
    on = mask > 0.5
    return int(on.any(axis=1).sum()), int(on.any(axis=0).sum())


def test_even_starts_are_segment_centres_and_stay_inside():
    assert even_starts(100, 10, 1).tolist() == [45]
    starts = even_starts(100, 10, 4)
    assert starts.tolist() == sorted(starts.tolist())
    assert np.all(np.diff(starts) >= 22) and starts[0] >= 0 and starts[-1] <= 90
    for n, span, k in ((10, 10, 5), (11, 10, 3), (500, 16, 100)):
        s = even_starts(n, span, k)
        assert s.min() >= 0 and s.max() + span <= n and len(s) == k
    with pytest.raises(InputError, match="fewer than one clip"):
        even_starts(5, 8, 1)


def test_random_starts_are_seeded_and_cover_the_range():
    a = random_starts(50, 10, 2000, np.random.default_rng(3))
    b = random_starts(50, 10, 2000, np.random.default_rng(3))
    assert a.tolist() == b.tolist()
    assert a.min() == 0 and a.max() == 40  # every start 0 … n - span is reachable, none beyond
    assert random_starts(50, 10, 5, np.random.default_rng(4)).tolist() != a[:5].tolist()


def test_short_side_size_keeps_the_aspect():
    assert short_side_size(240, 320, (64, 64)) == (64, 85)
    assert short_side_size(320, 240, (64, 64)) == (85, 64)
    assert short_side_size(240, 320, (112, 112)) == (112, 149)
    assert short_side_size(64, 64, (64, 64)) == (64, 64)
    assert crop_offset(64, 85, (64, 64)) == (0, 10)
    assert crop_offset(64, 85, (64, 64), (0.0, 0.0)) == (0, 0)
    assert crop_offset(64, 85, (64, 64), (0.0, 0.999)) == (0, 20)


def test_a_320x240_disk_stays_round_at_64x64_with_a_centre_crop():
    from skimage.transform import resize

    frame = _disk_frame()
    out = resize_crop(frame[None], (64, 64))[0]
    rows, cols = _extent(out)
    assert out.shape == (64, 64)
    assert abs(rows - cols) <= 1  # round: as wide as high
    assert rows == pytest.approx(160 * 64 / 240, abs=1.5)  # scaled by 64/240 = the short side's factor
    centre = np.argwhere(out > 0.5).mean(axis=0)
    assert centre == pytest.approx([31.5, 31.5], abs=0.6)  # the centre crop keeps it centred
    squashed = resize(frame, (64, 64), anti_aliasing=True, preserve_range=True)
    s_rows, s_cols = _extent(squashed)
    assert s_cols / s_rows == pytest.approx(0.75, abs=0.04)  # what the plain resize did


def test_flip_mirrors_the_crop():
    frame = np.zeros((1, 240, 320))
    frame[:, :, :100] = 1.0  # the left part bright
    out = resize_crop(frame, (64, 64))
    flipped = resize_crop(frame, (64, 64), flip=True)
    np.testing.assert_array_equal(flipped, out[:, :, ::-1])
    assert out[0, :, 0].mean() > 0.9 and flipped[0, :, -1].mean() > 0.9


def test_spec_bounds():
    with pytest.raises(InputError, match="clips_per_video"):
        SamplingSpec(clips_per_video=0)
    with pytest.raises(InputError, match="train_clips_per_video"):
        SamplingSpec(train_clips_per_video=101)
    with pytest.raises(InputError, match="resize"):
        SamplingSpec(resize="squash")
    with pytest.raises(InputError, match="train_crop"):
        SamplingSpec(train_crop="corner")


# --------------------------------------------------------------------------- real videos
def _write_video(path: Path, n: int = N_VIDEO_FRAMES, fps: float = 25.0) -> None:
    """A 320 x 240 H.264 video: frame i is grey 40 + 4 i with a bright disk at its centre."""
    disk = _disk_frame(radius=60.0) > 0
    with imageio.get_writer(str(path), fps=fps, codec="libx264", quality=9, ffmpeg_log_level="error") as w:
        for i in range(n):
            img = np.full((240, 320), 40 + 4 * i, np.uint8)
            img[disk] = 250
            w.append_data(np.repeat(img[..., None], 3, axis=2))


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    from fsdvs_hw.scenes.datasets import VideoFolderDataset

    root = tmp_path_factory.mktemp("sampled")
    for cls in ("A", "B"):
        (root / cls).mkdir()
        _write_video(root / cls / f"v_{cls}.mp4")
    return VideoFolderDataset(root, n_frames=4, stride=2, transfer="sRGB")


def _start_of(clip) -> float:
    """The frame index read back from the first frame's grey (the corner, away from the disk)."""
    from fsdvs_hw.scenes.datasets import code_to_linear

    lut = code_to_linear(np.arange(256, dtype=np.uint8)[None])[0]
    code = float(np.interp(clip.frames[0, :6, :6].mean(), lut, np.arange(256)))
    return (code - 40) / 4


def test_test_clips_are_evenly_spaced_centre_cropped_and_round(videos):
    clips = SampledVideoClips(videos, (64, 64), SamplingSpec(clips_per_video=3))
    assert len(clips) == 6 and clips.video_of.tolist() == [0, 0, 0, 1, 1, 1]
    span = (4 - 1) * 2 + 1
    want = even_starts(N_VIDEO_FRAMES, span, 3).tolist()
    got = [clips.placement(j)["start"] for j in range(3)]
    assert got == want
    for j in range(3):
        clip = clips[j]
        assert clip.frames.shape == (4, 64, 64) and clip.metadata["crop"] == (0, 10)
        assert _start_of(clip) == pytest.approx(want[j], abs=0.6)
        rows, cols = _extent(clip.frames[0] > 0.5)
        assert abs(rows - cols) <= 1 and rows == pytest.approx(120 * 64 / 240, abs=2)
    assert int(clips[4].targets["motion"]) == 1


def test_training_clips_are_seeded_per_epoch_and_independent_of_order(videos):
    spec = SamplingSpec(train_clips_per_video=4, seed=7)
    a = SampledVideoClips(videos, (64, 64), spec, train=True)
    b = SampledVideoClips(videos, (64, 64), spec, train=True)
    order = list(range(len(a)))
    first = [a.placement(j) for j in order]
    assert [b.placement(j) for j in reversed(order)] == first[::-1]  # no hidden state: any worker, any order
    a.epoch = 1
    assert [a.placement(j) for j in order] != first
    flips = []
    for epoch in range(5):
        a.epoch = epoch
        flips += [a.placement(j)["flip"] for j in order]
    assert 0 < sum(flips) < len(flips)
    a.epoch = 0
    clip = a[0]
    at = a.placement(0)
    assert _start_of(clip) == pytest.approx(at["start"], abs=0.6)
    assert clip.frames.shape == (4, 64, 64) and clip.metadata["crop"] == (0, int(21 * at["where"][1]))


def test_other_formats_are_refused_by_name(tmp_path):
    with pytest.raises(InputError, match="video_folder"):
        SampledVideoClips(object(), (64, 64), SamplingSpec())
