"""Bandwidth-matched comparison: a kernel's task metric at another kernel's event rate.

A learned kernel fires several times more events than a plain DVS (the w/o, 1×1 delta kernel) at
the same contrast threshold, so a raw accuracy gain mixes the filter's effect with that of a
lowered threshold. This module measures each kernel's **rate curve** — event rate and task metric
as the ON/OFF contrast threshold is swept — in the fixed shipped networks (phase 1, the
fixed-network protocol: every kernel swapped zero-shot into the same trained networks), and
compares kernels **at equal event rate** by interpolating one curve at the other's rate.

:func:`rate_curve`
    For each threshold (ON and OFF set together) the kernel is scored by
    :func:`fsdvs_hw.explore.paired.clip_evidence` in every network with the same paired clips,
    noise draws and mismatch patterns as the exploration (network ``s``: clip set ``s``, sensor
    seed + ``s``), and each clip's event rate (events/pixel/s) is kept with its per-clip metric.
:func:`matched_rate_difference`
    ``metric(reference at its threshold) − metric(curve at the reference's event rate)``,
    interpolated in log rate along the curve (rate falls monotonically with threshold; linear by
    default, ``interpolation="pchip"`` or ``"quadratic"`` to measure how much the answer depends
    on that choice, :data:`INTERPOLATIONS`), with a percentile bootstrap CI over networks × clips
    that carries the uncertainty of both axes: one resample of (network, clips) clusters re-weights every point of both kernels, both
    rates and metrics are recomputed and the curve is re-interpolated at the resampled reference
    rate. A reference rate outside the curve's measured range is refused (``status``), never
    extrapolated.

Caveat of the protocol: the shipped networks were trained with the learned kernel, so every other
kernel (w/o included) is scored zero-shot in networks tuned to the learned kernel's events; the
retrained-network protocol (a network per kernel and threshold) is what removes that bias.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..fingerprints import fingerprint, text_fingerprint
from ..kernels import Kernel
from ..paths import Confinement, write_output
from ..progress import progress_bar
from ..stats import ClipMetric
from .paired import EVENT_RATE_UNIT, bootstrap_weights, clip_evidence, decode_evidence, encode_evidence, weighted_rate
from .scoring import DESIGN_SENSOR_FIELDS, task_sensor

__all__ = [
    "DEFAULT_THRESHOLDS",
    "EVENT_RATE_UNIT",
    "INTERPOLATIONS",
    "THRESHOLD_RANGE",
    "MatchedRateDifference",
    "RateCurve",
    "RatePoint",
    "dataset_rate_curve",
    "interpolate_log_rate",
    "matched_rate_difference",
    "rate_curve",
]

#: Contrast thresholds (log units, ON = OFF) of a default rate curve: from where noise dominates up.
DEFAULT_THRESHOLDS: tuple[float, ...] = (0.05, 0.07, 0.1, 0.125, 0.15, 0.2, 0.3, 0.4, 0.6)

#: Allowed contrast thresholds (log units), as the design's ``sensor.threshold_on``.
THRESHOLD_RANGE: tuple[float, float] = (1e-4, 10.0)

#: How :func:`interpolate_log_rate` reads a curve between its points (x = ln rate):
#: ``"linear"`` (straight lines between the two bracketing points, ``np.interp``; the default),
#: ``"pchip"`` (``scipy.interpolate.PchipInterpolator``: piecewise cubic, monotone between points
#: where the data are, never overshooting a local extremum) and ``"quadratic"`` (the parabola
#: through the two bracketing points and the nearer of their outer neighbours, 3-point Lagrange;
#: needs 3 points).
INTERPOLATIONS: tuple[str, ...] = ("linear", "pchip", "quadratic")


@dataclass(frozen=True)
class RatePoint:
    """One kernel at one contrast threshold, in every network: per-clip metric and event rates.

    Attributes
    ----------
    threshold : float
        ON and OFF contrast threshold (log units).
    metrics : tuple of ClipMetric
        One per network (its per-clip task metric, :mod:`fsdvs_hw.stats`).
    clip_rates : ndarray (n_networks, n_clips)
        Events per pixel per second of each clip (ON + OFF).
    test_seeds, sensor_seeds : tuple of int
        The clips and the noise / mismatch draws of each network (the pairing).
    seconds : float
        Wall time of the evaluations (s).
    """

    threshold: float
    metrics: tuple[ClipMetric, ...]
    clip_rates: np.ndarray = field(repr=False)
    test_seeds: tuple[int, ...] = ()
    sensor_seeds: tuple[int, ...] = ()
    seconds: float = math.nan

    @property
    def metric(self) -> float:
        """Mean over the networks of the metric on all their clips (fraction)."""
        return float(np.mean([m.weighted(np.ones((1, m.n_clips)))[0] for m in self.metrics]))

    @property
    def rate(self) -> float:
        """Mean event rate over networks and clips (events/pixel/s)."""
        return float(np.mean(self.clip_rates))

    def to_dict(self) -> dict[str, Any]:
        """JSON form (per-clip metrics as base64 ``.npz``, :func:`~fsdvs_hw.explore.paired.encode_evidence`)."""
        return {
            "threshold": self.threshold,
            "metric": self.metric,
            "rate": self.rate,
            "evidence": [encode_evidence(m) for m in self.metrics],
            "clip_rates": np.asarray(self.clip_rates).tolist(),
            "test_seeds": list(self.test_seeds),
            "sensor_seeds": list(self.sensor_seeds),
            "seconds": self.seconds,
        }

    @classmethod
    def from_evidence(cls, threshold: float, evidence: Sequence[Any]) -> RatePoint:
        """The point of one threshold from each network's scores there.

        Parameters
        ----------
        threshold : float
            ON = OFF contrast threshold (log units).
        evidence : sequence of ClipEvidence
            One per network (:func:`fsdvs_hw.explore.paired.clip_evidence`), with per-clip event rates.

        Returns
        -------
        RatePoint
            ``seconds`` is the evaluations' summed wall time (s).
        """
        return cls(
            threshold=threshold,
            metrics=tuple(e.metric for e in evidence),
            clip_rates=np.stack([np.asarray(e.clip_event_rates, dtype=np.float64) for e in evidence]),
            test_seeds=tuple(e.test_seed for e in evidence),
            sensor_seeds=tuple(e.sensor_seed for e in evidence),
            seconds=float(sum(e.seconds for e in evidence)),
        )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RatePoint:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                threshold=float(data["threshold"]),
                metrics=tuple(decode_evidence(t) for t in data["evidence"]),
                clip_rates=np.asarray(data["clip_rates"], dtype=np.float64),
                test_seeds=tuple(int(s) for s in data["test_seeds"]),
                sensor_seeds=tuple(int(s) for s in data["sensor_seeds"]),
                seconds=float(data.get("seconds", math.nan)),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"RatePoint.from_dict: not a stored rate point ({exc!r})") from None


@dataclass(frozen=True)
class RateCurve:
    """One kernel's event rate and task metric versus contrast threshold, in fixed networks.

    Attributes
    ----------
    kernel_name, task, metric_name : str
    test_clips : {"per_network", "shared"}
        How the networks' clips were drawn (:func:`fsdvs_hw.explore.paired.bootstrap_weights`).
    points : tuple of RatePoint
        In increasing threshold.
    checkpoints : tuple of str
        The networks (file names), in order.
    """

    kernel_name: str
    task: str
    metric_name: str
    test_clips: str
    points: tuple[RatePoint, ...]
    checkpoints: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.points:
            raise InputError("RateCurve: no points")
        object.__setattr__(self, "points", tuple(sorted(self.points, key=lambda p: p.threshold)))
        shapes = {np.shape(p.clip_rates) for p in self.points}
        if len(shapes) != 1 or len(next(iter(shapes))) != 2:
            raise InputError(
                f"RateCurve {self.kernel_name!r}: every point needs the same (networks, clips) "
                f"per-clip rates; got shapes {sorted(shapes)}"
            )

    @property
    def thresholds(self) -> tuple[float, ...]:
        return tuple(p.threshold for p in self.points)

    @property
    def n_networks(self) -> int:
        return int(np.shape(self.points[0].clip_rates)[0])

    @property
    def n_clips_per_network(self) -> int:
        return int(np.shape(self.points[0].clip_rates)[1])

    @property
    def n_clips(self) -> int:
        """Distinct test clips (over the networks when clips are nested in them)."""
        n = self.n_clips_per_network
        return n * self.n_networks if self.test_clips == "per_network" else n

    def point(self, threshold: float) -> RatePoint:
        """The point at ``threshold`` (to 1e-12)."""
        for p in self.points:
            if abs(p.threshold - threshold) <= 1e-12:
                return p
        raise InputError(
            f"rate curve of {self.kernel_name!r}: no point at threshold {threshold!r}; allowed: {list(self.thresholds)}"
        )

    def summary(
        self,
        *,
        confidence: float = 0.95,
        n_resamples: int = 2000,
        rng: Any = 0,
        resolution_px: tuple[int, int] = (720, 1280),
    ) -> list[dict[str, Any]]:
        """One row per threshold: event rate and metric with percentile bootstrap CIs.

        Parameters
        ----------
        confidence : float
            Two-sided level in (0, 1).
        n_resamples : int
            Bootstrap resamples over networks × clips.
        rng : int or numpy Generator
        resolution_px : (int, int)
            Sensor size (H, W) for the event bandwidth in Mev/s (rate × H × W / 10⁶).

        Returns
        -------
        list of dict
            ``threshold``, ``rate``/``rate_low``/``rate_high`` (events/pixel/s),
            ``mev_s``/``mev_s_low``/``mev_s_high`` (Mev/s at ``resolution_px``), ``metric``/
            ``metric_low``/``metric_high`` (fraction), ``n_clips``, ``n_networks``.
        """
        _check_confidence(confidence)
        ws, wc = self._weights(n_resamples, rng)
        alpha = (1.0 - confidence) / 2.0
        px = int(resolution_px[0]) * int(resolution_px[1])
        rows = []
        for p in self.points:
            m, r = _point_values(p, ws, wc)
            rlo, rhi = np.quantile(r, [alpha, 1 - alpha])
            mlo, mhi = np.quantile(m, [alpha, 1 - alpha])
            rows.append(
                {
                    "kernel": self.kernel_name,
                    "task": self.task,
                    "threshold": p.threshold,
                    "rate": p.rate,
                    "rate_low": float(rlo),
                    "rate_high": float(rhi),
                    "rate_unit": EVENT_RATE_UNIT,
                    "mev_s": p.rate * px / 1e6,
                    "mev_s_low": float(rlo) * px / 1e6,
                    "mev_s_high": float(rhi) * px / 1e6,
                    "metric_name": self.metric_name,
                    "metric": p.metric,
                    "metric_low": float(mlo),
                    "metric_high": float(mhi),
                    "confidence": confidence,
                    "n_clips": self.n_clips,
                    "n_networks": self.n_networks,
                }
            )
        return rows

    def _weights(self, n_resamples: int, rng: Any) -> tuple[np.ndarray, np.ndarray | None]:
        return bootstrap_weights(
            self.n_networks, self.n_clips_per_network, test_clips=self.test_clips, n_resamples=n_resamples, rng=rng
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "kernel": self.kernel_name,
            "task": self.task,
            "metric_name": self.metric_name,
            "test_clips": self.test_clips,
            "checkpoints": list(self.checkpoints),
            "points": [p.to_dict() for p in self.points],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RateCurve:
        return cls(
            kernel_name=str(data["kernel"]),
            task=str(data["task"]),
            metric_name=str(data["metric_name"]),
            test_clips=str(data["test_clips"]),
            points=tuple(RatePoint.from_dict(p) for p in data["points"]),
            checkpoints=tuple(data.get("checkpoints", ())),
        )


def _check_confidence(confidence: float) -> None:
    if isinstance(confidence, bool) or not isinstance(confidence, (int, float)) or not 0.0 < confidence < 1.0:
        raise InputError(f"confidence={confidence!r}; allowed: a number in (0, 1)")


def _point_values(point: RatePoint, ws: np.ndarray, wc: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(metric (B,), rate (B,)) of one point under bootstrap weights."""
    b = ws.shape[0]
    per_net = np.stack(
        [np.full(b, m.weighted(np.ones((1, m.n_clips)))[0]) if wc is None else m.weighted(wc) for m in point.metrics],
        axis=1,
    )  # (B, S)
    metric = (ws * per_net).sum(axis=1) / ws.sum(axis=1)
    return metric, weighted_rate(point.clip_rates, ws, wc)


