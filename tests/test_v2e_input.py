"""The v2e presets read a video as v2e does (OpenCV gray code values / 255, no gamma decoding),
the toolkit's presets as linear light; and, where a v2e source checkout is named by
FSDVS_HW_V2E_SRC, ``simulate --preset v2e-default`` counts within 1 % of v2e's EventEmulator."""

import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.errors import InputError
from fsdvs_hw.scenes.video import example_clip_path, iter_video, v2e_gray
from fsdvs_hw.sensor.eventfiles.eventfile import read_events
from fsdvs_hw.sensor.cameras.presets import preset_input_mapping


def test_v2e_gray_is_opencv_bt601_luma_of_code_values():
    # hand-computed: round(0.299 R + 0.587 G + 0.114 B); no gamma decoding (code 128 stays 128/255)
    rgb = np.array([[[255, 255, 255], [128, 128, 128], [10, 200, 30], [0, 0, 0]]], dtype=np.uint8)
    want = [255, 128, round(0.299 * 10 + 0.587 * 200 + 0.114 * 30), 0]  # 123.8 -> 124
    assert np.array_equal(np.rint(v2e_gray(rgb) * 255).astype(int)[0], want)
    assert v2e_gray(rgb)[0, 1] == pytest.approx(128 / 255)  # linear light would give about 0.21
    with pytest.raises(InputError, match="8-bit"):
        v2e_gray(rgb.astype(np.float32))


def test_presets_choose_their_input_mapping():
    assert {n: preset_input_mapping(n) for n in ("v2e-clean", "v2e-default", "v2e-noisy")} == dict.fromkeys(
        ("v2e-clean", "v2e-default", "v2e-noisy"), "v2e_gray"
    )
    assert {preset_input_mapping(n) for n in ("default", "ideal", "dvs128", "davis346", "imx636")} == {"linear_light"}
    with pytest.raises(InputError, match="unknown"):
        preset_input_mapping("v2e-loud")
    with pytest.raises(InputError, match="input_mapping 'gamma' unknown"):
        next(iter_video(example_clip_path("carphone"), input_mapping="gamma"))


def test_simulate_cli_v2e_preset_reads_code_values_unless_told(tmp_path):
    args = ["simulate", "example:carphone", "--frames", "4", "--preset", "v2e-clean", "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "gray.npz")]) == 0
    assert main([*args, "--out", str(tmp_path / "lin.npz"), "--input-mapping", "linear_light"]) == 0
    gray, lin = read_events(tmp_path / "gray.npz"), read_events(tmp_path / "lin.npz")
    # gamma ~2.4 decoding expands log contrast: linear light gives well over twice the events
    assert len(lin) > 2 * len(gray) > 0


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("FSDVS_HW_V2E_SRC"), reason="FSDVS_HW_V2E_SRC (a v2e source checkout) unset")
@pytest.mark.parametrize("clip", ["bikes", "carphone"])
def test_v2e_default_preset_counts_match_v2e_from_the_same_file(clip, tmp_path, capsys):
    """v2e's own frames (cv2.VideoCapture, BGR2GRAY) through its EventEmulator vs the whole
    ``simulate`` command from the same file; v2e's GUI imports stubbed (benchmarks.sim)."""
    import cv2

    from benchmarks.sim import _V2E_CHILD, _V2E_STUBS, _run_child

    path = example_clip_path(clip)
    cap = cv2.VideoCapture(str(path))
    gray = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        gray.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
    fps = cap.get(cv2.CAP_PROP_FPS)
    cap.release()
    with tempfile.TemporaryDirectory() as d:
        stubs = Path(d) / "stubs"
        stubs.mkdir()
        for name, text in _V2E_STUBS.items():
            (stubs / f"{name}.py").write_text(text)
        np.save(Path(d) / "frames.npy", np.stack(gray).astype(np.float32) / np.float32(255.0))
        child = _V2E_CHILD.replace("k / 25.0", f"k / {fps!r}")  # the clip's own frame times, as v2e's command
        r, _, _ = _run_child(
            [
                sys.executable,
                "-c",
                child,
                str(stubs),
                os.environ["FSDVS_HW_V2E_SRC"],
                "default",
                "1",
                "1",
                "0",
                str(Path(d) / "frames.npy"),
                "cpu",
            ],
            "v2e EventEmulator",
        )
    for dtype in ("float32", "float64"):  # the command's default precision (v2e's) and float64
        out = tmp_path / f"ev_{dtype}.h5"
        args = ["simulate", str(path), "--out", str(out), "--preset", "v2e-default", "--no-progress", "--dtype", dtype]
        assert main(args) == 0
        n = len(read_events(out))
        print(
            f"{clip} {dtype}: fsdvs-hw {n} events, v2e {r['events']}, ratio {n / r['events']:.4f} ({len(gray)} frames)"
        )
        assert abs(n / r["events"] - 1) < 0.01


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("peak", [1.0, 3.7, 1e-40, 1e29])
def test_iter_video_v2e_frames_are_the_bits_of_the_whole_frame_formula(dtype, peak):
    """iter_video converts v2e's gray codes by a 256-entry table; each frame must carry the same
    bits as the frame-wide formula (gray / 255 in float64, times the peak, then the dtype), also
    at the extremes of the allowed peaks (float32 subnormals and zeros at 1e-40, 1e29 below 1e30)."""
    import imageio

    path = example_clip_path("carphone")
    with imageio.get_reader(str(path), "ffmpeg") as reader:
        raw = [np.asarray(f) for _, f in zip(range(4), reader, strict=False)]
    got = [f for _, f in iter_video(path, input_mapping="v2e_gray", dtype=dtype, peak_intensity=peak, n_frames=4)]
    assert len(got) == 4
    for frame, out in zip(raw, got, strict=True):
        lum = v2e_gray(frame)
        lum = np.maximum(lum, 0.0, out=lum)
        if peak != 1.0:
            lum *= peak
        want = lum.astype(dtype)
        assert out.dtype == np.dtype(dtype) and out.shape == want.shape
        assert np.array_equal(out.view(f"u{out.itemsize}"), want.view(f"u{want.itemsize}"))


def test_v2e_mapping_times_frames_at_opencvs_exact_rate():
    """v2e.py reads a video through OpenCV and takes its frame rate; so does the v2e mapping:
    carphone.mp4 is 30000/1001 Hz there (imageio's metadata says 29.97). The frame times are
    i / rate, also through load_video, whose clip carries the same rate."""
    import imageio

    from fsdvs_hw.scenes.video import load_video

    path = example_clip_path("carphone")
    times = [t for t, _ in iter_video(path, input_mapping="v2e_gray", n_frames=5, start_frame=2, stride=3)]
    rate = 30000 / 1001
    assert times == [i / rate for i in (2, 5, 8, 11, 14)]
    with imageio.get_reader(str(path), "ffmpeg") as reader:
        assert reader.get_meta_data()["fps"] == 29.97  # what the linear-light mapping times frames with
    clip = load_video(path, n_frames=5, start_frame=2, stride=3, input_mapping="v2e_gray")
    assert clip.fps == rate and clip.timestamps_s.tolist() == times
