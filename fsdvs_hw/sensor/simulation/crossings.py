"""Exact threshold crossings of one comparator step, computed on the pixels that cross only.

The comparator step of :mod:`.events` gives, per pixel, the number of ON and OFF crossings
``h`` of a step from ``t_a`` to ``t_b``; its input moves linearly from ``d_a = L_a - r_a`` to
``d_b``. This module turns those counts into events without a Python loop per event or pixel:

1. **Active pixels only.** The pixels with ``h > 0`` are gathered once (``nonzero``); the
   refractory arithmetic (first emitted index ``j0``, stride ``m``, count, last event time) runs
   on them alone. A pixel that crosses in a step crosses one way only (``d_b`` has one sign), so
   ON and OFF never meet in a pixel within a step. Without a refractory period ``j0 = m = 1`` and
   every crossing is emitted: that path does no refractory arithmetic at all.
2. **Events by expansion.** Each active pixel's ``emitted`` crossings are expanded with one sorted
   search (the ``k``-th crossing of a pixel is ``j = j0 + k m``) and timed in closed form,
   ``t = t_a + (j C - d_a) / v``, clamped into ``(t_a, t_b]``.
3. **Time order per frame interval.** Events of a frame interval lie in ``(t_k, t_k+1]``, so a
   clip is time-sorted once each interval is: one sort of the interval's events, NumPy's
   (vectorised) unstable sort plus an exact repair of tied times, which reproduces a stable sort.

Every arithmetic operation on an emitted event is the one the full-frame formulation does on the
same values, so event lists are bit-identical to it (``tests/test_sensor_fast_events.py``
compares against a straightforward full-frame reference).

Events are carried as ``(flat, t, p)``: the flat pixel index ``b·H·W + y·W + x`` (int64), time in
seconds (float64) and polarity (int8); :func:`to_event_columns` splits the index at the end.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import torch

from ..native import library as native

__all__: list[str] = []  # private helpers of .events and .stream


def repeat_index(counts: Any) -> tuple[Any, Any]:
    """``(repeat_interleave(arange(n), counts), cumsum(counts))``.

    On the CPU through ``numpy.repeat`` (single-threaded, ~20× faster than a sorted search and
    free of the thread wake-ups that make torch's parallel ``repeat_interleave`` cost
    milliseconds per call on a loaded machine); on other devices torch's.
    """
    ends = torch.cumsum(counts, 0)
    if counts.device.type == "cpu":
        c = counts.numpy()
        return torch.from_numpy(np.repeat(np.arange(len(c), dtype=np.int64), c)), ends
    total = int(ends[-1]) if len(ends) else 0
    return torch.repeat_interleave(torch.arange(len(counts), device=counts.device), counts, output_size=total), ends


def _gather(x: Any, idx: Any, shape: tuple[int, int, int]) -> Any:
    """``x`` broadcast to (B, H, W), flattened, at flat indices ``idx`` (a 0-d ``x`` stays 0-d)."""
    if x.ndim == 0:
        return x
    if x.shape == shape:
        return x.reshape(-1)[idx]
    _, H, W = shape
    if x.ndim == 2 or x.shape[0] == 1:  # one map for every batch element
        return x.reshape(-1)[idx % (H * W)]
    return x.expand(shape).reshape(-1)[idx]


class ComparatorStep(NamedTuple):
    """One comparator step of every pixel: what :func:`crossing_step` turns into events.

    Attributes
    ----------
    h_on, h_off : torch.Tensor (B, H, W)
        Crossing counts (whole numbers, floating).
    sig_a, ref_a : torch.Tensor (B, H, W)
        Comparator input and reference at the step start (before the leak): ``d_a = sig_a - ref_a``.
    d_b : torch.Tensor (B, H, W)
        Comparator input minus reference at the step end.
    c_on, c_off : torch.Tensor, 0-d, (H, W) or (B, H, W)
        Thresholds (log units).
    t_a, t_b, dt : torch.Tensor (B, 1, 1) float64
        Step start, end and length (seconds).
    last_t : torch.Tensor (B, H, W) float64 or None
        Each pixel's last event time (updated in place); None without a refractory period.
    refractory_s : float
        Refractory period (seconds).
    """

    h_on: Any
    h_off: Any
    sig_a: Any
    ref_a: Any
    d_b: Any
    c_on: Any
    c_off: Any
    t_a: Any
    t_b: Any
    dt: Any
    last_t: Any
    refractory_s: float


def crossing_step(
    parts: list,
    step: ComparatorStep,
    collect: bool,
    want_counts: bool,
) -> tuple[float, Any, Any]:
    """Emit the crossings of one comparator step.

    On the CPU this runs the compiled kernel (:mod:`~fsdvs_hw.sensor.native.library`), elsewhere (or without a
    C compiler) the vectorised torch path (:func:`crossing_step_torch`); both give the same events
    bit for bit.

    Parameters
    ----------
    parts : list
        ``(flat, t, p)`` event triples are appended here (ON pixels first, then OFF; within a
        polarity in raster order, each pixel's events consecutive) when ``collect``.
    step : ComparatorStep
        The step of every pixel: crossing counts, comparator input and reference at its start,
        the difference at its end, thresholds, times and the last-event-time map (updated in
        place).
    collect : bool
        Append the events to ``parts``.
    want_counts : bool
        Also return the emitted ON/OFF counts as (B, H, W) tensors (the refractory surrogate).

    Returns
    -------
    lost : float
        Crossings lost to the refractory period (0 when ``last_t`` is None).
    em_on, em_off : torch.Tensor (B, H, W) or None
        Emitted counts (``want_counts``), dtype of ``h_on``.
    """
    if _native_ok(*step[:7]):
        return _crossing_step_cpu(parts, step, collect, want_counts)
    return crossing_step_torch(parts, step, collect, want_counts)


def _native_ok(h: Any, *same_dtype: Any) -> bool:
    """Whether the compiled kernel applies: CPU, float32/64 counts with every other per-pixel input
    of the same dtype, pixel indices within int32, and the kernel built (:mod:`~fsdvs_hw.sensor.native.library`)."""
    return (
        h.device.type == "cpu"
        and h.dtype in (torch.float32, torch.float64)
        and all(x.dtype == h.dtype for x in same_dtype)
        and h.numel() < 2**31
        and native.available()
    )


def _flat_np(x: Any) -> np.ndarray:
    return x.detach().contiguous().reshape(-1).numpy()


def _total(h: np.ndarray) -> int:
    """The sum of non-negative integer counts, exactly: in the array's own dtype when the result
    shows no partial sum can have rounded (every partial sum of non-negative values is at most the
    total, and integers below 2**24 are exact in float32), else in float64 (half the speed)."""
    s = float(h.sum())
    exact_below = 2.0**24 if h.dtype == np.float32 else 2.0**53
    return int(s) if s < exact_below else int(h.sum(dtype=np.float64))


def threshold_array(c: Any, B: int, H: int, W: int) -> np.ndarray:
    """Thresholds as 1, H·W or B·H·W values (the kernel's three layouts)."""
    c = c.detach()
    if c.numel() == 1:
        out = c.reshape(1)
    elif c.shape[-2:] == (H, W) and (c.ndim == 2 or c.shape[0] == 1):
        out = c.reshape(H * W)
    else:
        out = c.expand(B, H, W).reshape(-1)
    return out.contiguous().numpy()


def event_arrays(h_on: np.ndarray, h_off: np.ndarray, shape: tuple[int, int, int]) -> tuple[np.ndarray, ...]:
    """Empty ``(flat, t, p)`` arrays (int32, float64, int8) with room for every crossing a step's
    ON and OFF counts ``h_on``, ``h_off`` announce, on a (B, H, W) frame ``shape``. A tiny threshold
    makes the list unbounded: it is refused with its size (:class:`~fsdvs_hw.errors.InputError`),
    not a ``MemoryError``."""
    from ...limits import check_allocation

    cap = _total(h_on) + _total(h_off)
    B, H, W = shape
    check_allocation(f"event list: {cap} threshold crossings in one step ({B}x{H}x{W} px; 13 bytes each)", 13.0 * cap)
    return np.empty(cap, dtype=np.int32), np.empty(cap, dtype=np.float64), np.empty(cap, dtype=np.int8)


def append_part(parts: list, flat: np.ndarray, t: np.ndarray, p: np.ndarray, n: int) -> None:
    """Append the first ``n`` events of :func:`event_arrays`' arrays to ``parts`` as a ``(flat, t,
    p)`` tensor triple (nothing when ``n`` is 0); copied when under half the room was used (many
    crossings lost to the refractory period), so the spare capacity is not kept alive."""
    if not n:
        return
    if n < len(t) // 2:
        flat, t, p = flat[:n].copy(), t[:n].copy(), p[:n].copy()
    parts.append((torch.from_numpy(flat[:n]), torch.from_numpy(t[:n]), torch.from_numpy(p[:n])))


def _crossing_step_cpu(
    parts: list,
    step: ComparatorStep,
    collect: bool,
    want_counts: bool,
) -> tuple[float, Any, Any]:
    """:func:`crossing_step` through the compiled kernel (same arguments and results)."""
    h_on, h_off, sig_a, ref_a, d_b, c_on, c_off, t_a, t_b, dt, last_t, refractory_s = step
    B, H, W = h_on.shape
    # NumPy, not torch, for the work arrays: this may run on a worker thread (events.py), where a
    # parallel torch op would start its own OpenMP team
    hon, hoff = _flat_np(h_on), _flat_np(h_off)
    em_on = np.zeros(hon.shape, hon.dtype) if want_counts else None
    em_off = np.zeros(hoff.shape, hoff.dtype) if want_counts else None
    flat, t, p = event_arrays(hon, hoff, (B, H, W)) if collect else (None, None, None)
    refr = last_t is not None

    def times(x: Any) -> np.ndarray:
        return _flat_np(x.expand(B, 1, 1).to(torch.float64))

    n, lost = native.step_events(
        hon,
        hoff,
        _flat_np(sig_a),
        _flat_np(ref_a),
        _flat_np(d_b),
        threshold_array(c_on, B, H, W),
        threshold_array(c_off, B, H, W),
        times(t_a),
        times(t_b),
        times(dt),
        H * W,
        last_t.view(-1).numpy() if refr else None,
        float(refractory_s),
        em_on,
        em_off,
        flat,
        t,
        p,
    )
    if collect:
        assert flat is not None and t is not None and p is not None  # allocated when collect
        append_part(parts, flat, t, p, n)
    em = [None if e is None else torch.from_numpy(e).view(B, H, W) for e in (em_on, em_off)]
    return float(lost) if refr else 0.0, em[0], em[1]


def crossing_step_torch(
    parts: list,
    step: ComparatorStep,
    collect: bool,
    want_counts: bool,
) -> tuple[float, Any, Any]:
    """:func:`crossing_step` in vectorised torch (any device; same arguments and results)."""
    h_on, h_off, sig_a, ref_a, d_b, c_on, c_off, t_a, t_b, dt, last_t, refractory_s = step
    shape = tuple(h_on.shape)
    B, H, W = shape
    HW = H * W
    lost = 0.0
    ems: list = []
    for h, c, sign in ((h_on, c_on, 1), (h_off, c_off, -1)):
        hf = h.reshape(-1)
        idx = torch.nonzero(hf > 0).squeeze(1)
        em_full = torch.zeros_like(hf) if want_counts else None
        ems.append(None if em_full is None else em_full.view(shape))
        if idx.numel() == 0:
            continue
        bi = torch.div(idx, HW, rounding_mode="floor") if B > 1 else None
        n = hf[idx].double()
        da = (sig_a.reshape(-1)[idx] - ref_a.reshape(-1)[idx]).double()
        v = (d_b.reshape(-1)[idx].double() - da) / (dt.reshape(-1)[bi] if B > 1 else dt.reshape(()))
        if sign < 0:  # negation is exact: the OFF side is the ON side of -d
            da, v = da.neg_(), v.neg_()
        cc = _gather(c, idx, shape).double()
        ta = t_a.reshape(-1)[bi] if B > 1 else t_a.reshape(())
        rising = v > 0
        if last_t is None:  # no refractory period: every crossing of a rising input is emitted
            emitted = torch.where(rising, n, torch.zeros_like(n))
            j0 = m = None
        else:
            vs = torch.where(rising, v, torch.ones_like(v))
            lt = last_t.reshape(-1)[idx]
            j0 = torch.ceil((vs * (lt + refractory_s - ta) + da) / cc).clamp(min=1.0)
            m = torch.ceil(refractory_s * vs / cc).clamp(min=1.0)
            emitted = torch.where(n >= j0, 1.0 + torch.floor((n - j0) / m), torch.zeros_like(n))
            emitted = torch.where(rising, emitted, torch.zeros_like(n))
            fired = torch.nonzero(emitted > 0).squeeze(1)
            if fired.numel():
                j_last = j0[fired] + (emitted[fired] - 1.0) * m[fired]
                t_last = _at(ta, fired) + (j_last * _at(cc, fired) - da[fired]) / vs[fired]
                last_t.view(-1)[idx[fired]] = t_last
            lost += float(n.sum() - emitted.sum())
        if em_full is not None:
            em_full[idx] = emitted.to(em_full.dtype)
        if not collect:
            continue
        sel = torch.nonzero(emitted > 0).squeeze(1)
        if sel.numel() == 0:
            continue
        counts = emitted[sel].long()
        rep, ends = repeat_index(counts)
        src = sel[rep]
        # k-th crossing of its pixel (int64 → float64 in place of the index arithmetic)
        j = torch.arange(len(rep), device=rep.device).sub_((ends - counts)[rep]).double()
        del rep, ends, counts
        if j0 is None:
            j = j.add_(1.0)
        else:
            assert m is not None  # set with j0
            j = j.mul_(m[src]).add_(j0[src])  # j0 + k m, as (k m) + j0
        # t = t_a + (j C - d_a) / v, in place, same roundings (IEEE + and * commute exactly)
        t = j.mul_(_at(cc, src)).sub_(da[src]).div_(v[src])
        if B > 1:
            assert bi is not None  # set when B > 1
            ta_e, tb_e = ta[src], t_b.reshape(-1)[bi[src]]
            t = t.add_(ta_e)
            # a crossing already due at the step start (after a noise reset) fires just after it
            t = torch.minimum(torch.maximum(t, torch.nextafter(ta_e, torch.full_like(ta_e, math.inf))), tb_e)
        else:
            t0 = float(ta)
            t = t.add_(t0).clamp_(min=math.nextafter(t0, math.inf), max=float(t_b.reshape(())))
        parts.append((idx[src], t, torch.full((len(t),), sign, dtype=torch.int8)))
    return lost, ems[0], ems[1]


def _at(x: Any, i: Any) -> Any:
    """``x[i]`` for a per-pixel vector, ``x`` itself for a 0-d (broadcast) value."""
    return x[i] if x.ndim else x


def stable_time_order(t: np.ndarray) -> np.ndarray:
    """Indices that sort ``t`` stably (ties keep their input order), as ``argsort(kind="stable")``.

    NumPy's default sort is vectorised and several times faster than its stable sorts; ties
    (rare: events clamped to a step end) are put back into input order exactly.
    """
    order = np.argsort(t)
    ts = t[order]
    tie = ts[1:] == ts[:-1]
    first = np.flatnonzero(tie)  # sorted position i ties with i + 1
    if len(first):
        pos = np.union1d(first, first + 1)  # every position inside a run of equal times
        starts = np.ones(len(pos), dtype=bool)  # a run starts where the previous position is no tie
        starts[1:] = ~tie[pos[1:] - 1]
        run = np.maximum.accumulate(np.where(starts, pos, 0))  # each position's run start
        key = run.astype(np.int64) * len(t) + order[pos]
        order[pos] = order[pos][np.argsort(key)]
    return order


def sort_interval(parts: list, lo: float | None = None, hi: float | None = None) -> tuple[Any, Any, Any] | None:
    """Concatenate one frame interval's ``(flat, t, p)`` parts and sort them stably by time
    (``lo``, ``hi``: bounds of the times, e.g. the interval's frame times, if known).

    CPU parts go through the compiled bucket sort (:func:`~fsdvs_hw.sensor.native.library.sort_events`: one
    move per event, no concatenated copy); others through :func:`stable_time_order`.
    """
    if not parts:
        return None
    if all(q[1].device.type == "cpu" for q in parts) and native.available():
        out = native.sort_events([tuple(c.numpy() for c in q) for q in parts], lo, hi)
        parts.clear()
        return torch.from_numpy(out[0]), torch.from_numpy(out[1]), torch.from_numpy(out[2])
    # parts on other devices (a CUDA step's crossings beside CPU-made empty parts) meet on the CPU
    flat, t, p = (torch.cat([x.cpu() for x in c]) for c in zip(*parts, strict=True))
    parts.clear()
    order = torch.from_numpy(stable_time_order(t.numpy()))
    return flat[order], t[order], p[order]


def to_event_columns(pieces: list, H: int, W: int, B: int) -> tuple[Any, Any, Any, Any, Any]:
    """(b, x, y, t, p) of time-sorted interval pieces; sorted by (b, t) when ``B > 1``.

    The pieces are written straight into the output columns (no concatenated intermediate) and
    freed as they go; with ``B = 1`` the batch column is a broadcast zero (``expand``, no memory).
    """
    pieces = [q for q in pieces if q is not None]
    n = sum(len(q[1]) for q in pieces)
    b = torch.zeros(1, dtype=torch.int64).expand(n)
    x = torch.empty(n, dtype=torch.int64)
    y = torch.empty(n, dtype=torch.int64)
    t = torch.empty(n, dtype=torch.float64)
    p = torch.empty(n, dtype=torch.int8)
    start = 0
    HW = H * W
    for i, (flat, tq, pq) in enumerate(pieces):
        end = start + len(tq)
        if flat.device.type == "cpu" and flat.dtype == torch.int32 and native.available():
            native.write_columns(
                flat.numpy(), tq.numpy(), pq.numpy(), HW, W, x.numpy(), y.numpy(), t.numpy(), p.numpy(), start
            )
        else:
            f32 = flat.to(torch.int32) if B * HW < 2**31 else flat  # int32 division is faster
            if B > 1:
                f32 = f32 - torch.div(f32, HW, rounding_mode="floor") * HW
            yq = torch.div(f32, W, rounding_mode="floor")
            y[start:end] = yq
            x[start:end] = f32 - yq * W
            t[start:end] = tq
            p[start:end] = pq
        if B > 1:
            pieces[i] = (torch.div(flat.to(torch.int64), HW, rounding_mode="floor"), None, None)
        start = end
    if B > 1:
        b = torch.cat([q[0] for q in pieces]) if pieces else torch.zeros(0, dtype=torch.int64)
        order = torch.argsort(b, stable=True)
        b, x, y, t, p = b[order], x[order], y[order], t[order], p[order]
    pieces.clear()
    return b, x, y, t, p


def shot_noise_pixels(B: int, HW: int, lam: Any, generator: Any, sparse: bool = False) -> tuple[Any, Any]:
    """Flat pixel indices (sorted, one entry per event) of one step's ON and OFF shot-noise events.

    Each pixel of batch element ``b`` gets Poisson(``lam[b]``) events per polarity, independently.
    ``sparse=False``: drawn per pixel (``torch.poisson`` over the (B, H·W) frame, ON then OFF), the
    stream every stored result was made with. ``sparse=True``: the same law drawn in O(events):
    the total ``N_b ~ Poisson(HW · lam_b)``, then ``N_b`` pixels uniformly with replacement (a
    Poisson process split uniformly over pixels is independent Poisson per pixel); other
    realisations.

    Parameters
    ----------
    B, HW : int
        Batch size and pixels per frame.
    lam : torch.Tensor (B,) float64
        Expected events per pixel and polarity in the step.
    generator : torch.Generator
        The shot-noise count stream (its device is used).
    sparse : bool
        The O(events) draw (``SensorConfig.shot_noise_draw == "sparse"``).
    """
    dev = generator.device
    out = []
    if sparse:
        for _ in range(2):  # ON, then OFF
            n = torch.poisson(lam.to(dev, torch.float64) * HW, generator=generator).long()
            total = int(n.sum())
            if total == 0:
                out.append(torch.zeros(0, dtype=torch.int64, device=dev))
                continue
            px = torch.randint(0, HW, (total,), generator=generator, device=dev)
            if B > 1:
                px += torch.repeat_interleave(torch.arange(B, device=dev) * HW, n)
            out.append(torch.sort(px).values)
        return out[0], out[1]
    rate = lam.to(dev, torch.float64).view(B, 1).expand(B, HW).contiguous()
    for _ in range(2):  # ON, then OFF
        k = torch.poisson(rate, generator=generator).view(-1)
        idx = torch.nonzero(k > 0).squeeze(1)
        out.append(
            idx if idx.numel() == 0 or bool((k[idx] == 1).all()) else torch.repeat_interleave(idx, k[idx].long())
        )
    return out[0], out[1]


def noise_step(
    parts: list, on_px: Any, off_px: Any, shape: tuple[int, int, int], t_a: Any, t_b: Any, dt: Any, time_g: Any
) -> None:
    """Append the shot-noise events of one step (:func:`shot_noise_pixels`' flat indices ``on_px``,
    ``off_px`` of a (B, H, W) frame), each at a uniform time in ``(t_a, t_b]`` drawn from
    ``time_g`` (ON events first, raster order)."""
    B, H, W = shape
    HW = H * W
    for flat, pol in ((on_px, 1), (off_px, -1)):
        if flat.numel() == 0:
            continue
        bi = torch.div(flat, HW, rounding_mode="floor")
        u = torch.rand(len(flat), generator=time_g, device=time_g.device, dtype=torch.float64).to(flat.device)
        t = torch.minimum(t_a.reshape(B)[bi] + (1.0 - u) * dt.reshape(B)[bi], t_b.reshape(B)[bi])
        parts.append((flat, t, torch.full((len(flat),), pol, dtype=torch.int8, device=flat.device)))
