"""Frame upsampling: flow recovers a translated mid-frame where linear blending blurs, occlusion
rule, identity on equal frames, bad options refused, and ``simulate --upsample``."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from fsdvs_hw.cli import main
from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor.eventfiles.eventfile import read_events
from fsdvs_hw.sensor.simulation.upsampling import interpolate_frames, upsample_frames, visible_masks


def _texture(shape=(64, 64), seed=0):
    """Smooth periodic log-normal texture (so np.roll is an exact translation)."""
    rng = np.random.default_rng(seed)
    return np.exp(3.0 * gaussian_filter(rng.normal(size=shape), 2.0, mode="wrap"))


@pytest.mark.parametrize("shift", [4, 8])
def test_flow_recovers_the_translated_mid_frame_where_linear_blurs(shift):
    tex = _texture()
    a, b, mid = tex, np.roll(tex, shift, axis=1), np.roll(tex, shift // 2, axis=1)
    inner = (slice(8, -8), slice(16, -16))  # away from the wrap-around seam

    def err(x):
        return float(np.median(np.abs(np.log(x[inner]) - np.log(mid[inner]))))

    flow = interpolate_frames(a, b, [0.5], mode="flow")[0]
    linear = interpolate_frames(a, b, [0.5], mode="linear")[0]
    assert err(flow) < 0.01  # log units: 1 % of intensity
    assert err(linear) > 0.05 > 5 * err(flow)


def test_linear_mode_is_linear_in_log_intensity():
    a, b = np.full((4, 4), 0.1), np.full((4, 4), 10.0)
    out = interpolate_frames(a, b, [0.0, 0.25, 0.5, 1.0], mode="linear")
    eps = 1e-4 * 10.0  # the module's log offset: 1e-4 x the brightest pixel
    want = np.exp(np.log(0.1 + eps) + np.array([0.0, 0.25, 0.5, 1.0]) * (np.log(10 + eps) - np.log(0.1 + eps))) - eps
    assert np.allclose(out[:, 0, 0], want, rtol=1e-12)
    assert np.allclose(out[0], a) and np.allclose(out[-1], b)


def test_sub_pixel_motion_is_left_to_linear_interpolation():
    """Flow vectors under 0.5 px are zeroed (their error is as large as the motion): a 0.25 px
    shift gives exactly the linear-in-log frames."""
    from scipy.ndimage import shift

    tex = _texture((32, 32), seed=5)
    moved = shift(tex, (0.0, 0.25), order=3, mode="wrap")
    taus = [0.25, 0.5, 0.75]
    assert np.array_equal(
        interpolate_frames(tex, moved, taus, mode="flow"), interpolate_frames(tex, moved, taus, mode="linear")
    )


@pytest.mark.parametrize("mode", ["linear", "flow"])
def test_equal_frames_give_the_same_frame(mode):
    tex = _texture((32, 32), seed=1)
    out = interpolate_frames(tex, tex, [0.1, 0.5, 0.9], mode=mode)
    assert np.allclose(out, tex[None], rtol=1e-12)


def test_occlusion_rule_marks_pixels_whose_flows_do_not_cancel():
    fw = np.zeros((5, 10, 2), np.float32)
    fw[..., 0] = 3.0  # frame 0 moves 3 px right
    bw = -fw.copy()
    bw[:, 6:] = 0.0  # but columns 6-9 of frame 1 did not come from frame 0 (uncovered background)
    v0, v1 = visible_masks(fw, bw)
    assert v0[:, :3].all() and not v0[:, 3:].any()  # destinations 6.. are inconsistent: covered
    assert v1[:, :6].all() and not v1[:, 6:].any()
    # a 0.5 px disagreement is within the absolute tolerance (0.5 px²), 1 px is not
    assert visible_masks(fw, -fw + np.float32([0.5, 0.0]))[0].all()
    assert not visible_masks(fw, -fw + np.float32([1.0, 0.0]))[0].any()


def test_occluded_pixels_take_the_visible_neighbour_only():
    """A dark square moves right over a static bright textured background: where it uncovers
    background, the mid-frame takes frame 1's background (not half the square)."""
    bg = 1.0 + 0.3 * (_texture((48, 64), seed=2) > 1.0)  # textured so the flow has structure
    a, b = bg.copy(), bg.copy()
    a[16:32, 12:28] = 0.05
    b[16:32, 20:36] = 0.05
    mid = interpolate_frames(a, b, [0.5], mode="flow")[0]
    lin = interpolate_frames(a, b, [0.5], mode="linear")[0]
    truth = bg.copy()
    truth[16:32, 16:32] = 0.05
    region = (slice(18, 30), slice(12, 15))  # uncovered between frame 0 and the mid-frame (edge column left out)
    flow_err = np.median(np.abs(np.log(mid[region] / truth[region])))
    lin_err = np.median(np.abs(np.log(lin[region] / truth[region])))
    assert flow_err < 0.25 and lin_err > 1.0  # linear: half of the square's log contrast ln(1/0.05) = 3.0


