"""Streaming simulation: chunked output equals the whole-clip output bit for bit; state carried."""

import numpy as np
import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.sensor import SensorConfig, event_frames, event_list
from fsdvs_hw.sensor.simulation.stream import collect, simulate


def _clip(T=9, H=16, W=24, seed=0):
    g = torch.Generator().manual_seed(seed)
    base = torch.rand(1, 1, H, W, generator=g) * 0.8 + 0.05
    drift = torch.linspace(0, 1, T).view(1, T, 1, 1)
    wave = torch.sin(6.28 * (drift + torch.arange(W).view(1, 1, 1, W) / 9.0))
    return (base * (1 + 0.6 * wave)).clamp(min=0.0)


def _same_events(a, b):
    assert len(a) == len(b) and len(a) > 0
    for name in ("b", "x", "y", "t", "p"):
        assert torch.equal(getattr(a, name), getattr(b, name)), name


# noisy v2e-like sensor with every stateful effect on: mismatch, refractory, leak (random phase),
# shot noise, photoreceptor low-pass with adaptive per-interval sub-steps
NOISY = SensorConfig(
    adaptive_fraction=0.5,
    max_substeps=12,
    adaptive_region_px=0,
    random_reference_phase=True,
    shot_noise_rate_hz=5.0,
    leak_rate_hz=1.0,
    refractory_s=2e-3,
    seed=3,
)


@pytest.mark.parametrize("kernel", [None, "dog"])
@pytest.mark.parametrize("chunk", [1, 3, 4])
def test_chunked_equals_whole_clip_bit_for_bit(kernel, chunk):
    video = _clip()
    k = None if kernel is None else reference_kernel(kernel, 5)
    whole_ev = event_list(video, k, config=NOISY)
    whole_fr, whole_info = event_frames(video, k, config=NOISY, return_info=True)
    frames, ev, info = collect(simulate(video, k, config=NOISY, chunk_frames=chunk, event_frames=True))
    _same_events(ev, whole_ev)
    assert torch.equal(frames, whole_fr)
    assert info.substeps == whole_info.substeps and max(info.substeps) > 1
    assert info.noise_events == whole_info.noise_events > 0
    assert info.refractory_lost == whole_info.refractory_lost
    assert info.floor_fraction == pytest.approx(whole_info.floor_fraction, abs=1e-12)


def _record_pipelines(monkeypatch):
    """The ``inline`` flag of every event pipeline made from now on, in order."""
    from fsdvs_hw.sensor.simulation import event_pipeline

    made = []
    real_init = event_pipeline.EventPipeline.__init__

    def spy(self, *args, **kwargs):
        real_init(self, *args, **kwargs)
        made.append(self.inline)

    monkeypatch.setattr(event_pipeline.EventPipeline, "__init__", spy)
    return made


@pytest.mark.parametrize("inline", [False, True], ids=["worker threads", "inline"])
@pytest.mark.parametrize("lookahead", [0, 1, 3])
@pytest.mark.parametrize("chunk", [1, 3])
@pytest.mark.parametrize(
    "config",
    [NOISY.replace(refractory_s=0.02), SensorConfig.preset("v2e-default", shot_noise_rate_hz=5.0, refractory_s=0.02)],
    ids=["per-pixel noise", "v2e preset, sparse noise"],
)
def test_event_only_stream_equals_whole_clip_through_the_pipeline(config, chunk, lookahead, inline, monkeypatch):
    """An event-only CPU stream runs on the worker pipeline (emit, sort, noise threads, chunks handed
    over ``LOOKAHEAD_CHUNKS`` late), or on the stepping thread below ``INLINE_PIXELS``: same
    events, noise count and refractory losses as event_list."""
    from fsdvs_hw.sensor.simulation import stream

    monkeypatch.setattr(stream, "LOOKAHEAD_CHUNKS", lookahead)
    monkeypatch.setattr(stream, "INLINE_PIXELS", 2**30 if inline else 0)
    made = _record_pipelines(monkeypatch)
    video = _clip(T=11)
    whole_ev = event_list(video, None, config=config)
    _, whole_info = event_frames(video, None, config=config, return_info=True)
    chunks = list(simulate(video, None, config=config, chunk_frames=chunk))
    assert [c.first_interval for c in chunks] == list(range(0, 10, chunk))
    assert made[-1] is inline  # the stream's pipeline (event_list, with counts, makes its own threaded one)
    _, ev, info = collect(iter(chunks))
    _same_events(ev, whole_ev)
    assert info.noise_events == whole_info.noise_events > 0
    assert info.refractory_lost == whole_info.refractory_lost > 0


