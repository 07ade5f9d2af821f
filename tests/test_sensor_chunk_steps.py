"""The chunk fast path (fsdvs_hw.sensor.native.chunk_steps) gives the step-by-step path's events bit for bit."""

import pytest
import torch

from fsdvs_hw.sensor import SensorConfig, event_frames, event_list
from fsdvs_hw.sensor.native import chunk_steps, library
from fsdvs_hw.sensor.simulation import events
from fsdvs_hw.sensor.native.chunk_steps import BufferPool
from fsdvs_hw.sensor.simulation.stream import collect, simulate

pytestmark = pytest.mark.skipif(not library.available(), reason="compiled kernels unavailable")


def _clip(T=13, H=12, W=20, seed=1, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    base = torch.rand(1, 1, H, W, generator=g) * 0.8 + 0.05
    drift = torch.linspace(0, 1, T).view(1, T, 1, 1)
    wave = torch.sin(6.28 * (drift + torch.arange(W).view(1, 1, 1, W) / 7.0))
    return (base * (1 + 0.7 * wave)).clamp(min=0.0).to(dtype)


CONFIGS = {
    # photoreceptor low-pass, refractory period that binds, sparse shot noise
    "v2e preset": SensorConfig.preset("v2e-default", shot_noise_rate_hz=20.0, refractory_s=0.02, seed=2),
    # no photoreceptor, no noise, no refractory period
    "v2e clean": SensorConfig.preset("v2e-clean", seed=2),
    # per-pixel noise draw, leak with a random reference phase, mismatch
    "per-pixel noise": SensorConfig(
        shot_noise_rate_hz=10.0, leak_rate_hz=2.0, random_reference_phase=True, refractory_s=5e-3, seed=4
    ),
}


def _without_chunk_path(monkeypatch):
    monkeypatch.setattr(events, "chunk_applies", lambda *a, **k: False)


def _run(video, config, chunk):
    whole = event_list(video, config=config)
    _, info = event_frames(video, config=config, return_info=True)
    _, ev, s_info = collect(simulate(video, config=config, chunk_frames=chunk))
    return whole, ev, s_info, info


def _same(a, b):
    assert len(a) == len(b) > 0
    for name in ("b", "x", "y", "t", "p"):
        assert torch.equal(getattr(a, name), getattr(b, name)), name


@pytest.mark.parametrize("inline", [False, True], ids=["worker threads", "inline"])
@pytest.mark.parametrize("group_pixels", [None, 1, 3 * 240])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("name", list(CONFIGS))
def test_chunk_path_equals_step_by_step_bit_for_bit(name, dtype, group_pixels, inline, monkeypatch):
    """Chunks of 5 intervals in crossing tasks of 1, 3 (with a remainder) or all intervals, on the
    worker threads or inline (stream.INLINE_PIXELS)."""
    from fsdvs_hw.sensor.simulation import stream

    config, video = CONFIGS[name], _clip(dtype=dtype)
    monkeypatch.setattr(stream, "INLINE_PIXELS", 2**30 if inline else 0)
    if group_pixels is not None:
        monkeypatch.setattr(chunk_steps, "GROUP_PIXELS", group_pixels)
    taken = []
    real = chunk_steps.advance_chunk

    def spy(*args, **kwargs):
        taken.append(len(args[1]) - 1)
        return real(*args, **kwargs)

    monkeypatch.setattr(events, "advance_chunk", spy)
    fast_list, fast_stream, fast_info, _ = _run(video, config, chunk=5)
    assert taken == [5, 5, 2]  # the stream's chunks went through it (event_list counts too: it does not)
    monkeypatch.undo()
    monkeypatch.setattr(stream, "INLINE_PIXELS", 0)  # the reference: step by step, on the workers
    _without_chunk_path(monkeypatch)
    slow_list, slow_stream, slow_info, frames_info = _run(video, config, chunk=5)
    _same(fast_list, slow_list)
    _same(fast_stream, slow_stream)
    _same(fast_stream, fast_list)
    assert fast_info.noise_events == slow_info.noise_events == frames_info.noise_events
    assert fast_info.refractory_lost == slow_info.refractory_lost
    if name == "v2e preset":
        assert fast_info.noise_events > 0 and fast_info.refractory_lost > 0


def test_chunk_path_is_not_taken_where_it_does_not_apply(monkeypatch):
    """Sub-steps, a batch of sensors and event counts stay on the step-by-step path."""
    taken = []
    monkeypatch.setattr(events, "advance_chunk", lambda *a, **k: taken.append(1))
    video = _clip(T=5)
    event_list(video, config=SensorConfig(substeps=2))
    event_list(torch.cat([video, video]), config=SensorConfig())
    frames = event_frames(video, config=SensorConfig())
    assert taken == [] and frames.shape[1] == 4


def test_buffer_pool_keeps_each_shape_apart():
    """A tensor of another shape handed back is kept, not dropped, and never handed out for this one."""
    pool = BufferPool(keep=2)
    a, b = pool.take((2, 3), torch.float32), pool.take((4,), torch.float32)
    pool.give(a)
    pool.give(b)
    assert pool.take((4,), torch.float32) is b
    assert pool.take((2, 3), torch.float32) is a
    assert pool.take((2, 3), torch.float64).dtype == torch.float64  # nothing kept: a new one
    given = [torch.empty(5) for _ in range(3)]
    for t in given:
        pool.give(t)
    taken = [pool.take((5,), torch.float32) for _ in range(3)]
    assert sum(any(t is g for g in given) for t in taken) == 2  # keep=2: the third given was dropped


def test_chunk_path_with_a_kernel_and_irregular_frame_times(monkeypatch):
    """A 5x5 DoG before the log stage and frame times with uneven gaps (each interval its own dt
    in the low-pass exponent, the crossing times and the noise rate): the same events either way."""
    from fsdvs_hw.kernels import reference_kernel

    config = CONFIGS["v2e preset"]
    video, kernel = _clip(T=11), reference_kernel("dog", 5)
    gaps = torch.tensor([0.0, 0.01, 0.013, 0.05, 0.0401, 0.002, 0.02, 0.03, 0.011, 0.04, 0.007])
    times = torch.cumsum(gaps, 0).double()
    taken = []
    real = chunk_steps.advance_chunk
    monkeypatch.setattr(events, "advance_chunk", lambda *a, **k: taken.append(1) or real(*a, **k))
    _, fast, fast_info = collect(simulate(video, kernel, timestamps_s=times, config=config, chunk_frames=4))
    assert taken
    monkeypatch.undo()
    _without_chunk_path(monkeypatch)
    _, slow, slow_info = collect(simulate(video, kernel, timestamps_s=times, config=config, chunk_frames=4))
    _same(fast, slow)
    assert fast_info.noise_events == slow_info.noise_events and fast_info.refractory_lost == slow_info.refractory_lost


@pytest.mark.parametrize("inline", [False, True], ids=["worker threads", "inline"])
@pytest.mark.parametrize("chunk_path", [True, False], ids=["chunk path", "step by step"])
def test_an_event_list_past_the_allocation_limit_is_refused_by_name(inline, chunk_path, monkeypatch):
    """A step whose crossings would not fit under the allocation limit stops the stream with an
    InputError that names the event list and the step's size (raised from the worker or inline)."""
    from fsdvs_hw.errors import InputError
    from fsdvs_hw.limits import allocation_limit
    from fsdvs_hw.sensor.simulation import stream

    monkeypatch.setattr(stream, "INLINE_PIXELS", 2**30 if inline else 0)
    if not chunk_path:
        _without_chunk_path(monkeypatch)
    config = SensorConfig.preset("v2e-clean", threshold_on=0.01, threshold_off=0.01)
    with allocation_limit(2000), pytest.raises(InputError, match=r"threshold crossings in one step \(1x12x20 px"):
        collect(simulate(_clip(), config=config, chunk_frames=4))
