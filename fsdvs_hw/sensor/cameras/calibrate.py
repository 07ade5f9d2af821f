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
    ``leak = r_on - r_off``. No steady state is assumed: the reference's start phase (at the
    first frame, at random, after a noise reset) moves each pixel's leak count by up to one event,
    so that interval is widened by ``1 / duration`` either side, and a recording that holds
    fewer than two leak periods only *bounds* the leak (``Estimate.status == "bounded"``).
    *Leak drift in the moving pixels*: the reference drifts down by ``λ = leak · C_on`` per
    second, so a pair one threshold apart spans ``pol · d = C - pol · λ · dt``; ``λ`` is the
    least-squares slope of ``pol · d`` on ``-pol · dt``, centred per pixel and polarity, over
    pairs within 10 % of one threshold. It needs no steady state and no leak event; the
    thresholds are fitted with that drift undone (an unknown leak otherwise reads OFF high and ON
    low by ``λ`` times the pairs' typical interval). It is a note, not the leak's estimate: ``λ
    dt`` is about 1e-5 log units at 0.01 Hz, the size of a photoreceptor model's error (a 30 Hz
    low-pass read a 0.1 Hz leak as 0.105 [0.102, 0.107]).
    *Bandwidth*: when no scanned cut-off explains the data better than no filter at all (per-pixel
    gain within two standard errors of 0) or the best is the scan's top, the cut-off is "not
    identifiable" (above the scan; ``value`` inf, the fitted config has no filter).

    Intervals are percentile bootstraps over pixels (``n_boot`` resamples): the population of
    pixels is what varies from one sensor (or one patch) to the next. With ``error_recordings``
    they also include the estimator's own bias and spread, measured on recordings simulated at
    the fit (:mod:`fsdvs_hw.sensor.cameras.estimator_error`).

What calibration assumes, and what it checks
    The recording is of this video, registered pixel for pixel, on the video's clock; the
    pixel follows the simulator's model under ``config.conventions`` (native: each event at its
    crossing time, crossings inside the refractory period lost, noise that leaves the reference
    alone); the signal is linear between the (sub-)frames. Checked on every input, in every form
    (an object or a path): the geometry against the video's, finite event times, events within
    the video's time span, at least 2 events and enough pairs in the moving pixels (told apart
    from a video that moves too little). A frame rate too low for the thresholds (more than half the
    pairs of consecutive events of a pixel inside one frame interval) adds a warning with the
    upsampling advice. After the fit, a posterior-predictive check
    (:mod:`fsdvs_hw.sensor.cameras.calibration_check`) simulates the video with the fitted
    parameters and compares the statistics the fit used: ``outcome`` is ``"fits"`` or ``"model
    mismatch"`` (the failing statistic named) instead of a precise wrong answer.

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

from typing import Any

from ...errors import InputError
from ..simulation.config import SensorConfig
from .calibration_check import check_calibration
from .calibration_fit import (
    CALIBRATED_FIELDS,
    ESTIMATE_STATUSES,
    OUTCOMES,
    Estimate,
    RecordingColumns,
    SensorCalibration,
    comparator_input,
    fit_sensor,
    recording_columns,
)
from .estimator_error import with_estimator_error

__all__ = [
    "CALIBRATED_FIELDS",
    "ESTIMATE_STATUSES",
    "OUTCOMES",
    "Estimate",
    "RecordingColumns",
    "SensorCalibration",
    "calibrate_sensor",
    "comparator_input",
    "recording_columns",
]


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
    check: bool = True,
    error_recordings: int = 0,
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
        Seed of the bootstrap (and of the model check's and estimator-error simulations).
    check : bool
        Run the posterior-predictive model check (default True): simulate the video with the
        fitted parameters and compare the statistics the fit used
        (:func:`~fsdvs_hw.sensor.cameras.calibration_check.check_calibration`); sets ``outcome``
        to ``"fits"`` or ``"model mismatch"``.
    error_recordings : int
        Recordings to simulate at the fitted parameters and calibrate again, to fold the
        estimator's own bias and spread into the intervals (default 0: pixel bootstrap only;
        :func:`~fsdvs_hw.sensor.cameras.calibration_coverage.with_estimator_error`).

    Returns
    -------
    SensorCalibration

    Raises
    ------
    InputError
        A recording that does not fit the video (geometry, in the form given: object or path;
        events outside the video's time span), non-finite event times, too few events (0, 1, or
        too few pairs in moving pixels, told apart from a video that moves too little), bad options.
    """
    for name, flag in (("check", check), ("fit_cutoff", fit_cutoff)):
        if not isinstance(flag, bool):
            raise InputError(f"calibrate_sensor: {name} must be True or False, got {flag!r}")
    if not isinstance(error_recordings, int) or isinstance(error_recordings, bool) or not 0 <= error_recordings <= 1000:
        raise InputError(
            f"calibrate_sensor: error_recordings must be an integer in [0, 1000], got {error_recordings!r}"
        )
    options: dict[str, Any] = dict(fit_cutoff=fit_cutoff, n_boot=n_boot, min_events=min_events)
    if video is None:
        return fit_sensor(recording, None, config=config, duration_s=duration_s, level=level, seed=seed, **options)
    rec = recording_columns(recording, video)
    cal = fit_sensor(rec, video, timestamps_s=timestamps_s, config=config, level=level, seed=seed, **options)
    if error_recordings:
        cal = with_estimator_error(
            cal, video, timestamps_s=timestamps_s, n_recordings=error_recordings, seed=seed, **options
        )
    if check:
        cal = check_calibration(cal, rec, video, timestamps_s=timestamps_s, seed=seed)
    return cal
