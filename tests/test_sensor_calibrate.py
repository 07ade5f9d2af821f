"""calibrate_sensor: recovery of known parameters from simulated recordings (through vendor files)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import SensorConfig, event_list
from fsdvs_hw.sensor.cameras.calibrate import calibrate_sensor, comparator_input
from fsdvs_hw.sensor.cameras.calibration_scene import calibration_video


def _check_all_covered(cal, truth, names):
    for k in names:
        e = cal.estimates[k]
        assert e.contains(float(getattr(truth, k))), (k, e, getattr(truth, k))


def _check_thresholds(cal, truth, video):
    """Exact against this sensor's own pixels; near the preset (population) value within 3 half-widths
    (the interval is for the population: one sensor's draw misses it 1 time in 20)."""
    from fsdvs_hw.sensor.simulation.pixel import threshold_maps

    H, W = video.shape[-2:]
    active = slice(int(0.25 * W), None)  # calibration_video's static border has no threshold pairs
    maps = dict(zip(("threshold_on", "threshold_off"), threshold_maps(truth, (H, W), video[0, 0]), strict=True))
    for k, m in maps.items():
        e = cal.estimates[k]
        assert e.value == pytest.approx(float(m[:, active].mean()), abs=2e-4), k
        assert abs(e.value - float(getattr(truth, k))) < 1.5 * (e.high - e.low), k
    sd = float(np.sqrt(0.5 * sum(float(m[:, active].var()) for m in maps.values())))
    assert cal.estimates["threshold_sigma"].value == pytest.approx(sd, rel=0.05)


def test_recovers_asymmetric_thresholds_mismatch_and_refractory_through_evt3(tmp_path):
    pytest.importorskip("expelliarmus")
    from fsdvs_hw.sensor.eventfiles.prophesee import write_prophesee
    from fsdvs_hw.sensor.eventfiles.recordings import read_recording

    video, ts = calibration_video(250, 24, 24)
    truth = SensorConfig.ideal(0.15, threshold_off=0.25, threshold_sigma=0.03, refractory_s=8e-4, seed=5)
    ev = event_list(video, config=truth, timestamps_s=ts)
    path = write_prophesee(tmp_path / "rec.raw", ev, width=24, height=24)  # µs timestamps, as a camera
    cal = calibrate_sensor(read_recording(path), video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=100)
    _check_thresholds(cal, truth, video)
    _check_all_covered(cal, truth, ("refractory_s",))
    assert cal.estimates["refractory_s"].value == pytest.approx(8e-4, rel=0.01)
    assert cal.estimates["threshold_on"].high - cal.estimates["threshold_on"].low < 0.02  # informative
    assert cal.config.threshold_off == cal.estimates["threshold_off"].value


def test_static_scene_noise_rates_recovered():
    truth = SensorConfig.ideal(0.2, shot_noise_rate_hz=2.0, leak_rate_hz=0.5, random_reference_phase=True, seed=2)
    video = torch.full((1, 2, 32, 32), 0.5)
    ev = event_list(video, config=truth, timestamps_s=torch.tensor([0.0, 20.0], dtype=torch.float64))
    cal = calibrate_sensor(ev, None, duration_s=20.0, n_boot=200)
    _check_all_covered(cal, truth, ("shot_noise_rate_hz", "leak_rate_hz"))
    assert cal.estimates["shot_noise_rate_hz"].value == pytest.approx(2.0, rel=0.1)
    assert "threshold_on" not in cal.estimates and cal.notes


def test_bandwidth_recovered_and_no_refractory_bounded():
    video, ts = calibration_video(200, 16, 16)
    truth = SensorConfig.ideal(0.2, cutoff_hz=40.0, threshold_sigma=0.02, seed=1)
    ev = event_list(video, config=truth, timestamps_s=ts)
    cal = calibrate_sensor(
        ev, video, timestamps_s=ts, config=SensorConfig.ideal(0.2, cutoff_hz=100.0), fit_cutoff=True, n_boot=60
    )
    _check_thresholds(cal, truth, video)
    _check_all_covered(cal, truth, ("cutoff_hz", "refractory_s"))
    assert cal.estimates["cutoff_hz"].value == pytest.approx(40.0, rel=0.02)
    assert cal.estimates["refractory_s"].value == 0.0  # nothing swallowed: only bounded


def test_comparator_input_matches_the_simulator_events():
    """At every event time of an ideal pixel the rebuilt log signal sits on a threshold level."""
    video, ts = calibration_video(60, 8, 8)
    cfg = SensorConfig.ideal(0.2, cutoff_hz=50.0)
    ev = event_list(video, config=cfg, timestamps_s=ts)
    grid_t, L = comparator_input(video, ts, cfg)
    pix = (ev.y * 8 + ev.x).numpy()
    t = ev.t.numpy()
    j = np.clip(np.searchsorted(grid_t, t) - 1, 0, grid_t.size - 2)
    a = (t - grid_t[j]) / (grid_t[j + 1] - grid_t[j])
    Lv = L[j, pix] * (1 - a) + L[j + 1, pix] * a
    k = (Lv - L[0, pix]) / 0.2  # whole thresholds from the first frame's reference
    assert np.abs(k - np.round(k)).max() < 1e-3


def test_refusals():
    video, ts = calibration_video(20, 8, 8)
    ev = event_list(video, config=SensorConfig.ideal(0.2), timestamps_s=ts)
    with pytest.raises(InputError, match="pixels up to x=7, y=7, the video is 4x8"):
        calibrate_sensor(ev, video[..., :4], timestamps_s=ts)
    with pytest.raises(InputError, match="level"):
        calibrate_sensor(ev, video, timestamps_s=ts, level=1.5)
    with pytest.raises(InputError, match="video moves too little"):
        calibrate_sensor(ev, video, timestamps_s=ts, min_events=10_000)
    with pytest.raises(InputError, match="duration_s"):
        calibrate_sensor(ev.select(5), None)
    video, ts = calibration_video(80, 8, 8)
    ev = event_list(video, config=SensorConfig.ideal(0.2), timestamps_s=ts)
    assert math.isfinite(calibrate_sensor(ev, video, timestamps_s=ts, n_boot=20).estimates["threshold_on"].value)


@pytest.mark.slow  # ~6 s on 2 cores
def test_leak_and_heavy_noise_do_not_bias_the_thresholds():
    """Static border pixels (leak and noise only) stay out of the threshold fit after the leak
    correction; a 5 Hz shot noise leaves the per-pixel medians on the thresholds."""
    video, ts = calibration_video(1500, 12, 16)  # 1.5 s: static pixels collect enough noise pairs to matter
    truth = SensorConfig.ideal(
        0.2, threshold_sigma=0.03, leak_rate_hz=0.5, shot_noise_rate_hz=5.0, random_reference_phase=True, seed=3
    )
    ev = event_list(video, config=truth, timestamps_s=ts)
    cal = calibrate_sensor(ev, video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=100)
    _check_thresholds(cal, truth, video)
    _check_all_covered(cal, truth, ("shot_noise_rate_hz", "leak_rate_hz", "refractory_s"))
