"""Sensor-in-the-loop emulation: display mapping, temporal upsampling, recapture."""

from __future__ import annotations

import numpy as np
import pytest

from fsdvs_hw.design.display_settings import DisplaySettings
from fsdvs_hw.errors import InputError
from fsdvs_hw.explore.emulation import display_luminance, recapture, upsample_linear
from fsdvs_hw.kernels import reference_kernel


def test_display_maps_into_its_range_and_reports_clipping(rng):
    f = rng.uniform(-0.1, 1.0, size=(2, 3, 8, 8))
    lum, info = display_luminance(f, DisplaySettings(bits=8, gamma=2.2, peak_nits=400, black_nits=4))
    assert lum.min() >= 4 / 400 - 1e-15 and lum.max() <= 1 + 1e-15
    assert info["clipped_black"] == pytest.approx(np.mean(f < 0))
    p999 = np.percentile(f.reshape(2, -1), 99.9, axis=1).reshape(2, 1, 1, 1)
    assert info["clipped_peak"] == pytest.approx(np.mean(f > p999))  # above each clip's 99.9th percentile
    assert 0 < info["clipped_peak"] < 0.01


def test_display_gamma_and_quantisation_round_trip():
    v = np.linspace(0, 1, 1001).reshape(1, 1, 1, -1)
    v[..., -1] = 1.0
    fine, _ = display_luminance(v, DisplaySettings(bits=16, gamma=2.2, black_nits=0.0))
    ref = v / np.percentile(v, 99.9)
    assert np.allclose(fine, np.clip(ref, 0, 1), atol=2e-4)  # encode ∘ decode = identity up to 16-bit steps
    coarse, _ = display_luminance(v, DisplaySettings(bits=1, gamma=2.2, black_nits=0.0))
    assert set(np.unique(coarse)) == {0.0, 1.0}
    # 8-bit steps in code space: the largest luminance step sits at the top of the range (γ > 1)
    l8, _ = display_luminance(v, DisplaySettings(bits=8, gamma=2.2, black_nits=0.0))
    levels = np.unique(l8)
    assert len(levels) <= 256 and np.argmax(np.diff(levels)) == len(levels) - 2


def test_upsampling_is_linear_in_light_and_keeps_the_source_frames(rng):
    v = rng.uniform(0.1, 1, size=(2, 3, 4, 5))
    t = np.array([0.0, 0.01, 0.03])
    up, tu = upsample_linear(v, t, 4)
    assert up.shape == (2, 9, 4, 5) and tu.shape == (9,)
    assert np.allclose(up[:, ::4], v) and np.allclose(tu[::4], t)
    assert np.allclose(up[:, 2], 0.5 * (v[:, 0] + v[:, 1]))
    assert tu[6] == pytest.approx(0.02)
    assert np.all(np.diff(tu) > 0)


def test_bad_display_settings_are_clear_errors():
    with pytest.raises(InputError, match="bits"):
        DisplaySettings(bits=0)
    with pytest.raises(InputError, match="black_nits < peak_nits"):
        DisplaySettings(black_nits=500, peak_nits=400)
    with pytest.raises(InputError, match=r"\(N, T, H, W\)"):
        display_luminance(np.ones((3, 3)), DisplaySettings())


def test_ideal_recapture_of_an_unfiltered_clip_matches_the_direct_simulation():
    """Delta kernel, 16-bit linear display with no black level, no upsampling, ideal sensor:
    the display only rescales the clip, and a log sensor is blind to a global scale."""
    pytest.importorskip("torch")
    import torch

    from fsdvs_hw.scenes.synthetic import SceneConfig, make_scenes
    from fsdvs_hw.sensor import SensorConfig, event_frames

    clips = make_scenes(SceneConfig(height_px=24, width_px=24, n_frames=5, illuminance=50.0), 2, seed=3)
    cfg = SensorConfig.ideal(0.2, dark_intensity=1e-6, full_scale_intensity=1e6)
    display = DisplaySettings(bits=16, gamma=1.0, black_nits=0.0, upsample_factor=1)
    rec, info = recapture(clips.video, clips.timestamps_s, reference_kernel("delta", 1), display=display, sensor=cfg)
    direct = event_frames(
        torch.as_tensor(clips.video), None, timestamps_s=torch.as_tensor(clips.timestamps_s), config=cfg
    )
    assert float(direct.sum()) > 50
    # clipping above the 99.9th percentile and 16-bit rounding may move a crossing or two at most
    assert float((rec - direct).abs().sum()) <= 2
    assert info["clipped_black"] == 0.0
    # blending in linear light is monotone within each interval: an ideal sensor counts the same
    # crossings per source interval whatever the upsampling factor
    up4, _ = recapture(
        clips.video,
        clips.timestamps_s,
        reference_kernel("delta", 1),
        display=DisplaySettings(bits=16, gamma=1.0, black_nits=0.0, upsample_factor=4),
        sensor=cfg,
    )
    assert torch.equal(up4, rec)


def test_emulation_scores_stay_finite_at_the_extremes():
    """An inverted kernel (negative DC: the filtered clip is mostly below zero and the display
    clips it to black) and a kernel scaled by 1e6 (the display gain removes any scale)."""
    pytest.importorskip("torch")
    from fsdvs_hw.design import parse_design
    from fsdvs_hw.explore.emulation import emulation_scores

    d = parse_design({"sensor": {"resolution": [24, 32]}, "emulation": {"n_clips": 1, "n_frames": 4}})
    sensor, emu = d.data["sensor"], d.data["emulation"]
    dog = reference_kernel("dog", 7)
    inverted = emulation_scores(dog.scaled(-1.0), sensor=sensor, emulation=emu)
    assert inverted["status"] == "ok"
    assert inverted["clipped_black"] > 0.9  # almost everything is below black: said, not hidden
    assert all(np.isfinite(inverted[k]) for k in ("events_in_sensor", "events_recaptured", "signed_correlation"))
    base = emulation_scores(dog, sensor=sensor, emulation=emu)
    huge = emulation_scores(dog.scaled(1e6), sensor=sensor, emulation=emu)
    assert huge["events_recaptured"] == base["events_recaptured"]
    assert huge["clipped_black"] == base["clipped_black"]
