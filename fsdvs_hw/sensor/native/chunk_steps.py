"""A chunk of frame intervals stepped and emitted by the compiled kernels, one worker task per chunk.

This is the event-list fast path of :func:`~fsdvs_hw.sensor.simulation.events._advance_steps`: the same kernels
(``fsdvs_lowpass_exponent``, torch's ``expm1``, ``fsdvs_pixel_step``, ``fsdvs_step_events``) in the
same order on the same values, so the events are bit for bit those of the step-by-step path. What
changes is the dispatch around them. The step-by-step path pays, for every frame interval, a few
dozen torch operations, tensor allocations and three thread-pool submissions (crossings, noise
draw, noise events), all holding the GIL that the worker threads also need; on a 176×144 frame
that dispatch was most of the ~1.3 ms each interval took. Here the stepping thread makes two
ctypes calls and one ``expm1_`` per interval into buffers allocated once per chunk, and submits
one crossing task and one noise task per chunk.

It applies (:func:`chunk_applies`) to an event list on the CPU through an event pipeline (the
streaming simulator and :func:`~fsdvs_hw.sensor.simulation.events.event_list`), one sensor (batch of 1), one sub-step per
frame interval, no transient surround, the straight-through comparator and no gradient: the
case of a video simulated to events. Everything else takes the step-by-step path.

Example
-------
>>> import torch
>>> from fsdvs_hw.sensor import SensorConfig, simulate
>>> video = torch.rand(6, 8, 8) + 0.1
>>> chunks = list(simulate(video, config=SensorConfig.preset("v2e-default")))  # runs through here
>>> ev = chunks[0].events
>>> len(chunks), bool((ev.t[1:] >= ev.t[:-1]).all())
(1, True)
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np
import torch

from ..simulation.config import SensorConfig
from ..simulation.crossings import append_part, event_arrays, noise_step, shot_noise_pixels, threshold_array
from . import library
from .fused import DTYPE_SUFFIX, ctypes_real, fused_substep_applies, threshold_values

__all__ = ["GROUP_PIXELS", "BufferPool", "advance_chunk", "chunk_applies"]

#: Pixel-intervals per crossing task: a chunk's intervals go to the crossing worker in groups of
#: about this many pixels, so its work overlaps the stepping of the rest of the chunk on large
#: frames (one interval per task at 1280x720) while small frames still pay one hand-off per group
#: (11 intervals at 176x144).
GROUP_PIXELS = 2**18


class BufferPool:
    """Work tensors handed back and forth between the stepping thread and a worker, so a chunk's
    buffers are the same pages every chunk: a fresh multi-megabyte ``torch.empty`` is a fresh
    ``mmap`` whose every page the kernel must clear and fault in (on 1280×720 frames that was a
    quarter of the CPU time). Thread-safe; at most ``keep`` tensors are kept.

    Examples
    --------
    >>> pool = BufferPool()
    >>> a = pool.take((2, 3), torch.float32)
    >>> pool.give(a)
    >>> pool.take((2, 3), torch.float32) is a
    True
    """

    def __init__(self, keep: int = 8) -> None:
        self._free: dict[tuple, list] = {}
        self._lock = threading.Lock()
        self._keep = keep

    def take(self, shape: tuple[int, ...], dtype: Any) -> Any:
        """A tensor of ``shape`` and ``dtype`` (contents undefined): a kept one when one fits."""
        with self._lock:
            kept = self._free.get((tuple(shape), dtype))
            if kept:
                return kept.pop()
        return torch.empty(shape, dtype=dtype)

    def give(self, t: Any) -> None:
        """Hand ``t`` back: no one may use it afterwards."""
        with self._lock:
            kept = self._free.setdefault((tuple(t.shape), t.dtype), [])
            if len(kept) < self._keep:
                kept.append(t)


def chunk_applies(
    like: Any, substeps: list[int], config: SensorConfig, transient: bool, collect_events: bool, want_counts: bool
) -> bool:
    """Whether :func:`advance_chunk` can stand in for the step-by-step loop: an event list without
    counts (``collect_events`` and not ``want_counts``), one sensor (``like`` is (1, H, W)), one
    sub-step in every interval, and :func:`.fused.fused_substep_applies` (CPU, float32 or float64,
    no gradient, no transient surround, the straight-through comparator, kernels available).

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw.sensor import SensorConfig
    >>> with torch.no_grad():
    ...     ok = chunk_applies(torch.zeros(1, 4, 4), [1, 1], SensorConfig(), False, True, False)
    >>> ok == library.available()
    True
    >>> chunk_applies(torch.zeros(1, 4, 4), [2, 1], SensorConfig(), False, True, False)
    False
    """
    return (
        collect_events
        and not want_counts
        and like.shape[0] == 1
        and all(s == 1 for s in substeps)
        and fused_substep_applies(like, config, transient)
    )


def _contiguous(x: Any) -> Any:
    return x if x.is_contiguous() else x.contiguous()


def advance_chunk(st: Any, Ls: Any, CI: Any, tsd: Any, config: SensorConfig, events: list, pipe: Any, bar: Any) -> list:
    """Step the pixel state ``st`` (:class:`~fsdvs_hw.sensor.simulation.events.PixelState`) through
    the frames ``Ls`` (and low-pass intensities ``CI``, or None) and submit their events to ``pipe``
    (:class:`~fsdvs_hw.sensor.simulation.event_pipeline.EventPipeline`), as
    :func:`~fsdvs_hw.sensor.simulation.events._advance_steps` does where :func:`chunk_applies` holds.

    Parameters
    ----------
    st : PixelState
        State at ``Ls[0]``; advanced to the last frame (``ref``, ``lp``, ``sig_prev`` replaced,
        ``last_t`` updated in place by the crossing task).
    Ls, CI : sequence of torch.Tensor
        (1, H, W) log signal (log units) and photoreceptor intensity (relative) per frame.
    tsd : torch.Tensor
        (1, len(Ls)) float64 frame times (s).
    config : SensorConfig
        The sensor.
    events : list
        Each interval's :meth:`~fsdvs_hw.sensor.simulation.event_pipeline.EventPipeline.sort` result is appended.
    pipe : EventPipeline
        Where the crossing tasks (one per :data:`GROUP_PIXELS` pixel-intervals, in order), the
        noise task (one per chunk, with shot noise) and the sorts run; its ``buffers`` pool lends
        the work tensors.
    bar : tqdm or None
        Advanced by one per interval.

    Returns
    -------
    list
        ``[None, None] * (len(Ls) - 1)``: no counts (the event-list path).
    """
    lib = library.loaded()
    B, H, W = Ls[0].shape
    hw, K = H * W, len(Ls) - 1
    dtype = Ls[0].dtype
    sfx, real = DTYPE_SUFFIX[dtype], ctypes_real(dtype)
    has_lp = config.has_photoreceptor
    t_np, dt64, dtr = _interval_times(tsd, dtype)
    frames, inten, lp0, ref0, sig0, con, coff = _kernel_inputs(st, Ls, CI, has_lp, dtype)
    out, em1 = _chunk_buffers(pipe.buffers, has_lp, K, hw, dtype)
    n_out = out.shape[0]
    ref_out, n_on, n_off, d_out = out[n_out - 4], out[n_out - 3], out[n_out - 2], out[n_out - 1]
    lp_out = out[0] if has_lp else None
    step = getattr(lib, f"fsdvs_pixel_step_{sfx}")
    exponent = getattr(lib, f"fsdvs_lowpass_exponent_{sfx}")
    dark, fs, cutoff, m2pi, leak, eps = _kernel_scalars(real, config, st.eps)
    size = out.element_size()
    dt_ptr = dtr.ctypes.data
    parts: list[list] = [[] for _ in range(K)]
    noise_parts: list[list] = [[] for _ in range(K)]
    noise_f = _submit_noise(pipe, st, tsd, K, (B, H, W), config, noise_parts)
    # comparator input and reference at each interval's start
    sig_a = [sig0, *(lp_out if lp_out is not None else frames[1:K])]
    ref_a = [ref0, *ref_out[: K - 1]]
    refr = float(config.refractory_s) if st.last_t is not None else 0.0
    group = max(1, -(-GROUP_PIXELS // hw))
    rows = (n_on, n_off, sig_a, ref_a, d_out, parts, noise_parts)
    task = None
    for k in range(K):
        e = None
        if em1 is not None:
            assert inten is not None
            row = em1[k]
            exponent(inten[k + 1].data_ptr(), hw, hw, dt_ptr + k * size, dark, fs, cutoff, m2pi, row.data_ptr())
            row.expm1_()  # torch's own expm1, per interval as the step-by-step path calls it
            e = row.data_ptr()
        step(
            frames[k + 1].data_ptr(),
            (lp0 if k == 0 else lp_out[k - 1]).data_ptr() if lp_out is not None and lp0 is not None else None,
            e,
            ref_a[k].data_ptr(),
            con.data_ptr(),
            con.numel(),
            coff.data_ptr(),
            coff.numel(),
            dt_ptr + k * size,
            leak,
            eps,
            hw,
            hw,
            lp_out[k].data_ptr() if lp_out is not None else None,
            ref_out[k].data_ptr(),
            n_on[k].data_ptr(),
            n_off[k].data_ptr(),
            d_out[k].data_ptr(),
        )
        if bar is not None:
            bar.update(1)
        if (k + 1) % group == 0 or k == K - 1:  # the group's crossings go out while the next ones step
            ks = range(k + 1 - ((k % group) + 1), k + 1)
            task = pipe.emit(_crossings_task, (H, W), ks, rows, st, refr, t_np, dt64, noise_f, crossing=True)
    if em1 is not None:
        pipe.buffers.give(em1)
    _leave_chunk(st, ref_out, lp_out, Ls, (B, H, W))
    assert task is not None  # K >= 1
    task.add_done_callback(lambda _: pipe.buffers.give(out))  # the chunk's last task: the others are done
    for k in range(K):
        events.append(pipe.sort(parts[k], float(t_np[k]), float(t_np[k + 1])))
    return [None, None] * K


def _interval_times(tsd: Any, dtype: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame times (s, float64), interval lengths (s, float64: ``(t1 - t0) / 1``, as the
    step-by-step path's ``dt_sub64`` with one sub-step) and the lengths rounded to the signal
    ``dtype`` as torch rounds ``dt_sub``."""
    t_np = np.ascontiguousarray(tsd[0].numpy(), dtype=np.float64)
    dt64 = t_np[1:] - t_np[:-1]
    dtr = torch.from_numpy(dt64).to(dtype).numpy()
    return t_np, dt64, dtr


