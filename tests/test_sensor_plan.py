"""The scene-adaptive plan: decisions with numbers, within tolerance of the full model, faster."""

from __future__ import annotations

import math

import pytest
import torch

from fsdvs_hw.sensor import SensorConfig, event_frames, event_list, plan_model
from fsdvs_hw.sensor.simulation.plan import SceneStats

TOL = 0.05
FULL = SensorConfig(substeps=64)  # v2e-like sensor, every effect on, fine fixed time steps


def _moving_grating(speed_px: float, lo: float, hi: float, H: int = 40, W: int = 40, T: int = 17) -> torch.Tensor:
    y, x = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64), indexing="ij")
    frames = [
        lo
        + (hi - lo)
        * (0.5 + 0.5 * torch.sin(2 * math.pi * (x - speed_px * t) / 12.0) * torch.cos(2 * math.pi * y / 20.0))
        for t in range(T)
    ]
    return torch.stack(frames)[None]


@pytest.mark.parametrize(
    "scene, skips_photoreceptor",
    [
        ("slow_bright", True),
        ("fast_dim", False),
    ],
)
def test_plan_within_tolerance_of_full_model_and_faster(scene, skips_photoreceptor):
    video = _moving_grating(0.5, 0.3, 1.0) if scene == "slow_bright" else _moving_grating(3.0, 0.003, 0.03)
    plan = plan_model(video, TOL, config=FULL)
    assert plan.decision("photoreceptor").included is (not skips_photoreceptor)
    assert "leak events" in plan.skipped and "shot noise" in plan.skipped  # tiny vs the signal
    assert plan.decision("threshold mismatch").included  # sigma/C = 0.15
    full = event_frames(video, None, config=FULL)
    planned = event_frames(video, None, plan=plan)
    count_err = abs(float(planned.sum() - full.sum())) / float(full.sum())
    frame_err = float((planned - full).abs().sum() / full.abs().sum())
    assert count_err < TOL
    assert frame_err < TOL
    # faster by construction: fewer time steps than the full model (the speed itself is measured in
    # `fsdvs-hw bench sim`, "plan_model" rows: no wall-clock asserts in tests)
    assert sum(plan.substeps) < 64 * 16


def test_plan_text_names_every_effect_with_numbers():
    plan = plan_model(_moving_grating(0.5, 0.3, 1.0), TOL, config=FULL)
    text = str(plan)
    for name in (
        "photoreceptor",
        "sub-steps",
        "threshold mismatch",
        "refractory",
        "leak events",
        "shot noise",
        "surround transient",
        "positivity floor",
    ):
        assert name in text
        assert plan.decision(name).reason
    assert "expected" in plan.decision("shot noise").reason and "Hz" in plan.decision("shot noise").reason
    # the effective config has the skipped effects switched off
    assert plan.config.cutoff_hz == 0.0 and plan.config.shot_noise_rate_hz == 0.0
    assert plan.config.threshold_sigma == FULL.threshold_sigma


def test_plan_includes_noise_and_refractory_when_they_matter():
    static = torch.full((1, 17, 16, 16), 0.5, dtype=torch.float64)
    static[:, 8:, 4:8, 4:8] = 0.6  # a tiny signal
    plan = plan_model(static, TOL, config=SensorConfig(shot_noise_rate_hz=5.0, leak_rate_hz=0.0))
    assert plan.decision("shot noise").included and plan.decision("shot noise").value > TOL
    flash = torch.ones(1, 3, 4, 4, dtype=torch.float64)
    flash[:, 1:] = 1e3  # 35 thresholds in 1 ms
    plan = plan_model(flash, TOL, config=SensorConfig(), timestamps_s=[0.0, 1e-3, 2e-3])
    assert plan.decision("refractory").included and plan.decision("refractory").value >= 1


