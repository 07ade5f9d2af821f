"""Gradients of the differentiable path: gradcheck, surrogate identity, reach and finiteness."""

from __future__ import annotations

import math

import pytest
import torch

from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.sensor import EventSimulator, SensorConfig, event_frames, voxel_grid


def _video(seed: int = 0, shape=(1, 4, 5, 6), lo: float = 0.2, hi: float = 0.8) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return lo + (hi - lo) * torch.rand(shape, generator=g, dtype=torch.float64)


@pytest.mark.parametrize(
    "config",
    [
        SensorConfig.ideal(surrogate="relaxed"),
        SensorConfig(
            surrogate="relaxed",
            cutoff_hz=300.0,
            substeps=3,
            leak_rate_hz=2.0,
            random_reference_phase=True,
            shot_noise_rate_hz=0.0,
        ),
        SensorConfig.ideal(
            surrogate="relaxed", placement="post_log", surround_lambda_px=1.5, surround_weight=0.7, surround_tau_s=0.01
        ),
        SensorConfig.ideal(surrogate="relaxed", positivity="differential"),
    ],
    ids=["ideal", "photoreceptor+leak+mismatch", "post_log_transient_surround", "differential"],
)
def test_gradcheck_float64(config):
    video = _video(shape=(1, 3, 4, 5)).requires_grad_(True)
    k = (
        torch.tensor(reference_kernel("dog", 3, sigma_centre_px=0.6, sigma_surround_px=1.5).taps)
        if config.positivity == "differential"
        else (
            torch.full((3, 3), 0.05, dtype=torch.float64)
            + 0.6 * torch.eye(3, dtype=torch.float64)[1].outer(torch.eye(3, dtype=torch.float64)[1])
        )
    )
    k.requires_grad_(True)
    c_on = torch.tensor(0.2, dtype=torch.float64, requires_grad=True)
    c_off = torch.tensor(0.25, dtype=torch.float64, requires_grad=True)

    def f(v, w, a, b):
        return event_frames(v, w, config=config.replace(threshold_on=a, threshold_off=b))

    assert torch.autograd.gradcheck(f, (video, k, c_on, c_off), eps=1e-6, atol=1e-6, fast_mode=True)