def _kernel_inputs(st: Any, Ls: Any, CI: Any, has_lp: bool, dtype: Any) -> tuple:
    """Contiguous tensors for the kernels: the frames, the low-pass intensities (None without a
    photoreceptor), the state's low-pass output (or None), reference and comparator input, and the
    ON and OFF thresholds (H·W values each)."""
    H, W = Ls[0].shape[1:]
    con = threshold_values(st.c_on, H * W, H * W, dtype, "c_on")
    coff = threshold_values(st.c_off, H * W, H * W, dtype, "c_off")
    frames = [_contiguous(x) for x in Ls]
    inten = [_contiguous(x) for x in CI] if has_lp else None
    lp0 = _contiguous(st.lp) if has_lp else None
    ref0, sig0 = _contiguous(st.ref), _contiguous(st.sig_prev)
    return frames, inten, lp0, ref0, sig0, con, coff


def _kernel_scalars(real: Any, config: SensorConfig, eps: float) -> tuple:
    """The pixel kernels' scalar arguments in the signal's ctypes type ``real``: dark and
    full-scale intensity, cut-off (Hz), -2π, leak rate (Hz) and the count guard ``eps``."""
    dark, fs, cutoff = real(config.dark_intensity), real(config.full_scale_intensity), real(config.cutoff_hz)
    m2pi, leak, eps_real = real(-2.0 * math.pi), real(float(config.leak_rate_hz)), real(eps)
    return dark, fs, cutoff, m2pi, leak, eps_real