def _check_interpolation(interpolation: str) -> None:
    if interpolation not in INTERPOLATIONS:
        raise InputError(f"interpolation={interpolation!r}; allowed: {', '.join(INTERPOLATIONS)}")


def _quadratic_at(x: np.ndarray, y: np.ndarray, t: float) -> float:
    """The 3-point Lagrange parabola at ``t``: bracketing pair of sorted ``x`` plus the nearer outer point."""
    j = int(np.clip(np.searchsorted(x, t, side="right") - 1, 0, x.size - 2))  # x[j] <= t <= x[j + 1]
    if j == 0:
        idx = (0, 1, 2)
    elif j + 2 >= x.size:
        idx = (j - 1, j, j + 1)
    else:
        idx = (j - 1, j, j + 1) if t - x[j - 1] <= x[j + 2] - t else (j, j + 1, j + 2)
    xs, ys = x[list(idx)], y[list(idx)]
    total = 0.0
    for i in range(3):
        others = [k for k in range(3) if k != i]
        total += ys[i] * np.prod([(t - xs[k]) / (xs[i] - xs[k]) for k in others])
    return float(total)


def interpolate_log_rate(
    rates: Sequence[float] | np.ndarray,
    metrics: Sequence[float] | np.ndarray,
    target_rate: float,
    *,
    interpolation: str = "linear",
) -> float:
    """A curve's metric at ``target_rate``, interpolated in log rate (never extrapolated).

    Parameters
    ----------
    rates : sequence of float
        The curve's event rates (events/pixel/s, > 0), strictly monotone along the curve.
    metrics : sequence of float
        Its metric at each rate.
    target_rate : float
        Where to read it (events/pixel/s).
    interpolation : {"linear", "pchip", "quadratic"}
        In x = ln(rate): straight lines between the two nearest points (``np.interp``; default),
        the monotone piecewise cubic ``scipy.interpolate.PchipInterpolator``, or the parabola
        through the bracketing pair and the nearer outer neighbour (needs ≥ 3 points). All three
        pass through every measured point; they differ between points, most across a peak.

    Returns
    -------
    float
        NaN where ``target_rate`` lies outside ``[min(rates), max(rates)]`` (never extrapolated).

    Raises
    ------
    InputError
        Fewer than 2 points (3 for ``"quadratic"``), rates ≤ 0, rates not strictly monotone,
        unequal lengths, an unknown ``interpolation``.

    Examples
    --------
    A metric quadratic in ln(rate) is reproduced exactly by ``"quadratic"``; ``"linear"`` reads the chord:

    >>> import math
    >>> rates = [1.0, math.e, math.e**2]
    >>> metrics = [0.0, 1.0, 0.0]  # 1 - (ln r - 1)**2
    >>> round(interpolate_log_rate(rates, metrics, math.e**1.5, interpolation="quadratic"), 12)
    0.75
    >>> round(interpolate_log_rate(rates, metrics, math.e**1.5), 12)
    0.5
    """
    _check_interpolation(interpolation)
    r = np.asarray(rates, dtype=np.float64)
    m = np.asarray(metrics, dtype=np.float64)
    if r.ndim != 1 or r.shape != m.shape or r.size < 2:
        raise InputError(
            f"interpolate_log_rate: rates and metrics must be 1-D of equal length >= 2; "
            f"got shapes {r.shape} and {m.shape}"
        )
    if interpolation == "quadratic" and r.size < 3:
        raise InputError(
            f"interpolate_log_rate: interpolation='quadratic' needs >= 3 points; got {r.size}; "
            "allowed: 'linear' or 'pchip' for 2 points"
        )
    if not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise InputError(f"interpolate_log_rate: rates must be finite and > 0 events/pixel/s; got {r.tolist()}")
    d = np.diff(r)
    if not (np.all(d > 0) or np.all(d < 0)):
        raise InputError(f"interpolate_log_rate: rates must be strictly monotone along the curve; got {r.tolist()}")
    order = np.argsort(r)
    x, y = np.log(r[order]), m[order]
    t = math.log(target_rate) if target_rate > 0 else -math.inf
    if not x[0] <= t <= x[-1]:
        return math.nan
    if interpolation == "pchip":
        from scipy.interpolate import PchipInterpolator

        return float(PchipInterpolator(x, y, extrapolate=False)(t))
    if interpolation == "quadratic":
        return _quadratic_at(x, y, t)
    return float(np.interp(t, x, y))


