"""The fast exact event path (sensor/simulation/crossings.py) against the full-frame formulation it replaced.

The reference below is the previous implementation's per-step code (full-frame refractory
arithmetic, per-polarity expansion, one stable sort): the fast path must give the same events bit
for bit, in the same order.
"""

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fsdvs_hw.sensor import SensorConfig, event_frames, event_list
from fsdvs_hw.sensor.native.library import sort_events, sort_intervals_to_columns
from fsdvs_hw.sensor.simulation.crossings import (
    ComparatorStep,
    crossing_step,
    crossing_step_torch,
    shot_noise_pixels,
    sort_interval,
    stable_time_order,
    to_event_columns,
)


def _ref_emit(n, d_a, v, c, t_a, last_t, refr):
    vs = torch.where(v > 0, v, torch.ones_like(v))
    j0 = torch.ceil((vs * (last_t + refr - t_a) + d_a) / c).clamp(min=1.0)
    m = torch.ceil(refr * vs / c).clamp(min=1.0)
    emitted = torch.where(n >= j0, 1.0 + torch.floor((n - j0) / m), torch.zeros_like(n))
    emitted = torch.where(v > 0, emitted, torch.zeros_like(n))
    j_last = j0 + (emitted - 1.0) * m
    t_last = torch.where(emitted > 0, t_a + (j_last * c - d_a) / vs, last_t)
    return emitted, j0, m, t_last


def _ref_collect(store, emitted, j0, m, d_a, v, c, t_a, t_b, polarity):
    idx = torch.nonzero(emitted > 0)
    if idx.numel() == 0:
        return
    bi, yi, xi = idx[:, 0], idx[:, 1], idx[:, 2]
    counts = emitted[bi, yi, xi].long()
    rep = torch.repeat_interleave(torch.arange(len(counts)), counts)
    ends = torch.cumsum(counts, 0)
    k = torch.arange(len(rep)) - (ends - counts)[rep]
    cc = c.expand_as(emitted)[bi, yi, xi][rep] if c.ndim else c.expand(len(rep))
    j = j0[bi, yi, xi][rep] + k.to(j0.dtype) * m[bi, yi, xi][rep]
    vv = v[bi, yi, xi][rep]
    ta = t_a.expand_as(emitted)[bi, yi, xi][rep]
    tb = t_b.expand_as(emitted)[bi, yi, xi][rep]
    t_min = torch.nextafter(ta, torch.full_like(ta, math.inf))
    t = torch.minimum(torch.maximum(ta + (j * cc - d_a[bi, yi, xi][rep]) / vv, t_min), tb)
    store.append((bi[rep], xi[rep], yi[rep], t, torch.full((len(rep),), polarity, dtype=torch.int8)))


def _reference_step(h_on, h_off, sig_a, ref_a, d_b, c_on, c_off, t_a, t_b, dt, last_t, refr):
    store = []
    d_a = (sig_a - ref_a).double()
    v = (d_b.double() - d_a) / dt
    co, cf = c_on.double(), c_off.double()
    lt = last_t if last_t is not None else torch.full_like(d_a, -math.inf)
    em_on, j0_on, m_on, lt = _ref_emit(h_on.double(), d_a, v, co, t_a, lt, refr)
    em_off, j0_off, m_off, lt = _ref_emit(h_off.double(), -d_a, -v, cf, t_a, lt, refr)
    _ref_collect(store, em_on, j0_on, m_on, d_a, v, co, t_a, t_b, 1)
    _ref_collect(store, em_off, j0_off, m_off, -d_a, -v, cf, t_a, t_b, -1)
    if not store:
        return None, lt, em_on, em_off
    b, x, y, t, p = (torch.cat(c) for c in zip(*store, strict=True))
    order = torch.argsort(t, stable=True)
    order = order[torch.argsort(b[order], stable=True)]
    return (b[order], x[order], y[order], t[order], p[order]), lt, em_on, em_off