def test_upsample_frames_times_and_passthrough():
    frames = [np.full((4, 4), 1.0), np.full((4, 4), 2.0), np.full((4, 4), 4.0)]
    out = list(upsample_frames(frames, mode="linear", rate_hz=100.0, timestamps_s=[0.0, 0.04, 0.05]))
    assert np.allclose([t for t, _ in out], [0.0, 0.01, 0.02, 0.03, 0.04, 0.05])
    assert np.allclose(out[2][1], np.sqrt(2.0), rtol=1e-3)
    same = list(upsample_frames(frames, mode="none", rate_hz=400.0, frame_rate_hz=25.0))
    assert [t for t, _ in same] == [0.0, 0.04, 0.08] and all(f is not None for _, f in same)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"mode": "slomo"}, "allowed: none, linear, flow"),
        ({"rate_hz": 0.0}, "(0, 100000]"),
        ({"rate_hz": float("nan")}, "rate_hz"),
        ({"rate_hz": "fast"}, "rate_hz"),
    ],
)
def test_bad_options_raise_input_error(kwargs, words):
    with pytest.raises(InputError, match=None) as exc:
        list(upsample_frames([np.ones((4, 4))] * 2, frame_rate_hz=25.0, **kwargs))
    assert words in str(exc.value)


def test_bad_frames_raise_input_error():
    with pytest.raises(InputError, match="strictly increasing"):
        list(upsample_frames([(0.1, np.ones((4, 4))), (0.1, np.ones((4, 4)))], mode="linear"))
    with pytest.raises(InputError, match="timestamps_s or frame_rate_hz"):
        list(upsample_frames([np.ones((4, 4))] * 2, mode="linear"))
    with pytest.raises(InputError, match=">= 0"):
        interpolate_frames(-np.ones((4, 4)), np.ones((4, 4)), [0.5])
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        interpolate_frames(np.ones((4, 4)), np.ones((4, 4)), [1.5])
    with pytest.raises(InputError, match="'none' makes no frames"):
        interpolate_frames(np.ones((4, 4)), np.ones((4, 4)), [0.5], mode="none")


def test_simulate_cli_upsample_inserts_frames_and_refuses_bad_rate(tmp_path, capsys):
    base, up = tmp_path / "base.npz", tmp_path / "up.npz"
    args = ["simulate", "example:carphone", "--frames", "3", "--size", "36x44", "--preset", "ideal", "--no-progress"]
    assert main([*args, "--out", str(base)]) == 0
    assert main([*args, "--out", str(up), "--upsample", "flow", "--upsample-rate", "300"]) == 0
    b, u = read_events(base), read_events(up)
    assert len(u) > 0 and len(b) > 0
    assert u.t_us.min() >= 0 and u.t_us.max() <= round(2 / 29.97 * 1e6)  # same clip span
    # flow frames put events at new times: some event times are not on the linear interpolation's grid
    assert not np.array_equal(np.sort(u.t_us), np.sort(b.t_us))
    assert main([*args, "--out", str(up), "--upsample-rate", "-5"]) == 2
    assert "--upsample-rate" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse refuses an unknown choice
        main([*args, "--out", str(up), "--upsample", "slomo"])


def test_plan_turns_upsampling_on_for_fast_motion_and_says_why():
    import torch

    from fsdvs_hw.sensor import SensorConfig, plan_model
    from fsdvs_hw.sensor.simulation.upsampling import UPSAMPLE_MOTION_PX

    tex = _texture((32, 48), seed=3)
    cfg = SensorConfig.ideal(0.2)

    def plan(step_px):
        video = torch.as_tensor(np.stack([np.roll(tex, step_px * k, axis=1) for k in range(4)]))[None]
        return plan_model(video, config=cfg, timestamps_s=torch.arange(4.0)[None] / 25.0)

    fast, slow = plan(6), plan(1)
    d = fast.decision("frame upsampling")
    # the 99th percentile includes the wrap-around seam of np.roll, a little above the true 6 px
    assert d.included and 5.5 < d.value < 8 and d.limit == UPSAMPLE_MOTION_PX
    rate = 25.0 * np.ceil(d.value)
    assert fast.upsample_rate_hz == pytest.approx(rate) and f"upsample to {rate:g} Hz" in d.reason
    assert not slow.decision("frame upsampling").included and slow.upsample_rate_hz is None
    assert "frame upsampling" in slow.skipped and "frame upsampling" in str(fast)


def test_design_key_emulation_upsample_is_checked_and_unset_keeps_the_fingerprint():
    from fsdvs_hw.design import DesignError, parse_design

    plain = parse_design({"design": {"name": "u"}})
    linear = parse_design({"design": {"name": "u"}, "emulation": {"upsample": "linear_light"}})
    flow = parse_design({"design": {"name": "u"}, "emulation": {"upsample": "flow"}})
    assert "upsample" not in plain.data["emulation"]  # unset: content and fingerprint as before the key existed
    assert len({plain.fingerprint(), linear.fingerprint(), flow.fingerprint()}) == 3
    with pytest.raises(DesignError, match=r"emulation\.upsample"):
        parse_design({"design": {"name": "u"}, "emulation": {"upsample": "slomo"}})


def test_emulation_flow_upsampling_keeps_the_source_frames():
    from fsdvs_hw.explore.emulation import upsample_linear

    tex = _texture((24, 24), seed=4)
    video = np.stack([tex, np.roll(tex, 4, axis=1), np.roll(tex, 8, axis=1)])[None]
    up, tu = upsample_linear(video, np.array([0.0, 0.04, 0.08]), 4, "flow")
    assert up.shape == (1, 9, 24, 24) and np.allclose(tu, np.arange(9) * 0.01)
    assert np.allclose(up[0, ::4], video[0])  # fraction 0 of each interval is the source frame
    inner = (slice(4, -4), slice(8, -8))
    assert np.median(np.abs(np.log(up[0, 2][inner] / np.roll(tex, 2, axis=1)[inner]))) < 0.02
