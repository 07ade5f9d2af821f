"""The compiled no-grad paths (sensor/native/fused.py) against the torch operations they stand in for.

Bit for bit, not approximately: the event list must not depend on whether the fused path ran.
Each check compares the raw bits (NaN included) on random frames plus the extremes a sensor sees:
black, the v2e knee and one float step either side of it, white, saturation, float overflow,
inf, NaN and negative intensities, thresholds of one value, H·W and B·H·W values.
"""

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fsdvs_hw.sensor import SensorConfig, event_list
from fsdvs_hw.sensor.native import fused as fused_mod
from fsdvs_hw.sensor.native.library import available
from fsdvs_hw.sensor.simulation.events import _COUNT_EPS, _Comparator
from fsdvs_hw.sensor.native.fused import fused_applies, fused_linlog_v2e, fused_substep
from fsdvs_hw.sensor.simulation.pixel import linlog_v2e, lowpass_step

pytestmark = pytest.mark.skipif(not available(), reason="no C compiler: the fused paths do not run")

KNEE = 20 / 255


def _bits(t):
    """The raw bit pattern (NaNs of one payload compare equal)."""
    return t.view(torch.int32) if t.dtype == torch.float32 else t.view(torch.int64)


def _same_bits(a, b):
    return torch.equal(_bits(a.contiguous()), _bits(b.contiguous()))


def _extremes(dtype):
    k = torch.tensor(KNEE, dtype=dtype)
    return torch.tensor(
        [0.0, 1e-30, 1.0, 1.0784, 2.0, 1e30, 1e38, math.inf, math.nan, -1.0, -0.0], dtype=dtype
    ).tolist() + [k.item(), torch.nextafter(k, k + 1).item(), torch.nextafter(k, k - 1).item()]


def _torch_linlog(x):
    """linlog_v2e with the fused path off."""
    saved = fused_mod.fused_applies
    fused_mod.fused_applies = lambda like: False
    try:
        return linlog_v2e(x, KNEE)
    finally:
        fused_mod.fused_applies = saved


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_linlog_v2e_bits_equal_torch(dtype):
    g = torch.Generator().manual_seed(0)
    x = torch.cat([torch.rand(100_003, generator=g, dtype=dtype) * 1.3, torch.tensor(_extremes(dtype), dtype=dtype)])
    x = x.reshape(-1, 1)  # any shape, returned as given
    y = fused_linlog_v2e(x, KNEE)
    assert y.shape == x.shape and y.dtype == dtype
    assert _same_bits(y, _torch_linlog(x))
    strided = torch.stack([x, torch.full_like(x, 0.5)], 1)[:, 0]  # a view, flattened by copy
    assert not strided.is_contiguous() and _same_bits(fused_linlog_v2e(strided, KNEE), y)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(width=32), min_size=1, max_size=40))
def test_linlog_v2e_bits_equal_torch_property(values):
    x = torch.tensor(values, dtype=torch.float32)
    assert _same_bits(fused_linlog_v2e(x, KNEE), _torch_linlog(x))


@pytest.mark.parametrize("knee", [0.0, -0.1, math.nan, math.inf])
def test_linlog_v2e_refuses_a_knee_without_a_chord(knee):
    from fsdvs_hw.errors import InputError

    with pytest.raises(InputError, match="knee: must be a finite number > 0"):
        fused_linlog_v2e(torch.rand(3), knee)


def test_linlog_v2e_takes_the_fused_path_only_without_gradient():
    x = torch.tensor([0.02, 0.05, 0.3, 0.9], requires_grad=True)  # two below the knee, two above
    assert not fused_applies(x)
    y = linlog_v2e(x, KNEE)
    y.sum().backward()  # the torch path: the rounding's gradient passes straight through
    k = 255 * KNEE
    want = torch.tensor([255 * math.log(k) / k, 255 * math.log(k) / k, 1 / 0.3, 1 / 0.9])
    assert torch.allclose(x.grad, want, rtol=1e-6)
    with torch.no_grad():
        assert fused_applies(x)
    assert not fused_applies(torch.rand(5, dtype=torch.float16))


def _torch_substep(target, inten, lp, ref, c_on, c_off, dt, eps, cfg):
    """events._substep_target + leak + events._Comparator, as _advance_steps runs them."""
    if inten is not None:
        fc = cfg.cutoff_hz * torch.clamp((inten + cfg.dark_intensity) / cfg.full_scale_intensity, 0.0, 1.0)
        lp = lowpass_step(lp, target, fc, dt)
        target = lp
    if cfg.leak_rate_hz > 0:
        ref = ref - cfg.leak_rate_hz * c_on * dt
    n_on, n_off, ref_new, d = _Comparator.apply(target, ref, c_on, c_off, eps)
    return (lp if inten is not None else None), ref_new, n_on, n_off, d


