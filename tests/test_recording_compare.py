"""compare_events for people (issue 41): printed summary, validated input, fast offset, bounded bins."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import EventList
from fsdvs_hw.sensor.cameras.compare import MAX_BINS, compare_events
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


def _bursty(seed: int = 0, n_bursts: int = 200) -> EventFile:
    """Events in bursts with a random envelope (one clear alignment), 5 ms per burst, µs times."""
    rng = np.random.default_rng(seed)
    env = rng.random(n_bursts) ** 4
    t = np.concatenate([k * 0.005 + 0.005 * rng.random(int(400 * e)) for k, e in enumerate(env)])
    t_us = np.sort(np.rint(t * 1e6).astype(np.int64))
    n = t_us.size
    return EventFile(
        t_us,
        rng.integers(0, 20, n),
        rng.integers(0, 10, n),
        np.where(rng.random(n) < 0.7, 1, -1).astype(np.int8),
        20,
        10,
    )


def test_summary_printed_leading_with_the_statistics_that_separate_fits():
    a = _bursty(0)
    b = _bursty(1)
    c = compare_events(a, b, bin_s=0.002)
    text = str(c)
    keys = ["events", "ON fraction", "rate correlation", "IEI KS statistic", "count-map correlation"]
    pos = [text.index(k) for k in keys]
    assert pos == sorted(pos), text  # the separating statistics first, the weak map correlation after
    assert f"{c.events_sim}" in text and f"{c.events_real}" in text
    assert f"{c.on_fraction_sim:.4f}" in text and f"{c.iei_ks_statistic:.4f}" in text
    r = repr(c)
    assert len(r) < 250 and "array" not in r and "EventComparison(" in r
    assert set(c.summary()) >= {"events_sim", "on_fraction_real", "rate_correlation", "iei_ks_statistic"}


@pytest.mark.parametrize(
    "t,x,y,match",
    [
        ([0.0, float("nan")], [0, 1], [0, 0], r"simulation: events: time of event 1 is nan"),
        ([0.0, float("inf")], [0, 1], [0, 0], r"time of event 1 is inf"),
        ([0.0, 0.1], [-1, 1], [0, 0], r"x of event 0 is -1"),
        ([0.0, 0.1], [0, 20], [0, 0], r"x of event 1 is 20, outside \[0, 20\) of the 20x10 sensor"),
        ([0.0, 0.1], [0, 1], [0, 10], r"y of event 1 is 10, outside \[0, 10\)"),
    ],
)
def test_bad_events_refused_with_one_line(t, x, y, match):
    real = _bursty(0)
    with pytest.raises(InputError, match=match):
        compare_events(_list(t, x, y, [1, -1]), real, shape=(10, 20))


def test_negative_pixel_refused_without_a_shape():
    """x = -1 was counted at another pixel (numpy's negative index); now refused."""
    with pytest.raises(InputError, match=r"x of event 0 is -1; pixel coordinates must be >= 0"):
        compare_events(_list([0.0, 0.1], [-1, 1], [0, 0], [1, 1]), _list([0.0], [0], [0], [1]))


def test_tiny_bin_refused_before_allocating():
    a = _bursty(0)
    with pytest.raises(InputError, match=rf"rate bins over the .* at most {MAX_BINS}: use bin_s >= "):
        compare_events(a, a, bin_s=1e-9)


def test_dsec_like_clock_offset_found_without_a_quadratic_search():
    """A recording on its camera's clock (50 000 s, as DSEC's t_offset) against a simulation from 0:
    the first events' difference removes the offset, the FFT cross-correlation finds the rest."""
    a = _bursty(0, n_bursts=2000)  # 10 s
    shift_us = 50_000_000_000 + 7_000
    b = EventFile(a.t_us + shift_us, a.x, a.y, a.p, 20, 10)
    c = compare_events(a, b, bin_s=0.001, max_lag_s=0.05)
    assert c.start_offset_s == pytest.approx((b.t_us[0] - a.t_us[0]) * 1e-6)
    assert abs(c.lag_s - shift_us * 1e-6) < 0.0005  # half a bin
    assert c.rate_correlation > 0.99 and c.iei_ks_statistic < 1e-3
    assert c.rate_sim_hz.size <= 10_100  # bins over the aligned span, not over 50 000 s


def test_fft_lag_equals_the_direct_search():
    """The FFT cross-correlation gives the lag and peak of numpy's direct (quadratic) correlation."""
    from fsdvs_hw.sensor.cameras import compare

    rng = np.random.default_rng(3)
    a = rng.random(400) ** 3
    b = np.roll(a, 17) + 0.1 * rng.random(400)
    lag, corr = compare._lag(a, b, 40)
    am, bm = a - a.mean(), b - b.mean()
    full = np.correlate(bm, am, mode="full") / np.sqrt((am**2).sum() * (bm**2).sum())
    lags = np.arange(-399, 400)
    keep = np.abs(lags) <= 40
    k = int(np.argmax(full[keep]))
    assert round(lag) == lags[keep][k] == 17
    assert corr == pytest.approx(full[keep][k], abs=1e-9)


def test_count_maps_of_a_huge_sensor_refused_before_allocating():
    """A stray pixel at x = 2e9 (an EventList carries no size): the maps would need 32 GB."""
    with pytest.raises(InputError, match=r"count maps of a 2000000001x1 sensor.*"):
        compare_events(_list([0.0, 0.1], [2_000_000_000, 1], [0, 0], [1, 1]), _list([0.0], [0], [0], [1]))
