"""Fit the simulator's sensor parameters to a recording of a known video or of a static scene.

:func:`calibrate_sensor` estimates the ON/OFF thresholds and their per-pixel spread, the
refractory period, the leak and shot-noise rates and (optionally) the photoreceptor bandwidth,
each with a confidence interval, and returns a :class:`SensorCalibration` whose ``config`` is the
fitted :class:`~fsdvs_hw.sensor.SensorConfig`.

Method (the pixel model of :mod:`fsdvs_hw.sensor.simulation.events`)
    The comparator input ``L`` of every pixel is rebuilt from the known video with the base
    configuration's photoreceptor (response, knee, low-pass at the candidate bandwidth, the
    simulator's sub-steps), linear between sub-steps as the simulator takes it. After an event
    the memorised reference sits at the crossed level, so for two consecutive events of a pixel
    the change ``d = L(t_i) - L(t_{i-1})`` is ``+C_on`` of that pixel for an ON event and
    ``-C_off`` for an OFF event, whatever the earlier polarity (``m C`` when the refractory
    period swallowed ``m - 1`` crossings; a noise event, which does not move the reference, gives
    an outlier), corrected for the leak's drift of the reference (``leak · C_on`` per second).

    *Thresholds*: per pixel the median of ``d`` (ON) and ``-d`` (OFF) over pixels with at least
    ``min_events`` pairs, using only pairs at least ``2 R`` apart (a pair that lost crossings to
    the refractory period ``R`` is closer: ``m`` crossings of spacing ``C / v < R`` span under
    ``R + C / v``; before ``R`` is known, twice the 0.1 % quantile of the intervals). The nominal
    thresholds are their means over pixels, ``threshold_sigma`` the pooled between-pixel standard
    deviation (the median's own sampling variance, from the MAD, subtracted).
    *Bandwidth* (``fit_cutoff=True``): the cut-off at which the per-pixel relative spread of ``d``
    around its median (pairs at least ``2 R`` apart) is smallest (zero for the right model); a
    log-spaced scan, then a bounded scalar minimisation.
    *Refractory period*: from pairs consistent with the thresholds (``d / C`` within 0.1 of an
    integer), the smallest intervals. If swallowed crossings are seen (pairs with ``m = 2``: at
    least 20 and 0.2 % of the consistent pairs, and well above the count at ``m = 2.5``, which
    noise events produce alike) the period binds: the smallest interval less ln 2 times the mean
    spacing of the ten smallest (median-unbiased; the gap above the true period is exponential
    for a locally uniform density), CI from that exponential law, widened by the time resolution
    (1 µs for a file). Otherwise nothing is lost and the data only bound it: estimate 0, CI
    [0, smallest interval].
    *Noise*: in static pixels (total variation of ``L`` below a quarter of the smaller threshold:
    every pixel for a static scene) OFF events come from shot noise only (rate ``shot / 2``) and
    ON events from shot noise and leak (``shot / 2 + leak``): ``shot = 2 r_off``,
    ``leak = r_on - r_off``.

    Intervals are percentile bootstraps over pixels (``n_boot`` resamples): the population of
    pixels is what varies from one sensor (or one patch) to the next.

References
----------
.. [1] P. Lichtsteiner, C. Posch, T. Delbruck, IEEE JSSC 43(2), 2008 (the pixel: events at
   log-intensity changes of one threshold; mismatch between pixels).
.. [2] B. Efron, R. Tibshirani, "An Introduction to the Bootstrap", Chapman & Hall, 1993
   (percentile intervals).

Examples
--------
>>> import torch
>>> from fsdvs_hw.sensor import SensorConfig, event_list
>>> T, H, W = 60, 12, 12
>>> ts = torch.linspace(0, 0.3, T)
>>> ph = torch.arange(W) * 0.7
>>> video = 0.5 * (1.2 + torch.sin(2 * torch.pi * 8 * ts[:, None, None] + ph)).expand(T, H, W)[None]
>>> true = SensorConfig.ideal(0.25, threshold_sigma=0.02, seed=1)
>>> rec = event_list(video, config=true, timestamps_s=ts)
>>> cal = calibrate_sensor(rec, video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=50)
>>> round(cal.estimates["threshold_on"].value, 2), cal.estimates["threshold_on"].contains(0.25)
(0.25, True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ..simulation.config import SensorConfig
from .compare import event_columns

__all__ = ["CALIBRATED_FIELDS", "Estimate", "SensorCalibration", "calibrate_sensor", "comparator_input"]

#: Parameters :func:`calibrate_sensor` can estimate (SensorConfig field names).
CALIBRATED_FIELDS = (
    "threshold_on",
    "threshold_off",
    "threshold_sigma",
    "refractory_s",
    "leak_rate_hz",
    "shot_noise_rate_hz",
    "cutoff_hz",
)


@dataclass(frozen=True)
class Estimate:
    """One fitted parameter: value and confidence interval (SensorConfig units).

    Attributes
    ----------
    value, low, high : float
        Point estimate and interval bounds.
    n : int
        Data behind it (pixels for thresholds and noise, event pairs for the refractory period).
    method : str
        How it was estimated (one line).
    """

    value: float
    low: float
    high: float
    n: int
    method: str

    def contains(self, x: float) -> bool:
        """True if ``x`` lies in [low, high]."""
        return bool(self.low <= x <= self.high)


@dataclass(frozen=True)
class SensorCalibration:
    """The result of :func:`calibrate_sensor`.

    Attributes
    ----------
    estimates : dict of str to Estimate
        Per :data:`CALIBRATED_FIELDS` name that could be estimated from the data.
    config : SensorConfig
        The base configuration with every estimated field replaced by its point estimate.
    level : float
        Confidence level of the intervals.
    notes : list of str
        What could not be estimated and why.
    """

    estimates: dict[str, Estimate]
    config: SensorConfig
    level: float
    notes: list[str] = field(default_factory=list)

    def table(self, truth: SensorConfig | None = None) -> list[dict[str, Any]]:
        """Rows ``parameter, true (if given), value, low, high, n, covered`` for reports."""
        rows = []
        for k, e in self.estimates.items():
            row: dict[str, Any] = {"parameter": k, "value": e.value, "low": e.low, "high": e.high, "n": e.n}
            if truth is not None:
                tv = float(getattr(truth, k))
                row["true"], row["covered"] = tv, e.contains(tv)
            rows.append(row)
        return rows


# ---------------------------------------------------------------------------- comparator input
@dataclass
class _Photoreceptor:
    """The log signal on the simulator's sub-step grid, ready for a low-pass at any cut-off.

    ``times`` (G,) s; ``start`` (P,) the first frame's log signal; ``target``, ``bandwidth``
    (G-1, P): the log signal at the end of each sub-step and its cut-off as a fraction of
    ``cutoff_hz``; ``dt`` (G-1,) the sub-step lengths; ``filtered``: whether the base has a low-pass.
    """

    times: np.ndarray
    start: np.ndarray
    target: np.ndarray
    bandwidth: np.ndarray
    dt: np.ndarray
    filtered: bool

    def signal(self, cutoff_hz: float) -> np.ndarray:
        """(G, P) comparator input after a first-order low-pass at ``cutoff_hz`` (none if 0)."""
        if not self.filtered or not 0 < cutoff_hz < math.inf:
            return np.concatenate([self.start[None], self.target])
        alpha = -np.expm1(-2.0 * math.pi * cutoff_hz * self.bandwidth * self.dt[:, None])
        out = np.empty((self.target.shape[0] + 1, self.start.size))
        out[0] = lp = self.start
        for k in range(self.target.shape[0]):
            lp = lp + alpha[k] * (self.target[k] - lp)
            out[k + 1] = lp
        return out


def _photoreceptor(video: Any, timestamps_s: Any, config: SensorConfig) -> _Photoreceptor:
    import torch

    from ..simulation.events import resolve_inputs, substeps_per_interval
    from ..simulation.filtering import filtered_log_signal

    vid = torch.as_tensor(video)
    if vid.ndim == 3:
        vid = vid[None]
    if vid.ndim != 4 or vid.shape[0] != 1:
        raise InputError(f"video: expected (T, H, W) or (1, T, H, W) intensities, got shape {tuple(vid.shape)}")
    vid, w, ts, cfg = resolve_inputs(vid, None, timestamps_s, config, None)[:4]
    with torch.no_grad():
        sig = filtered_log_signal(vid, w, cfg)
        L = sig.log_signal[0].to(torch.float64).reshape(vid.shape[1], -1).numpy()
        T = L.shape[0]
        tsd = ts.to(torch.float64).reshape(-1)[:T].numpy()
        if not cfg.has_photoreceptor:
            return _Photoreceptor(tsd, L[0], L[1:], np.ones_like(L[1:]), np.diff(tsd), False)
        subs = substeps_per_interval(sig.log_signal, cfg, False)
        frac = (
            torch.clamp(
                (sig.cutoff_intensity[0].to(torch.float64) + cfg.dark_intensity) / cfg.full_scale_intensity, 0.0, 1.0
            )
            .reshape(T, -1)
            .numpy()
        )
    times, targets, bands, dts = [tsd[:1]], [], [], []
    for k in range(T - 1):
        S = subs[k]
        a = (np.arange(1, S + 1) / S)[:, None]
        targets.append(L[k] + a * (L[k + 1] - L[k]))
        bands.append(frac[k] + a * (frac[k + 1] - frac[k]))
        dts.append(np.full(S, (tsd[k + 1] - tsd[k]) / S))
        times.append(tsd[k] + (tsd[k + 1] - tsd[k]) * a[:, 0])
    return _Photoreceptor(
        np.concatenate(times), L[0], np.concatenate(targets), np.concatenate(bands), np.concatenate(dts), True
    )


def comparator_input(video: Any, timestamps_s: Any, config: SensorConfig) -> tuple[np.ndarray, np.ndarray]:
    """The comparator input the simulator steps through, on its time grid.

    Returns ``(times (G,), L (G, H*W))``: frame and sub-step times (s) and the log signal after
    the photoreceptor (the simulator's ``filtered_log_signal``, then its low-pass at
    ``config.cutoff_hz`` with the sub-steps ``config`` implies: fixed ``substeps`` or, with
    ``adaptive_fraction``, one global count per interval), linear between grid points.

    Examples
    --------
    >>> import torch
    >>> t, L = comparator_input(torch.full((1, 3, 2, 2), 1.0), torch.tensor([0.0, 0.1, 0.2], dtype=torch.float64),
    ...                         SensorConfig(cutoff_hz=0.0))
    >>> t.tolist(), L.shape, float(L.max())
    ([0.0, 0.1, 0.2], (3, 4), 0.0)
    """
    pr = _photoreceptor(video, timestamps_s, config)
    return pr.times, pr.signal(float(config.cutoff_hz))


def _sample(grid_t: np.ndarray, grid_L: np.ndarray, t: np.ndarray, pix: np.ndarray) -> np.ndarray:
    """``L`` of pixel ``pix`` at time ``t`` (linear between grid points, clamped at the ends)."""
    j = np.clip(np.searchsorted(grid_t, t, side="left") - 1, 0, grid_t.size - 2)
    t0, t1 = grid_t[j], grid_t[j + 1]
    a = np.clip((t - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
    return grid_L[j, pix] * (1 - a) + grid_L[j + 1, pix] * a


@dataclass
class _Pairs:
    """Consecutive events of one pixel: the later event's pixel, polarity, time, interval and ``d``."""

    pix: np.ndarray
    pol: np.ndarray
    dt: np.ndarray
    d: np.ndarray


