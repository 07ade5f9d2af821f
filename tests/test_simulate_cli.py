"""``fsdvs-hw simulate``: a real clip streamed to an event file equals the whole-clip simulation."""

import numpy as np
import pytest
import torch

from fsdvs_hw.cli import main
from fsdvs_hw.scenes.video import load_example_clip
from fsdvs_hw.sensor import SensorConfig, event_list
from fsdvs_hw.sensor.eventfiles.eventfile import read_events


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_simulate_cli_writes_the_whole_clip_events(tmp_path, capsys, dtype):
    out = tmp_path / "carphone.npz"
    rc = main(
        [
            "simulate",
            "example:carphone",
            "--out",
            str(out),
            "--frames",
            "6",
            "--size",
            "36x44",
            "--preset",
            "v2e-noisy",
            "--chunk-frames",
            "2",
            "--no-progress",
            "--seed",
            "4",
            "--dtype",
            dtype,
        ]
    )
    assert rc == 0
    ev = read_events(out)
    clip = load_example_clip("carphone", n_frames=6, size=(36, 44), input_mapping="v2e_gray")  # the v2e preset's
    want = event_list(  # the in-memory run in the same precision: the same events, to the microsecond
        clip.intensity[None].astype(dtype),
        timestamps_s=clip.timestamps_s,
        config=SensorConfig.preset("v2e-noisy", seed=4),
    )
    assert (ev.width, ev.height) == (44, 36) and len(ev) == len(want) > 100
    assert np.array_equal(ev.t_us, np.rint(want.t.numpy() * 1e6).astype(np.int64))
    assert np.array_equal(ev.x, want.x.numpy()) and np.array_equal(ev.p, want.p.numpy())
    assert f"{len(want)} events" in capsys.readouterr().out


def test_simulate_cli_bad_output_is_one_line_error(tmp_path, capsys):
    assert main(["simulate", "example:carphone", "--out", str(tmp_path / "ev.txt")]) == 2
    assert "suffix" in capsys.readouterr().err
    assert main(["simulate", str(tmp_path / "missing.mp4"), "--out", str(tmp_path / "ev.h5")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_simulate_cli_creates_the_output_folder(tmp_path):
    out = tmp_path / "new" / "folder" / "ev.npz"
    assert main(["simulate", "example:carphone", "--out", str(out), "--frames", "3", "--size", "36x44"]) == 0
    assert out.is_file()