def test_stream_runs_small_frames_inline_and_large_ones_on_workers(monkeypatch):
    """The pipeline is inline below INLINE_PIXELS pixels per frame (all sensors), threaded from it;
    a task's error reaches the caller either way."""
    from fsdvs_hw.sensor.simulation import event_pipeline, stream

    made = _record_pipelines(monkeypatch)
    small = _clip(T=4, H=8, W=8)
    list(simulate(small, None, config=SensorConfig()))
    monkeypatch.setattr(stream, "INLINE_PIXELS", 64)  # 8x8 is no longer below it
    list(simulate(small, None, config=SensorConfig()))
    assert made == [True, False]
    with pytest.raises(ZeroDivisionError):
        event_pipeline._InlineExecutor().submit(lambda: 1 / 0).result()


def test_stream_from_a_generator_of_time_frame_pairs_equals_array_input():
    video = _clip(T=7)[0].double()
    ts = [0.0, 0.01, 0.025, 0.03, 0.05, 0.07, 0.071]
    gen = ((t, f.numpy()) for t, f in zip(ts, video))
    _, ev_gen, _ = collect(simulate(gen, config=NOISY, chunk_frames=2))
    ev_whole = event_list(video[None], timestamps_s=ts, config=NOISY)
    _same_events(ev_gen, ev_whole)
    assert ev_gen.t.dtype == torch.float64 and float(ev_gen.t.max()) <= 0.071


def test_state_is_carried_not_restarted():
    # a ramp that crosses one threshold per frame: a restarted reference would miss or double events
    T = 9
    lev = torch.exp(0.25 * torch.arange(T, dtype=torch.float64)) * 0.1
    video = lev.view(1, T, 1, 1).expand(1, T, 2, 2).contiguous()
    cfg = SensorConfig.ideal(0.2)
    _, ev, _ = collect(simulate(video, config=cfg, chunk_frames=1))
    assert len(ev) == len(event_list(video, config=cfg)) == 4 * int(0.25 * (T - 1) / 0.2)


def test_stream_memory_does_not_grow_with_clip_length():
    cfg = SensorConfig.ideal(0.2)
    chunks = simulate((torch.rand(16, 16) + 0.1 for _ in range(200)), config=cfg, chunk_frames=4)
    sizes = [c.timestamps_s.shape[1] for c in chunks]
    assert max(sizes) == 5 and sum(s - 1 for s in sizes) == 199


def test_stream_gradients_flow_within_a_chunk():
    k = torch.tensor(np.array(reference_kernel("dog", 3).taps), dtype=torch.float32, requires_grad=True)
    cfg = SensorConfig.ideal(0.1)
    for c in simulate(_clip(T=6), k, config=cfg, chunk_frames=2, events=False, event_frames=True):
        (c.frames.sum()).backward()
    assert k.grad is not None and bool(torch.isfinite(k.grad).all()) and float(k.grad.abs().sum()) > 0


def test_stream_bad_input_is_named():
    with pytest.raises(InputError, match="at least 2 frames"):
        list(simulate([np.ones((4, 4))]))
    with pytest.raises(InputError, match="differs"):
        list(simulate([np.ones((4, 4)), np.ones((4, 5))]))
    with pytest.raises(InputError, match="strictly increasing"):
        list(simulate([np.ones((4, 4))] * 3, timestamps_s=[0.0, 0.1, 0.1]))
    with pytest.raises(InputError, match=">= 0"):
        list(simulate([np.ones((4, 4)), -np.ones((4, 4))]))
    with pytest.raises(InputError, match="chunk_frames"):
        simulate(np.ones((3, 4, 4)), chunk_frames=0)


def test_stream_runs_a_plan_like_the_whole_clip():
    from fsdvs_hw.sensor import plan_model

    video = _clip(T=6, H=12, W=16).double() * 0.2  # dim: the photoreceptor lag matters, the plan sub-steps
    plan = plan_model(video, 0.2, config=SensorConfig(adaptive_region_px=0, seed=5))
    assert max(plan.substeps) > 1
    _, ev, info = collect(simulate(video, plan=plan, chunk_frames=3))
    _same_events(ev, event_list(video, plan=plan))
    assert info.substeps == tuple(plan.substeps)
    with pytest.raises(InputError, match="plan: made for"):
        list(simulate(_clip(T=8, H=12, W=16).double(), plan=plan, chunk_frames=4))