def _chunk_buffers(buffers: BufferPool, has_lp: bool, K: int, hw: int, dtype: Any) -> tuple[Any, Any]:
    """The chunk's work tensors from the pool: ``out`` ([lp,] ref, n_on, n_off, d per interval:
    (5 or 4, K, hw)) and the low-pass ``expm1`` rows (K, hw), or None without a photoreceptor."""
    n_out = 5 if has_lp else 4
    out = buffers.take((n_out, K, hw), dtype)
    em1 = buffers.take((K, hw), dtype) if has_lp else None
    return out, em1


def _submit_noise(
    pipe: Any, st: Any, tsd: Any, K: int, shape: tuple[int, int, int], config: SensorConfig, noise_parts: list
) -> Any:
    """The chunk's shot-noise task submitted (drawn while the pixels step: it needs no pixel state);
    its future, or None without shot noise. ``shape``: (B, H, W)."""
    if not float(config.shot_noise_rate_hz) > 0:
        return None
    return pipe.submit_noise(
        _noise_task,
        tsd,
        K,
        shape,
        config,
        st.shot_g,
        st.time_g,
        noise_parts,
        on_emit_worker=config.shot_noise_draw == "sparse",  # O(events): not worth a thread hand-off
    )


def _leave_chunk(st: Any, ref_out: Any, lp_out: Any, Ls: Any, shape: tuple[int, int, int]) -> None:
    """The state at the chunk's last frame, out of the chunk's buffer (which goes back to the pool
    once the crossings are out): reference, and low-pass output or frame as the comparator saw it."""
    K = len(Ls) - 1
    st.ref = ref_out[K - 1].clone().view(*shape)
    if lp_out is not None:
        st.lp = st.sig_prev = lp_out[K - 1].clone().view(*shape)  # the comparator saw the low-pass output
    else:
        st.sig_prev = Ls[K]