def test_plan_from_stats_and_photoreceptor_lag_scales_with_light():
    def lag(level):
        return plan_model(_moving_grating(2.0, level, 3 * level), TOL, config=FULL).decision("photoreceptor").value

    # dimmer light -> lower cut-off -> larger lag (bandwidth proportional to photocurrent);
    # same log contrast in both (above the linear-log knee): f_c 300 Hz vs 53 Hz
    assert lag(0.1) > 4 * lag(1.0)
    stats = SceneStats(
        n_pixels=100, duration_s=1.0, interval_max_abs_change=(0.1, 0.1), max_log_rate_per_s=2.0, total_abs_change=50.0
    )
    plan = plan_model(stats, TOL, config=SensorConfig())
    assert len(plan.substeps) == 2


def _small_fast_dim_object(H=64, W=64, T=6):
    video = torch.full((1, T, H, W), 0.8, dtype=torch.float64)  # bright, still background
    for t in range(T):
        x0 = 8 + 4 * t
        video[0, t, 24:36, x0 : x0 + 10] = 0.004  # a dim object moving 4 px/frame
    return video


def test_region_adaptive_steps_only_where_needed():
    video = _small_fast_dim_object()
    cfg = SensorConfig(
        adaptive_fraction=1.0,
        threshold_sigma=0.0,
        refractory_s=0.0,
        leak_rate_hz=0.0,
        shot_noise_rate_hz=0.0,
        dark_intensity=1e-3,
        seed=2,
    )
    glob, info_g = event_frames(video, None, config=cfg.replace(adaptive_region_px=0), return_info=True)
    reg, info_r = event_frames(video, None, config=cfg.replace(adaptive_region_px=16), return_info=True)
    assert info_r.substeps == info_g.substeps and max(info_g.substeps) > 8
    assert info_r.pixel_steps < 0.5 * info_g.pixel_steps  # most regions are still
    n = float(glob.sum())
    assert n > 100
    assert float((reg - glob).abs().sum()) / n < 0.02
    # the exact event list agrees with the region-stepped frames, pixel by pixel
    ev = event_list(video, None, config=cfg.replace(adaptive_region_px=16))
    ts = torch.arange(video.shape[1], dtype=torch.float64) / cfg.frame_rate_hz
    rebuilt = torch.zeros_like(reg)
    k = torch.clamp(torch.searchsorted(ts, ev.t, right=False) - 1, 0, video.shape[1] - 2)
    rebuilt.index_put_((ev.b, k, (ev.p < 0).long(), ev.y, ev.x), torch.ones(len(ev), dtype=reg.dtype), accumulate=True)
    assert torch.equal(rebuilt, reg)


def test_plan_surround_transient_decision_follows_mesh_time_constant():
    video = _moving_grating(2.0, 0.3, 1.0, H=24, W=24, T=6)
    base = SensorConfig.ideal(placement="post_log", surround_lambda_px=2.0, surround_weight=0.8)
    slow_mesh = plan_model(video, TOL, config=base.replace(surround_tau_s=0.02))
    fast_mesh = plan_model(video, TOL, config=base.replace(surround_tau_s=1e-6))
    assert slow_mesh.decision("surround transient").included and slow_mesh.decision("sub-steps").included
    assert not fast_mesh.decision("surround transient").included
    assert fast_mesh.config.surround_tau_s == 0 and all(s == 1 for s in fast_mesh.substeps)
    # skipping a fast mesh's transient stays within tolerance of simulating it finely
    full = event_frames(video, None, config=base.replace(surround_tau_s=1e-6, substeps=32))
    planned = event_frames(video, None, plan=fast_mesh)
    assert float((planned - full).abs().sum() / full.sum()) < TOL


def test_a_plan_that_is_not_a_model_plan_is_named_and_a_disagreeing_config_refused():
    import numpy as np

    from fsdvs_hw.errors import InputError
    from fsdvs_hw.sensor import SensorConfig, event_frames, plan_model

    video = np.full((1, 3, 8, 8), 0.5)
    with pytest.raises(InputError, match="plan: must be a ModelPlan from plan_model"):
        event_frames(video, None, plan={"config": SensorConfig()})
    plan = plan_model(video)
    with pytest.raises(InputError, match="config and plan disagree"):
        event_frames(video, None, config=SensorConfig(threshold_on=0.3), plan=plan)
    assert event_frames(video, None, plan=plan).shape[-2:] == (8, 8)  # a real plan is accepted
