"""The estimator's own error, by simulation at the fitted parameters (a parametric bootstrap [1]_).

:func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor`'s pixel bootstrap measures how much
the estimates move from one population of pixels to the next; it does not see the estimator's
own bias (a leak count cut by the recording's length, a refractory period read off a few close
pairs, threshold pairs that lost a crossing) nor the spread a new sensor of the same parameters
would give. Both are measured here:

:func:`estimator_error`
    Simulate ``n_recordings`` recordings of the same video with the fitted configuration (new
    seeds: new mismatch, noise and leak draws), fit each the same way, and report per parameter
    the bias (mean estimate minus the value simulated) and the spread (SD).
:func:`with_estimator_error`
    Fold them into the intervals: each becomes the hull of the pixel-bootstrap interval, that
    interval less the bias, and ``value - bias ± t · spread`` (Student t quantile for
    ``n - 1`` degrees of freedom at the calibration's level), clipped at 0.

How often the resulting intervals cover the truth is measured by
:func:`~fsdvs_hw.sensor.cameras.calibration_coverage.calibration_coverage`.

References
----------
.. [1] B. Efron, R. Tibshirani, "An Introduction to the Bootstrap", Chapman & Hall, 1993, ch. 6
   and 10 (parametric bootstrap; bias estimation).

Examples
--------
>>> from fsdvs_hw.sensor import SensorConfig, event_list
>>> from fsdvs_hw.sensor.cameras.calibration_fit import fit_sensor
>>> from fsdvs_hw.sensor.cameras.calibration_scene import calibration_video
>>> video, ts = calibration_video(80, 8, 10)
>>> rec = event_list(video, config=SensorConfig.ideal(0.25, threshold_sigma=0.02), timestamps_s=ts)
>>> fit = fit_sensor(rec, video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=30)
>>> wide = with_estimator_error(fit, video, timestamps_s=ts, n_recordings=3, n_boot=30)
>>> e0, e1 = fit.estimates["threshold_on"], wide.estimates["threshold_on"]
>>> e1.low <= e0.low and e1.high >= e0.high, wide.estimator_error["n_recordings"]
(True, 3)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...errors import InputError
from ..simulation.config import SensorConfig
from .calibration_fit import SensorCalibration, fit_sensor

__all__ = ["ParameterError", "estimator_error", "simulate_recording", "with_estimator_error"]


@dataclass(frozen=True)
class ParameterError:
    """The estimator's error for one parameter, over recordings simulated at a known value.

    Attributes
    ----------
    truth : float
        The value simulated.
    bias, spread : float
        Mean estimate minus ``truth``; standard deviation of the estimates (ddof 1).
    n : int
        Recordings calibrated.
    """

    truth: float
    bias: float
    spread: float
    n: int


def simulate_recording(video: Any, timestamps_s: Any, config: SensorConfig) -> Any:
    """The event list of ``video`` ((T, H, W) or (1, T, H, W)) under ``config``."""
    import torch

    from ..simulation.events import event_list

    vid = torch.as_tensor(np.asarray(video) if not isinstance(video, torch.Tensor) else video)
    return event_list(vid[None] if vid.ndim == 3 else vid, config=config, timestamps_s=timestamps_s)


def estimator_error(
    calibration: SensorCalibration,
    video: Any,
    *,
    timestamps_s: Any = None,
    n_recordings: int = 8,
    seed: int = 0,
    **fit_options: Any,
) -> dict[str, ParameterError]:
    """Bias and spread of each estimate of ``calibration`` over ``n_recordings`` recordings
    simulated with its fitted ``config`` (see the module docstring).

    ``fit_options``: ``fit_cutoff``, ``n_boot``, ``min_events`` as given to the calibration.
    Parameters not identifiable in ``calibration`` are left out.
    """
    if not isinstance(n_recordings, int) or isinstance(n_recordings, bool) or not 2 <= n_recordings <= 1000:
        raise InputError(f"estimator_error: n_recordings must be an integer in [2, 1000], got {n_recordings!r}")
    cfg = calibration.config
    names = [k for k, e in calibration.estimates.items() if e.status != "not identifiable"]
    values: dict[str, list[float]] = {k: [] for k in names}
    for i in range(n_recordings):
        sim = cfg.replace(seed=(int(seed) * 104_729 + 7_919 * (i + 1) + 17) % 2**32)
        rec = simulate_recording(video, timestamps_s, sim)
        try:
            cal = fit_sensor(rec, video, timestamps_s=timestamps_s, config=cfg, seed=seed + i, **fit_options)
        except InputError:
            continue  # a draw too poor to fit counts as no estimate (reported through n)
        for k in names:
            if k in cal.estimates and math.isfinite(cal.estimates[k].value):
                values[k].append(cal.estimates[k].value)
    out = {}
    for k, v in values.items():
        if len(v) >= 2:
            truth = float(getattr(cfg, k))
            out[k] = ParameterError(truth, float(np.mean(v)) - truth, float(np.std(v, ddof=1)), len(v))
    return out


def with_estimator_error(
    calibration: SensorCalibration,
    video: Any,
    *,
    timestamps_s: Any = None,
    n_recordings: int = 8,
    seed: int = 0,
    **fit_options: Any,
) -> SensorCalibration:
    """``calibration`` with :func:`estimator_error` folded into every interval (module docstring);
    ``estimator_error`` records it."""
    from scipy.stats import t as student_t

    errors = estimator_error(
        calibration, video, timestamps_s=timestamps_s, n_recordings=n_recordings, seed=seed, **fit_options
    )
    est = dict(calibration.estimates)
    for k, err in errors.items():
        e = est[k]
        q = float(student_t.ppf(0.5 + calibration.level / 2, err.n - 1))
        centre = e.value - err.bias
        low = max(min(e.low, e.low - err.bias, centre - q * err.spread), 0.0)
        high = max(e.high, e.high - err.bias, centre + q * err.spread)
        est[k] = replace(
            e,
            low=low,
            high=high,
            method=e.method + f"; widened by the estimator's error over {err.n} simulated recordings "
            f"(bias {err.bias:.3g}, spread {err.spread:.3g})",
        )
    record = {"n_recordings": n_recordings, "parameters": errors}
    return replace(calibration, estimates=est, estimator_error=record)