@pytest.mark.parametrize("step", [crossing_step, crossing_step_torch], ids=["compiled", "torch"])
@pytest.mark.parametrize("refr", [0.0, 2e-3, 0.02])
@pytest.mark.parametrize("mismatch", [False, True])
@pytest.mark.parametrize("B", [1, 3])
def test_crossing_step_equals_full_frame_reference(refr, mismatch, B, step):
    g = torch.Generator().manual_seed(int(refr * 1e4) + 7 * B + mismatch)
    H, W = 9, 11
    sig_a = torch.rand(B, H, W, generator=g) * 3
    ref_a = sig_a - (torch.rand(B, H, W, generator=g) - 0.5) * 0.3
    target = sig_a + (torch.rand(B, H, W, generator=g) - 0.5) * 4
    ref = ref_a - 0.001  # a small leak between the step start and end
    c_on = (0.2 + 0.03 * torch.randn(H, W, generator=g)).clamp(min=0.05) if mismatch else torch.tensor(0.2)
    c_off = (0.25 + 0.03 * torch.randn(H, W, generator=g)).clamp(min=0.05) if mismatch else torch.tensor(0.25)
    d_b = target - ref
    h_on = torch.floor(torch.clamp(d_b, min=0) / c_on + 1e-4)
    h_off = torch.floor(torch.clamp(-d_b, min=0) / c_off + 1e-4)
    t0 = torch.tensor([0.5, 0.7, 0.9][:B], dtype=torch.float64).view(B, 1, 1)
    dt = torch.tensor([0.04, 0.01, 0.02][:B], dtype=torch.float64).view(B, 1, 1)
    t_b = t0 + dt
    last = None
    if refr > 0:  # some pixels fired just before the step, some long ago, some never
        last = t0 - torch.rand(B, H, W, generator=g, dtype=torch.float64) * 2 * refr
        last[:, ::3] = -math.inf
    ref_ev, ref_lt, ref_on, ref_off = _reference_step(
        h_on, h_off, sig_a, ref_a, d_b, c_on, c_off, t0, t_b, dt, None if last is None else last.clone(), refr
    )
    parts = []
    lt = None if last is None else last.clone()
    comparator = ComparatorStep(h_on, h_off, sig_a, ref_a, d_b, c_on, c_off, t0, t_b, dt, lt, refr)
    lost, em_on, em_off = step(parts, comparator, True, True)
    got = to_event_columns([sort_interval(parts)], H, W, B)
    assert ref_ev is not None and len(ref_ev[0]) > 10
    for a, r in zip(got, ref_ev, strict=True):
        assert a.dtype == r.dtype and torch.equal(a, r)
    assert torch.equal(em_on, ref_on.float()) and torch.equal(em_off, ref_off.float())
    if refr > 0:
        assert torch.equal(lt, ref_lt)
        expect = float((h_on + h_off).sum() - (ref_on + ref_off).sum())
        assert lost == expect and (refr < 0.01 or lost > 0)  # the long period loses crossings
    if refr == 0.02:  # the kernel skips the divisions where j0 = m = 1: both sides are exercised here
        d_a = (sig_a - ref_a).double()
        v = (d_b.double() - d_a) / dt
        on = (h_on > 0) & (v > 0)
        co = c_on.double().expand_as(v)
        xj = v * (last + refr - t0) + d_a
        xm = refr * v
        assert bool((xm[on] > co[on]).any()) and bool((xm[on] <= co[on]).any())  # m > 1 and m = 1
        assert bool((xj[on] > co[on]).any()) and bool((xj[on] <= co[on]).any())  # j0 > 1 and j0 = 1


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 5), min_size=0, max_size=300))
def test_stable_time_order_is_a_stable_sort(values):
    t = np.asarray(values, dtype=np.float64) * 0.25  # many ties
    assert np.array_equal(stable_time_order(t), np.argsort(t, kind="stable"))


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.lists(st.integers(0, 40), max_size=200), min_size=1, max_size=4), st.sampled_from([0.25, 1e-9, 1e-300])
)
def test_compiled_bucket_sort_is_a_stable_sort(values, scale):
    """The compiled interval sort equals a stable argsort of the concatenated parts: ties (many
    here), clustered times (big buckets: the merge-sort branch) and spans too short for the bucket
    arithmetic (1e-300)."""
    parts, start = [], 0
    for v in values:
        t = 3.0 + np.asarray(v, dtype=np.float64) * scale
        parts.append((np.arange(start, start + len(t), dtype=np.int32), t, np.where(t > 3.0, 1, -1).astype(np.int8)))
        start += len(t)
    all_t = np.concatenate([q[1] for q in parts])
    order = np.argsort(all_t, kind="stable")
    # bucket range from the data, and given wider (as the simulator passes the frame times)
    for bounds in ((None, None), (2.0, 3.0 + 50 * scale + 1.0)):
        flat, t, p = sort_events(parts, *bounds)
        assert np.array_equal(t, all_t[order]) and np.array_equal(flat, order)
        assert np.array_equal(p, np.concatenate([q[2] for q in parts])[order])


