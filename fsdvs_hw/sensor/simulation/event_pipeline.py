"""Where an event list's work runs beside the stepping thread: the event pipeline's worker threads.

While the caller steps the pixels, :class:`EventPipeline` computes the events of the steps already
taken on worker threads (the compiled kernels release the GIL): crossings and noise events in
step order on an emit thread, each interval's (or chunk's) time sort on a sort thread, shot-noise
draws on a third. :func:`events_pipelined` says when the work may leave the stepping thread;
small frames run the same tasks inline (:class:`_InlineExecutor`), where handing work between
threads costs more than it overlaps.
"""

from __future__ import annotations

import contextvars
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import torch

from ..native import library as native
from ..native.chunk_steps import BufferPool
from .config import SensorConfig
from .crossings import sort_interval, to_event_columns
from .threads import name_os_thread

__all__ = ["EventPipeline", "events_pipelined", "noise_event_count"]


def noise_event_count(draws: list) -> int:
    """Noise events in finished (or pending: waits) draw futures of :meth:`EventPipeline.noise`."""
    return sum(len(a) + len(b) for a, b in (f.result() for f in draws))


def _worker(name: str) -> ThreadPoolExecutor:
    """One worker thread named ``name`` at the OS level too (``top -H``)."""
    return ThreadPoolExecutor(1, thread_name_prefix=name, initializer=name_os_thread)


def _submit(pool: Any, fn: Any, *args: Any) -> Future:
    """``pool.submit(fn, *args)`` in a copy of the caller's context, so a worker sees the
    caller's context variables (an :func:`~fsdvs_hw.limits.allocation_limit` block: a worker
    thread otherwise starts from an empty context and checked the default limit)."""
    return pool.submit(contextvars.copy_context().run, fn, *args)


def events_pipelined(device: Any, config: SensorConfig, want_counts: bool) -> bool:
    """Whether event work can leave the stepping thread: CPU, and the refractory counts do not feed
    back into the frames."""
    return device.type == "cpu" and not (float(config.refractory_s) > 0 and want_counts)


class _InlineExecutor:
    """The :class:`~concurrent.futures.ThreadPoolExecutor` interface, run on the caller's thread:
    ``submit`` runs the task at once and returns its finished future (its exception, if it raised,
    is raised by ``result()``, as from a thread; an interrupt or exit propagates at once)."""

    def submit(self, fn: Any, *args: Any) -> Future:
        f: Future = Future()
        try:
            f.set_result(fn(*args))
        except Exception as exc:  # noqa: BLE001 - handed to the caller through the future
            f.set_exception(exc)
        return f

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
        pass


