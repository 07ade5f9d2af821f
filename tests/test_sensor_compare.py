"""compare_events: alignment, polarity, maps, intervals and noise rates against known values."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import EventList, SensorConfig, event_list
from fsdvs_hw.sensor.cameras.compare import compare_events, inter_event_intervals, plot_event_comparison
from fsdvs_hw.sensor.eventfiles.eventfile import EventFile


def _list(t, x, y, p) -> EventList:
    n = len(t)
    return EventList(
        torch.zeros(n, dtype=torch.int64),
        torch.as_tensor(x, dtype=torch.int64),
        torch.as_tensor(y, dtype=torch.int64),
        torch.as_tensor(t, dtype=torch.float64),
        torch.as_tensor(p, dtype=torch.int8),
    )


def _bursty(shift_s: float, seed: int = 0) -> EventList:
    """Events in bursts with a random envelope (a rate curve with one clear alignment)."""
    rng = np.random.default_rng(seed)
    env = rng.random(200) ** 4
    t = np.concatenate([k * 0.005 + 0.005 * rng.random(int(400 * e)) for k, e in enumerate(env)])
    t = np.sort(t) + shift_s
    n = t.size
    return _list(t, rng.integers(0, 20, n), rng.integers(0, 10, n), np.where(rng.random(n) < 0.7, 1, -1))


@pytest.mark.parametrize("shift", [0.0, 0.013, -0.021])
def test_lag_recovered_within_a_fraction_of_a_bin(shift):
    a = _bursty(0.0)
    b = EventList(a.b, a.x, a.y, a.t + shift, a.p)
    c = compare_events(a, b, bin_s=0.002, max_lag_s=0.05, shape=(10, 20))
    assert abs(c.lag_s - shift) < 0.001  # half a bin
    assert c.rate_correlation > 0.8  # a non-integer shift re-bins the events
    assert c.count_map_correlation == pytest.approx(1.0)
    assert c.iei_ks_statistic < 1e-3  # shifted times round differently


def test_on_fraction_maps_and_intervals_hand_computed():
    sim = _list([0.0, 0.1, 0.3, 0.35], [0, 0, 0, 1], [0, 0, 0, 0], [1, 1, -1, 1])
    real = EventFile(
        np.array([0, 50_000, 60_000]), np.array([1, 1, 1]), np.array([0, 0, 0]), np.array([-1, -1, -1], np.int8), 2, 1
    )
    c = compare_events(sim, real, bin_s=0.05)
    assert c.on_fraction_sim == 0.75 and c.on_fraction_real == 0.0
    assert c.count_map_sim.tolist() == [[3, 1]] and c.count_map_real.tolist() == [[0, 3]]
    assert c.count_map_correlation == pytest.approx(-1.0)
    assert c.iei_median_sim_s == pytest.approx(0.15)  # intervals 0.1 and 0.2
    assert c.iei_median_real_s == pytest.approx(0.03)  # 0.05 and 0.01
    np.testing.assert_allclose(
        np.sort(
            inter_event_intervals(np.array([0.0, 0.1, 0.3, 0.35]), np.array([0, 0, 0, 1]), np.array([0, 0, 0, 0]), 2)
        ),
        [0.1, 0.2],
    )


def test_noise_rate_of_a_static_scene_matches_the_shot_noise_rate():
    """Static scene, shot noise 0.1 Hz/pixel: isolated events per pixel-second ≈ 0.1 (Poisson CI)."""
    cfg = SensorConfig.ideal(0.2, shot_noise_rate_hz=0.1, seed=4)
    video = torch.full((1, 2, 32, 32), 0.5)
    ev = event_list(video, config=cfg, timestamps_s=torch.tensor([0.0, 20.0]))
    c = compare_events(ev, ev, shape=(32, 32), support_s=0.01)
    n = len(ev)  # ~2048 events: the expected rate within 4 Poisson SDs, minus the few neighbours
    assert abs(n - 2048) < 4 * np.sqrt(2048)
    assert c.noise_rate_sim_hz == pytest.approx(n / (32 * 32 * 20.0), rel=0.03)
    assert 0.4 < c.on_fraction_sim < 0.6


def test_refusals_and_figure(tmp_path):
    a = _bursty(0.0)
    with pytest.raises(InputError, match="sensor sizes differ"):
        compare_events(a, EventFile(np.array([1]), np.array([0]), np.array([0]), np.array([1], np.int8), 8, 8))
    with pytest.raises(InputError, match="bin_s must be a positive"):
        compare_events(a, a, bin_s=0)
    with pytest.raises(InputError, match="empty stream"):
        compare_events(a, _list([], [], [], []), shape=(10, 20))
    import matplotlib

    matplotlib.use("Agg")
    fig, axes = plot_event_comparison(compare_events(a, a, shape=(10, 20)))
    assert len(np.asarray(axes).ravel()) == 4
    fig.savefig(tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size > 1000
