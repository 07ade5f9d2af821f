"""Compiled (numba) kernels of :mod:`.crossings`: one comparator step's events, and one frame
interval's stable time sort, on CPU arrays.

These are the same formulas as the vectorised torch path of :mod:`.crossings`, operation for
operation and in the same order (IEEE ``+ - * /``, ``floor``, ``ceil``, ``min``/``max`` are exact
or correctly rounded, so the results are bit-identical; ``fastmath`` is off), written as one loop
over the pixels. They exist for speed and memory: the torch path makes about ten full passes over
every event (expansion, gathers, the timing formula, the sort and its permutation gathers), while
here each event is computed once, written once and moved once by the sort.

Event order before sorting is the torch path's: ON pixels in raster order, then OFF pixels, each
pixel's events consecutive. :func:`sort_events` is a stable sort by time (ties keep their input
order): a counting sort into ``n`` buckets spaced evenly over the interval (the bucket of a time
is monotone in the time, so buckets are ordered), then a stable insertion sort inside each bucket
(a stable merge sort for a bucket holding more than 32 events, so clustered times cannot make it
quadratic).

Reference: the linear-interpolation event model of ESIM (Rebecq, Gehrig & Scaramuzza 2018),
crossing times ``t = t_a + (j C - d_a) / v``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__: list[str] = []  # private kernels of .crossings

_BIG_BUCKET = 32


@njit(cache=True, nogil=True)
def _threshold(c: np.ndarray, i: int, hw: int) -> float:
    """Threshold of flat pixel ``i``: ``c`` holds 1 (shared), H·W (per pixel) or B·H·W values."""
    n = c.shape[0]
    if n == 1:
        return np.float64(c[0])
    if n == hw:
        return np.float64(c[i % hw])
    return np.float64(c[i])


@njit(cache=True, nogil=True)
def step_events(h_on, h_off, sig_a, ref_a, d_b, c_on, c_off, t_a, t_b, dt, hw,
                last_t, refractory_s, use_refractory, collect, em_on, em_off, want_counts,
                flat, t, p):
    """Events of one comparator step, in input order (ON pixels first, raster order).

    Parameters (all 1-D arrays over the B·H·W flattened pixels unless stated)
    ----------
    h_on, h_off : crossing counts (floating, whole numbers).
    sig_a, ref_a : comparator input and reference at the step start (video dtype).
    d_b : comparator input minus reference at the step end.
    c_on, c_off : thresholds (1, H·W or B·H·W values).
    t_a, t_b, dt : float64 (B,) step start, end and length (seconds).
    hw : pixels per batch element.
    last_t : float64 last event time per pixel (updated in place; unused without refractory).
    refractory_s : refractory period (s); ``use_refractory``: apply it.
    collect : write the events into ``flat``, ``t``, ``p`` (capacity ≥ the emitted count).
    em_on, em_off : emitted counts per pixel (written when ``want_counts``).

    Returns
    -------
    (n_events, lost) : events written, crossings lost to the refractory period (float64).
    """
    n_pix = h_on.shape[0]
    k = 0
    lost = 0.0
    for pol in range(2):
        h = h_on if pol == 0 else h_off
        c = c_on if pol == 0 else c_off
        em = em_on if pol == 0 else em_off
        sign = 1 if pol == 0 else -1
        for i in range(n_pix):
            hi = h[i]
            if not hi > 0:
                continue
            n = np.float64(hi)
            b = i // hw
            da = np.float64(sig_a[i] - ref_a[i])
            v = (np.float64(d_b[i]) - da) / dt[b]
            if sign < 0:
                da = -da
                v = -v
            cc = _threshold(c, i, hw)
            ta = t_a[b]
            rising = v > 0
            j0 = 1.0
            m = 1.0
            if not use_refractory:
                emitted = n if rising else 0.0
            else:
                vs = v if rising else 1.0
                j0 = max(math.ceil((vs * (last_t[i] + refractory_s - ta) + da) / cc), 1.0)
                m = max(math.ceil(refractory_s * vs / cc), 1.0)
                emitted = 1.0 + math.floor((n - j0) / m) if n >= j0 else 0.0
                if not rising:
                    emitted = 0.0
                if emitted > 0:
                    j_last = j0 + (emitted - 1.0) * m
                    last_t[i] = ta + (j_last * cc - da) / vs
                lost += n - emitted
            if want_counts:
                em[i] = emitted
            if not collect or not emitted > 0:
                continue
            lo = np.nextafter(ta, np.inf)
            hi_t = t_b[b]
            for q in range(int(emitted)):
                j = np.float64(q)
                j = j + 1.0 if not use_refractory else j * m + j0
                tt = (j * cc - da) / v + ta
                if tt < lo:
                    tt = lo
                if tt > hi_t:
                    tt = hi_t
                flat[k] = i
                t[k] = tt
                p[k] = sign
                k += 1
    return k, lost


@njit(cache=True, nogil=True)
def _bucket(tt: float, lo: float, scale: float, nb: int) -> int:
    f = (tt - lo) * scale
    if not f > 0:  # also NaN
        return 0
    if f >= nb:
        return nb - 1
    return int(f)


@njit(cache=True, nogil=True)
def count_buckets(t, lo, scale, counts):
    """Add the bucket counts of times ``t`` into ``counts`` (length ``nb + 1``, shifted by one)."""
    nb = counts.shape[0] - 1
    for i in range(t.shape[0]):
        counts[_bucket(t[i], lo, scale, nb) + 1] += 1


@njit(cache=True, nogil=True)
def scatter_buckets(flat, t, p, lo, scale, next_pos, flat_out, t_out, p_out):
    """Move events into their buckets in input order (``next_pos``: each bucket's next slot)."""
    nb = next_pos.shape[0] - 1
    for i in range(t.shape[0]):
        b = _bucket(t[i], lo, scale, nb)
        j = next_pos[b]
        next_pos[b] = j + 1
        flat_out[j] = flat[i]
        t_out[j] = t[i]
        p_out[j] = p[i]


@njit(cache=True, nogil=True)
def sort_buckets(starts, flat, t, p):
    """Stable sort by ``t`` inside each bucket ``[starts[b], starts[b + 1])``, in place."""
    for b in range(starts.shape[0] - 1):
        s = starts[b]
        e = starts[b + 1]
        if e - s < 2:
            continue
        if e - s > _BIG_BUCKET:
            order = np.argsort(t[s:e], kind="mergesort") + s
            f2 = flat[order]
            t2 = t[order]
            p2 = p[order]
            flat[s:e] = f2
            t[s:e] = t2
            p[s:e] = p2
            continue
        for i in range(s + 1, e):
            ti = t[i]
            if not ti < t[i - 1]:
                continue
            fi = flat[i]
            pi = p[i]
            j = i - 1
            while j >= s and t[j] > ti:
                t[j + 1] = t[j]
                flat[j + 1] = flat[j]
                p[j + 1] = p[j]
                j -= 1
            t[j + 1] = ti
            flat[j + 1] = fi
            p[j + 1] = pi


@njit(cache=True, nogil=True)
def write_columns(flat, t, p, hw, w, x_out, y_out, t_out, p_out, start):
    """Copy one sorted interval into the event columns from ``start``: ``y = (f mod hw) // w``,
    ``x = (f mod hw) - y w`` (int64), ``t`` and ``p`` as they are."""
    fits32 = hw < 2**31
    for i in range(flat.shape[0]):
        f = flat[i]
        if f >= hw:
            f = f % hw
        if fits32:  # 32-bit division is about twice as fast
            yy = np.int64(np.int32(f) // np.int32(w))
        else:
            yy = np.int64(f) // w
        y_out[start + i] = yy
        x_out[start + i] = np.int64(f) - yy * w
        t_out[start + i] = t[i]
        p_out[start + i] = p[i]


def sort_events(parts: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stable time sort of one frame interval's ``(flat, t, p)`` NumPy parts, concatenated in order.

    Equivalent to concatenating the parts and applying ``argsort(t, kind="stable")``.
    """
    n = sum(len(q[1]) for q in parts)
    flat_dtype = np.int64 if any(q[0].dtype == np.int64 for q in parts) else np.int32
    flat_out = np.empty(n, dtype=flat_dtype)
    t_out = np.empty(n, dtype=np.float64)
    p_out = np.empty(n, dtype=np.int8)
    if n == 0:
        return flat_out, t_out, p_out
    lo = min(float(q[1].min()) for q in parts if len(q[1]))
    hi = max(float(q[1].max()) for q in parts if len(q[1]))
    nb = n  # one bucket per event on average (measured fastest against n/2 and n/4)
    scale = nb / (hi - lo) if hi > lo else 0.0
    if not math.isfinite(scale):  # an interval shorter than the float64 spacing allows
        scale = 0.0
    counts = np.zeros(nb + 1, dtype=np.int64)
    for q in parts:
        count_buckets(q[1], lo, scale, counts)
    starts = np.cumsum(counts)  # starts[b] = first slot of bucket b; starts[nb] = n
    next_pos = starts.copy()
    for q in parts:
        scatter_buckets(q[0].astype(flat_dtype, copy=False), q[1], q[2], lo, scale, next_pos, flat_out, t_out, p_out)
    sort_buckets(starts, flat_out, t_out, p_out)
    return flat_out, t_out, p_out