def _substep_case(dtype, B, c_layout, seed):
    g = torch.Generator().manual_seed(seed)
    H, W = 17, 29
    L = torch.rand(B, H, W, generator=g, dtype=dtype) * 9 - 2
    lp = torch.rand(B, H, W, generator=g, dtype=dtype) * 9 - 2
    ref = torch.rand(B, H, W, generator=g, dtype=dtype) * 9 - 2
    inten = torch.rand(B, H, W, generator=g, dtype=dtype) * 1.2
    # extremes in the first row: saturated, black, negative, huge jumps, a threshold-exact step
    inten[:, 0, :5] = torch.tensor([0.0, 2.0, -0.5, 1e30, 0.3], dtype=dtype)
    L[:, 0, 5:9] = torch.tensor([1e6, -1e6, 0.0, 0.4], dtype=dtype)
    ref[:, 0, 5:9] = torch.tensor([0.0, 0.0, 0.0, 0.0], dtype=dtype)
    shape = {"one": (1,), "hw": (H, W), "bhw": (B, H, W)}[c_layout]
    c_on = torch.rand(shape, generator=g, dtype=dtype) * 0.3 + 0.02
    c_off = torch.rand(shape, generator=g, dtype=dtype) * 0.3 + 0.02
    dt = torch.rand(B, 1, 1, generator=g, dtype=dtype) * 0.04 + 1e-5
    return L, inten, lp, ref, c_on, c_off, dt


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("c_layout", ["one", "hw", "bhw"])
@pytest.mark.parametrize("photoreceptor", [True, False])
@pytest.mark.parametrize("leak", [0.0, 0.7])
@pytest.mark.parametrize("strided", [False, True])
def test_substep_bits_equal_torch(dtype, c_layout, photoreceptor, leak, strided):
    """``strided``: the per-pixel inputs are views into a (B, n, H, W) clip, as the stepping loop
    passes them (non-contiguous for B > 1: flattened copies that must outlive the C call)."""
    B = 2
    cfg = SensorConfig.preset("v2e-default", leak_rate_hz=leak)
    eps = _COUNT_EPS[str(dtype).split(".")[-1]]
    L, inten, lp, ref, c_on, c_off, dt = _substep_case(dtype, B, c_layout, seed=1)
    if strided:
        L, inten, lp, ref = (torch.stack([x, torch.full_like(x, 7.0)], 1)[:, 0] for x in (L, inten, lp, ref))
        assert not L.is_contiguous()
    if not photoreceptor:
        inten = lp = None
    with torch.no_grad():
        got = fused_substep(L, inten, lp, ref, c_on, c_off, dt, eps, cfg)
        want = _torch_substep(L, inten, lp, ref, c_on, c_off, dt, eps, cfg)
    assert (got[0] is None) == (not photoreceptor)
    for name, a, b in zip(("lp", "ref", "n_on", "n_off", "d"), got, want, strict=True):
        if b is None:
            continue
        assert a.shape == b.shape == (B, 17, 29), name
        assert _same_bits(a, b), name
    assert float(got[2].max()) > 1e5  # the 1e6 jump crossed many thresholds in one step


def test_substep_addcmul_is_one_rounding():
    """The case that tells r + n c rounded twice from torch.addcmul's single rounding (fma)."""
    g = torch.Generator().manual_seed(5)
    n = 50_000
    ref = torch.randn(1, 1, n, generator=g) * 3
    target = ref + torch.randn(1, 1, n, generator=g) * 4
    c = torch.rand(1, 1, n, generator=g) * 0.3 + 0.05
    cfg = SensorConfig.preset("v2e-default", leak_rate_hz=0.0)
    with torch.no_grad():
        got = fused_substep(target, None, None, ref, c, c, torch.ones(1, 1, 1), 1e-4, cfg)[1]
        want = _torch_substep(target, None, None, ref, c, c, torch.ones(1, 1, 1), 1e-4, cfg)[1]
        d = target - ref
        twice = (ref + torch.floor(torch.clamp(d, min=0) / c + 1e-4) * c) - torch.floor(
            -(torch.clamp(d, max=0) / c) + 1e-4
        ) * c
    assert _same_bits(got, want)
    assert not _same_bits(got, twice)  # so the check above can tell the two apart


def test_substep_refuses_thresholds_of_the_wrong_size():
    cfg = SensorConfig.preset("v2e-default")
    x = torch.zeros(1, 4, 4)
    with torch.no_grad(), pytest.raises(ValueError, match="c_on: needs 1, H\\*W=16 or B\\*H\\*W=16 values, got 3"):
        fused_substep(x, None, None, x, torch.ones(3), torch.ones(16), torch.ones(1, 1, 1), 1e-4, cfg)


