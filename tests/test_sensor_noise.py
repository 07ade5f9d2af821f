"""Noise sources, seeds and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fsdvs_hw.errors import InputError, KernelError
from fsdvs_hw.sensor import EventSimulator, SensorConfig, event_frames, event_list, plan_model


def _static(H=64, W=64, T=17, level=0.5):
    return torch.full((1, T, H, W), level, dtype=torch.float64)


def test_shot_noise_rate_matches_configured_hz():
    rate, duration = 0.5, 100.0
    video = _static()
    ts = torch.linspace(0, duration, 17, dtype=torch.float64)
    cfg = SensorConfig.ideal(shot_noise_rate_hz=rate, seed=11)
    frames = event_frames(video, None, config=cfg, timestamps_s=ts)
    n_px = 64 * 64
    expected = rate * n_px * duration  # both polarities together
    sigma = math.sqrt(expected)  # Poisson
    assert abs(float(frames.sum()) - expected) < 4 * sigma
    on, off = float(frames[:, :, 0].sum()), float(frames[:, :, 1].sum())
    assert abs(on - off) < 4 * math.sqrt(expected)
    # Poisson in time: counts per pixel and interval have variance == mean
    per = frames.sum(2).flatten()
    assert float(per.var() / per.mean()) == pytest.approx(1.0, abs=0.05)


def test_leak_rate_matches_configured_hz_and_only_on_events():
    rate, duration = 0.2, 50.0
    video = _static()
    ts = torch.linspace(0, duration, 17, dtype=torch.float64)
    cfg = SensorConfig(
        leak_rate_hz=rate, shot_noise_rate_hz=0.0, refractory_s=0.0, cutoff_hz=0.0, random_reference_phase=True, seed=5
    )
    frames = event_frames(video, None, config=cfg, timestamps_s=ts)
    n_px = 64 * 64
    expected = rate * n_px * duration
    # deterministic drift with a uniform random phase: each pixel gives floor(rate·T + U) events
    assert abs(float(frames[:, :, 0].sum()) - expected) < 4 * math.sqrt(n_px / 12)
    assert float(frames[:, :, 1].sum()) == 0
    # the rate does not depend on the pixel's threshold mismatch (the drift scales with C_on)
    per_pixel = frames[:, :, 0].sum(1).flatten()
    assert set(per_pixel.unique().tolist()) <= {math.floor(rate * duration), math.floor(rate * duration) + 1}


def test_seed_makes_runs_repeatable_and_streams_independent():
    g = torch.Generator().manual_seed(0)
    video = torch.rand(1, 6, 16, 16, generator=g) + 0.05
    cfg = SensorConfig(shot_noise_rate_hz=5.0, leak_rate_hz=1.0, random_reference_phase=True, seed=3)
    a = event_frames(video, None, config=cfg)
    b = event_frames(video, None, config=cfg)
    assert torch.equal(a, b)
    ea, eb = event_list(video, None, config=cfg), event_list(video, None, config=cfg)
    assert torch.equal(ea.t, eb.t) and len(ea) > 0
    c = event_frames(video, None, config=cfg.replace(seed=4))
    assert not torch.equal(a, c)
    # switching shot noise off leaves the mismatch draws unchanged: signal events are identical
    quiet = event_frames(video, None, config=cfg.replace(shot_noise_rate_hz=0.0))
    assert torch.all(a >= quiet) and float((a - quiet).sum()) > 0
    # an explicit generator overrides the mismatch stream
    g1 = torch.Generator().manual_seed(99)
    g2 = torch.Generator().manual_seed(99)
    d1 = event_frames(video, None, config=cfg.replace(shot_noise_rate_hz=0.0), generator=g1)
    d2 = event_frames(video, None, config=cfg.replace(shot_noise_rate_hz=0.0), generator=g2)
    assert torch.equal(d1, d2) and not torch.equal(d1, quiet)


def test_threshold_mismatch_has_configured_spread():
    from fsdvs_hw.sensor.simulation.pixel import threshold_maps

    cfg = SensorConfig(threshold_sigma=0.03, seed=2)
    on, off = threshold_maps(cfg, (200, 200), torch.zeros((), dtype=torch.float64))
    assert float(on.mean()) == pytest.approx(0.2, abs=0.001)
    assert float(on.std()) == pytest.approx(0.03, rel=0.03)
    assert not torch.equal(on, off)


@pytest.mark.parametrize(
    "bad, match",
    [
        (lambda v: v[0], "shape \\(B, T, H, W\\)"),
        (lambda v: -v, "must be >= 0"),
        (lambda v: v * float("nan"), "NaN"),
        (lambda v: v[:, :1], "T >= 2"),
    ],
)
def test_bad_video_raises_input_error(bad, match):
    video = torch.rand(1, 4, 5, 5) + 0.1
    with pytest.raises(InputError, match=match):
        event_frames(bad(video), None)


def test_bad_timestamps_kernel_config_raise():
    video = torch.rand(1, 4, 5, 5) + 0.1
    with pytest.raises(InputError, match="strictly increasing; frame 2"):
        event_frames(video, None, timestamps_s=[0.0, 0.1, 0.1, 0.2])
    with pytest.raises(InputError, match="timestamps_s: must have shape"):
        event_frames(video, None, timestamps_s=[0.0, 0.1])
    with pytest.raises(KernelError, match="odd"):
        event_frames(video, torch.ones(4, 4))
    with pytest.raises(KernelError, match="NaN"):
        event_frames(video, torch.full((3, 3), float("nan")))
    with pytest.raises(KernelError, match="all taps are zero"):
        event_frames(video, torch.zeros(3, 3))
    with pytest.raises(InputError, match="placement"):
        SensorConfig(placement="middle")
    with pytest.raises(InputError, match="threshold_on"):
        SensorConfig(threshold_on=0.0)
    with pytest.raises(InputError, match="refractory_s"):
        SensorConfig(refractory_s=-1.0)
    with pytest.raises(InputError, match="tolerance"):
        plan_model(video, tolerance=0.0)
    with pytest.raises(InputError, match="config"):
        event_frames(video, None, config={"threshold_on": 0.2})


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_mismatched_devices_raise_and_cuda_matches_cpu():
    video = torch.rand(1, 4, 8, 8, dtype=torch.float64) + 0.1
    k = torch.ones(3, 3, dtype=torch.float64) / 9
    with pytest.raises(InputError, match="device"):
        event_frames(video.cuda(), k)
    cfg = SensorConfig.ideal()
    torch.testing.assert_close(
        event_frames(video.cuda(), k.cuda(), config=cfg).cpu(), event_frames(video, k, config=cfg)
    )


def test_mismatched_devices_raise_on_meta_device():
    # the device check does not need a GPU: a kernel on the meta device is another device
    video = torch.rand(1, 4, 8, 8) + 0.1
    with pytest.raises(InputError, match="device"):
        event_frames(video, torch.ones(3, 3, device="meta"))


def test_numpy_input_and_module_defaults():
    video = (np.random.default_rng(0).random((1, 4, 6, 6)) + 0.1).astype(np.float32)
    out = EventSimulator()(video)
    assert out.shape == (1, 3, 2, 6, 6) and out.dtype == torch.float32