@dataclass(frozen=True)
class MatchedRateDifference:
    """``metric(reference) − metric(curve at the reference's event rate)``, with its CI.

    Attributes
    ----------
    status : str
        ``"ok"``, or ``"refused: …"`` (reference rate outside the curve, a non-monotone curve, too
        many resamples outside the curve for a CI) — then the refused numbers are NaN.
    estimate, low, high : float
        The matched-rate difference and its percentile CI (metric units, fraction).
    raw_estimate, raw_low, raw_high : float
        The same-threshold difference ``metric(reference) − metric(curve)`` at the reference's
        threshold, from the same resamples (NaN if the curve has no point there).
    reference_rate, reference_rate_low, reference_rate_high : float
        The reference's event rate and CI (events/pixel/s).
    matched_threshold : float
        The curve's threshold at the reference rate (interpolated in log rate; log units).
    curve_rate_range : (float, float)
        The curve's measured rates (events/pixel/s).
    inside_range : bool
        Whether the reference rate lies inside ``curve_rate_range``.
    fraction_outside : float
        Fraction of bootstrap resamples whose reference rate fell outside the resampled curve
        (dropped from the CI; above ``(1 − confidence)/2`` the CI is refused).
    n_clips, n_networks : int
    confidence : float
    curve_kernel, reference_kernel, metric_name, task : str
    reference_threshold : float
    interpolation : str
        How the curve was read between its points (:data:`INTERPOLATIONS`), the same in the
        estimate, the matched threshold and every resample.
    """

    status: str
    estimate: float
    low: float
    high: float
    raw_estimate: float
    raw_low: float
    raw_high: float
    reference_rate: float
    reference_rate_low: float
    reference_rate_high: float
    matched_threshold: float
    curve_rate_range: tuple[float, float]
    inside_range: bool
    fraction_outside: float
    n_clips: int
    n_networks: int
    confidence: float
    curve_kernel: str
    reference_kernel: str
    reference_threshold: float
    metric_name: str
    task: str
    interpolation: str = "linear"

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict[str, Any]:
        out = dict(self.__dict__)
        out["curve_rate_range"] = list(self.curve_rate_range)
        out["rate_unit"] = EVENT_RATE_UNIT
        return out

    def describe(self, digits: int = 3) -> str:
        """One line: the difference with its CI, or why there is none."""
        head = (
            f"{self.task}: {self.reference_kernel} @ threshold {self.reference_threshold:g} "
            f"({self.reference_rate:.3g} {EVENT_RATE_UNIT}) minus {self.curve_kernel} at that rate"
        )
        if self.interpolation != "linear":
            head += f" ({self.interpolation} interpolation)"
        if not self.ok:
            return f"{head}: {self.status}"
        return (
            f"{head} (threshold {self.matched_threshold:.3g}): {self.estimate:+.{digits}f} {self.metric_name} "
            f"[{self.low:+.{digits}f}, {self.high:+.{digits}f}] ({self.confidence:.0%} CI, n={self.n_clips} clips, "
            f"{self.n_networks} networks); same threshold: {self.raw_estimate:+.{digits}f} "
            f"[{self.raw_low:+.{digits}f}, {self.raw_high:+.{digits}f}]"
        )


