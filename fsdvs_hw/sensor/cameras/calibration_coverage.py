"""The calibration of the calibration: how often its intervals cover the truth.

:func:`calibration_coverage` simulates one recording per seed with known parameters, calibrates
each with :func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor` (with the options given,
e.g. ``error_recordings`` for intervals that include the estimator's own error,
:mod:`fsdvs_hw.sensor.cameras.estimator_error`), and counts per parameter the intervals that
contain the true value, with the Wilson interval [1]_ of that share, and the outcomes.

References
----------
.. [1] E. B. Wilson, "Probable inference, the law of succession, and statistical inference",
   JASA 22, 1927 (the interval of a coverage proportion).

Examples
--------
>>> from fsdvs_hw.sensor import SensorConfig
>>> from fsdvs_hw.sensor.cameras.calibration_scene import calibration_video
>>> video, ts = calibration_video(100, 8, 10)
>>> truth = SensorConfig.ideal(0.25, threshold_sigma=0.02)
>>> cov = calibration_coverage(truth, video, timestamps_s=ts, seeds=range(3), n_boot=30, check=False)
>>> cov.n, cov.counted["threshold_on"]
(3, 3)
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from ...errors import InputError
from ..simulation.config import SensorConfig
from .calibrate import CALIBRATED_FIELDS, Estimate, calibrate_sensor
from .estimator_error import simulate_recording

__all__ = ["CoverageResult", "calibration_coverage"]


@dataclass(frozen=True)
class CoverageResult:
    """The result of :func:`calibration_coverage`.

    Attributes
    ----------
    n : int
        Recordings calibrated.
    covered : dict of str to int
        Per parameter: how many intervals contained the true value.
    counted : dict of str to int
        Per parameter: how many recordings gave it an interval.
    outcomes : dict of str to int
        How many calibrations ended in each outcome.
    level : float
        The intervals' nominal level.
    """

    n: int
    covered: dict[str, int]
    counted: dict[str, int]
    outcomes: dict[str, int] = field(default_factory=dict)
    level: float = 0.95

    def coverage(self, name: str, confidence: float = 0.95) -> tuple[float, float, float]:
        """``(share, low, high)``: the share of intervals covering ``name``'s truth and its Wilson interval [2]_."""
        from scipy.stats import binomtest

        k, n = self.covered[name], self.counted[name]
        ci = binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
        return k / n, float(ci.low), float(ci.high)

    def lines(self) -> list[str]:
        """One printable line per parameter."""
        out = []
        for k in self.covered:
            share, lo, hi = self.coverage(k)
            out.append(
                f"{k:<20s} {self.covered[k]:3d}/{self.counted[k]:<3d} covered = {share:.0%} [{lo:.0%}, {hi:.0%}]"
            )
        return out


def calibration_coverage(
    truth: SensorConfig,
    video: Any,
    *,
    timestamps_s: Any = None,
    seeds: Iterable[int] = range(20),
    base: SensorConfig | None = None,
    **calibrate_options: Any,
) -> CoverageResult:
    """Calibrate one recording per seed of ``truth`` (its ``seed`` replaced) and count the
    intervals that contain the true values (``truth``'s fields: the population parameters).

    ``base``: the configuration handed to the calibration (default ``truth`` with its fitted
    fields at their defaults, i.e. ``SensorConfig.ideal(0.2)`` with ``truth``'s non-fitted
    fields); ``calibrate_options``: passed to
    :func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor` (``error_recordings``, ``n_boot``...).
    """
    start = base if base is not None else truth.replace(
        threshold_on=0.2, threshold_off=0.2, threshold_sigma=0.0, refractory_s=0.0, leak_rate_hz=0.0,
        shot_noise_rate_hz=0.0,
    )  # fmt: skip
    covered: dict[str, int] = {}
    counted: dict[str, int] = {}
    outcomes: dict[str, int] = {}
    n = 0
    for s in seeds:
        rec = simulate_recording(video, timestamps_s, truth.replace(seed=int(s)))
        cal = calibrate_sensor(rec, video, timestamps_s=timestamps_s, config=start, seed=int(s), **calibrate_options)
        n += 1
        outcomes[cal.outcome] = outcomes.get(cal.outcome, 0) + 1
        for k in CALIBRATED_FIELDS:
            e: Estimate | None = cal.estimates.get(k)
            if e is None or e.status == "not identifiable":
                continue
            counted[k] = counted.get(k, 0) + 1
            covered[k] = covered.get(k, 0) + int(e.contains(float(getattr(truth, k))))
    if n == 0:
        raise InputError("calibration_coverage: no seeds given")
    return CoverageResult(n, covered, counted, outcomes, float(calibrate_options.get("level", 0.95)))