def test_chunks_of_one_clip_are_views_and_equal_the_stack():
    """Consecutive frames of one clip in memory make a chunk without a copy; any other frames
    (a list of separate tensors, a strided clip) are stacked; the values agree either way."""
    from fsdvs_hw.sensor.simulation.stream import _stack_frames

    clip = torch.rand(5, 2, 6, 7)  # (T, B, H, W): frames are (B, H, W) views with a batch stride
    frames = list(clip.unbind(0))
    view = _stack_frames(frames[1:4])
    assert view.untyped_storage().data_ptr() == clip.untyped_storage().data_ptr()
    assert torch.equal(view, torch.stack(frames[1:4], dim=1))
    one = _stack_frames(frames[2:3])
    assert one.shape == (2, 1, 6, 7) and torch.equal(one[:, 0], frames[2])
    separate = [f.clone() for f in frames[:3]]
    copied = _stack_frames(separate)
    assert copied.untyped_storage().data_ptr() != separate[0].untyped_storage().data_ptr()
    assert torch.equal(copied, torch.stack(frames[:3], dim=1))
    reversed_frames = frames[3::-1]  # same storage, backwards: not a forward stride, stacked
    backwards = _stack_frames(reversed_frames)
    assert backwards.untyped_storage().data_ptr() != clip.untyped_storage().data_ptr()
    assert torch.equal(backwards, torch.stack(reversed_frames, dim=1))
    gaps = frames[0:5:2]  # every other frame: a larger stride, still one view
    gapped = _stack_frames(gaps)
    assert gapped.untyped_storage().data_ptr() == clip.untyped_storage().data_ptr()
    assert torch.equal(gapped, torch.stack(gaps, dim=1))


def test_chunk_frames_for_aims_at_chunk_pixels_and_at_least_min_chunk_frames():
    from fsdvs_hw.sensor.simulation.stream import CHUNK_PIXELS, MIN_CHUNK_FRAMES, chunk_frames_for

    assert MIN_CHUNK_FRAMES == 2 and CHUNK_PIXELS == 2**19
    assert chunk_frames_for(272, 640) == CHUNK_PIXELS // (272 * 640) == 3
    assert chunk_frames_for(720, 1280) == chunk_frames_for(2160, 3840) == MIN_CHUNK_FRAMES
    assert chunk_frames_for(144, 176) == 20
    assert chunk_frames_for(1, 1) == CHUNK_PIXELS
    assert chunk_frames_for(0, 5) == CHUNK_PIXELS  # a degenerate size does not divide by zero


def test_simulate_command_default_chunks_follow_the_frame_size(tmp_path):
    """The command's default --chunk-frames is chunk_frames_for(H, W) of the simulated frames
    (--size if given, else the file's), MIN_CHUNK_FRAMES if the file does not say its size."""
    from fsdvs_hw.cli import main
    from fsdvs_hw.sensor.eventfiles.video_to_file import frame_size
    from fsdvs_hw.sensor.simulation import stream

    assert frame_size({"source_size": (640, 272)}, None) == (272, 640)
    assert frame_size({"source_size": (640, 272)}, (30, 40)) == (30, 40)
    assert frame_size({}, None) is None
    seen = []
    real = stream.simulate

    def spy(*a, **k):
        seen.append(k["chunk_frames"])
        return real(*a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(stream, "simulate", spy)
        base = ["simulate", "example:carphone", "--frames", "12", "--preset", "v2e-default", "--no-progress"]
        assert main([*base, "--out", str(tmp_path / "a.npz")]) == 0
        assert main([*base, "--out", str(tmp_path / "b.npz"), "--size", "272x640"]) == 0
        assert main([*base, "--out", str(tmp_path / "c.npz"), "--chunk-frames", "5"]) == 0
    assert seen == [20, 3, 5]


def test_default_chunks_follow_the_frame_size_for_events_and_stay_16_for_frames():
    """chunk_frames=None: an event list alone in chunk_frames_for(H, W) intervals (its events do
    not depend on the chunks); with event frames, 16 (the truncated-BPTT window)."""
    from fsdvs_hw.sensor.simulation.stream import DEFAULT_FRAMES_CHUNK, chunk_frames_for

    video = _clip(T=7, H=512, W=512)
    assert chunk_frames_for(512, 512) == 2
    ev_chunks = list(simulate(video, None, config=SensorConfig()))
    assert [c.first_interval for c in ev_chunks] == [0, 2, 4]
    small = _clip(T=40)
    fr_chunks = list(simulate(small, None, config=SensorConfig(), event_frames=True))
    assert DEFAULT_FRAMES_CHUNK == 16 and [c.first_interval for c in fr_chunks] == [0, 16, 32]
    _, ev, _ = collect(iter(ev_chunks))
    _same_events(ev, event_list(video, None, config=SensorConfig()))
