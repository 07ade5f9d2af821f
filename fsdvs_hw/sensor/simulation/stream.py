"""Streaming simulation: a clip of any length, chunk by chunk, in memory independent of its length.

:func:`simulate` takes frames from any iterable (a generator, a (T, H, W) or (B, T, H, W) array,
or :func:`fsdvs_hw.scenes.video.iter_video` on a video file) and yields one :class:`EventChunk`
per ``chunk_frames`` frame intervals. Every piece of pixel state — the memorised reference, the
photoreceptor low-pass and surround-mesh outputs, the leak drift, each pixel's last event time
(refractory period) and the shot-noise random streams — is carried from chunk to chunk, and each
chunk runs exactly the operations of a whole-clip :func:`~fsdvs_hw.sensor.event_list` /
:func:`~fsdvs_hw.sensor.event_frames` run, so the concatenated output equals the whole-clip output
bit for bit at a fixed seed (tested). Memory: the chunk's frames, their filtered log signal and
the per-pixel state, O(chunk × H × W) plus the kernel's FFT/conv workspace; an event-only CPU
stream computes its events on worker threads (:class:`~fsdvs_hw.sensor.simulation.event_pipeline.EventPipeline`)
and keeps :data:`LOOKAHEAD_CHUNKS` more chunks in flight.

Differences from the whole-clip functions (both stated where they matter):

- adaptive sub-steps are chosen per frame interval for the whole frame (ESIM's global step);
  per-region stepping (``adaptive_region_px``) needs every frame's motion in advance, so it is
  not used here; a whole-clip run equals the stream when ``adaptive_region_px=0`` (or without
  adaptive stepping, the default);
- gradients flow within a chunk (to the video, kernel and thresholds); the state entering a chunk
  is detached (truncated back-propagation through time);
- with a batch (B > 1) events are sorted by (b, t) within each chunk, so the concatenation is
  chunk-major; with B = 1 (a video file) it is time-sorted like the whole-clip list.

Polarity and time conventions of the yielded events are those of
:class:`~fsdvs_hw.sensor.EventList`: ``p = +1`` ON (brighter), ``-1`` OFF; ``t`` in seconds
(float64) on the clock of the frame timestamps.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ...errors import InputError
from ...validation import check_bool, check_instance
from .config import SATURATION_INTENSITY, SensorConfig
from .conventions import check_native
from .crossings import to_event_columns
from .event_pipeline import EventPipeline, events_pipelined, noise_event_count
from .events import (
    EventList,
    PixelState,
    SimulationInfo,
    advance_pixels,
    config_from_plan,
    initial_pixel_state,
    saturate,
    substeps_per_interval,
)
from .filtering import filtered_log_signal, kernel_tensor
from .pixel import threshold_maps

__all__ = ["CHUNK_PIXELS", "INLINE_PIXELS", "MIN_CHUNK_FRAMES", "EventChunk", "chunk_frames_for", "collect", "simulate"]

#: Chunks whose events are still being computed when the stream hands one over (CPU event lists).
LOOKAHEAD_CHUNKS = 1

#: Pixels per chunk that :func:`chunk_frames_for` aims at (2**19: three frames of 640×272).
CHUNK_PIXELS = 2**19

#: The fewest frame intervals per chunk :func:`chunk_frames_for` gives.
MIN_CHUNK_FRAMES = 2

#: :func:`simulate`'s chunk when event frames are asked for (the truncated-BPTT window).
DEFAULT_FRAMES_CHUNK = 16

#: Below this many pixels per frame (all sensors of the batch) a CPU event list runs its event
#: work on the stepping thread instead of the emit, sort and noise workers: on small frames handing
#: each task to a thread costs more than the overlap gains. In-process event list, ``v2e-default``,
#: default chunks, medians [min–max] of 7 alternating runs (5 for the crops, 3 for bikes;
#: docs/speed.md): carphone (176×144, 25 344 px) 0.077 [0.069–0.118] s on one thread against 0.099
#: [0.079–0.164] s with the workers; a 240×180 crop of bikes (43 200 px) 0.279 [0.249–0.409] against
#: 0.271 [0.260–0.322] s (a tie); 346×260 (89 960 px) 0.556 [0.492–0.584] against 0.404
#: [0.380–0.729] s; bikes (640×272) 1.06 [0.98–1.20] against 0.74 [0.63–1.07] s.
INLINE_PIXELS = 2**15


def chunk_frames_for(height: int, width: int) -> int:
    """Frame intervals per chunk for frames of ``height`` × ``width`` pixels: about
    :data:`CHUNK_PIXELS` pixels per chunk, at least :data:`MIN_CHUNK_FRAMES` frames.

    Every chunk has a fixed cost (its log signal, the hand-offs to the event workers, the writer's
    slice), and the event workers run at most one chunk behind the stepping
    (:data:`LOOKAHEAD_CHUNKS`), so one-frame chunks leave them idle between frames. On 2 cores
    (in-process event list, ``v2e-default``, range of 3 runs each) bikes took 1.2–1.35 s in
    one-frame chunks and 0.93–0.98 s in four-frame ones, no faster in 6 or 8 and slower in 24
    (1.18–1.33 s); bigbuckbunny 1.54–1.78 s in one-frame chunks, 1.42–1.48 s in two-frame ones,
    no faster in four; the ``simulate`` command simulated carphone's 120 frames of 176×144 in
    0.6–0.9 s in one-frame chunks and 0.3–0.5 s in ten-frame ones (docs/speed.md). Memory grows
    with the chunk: the ``simulate`` command on bigbuckbunny peaked at 521 MB in one-frame chunks,
    615 MB in two-frame ones and 739 MB in four-frame ones (bikes: 414 MB in one-frame chunks,
    452 MB in three-frame ones; one run each, ``/usr/bin/time``).

    Examples
    --------
    >>> chunk_frames_for(272, 640), chunk_frames_for(720, 1280), chunk_frames_for(144, 176)
    (3, 2, 20)
    """
    return max(MIN_CHUNK_FRAMES, CHUNK_PIXELS // max(int(height) * int(width), 1))


@dataclass
class EventChunk:
    """The output of one chunk of a streamed simulation.

    Attributes
    ----------
    first_interval : int
        Index (in the whole clip) of this chunk's first frame interval.
    timestamps_s : torch.Tensor (B, n + 1) float64
        Frame times bounding the chunk's ``n`` intervals (seconds).
    frames : torch.Tensor (B, n, 2, H, W) or None
        ON/OFF event counts per interval (as :func:`~fsdvs_hw.sensor.event_frames`) when asked for.
    events : EventList or None
        The chunk's exact events (as :func:`~fsdvs_hw.sensor.event_list`) when asked for.
    info : SimulationInfo
        The chunk's diagnostics (``floor_fraction`` over the chunk's new frames).
    n_frames : int
        Frames whose signal this chunk computed (the first chunk includes frame 0).
    height, width : int
        Sensor size in pixels.
    """

    first_interval: int
    timestamps_s: Any
    frames: Any
    events: EventList | None
    info: SimulationInfo
    n_frames: int
    height: int
    width: int

    @property
    def n_intervals(self) -> int:
        """Number of frame intervals in this chunk."""
        return int(self.timestamps_s.shape[1]) - 1


def _as_frame(item: Any, index: int, dtype: Any) -> tuple[float | None, Any, float]:
    """``(t or None, frame (B, H, W), its largest intensity)``, the frame checked (finite, >= 0)."""
    t = None
    if isinstance(item, tuple):
        if len(item) != 2:
            raise InputError(f"frames[{index}]: a tuple must be (t_s, frame), got {len(item)} items")
        t, item = item
        try:
            t = float(t)
        except (TypeError, ValueError):
            raise InputError(f"frames[{index}]: time {t!r} is not a number") from None
    if not isinstance(item, torch.Tensor):
        arr = np.asarray(item)
        if arr.dtype.kind not in "fiub":
            raise InputError(f"frames[{index}]: must be numeric, got dtype {arr.dtype}")
        item = torch.from_numpy(np.ascontiguousarray(arr, dtype=np.float64 if arr.dtype == np.float64 else np.float32))
    if item.ndim == 2:
        item = item[None]
    if item.ndim != 3:
        raise InputError(f"frames[{index}]: must be (H, W) or (B, H, W), got shape {tuple(item.shape)}")
    if not item.is_floating_point() or item.dtype in (torch.float16, torch.bfloat16):
        item = item.float()
    if dtype is not None and item.dtype != dtype:
        item = item.to(dtype)
    hi = -math.inf
    if item.numel():
        with torch.no_grad():
            lo, hi = (float(v) for v in torch.aminmax(item))  # one pass; NaN propagates into both
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise InputError(f"frames[{index}]: contains NaN or inf intensities")
        if lo < 0:
            raise InputError(f"frames[{index}]: linear intensities must be >= 0, got minimum {lo:g}")
    return t, item, hi


def _stack_frames(batch: list) -> Any:
    """``torch.stack(batch, dim=1)`` of (B, H, W) frames, as a view where that is the same tensor:
    one frame, or consecutive frames of one clip in memory (a (T, H, W) or (B, T, H, W) tensor
    given to :func:`simulate`), so the chunk's frames are not copied. Values are the same either way.
    """
    f0 = batch[0]
    if len(batch) == 1:
        return f0.unsqueeze(1)
    if not any(f.requires_grad for f in batch):
        step = batch[1].storage_offset() - f0.storage_offset()
        base = f0.untyped_storage().data_ptr()
        if step > 0 and all(
            f.untyped_storage().data_ptr() == base
            and f.stride() == f0.stride()
            and f.storage_offset() == f0.storage_offset() + i * step
            for i, f in enumerate(batch)
        ):
            B, H, W = f0.shape
            sB, sH, sW = f0.stride()
            return f0.as_strided((B, len(batch), H, W), (sB, step, sH, sW), f0.storage_offset())
    return torch.stack(batch, dim=1)


def _frame_source(frames: Any) -> Iterator[Any]:
    """Iterate frames of a 3-D/4-D array (over T) or of any iterable of frames / (t, frame)."""
    if isinstance(frames, (torch.Tensor, np.ndarray)):
        if frames.ndim == 3:
            return iter(frames.unbind(0) if isinstance(frames, torch.Tensor) else list(frames))
        if frames.ndim == 4:
            return iter(frames.unbind(1) if isinstance(frames, torch.Tensor) else list(np.moveaxis(frames, 1, 0)))
        raise InputError(f"frames: an array must be (T, H, W) or (B, T, H, W), got shape {tuple(frames.shape)}")
    if isinstance(frames, (str, bytes)) or not isinstance(frames, Iterable):
        raise InputError(
            "frames: must be an array or an iterable of frames (for a video file use "
            "fsdvs_hw.scenes.video.iter_video(path))"
        )
    return iter(frames)


def simulate(
    frames: Any,
    kernel: Any = None,
    *,
    timestamps_s: Any = None,
    config: SensorConfig | None = None,
    plan: Any = None,
    chunk_frames: int | None = None,
    events: bool = True,
    event_frames: bool = False,
    generator: Any = None,
) -> Iterator[EventChunk]:
    """Simulate a clip chunk by chunk; yield an :class:`EventChunk` per ``chunk_frames`` intervals.

    Parameters
    ----------
    frames : iterable or array
        Linear-intensity frames, (H, W) or (B, H, W) each (>= 0, video units): a generator, a
        list, a (T, H, W) or (B, T, H, W) array/tensor, or ``(t_s, frame)`` pairs (as
        :func:`fsdvs_hw.scenes.video.iter_video` yields). float64 frames run in float64,
        everything else in float32 (as :func:`~fsdvs_hw.sensor.event_frames`).
    kernel : Kernel, tensor (k, k) or None
        Spatial kernel at ``config.placement`` (``None``: plain DVS).
    timestamps_s : iterable of float, optional
        Frame times in seconds (strictly increasing); default: the times carried by
        ``(t_s, frame)`` items, else ``index / config.frame_rate_hz``.
    config : SensorConfig, optional
        Sensor parameters (default ``SensorConfig()``).
    plan : ModelPlan, optional
        A :func:`~fsdvs_hw.sensor.plan_model` plan (its config and per-interval sub-steps).
    chunk_frames : int or None
        Frame intervals per chunk (>= 1). Default (None): for an event list alone,
        :func:`chunk_frames_for` of the frame size, as ``fsdvs-hw simulate`` uses (640×272: 3,
        1280×720: 2, 176×144: 20; the events do not depend on the chunks); with ``event_frames``,
        16, since the chunk is also the window of truncated backpropagation through time (it was
        16 for both before 2026-11-28). Peak memory grows with one chunk's frames and events:
        on the event-list path each event of the chunk costs 17 bytes while the chunk is built
        (pixel index, time, polarity) and 25 bytes in the returned columns (x, y int64, t
        float64, p int8; the batch column of a B = 1 stream is a broadcast zero), plus the
        transient work arrays of the busiest single step (about 100 bytes per event of that
        step), plus, where the chunk path applies (:mod:`~fsdvs_hw.sensor.native.chunk_steps`), 24 bytes per pixel and
        interval of the chunk in float32 (48 in float64) of pooled work buffers, up to a few
        chunks' worth while they are in flight (1280×720 in chunks of 16: about 350 MB per
        chunk; in the default 2: 44 MB). The per-frame work does not depend on it.
    events, event_frames : bool
        Return each chunk's exact event list and/or its event frames.
    generator : torch.Generator, optional
        Overrides the threshold-mismatch stream (as in ``event_frames``).

    Yields
    ------
    EventChunk

    Raises
    ------
    InputError
        Bad frames (rank, NaN, negative, shape change), non-increasing times, a plan for fewer
        frames than given, bad ``chunk_frames``.
    """
    if chunk_frames is not None and (
        not isinstance(chunk_frames, int) or isinstance(chunk_frames, bool) or chunk_frames < 1
    ):
        raise InputError(f"chunk_frames: must be an integer >= 1 (or None: by frame size), got {chunk_frames!r}")
    events = check_bool("events", events)
    event_frames = check_bool("event_frames", event_frames)
    check_instance("generator", generator, torch.Generator, "a torch.Generator", nullable=True)
    if timestamps_s is not None and (
        isinstance(timestamps_s, (str, bytes, dict))
        or not isinstance(timestamps_s, (Iterable, torch.Tensor, np.ndarray))
    ):
        raise InputError(
            f"timestamps_s: wrong type {type(timestamps_s).__name__}; allowed: frame times in seconds "
            "(an array or iterable), finite and strictly increasing"
        )
    if not (events or event_frames):
        raise InputError("simulate: ask for events, event_frames or both")
    config = config_from_plan(config, plan)
    check_native(config, "stream")
    subs_plan = list(plan.substeps) if plan is not None and plan.substeps else None
    return _stream(
        _frame_source(frames),
        kernel,
        timestamps_s,
        config,
        plan,
        subs_plan,
        chunk_frames,
        events,
        event_frames,
        generator,
    )


@dataclass
class _Submitted:
    """A chunk whose steps are done and whose events may still be computing (futures)."""

    first_interval: int
    timestamps_s: Any
    frames: Any
    events: Any  # sorted interval pieces, or the future of their (b, x, y, t, p) columns; None: not wanted
    steps: list  # futures of the chunk's crossing steps (refractory losses), when pipelined
    noise: list  # futures of the chunk's shot-noise draws, when pipelined
    info: SimulationInfo
    n_frames: int
    batch: int

    def finish(self, state: Any, shape: tuple[int, ...]) -> EventChunk:
        """Wait for the chunk's events and build its :class:`EventChunk`."""
        ev = None
        if self.steps:
            lost = sum(f.result()[0] for f in self.steps)
            state.lost += lost
            self.info.refractory_lost = int(round(self.info.refractory_lost + lost))
        if self.noise:
            n_noise = noise_event_count(self.noise)
            state.noise_events += n_noise
            self.info.noise_events += n_noise
        if isinstance(self.events, Future):
            ev = EventList(*self.events.result())
        elif self.events is not None:
            ev = EventList(*to_event_columns(self.events, shape[1], shape[2], self.batch))
        return EventChunk(
            self.first_interval, self.timestamps_s, self.frames, ev, self.info, self.n_frames, shape[1], shape[2]
        )


