"""Event generation against closed-form cases: counts, timestamps, placement, positivity."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.sensor import SensorConfig, event_frames, event_list, mesh_surround_steady_state, voxel_grid

C = 0.2
IDEAL = SensorConfig.ideal(threshold=C, dark_intensity=1e-4)


def _ramp_video(n_thresholds: float, T: int = 11, H: int = 3, W: int = 4, sign: float = 1.0) -> torch.Tensor:
    """Uniform video whose log intensity changes linearly by n_thresholds * C over the clip."""
    L = torch.linspace(0.0, sign * n_thresholds * C, T, dtype=torch.float64)
    return torch.exp(L).view(1, T, 1, 1).expand(1, T, H, W).contiguous()


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_linear_log_ramp_gives_exact_events_at_exact_times(sign):
    video = _ramp_video(5, T=11, sign=sign)
    frames = event_frames(video, None, config=IDEAL)
    on, off = frames[0, :, 0], frames[0, :, 1]
    produced, other = (on, off) if sign > 0 else (off, on)
    assert torch.all(produced.sum(0) == 5)
    assert torch.all(other == 0)
    # 10 intervals of 0.5 C each: events at the end of intervals 1, 3, 5, 7, 9
    per_interval = produced[:, 0, 0]
    assert per_interval.tolist() == [0, 1, 0, 1, 0, 1, 0, 1, 0, 1]
    ev = event_list(video, None, config=IDEAL).select(0)
    px = (ev.x == 0) & (ev.y == 0)
    # log reaches j*C at t = j * 2 / 25 s (frame rate 25 Hz, 0.5 C per frame)
    np.testing.assert_allclose(ev.t[px].numpy(), [0.08, 0.16, 0.24, 0.32, 0.40], atol=1e-9)
    assert set(ev.p[px].tolist()) == {int(sign)}


def test_event_times_are_interpolated_within_an_interval():
    # 3.5 C in one interval: 3 events at C, 2C, 3C -> t = t0 + j/3.5 * dt (distinct times)
    video = torch.exp(torch.tensor([0.0, 3.5 * C], dtype=torch.float64)).view(1, 2, 1, 1)
    ev = event_list(video, None, config=IDEAL, timestamps_s=[0.0, 1.0])
    np.testing.assert_allclose(ev.t.numpy(), [1 / 3.5, 2 / 3.5, 3 / 3.5], rtol=1e-9)


def test_event_list_counts_match_event_frames():
    g = torch.Generator().manual_seed(3)
    video = torch.rand(2, 6, 8, 9, generator=g, dtype=torch.float64) + 0.05
    cfg = SensorConfig(seed=4, refractory_s=5e-3, shot_noise_rate_hz=2.0, leak_rate_hz=1.0)
    frames = event_frames(video, reference_kernel("dog", 5), config=cfg)
    ev = event_list(video, reference_kernel("dog", 5), config=cfg)
    ts = torch.arange(6, dtype=torch.float64) / cfg.frame_rate_hz
    rebuilt = torch.zeros_like(frames)
    k = torch.clamp(torch.searchsorted(ts, ev.t, right=False) - 1, 0, 4)
    rebuilt.index_put_(
        (ev.b, k, (ev.p < 0).long(), ev.y, ev.x), torch.ones(len(ev), dtype=frames.dtype), accumulate=True
    )
    assert torch.equal(rebuilt, frames)


def test_delta_kernel_equals_no_filter():
    g = torch.Generator().manual_seed(1)
    video = torch.rand(1, 5, 10, 12, generator=g) * 2 + 0.01
    cfg = SensorConfig(seed=7)
    a = event_frames(video, None, config=cfg)
    b = event_frames(video, reference_kernel("delta", 7), config=cfg)
    assert a.sum() > 0
    assert torch.equal(a, b)


def test_post_log_zero_surround_equals_plain_dvs():
    g = torch.Generator().manual_seed(2)
    video = torch.rand(1, 5, 10, 12, generator=g) + 0.01
    plain = event_frames(video, None, config=SensorConfig(seed=1))
    post = event_frames(
        video, None, config=SensorConfig(seed=1, placement="post_log", surround_lambda_px=3.0, surround_weight=0.0)
    )
    assert torch.equal(plain, post)
    strong = event_frames(
        video, None, config=SensorConfig(seed=1, placement="post_log", surround_lambda_px=3.0, surround_weight=0.9)
    )
    assert not torch.equal(plain, strong)


def test_mesh_surround_solves_screened_poisson_exactly():
    g = torch.Generator().manual_seed(5)
    p = torch.rand(7, 9, generator=g, dtype=torch.float64)
    lam = 2.5
    u = mesh_surround_steady_state(p, lam)
    # 5-point Laplacian with reflecting (Neumann) borders
    up = torch.nn.functional.pad(u[None, None], (1, 1, 1, 1), mode="replicate")[0, 0]
    lap = up[:-2, 1:-1] + up[2:, 1:-1] + up[1:-1, :-2] + up[1:-1, 2:] - 4 * u
    torch.testing.assert_close(u - lam**2 * lap, p, rtol=0, atol=1e-10)
    # a uniform input is its own steady state (no current flows)
    torch.testing.assert_close(
        mesh_surround_steady_state(torch.full((5, 6), 3.0, dtype=torch.float64), 4.0),
        torch.full((5, 6), 3.0, dtype=torch.float64),
    )


def test_differential_positivity_equals_floor_for_positive_kernel():
    g = torch.Generator().manual_seed(6)
    video = torch.rand(1, 5, 10, 12, generator=g, dtype=torch.float64) + 0.2
    k = reference_kernel("gaussian", 5, sigma_px=1.0)
    a = event_frames(video, k, config=IDEAL)
    b = event_frames(video, k, config=IDEAL.replace(positivity="differential"))
    assert torch.equal(a, b)


def test_negative_lobes_hit_the_floor_and_are_reported():
    video = torch.zeros(1, 3, 16, 16, dtype=torch.float64) + 0.01
    video[:, :, :, 8:] = 1.0  # bright half: a DoG undershoots on the dark side of the edge
    k = torch.tensor(reference_kernel("dog", 7).taps)
    _, info = event_frames(video, k, config=IDEAL, return_info=True)
    assert 0 < info.floor_fraction < 1
    _, info_ped = event_frames(
        video, k, config=IDEAL.replace(positivity="pedestal", pedestal_intensity=10.0), return_info=True
    )
    assert info_ped.floor_fraction == 0.0


def test_refractory_period_limits_event_spacing():
    # 10 C in 1 ms: crossings every 0.1 ms; refractory 0.35 ms keeps every 4th crossing
    video = torch.exp(torch.tensor([0.0, 10 * C], dtype=torch.float64)).view(1, 2, 1, 1)
    cfg = IDEAL.replace(refractory_s=3.5e-4)
    ev = event_list(video, None, config=cfg, timestamps_s=[0.0, 1e-3])
    np.testing.assert_allclose(ev.t.numpy(), [1e-4, 5e-4, 9e-4], rtol=1e-9)
    assert torch.all(torch.diff(ev.t) >= 3.5e-4 - 1e-12)


def test_voxel_grid_from_frames_conserves_events_and_matches_event_list():
    video = _ramp_video(5, T=11)
    frames = event_frames(video, None, config=IDEAL)
    vox = voxel_grid(frames, 4, signed=False)
    torch.testing.assert_close(vox.sum(dim=1), frames.sum(dim=1))
    ev = event_list(video, None, config=IDEAL)
    ts = torch.arange(11, dtype=torch.float64) / 25
    vox_ev = voxel_grid(ev, 4, timestamps_s=ts, height=3, width=4, signed=True)
    assert vox_ev.shape == (1, 4, 3, 4)
    torch.testing.assert_close(vox_ev.sum(dim=1), torch.full((1, 3, 4), 5.0, dtype=torch.float64))


@pytest.mark.parametrize("intensity", [1.0, 0.1])
def test_photoreceptor_lowpass_step_response_times(intensity):
    # a step of 2.5 C at t = 1 µs; first-order response 2.5 C (1 - exp(-t / tau)) crosses C and
    # 2 C at tau ln(2.5/1.5) and tau ln 5; tau = 1 / (2π f_c), f_c = 300 Hz (I + I_dark) / 1
    ts = torch.tensor([0.0, 1e-6] + [1e-6 + 1e-3 * k for k in range(1, 31)], dtype=torch.float64)
    video = torch.full((1, len(ts), 1, 1), intensity, dtype=torch.float64)
    video[:, 1:] *= math.exp(2.5 * C)
    cfg = IDEAL.replace(cutoff_hz=300.0, substeps=100, dark_intensity=1e-3)
    ev = event_list(video, None, config=cfg, timestamps_s=ts)
    # the cut-off follows the (rising) photocurrent; after the step it is set by the new level
    tau = 1 / (2 * math.pi * 300.0 * min(1.0, intensity * math.exp(2.5 * C) + 1e-3))
    assert len(ev) == 2 and torch.all(ev.p == 1)
    expected = [1e-6 + tau * math.log(2.5 / 1.5), 1e-6 + tau * math.log(5.0)]
    np.testing.assert_allclose(ev.t.numpy(), expected, rtol=0.02)


def test_post_log_unit_gain_kernel_on_uniform_video_equals_plain_dvs():
    # W * log(I) = log(I) when I is spatially uniform and sum(W) = 1 (replicated borders)
    video = _ramp_video(4, T=9, H=12, W=12)
    k = reference_kernel("gaussian", 5, sigma_px=1.2).normalised("sum")
    plain = event_frames(video, None, config=IDEAL)
    post = event_frames(video, k, config=IDEAL.replace(placement="post_log"))
    assert plain.sum() == 4 * 144
    assert torch.equal(plain, post)


def test_fast_surround_transient_equals_steady_state_and_slow_one_lags():
    g = torch.Generator().manual_seed(8)
    video = torch.rand(1, 5, 10, 12, generator=g, dtype=torch.float64) + 0.1
    cs = IDEAL.replace(placement="post_log", surround_lambda_px=2.0, surround_weight=0.8, substeps=8)
    steady = event_frames(video, None, config=cs)
    fast = event_frames(video, None, config=cs.replace(surround_tau_s=1e-7))
    slow = event_frames(video, None, config=cs.replace(surround_tau_s=1.0))
    assert torch.equal(steady, fast)
    assert not torch.equal(steady, slow)


def test_floor_gradient_is_straight_through_and_clipped():
    from fsdvs_hw.sensor.simulation.filtering import filtered_log_signal

    video = torch.tensor([[[[1e-5, 1.0]], [[1e-5, 1.0]]]], dtype=torch.float64, requires_grad=True)
    cfg = IDEAL.replace(floor_intensity=1e-3, dark_intensity=1e-6)
    sig = filtered_log_signal(video, torch.ones((1, 1), dtype=torch.float64), cfg)
    assert sig.floor_fraction == 0.5
    sig.log_signal.sum().backward()
    # below the floor d log / d I would be 1 / I_dark = 1e6; the straight-through gradient is clipped to 1
    assert torch.all(video.grad[..., 0] == 1.0)
    torch.testing.assert_close(video.grad[..., 1], torch.ones_like(video.grad[..., 1]))  # d log I / d I at I = 1


@pytest.mark.parametrize("H, W", [(67, 61), (64, 64), (131, 97), (272, 640)])
@pytest.mark.parametrize("k", [5, 9])
def test_fft_correlation_equals_conv2d_at_any_frame_size(H, W, k):
    """The FFT path (transforms at fast sizes, larger than the padded frame) equals conv2d with
    replicated borders, values and kernel gradients, including prime frame sizes."""
    from fsdvs_hw.sensor.simulation.filtering import apply_kernel

    g = torch.Generator().manual_seed(H + W + k)
    frames = torch.rand(2, H, W, generator=g, dtype=torch.float64)
    ker = torch.randn(k, k, generator=g, dtype=torch.float64)
    outs, grads = [], []
    for method in ("fft", "direct"):
        kk = ker.clone().requires_grad_(True)
        y = apply_kernel(frames, kk, method)
        (y * frames).sum().backward()
        outs.append(y.detach())
        grads.append(kk.grad)
    assert outs[0].shape == (2, H, W)
    assert torch.allclose(outs[0], outs[1], rtol=0, atol=1e-12)
    assert torch.allclose(grads[0], grads[1], rtol=1e-10, atol=1e-9)
