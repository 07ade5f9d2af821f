"""SensorConfig.conventions: v2e's event-generation rules beside the native model; defaults unchanged."""

from __future__ import annotations

import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import SensorConfig, event_frames, event_list


def _step(level=2.0, frames=2):
    video = torch.ones(1, frames, 1, 2)
    video[:, 1:, :, 1] = level
    return video


def test_default_conventions_are_native_and_absent_from_the_stored_dict():
    assert SensorConfig().conventions == "native"
    assert "conventions" not in SensorConfig().to_dict()  # fingerprints of stored results unchanged
    v2e = SensorConfig(conventions="v2e")
    assert v2e.to_dict()["conventions"] == "v2e" and SensorConfig.from_dict(v2e.to_dict()) == v2e
    with pytest.raises(InputError, match="conventions: 'esim' unknown; allowed: native, v2e"):
        SensorConfig(conventions="esim")


def test_events_on_the_frame_grid_not_at_the_crossings():
    """log 2 = 0.693 at C = 0.2: three crossings; native times interpolate the ramp (at 0.2/0.693,
    0.4/0.693, 0.6/0.693 of the interval), v2e's are the grid i·Δt/3."""
    ts = [0.0, 0.03]
    nat = event_list(_step(), config=SensorConfig.ideal(0.2), timestamps_s=ts)
    v2e = event_list(_step(), config=SensorConfig.ideal(0.2, conventions="v2e"), timestamps_s=ts)
    assert nat.t.tolist() == pytest.approx([0.03 * k * 0.2 / 0.6931471805599453 for k in (1, 2, 3)])
    assert v2e.t.tolist() == pytest.approx([0.01, 0.02, 0.03])
    assert v2e.x.tolist() == [1, 1, 1] and v2e.p.tolist() == [1, 1, 1]


def test_refractory_delays_instead_of_dropping():
    """Three crossings in one frame, a refractory period longer than the frame: native emits one
    and loses two; v2e emits one per frame until the crossings are all out."""
    video = torch.ones(1, 5, 1, 1)
    video[:, 1:] = 2.0
    ts = [0.0, 0.01, 0.02, 0.03, 0.04]
    nat = event_list(video, config=SensorConfig.ideal(0.2, refractory_s=0.008), timestamps_s=ts)
    v2e = event_list(video, config=SensorConfig.ideal(0.2, refractory_s=0.008, conventions="v2e"), timestamps_s=ts)
    assert len(nat) == 1
    # frame 1: one event at 0.01/3; frame 2 (two pending, grid 0.005): one at 0.015, the next 5 ms
    # later is inside the period; frame 3: the last one at 0.03. No crossing is lost.
    assert v2e.t.tolist() == pytest.approx([0.01 / 3, 0.015, 0.03])


def test_shot_noise_rate_falls_with_intensity_and_resets_the_reference():
    """v2e: rate (r/2)(1 - 0.75 i) per polarity, i = (I + dark) / full scale."""
    ts = torch.linspace(0, 40.0, 4001, dtype=torch.float64)
    rates = {}
    for level in (0.0, 0.9):
        video = torch.full((1, ts.numel(), 8, 8), level)
        cfg = SensorConfig.ideal(0.2, shot_noise_rate_hz=2.0, conventions="v2e", dark_intensity=0.1, seed=1)
        ev = event_list(video, config=cfg, timestamps_s=ts)
        rates[level] = len(ev) / (64 * 40.0)
    assert rates[0.0] == pytest.approx(2.0 * (1 - 0.75 * 0.1), rel=0.08)
    assert rates[0.9] == pytest.approx(2.0 * (1 - 0.75 * 1.0), rel=0.15)
    # a noise event sets the reference to the signal, which clears the leak drift: with a reset
    # every 0.1 s on average a 1 Hz leak (one event a second alone) hardly ever reaches a threshold
    video = torch.full((1, 401, 16, 16), 0.5)
    ts = torch.linspace(0, 4.0, 401, dtype=torch.float64)
    leak_only = SensorConfig.ideal(0.2, leak_rate_hz=1.0, conventions="v2e")
    assert len(event_list(video, config=leak_only, timestamps_s=ts)) == 256 * 4
    ev = event_list(video, config=leak_only.replace(shot_noise_rate_hz=10.0, seed=3), timestamps_s=ts)
    n_on, n_off = int((ev.p > 0).sum()), int((ev.p < 0).sum())
    assert abs(n_on - n_off) < 300 and n_off > 2000  # ON = OFF: noise only (SD of the difference ~75)


def test_only_event_lists_take_other_conventions():
    cfg = SensorConfig.ideal(0.2, conventions="v2e")
    with pytest.raises(InputError, match="event lists only"):
        event_frames(_step(), config=cfg, timestamps_s=[0.0, 0.03])
    from fsdvs_hw.sensor.simulation.stream import simulate

    with pytest.raises(InputError, match=r"stream: SensorConfig\.conventions='v2e'"):
        simulate(_step()[0], config=cfg, timestamps_s=[0.0, 0.03])


def test_native_events_unchanged_by_the_new_field():
    cfg = SensorConfig(seed=5)
    video = torch.rand(1, 6, 8, 8, generator=torch.Generator().manual_seed(0)) + 0.2
    a = event_list(video, config=cfg)
    b = event_list(video, config=cfg.replace(conventions="native"))
    assert torch.equal(a.t, b.t) and torch.equal(a.x, b.x) and torch.equal(a.p, b.p)
