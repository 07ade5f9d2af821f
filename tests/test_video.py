"""Real-video loading: transfer functions, luminance weights, bundled clips, errors."""

from __future__ import annotations

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.scenes.video import display_to_linear, load_example_clip, load_video


def test_display_to_linear_matches_published_transfer_functions_and_weights():
    # BT.709 luminance weights (ITU-R BT.709-6): Y = 0.2126 R + 0.7152 G + 0.0722 B
    rgb = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255], [0, 0, 0]], dtype=np.uint8)
    y = display_to_linear(rgb, transfer="sRGB", colourspace="sRGB")
    np.testing.assert_allclose(y, [0.2126, 0.7152, 0.0722, 1.0, 0.0], atol=2e-4)
    # sRGB decoding (IEC 61966-2-1): V = 0.5 -> ((0.5 + 0.055) / 1.055) ** 2.4 = 0.21404
    assert display_to_linear(np.array([0.5]), transfer="sRGB")[0] == pytest.approx(0.214041, abs=1e-6)
    # BT.1886 with zero black level is a pure 2.4 power law
    assert display_to_linear(np.array([0.5]), transfer="ITU-R BT.1886")[0] == pytest.approx(0.5**2.4, rel=1e-6)
    # 10-bit code values scale by 1023
    assert display_to_linear(np.array([1023], dtype=np.uint16), bit_depth=10, transfer="sRGB")[0] == pytest.approx(1.0)


def test_load_bundled_clip_gives_linear_luminance_and_timestamps():
    clip = load_example_clip("carphone", n_frames=5, stride=2, peak_intensity=0.5)
    assert clip.intensity.shape == (5, 144, 176)
    assert clip.intensity.dtype == np.float64
    assert 0.0 <= clip.intensity.min() and clip.intensity.max() <= 0.5 + 1e-9
    np.testing.assert_allclose(np.diff(clip.timestamps_s), 2 / clip.fps)
    assert clip.fps == pytest.approx(29.97, abs=0.01)
    # linear light is darker than code values for mid-greys (gamma 2.4): mean well below 0.5 * mean code
    assert clip.intensity.mean() < 0.5 * 0.5


def test_video_file_roundtrip_decodes_grey_level(tmp_path):
    import imageio

    path = tmp_path / "grey.mp4"
    frames = np.full((4, 64, 64, 3), 128, dtype=np.uint8)
    frames[2:, 16:48, 16:48] = 200  # a brighter square appears
    with imageio.get_writer(str(path), fps=20, quality=10, macro_block_size=16) as w:
        for f in frames:
            w.append_data(f)
    clip = load_video(path, n_frames=4, transfer="sRGB", colourspace="sRGB")
    expected_grey = ((128 / 255 + 0.055) / 1.055) ** 2.4
    assert np.median(clip.intensity[0]) == pytest.approx(expected_grey, abs=0.01)
    assert clip.intensity[3, 32, 32] > 2 * clip.intensity[0, 32, 32]
    resized = load_video(path, n_frames=4, size=(16, 16), transfer="sRGB", colourspace="sRGB")
    assert resized.intensity.shape == (4, 16, 16)
    # area resizing in linear light preserves the mean luminance
    assert resized.intensity.mean() == pytest.approx(clip.intensity.mean(), rel=0.02)


def test_real_clip_through_the_simulator():
    import torch

    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.sensor import SensorConfig, event_frames

    clip = load_example_clip("bikes", n_frames=9, size=(68, 160))
    video = clip.as_batch(dtype=torch.float32)
    frames = event_frames(
        video, reference_kernel("dog", 7), config=SensorConfig.ideal(), timestamps_s=clip.timestamps_s
    )
    assert frames.shape == (1, 8, 2, 68, 160)
    assert frames[:, :, 0].sum() > 100 and frames[:, :, 1].sum() > 100  # moving cyclists: both polarities


def test_video_errors_name_the_problem(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_video(tmp_path / "missing.mp4")
    with pytest.raises(InputError, match="example clip"):
        load_example_clip("nope")
    with pytest.raises(InputError, match="transfer"):
        display_to_linear(np.array([0.5]), transfer="gamma-ish")
    with pytest.raises(InputError, match="colourspace"):
        load_example_clip("carphone", n_frames=2, colourspace="Martian RGB")
    with pytest.raises(InputError, match="has only"):
        load_example_clip("carphone", n_frames=5, start_frame=10_000)
    with pytest.raises(InputError, match="n_frames"):
        load_example_clip("carphone", n_frames=1)
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video")
    with pytest.raises(InputError, match="cannot be decoded"):
        load_video(bad)