class _FrameReader:
    """The stream's frames, a batch at a time: each converted, saturated, timed and checked (shape,
    time order); the first one sets the dtype, frame shape, kernel tensor and, unless given, the
    chunk length (frame intervals)."""

    def __init__(
        self,
        source: Iterator[Any],
        kernel: Any,
        timestamps_s: Any,
        config: SensorConfig,
        chunk: int | None,
        want_frames: bool,
    ) -> None:
        self.source, self.kernel, self.config, self.chunk, self.want_frames = source, kernel, config, chunk, want_frames
        self.times = iter(timestamps_s) if timestamps_s is not None else None
        self.dtype = None
        self.shape: tuple[int, ...] | None = None
        self.w = None
        self.index = 0
        self.saturated = 0  # pixel-frames clipped at SATURATION_INTENSITY since the last chunk
        self.exhausted = False

    def frame_time(self, t_item: float | None, i: int) -> float:
        """Time of frame ``i`` (s): from ``timestamps_s``, else the item's own, else the frame rate's."""
        if self.times is not None:
            try:
                t = float(next(self.times))
            except StopIteration:
                raise InputError(f"timestamps_s: has fewer times than frames (ran out at frame {i})") from None
            except (TypeError, ValueError):
                raise InputError(f"timestamps_s[{i}]: not a number") from None
        elif t_item is not None:
            t = t_item
        else:
            t = i / self.config.frame_rate_hz
        if not math.isfinite(t):
            raise InputError(f"timestamps_s[{i}]: {t!r} is not finite")
        return t

    def read(self, first: bool, prev_t: float | None) -> tuple[list[Any], list[float]]:
        """The next chunk's frames and times (one more frame for the ``first`` chunk); ``prev_t``:
        the previous chunk's last time (s). Fewer at the end of the source (then :attr:`exhausted`)."""
        batch: list[Any] = []
        ts: list[float] = []
        need = (self.chunk or 1) + (1 if first else 0)  # chunk None: set by the first frame
        while len(batch) < need:
            try:
                item = next(self.source)
            except StopIteration:
                self.exhausted = True
                break
            t_item, fr, hi = _as_frame(item, self.index, self.dtype)
            if hi > SATURATION_INTENSITY:  # the check's maximum spares saturate() its own pass
                fr, n_sat = saturate(fr)
                self.saturated += n_sat
            if self.dtype is None:
                self.dtype, self.shape = fr.dtype, tuple(fr.shape)
                if self.chunk is None:
                    self.chunk = (
                        DEFAULT_FRAMES_CHUNK if self.want_frames else chunk_frames_for(self.shape[-2], self.shape[-1])
                    )
                    need = self.chunk + 1
                self.w = kernel_tensor(self.kernel, fr)
            elif tuple(fr.shape) != self.shape:
                raise InputError(
                    f"frames[{self.index}]: shape {tuple(fr.shape)} differs from the first frame's {self.shape}"
                )
            t = self.frame_time(t_item, self.index)
            last_t = ts[-1] if ts else prev_t
            if last_t is not None and not t > last_t:
                raise InputError(
                    f"timestamps_s: must be strictly increasing; frame {self.index} is not later than frame {self.index - 1}"
                )
            batch.append(fr)
            ts.append(t)
            self.index += 1
        return batch, ts