def _paired(curve: RateCurve, reference: RateCurve) -> None:
    if curve.task != reference.task:
        raise InputError(f"matched_rate_difference: curves of different tasks ({curve.task!r}, {reference.task!r})")
    if curve.test_clips != reference.test_clips or np.shape(curve.points[0].clip_rates) != np.shape(
        reference.points[0].clip_rates
    ):
        raise InputError(
            "matched_rate_difference: the curves are not paired (different networks × clips: "
            f"{np.shape(curve.points[0].clip_rates)} {curve.test_clips} vs "
            f"{np.shape(reference.points[0].clip_rates)} {reference.test_clips})"
        )
    seeds = {(p.test_seeds, p.sensor_seeds) for p in curve.points + reference.points}
    if len(seeds) > 1:
        raise InputError(
            "matched_rate_difference: the curves are not paired (points scored on different test "
            f"clips or noise draws: {sorted(seeds)[:2]})"
        )


def _check_curve_length(curve: RateCurve, interpolation: str) -> None:
    """Refuse a curve with too few points for ``interpolation`` (2, or 3 for ``"quadratic"``)."""
    if len(curve.points) < (3 if interpolation == "quadratic" else 2):
        raise InputError(
            f"matched_rate_difference: the curve of {curve.kernel_name!r} has {len(curve.points)} "
            f"point(s); allowed: at least {3 if interpolation == 'quadratic' else 2} thresholds "
            f"(interpolation={interpolation!r})"
        )


