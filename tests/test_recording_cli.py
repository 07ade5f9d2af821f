"""``fsdvs-hw recording info | compare | calibrate`` and the camera presets of ``simulate --preset``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.sensor.eventfiles.eventfile import EventFile, read_events, write_events
from fsdvs_hw.sensor.eventfiles.prophesee import write_prophesee


def _events(n: int = 2000, width: int = 32, height: int = 24, span_us: int = 400_000, seed: int = 0) -> EventFile:
    rng = np.random.default_rng(seed)
    return EventFile(
        np.sort(rng.integers(0, span_us, n)),
        rng.integers(0, width, n),
        rng.integers(0, height, n),
        np.where(rng.random(n) < 0.6, 1, -1).astype(np.int8),
        width,
        height,
    )


def _one_line_error(argv, capsys) -> str:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2, (argv, code, err)
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_info_reports_what_the_file_holds(tmp_path, capsys):
    ev = _events()
    path = write_prophesee(tmp_path / "rec.raw", ev, encoding="evt3")
    path.write_bytes(b"% t0 5000\n" + path.read_bytes())
    assert main(["recording", "info", str(path), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["format"] == "evt3" and (d["width"], d["height"]) == (32, 24) and d["events"] == len(ev)
    assert d["on_fraction"] == pytest.approx(float((ev.p > 0).mean()))
    assert d["first_t_us"] == int(ev.t_us[0]) + 5000 and d["time_offset_us"] == 5000 and d["triggers"] == 0
    assert main(["recording", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "evt3" in out and f"{len(ev)}" in out and "time_offset_us" in out


def test_compare_prints_the_summary(tmp_path, capsys):
    a, b = _events(seed=0), _events(seed=1)
    write_events(tmp_path / "sim.npz", a, 32, 24)
    write_prophesee(tmp_path / "rec.dat", b)
    assert main(["recording", "compare", str(tmp_path / "sim.npz"), str(tmp_path / "rec.dat"), "--bin-ms", "5"]) == 0
    out = capsys.readouterr().out
    for key in ("events", "ON fraction", "rate correlation", "IEI KS statistic"):
        assert key in out
    assert f"{len(a)}" in out
    argv = ["recording", "compare", str(tmp_path / "sim.npz"), str(tmp_path / "rec.dat"), "--json"]
    assert main(argv) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["events_sim"] == len(a) and d["events_real"] == len(b)
    err = _one_line_error([*argv, "--bin-ms", "0"], capsys)
    assert err.startswith("fsdvs-hw recording: error: --bin-ms 0.0: must be a positive")
    err = _one_line_error([*argv, "--bin-ms", "1e-9"], capsys)
    assert "rate bins" in err


def test_bad_files_and_options_are_one_line_errors(tmp_path, capsys):
    (tmp_path / "dir.raw").mkdir()
    assert "is a directory" in _one_line_error(["recording", "info", str(tmp_path / "dir.raw")], capsys)
    bad = tmp_path / "v3.dat"
    bad.write_bytes(b"% Version 3\n\x0c\x08" + bytes(8))
    assert "unsupported DAT version '3'" in _one_line_error(["recording", "info", str(bad)], capsys)
    rec = tmp_path / "rec.npz"
    write_events(rec, _events(), 32, 24)
    for extra, text in (
        (["--n-boot", "3"], "--n-boot 3"),
        (["--level", "1.5"], "--level 1.5"),
        (["--frames", "1"], "--frames 1"),
        (["--seed", "-1"], "--seed -1"),
        (["--duration-s", "2"], "--duration-s: only with --static"),
    ):
        err = _one_line_error(["recording", "calibrate", str(rec), "--video", "example:carphone", *extra], capsys)
        assert text in err, err
    err = _one_line_error(["recording", "calibrate", str(rec), "--video", str(tmp_path / "missing.mp4")], capsys)
    assert "missing.mp4" in err
    assert "--video" in _one_line_error(["recording", "calibrate", str(rec)], capsys)  # --video or --static
    assert "ACTION" in _one_line_error(["recording"], capsys)
    assert "--width 0" in _one_line_error(["recording", "info", str(rec), "--width", "0"], capsys)


def _carphone_recording(tmp_path, frames: int, config_name: str = "ideal", seed: int = 0):
    from fsdvs_hw.scenes.video import load_example_clip
    from fsdvs_hw.sensor import event_list
    from fsdvs_hw.sensor.cameras.presets import sensor_config

    clip = load_example_clip("carphone", n_frames=frames, size=(36, 44))
    ev = event_list(clip.intensity[None], timestamps_s=clip.timestamps_s, config=sensor_config(config_name, seed=seed))
    path = tmp_path / "rec.npz"
    write_events(path, ev, 44, 36)
    return path, clip


def test_calibrate_a_recording_of_a_known_video(tmp_path, capsys):
    """A recording simulated from carphone with the ideal sensor (thresholds 0.2, no mismatch, no
    noise): the verb decodes the same frames at the recording's size and recovers the thresholds."""
    path, _ = _carphone_recording(tmp_path, 30)
    argv = ["recording", "calibrate", str(path), "--video", "example:carphone", "--frames", "30", "--preset", "ideal"]
    assert main([*argv, "--n-boot", "30", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    rows = {r["parameter"]: r for r in d["estimates"]}
    assert rows["threshold_on"]["value"] == pytest.approx(0.2, abs=0.005)
    assert rows["threshold_off"]["value"] == pytest.approx(0.2, abs=0.005)
    assert d["outcome"] in ("fits", "unchecked")
    assert main([*argv, "--n-boot", "30", "--no-check"]) == 0
    assert "threshold_on" in capsys.readouterr().out


def test_calibrate_refuses_a_recording_longer_than_the_video(tmp_path, capsys):
    """The same validation as the library: a recording past the video's span is refused, one line."""
    path, _ = _carphone_recording(tmp_path, 30)
    ev = read_events(path)
    ev.t_us = ev.t_us + 3_000_000  # 3 s after the video ends
    write_events(path, ev, 44, 36)
    err = _one_line_error(
        ["recording", "calibrate", str(path), "--video", "example:carphone", "--frames", "30", "--preset", "ideal"],
        capsys,
    )
    assert err.startswith("fsdvs-hw recording: error:") and "video" in err


@pytest.mark.parametrize("preset", ["imx636", "davis346", "dvs128"])
def test_simulate_offers_the_camera_presets(tmp_path, preset):
    from fsdvs_hw.scenes.video import load_example_clip
    from fsdvs_hw.sensor import event_list
    from fsdvs_hw.sensor.cameras.presets import preset_input_mapping, sensor_config

    out = tmp_path / "ev.npz"
    argv = ["simulate", "example:carphone", "--out", str(out), "--frames", "4", "--size", "24x32"]
    assert main([*argv, "--preset", preset, "--no-progress"]) == 0
    clip = load_example_clip("carphone", n_frames=4, size=(24, 32), input_mapping=preset_input_mapping(preset))
    want = event_list(
        clip.intensity[None].astype("float32"), timestamps_s=clip.timestamps_s, config=sensor_config(preset, seed=0)
    )
    got = read_events(out)
    assert len(got) == len(want)
    assert np.array_equal(got.t_us, np.rint(want.t.numpy() * 1e6).astype(np.int64))
    assert np.array_equal(got.x, want.x.numpy()) and np.array_equal(got.p, want.p.numpy())


def test_calibrate_static_scene_noise_rates(tmp_path, capsys):
    """A static scene with shot noise 2 Hz per pixel and no leak: --static fits the noise rates."""
    import torch

    from fsdvs_hw.sensor import SensorConfig, event_list

    cfg = SensorConfig.ideal(0.2, shot_noise_rate_hz=2.0, seed=3)
    ev = event_list(torch.full((1, 2, 16, 16), 0.5), config=cfg, timestamps_s=torch.tensor([0.0, 20.0]))
    path = tmp_path / "static.npz"
    write_events(path, ev, 16, 16)
    argv = ["recording", "calibrate", str(path), "--static", "--duration-s", "20", "--n-boot", "50", "--json"]
    assert main(argv) == 0
    rows = {r["parameter"]: r for r in json.loads(capsys.readouterr().out)["estimates"]}
    shot = rows["shot_noise_rate_hz"]
    assert shot["low"] <= 2.0 <= shot["high"] and shot["value"] == pytest.approx(2.0, rel=0.15)
