"""The fit behind :func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor`: data types, checked
inputs and the estimators (the method is described in :mod:`fsdvs_hw.sensor.cameras.calibrate`).

:func:`fit_sensor` is the calibration without its model check and without the estimator-error
widening; :class:`SensorCalibration` and :class:`Estimate` are its results.

Examples
--------
>>> import torch
>>> from fsdvs_hw.sensor import SensorConfig, event_list
>>> from fsdvs_hw.sensor.cameras.calibration_scene import calibration_video
>>> video, ts = calibration_video(80, 8, 10)
>>> rec = event_list(video, config=SensorConfig.ideal(0.25), timestamps_s=ts)
>>> cal = fit_sensor(rec, video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=30)
>>> round(cal.estimates["threshold_on"].value, 3), cal.outcome
(0.25, 'unchecked')
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

__all__ = [
    "CALIBRATED_FIELDS",
    "ESTIMATE_STATUSES",
    "OUTCOMES",
    "Estimate",
    "RecordingColumns",
    "SensorCalibration",
    "comparator_input",
    "fit_sensor",
    "recording_columns",
]

#: What a calibration concluded (``SensorCalibration.outcome``).
OUTCOMES = ("unchecked", "fits", "model mismatch")
#: How far the data determine one parameter (``Estimate.status``).
ESTIMATE_STATUSES = ("estimated", "bounded", "not identifiable")

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
    status : str
        One of :data:`ESTIMATE_STATUSES`: ``"estimated"``; ``"bounded"`` (the data bound the
        parameter but do not pin it: the interval is the statement, e.g. a refractory period
        that never binds, a leak slower than the recording); ``"not identifiable"`` (e.g. a
        cut-off above the scan: ``value`` is ``inf``, ``low`` the scan's top).
    """

    value: float
    low: float
    high: float
    n: int
    method: str
    status: str = "estimated"

    def contains(self, x: float) -> bool:
        """True if ``x`` lies in [low, high]."""
        return bool(self.low <= x <= self.high)

    def line(self, name: str) -> str:
        """One printable line: name, value, interval, n and (unless estimated) the status."""
        if self.status == "not identifiable":
            return f"{name:<20s} not identifiable: {self.method}"
        tail = "" if self.status == "estimated" else f"  ({self.status})"
        return f"{name:<20s} {self.value:11.5g}  [{self.low:.5g}, {self.high:.5g}]  n={self.n}{tail}"


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
    outcome : str
        One of :data:`OUTCOMES`: ``"unchecked"`` (no model check run, or a static scene),
        ``"fits"`` (the posterior-predictive check passed every statistic), ``"model mismatch"``
        (a statistic of the recording falls outside what the fitted model produces: the
        intervals are not to be trusted; :attr:`check` names it).
    warnings : list of str
        Conditions that make the estimates doubtful (a frame rate too low for the thresholds...).
    check : ModelCheck or None
        The posterior-predictive check (:mod:`fsdvs_hw.sensor.cameras.calibration_check`).
    estimator_error : dict or None
        Bias and spread of each estimate over recordings simulated at the fit, already folded
        into the intervals (:mod:`fsdvs_hw.sensor.cameras.calibration_coverage`).
    """

    estimates: dict[str, Estimate]
    config: SensorConfig
    level: float
    notes: list[str] = field(default_factory=list)
    outcome: str = "unchecked"
    warnings: list[str] = field(default_factory=list)
    check: Any = None
    estimator_error: dict[str, Any] | None = None

    def summary(self) -> str:
        """A printable report: the outcome, one line per parameter, the model check, warnings, notes."""
        head = f"sensor calibration ({self.level:.0%} intervals, conventions {self.config.conventions}): {self.outcome}"
        lines = [head, *("  " + e.line(k) for k, e in self.estimates.items())]
        if self.estimator_error:
            lines.append(
                f"  intervals include the estimator's error from {self.estimator_error['n_recordings']} "
                "recordings simulated at the fit"
            )
        if self.check is not None:
            lines.extend("  " + row for row in self.check.lines())
        lines.extend(f"  warning: {w}" for w in self.warnings)
        lines.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def table(self, truth: SensorConfig | None = None) -> list[dict[str, Any]]:
        """Rows ``parameter, value, low, high, n, status`` (and ``true``, ``covered`` given ``truth``) for reports."""
        rows = []
        for k, e in self.estimates.items():
            row: dict[str, Any] = {
                "parameter": k,
                "value": e.value,
                "low": e.low,
                "high": e.high,
                "n": e.n,
                "status": e.status,
            }
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
    ``cutoff_hz``; ``dt`` (G-1,) the sub-step lengths; ``filtered``: whether the base has a low-pass;
    ``frame_index`` (T,): where the frames sit in the grid.
    """

    times: np.ndarray
    start: np.ndarray
    target: np.ndarray
    bandwidth: np.ndarray
    dt: np.ndarray
    filtered: bool
    frame_index: np.ndarray

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
            return _Photoreceptor(tsd, L[0], L[1:], np.ones_like(L[1:]), np.diff(tsd), False, np.arange(T))
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
    frame_index = np.concatenate([[0], np.cumsum(subs[: T - 1])])
    return _Photoreceptor(
        np.concatenate(times),
        L[0],
        np.concatenate(targets),
        np.concatenate(bands),
        np.concatenate(dts),
        True,
        frame_index,
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
def fit_sensor(
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
    """The estimates and pixel-bootstrap intervals alone (``outcome`` ``"unchecked"``).

    Arguments and errors as :func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor`'s.
    """
    _check_level(level, n_boot, min_events)
    if not isinstance(fit_cutoff, bool):
        raise InputError(f"calibrate_sensor: fit_cutoff must be True or False, got {fit_cutoff!r}")
    base = SensorConfig() if config is None else config
    if not isinstance(base, SensorConfig):
        raise InputError(f"calibrate_sensor: config must be a SensorConfig, got {type(base).__name__}")
    if base.conventions != "native":
        raise InputError(
            f"calibrate_sensor: config.conventions={base.conventions!r}: the fit assumes the native conventions "
            "(each event at its crossing time); fit with conventions='native' and read the model check, or "
            "check a recording against known parameters under other conventions with "
            "fsdvs_hw.sensor.cameras.calibration_check.model_check"
        )
    rng = np.random.default_rng(seed)
    if video is None:
        return _static_scene_calibration(recording, duration_s, base, n_boot, level, rng)
    rec = recording_columns(recording, video)
    return _fit(rec, video, timestamps_s, base, fit_cutoff, n_boot, level, min_events, rng)


@dataclass(frozen=True)
class RecordingColumns:
    """A recording's events as checked columns (:func:`recording_columns`).

    Attributes
    ----------
    t : numpy.ndarray
        Event times, s (float64, finite).
    x, y : numpy.ndarray
        Pixel column and row (int64, inside the video's frame).
    p : numpy.ndarray
        Polarity (int8, +1 ON, -1 OFF).
    height, width : int
        The sensor's size (the video's).
    resolution_s : float
        The recording's time resolution: 1 µs for a file (an EventFile), else 1 ns.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    height: int
    width: int
    resolution_s: float

    def __len__(self) -> int:
        return int(self.t.size)


def recording_columns(recording: Any, video: Any) -> RecordingColumns:
    """The events of ``recording`` (EventList, EventFile, path or :class:`RecordingColumns`),
    checked against ``video`` ((T, H, W) or (1, T, H, W)) the same way in every form.

    Raises :class:`~fsdvs_hw.errors.InputError` for a geometry that is not the video's (a file's
    declared size, or pixels outside the frame), non-finite times, or fewer than 2 events.

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw.sensor import SensorConfig, event_list
    >>> video = torch.ones(1, 3, 2, 2); video[:, 1:, 0, 0] = 2.0
    >>> ev = event_list(video, config=SensorConfig.ideal(), timestamps_s=[0.0, 0.1, 0.2])
    >>> rec = recording_columns(ev, video)
    >>> len(rec), rec.width, rec.height
    (3, 2, 2)
    """
    if isinstance(recording, RecordingColumns):
        return recording
    shape = tuple(getattr(video, "shape", np.shape(video)))
    if len(shape) < 3:
        raise InputError(f"video: expected (T, H, W) or (1, T, H, W) intensities, got shape {shape}")
    H, W = int(shape[-2]), int(shape[-1])
    if isinstance(recording, (str, Path)):
        from ..eventfiles.recordings import read_recording

        recording = read_recording(recording)  # a file: its declared geometry is checked below
    is_file = hasattr(recording, "t_us")
    t, x, y, p, h, w = event_columns(recording)  # the geometry is checked here, the same in every form
    if is_file and (h, w) != (H, W):
        raise InputError(f"calibrate_sensor: recording has a {w}x{h} sensor, the video is {W}x{H}; register them first")
    if x.size and (int(x.min()) < 0 or int(y.min()) < 0):
        raise InputError(
            f"calibrate_sensor: recording has negative pixel coordinates (x >= {int(x.min())}, y >= {int(y.min())})"
        )
    if x.size and (int(x.max()) >= W or int(y.max()) >= H):
        raise InputError(
            f"calibrate_sensor: recording has pixels up to x={int(x.max())}, y={int(y.max())}, "
            f"the video is {W}x{H}; register them first"
        )
    if not np.isfinite(t).all():
        bad = int(np.flatnonzero(~np.isfinite(t))[0])
        raise InputError(
            f"calibrate_sensor: recording event {bad} has time {float(t[bad])}; event times must be finite"
        )
    if t.size < 2:
        raise InputError(
            f"calibrate_sensor: the recording has {t.size} event{'s' * (t.size != 1)}: nothing to calibrate "
            "(the fit needs pairs of consecutive events in pixels the video moves)"
        )
    return RecordingColumns(t, x, y, p, H, W, 1e-6 if is_file else 1e-9)


def _check_span(rec: RecordingColumns, grid_t: np.ndarray) -> None:
    """Refuse events outside the video's time span (one frame interval of slack either side)."""
    slack = float(np.median(np.diff(grid_t))) if grid_t.size > 1 else 0.0
    t0, t1 = float(grid_t[0]), float(grid_t[-1])
    lo, hi = float(rec.t.min()), float(rec.t.max())
    if lo < t0 - slack or hi > t1 + slack:
        raise InputError(
            f"calibrate_sensor: the recording spans {lo:.6g} to {hi:.6g} s, the video {t0:.6g} to {t1:.6g} s "
            "(timestamps_s): the events must lie within the video's span, on the recording's clock; "
            "cut the recording to the video or give the video's frame times"
        )


def _fit(
    rec: RecordingColumns,
    video: Any,
    timestamps_s: Any,
    base: SensorConfig,
    fit_cutoff: bool,
    n_boot: int,
    level: float,
    min_events: int,
    rng: np.random.Generator,
) -> SensorCalibration:
    """The fit itself (see the module docstring), on checked columns."""
    notes: list[str] = []
    est: dict[str, Estimate] = {}
    order = np.lexsort((rec.t, rec.y * rec.width + rec.x))
    t, p, pix, n_pix = rec.t[order], rec.p[order], (rec.y * rec.width + rec.x)[order], rec.height * rec.width
    if base.has_photoreceptor is False and fit_cutoff:
        raise InputError("calibrate_sensor: fit_cutoff needs config.cutoff_hz > 0 as the starting guess")
    photo = _photoreceptor(video, timestamps_s, base)
    _check_span(rec, photo.times)
    _check_enough_pairs(t, pix, photo, base, min_events)
    if fit_cutoff:
        base = _fit_cutoff(est, t, pix, p, photo, base, n_pix, n_boot, level, rng)
    grid_t, grid_L = photo.times, photo.signal(float(base.cutoff_hz))
    duration = float(grid_t[-1] - grid_t[0])
    pairs = _pairs(t, pix, p, grid_t, grid_L, 0.0)
    right_sign = pairs.pol * pairs.d > 0
    # a pair that lost crossings to the refractory period R is closer than 2 R: fit the thresholds on
    # pairs at least twice the 0.1 % quantile of the intervals apart (about 2 R), refined once R is known
    min_dt = 2.0 * float(np.quantile(pairs.dt[right_sign], 0.02)) if right_sign.any() else 0.0
    map_on, map_off = _thresholds(est, pairs, n_pix, min_events, n_boot, level, rng, min_dt, np.ones(n_pix, bool))
    c_on, c_min = est["threshold_on"].value, min(est["threshold_on"].value, est["threshold_off"].value)
    static = np.abs(np.diff(grid_L, axis=0)).sum(axis=0) < 0.25 * c_min
    leak = 0.0
    if static.sum() >= 10:
        _noise(est, pix, p, static, duration, n_boot, level, rng)
        leak = est["leak_rate_hz"].value
    else:
        notes.append(f"noise rates: only {int(static.sum())} static pixels (need 10)")
    drift = _leak_from_pairs(pairs, (map_on, map_off), ~static, min_dt, c_on, n_boot, level, rng)
    if drift is not None:
        leak = drift[0]
        notes.append(
            f"reference drift in the moving pixels (pair slope): leak {drift[0]:.4g} [{drift[1]:.4g}, "
            f"{drift[2]:.4g}] Hz; undone in the threshold fit, not reported as the leak (a small effect, "
            "as sensitive to the photoreceptor model as to the leak)"
        )
    if leak > 0:  # remove the reference's leak drift
        pairs = _pairs(t, pix, p, grid_t, grid_L, leak * c_on)
    _refractory(
        est,
        pairs,
        np.where(np.isnan(map_on), c_on, map_on),
        np.where(np.isnan(map_off), est["threshold_off"].value, map_off),
        level,
        rec.resolution_s,
    )
    if "refractory_s" in est and est["refractory_s"].value > 0:
        min_dt = max(min_dt, 2.0 * est["refractory_s"].high)
    if leak > 0 or "refractory_s" in est:
        # static pixels only see leak and noise events: with the leak's drift undone their pairs
        # would look like (noise-corrupted) thresholds, so the threshold fit leaves them out
        _thresholds(est, pairs, n_pix, min_events, n_boot, level, rng, min_dt, ~static)
    c_min = min(est["threshold_on"].value, est["threshold_off"].value)
    warnings = _frame_rate_warning(photo, t, pix, c_min)
    fitted = base.replace(**{k: (0.0 if k == "cutoff_hz" and not math.isfinite(e.value) else e.value)
                             for k, e in est.items()})  # fmt: skip
    return SensorCalibration(est, fitted, level, notes, warnings=warnings)


def _check_enough_pairs(
    t: np.ndarray, pix: np.ndarray, photo: _Photoreceptor, base: SensorConfig, min_events: int
) -> None:
    """Too few events for the moving pixels: told apart from a video that moves too little."""
    L = photo.signal(float(base.cutoff_hz))
    c = min(float(base.threshold_on), float(base.threshold_off))
    moving = np.flatnonzero(np.abs(np.diff(L, axis=0)).sum(axis=0) >= 2 * c)
    if moving.size < 3:
        return  # the threshold fit says the video moves too little
    in_moving = np.isin(pix, moving)
    n_pairs = int((np.diff(pix[in_moving]) == 0).sum())
    need = 3 * min(min_events, 5)
    if n_pairs < need:
        raise InputError(
            f"calibrate_sensor: the recording has {t.size} events, {n_pairs} consecutive pairs in the "
            f"{moving.size} pixels the video moves by two base thresholds or more: too few events for a "
            f"threshold fit (need {need}); is this the recording of this video, on its clock?"
        )


def _frame_rate_warning(photo: _Photoreceptor, t: np.ndarray, pix: np.ndarray, c_min: float) -> list[str]:
    """The advice to upsample when most pairs of consecutive events of a pixel (``t``, ``pix``:
    sorted by pixel, then time) fall inside one frame interval: there the fit knows the signal
    only by interpolating between two frames."""
    frames = photo.times[photo.frame_index]
    k = np.searchsorted(frames, t, side="left")
    same_pixel = pix[1:] == pix[:-1]
    if not same_pixel.any():
        return []
    share = float((k[1:] == k[:-1])[same_pixel].mean())
    if share <= 0.5:
        return []
    rate = (frames.size - 1) / float(frames[-1] - frames[0])
    return [
        f"frame rate {rate:.3g} fps is too low for thresholds near {c_min:.3g}: {share:.0%} of the pairs of "
        "consecutive events of a pixel fall inside one frame interval, where the fit takes the signal as "
        "linear between frames (a real scene is not: thresholds and mismatch then read wrong); upsample the "
        "video first (fsdvs_hw.sensor.simulation.upsampling.upsample_frames, or `fsdvs-hw simulate "
        "--upsample`) until most pairs span a frame"
    ]


def _static_scene_calibration(
    recording: Any, duration_s: float | None, base: SensorConfig, n_boot: int, level: float, rng: Any
) -> SensorCalibration:
    """Noise rates alone, from a recording of a static scene (``duration_s``: its length, s;
    default its first to last event)."""
    notes: list[str] = []
    est: dict[str, Estimate] = {}
    if isinstance(recording, (str, Path)):
        from ..eventfiles.recordings import read_recording

        recording = read_recording(recording)
    t, x, y, p, h, w = event_columns(recording)
    if not np.isfinite(t).all():
        raise InputError("calibrate_sensor: the recording has non-finite event times")
    if duration_s is None:
        duration_s = float(t.max() - t.min()) if t.size > 1 else 0.0
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s) and duration_s > 0):
        raise InputError("calibrate_sensor: a static-scene recording needs duration_s > 0 (or two events)")
    if t.size > 1 and float(t.max() - t.min()) > duration_s * (1 + 1e-6):
        raise InputError(
            f"calibrate_sensor: the recording spans {float(t.max() - t.min()):.6g} s, longer than duration_s={duration_s:g}"
        )
    notes.append("static scene: thresholds, refractory period and bandwidth need a known video")
    _noise(est, y * w + x, p, np.ones(h * w, bool), float(duration_s), n_boot, level, rng)
    return SensorCalibration(est, base.replace(**{k: e.value for k, e in est.items()}), level, notes)


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
    # no steady state assumed: the reference's start phase (unknown: at the first frame, at random,
    # or reset by noise) shifts each pixel's leak count by up to one event, 1 / duration in rate
    phase = 1.0 / duration
    bounded = leak * duration < 2.0
    est["leak_rate_hz"] = Estimate(
        float(leak),
        max(lo - phase, 0.0),
        hi + phase,
        int(ids.size),
        "(ON - OFF) events per static pixel per second, +- 1/duration for the reference's unknown start phase"
        + ("; under 2 leak events per pixel in the recording: bounded only" if bounded else "")
        + "; pixel bootstrap",
        "bounded" if bounded else "estimated",
    )