def _falls_strictly(rates: np.ndarray) -> bool:
    """Whether event rates (events/pixel/s, in increasing threshold) are all > 0 and strictly falling."""
    return not (np.any(rates <= 0) or not np.all(np.diff(rates) < 0))


def _resampled_values(
    curve: RateCurve, reference_point: RatePoint, n_resamples: int, rng: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The reference point's and the curve's metric and event rate in each bootstrap resample.

    Parameters
    ----------
    curve : RateCurve
        Whose (network, clips) clusters are resampled (:meth:`RateCurve._weights`).
    reference_point : RatePoint
        The reference at its threshold, paired with ``curve``.
    n_resamples : int
    rng : int or numpy Generator

    Returns
    -------
    reference_metrics, reference_rates : ndarray (B,)
        Metric (fraction) and event rate (events/pixel/s) of the reference.
    curve_metrics, curve_rates : ndarray (B, P)
        The same at each point of ``curve``, in increasing threshold.
    """
    ws, wc = curve._weights(n_resamples, rng)
    ref_m, ref_r = _point_values(reference_point, ws, wc)
    vals = [_point_values(p, ws, wc) for p in curve.points]
    cm = np.stack([v[0] for v in vals], axis=1)
    cr = np.stack([v[1] for v in vals], axis=1)
    return ref_m, ref_r, cm, cr


def _unreadable_curve(
    curve: RateCurve, reference: RateCurve, reference_threshold: float, reference_rate: float, rates: np.ndarray
) -> str | None:
    """Why ``curve`` cannot be read at the reference's event rate (a refusal status), or None.

    Parameters
    ----------
    curve, reference : RateCurve
    reference_threshold : float
        Log units.
    reference_rate : float
        The reference's event rate at that threshold (events/pixel/s).
    rates : ndarray (P,)
        The curve's event rates (events/pixel/s), in increasing threshold.

    Returns
    -------
    str or None
        The curve does not fall strictly with threshold, or the reference rate lies outside it.
    """
    if not _falls_strictly(rates):
        return (
            f"refused: the rate curve of {curve.kernel_name!r} does not fall strictly "
            f"with threshold (rates {np.round(rates, 6).tolist()} {EVENT_RATE_UNIT} at "
            f"thresholds {list(curve.thresholds)})"
        )
    if not rates.min() <= reference_rate <= rates.max():
        return (
            f"refused: the reference rate {reference_rate:.4g} {EVENT_RATE_UNIT} ({reference.kernel_name} at "
            f"threshold {reference_threshold:g}) lies outside the measured rates of {curve.kernel_name!r} "
            f"[{rates.min():.4g}, {rates.max():.4g}] (thresholds {min(curve.thresholds):g}…"
            f"{max(curve.thresholds):g}); extend its thresholds instead of extrapolating"
        )
    return None


def _same_threshold_difference(
    curve: RateCurve,
    reference_metric: float,
    reference_resamples: np.ndarray,
    curve_resamples: np.ndarray,
    reference_threshold: float,
    alpha: float,
) -> dict[str, Any]:
    """``raw_estimate``, ``raw_low``, ``raw_high`` of :class:`MatchedRateDifference`.

    Parameters
    ----------
    curve : RateCurve
    reference_metric : float
        The reference's metric at ``reference_threshold`` (fraction).
    reference_resamples : ndarray (B,)
        That metric in each bootstrap resample.
    curve_resamples : ndarray (B, P)
        The curve's metric at each of its points in each resample.
    reference_threshold : float
        Log units.
    alpha : float
        Each tail's probability of the CI.

    Returns
    -------
    dict
        The difference at the curve's own point at ``reference_threshold`` and its percentile CI
        (metric units); NaN when the curve has no point there.
    """
    nan = math.nan
    raw = (nan, nan, nan)
    if any(abs(t - reference_threshold) <= 1e-12 for t in curve.thresholds):
        j = [abs(t - reference_threshold) <= 1e-12 for t in curve.thresholds].index(True)
        d = reference_resamples - curve_resamples[:, j]
        metrics = np.array([p.metric for p in curve.points])
        raw = (reference_metric - metrics[j], float(np.quantile(d, alpha)), float(np.quantile(d, 1 - alpha)))
    return dict(raw_estimate=raw[0], raw_low=raw[1], raw_high=raw[2])


def _resampled_matched_differences(
    reference_metrics: np.ndarray,
    reference_rates: np.ndarray,
    curve_metrics: np.ndarray,
    curve_rates: np.ndarray,
    interpolation: str,
) -> np.ndarray:
    """The matched-rate difference in each bootstrap resample.

    Parameters
    ----------
    reference_metrics, reference_rates : ndarray (B,)
        The reference's metric (fraction) and event rate (events/pixel/s) in each resample.
    curve_metrics, curve_rates : ndarray (B, P)
        The curve's metric and event rate at each point (increasing threshold) in each resample.
    interpolation : str
        As :func:`interpolate_log_rate`.

    Returns
    -------
    ndarray (B,)
        NaN where the resampled curve does not fall strictly or the resampled reference rate lies
        outside it.
    """
    boot = np.full(reference_metrics.shape[0], math.nan)
    for b in range(reference_metrics.shape[0]):
        rb = curve_rates[b]
        if not _falls_strictly(rb):
            continue
        boot[b] = reference_metrics[b] - interpolate_log_rate(
            rb, curve_metrics[b], float(reference_rates[b]), interpolation=interpolation
        )
    return boot


def _refused(status: str, fields: Mapping[str, Any], **known: Any) -> MatchedRateDifference:
    """A :class:`MatchedRateDifference` refused with ``status``: the numbers not in ``known`` are NaN."""
    nan = math.nan
    numbers: dict[str, Any] = dict(
        estimate=nan, low=nan, high=nan, matched_threshold=nan, inside_range=False, fraction_outside=nan
    )
    return MatchedRateDifference(status=status, **{**numbers, **known}, **fields)


def matched_rate_difference(
    curve: RateCurve,
    reference: RateCurve,
    reference_threshold: float,
    *,
    confidence: float = 0.95,
    n_resamples: int = 2000,
    rng: Any = 0,
    interpolation: str = "linear",
) -> MatchedRateDifference:
    """The reference's metric minus ``curve``'s metric at the reference's event rate, with a CI.

    Parameters
    ----------
    curve : RateCurve
        The kernel read at the matched rate (e.g. w/o: a plain DVS with its threshold moved).
    reference : RateCurve
        The kernel whose point at ``reference_threshold`` sets the rate (e.g. the learned kernel
        at the design's threshold). Must be paired with ``curve`` (same networks, clips, seeds).
    reference_threshold : float
        The reference's operating threshold (log units); a point of ``reference``.
    confidence : float
        Two-sided level in (0, 1).
    n_resamples : int
        Bootstrap resamples of (network, clips) clusters (≥ 100).
    rng : int or numpy Generator
    interpolation : {"linear", "pchip", "quadratic"}
        How ``curve`` is read between its points in log rate (:func:`interpolate_log_rate`),
        applied alike to the estimate, the matched threshold and every bootstrap resample.

    Returns
    -------
    MatchedRateDifference
        With ``status`` saying why a number was refused (the reference rate outside the curve's
        range is never extrapolated).

    Raises
    ------
    InputError
        Unpaired curves, a curve with fewer than 2 points, a threshold the reference lacks.
    """
    _check_confidence(confidence)
    _check_interpolation(interpolation)
    _paired(curve, reference)
    _check_curve_length(curve, interpolation)
    ref_point = reference.point(reference_threshold)
    ref_m, ref_r, cm, cr = _resampled_values(curve, ref_point, n_resamples, rng)
    rates = np.array([p.rate for p in curve.points])
    metrics = np.array([p.metric for p in curve.points])
    alpha = (1.0 - confidence) / 2.0
    fields: dict[str, Any] = dict(
        n_clips=curve.n_clips,
        n_networks=curve.n_networks,
        confidence=confidence,
        curve_kernel=curve.kernel_name,
        reference_kernel=reference.kernel_name,
        reference_threshold=float(reference_threshold),
        metric_name=curve.metric_name,
        task=curve.task,
        interpolation=interpolation,
        reference_rate=ref_point.rate,
        reference_rate_low=float(np.quantile(ref_r, alpha)),
        reference_rate_high=float(np.quantile(ref_r, 1 - alpha)),
        curve_rate_range=(float(rates.min()), float(rates.max())),
        **_same_threshold_difference(curve, ref_point.metric, ref_m, cm, reference_threshold, alpha),
    )
    unreadable = _unreadable_curve(curve, reference, reference_threshold, ref_point.rate, rates)
    if unreadable is not None:
        return _refused(unreadable, fields)
    estimate = ref_point.metric - interpolate_log_rate(rates, metrics, ref_point.rate, interpolation=interpolation)
    matched_t = interpolate_log_rate(rates, np.array(curve.thresholds), ref_point.rate, interpolation=interpolation)
    boot = _resampled_matched_differences(ref_m, ref_r, cm, cr, interpolation)
    outside = float(np.mean(~np.isfinite(boot)))
    if outside > alpha:
        status = (
            f"refused: in {outside:.1%} of the bootstrap resamples the reference rate fell outside the "
            f"resampled curve of {curve.kernel_name!r} (allowed: {alpha:.1%}); the CI would be cut; add "
            "thresholds beyond the reference rate"
        )
        known = dict(estimate=estimate, matched_threshold=matched_t, inside_range=True, fraction_outside=outside)
        return _refused(status, fields, **known)
    lo, hi = np.quantile(boot[np.isfinite(boot)], [alpha, 1 - alpha])
    return MatchedRateDifference(
        status="ok",
        estimate=float(estimate),
        low=float(lo),
        high=float(hi),
        matched_threshold=float(matched_t),
        inside_range=True,
        fraction_outside=outside,
        **fields,
    )


# --------------------------------------------------------------------------- measuring a curve
def _sensor_at(checkpoint: Path, design_sensor: Mapping[str, Any] | None, threshold: float) -> Any:
    """The simulator settings of one network at ``threshold`` (ON = OFF), the design's sensor path."""
    from ..tasks.checkpoints import load_checkpoint

    if design_sensor is None:
        stored = dict(load_checkpoint(checkpoint)[0].get("sensor", {}))
        design_sensor = {k: stored[k] for k in DESIGN_SENSOR_FIELDS}
    cfg, _ = task_sensor(checkpoint, {**design_sensor, "threshold_on": threshold, "threshold_off": threshold})
    return cfg


def _point_key(
    kernel: Kernel | None,
    task: str,
    networks: Mapping[str, Any],
    test_clips: str,
    design_sensor: Mapping[str, Any] | None,
    threshold: float,
) -> str:
    """The fingerprint under which a measured :class:`RatePoint` is saved and found again.

    Parameters
    ----------
    kernel : Kernel or None
        None: the 1×1 delta of a plain DVS.
    task : str
    networks : mapping
        What names the networks and their clips: ``checkpoints`` and ``n_test`` (fixed shipped
        networks) or ``user_task`` (a user-data table).
    test_clips : str
    design_sensor : mapping or None
        The design's sensor settings, thresholds aside.
    threshold : float
        ON = OFF contrast threshold (log units).

    Returns
    -------
    str
        16 hex characters.
    """
    taps = [[1.0]] if kernel is None else np.asarray(kernel.taps).round(15).tolist()
    return fingerprint(
        {
            "taps": taps,
            "task": task,
            **networks,
            "test_clips": test_clips,
            "sensor": dict(design_sensor) if design_sensor else None,
            "threshold": threshold,
        },
        length=16,
    )


def check_thresholds(thresholds: Sequence[float]) -> tuple[float, ...]:
    try:
        ts = tuple(float(t) for t in thresholds)
    except (TypeError, ValueError):
        raise InputError(
            f"rate_curve: thresholds={thresholds!r}; allowed: numbers in "
            f"[{THRESHOLD_RANGE[0]:g}, {THRESHOLD_RANGE[1]:g}] log units"
        ) from None
    lo, hi = THRESHOLD_RANGE
    bad = [t for t in ts if not (math.isfinite(t) and lo <= t <= hi)]
    if bad or len(ts) < 2 or len(set(ts)) != len(ts):
        raise InputError(
            f"rate_curve: thresholds={list(ts)}; allowed: at least 2 distinct values in "
            f"[{lo:g}, {hi:g}] log units" + (f" (out of range: {bad})" if bad else "")
        )
    return tuple(sorted(ts))


def rate_curve(
    kernel: Kernel | None,
    task: str,
    checkpoints: Sequence[str | Path],
    thresholds: Sequence[float] = DEFAULT_THRESHOLDS,
    *,
    n_test: int | None = None,
    design_sensor: Mapping[str, Any] | None = None,
    test_clips: str = "per_network",
    label: str | None = None,
    cache_dir: str | Path | None = None,
    progress: bool | None = None,
    on_point: Callable[[RatePoint], None] | None = None,
    events_fn: Any = None,
) -> RateCurve:
    """Measure a kernel's event rate and task metric at each contrast threshold, in fixed networks.

    Parameters
    ----------
    kernel : Kernel or None
        The kernel (None: w/o, the 1×1 delta of a plain DVS).
    task : str
        A task with a per-clip metric (:data:`fsdvs_hw.explore.paired.PER_CLIP_METRICS`).
    checkpoints : sequence of path
        The trained networks (one per training seed), each scored zero-shot with ``kernel``.
    thresholds : sequence of float
        ON = OFF contrast thresholds (log units, in :data:`THRESHOLD_RANGE`), at least 2.
    n_test : int, optional
        Test clips per network (default: the checkpoint's).
    design_sensor : mapping, optional
        A design's ``[sensor]`` section (its mismatch, placement and positivity replace the
        checkpoint's, as ``tasks.sensor = "design"``); None: the checkpoint's simulator settings.
        Only the thresholds are swept.
    test_clips : {"per_network", "shared"}
        Network ``s`` scores clip set ``s`` (default) or every network clip set 0.
    label : str, optional
        The curve's name (default the kernel's name, ``"w/o"`` for None).
    cache_dir : path, optional
        Folder where each finished point is saved (``{label}_t{threshold}.json``) and from which a
        rerun with the same kernel, networks and settings loads it instead of recomputing.
    progress : bool, optional
        Progress bar over (threshold, network) evaluations (:mod:`fsdvs_hw.progress`).
    on_point : callable, optional
        Called with each finished point (loaded or computed).
    events_fn : callable, optional
        Replaces the simulator (:func:`fsdvs_hw.tasks.learn.evaluate_kernel`'s ``events_fn``), e.g.
        :class:`fsdvs_hw.sensor.simulation.photon_noise.PhotonNoise` for photon shot noise of the scene; its
        ``repr`` enters the saved points' fingerprint.

    Returns
    -------
    RateCurve

    Raises
    ------
    InputError
        Bad thresholds, no checkpoints, unknown task, missing checkpoint.
    """
    ts = check_thresholds(thresholds)
    paths = [Path(p) for p in checkpoints]
    if not paths:
        raise InputError("rate_curve: checkpoints is empty; allowed: one or more trained networks")
    if test_clips not in ("per_network", "shared"):
        raise InputError(f"rate_curve: test_clips={test_clips!r}; allowed: 'per_network', 'shared'")
    name = label or ("w/o" if kernel is None else kernel.name)

    def point_key(t: float) -> str:
        networks = {"checkpoints": [p.name for p in paths], "n_test": n_test}
        fp = _point_key(kernel, task, networks, test_clips, design_sensor, t)
        return fp if events_fn is None else text_fingerprint(f"{fp}|{events_fn!r}", length=16)

    def evaluate(t: float, bar: Any) -> list[Any]:
        evid = []
        for s, ckpt in enumerate(paths):
            evid.append(
                clip_evidence(
                    kernel,
                    task,
                    ckpt,
                    n_test=n_test,
                    sensor=_sensor_at(ckpt, design_sensor, t),
                    events_fn=events_fn,
                    seed_offset=s,
                    clip_set=s if test_clips == "per_network" else 0,
                )
            )
            bar.update(1)
        return evid

    points, metric_name = _measure_points(
        name, task, ts, point_key, evaluate, len(paths), cache_dir, progress, on_point
    )
    return RateCurve(
        kernel_name=name,
        task=task,
        metric_name=metric_name,
        test_clips=test_clips,
        points=tuple(points),
        checkpoints=tuple(p.name for p in paths),
    )


def _measure_points(
    name: str,
    task: str,
    ts: Sequence[float],
    point_key: Callable[[float], str],
    evaluate: Callable[[float, Any], list[Any]],
    n_networks: int,
    cache_dir: str | Path | None,
    progress: bool | None,
    on_point: Callable[[RatePoint], None] | None,
) -> tuple[list[RatePoint], str]:
    """Each threshold's :class:`RatePoint` from ``evaluate(t, bar)`` (one ClipEvidence per network), or
    from ``cache_dir`` when a saved point has ``point_key(t)``; finished points are saved there."""
    cache = Path(cache_dir) if cache_dir is not None else None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    slug = "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
    points: list[RatePoint] = []
    metric_name = ""
    with progress_bar(total=len(ts) * n_networks, desc=f"rate curve {name}", unit="eval", progress=progress) as bar:
        for t in ts:
            fp = point_key(t)
            file = cache / f"{slug}_t{t:g}.json" if cache is not None else None
            if file is not None and file.is_file():
                stored = json.loads(file.read_text())
                if stored.get("fingerprint") == fp:
                    point = RatePoint.from_dict(stored["point"])
                    metric_name = stored.get("metric_name", metric_name)
                    points.append(point)
                    bar.update(n_networks)
                    if on_point is not None:
                        on_point(point)
                    continue
            evid = evaluate(t, bar)
            if any(e.clip_event_rates is None for e in evid):
                raise InputError(f"rate_curve: the evaluator returned no per-clip event rates for {name!r}")
            metric_name = evid[0].metric_name
            point = RatePoint.from_evidence(t, evid)
            if file is not None:
                write_output(
                    file,
                    json.dumps(
                        {
                            "fingerprint": fp,
                            "kernel": name,
                            "task": task,
                            "metric_name": metric_name,
                            "point": point.to_dict(),
                        }
                    ),
                )
            points.append(point)
            if on_point is not None:
                on_point(point)
    return points, metric_name


def dataset_rate_curve(
    kernel: Kernel | None,
    task: str,
    entry: Mapping[str, Any],
    base_dir: str | Path,
    thresholds: Sequence[float] = DEFAULT_THRESHOLDS,
    *,
    design_sensor: Mapping[str, Any] | None = None,
    test_clips: str = "per_network",
    label: str | None = None,
    cache_dir: str | Path | None = None,
    progress: bool | None = None,
    confine: Confinement = True,
) -> RateCurve:
    """A kernel's rate curve on a user-data task: the user's network and clips at each threshold.

    The counterpart of :func:`rate_curve` for a ``[tasks.datasets.<task>]`` table: each threshold
    is scored by :func:`fsdvs_hw.explore.user_data.dataset_evidence` (one network, the table's
    seeded clips, the simulator reseeded per clip), so its points pair with the exploration's
    own scores of that task clip by clip.

    Parameters
    ----------
    kernel : Kernel or None
        The kernel (None: the 1×1 delta of a plain DVS).
    task : str
        The table's task.
    entry : mapping
        The validated ``[tasks.datasets.<task>]`` table (:class:`fsdvs_hw.design.user_data_section.UserTask` dumped).
    base_dir : path
        The design file's folder.
    thresholds : sequence of float
        ON = OFF contrast thresholds (log units, in :data:`THRESHOLD_RANGE`), at least 2.
    design_sensor : mapping, optional
        ``SensorConfig`` fields replacing the training default's (``tasks.sensor = "design"``);
        only the thresholds are swept.
    test_clips : str
        Recorded on the curve (the exploration's ``[tasks] test_clips``, for the pairing check).
    label, cache_dir, progress
        As :func:`rate_curve` (finished points saved and reused; the disk-cache settings of the
        dataset do not enter their fingerprint).
    confine : bool
        Refuse dataset paths outside ``base_dir``.

    Returns
    -------
    RateCurve
        ``checkpoints`` holds the network's factory name.

    Raises
    ------
    InputError
        Bad thresholds, or any dataset, network or clip problem.

    Examples
    --------
    >>> curve = dataset_rate_curve(None, "recognition", entry, "designs", [0.1, 0.3])   # doctest: +SKIP
    >>> curve.thresholds                                                                # doctest: +SKIP
    (0.1, 0.3)
    """
    from .user_data import dataset_evidence

    ts = check_thresholds(thresholds)
    name = label or ("w/o" if kernel is None else kernel.name)
    recorded = {**entry, "dataset": {k: v for k, v in entry["dataset"].items() if k != "cache"}}

    def point_key(t: float) -> str:
        return _point_key(kernel, task, {"user_task": recorded}, test_clips, design_sensor, t)

    def evaluate(t: float, bar: Any) -> list[Any]:
        ev, _ = dataset_evidence(
            kernel,
            task,
            entry,
            base_dir,
            confine=confine,
            design_sensor={**(design_sensor or {}), "threshold_on": t, "threshold_off": t},
        )
        bar.update(1)
        return [ev]

    points, metric_name = _measure_points(name, task, ts, point_key, evaluate, 1, cache_dir, progress, None)
    return RateCurve(
        kernel_name=name,
        task=task,
        metric_name=metric_name,
        test_clips=test_clips,
        points=tuple(points),
        checkpoints=(str(entry.get("network") or "built-in"),),
    )
