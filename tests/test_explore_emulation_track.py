"""Task accuracy on the sensor-in-the-loop emulation track (display + recapture), end to end."""

from __future__ import annotations

from pathlib import Path

import pytest

from fsdvs_hw.kernels import load_kernel

KERNELS = Path(__file__).parents[1] / "designs" / "kernels"
REC = KERNELS / "learned_recognition_7x7.safetensors"


def test_events_fn_is_what_the_network_sees():
    import torch

    from fsdvs_hw.tasks import evaluate_kernel

    k = load_kernel(KERNELS / "learned_recognition_7x7.json")
    sim = evaluate_kernel(k, "recognition", REC, n_test=64)

    def no_events(video, kernel_taps, sensor, timestamps_s):
        b, t, h, w = video.shape
        return torch.zeros(b, t - 1, 2, h, w, dtype=video.dtype)

    blind = evaluate_kernel(k, "recognition", REC, n_test=64, events_fn=no_events)
    assert blind.event_rate == 0.0 and sim.event_rate > 0
    assert blind.value < sim.value  # a network that sees no events cannot keep its accuracy


def test_task_scores_on_both_tracks():
    from fsdvs_hw.design.display_settings import DisplaySettings
    from fsdvs_hw.explore.scoring import task_scores

    k = load_kernel(KERNELS / "learned_recognition_7x7.json")
    out = task_scores(k, {"recognition": REC}, n_test=64, tracks=("simulator", "emulation"))
    sim, emu = out["recognition"]["simulator"], out["recognition"]["emulation"]
    assert out["status"] == "ok" and sim["status"] == emu["status"] == "ok"
    assert 0.0 <= emu["metric"] <= 1.0
    # the emulation recaptures a displayed, re-quantised video: close to, not identical with, in-pixel
    assert emu["event_rate"] != sim["event_rate"]
    assert emu["event_rate"] == pytest.approx(sim["event_rate"], rel=0.5)
    # a 1-bit display destroys the filtered image's grey levels: far fewer usable events
    coarse = task_scores(
        k, {"recognition": REC}, n_test=64, tracks=("emulation",), display=DisplaySettings(bits=1, upsample_factor=1)
    )
    assert coarse["recognition"]["emulation"]["event_rate"] != emu["event_rate"]


def test_unknown_track_is_a_clear_error():
    from fsdvs_hw.errors import InputError
    from fsdvs_hw.explore.scoring import task_scores

    k = load_kernel(KERNELS / "learned_recognition_7x7.json")
    with pytest.raises(InputError, match="track"):
        task_scores(k, {"recognition": REC}, n_test=8, tracks=("hardware",))
