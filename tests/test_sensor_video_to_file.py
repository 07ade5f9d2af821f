"""A video file to an event file through the library (fsdvs_hw.sensor.eventfiles.video_to_file), as
the ``simulate`` command runs it."""

from __future__ import annotations

import gc
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.errors import KernelError
from fsdvs_hw.scenes.video import example_clip_path
from fsdvs_hw.sensor import SensorConfig
from fsdvs_hw.sensor.eventfiles.eventfile import read_events
from fsdvs_hw.sensor.eventfiles.video_to_file import (
    VideoToFileOptions,
    frame_size,
    prefetch_frame_count,
    progress_total,
    simulate_video_to_file,
)


def _options(out: Path, **changes) -> VideoToFileOptions:
    values = dict(
        out=out,
        preset="default",
        kernel=None,
        start_frame=0,
        frames=3,
        size=(12, 16),
        peak_intensity=1.0,
        allow_truncated=False,
        input_mapping="linear_light",
        dtype="float32",
        upsample="none",
        upsample_rate=400.0,
        threads=None,
        chunk_frames=None,
        progress=False,
    )
    values.update(changes)
    return VideoToFileOptions(**values)


def test_the_library_run_writes_what_the_command_writes(tmp_path):
    gc.unfreeze()
    n, n_on, wall = simulate_video_to_file(
        _options(tmp_path / "lib.npz"), example_clip_path("carphone"), SensorConfig.preset("default", seed=0)
    )
    assert gc.get_freeze_count() == 0  # the run undoes its own freeze
    rc = main(
        ["simulate", "example:carphone", "--out", str(tmp_path / "cli.npz"), "--frames", "3", "--size", "12x16"]
        + ["--no-progress"]
    )
    assert rc == 0 and wall >= 0 and n > 0  # events to compare
    lib, cli = read_events(tmp_path / "lib.npz"), read_events(tmp_path / "cli.npz")
    assert len(lib.t_us) == n and int((lib.p > 0).sum()) == n_on
    for name in ("t_us", "x", "y", "p"):
        np.testing.assert_array_equal(getattr(lib, name), getattr(cli, name), err_msg=name)


def test_a_failed_run_leaves_no_file(tmp_path):
    out = tmp_path / "e.npz"
    with pytest.raises(KernelError, match="no-such-kernel"):  # raised after the writer was opened
        simulate_video_to_file(
            _options(out, kernel="no-such-kernel"), example_clip_path("carphone"), SensorConfig.preset("default")
        )
    assert not out.exists() and not any(tmp_path.iterdir())


def test_frame_size_prefetch_and_progress_total():
    assert frame_size({"source_size": (640, 272)}, None) == (272, 640)
    assert frame_size({}, (30, 40)) == (30, 40)
    assert prefetch_frame_count(None, "float32") == 8
    assert prefetch_frame_count((4000, 4000), "float64") == 2
    assert prefetch_frame_count((1, 1), "float32") == 256
    opts = _options(Path("e.npz"), frames=None, start_frame=5)
    assert progress_total(opts, {"nframes": 25, "fps": 25.0}) == 20
    assert progress_total(opts, {}) is None
    up = _options(Path("e.npz"), frames=11, upsample="linear", upsample_rate=100.0)
    assert progress_total(up, {"nframes": 25, "fps": 25.0}) == 41  # 10 intervals x 4 + 1