class _ChunkThresholds:
    """The per-pixel thresholds of every chunk: the same draw (from the generator's state at the
    start), drawn again only when it carries a graph (truncated BPTT)."""

    def __init__(self, config: SensorConfig, generator: Any) -> None:
        self.config, self.generator = config, generator
        self.gen_state = generator.get_state() if generator is not None else None
        self.cache: list = []
        self.grad = any(
            isinstance(c, torch.Tensor) and c.requires_grad for c in (config.threshold_on, config.threshold_off)
        )

    def draw(self, like: Any, shape: tuple[int, ...]) -> Any:
        """``(c_on, c_off)`` for frames like ``like`` of ``shape`` (B, H, W)."""
        if self.cache and not (self.grad and torch.is_grad_enabled()):
            return self.cache[0]
        g = None
        if self.gen_state is not None:
            g = torch.Generator(device=self.generator.device)
            g.set_state(self.gen_state)
        thr = threshold_maps(self.config, tuple(shape[1:]), like, generator=g)
        self.cache[:] = [thr]
        return thr


def _carry_over(
    state: PixelState, thresholds: Any, prev: tuple, Ls: list, CI: list | None, SU: list | None, ts: list
) -> None:
    """Continue ``state`` into a new chunk: its thresholds, its tensors detached (truncated BPTT:
    no graph across chunks), and the previous chunk's last frame ``prev`` = (L, CI, SU, t) put
    first in the chunk's frames and times."""
    state.c_on, state.c_off = thresholds
    for name in ("ref", "lp", "sur", "sig_prev"):
        v = getattr(state, name)
        if v is not None:
            setattr(state, name, v.detach())
    Ls.insert(0, prev[0])
    if CI is not None:
        CI.insert(0, prev[1])
    if SU is not None:
        SU.insert(0, prev[2])
    ts.insert(0, prev[3])