def _crossings_task(
    hw_shape: tuple[int, int],
    ks: range,
    rows: tuple,
    st: Any,
    refr: float,
    t_np: np.ndarray,
    dt64: np.ndarray,
    noise_f: Any,
) -> tuple[float, None, None]:
    """The crossings of intervals ``ks`` in order (:func:`~fsdvs_hw.sensor.native.library.step_events`, as
    :func:`~fsdvs_hw.sensor.simulation.crossings.crossing_step` calls it). ``rows``: per interval of the chunk, the ON and OFF
    counts, comparator input and reference at the start, difference at the end, the interval's
    event parts (its crossing part is appended) and its shot-noise parts (appended after it once
    ``noise_f`` is done). Returns ``(lost, None, None)`` like :func:`~fsdvs_hw.sensor.simulation.crossings.crossing_step`
    (the crossings lost to the refractory period)."""
    h_on, h_off, sig_a, ref_a, d_b, parts, noise_parts = rows
    H, W = hw_shape
    c_on = threshold_array(st.c_on, 1, H, W)
    c_off = threshold_array(st.c_off, 1, H, W)
    last_t = st.last_t.view(-1).numpy() if st.last_t is not None else None
    lost = 0.0
    for k in ks:
        hon, hoff = h_on[k].numpy(), h_off[k].numpy()
        flat, t, p = event_arrays(hon, hoff, (1, H, W))
        if not len(t):
            continue
        n, lost_k = library.step_events(
            hon,
            hoff,
            sig_a[k].reshape(-1).numpy(),
            ref_a[k].reshape(-1).numpy(),
            d_b[k].numpy(),
            c_on,
            c_off,
            t_np[k : k + 1],
            t_np[k + 1 : k + 2],
            dt64[k : k + 1],
            H * W,
            last_t,
            refr,
            None,
            None,
            flat,
            t,
            p,
        )
        lost += lost_k
        append_part(parts[k], flat, t, p, n)
    if noise_f is not None:
        noise_f.result()
        for k in ks:
            parts[k].extend(noise_parts[k])
    return lost, None, None


def _noise_task(
    tsd: Any, K: int, shape: tuple[int, int, int], config: SensorConfig, shot_g: Any, time_g: Any, noise_parts: list
) -> tuple[Any, Any]:
    """Shot noise of a chunk's intervals in order: each interval's draw
    (:func:`~fsdvs_hw.sensor.simulation.crossings.shot_noise_pixels`) and its events
    (:func:`~fsdvs_hw.sensor.simulation.crossings.noise_step`) into ``noise_parts[k]``, the draws and
    times from the same streams in the same order as the step-by-step path. Returns every ON and
    OFF noise pixel (their count is the noise total)."""
    B = shape[0]
    shot = float(config.shot_noise_rate_hz)
    sparse = config.shot_noise_draw == "sparse"
    ons, offs = [], []
    for k in range(K):
        t_a, t_b = tsd[:, k].view(B, 1, 1), tsd[:, k + 1].view(B, 1, 1)
        dt_sub64 = ((tsd[:, k + 1] - tsd[:, k]) / 1).view(B, 1, 1)
        on_px, off_px = shot_noise_pixels(B, shape[1] * shape[2], (0.5 * shot) * dt_sub64.reshape(B), shot_g, sparse)
        noise_step(noise_parts[k], on_px, off_px, shape, t_a, t_b, dt_sub64, time_g)
        ons.append(on_px)
        offs.append(off_px)
    return torch.cat(ons), torch.cat(offs)