def _pairs(
    t: np.ndarray, pix: np.ndarray, p: np.ndarray, grid_t: np.ndarray, grid_L: np.ndarray, leak_drift: float
) -> _Pairs:
    """The pairs of events sorted by pixel, then time (as :func:`calibrate_sensor` sorts them)."""
    Lv = _sample(grid_t, grid_L, t, pix)
    same = pix[1:] == pix[:-1]
    dt = (t[1:] - t[:-1])[same]
    d = (Lv[1:] - Lv[:-1])[same] + leak_drift * dt  # undo the reference's leak drift
    return _Pairs(pix[1:][same], p[1:][same], dt, d)


def _group_medians(pix: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per pixel present: (ids, counts, median of v, median absolute deviation around it); vectorised."""

    def medians(keys: np.ndarray, vals: np.ndarray) -> tuple[np.ndarray, ...]:
        order = np.lexsort((vals, keys))
        k, x = keys[order], vals[order]
        ids, start, count = np.unique(k, return_index=True, return_counts=True)
        lo, hi = start + (count - 1) // 2, start + count // 2
        return ids, count, 0.5 * (x[lo] + x[hi])

    ids, count, med = medians(pix, v)
    dev = np.abs(v - med[np.searchsorted(ids, pix)])
    _, _, mad = medians(pix, dev)
    return ids, count, med, mad


def _per_pixel_median(pix: np.ndarray, v: np.ndarray, n_pix: int, min_events: int) -> tuple[np.ndarray, ...]:
    """Per pixel with >= min_events values: (pixel ids, median, sampling variance of the median)."""
    ids, count, med, mad = _group_medians(pix, v)
    keep = count >= min_events
    var_med = (1.2533 * 1.4826 * mad[keep]) ** 2 / count[keep]  # asymptotic variance of a median
    return ids[keep], med[keep], var_med


def _dispersion(pairs: _Pairs, n_pix: int, min_dt: float) -> np.ndarray:
    """Per pixel: the relative median absolute deviation of ``pol * d`` around its median, ON and OFF
    added (pairs of the right sign at least ``min_dt`` apart; 0 for a pixel with under 3 pairs).

    Zero when the rebuilt comparator input is the pixel's (every pair one threshold apart); scale-
    free and over a pair set that does not depend on the candidate, so no candidate gains by
    pushing pairs out of it (the bandwidth criterion)."""
    out = np.zeros(n_pix)
    for sign in (1, -1):
        sel = (pairs.pol == sign) & (pairs.dt >= min_dt)
        if not sel.any():
            continue
        ids, count, med, mad = _group_medians(pairs.pix[sel], sign * pairs.d[sel])
        keep = count >= 3
        out[ids[keep]] += mad[keep] / np.maximum(np.abs(med[keep]), 1e-6)
    return out


def _percentile_ci(boot: np.ndarray, level: float) -> tuple[float, float]:
    a = (1 - level) / 2
    return float(np.quantile(boot, a)), float(np.quantile(boot, 1 - a))


def _check_level(level: float, n_boot: int, min_events: int) -> None:
    if not (isinstance(level, float) and 0.5 <= level < 1):
        raise InputError(f"calibrate_sensor: level must be a float in [0.5, 1), got {level!r}")
    for name, v, lo in (("n_boot", n_boot, 20), ("min_events", min_events, 1)):
        if not isinstance(v, int) or isinstance(v, bool) or v < lo:
            raise InputError(f"calibrate_sensor: {name} must be an integer >= {lo}, got {v!r}")


# ---------------------------------------------------------------------------- the fit
def calibrate_sensor(
    recording: Any,
    video: Any = None,
    *,
    timestamps_s: Any = None,
    config: SensorConfig | None = None,
    duration_s: float | None = None,
    fit_cutoff: bool = False,
    n_boot: int = 200,
    level: float = 0.95,
    min_events: int = 5,
    seed: int = 0,
) -> SensorCalibration:
    """Fit thresholds, their spread, refractory period, noise rates (and bandwidth) to a recording.

    Parameters
    ----------
    recording : EventList, EventFile or path
        The events (a path is read by :func:`~fsdvs_hw.sensor.eventfiles.recordings.read_recording`).
    video : array or tensor (T, H, W) or (1, T, H, W), optional
        The known source video in linear intensity, registered to the sensor pixel for pixel;
        None for a recording of a static scene (noise rates only).
    timestamps_s : array (T,), optional
        Frame times in seconds on the recording's clock (default ``config.frame_rate_hz``).
    config : SensorConfig, optional
        Base configuration: the model choices not fitted (response, knee, sub-steps, and the
        bandwidth unless ``fit_cutoff``); default ``SensorConfig()``.
    duration_s : float, optional
        Static scene: the recording's length (default: its first to last event).
    fit_cutoff : bool
        Also fit ``cutoff_hz`` (needs ``config.cutoff_hz > 0``: the starting guess; the scan spans
        a factor 8 either side).
    n_boot : int
        Bootstrap resamples over pixels (default 200).
    level : float
        Confidence level (default 0.95).
    min_events : int
        Pairs a pixel needs to enter the threshold estimate (default 5).
    seed : int
        Seed of the bootstrap.

    Returns
    -------
    SensorCalibration

    Raises
    ------
    InputError
        Shapes that disagree, too few events to estimate anything, bad options.
    """
    _check_level(level, n_boot, min_events)
    base = SensorConfig() if config is None else config
    if not isinstance(base, SensorConfig):
        raise InputError(f"calibrate_sensor: config must be a SensorConfig, got {type(base).__name__}")
    rng = np.random.default_rng(seed)
    notes: list[str] = []
    est: dict[str, Estimate] = {}
    if video is None:
        return _static_scene_calibration(recording, duration_s, base, n_boot, level, rng)
    t, p, pix, n_pix = _events_by_pixel(recording, video)
    if base.has_photoreceptor is False and fit_cutoff:
        raise InputError("calibrate_sensor: fit_cutoff needs config.cutoff_hz > 0 as the starting guess")
    photo = _photoreceptor(video, timestamps_s, base)
    if fit_cutoff:
        base = _fit_cutoff(est, t, pix, p, photo, base, n_pix, n_boot, level, rng)
    grid_t, grid_L = photo.times, photo.signal(float(base.cutoff_hz))
    duration = float(grid_t[-1] - grid_t[0])
    pairs = _pairs(t, pix, p, grid_t, grid_L, 0.0)
    right_sign = pairs.pol * pairs.d > 0
    # a pair that lost crossings to the refractory period R is closer than 2 R: fit the thresholds on
    # pairs at least twice the 0.1 % quantile of the intervals apart (about 2 R), refined once R is known
    min_dt = 2.0 * float(np.quantile(pairs.dt[right_sign], 0.001)) if right_sign.any() else 0.0
    map_on, map_off = _thresholds(est, pairs, n_pix, min_events, n_boot, level, rng, min_dt, np.ones(n_pix, bool))
    c_on, c_min = est["threshold_on"].value, min(est["threshold_on"].value, est["threshold_off"].value)
    static = np.abs(np.diff(grid_L, axis=0)).sum(axis=0) < 0.25 * c_min
    leak = 0.0
    if static.sum() >= 10:
        _noise(est, pix, p, static, duration, n_boot, level, rng)
        leak = est["leak_rate_hz"].value
    else:
        notes.append(f"noise rates: only {int(static.sum())} static pixels (need 10)")
    if leak > 0:  # remove the reference's leak drift
        pairs = _pairs(t, pix, p, grid_t, grid_L, leak * c_on)
    # time resolution of the recording: whole µs from a file (EventFile), else float rounding
    resolution = 1e-6 if hasattr(recording, "t_us") or isinstance(recording, (str, Path)) else 1e-9
    _refractory(
        est,
        pairs,
        np.where(np.isnan(map_on), c_on, map_on),
        np.where(np.isnan(map_off), est["threshold_off"].value, map_off),
        level,
        resolution,
    )
    if "refractory_s" in est and est["refractory_s"].value > 0:
        min_dt = max(min_dt, 2.0 * est["refractory_s"].high)
    if leak > 0 or "refractory_s" in est:
        # static pixels only see leak and noise events: with the leak's drift undone their pairs
        # would look like (noise-corrupted) thresholds, so the threshold fit leaves them out
        _thresholds(est, pairs, n_pix, min_events, n_boot, level, rng, min_dt, ~static)
    return SensorCalibration(est, base.replace(**{k: e.value for k, e in est.items()}), level, notes)


def _static_scene_calibration(
    recording: Any, duration_s: float | None, base: SensorConfig, n_boot: int, level: float, rng: Any
) -> SensorCalibration:
    """Noise rates alone, from a recording of a static scene (``duration_s``: its length, s;
    default its first to last event)."""
    notes: list[str] = []
    est: dict[str, Estimate] = {}
    t, x, y, p, h, w = event_columns(recording)
    if duration_s is None:
        duration_s = float(t.max() - t.min()) if t.size > 1 else 0.0
    if not duration_s or duration_s <= 0:
        raise InputError("calibrate_sensor: a static-scene recording needs duration_s > 0 (or two events)")
    notes.append("static scene: thresholds, refractory period and bandwidth need a known video")
    _noise(est, y * w + x, p, np.ones(h * w, bool), float(duration_s), n_boot, level, rng)
    return SensorCalibration(est, base.replace(**{k: e.value for k, e in est.items()}), level, notes)


def _events_by_pixel(recording: Any, video: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``(t, p, pixel, n_pixels)`` of the recording's events, sorted by pixel (row-major index in
    the video's frame) then time, so that consecutive events of a pixel are neighbours; the
    recording checked to fit the video's H x W."""
    import torch

    vid = torch.as_tensor(np.asarray(video) if not isinstance(video, torch.Tensor) else video)
    H, W = int(vid.shape[-2]), int(vid.shape[-1])
    t, x, y, p, h, w = event_columns(recording)
    if (hasattr(recording, "t_us") and (h, w) != (H, W)) or (x.size and (int(x.max()) >= W or int(y.max()) >= H)):
        size = f"a {w}x{h} sensor" if hasattr(recording, "t_us") else f"pixels up to x={w - 1}, y={h - 1}"
        raise InputError(f"calibrate_sensor: recording has {size}, the video is {W}x{H}; register them first")
    order = np.lexsort((t, y * W + x))
    return t[order], p[order], (y * W + x)[order], H * W


def _thresholds(
    est: dict[str, Estimate],
    pairs: _Pairs,
    n_pix: int,
    min_events: int,
    n_boot: int,
    level: float,
    rng: np.random.Generator,
    min_dt: float,
    active: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Fill the threshold estimates; return the per-pixel ON and OFF threshold maps (nan: too few pairs)."""
    meds: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    maps: dict[str, np.ndarray] = {}
    for name, sign in (("threshold_on", 1), ("threshold_off", -1)):
        sel = (pairs.pol == sign) & (sign * pairs.d > 0) & (pairs.dt >= min_dt) & active[pairs.pix]
        ids, med, var_med = _per_pixel_median(pairs.pix[sel], sign * pairs.d[sel], n_pix, min_events)
        if ids.size < 3:
            raise InputError(
                f"calibrate_sensor: only {ids.size} pixels with {min_events} or more "
                f"{name[10:].upper()} event pairs: the video moves too little for a threshold fit"
            )
        meds[name] = (med, var_med)
        maps[name] = np.full(n_pix, np.nan)
        maps[name][ids] = med
    boot_idx = {k: rng.integers(0, v[0].size, size=(n_boot, v[0].size)) for k, v in meds.items()}
    for name, (med, _) in meds.items():
        boot = med[boot_idx[name]].mean(axis=1)
        lo, hi = _percentile_ci(boot, level)
        est[name] = Estimate(
            float(med.mean()),
            lo,
            hi,
            int(med.size),
            "mean over pixels of the median log change between consecutive events; pixel bootstrap",
        )

    def sigma(sel: dict[str, np.ndarray] | None) -> float:
        var = []
        for k, (med, vm) in meds.items():
            m, v = (med, vm) if sel is None else (med[sel[k]], vm[sel[k]])
            var.append(max(float(m.var(ddof=1)) - float(v.mean()), 0.0))
        return math.sqrt(float(np.mean(var)))

    boots = np.array([sigma({k: boot_idx[k][i] for k in meds}) for i in range(n_boot)])
    lo, hi = _percentile_ci(boots, level)
    est["threshold_sigma"] = Estimate(
        sigma(None),
        lo,
        hi,
        int(sum(m[0].size for m in meds.values())),
        "between-pixel SD of the per-pixel thresholds (median's variance removed), ON and OFF pooled; pixel bootstrap",
    )
    return maps["threshold_on"], maps["threshold_off"]


def _noise(
    est: dict[str, Estimate],
    pix: np.ndarray,
    p: np.ndarray,
    static: np.ndarray,
    duration: float,
    n_boot: int,
    level: float,
    rng: np.random.Generator,
) -> None:
    ids = np.flatnonzero(static)
    n_on = np.bincount(pix[p > 0], minlength=static.size)[ids].astype(np.float64)
    n_off = np.bincount(pix[p < 0], minlength=static.size)[ids].astype(np.float64)
    b = rng.integers(0, ids.size, size=(n_boot, ids.size))

    def rates(on: np.ndarray, off: np.ndarray) -> tuple[Any, Any]:
        r_on, r_off = on / duration, off / duration
        return 2 * r_off, r_on - r_off

    shot, leak = (max(float(v), 0.0) for v in rates(n_on.mean(), n_off.mean()))  # rates are >= 0
    shot_b, leak_b = (np.maximum(v, 0.0) for v in rates(n_on[b].mean(axis=1), n_off[b].mean(axis=1)))
    # a pixel bootstrap of zero counts has no spread: fall back to the Poisson bound on the total (3/N rule)
    pois = 3.0 / (ids.size * duration)
    lo, hi = _percentile_ci(shot_b, level)
    est["shot_noise_rate_hz"] = Estimate(
        float(shot),
        lo,
        max(hi, 2 * pois if n_off.sum() == 0 else hi),
        int(ids.size),
        "2 x OFF events per static pixel per second; pixel bootstrap",
    )
    lo, hi = _percentile_ci(leak_b, level)
    if n_on.sum() == 0:
        hi = max(hi, pois)
    est["leak_rate_hz"] = Estimate(
        float(leak), lo, hi, int(ids.size), "(ON - OFF) events per static pixel per second; pixel bootstrap"
    )


def _refractory(
    est: dict[str, Estimate], pairs: _Pairs, map_on: np.ndarray, map_off: np.ndarray, level: float, resolution: float
) -> None:
    c = np.where(pairs.pol > 0, map_on[pairs.pix], map_off[pairs.pix])  # each pixel's own thresholds
    m = pairs.pol * pairs.d / c
    consistent = (np.abs(m - np.round(m)) < 0.1) & (np.round(m) >= 1)
    iei = np.sort(pairs.dt[consistent])
    if iei.size < 10:
        return
    # swallowed crossings: pairs of 2 thresholds, against the background of pairs half-way between
    # integers (a noise event between two others gives a pair of any size)
    swallowed = int((np.abs(m - 2) < 0.1).sum())
    background = int((np.abs(m - 2.5) < 0.1).sum())
    a = 1 - level
    if swallowed < max(20, 0.002 * iei.size) or swallowed < 3 * background + 5 * math.sqrt(background + 1):
        est["refractory_s"] = Estimate(
            0.0,
            0.0,
            float(iei[0]),
            int(iei.size),
            f"no swallowed crossings ({swallowed} pairs of 2 thresholds, "
            f"{background} at 2.5): "
            "bounded by the smallest interval",
        )
        return
    spacing = float(iei[9] - iei[0]) / 9
    est["refractory_s"] = Estimate(
        max(float(iei[0]) - spacing * math.log(2), 0.0),
        max(float(iei[0]) - spacing * math.log(2 / a) - resolution, 0.0),
        float(iei[0]) - spacing * math.log(1 / (1 - a / 2)) + resolution,
        int(iei.size),
        f"smallest interval less the exponential gap ({swallowed} pairs with swallowed crossings)",
    )


def _fit_cutoff(
    est: dict[str, Estimate],
    t: np.ndarray,
    pix: np.ndarray,
    p: np.ndarray,
    photo: _Photoreceptor,
    base: SensorConfig,
    n_pix: int,
    n_boot: int,
    level: float,
    rng: np.random.Generator,
) -> SensorConfig:
    from scipy.optimize import minimize_scalar

    f0 = float(base.cutoff_hz)
    dt = np.diff(t)[np.diff(pix) == 0]  # events come sorted by pixel, then time
    min_dt = 2.0 * float(np.quantile(dt, 0.001)) if dt.size else 0.0  # refractory-safe pairs (see the thresholds)

    def per_pixel(log_f: float) -> np.ndarray:
        return _dispersion(_pairs(t, pix, p, photo.times, photo.signal(float(np.exp(log_f))), 0.0), n_pix, min_dt)

    scan = np.log(f0) + np.linspace(-np.log(8), np.log(8), 13)
    scores = [per_pixel(v).sum() for v in scan]
    i = int(np.argmin(scores))
    lo_b, hi_b = scan[max(i - 1, 0)], scan[min(i + 1, scan.size - 1)]
    res = minimize_scalar(lambda v: per_pixel(v).sum(), bounds=(lo_b, hi_b), method="bounded", options={"xatol": 1e-4})
    best = float(res.x)
    fine = best + np.linspace(-0.1, 0.1, 21) * (hi_b - lo_b)
    table = np.stack([per_pixel(v) for v in fine])  # (grid, pixels)
    b = rng.integers(0, n_pix, size=(n_boot, n_pix))
    boot = fine[np.argmin(table[:, b].sum(axis=2), axis=0)]
    step = float(fine[1] - fine[0])
    lo, hi = _percentile_ci(boot, level)
    est["cutoff_hz"] = Estimate(
        float(np.exp(best)),
        float(np.exp(min(lo, best) - step)),
        float(np.exp(max(hi, best) + step)),
        n_pix,
        "cut-off minimising the per-pixel spread of the log change between events; "
        "pixel bootstrap on a local grid (+- one grid step)",
    )
    return base.replace(cutoff_hz=float(np.exp(best)))