def _chunk_substeps(
    subs_plan: list[int] | None, first_interval: int, Ls: list, config: SensorConfig, transient: bool
) -> list[int]:
    """Sub-steps of the chunk's ``len(Ls) - 1`` intervals: the plan's, else chosen from its signal."""
    n_int = len(Ls) - 1
    if subs_plan is not None:
        if first_interval + n_int > len(subs_plan):
            raise InputError(f"plan: made for {len(subs_plan) + 1} frames, the stream has more")
        return subs_plan[first_interval : first_interval + n_int]
    return substeps_per_interval(Ls, config, transient)


def _stream(
    source: Iterator[Any],
    kernel: Any,
    timestamps_s: Any,
    config: SensorConfig,
    plan: Any,
    subs_plan: list[int] | None,
    chunk: int | None,
    want_events: bool,
    want_frames: bool,
    generator: Any,
) -> Iterator[EventChunk]:
    """The chunks of :func:`simulate` (arguments resolved), pixel state carried between them."""
    thresholds = _ChunkThresholds(config, generator)
    reader = _FrameReader(source, kernel, timestamps_s, config, chunk, want_frames)
    state: PixelState | None = None
    prev = None  # (L, CI, SU, t) of the last frame of the previous chunk
    first_interval = 0
    # An event-only stream on the CPU keeps one event pipeline for the whole clip and hands each
    # chunk over after submitting the next LOOKAHEAD_CHUNKS chunks' steps: the worker threads never
    # drain at a chunk boundary (that many extra chunks of events are in flight).
    pipe = None
    pending: list = []
    try:
        while not reader.exhausted:
            batch, ts = reader.read(prev is None, prev[3] if prev is not None else None)
            if not batch or (prev is None and len(batch) < 2):
                if prev is None:
                    raise InputError(f"frames: need at least 2 frames, got {len(batch)}")
                break
            shape = reader.shape
            assert shape is not None  # set by the first frame (batch is not empty)
            video = _stack_frames(batch)  # (B, n, H, W)
            sig = filtered_log_signal(video, reader.w, config)
            B = video.shape[0]
            Ls = list(sig.log_signal.unbind(1))
            CI = list(sig.cutoff_intensity.unbind(1)) if config.has_photoreceptor else None
            SU = list(sig.surround.unbind(1)) if sig.surround is not None else None
            if prev is None:
                state = initial_pixel_state(
                    Ls[0],
                    SU[0] if SU is not None else None,
                    config,
                    thresholds.draw(Ls[0], shape),
                    None,
                    None,
                    want_events,
                )
            else:
                assert state is not None  # set with the first chunk (prev is not None)
                _carry_over(state, thresholds.draw(Ls[0], shape), prev, Ls, CI, SU, ts)
            n_int = len(Ls) - 1
            tsd = torch.tensor(ts, dtype=torch.float64, device=video.device).expand(B, -1)
            subs = _chunk_substeps(subs_plan, first_interval, Ls, config, sig.surround is not None)
            noise0, lost0 = state.noise_events, state.lost
            ev_parts: list = []
            if pipe is None and want_events and not want_frames and events_pipelined(video.device, config, False):
                pipe = EventPipeline(chunked=True, inline=B * shape[1] * shape[2] < INLINE_PIXELS)
            ctx = torch.no_grad() if not want_frames else contextlib.nullcontext()
            with ctx:
                out = advance_pixels(
                    state, Ls, CI, SU, tsd, config, subs, want_events, ev_parts, want_frames, pipe=pipe
                )
            frames = torch.stack(out, dim=1).view(B, n_int, 2, *shape[1:]) if want_frames else None
            if pipe is not None and want_events:  # the columns too are built on the worker
                ev_parts = pipe.columns(ev_parts, shape[1], shape[2], B)
            steps, noise = (pipe.take_steps(), pipe.take_noise()) if pipe is not None else ([], [])
            info = SimulationInfo(
                sig.floor_fraction,
                tuple(subs),
                state.noise_events - noise0,
                int(round(state.lost - lost0)),
                B * shape[1] * shape[2] * sum(subs),
                reader.saturated,
            )
            done = _Submitted(
                first_interval, tsd, frames, ev_parts if want_events else None, steps, noise, info, len(batch), B
            )
            pending.append(done)
            reader.saturated = 0
            # hand chunks over once LOOKAHEAD_CHUNKS newer ones are submitted (at once without a pipeline)
            while len(pending) > (LOOKAHEAD_CHUNKS if pipe is not None else 0):
                yield pending.pop(0).finish(state, shape)
            prev = (
                Ls[-1].detach(),
                CI[-1].detach() if CI is not None else None,
                SU[-1].detach() if SU is not None else None,
                ts[-1],
            )
            first_interval += n_int
            del video, sig, Ls, CI, SU, out, frames, done, ev_parts, batch  # only the chunks in flight stay alive
        while pending:
            yield pending.pop(0).finish(state, shape)
    finally:
        if pipe is not None:
            pipe.close()
    if plan is not None and subs_plan is not None and first_interval != len(subs_plan):
        raise InputError(f"plan: made for {len(subs_plan) + 1} frames, the stream had {first_interval + 1}")