def _leak_from_pairs(
    pairs: _Pairs,
    maps: tuple[np.ndarray, np.ndarray],
    active: np.ndarray,
    min_dt: float,
    c_on: float,
    n_boot: int,
    level: float,
    rng: np.random.Generator,
) -> tuple[float, float, float] | None:
    """The leak as the reference's drift in the moving pixels, without a steady state: ``(value,
    low, high)`` Hz, or None with under 50 usable pairs.

    The reference drifts down by ``λ = leak · C_on`` per second, so a pair one threshold apart
    spans ``pol · d = C - pol · λ · dt``. ``λ`` is the least-squares slope of ``pol · d`` on
    ``-pol · dt`` (both centred per pixel and polarity) over the pairs within 10 % of one
    threshold; pixel bootstrap. Undoing it keeps an unknown leak from reading OFF high and ON
    low; as the leak's estimate it is fragile (``λ · dt`` is about 1e-5 log units at 0.01 Hz,
    the size of a photoreceptor model's error), so it is not reported as one.
    """
    c = np.where(pairs.pol > 0, maps[0][pairs.pix], maps[1][pairs.pix])
    y = pairs.pol * pairs.d
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = active[pairs.pix] & (pairs.dt >= min_dt) & np.isfinite(c) & (np.abs(y / c - 1) < 0.1)
    if ok.sum() < 50:
        return None
    pix, pol, dt, y = pairs.pix[ok], pairs.pol[ok], pairs.dt[ok], y[ok]
    _, inv, cnt = np.unique(pix * 2 + (pol > 0), return_inverse=True, return_counts=True)
    x = -pol * (dt - (np.bincount(inv, dt) / cnt)[inv])
    r = y - (np.bincount(inv, y) / cnt)[inv]
    n_pix = active.size
    sxy, sxx = np.bincount(pix, x * r, minlength=n_pix), np.bincount(pix, x * x, minlength=n_pix)
    used = np.flatnonzero(sxx > 0)
    if used.size < 3:
        return None
    b = rng.integers(0, used.size, size=(n_boot, used.size))
    lo, hi = _percentile_ci(sxy[used][b].sum(axis=1) / sxx[used][b].sum(axis=1) / c_on, level)
    return max(float(sxy[used].sum() / sxx[used].sum()) / c_on, 0.0), max(lo, 0.0), max(hi, 0.0)


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
            "bounded",
        )
        return
    j = _edge(iei)
    spacing = float(iei[j + 9] - iei[j]) / 9
    est["refractory_s"] = Estimate(
        max(float(iei[j]) - spacing * math.log(2), 0.0),
        max(float(iei[j]) - spacing * math.log(2 / a) - resolution, 0.0),
        float(iei[j]) - spacing * math.log(1 / (1 - a / 2)) + resolution,
        int(iei.size),
        f"lower edge of the intervals less the exponential gap ({swallowed} pairs with swallowed crossings; "
        f"{j} sparser intervals below the edge, noise pairs, left out)",
    )


