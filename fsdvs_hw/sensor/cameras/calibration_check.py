"""Posterior-predictive check of a sensor calibration: does the fitted model make this recording?

A calibration (:func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor`) reads parameters off
statistics of the recording under a model of the pixel. When the model is wrong (another
simulator's conventions, a camera that does something the model does not) the fit still returns
numbers, with intervals as tight as ever. :func:`check_calibration` simulates the same video with
the fitted parameters (``n_replicates`` sensors, new seeds, the configuration's conventions),
computes the same statistics on the recording and on each replicate, and calls the model a
mismatch when a statistic of the recording lies outside the replicates' by more than its stated
tolerance (:data:`TOLERANCES`).

The statistics (:func:`recording_statistics`), each what a part of the fit rests on:

``ON events``, ``OFF events``, ``ON fraction``
    Counts of the whole recording (thresholds, mismatch, refractory period together).
``pair spread``
    Mean over moving pixels of the relative median absolute deviation of the log change between
    consecutive events of one polarity (pairs at least twice the refractory period apart), the
    comparator input rebuilt from the video with the fitted photoreceptor. The threshold fit
    assumes it is near 0: events at the crossing times, one threshold apart. Events stamped on a
    frame's time grid, or a cut-off the model does not have, raise it.
``static ON rate``, ``static OFF rate``
    Events per static pixel per second (the noise and leak fit).
``short intervals``
    The 1 % quantile of the intervals between consecutive events of a moving pixel (the
    refractory fit).

Tolerance of a statistic: ``|observed - replicate mean| <= absolute + relative · |replicate mean|
+ 4 · sqrt(replicate SD² + observed SE²)`` (SE: its counting error; SD over the replicates).

Examples
--------
>>> import torch
>>> from fsdvs_hw.sensor import SensorConfig, event_list
>>> from fsdvs_hw.sensor.cameras.calibration_fit import fit_sensor
>>> from fsdvs_hw.sensor.cameras.calibration_scene import calibration_video
>>> video, ts = calibration_video(120, 10, 12)
>>> rec = event_list(video, config=SensorConfig.ideal(0.25, threshold_sigma=0.02, seed=4), timestamps_s=ts)
>>> fit = fit_sensor(rec, video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=40)
>>> check_calibration(fit, rec, video, timestamps_s=ts).outcome
'fits'
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...errors import InputError
from ..simulation.config import CONVENTIONS, SensorConfig
from .calibration_fit import RecordingColumns, SensorCalibration, comparator_input, recording_columns

__all__ = ["TOLERANCES", "CheckRow", "ModelCheck", "check_calibration", "recording_statistics", "which_conventions"]

#: Per statistic: (absolute, relative) tolerance beyond four standard errors.
TOLERANCES: dict[str, tuple[float, float]] = {
    "ON events": (0.0, 0.10),
    "OFF events": (0.0, 0.10),
    "ON fraction": (0.02, 0.0),
    "pair spread": (0.03, 0.25),
    "static ON rate": (0.0, 0.25),
    "static OFF rate": (0.0, 0.25),
    "short intervals": (2e-6, 0.25),
}


@dataclass(frozen=True)
class CheckRow:
    """One statistic of the check.

    Attributes
    ----------
    statistic : str
        Its name (a key of :data:`TOLERANCES`).
    observed : float
        On the recording.
    expected, spread : float
        Mean and standard deviation over the replicates.
    tolerance : float
        The largest ``|observed - expected|`` that passes.
    passed : bool
        Within tolerance.
    """

    statistic: str
    observed: float
    expected: float
    spread: float
    tolerance: float
    passed: bool

    def line(self) -> str:
        """``statistic: observed vs expected ± tolerance  ok|FAILS``."""
        verdict = "ok" if self.passed else "FAILS"
        return f"{self.statistic:<16s} {self.observed:10.4g} vs {self.expected:10.4g} ± {self.tolerance:.3g}  {verdict}"


@dataclass(frozen=True)
class ModelCheck:
    """The result of :func:`check_calibration`.

    Attributes
    ----------
    rows : list of CheckRow
        One per statistic computed.
    n_replicates : int
        Simulated recordings compared with.
    conventions : str
        The simulator conventions the replicates used.
    """

    rows: list[CheckRow]
    n_replicates: int
    conventions: str

    @property
    def passed(self) -> bool:
        """Every statistic within tolerance."""
        return all(r.passed for r in self.rows)

    @property
    def failed(self) -> list[str]:
        """Names of the statistics outside tolerance."""
        return [r.statistic for r in self.rows if not r.passed]

    def lines(self) -> list[str]:
        """Printable lines: a verdict, then one per statistic."""
        head = f"model check ({self.n_replicates} replicates, conventions {self.conventions}): " + (
            "every statistic within tolerance" if self.passed else "mismatch in " + ", ".join(self.failed)
        )
        return [head, *("  " + r.line() for r in self.rows)]


def _sample(grid_t: np.ndarray, grid_L: np.ndarray, t: np.ndarray, pix: np.ndarray) -> np.ndarray:
    j = np.clip(np.searchsorted(grid_t, t, side="left") - 1, 0, grid_t.size - 2)
    t0, t1 = grid_t[j], grid_t[j + 1]
    a = np.clip((t - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
    return grid_L[j, pix] * (1 - a) + grid_L[j + 1, pix] * a


def _relative_spread(pix: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per pixel with >= 3 values: median |v - median| / |median|."""
    order = np.lexsort((v, pix))
    k, x = pix[order], v[order]
    _, start, count = np.unique(k, return_index=True, return_counts=True)
    med = 0.5 * (x[start + (count - 1) // 2] + x[start + count // 2])
    dev = np.abs(x - np.repeat(med, count))
    out = []
    for s, c, m in zip(start, count, med, strict=True):
        if c >= 3:
            out.append(float(np.median(dev[s : s + c])) / max(abs(float(m)), 1e-6))
    return np.asarray(out)


def recording_statistics(
    recording: Any, video: Any, timestamps_s: Any, config: SensorConfig
) -> dict[str, tuple[float, float]]:
    """The check's statistics of one recording under ``config``: name -> (value, standard error).

    ``recording``: an EventList, EventFile, path or checked columns; ``video``, ``timestamps_s``:
    as for :func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor`. The static-pixel rates
    are left out with under 10 static pixels, ``pair spread`` with under 3 pixels of 3 pairs.
    """
    rec = recording_columns(recording, video)
    grid_t, L = comparator_input(video, timestamps_s, config)
    c_on, c_off = float(config.threshold_on), float(config.threshold_off)
    n = len(rec)
    n_on = int((rec.p > 0).sum())
    out: dict[str, tuple[float, float]] = {
        "ON events": (float(n_on), math.sqrt(max(n_on, 1))),
        "OFF events": (float(n - n_on), math.sqrt(max(n - n_on, 1))),
        "ON fraction": (n_on / n, math.sqrt(max(n_on * (n - n_on), 1) / n**3)),
    }
    pix = rec.y * rec.width + rec.x
    order = np.lexsort((rec.t, pix))
    t, p, pix = rec.t[order], rec.p[order], pix[order]
    static = np.abs(np.diff(L, axis=0)).sum(axis=0) < 0.25 * min(c_on, c_off)
    Lv = _sample(grid_t, L, t, pix)
    same = (pix[1:] == pix[:-1]) & ~static[pix[1:]]
    dt = (t[1:] - t[:-1])[same]
    d = (Lv[1:] - Lv[:-1])[same] + float(config.leak_rate_hz) * c_on * dt
    pol, ppix = p[1:][same], pix[1:][same]
    spreads = []
    for sign in (1, -1):
        sel = (pol == sign) & (sign * d > 0) & (dt >= 2 * float(config.refractory_s))
        spreads.append(_relative_spread(ppix[sel], sign * d[sel]))
    both = np.concatenate(spreads)
    if both.size >= 3:
        out["pair spread"] = (float(both.mean()), float(both.std(ddof=1) / math.sqrt(both.size)))
    if dt.size >= 100:
        out["short intervals"] = (float(np.quantile(dt, 0.01)), 0.0)
    n_static, duration = int(static.sum()), float(grid_t[-1] - grid_t[0])
    if n_static >= 10:
        on_s = np.isin(pix, np.flatnonzero(static))
        for name, sel in (("static ON rate", on_s & (p > 0)), ("static OFF rate", on_s & (p < 0))):
            k = int(sel.sum())
            out[name] = (k / (n_static * duration), math.sqrt(max(k, 1)) / (n_static * duration))
    return out


def _replicates(
    rec: RecordingColumns, video: Any, timestamps_s: Any, config: SensorConfig, n: int, seed: int
) -> list[dict[str, tuple[float, float]]]:
    import torch

    from ..simulation.events import event_list

    vid = torch.as_tensor(np.asarray(video) if not isinstance(video, torch.Tensor) else video)
    vid = vid[None] if vid.ndim == 3 else vid
    stats = []
    for i in range(n):
        cfg = config.replace(seed=(int(seed) * 7919 + 104_729 * (i + 1) + config.seed) % 2**32)
        ev = event_list(vid, config=cfg, timestamps_s=timestamps_s)
        t = ev.t.numpy()
        if rec.resolution_s >= 1e-6:  # a file's whole microseconds, as the recording's
            t = np.round(t * 1e6) / 1e6
        cols = RecordingColumns(t, ev.x.numpy(), ev.y.numpy(), ev.p.numpy(), rec.height, rec.width, rec.resolution_s)
        if len(cols) < 2:
            raise InputError("check_calibration: the fitted model makes fewer than 2 events for this video")
        stats.append(recording_statistics(cols, video, timestamps_s, config))
    return stats


def model_check(
    rec: RecordingColumns,
    video: Any,
    timestamps_s: Any,
    config: SensorConfig,
    *,
    n_replicates: int = 3,
    seed: int = 0,
) -> ModelCheck:
    """The :class:`ModelCheck` of checked columns ``rec`` against ``config`` (see :func:`check_calibration`)."""
    if not isinstance(n_replicates, int) or isinstance(n_replicates, bool) or not 2 <= n_replicates <= 100:
        raise InputError(f"check_calibration: n_replicates must be an integer in [2, 100], got {n_replicates!r}")
    observed = recording_statistics(rec, video, timestamps_s, config)
    reps = _replicates(rec, video, timestamps_s, config, n_replicates, seed)
    rows = []
    for name, (value, se) in observed.items():
        sims = np.array([r[name][0] for r in reps if name in r])
        if sims.size < 2:
            continue
        mean, sd = float(sims.mean()), float(sims.std(ddof=1))
        absolute, relative = TOLERANCES[name]
        tol = absolute + relative * abs(mean) + 4.0 * math.sqrt(sd**2 + se**2)
        rows.append(CheckRow(name, value, mean, sd, tol, bool(abs(value - mean) <= tol)))
    return ModelCheck(rows, n_replicates, config.conventions)


def check_calibration(
    calibration: SensorCalibration,
    recording: Any,
    video: Any,
    *,
    timestamps_s: Any = None,
    n_replicates: int = 3,
    seed: int = 0,
) -> SensorCalibration:
    """The calibration with its posterior-predictive check: ``check`` set and ``outcome``
    ``"fits"`` or ``"model mismatch"`` (a note names the failing statistics).

    Parameters
    ----------
    calibration : SensorCalibration
        A fit of ``recording`` to ``video`` (its ``config`` is simulated, with its conventions).
    recording : EventList, EventFile, path or RecordingColumns
        The recording that was fitted.
    video, timestamps_s
        As given to :func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor`.
    n_replicates : int
        Simulated recordings (new seeds) to compare with (default 3, at least 2).
    seed : int
        Seed of the replicates.
    """
    rec = recording_columns(recording, video)
    mc = model_check(rec, video, timestamps_s, calibration.config, n_replicates=n_replicates, seed=seed)
    notes = list(calibration.notes)
    if not mc.passed:
        notes.append(
            "model mismatch: " + ", ".join(mc.failed) + " of the recording lie outside what the fitted model "
            "makes: the estimates and intervals assume a model that does not describe this recording "
            "(try which_conventions, or another configuration)"
        )
    return replace(calibration, check=mc, outcome="fits" if mc.passed else "model mismatch", notes=notes)


def which_conventions(
    calibration: SensorCalibration, recording: Any, video: Any, *, timestamps_s: Any = None, seed: int = 0
) -> dict[str, ModelCheck]:
    """The model check of ``calibration``'s parameters under each of the simulator's named
    conventions (:data:`~fsdvs_hw.sensor.simulation.config.CONVENTIONS`).

    At the parameters a recording was made with, the check passes under its conventions and
    fails under the others (a v2e recording, measured in ``docs/measured.md``). The fit itself
    assumes the native conventions: on a recording that follows others its parameters are
    biased, and then every convention may fail; the native one failing is the finding.
    """
    rec = recording_columns(recording, video)
    return {
        c: model_check(rec, video, timestamps_s, calibration.config.replace(conventions=c), seed=seed)
        for c in CONVENTIONS
    }