def test_straight_through_gradient_equals_relaxed_gradient_in_one_interval():
    video = _video(1, (1, 2, 8, 8), lo=0.05, hi=1.0)
    k = torch.tensor(reference_kernel("dog", 5).taps, requires_grad=True)
    weights = torch.rand(1, 1, 2, 8, 8, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    grads = {}
    for sur in ("straight_through", "relaxed"):
        k.grad = None
        cfg = SensorConfig.ideal(surrogate=sur)
        (event_frames(video, k, config=cfg) * weights).sum().backward()
        grads[sur] = k.grad.clone()
    assert grads["relaxed"].abs().sum() > 0
    torch.testing.assert_close(grads["straight_through"], grads["relaxed"])
    # and the forward differs: integer counts versus continuous counts
    hard = event_frames(video, k.detach(), config=SensorConfig.ideal())
    assert torch.equal(hard, torch.floor(hard))


def test_gradients_reach_kernel_thresholds_and_video():
    video = _video(3, (2, 5, 10, 10), lo=0.05, hi=1.0).requires_grad_(True)
    k = torch.tensor(reference_kernel("dog", 5).taps, requires_grad=True)
    c = torch.tensor(0.15, dtype=torch.float64, requires_grad=True)
    cfg = SensorConfig(threshold_on=c, threshold_off=c, refractory_s=1e-3, seed=3)
    frames = event_frames(video, k, config=cfg)
    vox = voxel_grid(frames, 3)
    (frames.sum() + (vox**2).sum()).backward()
    for name, g in (("kernel", k.grad), ("threshold", c.grad), ("video", video.grad)):
        assert g is not None and torch.isfinite(g).all() and g.abs().sum() > 0, name
    # more events when the threshold drops: the threshold gradient of the total count is negative
    c.grad = None
    event_frames(video, k.detach(), config=SensorConfig.ideal(threshold=c)).sum().backward()
    assert c.grad < 0


@pytest.mark.parametrize("case", ["zero", "huge", "dark_frames", "saturated", "tiny_threshold", "huge_threshold"])
def test_gradients_finite_at_extremes(case):
    T, H, W = 4, 8, 8
    video = _video(4, (1, T, H, W), lo=0.0, hi=1.0)
    threshold = 0.2
    if case == "zero":
        video = torch.zeros_like(video)
        video[:, 2:, 2:5, 2:5] = 1.0  # light appears out of total darkness
    elif case == "huge":
        video = video * 1e6
    elif case == "dark_frames":
        video[:, 1:3] = 0.0
    elif case == "saturated":
        video[:, 1:3] = 1e6
    elif case == "tiny_threshold":
        threshold = 1e-4
    elif case == "huge_threshold":
        threshold = 10.0
    video.requires_grad_(True)
    k = torch.tensor(reference_kernel("dog", 5).taps, requires_grad=True)
    c = torch.tensor(threshold, dtype=torch.float64, requires_grad=True)
    for cfg in (
        SensorConfig.ideal(threshold=c),
        SensorConfig(threshold_on=c, threshold_off=c, cutoff_hz=300.0, substeps=4, seed=1),
        SensorConfig.ideal(threshold=c, placement="post_log", surround_lambda_px=2.0, surround_weight=0.5),
        SensorConfig.ideal(threshold=c, positivity="differential"),
    ):
        frames = event_frames(video, k, config=cfg)
        assert torch.isfinite(frames).all() and (frames >= 0).all()
        gk, gc, gv = torch.autograd.grad(frames.sum() + frames[:, :, 0].pow(2).sum(), (k, c, video), allow_unused=True)
        for g in (gk, gc, gv):
            assert g is None or torch.isfinite(g).all()
    if case == "tiny_threshold":
        assert frames.sum() > 1e3  # thousands of events per pixel change, still finite


def test_event_simulator_module_parameter_buffer_and_swap():
    video = _video(5, (1, 5, 12, 12), lo=0.05, hi=1.0)
    learn = EventSimulator(SensorConfig.ideal(), kernel=reference_kernel("dog", 5), learnable=True)
    assert [n for n, _ in learn.named_parameters()] == ["kernel"]
    learn(video.float()).sum().backward()
    assert learn.kernel.grad is not None and learn.kernel.grad.abs().sum() > 0
    fixed = EventSimulator(SensorConfig.ideal(), kernel=reference_kernel("dog", 5))
    assert list(fixed.parameters()) == [] and "kernel" in dict(fixed.named_buffers())
    # a kernel given at call time replaces the stored one for that call only
    swapped = fixed(video, kernel=torch.ones((1, 1), dtype=torch.float64))
    plain = event_frames(video, None, config=SensorConfig.ideal())
    assert torch.equal(swapped, plain)
    assert not torch.equal(fixed(video.float()), plain.float())


@pytest.mark.parametrize("refractory_s, emitted", [(0.0, 3.0), (4e-4, 2.0), (8e-4, 1.0)])
def test_refractory_gradient_follows_the_emitted_events(refractory_s, emitted):
    # log intensity rises by 3.5 C in 1 ms: crossings at 0.29, 0.57, 0.86 ms; a refractory period
    # of 0.4 ms keeps 2 of them, 0.8 ms keeps 1 (issue 13: the gradient used to count all 3)
    c = 0.2
    end = torch.tensor(math.exp(3.5 * c), dtype=torch.float64, requires_grad=True)
    video = torch.stack([torch.ones((), dtype=torch.float64), end]).view(1, 2, 1, 1)
    cfg = SensorConfig.ideal(threshold=c, dark_intensity=1e-12, refractory_s=refractory_s)
    frames = event_frames(video, None, config=cfg, timestamps_s=[0.0, 1e-3])
    assert float(frames[0, 0, 0].detach().sum()) == emitted
    (g,) = torch.autograd.grad(frames[:, :, 0].sum(), end)
    # d(count)/d(end) = (emitted / crossings) · d(ΔL / C)/d(end) = (emitted / 3) / (C · end)
    assert float(g) == pytest.approx(emitted / 3.0 / (c * float(end)), rel=1e-9)