def _edge(iei: np.ndarray) -> int:
    """Index of the refractory edge in the sorted intervals ``iei``: the first interval from which
    ten in a row span under 2 % of it. Noise events make a few consistent-looking pairs at any
    interval below the period; the pairs that lost crossings pile up just above it."""
    width = iei[9:] - iei[:-9]
    dense = np.flatnonzero(width <= 0.02 * iei[:-9])
    return int(dense[0]) if dense.size else 0


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
    unfiltered = _dispersion(_pairs(t, pix, p, photo.times, photo.signal(0.0), 0.0), n_pix, min_dt)
    gain = unfiltered - per_pixel(scan[i])  # per pixel: how much the best scanned cut-off explains
    se = float(gain.std(ddof=1) * math.sqrt(gain.size)) if gain.size > 1 else math.inf
    if i == scan.size - 1 or not gain.sum() > 2.0 * se:
        top = float(np.exp(scan[-1]))
        est["cutoff_hz"] = Estimate(
            math.inf,
            top,
            math.inf,
            n_pix,
            f"above the scan (> {top:.4g} Hz): no low-pass seen, the log change between events is as "
            f"consistent without a filter as at the best scanned cut-off ({float(np.exp(scan[i])):.4g} Hz); "
            "the fitted config has none",
            "not identifiable",
        )
        return base.replace(cutoff_hz=0.0)
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
