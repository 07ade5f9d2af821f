"""v2e-compatible presets: v2e's linear-log chord, bandwidth offset and named noise settings."""

import math

import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import SensorConfig, event_frames
from fsdvs_hw.sensor.simulation.pixel import linlog_v2e, photoreceptor_cutoff_hz


def test_v2e_response_matches_v2e_lin_log_values():
    i = torch.tensor([0.0, 10 / 255, 20 / 255, 1.0], dtype=torch.float64)
    y = linlog_v2e(i, 20 / 255)
    # v2e lin_log on DN: x·log(20)/20 at and below 20 DN, log(x) above; rounded to 1e-8
    want = [0.0, 0.5 * math.log(20), math.log(20), math.log(255)]
    assert y.tolist() == pytest.approx(want, abs=1e-8)
    assert float(y[1] * 1e8) == pytest.approx(round(float(y[1]) * 1e8), abs=1e-6)  # rounded to 8 digits


def test_v2e_chord_gives_v2e_contrast_gain_below_the_knee():
    # a step from 5 to 10 DN: v2e's chord sees 5·log(20)/20 = 0.749 log units (3 events at C=0.2),
    # the tangent sees 5/20 = 0.25 (1 event); above the knee both see log(2) = 0.693 (3 events)
    def count(lo, hi, preset):
        v = torch.tensor([lo, hi], dtype=torch.float64).view(1, 2, 1, 1) / 255
        cfg = SensorConfig.preset(preset, threshold_sigma=0.0) if preset.startswith("v2e") else SensorConfig.ideal(0.2)
        return int(event_frames(v, config=cfg)[0, 0, 0].sum())

    assert count(5, 10, "v2e-clean") == 3 and count(5, 10, "ideal") == 1
    assert count(100, 200, "v2e-clean") == count(100, 200, "ideal") == 3


def test_v2e_bandwidth_offset_is_dn_plus_20_over_275():
    cfg = SensorConfig.preset("v2e-default")
    fc = photoreceptor_cutoff_hz(torch.tensor([0.0, 100 / 255, 1.0], dtype=torch.float64), cfg)
    assert fc.tolist() == pytest.approx([300 * 20 / 275, 300 * 120 / 275, 300.0], rel=1e-12)


def test_presets_carry_v2e_settings_and_default_is_unchanged():
    assert SensorConfig.preset("default") == SensorConfig()
    assert SensorConfig.preset("ideal") == SensorConfig.ideal()
    clean, noisy = SensorConfig.preset("v2e-clean"), SensorConfig.preset("v2e-noisy")
    assert (clean.threshold_sigma, clean.cutoff_hz, clean.shot_noise_rate_hz, clean.refractory_s) == (0.02, 0, 0, 0)
    assert (noisy.threshold_sigma, noisy.cutoff_hz, noisy.leak_rate_hz, noisy.shot_noise_rate_hz) == (
        0.05,
        30,
        0.1,
        5.0,
    )
    assert SensorConfig().response == "tangent"
    with pytest.raises(InputError, match="preset"):
        SensorConfig.preset("v2e-loud")
    with pytest.raises(InputError, match="response"):
        SensorConfig(response="chord")


def test_linlog_v2e_rounding_equals_torch_round():
    """v2e's 1e-8 rounding (here by the add-and-subtract 1.5·2**52 trick) equals torch.round's
    ties-to-even result bit for bit, with and without autograd, from 0 and sub-knee values to the
    float32 maximum (where 255·I overflows to inf: inf, never NaN, on both paths); exact ties round
    to even."""
    import math

    import torch

    from fsdvs_hw.sensor.simulation.pixel import _round_half_even, linlog_v2e

    g = torch.Generator().manual_seed(0)
    inten = torch.cat(
        [
            torch.zeros(3),
            torch.rand(2000, generator=g) * 0.1,
            torch.rand(2000, generator=g),
            torch.logspace(-30, 38, 500),
            torch.tensor([3.4e38]),
        ]
    ).float()
    knee = 20 / 255
    x, k = inten * 255.0, knee * 255.0
    y = torch.where(x <= k, x * (math.log(k) / k), torch.log(torch.clamp(x, min=k)))
    want = torch.round(y.double() * 1e8).div(1e8).to(y.dtype)
    assert torch.equal(linlog_v2e(inten, knee), want)
    inten.requires_grad_(True)
    out = linlog_v2e(inten, knee)
    assert out.requires_grad and torch.equal(out.detach(), want) and not torch.isnan(out).any()
    assert torch.isinf(want[-1]) and torch.isfinite(want[:-60]).all()
    ties = torch.tensor([0.5, 1.5, 2.5, -0.5, -2.5, 1e10 + 0.5], dtype=torch.float64)
    assert torch.equal(_round_half_even(ties.clone()), torch.round(ties))


def test_shot_noise_draw_is_per_pixel_by_default_and_sparse_in_v2e_presets():
    """Stored results were made with the per-pixel draw: it stays the default; the v2e presets
    (no stored result uses them) draw sparsely; a bad value names the field and the choices."""
    assert SensorConfig().shot_noise_draw == "per_pixel" and SensorConfig.ideal().shot_noise_draw == "per_pixel"
    for name in ("v2e-clean", "v2e-default", "v2e-noisy"):
        assert SensorConfig.preset(name).shot_noise_draw == "sparse"
    with pytest.raises(InputError, match="shot_noise_draw.*per_pixel, sparse"):
        SensorConfig(shot_noise_draw="fast")
    # same law: the mean noise count of a static clip agrees between the draws (5 Hz, 64x64, 60 frames)
    video = torch.full((1, 61, 64, 64), 0.5)
    counts = [
        float(
            event_frames(
                video, None, config=SensorConfig.ideal(shot_noise_rate_hz=5.0, seed=s, shot_noise_draw=d)
            ).sum()
        )
        for d in ("per_pixel", "sparse")
        for s in (0, 1)
    ]
    expect = 5.0 * 64 * 64 * 60 / SensorConfig().frame_rate_hz  # events: rate x pixels x duration
    for c in counts:
        assert abs(c - expect) < 5 * math.sqrt(expect)