@pytest.mark.parametrize("substeps", [1, 3])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_event_list_is_the_same_with_and_without_fused_paths(monkeypatch, substeps, dtype):
    """Whole event lists (v2e-default: photoreceptor, leak, refractory period, shot noise) with the
    fused paths and with the torch operations; sub-steps > 1 take the interpolated targets."""
    g = torch.Generator().manual_seed(3)
    video = (torch.rand(1, 8, 24, 32, generator=g, dtype=dtype) * 0.8 + 0.05).cumsum(1) / 4
    cfg = SensorConfig.preset("v2e-default", substeps=substeps, shot_noise_rate_hz=2.0, leak_rate_hz=0.5)
    calls = []
    real = fused_mod.fused_substep

    def counting(*a):
        calls.append(1)
        return real(*a)

    monkeypatch.setattr("fsdvs_hw.sensor.simulation.events.fused_substep", counting)
    fused_ev = event_list(video, None, config=cfg)
    assert len(calls) == 7 * substeps  # every sub-step took the fused path
    monkeypatch.setattr("fsdvs_hw.sensor.simulation.events.fused_substep_applies", lambda *a: False)
    monkeypatch.setattr(fused_mod, "fused_applies", lambda like: False)
    torch_ev = event_list(video, None, config=cfg)
    assert len(calls) == 7 * substeps
    assert len(fused_ev) > 500
    for a in ("b", "x", "y", "t", "p"):
        assert torch.equal(getattr(fused_ev, a), getattr(torch_ev, a)), a


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_floor_bits_and_count_equal_torch(dtype):
    g = torch.Generator().manual_seed(2)
    x = torch.cat([torch.rand(50_001, generator=g, dtype=dtype) * 2e-3, torch.tensor(_extremes(dtype), dtype=dtype)])
    floor = 1e-3
    y, n = fused_mod.fused_floor(x.reshape(-1, 7), floor)
    assert y.shape == (x.numel() // 7, 7)
    assert n == int(torch.count_nonzero(x < floor)) and n > 20_000
    assert _same_bits(y.reshape(-1), torch.clamp(x, min=floor))


def test_filtered_log_signal_is_the_same_with_and_without_fused_paths(monkeypatch):
    """The no-grad filtered signal (floor, v2e response, identity kernel skipped) against the torch path."""
    from fsdvs_hw.sensor.simulation.filtering import _is_identity, apply_kernel, filtered_log_signal, kernel_tensor

    g = torch.Generator().manual_seed(4)
    video = torch.rand(2, 3, 9, 11, generator=g)
    video[0, 0, 0, :4] = torch.tensor([0.0, 1e-4, 1.0, 3.0])  # below the floor, at white, above
    cfg = SensorConfig.preset("v2e-default")
    w = kernel_tensor(None, video)
    assert _is_identity(w) and _same_bits(apply_kernel(video, w), video)  # what skipping it skips
    assert not _is_identity(w * 0.5)
    with torch.no_grad():
        got = filtered_log_signal(video, w, cfg)
        monkeypatch.setattr(fused_mod, "fused_applies", lambda like: False)
        want = filtered_log_signal(video, w, cfg)
    assert got.floor_fraction == want.floor_fraction > 0
    assert _same_bits(got.log_signal, want.log_signal)
    assert _same_bits(got.cutoff_intensity, want.cutoff_intensity)


def test_baseline_build_without_clones_gives_the_same_events(monkeypatch, tmp_path):
    """The kernels built for baseline x86-64 alone (``-DFSDVS_NO_CLONES``: floor and fma through
    libm, no AVX2) against the default build, whose x86-64-v3 clone runs on this machine: the
    fused outputs and a whole event list, bit for bit, so a machine without AVX2 sees the same."""
    import ctypes

    from fsdvs_hw.sensor.native import library as native

    default = native.loaded()
    monkeypatch.setenv("FSDVS_HW_CACHE", str(tmp_path))
    path = native._build(("-DFSDVS_NO_CLONES",))
    baseline = ctypes.CDLL(str(path))
    native._declare(baseline)
    assert path.parent == tmp_path and path.name.startswith("crossings-")

    g = torch.Generator().manual_seed(9)
    video = (torch.rand(1, 7, 20, 26, generator=g) * 0.9 + 0.02).cumsum(1) / 3
    video[0, 2, :3, :3] = 0.0  # below the floor
    cfg = SensorConfig.preset("v2e-default", shot_noise_rate_hz=2.0, leak_rate_hz=0.5)
    L, inten, lp, ref, c_on, c_off, dt = _substep_case(torch.float32, 2, "hw", seed=3)
    outputs = []
    for lib in (default, baseline):
        monkeypatch.setattr(native, "_lib", lib)
        with torch.no_grad():
            step = fused_substep(L, inten, lp, ref, c_on, c_off, dt, 1e-4, cfg)
        outputs.append((step, fused_linlog_v2e(inten, KNEE), event_list(video, None, config=cfg)))
    (step_a, lin_a, ev_a), (step_b, lin_b, ev_b) = outputs
    assert all(_same_bits(a, b) for a, b in zip(step_a, step_b, strict=True))
    assert _same_bits(lin_a, lin_b)
    assert len(ev_a) > 300
    for a in ("x", "y", "t", "p"):
        assert torch.equal(getattr(ev_a, a), getattr(ev_b, a)), a