@pytest.mark.parametrize(
    "n, kind",
    [
        (50_000, "uniform"),
        (50_000, "ties"),
        (50_000, "one_cluster"),  # nearly every event in one bucket: the merge-sort branch
    ],
)
def test_compiled_bucket_sort_of_an_interval_sized_list_is_a_stable_sort(n, kind):
    """At the size of a real interval (bikes: ~70 000 events in 3 parts), as the hypothesis tests
    above cannot reach: the stable argsort of the concatenated parts, ties in part order, pixel
    and polarity carried along, with uniform, tied and one-bucket-clustered times."""
    rng = np.random.default_rng(n)
    if kind == "uniform":
        t = 5.0 + rng.random(n)
    elif kind == "ties":
        t = 5.0 + rng.integers(0, 300, n) * 0.125
    else:
        t = 5.0 + np.where(rng.random(n) < 0.999, 0.5 + rng.random(n) * 1e-12, rng.random(n))
    cuts = np.sort(rng.choice(np.arange(1, n), 3, replace=False))
    flat = rng.permutation(n).astype(np.int32)
    pol = np.where(rng.random(n) < 0.5, 1, -1).astype(np.int8)
    parts = [(flat[a:b], t[a:b], pol[a:b]) for a, b in zip([0, *cuts], [*cuts, n], strict=True)]
    order = np.argsort(t, kind="stable")
    got_flat, got_t, got_p = sort_events(parts, 4.0, 7.0)
    assert np.array_equal(got_t, t[order]) and np.array_equal(got_flat, flat[order])
    assert np.array_equal(got_p, pol[order])


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.lists(st.lists(st.integers(0, 40), max_size=120), min_size=1, max_size=3), min_size=1, max_size=3),
    st.sampled_from([0.25, 1e-9, 1e-300]),
)
def test_compiled_sort_to_columns_is_a_stable_sort(intervals, scale):
    """A chunk's columns, each interval bucket-sorted as records (``sort_intervals_to_columns``):
    each interval's events in stable time order (ties in part order, clustered times taking the
    merge-sort branch, spans of 1e-300 s), pixel indices split into x = f mod W, y = f div W."""
    H, W = 7, 13
    chunk, expect = [], []
    for k, values in enumerate(intervals):
        parts, lo = [], 3.0 + 10.0 * k
        for v in values:
            t = lo + np.asarray(v, dtype=np.float64) * scale
            flat = ((np.arange(len(t)) * 37 + 11 * len(parts)) % (H * W)).astype(np.int32)
            parts.append((flat, t, np.where(np.arange(len(t)) % 3 == 0, 1, -1).astype(np.int8)))
        cat = [np.concatenate([q[i] for q in parts]) for i in range(3)]
        order = np.argsort(cat[1], kind="stable")
        expect.append((cat[0][order] % W, cat[0][order] // W, cat[1][order], cat[2][order]))
        chunk.append((parts, lo - 1.0, lo + 50 * scale + 1.0))
    x, y, t, p = sort_intervals_to_columns(chunk, H * W, W)
    for got, want in zip((x, y, t, p), zip(*expect, strict=True), strict=True):
        assert np.array_equal(got, np.concatenate(want))
    assert x.dtype == np.int64 and t.dtype == np.float64 and p.dtype == np.int8
    assert all(not parts for parts, _, _ in chunk)  # each interval's parts are released


@pytest.mark.parametrize("sparse", [False, True], ids=["per_pixel", "sparse"])
def test_shot_noise_pixels_are_independent_poisson_per_pixel(sparse):
    """Both draws: per-pixel counts with the mean and variance of Poisson(lam) (dispersion 1),
    per-batch rates, no pixel far from the rest, indices sorted with one entry per event; and the
    per-pixel draw is torch.poisson's over the frame, ON then OFF (the stream every stored result
    was made with)."""
    g = torch.Generator().manual_seed(5)
    B, HW, steps = 2, 400, 500
    lam = torch.tensor([0.02, 0.2], dtype=torch.float64)
    counts = torch.zeros(steps, B * HW)
    for i in range(steps):
        on, off = shot_noise_pixels(B, HW, lam, g, sparse)
        assert torch.equal(on, torch.sort(on).values) and on.dtype == torch.int64
        counts[i] = torch.bincount(on, minlength=B * HW).float()
    for b in range(B):
        c = counts[:, b * HW : (b + 1) * HW]
        se = math.sqrt(float(lam[b]) / c.numel())
        assert abs(float(c.mean()) - float(lam[b])) < 4 * se
        assert float(c.var()) / float(c.mean()) == pytest.approx(1.0, abs=0.05)
    per_px = counts[:, HW:].sum(0)  # uniform over pixels: Poisson(100) each, none beyond 6 sd
    assert float((per_px - steps * 0.2).abs().max()) < 6 * math.sqrt(steps * 0.2)
    if sparse:
        return
    g1, g2 = torch.Generator().manual_seed(9), torch.Generator().manual_seed(9)
    on, off = shot_noise_pixels(B, HW, lam, g1)
    rate = lam.view(B, 1).expand(B, HW).contiguous()
    k_on, k_off = torch.poisson(rate, generator=g2).view(-1), torch.poisson(rate, generator=g2).view(-1)
    assert torch.equal(torch.bincount(on, minlength=B * HW), k_on.long())
    assert torch.equal(torch.bincount(off, minlength=B * HW), k_off.long())


def test_event_list_counts_match_frames_with_every_effect():
    """The event list binned per interval equals event_frames (refractory losses and noise on)."""
    g = torch.Generator().manual_seed(3)
    base = torch.rand(24, 40, generator=g) * 0.8 + 0.1
    video = torch.stack([torch.roll(base, 2 * t, dims=1) for t in range(6)])[None]
    cfg = SensorConfig.preset("v2e-default", refractory_s=0.01, shot_noise_rate_hz=5.0)
    frames, info = event_frames(video, config=cfg, return_info=True)
    ev = event_list(video, config=cfg)
    assert info.refractory_lost > 0 and info.noise_events > 0
    assert bool((ev.t[1:] >= ev.t[:-1]).all())
    k = torch.searchsorted(torch.arange(6, dtype=torch.float64) / cfg.frame_rate_hz, ev.t, right=False) - 1
    counts = torch.zeros(5, 2, 24, 40)
    counts.index_put_((k, (ev.p < 0).long(), ev.y, ev.x), torch.ones(len(ev)), accumulate=True)
    assert torch.equal(counts, frames[0])


def test_compiled_kernels_build_here():
    """The C kernels build with this machine's compiler (the Makefile installs gcc); otherwise every
    event list silently takes the slower torch path."""
    from fsdvs_hw.sensor.native import library

    assert library.available(), library.why_unavailable()


def test_event_list_without_compiled_kernels_is_identical(monkeypatch):
    """The torch fallback (no C compiler) gives the same events, bit for bit and in the same order,
    as the compiled path, with every effect on (refractory losses, leak, shot noise, mismatch)."""
    from fsdvs_hw.sensor.native import library

    g = torch.Generator().manual_seed(3)
    video = (torch.rand(1, 9, 24, 32, generator=g) * 0.8 + 0.1).cumsum(1) / 5
    cfg = SensorConfig.preset("v2e-default", refractory_s=0.01, shot_noise_rate_hz=5.0, leak_rate_hz=1.0)
    native = event_list(video, None, config=cfg)
    monkeypatch.setattr(library, "_lib", None)
    monkeypatch.setattr(library, "_tried", True)
    assert not library.available()
    fallback = event_list(video, None, config=cfg)
    assert len(native) > 100
    for a in ("b", "x", "y", "t", "p"):
        assert torch.equal(getattr(native, a), getattr(fallback, a)), a


def test_crossing_totals_are_exact_on_both_sides_of_float32s_exact_range():
    from fsdvs_hw.sensor.simulation.crossings import _total

    small = np.floor(np.random.default_rng(0).random(200_000, dtype=np.float32) * 3)
    assert _total(small) == int(small.astype(np.int64).sum())
    big = np.array([2.0**24, 1.0, 1.0], dtype=np.float32)  # float32 rounds 2**24 + 1 back to 2**24
    assert float(big.sum()) != 2**24 + 2  # the rounding _total must not inherit
    assert _total(big) == 2**24 + 2
    assert _total(big.astype(np.float64)) == 2**24 + 2
    with pytest.raises(ValueError):
        _total(np.array([1.0, np.nan], dtype=np.float32))  # as before: a NaN count is refused
