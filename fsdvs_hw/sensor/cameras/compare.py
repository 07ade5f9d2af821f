"""Compare simulated events with a recording: rates, polarity, pixel maps, intervals, noise, alignment.

:func:`compare_events` summarises two event streams of the same sensor size (a simulation and a
recording of the same scene, or two recordings) in an :class:`EventComparison`;
:func:`plot_event_comparison` draws it (matplotlib).

Statistics (per stream unless said otherwise)
    *Event rate over time*: events per second of the whole array in bins of ``bin_s``.
    *Temporal alignment*: where the two streams' first events are more than ``max_lag_s``
    apart (a recording on its camera's clock, e.g. DSEC's ``t_offset``, against a simulation
    from 0), the recording is first shifted by that difference (``start_offset_s``); then the
    lag maximising the normalised cross-correlation of the two rate curves (mean removed),
    computed by FFT (O(n log n) in the bins) and searched within ``max_lag_s``, refined by a
    parabola through the peak; positive when the recording is later. The rate correlation is
    taken at that lag. At most :data:`MAX_BINS` rate bins (memory is bounded).
    *ON fraction*: ON events / all events.
    *Count maps*: events per pixel; their Pearson correlation.
    *Inter-event intervals*: between consecutive events of one pixel; medians, and the two-sample
    Kolmogorov-Smirnov statistic of the two distributions (scipy).
    *Noise*: an event is isolated when no other event fell in its 3 x 3 neighbourhood in the same
    or the previous window of ``support_s`` (the background-activity criterion of Delbruck's
    filter, on windows rather than exact times [1]_); the noise rate is isolated events per pixel
    per second.

References
----------
.. [1] T. Delbruck, "Frame-free dynamic digital vision", Proc. Int. Symp. Secure-Life
   Electronics, 2008 (background-activity filter: an event needs a neighbour's recent event).

Examples
--------
>>> import torch
>>> from fsdvs_hw.sensor import SensorConfig, event_list
>>> video = 0.3 + 0.5 * torch.rand(1, 30, 16, 16, generator=torch.Generator().manual_seed(1))
>>> ts = torch.linspace(0, 0.29, 30)
>>> a = event_list(video, config=SensorConfig.ideal(0.2), timestamps_s=ts)
>>> b = event_list(video, config=SensorConfig.ideal(0.2), timestamps_s=ts + 0.02)
>>> c = compare_events(a, b, bin_s=0.01)
>>> round(c.lag_s, 2), round(c.count_map_correlation, 6)
(0.02, 1.0)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError

__all__ = ["MAX_BINS", "EventComparison", "compare_events", "event_columns", "plot_event_comparison"]

#: Most rate bins :func:`compare_events` allocates (a smaller ``bin_s`` over a long span is refused).
MAX_BINS = 1 << 21


def event_columns(
    events: Any, shape: tuple[int, int] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int]:
    """``(t_s float64, x int64, y int64, p int8, height, width)`` of an EventList, EventFile or file path.

    ``shape`` = (height, width) where the events do not carry it (an EventList); default the
    largest pixel + 1.
    """
    if isinstance(events, (str, Path)):
        from ..eventfiles.recordings import read_recording

        events = read_recording(events)
    if hasattr(events, "t_us"):  # EventFile
        t = np.asarray(events.t_us, dtype=np.float64) * 1e-6
        x, y, p = (np.asarray(events.x, np.int64), np.asarray(events.y, np.int64), np.asarray(events.p, np.int8))
        h, w = shape or (events.height, events.width)
    elif hasattr(events, "t") and hasattr(events, "b"):  # EventList
        b = np.asarray(events.b)
        if b.size and int(b.max()) > 0:
            raise InputError("events: several batch elements; select one (EventList.select(b))")
        t = np.asarray(events.t, dtype=np.float64)
        x, y, p = (np.asarray(events.x, np.int64), np.asarray(events.y, np.int64), np.asarray(events.p, np.int8))
        h, w = shape or ((int(y.max()) + 1 if y.size else 1), (int(x.max()) + 1 if x.size else 1))
    else:
        raise InputError(f"events: expected an EventList, EventFile or event-file path, got {type(events).__name__}")
    _check_columns(t, x, y, p, int(h), int(w), shape is not None or hasattr(events, "t_us"))
    return t, x, y, p, int(h), int(w)


def _check_columns(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, h: int, w: int, declared: bool) -> None:
    """Finite times, pixels inside the sensor (or at least >= 0), polarity ±1: else an InputError."""
    if not (t.size == x.size == y.size == p.size):
        raise InputError(f"events: columns of different lengths (t {t.size}, x {x.size}, y {y.size}, p {p.size})")
    if not t.size:
        return
    bad = ~np.isfinite(t)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"events: time of event {i} is {float(t[i])}; times must be finite seconds")
    for name, v, n in (("x", x, w), ("y", y, h)):
        lo, hi = int(v.min()), int(v.max())
        if lo < 0 or (declared and hi >= n):
            i = int(np.argmax(v < 0)) if lo < 0 else int(np.argmax(v >= n))
            raise InputError(
                f"events: {name} of event {i} is {int(v[i])}, outside [0, {n}) of the {w}x{h} sensor"
                if declared
                else f"events: {name} of event {i} is {int(v[i])}; pixel coordinates must be >= 0"
            )
    if not bool((np.abs(p.astype(np.int16)) == 1).all()):
        raise InputError("events: polarity must be +1 (ON) or -1 (OFF)")


@dataclass(frozen=True)
class EventComparison:
    """The statistics of :func:`compare_events` (``_sim`` / ``_real`` per stream).

    Attributes
    ----------
    bin_s : float
        Rate bin width (s).
    bin_start_s : numpy.ndarray
        Start of each rate bin (s).
    rate_sim_hz, rate_real_hz : numpy.ndarray
        Events per second of the whole array in each bin.
    lag_s : float
        Lag of the recording behind the simulation at the cross-correlation peak (s).
    rate_correlation : float
        Normalised cross-correlation of the rate curves at ``lag_s`` (Pearson, -1..1).
    on_fraction_sim, on_fraction_real : float
        ON events / all events.
    count_map_sim, count_map_real : numpy.ndarray
        Events per pixel, (height, width).
    count_map_correlation : float
        Pearson correlation of the two count maps (nan if one is constant).
    iei_median_sim_s, iei_median_real_s : float
        Median interval between consecutive events of a pixel (s; nan without any).
    iei_ks_statistic : float
        Two-sample Kolmogorov-Smirnov statistic of the interval distributions (0..1).
    noise_rate_sim_hz, noise_rate_real_hz : float
        Isolated (unsupported) events per pixel per second.
    events_sim, events_real : int
        Event counts.
    start_offset_s : float
        Shift applied to the recording before the rate curves are binned (s): the difference of
        the streams' first events where it exceeds ``max_lag_s``, else 0; part of ``lag_s``.
    """

    bin_s: float
    bin_start_s: np.ndarray
    rate_sim_hz: np.ndarray
    rate_real_hz: np.ndarray
    lag_s: float
    rate_correlation: float
    on_fraction_sim: float
    on_fraction_real: float
    count_map_sim: np.ndarray
    count_map_real: np.ndarray
    count_map_correlation: float
    iei_median_sim_s: float
    iei_median_real_s: float
    iei_ks_statistic: float
    noise_rate_sim_hz: float
    noise_rate_real_hz: float
    events_sim: int
    events_real: int
    start_offset_s: float = 0.0

    def summary(self) -> dict[str, float]:
        """The scalar statistics as a dict (for tables and JSON)."""
        return {
            k: float(getattr(self, k))
            for k in (
                "start_offset_s",
                "lag_s",
                "rate_correlation",
                "on_fraction_sim",
                "on_fraction_real",
                "count_map_correlation",
                "iei_median_sim_s",
                "iei_median_real_s",
                "iei_ks_statistic",
                "noise_rate_sim_hz",
                "noise_rate_real_hz",
                "events_sim",
                "events_real",
            )
        }

    def __repr__(self) -> str:
        return (
            f"EventComparison(events {self.events_sim} / {self.events_real}, ON fraction "
            f"{self.on_fraction_sim:.3f} / {self.on_fraction_real:.3f}, rate r {self.rate_correlation:.3f}, "
            f"IEI KS {self.iei_ks_statistic:.3f}, lag {self.lag_s:.6g} s)"
        )

    def __str__(self) -> str:
        """A table for people: first the statistics that separate good from bad sensor parameters
        (counts, ON fraction, rate correlation, inter-event-interval KS), then the others."""

        def pct(a: float, b: float) -> str:
            return f"{100 * (a / b - 1):+.1f} %" if b else "—"

        def ms(v: float) -> str:
            return f"{v * 1e3:.3f} ms" if np.isfinite(v) else "—"

        h, w = self.count_map_sim.shape
        rows = [
            (
                "events",
                f"{self.events_sim}",
                f"{self.events_real}",
                f"sim/rec {pct(self.events_sim, self.events_real)}",
            ),
            (
                "ON fraction",
                f"{self.on_fraction_sim:.4f}",
                f"{self.on_fraction_real:.4f}",
                f"difference {self.on_fraction_sim - self.on_fraction_real:+.4f}",
            ),
            ("rate correlation", "", "", f"{self.rate_correlation:.4f} (1 = same rate curve; bins {self.bin_s:g} s)"),
            ("IEI KS statistic", "", "", f"{self.iei_ks_statistic:.4f} (0 = same interval distribution)"),
            ("IEI median", ms(self.iei_median_sim_s), ms(self.iei_median_real_s), ""),
            (
                "noise rate (Hz/px)",
                f"{self.noise_rate_sim_hz:.4g}",
                f"{self.noise_rate_real_hz:.4g}",
                "isolated events",
            ),
            ("count-map correlation", "", "", f"{self.count_map_correlation:.4f} (weak: ranks parameters poorly)"),
            (
                "lag",
                "",
                "",
                f"{self.lag_s:.6f} s (recording after simulation; start offset {self.start_offset_s:.6f} s)",
            ),
        ]
        head = f"event comparison ({w}x{h} sensor): simulation vs recording"
        lines = [head, f"  {'statistic':<22} {'simulation':>12} {'recording':>12}  note"]
        lines += [f"  {n:<22} {a:>12} {b:>12}  {c}".rstrip() for n, a, b, c in rows]
        return "\n".join(lines)


def inter_event_intervals(t: np.ndarray, x: np.ndarray, y: np.ndarray, width: int) -> np.ndarray:
    """Intervals (s) between consecutive events of the same pixel, all pixels pooled."""
    key = y * width + x
    order = np.lexsort((t, key))
    k, ts = key[order], t[order]
    same = k[1:] == k[:-1]
    return (ts[1:] - ts[:-1])[same]


def isolated_events(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, height: int, width: int, support_s: float
) -> np.ndarray:
    """Boolean per event: no other event in its 3 x 3 neighbourhood in its window or the previous one."""
    if not t.size:
        return np.zeros(0, dtype=bool)
    win = np.floor((t - t.min()) / support_s).astype(np.int64)
    plane = height * width
    keys = win * plane + y * width + x
    uniq, counts = np.unique(keys, return_counts=True)

    def count_at(w: np.ndarray, yy: np.ndarray, xx: np.ndarray) -> np.ndarray:
        ok = (yy >= 0) & (yy < height) & (xx >= 0) & (xx < width) & (w >= 0)
        q = w * plane + np.clip(yy, 0, height - 1) * width + np.clip(xx, 0, width - 1)
        i = np.clip(np.searchsorted(uniq, q), 0, uniq.size - 1)
        return np.where(ok & (uniq[i] == q), counts[i], 0)

    support = np.zeros(t.size, dtype=np.int64)
    for dw in (0, -1):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                support += count_at(win + dw, y + dy, x + dx)
    return support - 1 == 0  # minus the event itself


def _pearson(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a.astype(np.float64).ravel(), b.astype(np.float64).ravel()
    a, b = a - a.mean(), b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 0 else float("nan")


def _lag(sim: np.ndarray, real: np.ndarray, max_lag: int) -> tuple[float, float]:
    """Lag (bins, real after sim, parabola-refined) and the correlation at the integer peak.

    The cross-correlation is computed by FFT (:func:`scipy.signal.correlate`, O(n log n) in the
    bins) and searched within ``|lag| <= max_lag``."""
    from scipy.signal import correlate

    a, b = sim - sim.mean(), real - real.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    if den == 0:
        return 0.0, float("nan")
    full = correlate(b, a, mode="full", method="fft") / den  # index n-1 is lag 0; k > 0: real later
    n = a.size
    m = min(max_lag, n - 1)
    cc = full[n - 1 - m : n + m]
    lg = np.arange(-m, m + 1)
    i = int(np.argmax(cc))
    frac = 0.0
    if 0 < i < cc.size - 1:
        d = cc[i - 1] - 2 * cc[i] + cc[i + 1]
        frac = 0.5 * (cc[i - 1] - cc[i + 1]) / d if d < 0 else 0.0
    return float(lg[i] + frac), float(min(cc[i], 1.0))


def _two_streams(sim: Any, real: Any, shape: tuple[int, int] | None) -> tuple[Any, Any, tuple[int, int]]:
    """The checked columns ``(t, x, y, p)`` of both streams and the common sensor (height, width)."""
    columns = []
    for name, ev in (("simulation", sim), ("recording", real)):
        try:
            columns.append(event_columns(ev, shape))
        except InputError as exc:
            raise InputError(f"compare_events: {name}: {exc}") from None
    (ts, xs, ys, ps, hs, ws), (tr, xr, yr, pr, hr, wr) = columns
    known = [
        (h_, w_)
        for ev, h_, w_ in ((sim, hs, ws), (real, hr, wr))
        if shape is not None or hasattr(ev, "t_us") or isinstance(ev, (str, Path))
    ]
    if len(set(known)) > 1:
        raise InputError(f"compare_events: sensor sizes differ: simulation {ws}x{hs}, recording {wr}x{hr}")
    h, w = known[0] if known else (max(hs, hr), max(ws, wr))
    for name, hh, ww in (("simulation", hs, ws), ("recording", hr, wr)):
        if hh > h or ww > w:
            raise InputError(
                f"compare_events: sensor sizes differ: {name} has pixels up to {ww - 1}, {hh - 1}, "
                f"outside the {w}x{h} sensor"
            )
    return (ts, xs, ys, ps), (tr, xr, yr, pr), (h, w)


def compare_events(
    sim: Any,
    real: Any,
    *,
    bin_s: float = 0.01,
    max_lag_s: float = 0.1,
    support_s: float = 0.01,
    shape: tuple[int, int] | None = None,
) -> EventComparison:
    """Compare a simulated event stream with a recording (or any two streams of one sensor size).

    Parameters
    ----------
    sim, real : EventList, EventFile or path
        The two streams (a path is read by :func:`~fsdvs_hw.sensor.eventfiles.recordings.read_recording`).
    bin_s : float
        Rate bin width in seconds (default 10 ms).
    max_lag_s : float
        Largest |lag| searched for the alignment, seconds (default 0.1).
    support_s : float
        Window of the isolated-event (noise) criterion, seconds (default 10 ms).
    shape : (int, int), optional
        (height, width) for EventLists (default: the larger stream's extent).

    Returns
    -------
    EventComparison

    Raises
    ------
    InputError
        Sensor sizes differ, a stream is empty, a time that is not finite, a pixel outside the
        sensor (or negative), a polarity other than ±1, a non-positive ``bin_s``/``support_s``,
        or more than :data:`MAX_BINS` rate bins.
    """
    for name, v in (("bin_s", bin_s), ("support_s", support_s), ("max_lag_s", max_lag_s)):
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
            raise InputError(f"compare_events: {name} must be a positive number of seconds, got {v!r}")
    (ts, xs, ys, ps), (tr, xr, yr, pr), (h, w) = _two_streams(sim, real, shape)
    if not ts.size or not tr.size:
        raise InputError(f"compare_events: empty stream (simulation {ts.size} events, recording {tr.size})")
    offset = float(tr.min() - ts.min())
    offset = offset if abs(offset) > max_lag_s else 0.0
    tr = tr - offset  # a recording on its own clock (DSEC's t_offset) brought to the simulation's start
    t0 = min(ts.min(), tr.min())
    t1 = max(ts.max(), tr.max())
    n_bins = max(int(np.ceil((t1 - t0) / bin_s)), 1)
    if n_bins > MAX_BINS:
        raise InputError(
            f"compare_events: bin_s {bin_s:g} s gives {n_bins} rate bins over the {t1 - t0:g} s span "
            f"(start offset {offset:g} s removed); at most {MAX_BINS}: use bin_s >= {(t1 - t0) / MAX_BINS:.3g} s"
        )
    edges = t0 + bin_s * np.arange(n_bins + 1)
    rate_s = np.histogram(ts, edges)[0] / bin_s
    rate_r = np.histogram(tr, edges)[0] / bin_s
    lag_bins, corr = _lag(rate_s, rate_r, int(round(max_lag_s / bin_s)))
    from ...limits import check_allocation

    check_allocation(f"compare_events: two count maps of a {w}x{h} sensor (int64)", 2 * 8 * h * w)
    maps = [np.bincount(yy * w + xx, minlength=h * w).reshape(h, w) for xx, yy in ((xs, ys), (xr, yr))]
    iei_s, iei_r = inter_event_intervals(ts, xs, ys, w), inter_event_intervals(tr, xr, yr, w)
    if iei_s.size and iei_r.size:
        from scipy.stats import ks_2samp

        ks = float(ks_2samp(iei_s, iei_r).statistic)
    else:
        ks = float("nan")
    dur_s, dur_r = max(float(ts.max() - ts.min()), bin_s), max(float(tr.max() - tr.min()), bin_s)
    noise_s = isolated_events(ts, xs, ys, h, w, support_s).sum() / (h * w * dur_s)
    noise_r = isolated_events(tr, xr, yr, h, w, support_s).sum() / (h * w * dur_r)
    return EventComparison(
        bin_s=float(bin_s),
        bin_start_s=edges[:-1],
        rate_sim_hz=rate_s,
        rate_real_hz=rate_r,
        lag_s=offset + lag_bins * bin_s,
        rate_correlation=corr,
        on_fraction_sim=float((ps > 0).mean()),
        on_fraction_real=float((pr > 0).mean()),
        count_map_sim=maps[0],
        count_map_real=maps[1],
        count_map_correlation=_pearson(maps[0], maps[1]),
        iei_median_sim_s=float(np.median(iei_s)) if iei_s.size else float("nan"),
        iei_median_real_s=float(np.median(iei_r)) if iei_r.size else float("nan"),
        iei_ks_statistic=ks,
        noise_rate_sim_hz=float(noise_s),
        noise_rate_real_hz=float(noise_r),
        events_sim=int(ts.size),
        events_real=int(tr.size),
        start_offset_s=offset,
    )


def plot_event_comparison(comparison: EventComparison, axes: Any = None) -> tuple[Any, Any]:
    """Draw a comparison: rate curves (recording shifted by the lag), both count maps, IEI histograms.

    Parameters
    ----------
    comparison : EventComparison
    axes : array of 4 matplotlib Axes, optional
        Where to draw; default a new 2 x 2 figure.

    Returns
    -------
    (Figure, numpy.ndarray of Axes)
        Nothing is shown or saved (as :mod:`fsdvs_hw.plots`).
    """
    import matplotlib.pyplot as plt

    c = comparison
    if axes is None:
        fig, axes = plt.subplots(2, 2, figsize=(8.4, 6.4), constrained_layout=True)
    else:
        fig = np.asarray(axes).ravel()[0].figure
    ax = np.asarray(axes).ravel()
    ax[0].plot(c.bin_start_s, c.rate_sim_hz, label="simulation")
    fine = c.lag_s - c.start_offset_s  # the rate curves are binned after the start offset
    ax[0].plot(c.bin_start_s - fine, c.rate_real_hz, label=f"recording (shifted {c.lag_s * 1e3:.1f} ms)")
    ax[0].set(xlabel="time (s)", ylabel="events / s", title=f"rate, r = {c.rate_correlation:.3f}")
    ax[0].legend(fontsize="small")
    vmax = max(float(c.count_map_sim.max()), float(c.count_map_real.max()), 1.0)
    for a, m, name in ((ax[1], c.count_map_sim, "simulation"), (ax[2], c.count_map_real, "recording")):
        im = a.imshow(m, vmin=0, vmax=vmax, cmap="magma")
        a.set(title=f"{name}: events / pixel", xticks=[], yticks=[])
    fig.colorbar(im, ax=[ax[1], ax[2]], shrink=0.8)
    ax[2].set_xlabel(f"map correlation {c.count_map_correlation:.3f}")
    ax[3].bar([0, 1], [c.on_fraction_sim, c.on_fraction_real], tick_label=["simulation", "recording"])
    ax[3].set(
        ylim=(0, 1),
        ylabel="ON fraction",
        title=f"IEI median {c.iei_median_sim_s * 1e3:.2f} / {c.iei_median_real_s * 1e3:.2f} ms, "
        f"KS {c.iei_ks_statistic:.2f}",
    )
    return fig, axes