def collect(chunks: Iterable[EventChunk]) -> tuple[Any, EventList | None, SimulationInfo]:
    """Concatenate a stream's chunks: (frames (B, T-1, 2, H, W) or None, events or None, info).

    ``info.floor_fraction`` is the pixel-frame-weighted fraction over the whole clip,
    ``refractory_lost`` and ``noise_events`` are summed, ``substeps`` concatenated.
    """
    if isinstance(chunks, (str, bytes)) or not isinstance(chunks, Iterable):
        raise InputError(f"chunks: wrong type {type(chunks).__name__}; allowed: the EventChunk iterator of simulate()")
    frames, evs, subs = [], [], []
    noise = lost = steps = saturated = 0
    floor_px = total_px = 0.0
    for i, c in enumerate(chunks):
        if not isinstance(c, EventChunk):
            raise InputError(f"chunks[{i}]: wrong type {type(c).__name__}; allowed: an EventChunk from simulate()")
        saturated += c.info.saturated
        if c.frames is not None:
            frames.append(c.frames)
        if c.events is not None:
            evs.append(c.events)
        subs += list(c.info.substeps)
        noise += c.info.noise_events
        lost += c.info.refractory_lost
        steps += c.info.pixel_steps
        floor_px += c.info.floor_fraction * c.n_frames
        total_px += c.n_frames
    f = torch.cat(frames, dim=1) if frames else None
    ev = None
    if evs:
        ev = EventList(*(torch.cat([getattr(e, a) for e in evs]) for a in ("b", "x", "y", "t", "p")))
    return f, ev, SimulationInfo(floor_px / max(total_px, 1), tuple(subs), noise, lost, steps, saturated)