class EventPipeline:
    """Where the event-list work runs while the caller computes the next steps: worker threads (the
    compiled kernels release the GIL). ``emit`` runs step work (crossings, noise events) in
    submission order, since the refractory state passes from step to step; ``sort`` sorts an
    interval (or, ``chunked``, a whole chunk) once every emit task submitted before it has
    finished; a third thread, started by the first :meth:`noise`, draws shot noise in step order.
    ``inline``: the same tasks, run on the caller's thread as they are submitted (small frames).
    Tasks run in a copy of the submitter's context (:func:`_submit`)."""

    def __init__(self, chunked: bool = False, inline: bool = False) -> None:
        self.chunked = chunked  # sort a whole chunk at once, into its columns (see columns())
        # inline: every task runs on the caller's thread as it is submitted (small frames, where
        # handing work between threads costs more than it overlaps: .stream.INLINE_PIXELS)
        self.inline = inline
        self.emit_pool: Any = _InlineExecutor() if inline else _worker("fsdvs-emit")
        self.sort_pool: Any = _InlineExecutor() if inline else _worker("fsdvs-sort")
        self.noise_pool: Any = None  # started by the first noise draw
        self.steps: list = []  # futures of crossing_step: (lost, em_on, em_off)
        self.noise_draws: list = []  # futures of shot-noise draws: (on_px, off_px)
        self.pending: list = []  # emit futures of the interval being stepped
        self.buffers = BufferPool()  # work tensors of advance_chunk, reused from chunk to chunk

    def emit(self, fn: Any, *args: Any, crossing: bool = False) -> Future:
        f = _submit(self.emit_pool, fn, *args)
        self.pending.append(f)
        if crossing:
            self.steps.append(f)
        return f

    def sort(self, parts: list, lo: float, hi: float) -> Any:
        """Future of :func:`.crossings.sort_interval` of an interval's parts (times in [lo, hi]);
        in a chunked pipeline the interval's work, sorted later by :meth:`columns`."""
        waits, self.pending = self.pending, []
        if self.chunked:
            return (waits, parts, lo, hi)

        def run() -> Any:
            for f in waits:
                f.result()
            return sort_interval(parts, lo, hi)

        return _submit(self.sort_pool, run)

    def columns(self, pieces: list, H: int, W: int, B: int) -> Any:
        """Future of the chunk's ``(b, x, y, t, p)`` columns, from what :meth:`sort` returned for
        each of its intervals. Chunked, one sensor, compiled kernels: the intervals are sorted
        straight into the chunk's columns (:func:`~fsdvs_hw.sensor.native.library.sort_intervals_to_columns`);
        otherwise :func:`.crossings.to_event_columns` of the sorted intervals."""

        def run() -> Any:
            if not self.chunked:
                return to_event_columns([q.result() if isinstance(q, Future) else q for q in pieces], H, W, B)
            for waits, *_ in pieces:
                for f in waits:
                    f.result()
            if B == 1 and B * H * W < 2**31 and native.available():
                cols = native.sort_intervals_to_columns([w[1:] for w in pieces], H * W, W)
                x, y, t, p = (torch.from_numpy(c) for c in cols)
                return torch.zeros(1, dtype=torch.int64).expand(len(t)), x, y, t, p
            return to_event_columns([sort_interval(parts, lo, hi) for _, parts, lo, hi in pieces], H, W, B)

        return _submit(self.sort_pool, run)

    def submit_noise(self, fn: Any, *args: Any, on_emit_worker: bool = False) -> Future:
        """Run ``fn(*args)`` on the noise worker (started here if need be), after every noise task
        submitted before it, or (``on_emit_worker``, for cheap draws: one thread fewer to hand over
        to) on the emit worker, in order with the emit tasks; its result, ``(on_px, off_px)`` sized
        by the noise events drawn, is kept for :meth:`take_noise`. Returns its future."""
        if on_emit_worker:
            drawn = _submit(self.emit_pool, fn, *args)
        else:
            if self.noise_pool is None:
                self.noise_pool = _InlineExecutor() if self.inline else _worker("fsdvs-noise")
            drawn = _submit(self.noise_pool, fn, *args)
        self.noise_draws.append(drawn)
        return drawn

    def noise(self, draw: Any, emit: Any, draw_args: tuple, emit_args: tuple) -> None:
        """Shot noise of one step: ``draw(*draw_args)`` (the count draw, per-pixel or sparse, in
        step order on the noise worker, ahead of the emitter) then ``emit(parts, on_px, off_px,
        *rest)`` in step order on the emit worker. The draw is kept for :meth:`take_noise`."""
        drawn = self.submit_noise(draw, *draw_args)
        parts, *rest = emit_args

        def run() -> None:
            on_px, off_px = drawn.result()
            emit(parts, on_px, off_px, *rest)

        self.emit(run)

    def take_noise(self) -> list:
        """Futures of the noise draws submitted since the last call (``(on_px, off_px)``)."""
        draws, self.noise_draws = self.noise_draws, []
        return draws

    def take_steps(self) -> list:
        """Futures of the crossing steps submitted since the last call (their refractory losses)."""
        steps, self.steps = self.steps, []
        return steps

    def take_lost(self) -> float:
        """Crossings lost to the refractory period in the steps submitted so far (waits for them)."""
        return float(sum(f.result()[0] for f in self.take_steps()))

    def close(self) -> None:
        for pool in (self.noise_pool, self.emit_pool, self.sort_pool):
            if pool is not None:
                pool.shutdown(wait=True, cancel_futures=True)
