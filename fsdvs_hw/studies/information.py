"""Information per event: MI between ground truth and a reconstruction from events, per kernel.

The FS-DVS paper's information analysis (Sec. IV-E): intensity frames are reconstructed from the
events of a plain DVS and of FS-DVS, and the mutual information (MI) between reconstruction and
ground truth rises from 0.98 to 1.06 bits per pixel (+8.16 %). :func:`run_information_study`
repeats it per kernel **condition** — w/o (1×1 delta, a plain DVS), the design's learned kernel,
each hardware realisation (fitted with the design's options), and w/o with its threshold lowered
to the learned kernel's event rate (``w/o @ matched rate``) — and adds what the paper leaves out:
the **bits per event** (MI per pixel ÷ events per pixel of the clip), since a kernel that fires
more events may carry more information simply because it fires more.

Per condition, ``n_networks`` reconstruction networks (:mod:`fsdvs_hw.tasks.reconstruction`,
training seeds 0 … n−1, the kernel frozen) are trained on the same synthetic clips and scored on the
same ``n_test`` held-out clips (seed :data:`~fsdvs_hw.tasks.learn.TEST_SEED`) with the same sensor
noise draws; the MI estimator is :mod:`fsdvs_hw.mutual_information` (equal-mass 32 × 32 joint
histogram, Miller–Madow corrected; ground-truth bin edges shared by every condition, the
reconstruction's per network). Every clip keeps its own joint histogram, so a bootstrap resample
of networks × clips (crossed: the clips are shared, :func:`fsdvs_hw.explore.paired.bootstrap_weights`)
re-weights the histograms and recomputes MI, events per pixel and bits per event; the same
resamples serve every condition, so differences to w/o are paired. A resample that repeats clips
biases a histogram MI up (fewer distinct samples than the count Miller–Madow assumes), so each
percentile interval is shifted by the bootstrap's bias estimate (mean of the resamples − estimate).

Matched rate: the w/o event rate on the test clips is measured along ``rate_thresholds``
(simulator only) and the threshold where it equals the learned kernel's rate at the design's
threshold is read off by interpolation in log rate (:func:`fsdvs_hw.explore.rate.interpolate_log_rate`,
never extrapolated); networks are then trained at that threshold (the retrained protocol).

Files written to ``out`` (a rerun resumes: trained networks and scored conditions are reused when
their fingerprint matches):

``networks/{condition}_s{seed}.*``
    Each reconstruction network (:func:`~fsdvs_hw.tasks.learn.learn_kernel` checkpoint with provenance).
``evidence/{condition}.npz``
    Per network and clip: the joint histogram and the events per pixel.
``kernels/{realisation}.json``
    The fitted realisation kernels.
``information.json`` / ``information.csv``
    One row per condition (:data:`TABLE_FIELDS`: gains against w/o), the settings and provenance;
    the JSON also holds ``vs_matched_rate``, each condition's gains against ``w/o @ matched rate``
    (:data:`MATCHED_FIELDS`): the learned kernel against a plain DVS that fires as many events.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as _dt
import io
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..explore.paired import EVENT_RATE_UNIT, bootstrap_weights
from ..explore.rate import interpolate_log_rate
from ..fingerprints import fingerprint
from ..kernels import Kernel
from ..mutual_information import DEFAULT_BINS, MI_UNIT, histogram_mi, joint_histogram, quantile_edges
from ..paths import output_dir, write_output
from ..progress import progress_bar
from ..provenance import library_versions

__all__ = [
    "BOOTSTRAP_METHOD",
    "DEFAULT_RATE_THRESHOLDS",
    "MATCHED",
    "MATCHED_FIELDS",
    "TABLE_FIELDS",
    "ConditionEvidence",
    "InformationOptions",
    "InformationStudy",
    "bits_per_event",
    "information_table",
    "run_information_study",
]

#: The interval method of every CI in ``information.json`` (its ``settings.bootstrap``), named exactly.
BOOTSTRAP_METHOD = (
    "bias-shifted percentile (not BCa): the (1 - confidence)/2 and (1 + confidence)/2 quantiles of "
    "resampled value - (mean of the resamples - estimate), i.e. the percentile interval moved by minus the "
    "bootstrap bias estimate (Efron & Tibshirani 1993, ch. 10); non-finite resamples dropped, no interval "
    "when over 10 % are; resamples of networks x clips crossed (clips shared by every network and "
    "condition), the same resamples for every condition (paired gains)"
)

#: ON = OFF thresholds (log units) along which the w/o event rate is measured for the matched rate.
DEFAULT_RATE_THRESHOLDS: tuple[float, ...] = (0.05, 0.07, 0.1, 0.125, 0.15, 0.2, 0.3)

#: The condition "w/o with its threshold moved to the learned kernel's event rate".
MATCHED: str = "w/o @ matched rate"

#: The gains over a reference condition and their CI bounds, in :data:`TABLE_FIELDS` and :data:`MATCHED_FIELDS`.
_GAIN_FIELDS: tuple[str, ...] = (
    "mi_gain",
    "mi_gain_low",
    "mi_gain_high",
    "mi_gain_pct",
    "mi_gain_pct_low",
    "mi_gain_pct_high",
    "bits_per_event_gain",
    "bits_per_event_gain_low",
    "bits_per_event_gain_high",
)

#: Fields of the comparison of each condition against :data:`MATCHED` (``information.json``,
#: ``vs_matched_rate``): the gains of :data:`TABLE_FIELDS`, taken against the matched w/o.
MATCHED_FIELDS: tuple[str, ...] = ("condition", *_GAIN_FIELDS, "confidence")

#: Columns of the table (``information.csv``); ``_low``/``_high`` are the CI bounds.
TABLE_FIELDS: tuple[str, ...] = (
    "condition",
    "kernel",
    "kernel_size",
    "threshold",
    "n_networks",
    "n_clips",
    "mi",
    "mi_low",
    "mi_high",
    "mi_shuffled",
    "events_per_pixel",
    "events_per_pixel_low",
    "events_per_pixel_high",
    "rate",
    "rate_low",
    "rate_high",
    "bits_per_event",
    "bits_per_event_low",
    "bits_per_event_high",
    *_GAIN_FIELDS,
    "r2",
    "confidence",
)


def bits_per_event(mi_bits_per_pixel: Any, events_per_pixel: Any) -> np.ndarray | float:
    """Information per event: MI per pixel ÷ events per pixel (bits/event).

    Parameters
    ----------
    mi_bits_per_pixel : float or array
        MI between reconstruction and ground truth (bits/pixel).
    events_per_pixel : float or array
        Events (ON + OFF) per pixel of the clip the reconstruction came from (> 0).

    Returns
    -------
    float or ndarray
        Bits per event; NaN where there were no events.

    Raises
    ------
    InputError
        Negative or non-finite inputs.

    Examples
    --------
    >>> bits_per_event(1.0, 0.5)
    2.0
    """
    mi = np.asarray(mi_bits_per_pixel, dtype=np.float64)
    ev = np.asarray(events_per_pixel, dtype=np.float64)
    if not (np.all(np.isfinite(mi)) and np.all(np.isfinite(ev))) or np.any(mi < 0) or np.any(ev < 0):
        raise InputError(
            f"bits_per_event: MI {mi.tolist()} bits/pixel and events {ev.tolist()} per pixel; allowed: "
            "finite values >= 0"
        )
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(ev > 0, mi / np.where(ev > 0, ev, 1.0), np.nan)
    return float(out) if out.ndim == 0 else out


@dataclass(frozen=True)
class ConditionEvidence:
    """One condition's per-(network, clip) evidence: joint histograms and events per pixel.

    Attributes
    ----------
    name : str
        Condition (``"w/o"``, ``"learned"``, a realisation, ``"w/o @ matched rate"``).
    kernel : str
        The kernel's name.
    kernel_size : int
    threshold : float
        ON = OFF contrast threshold (log units).
    histograms : ndarray (n_networks, n_clips, n_x, n_y)
        Joint counts of (ground truth, reconstruction) per clip, bins fixed per network.
    events_per_pixel : ndarray (n_networks, n_clips)
        ON + OFF events per pixel over each clip.
    span_s : float
        The clip's duration (s), for the rate in events/pixel/s.
    r2 : ndarray (n_networks,)
        Each network's squared correlation with the ground truth (:mod:`~fsdvs_hw.tasks.reconstruction`).
    mi_shuffled : float
        MI with the clips' ground truth rolled by one clip (pairing broken): the estimator's floor.
    """

    name: str
    kernel: str
    kernel_size: int
    threshold: float
    histograms: np.ndarray
    events_per_pixel: np.ndarray
    span_s: float
    r2: np.ndarray
    mi_shuffled: float

    def __post_init__(self) -> None:
        h, e = np.shape(self.histograms), np.shape(self.events_per_pixel)
        if len(h) != 4 or h[:2] != e:
            raise InputError(
                f"ConditionEvidence {self.name!r}: histograms {h} and events_per_pixel {e} do not "
                "share (networks, clips)"
            )

    def to_npz(self) -> bytes:
        buf = io.BytesIO()
        meta = {k: getattr(self, k) for k in ("name", "kernel", "kernel_size", "threshold", "span_s", "mi_shuffled")}
        np.savez_compressed(
            buf,
            histograms=self.histograms,
            events_per_pixel=self.events_per_pixel,
            r2=self.r2,
            meta=np.array(json.dumps(meta)),
        )
        return buf.getvalue()

    @classmethod
    def from_npz(cls, path: Path) -> ConditionEvidence:
        try:
            with np.load(path) as z:
                meta = json.loads(str(z["meta"]))
                return cls(histograms=z["histograms"], events_per_pixel=z["events_per_pixel"], r2=z["r2"], **meta)
        except (OSError, KeyError, ValueError, TypeError) as exc:
            raise InputError(f"{path}: not a stored information evidence file ({exc!r})") from None


def _percent_gain(value: Any, reference: Any) -> Any:
    """``100 (value / reference − 1)``; NaN where the reference is 0 (no information to gain over)."""
    v, r = np.asarray(value, dtype=np.float64), np.asarray(reference, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(r > 0, 100.0 * (v / np.where(r > 0, r, 1.0) - 1.0), np.nan)
    return float(out) if out.ndim == 0 else out


def _condition_values(ev: ConditionEvidence, ws: np.ndarray, wc: np.ndarray) -> dict[str, np.ndarray]:
    """Bootstrap values (B,) of MI, events per pixel and bits per event of one condition."""
    hist = np.einsum("bc,scxy->bsxy", wc, ev.histograms.astype(np.float64))
    mi_bs = np.asarray(histogram_mi(hist))  # (B, S)
    mi = (ws * mi_bs).sum(axis=1) / ws.sum(axis=1)
    epp = np.einsum("bs,bc,sc->b", ws, wc, ev.events_per_pixel) / (ws.sum(axis=1) * wc.sum(axis=1))
    return {"mi": mi, "events_per_pixel": epp, "bits_per_event": np.asarray(bits_per_event(mi, epp))}


def _bias_shifted_ci(values: np.ndarray, estimate: float, alpha: float) -> tuple[float, float]:
    """A percentile interval of bootstrap ``values`` moved by minus their bias (:data:`BOOTSTRAP_METHOD`).

    Centred on the estimate: a resample repeats clips, which biases a histogram MI up (fewer distinct
    samples than Miller-Madow's N); the bootstrap's own mean shift is that bias.

    Parameters
    ----------
    values : ndarray (B,)
        The resampled values (the unit of ``estimate``).
    estimate : float
        The value on the data as they are.
    alpha : float
        Each tail's probability, ``(1 - confidence) / 2``.

    Returns
    -------
    (float, float)
        The bounds; NaN when the estimate is not finite or over 10 % of the resamples are not.
    """
    v = values[np.isfinite(values)]
    if v.size < 0.9 * values.size or not math.isfinite(estimate):
        return math.nan, math.nan
    lo, hi = np.quantile(v - (v.mean() - estimate), [alpha, 1 - alpha])
    return float(lo), float(hi)


def _condition_row(
    c: ConditionEvidence,
    b: Mapping[str, np.ndarray],
    p: Mapping[str, float],
    ref_b: Mapping[str, np.ndarray],
    ref_p: Mapping[str, float],
    alpha: float,
) -> dict[str, Any]:
    """One condition's values, gains over the reference and their CIs (:data:`TABLE_FIELDS` but the counts).

    Parameters
    ----------
    c : ConditionEvidence
    b, p : mapping
        The condition's bootstrap values (B,) and estimates of ``mi`` (bits/pixel),
        ``events_per_pixel`` and ``bits_per_event`` (bits/event).
    ref_b, ref_p : mapping
        The same of the reference condition.
    alpha : float
        Each tail's probability of the CIs.

    Returns
    -------
    dict
        Every field of :data:`TABLE_FIELDS` except ``n_networks``, ``n_clips`` and ``confidence``;
        the rate in events/pixel/s.
    """
    row: dict[str, Any] = {
        "condition": c.name,
        "kernel": c.kernel,
        "kernel_size": c.kernel_size,
        "threshold": c.threshold,
    }
    for key in ("mi", "events_per_pixel", "bits_per_event"):
        row[key] = p[key]
        row[f"{key}_low"], row[f"{key}_high"] = _bias_shifted_ci(b[key], p[key], alpha)
        if key == "mi":
            row["mi_shuffled"] = c.mi_shuffled
        if key == "events_per_pixel":
            row["rate"] = p[key] / c.span_s
            row["rate_low"], row["rate_high"] = row[f"{key}_low"] / c.span_s, row[f"{key}_high"] / c.span_s
    gains = {
        "mi_gain": (p["mi"] - ref_p["mi"], b["mi"] - ref_b["mi"]),
        "mi_gain_pct": (_percent_gain(p["mi"], ref_p["mi"]), _percent_gain(b["mi"], ref_b["mi"])),
        "bits_per_event_gain": (
            p["bits_per_event"] - ref_p["bits_per_event"],
            b["bits_per_event"] - ref_b["bits_per_event"],
        ),
    }
    for key, (est, vals) in gains.items():
        row[key] = est
        row[f"{key}_low"], row[f"{key}_high"] = _bias_shifted_ci(vals, est, alpha)
    row["r2"] = float(np.mean(c.r2))
    return row


def information_table(
    conditions: Sequence[ConditionEvidence],
    *,
    reference: str = "w/o",
    confidence: float = 0.95,
    n_resamples: int = 2000,
    rng: Any = 0,
) -> list[dict[str, Any]]:
    """One row per condition: MI, events per pixel, rate, bits per event, gains over ``reference``, CIs.

    Parameters
    ----------
    conditions : sequence of ConditionEvidence
        Scored on the same clips by the same number of networks (paired).
    reference : str
        The condition the gains are taken against (``mi − mi(reference)``, in bits/pixel and %).
    confidence : float
        Two-sided level in (0, 1) of the bootstrap CIs: percentile intervals of the resampled values
        shifted by the bootstrap bias estimate (mean of the resamples − estimate; Efron & Tibshirani
        1993, *An Introduction to the Bootstrap*, ch. 10), because a resample that repeats clips
        biases a histogram MI up; for the event counts (a mean) the shift is ~0.
    n_resamples : int
        Bootstrap resamples of networks × clips (crossed), the same for every condition.
    rng : int or numpy Generator

    Returns
    -------
    list of dict
        Keys :data:`TABLE_FIELDS`.

    Raises
    ------
    InputError
        No conditions, unpaired conditions, unknown reference, bad confidence.

    Examples
    --------
    Two conditions, 2 networks × 3 clips of 2 × 2 histograms: w/o independent, the other perfect.

    >>> def evidence(name, hist, epp):
    ...     return ConditionEvidence(name=name, kernel=name, kernel_size=1, threshold=0.2,
    ...                              histograms=np.broadcast_to(hist, (2, 3, 2, 2)),
    ...                              events_per_pixel=np.full((2, 3), epp), span_s=0.04, r2=np.zeros(2),
    ...                              mi_shuffled=0.0)
    >>> rows = information_table([evidence("w/o", np.full((2, 2), 50), 0.5),
    ...                           evidence("learned", np.diag([100, 100]), 2.0)], n_resamples=100)
    >>> [(r["condition"], round(r["mi"], 2), round(r["bits_per_event"], 2)) for r in rows]
    [('w/o', 0.0, 0.0), ('learned', 1.0, 0.5)]
    """
    if not conditions:
        raise InputError("information_table: no conditions")
    if isinstance(confidence, bool) or not isinstance(confidence, (int, float)) or not 0 < confidence < 1:
        raise InputError(f"confidence={confidence!r}; allowed: a number in (0, 1)")
    by_name = {c.name: c for c in conditions}
    if reference not in by_name:
        raise InputError(f"information_table: reference {reference!r} not among the conditions {list(by_name)}")
    shapes = {np.shape(c.events_per_pixel) for c in conditions}
    if len(shapes) != 1:
        raise InputError(f"information_table: conditions are not paired (networks × clips {sorted(shapes)})")
    n_net, n_clips = next(iter(shapes))
    ws, wc = bootstrap_weights(n_net, n_clips, test_clips="shared", n_resamples=n_resamples, rng=rng)
    assert wc is not None  # shared clips: always drawn
    ones_s, ones_c = np.ones((1, n_net)), np.ones((1, n_clips))
    boot = {c.name: _condition_values(c, ws, wc) for c in conditions}
    point = {c.name: {k: float(v[0]) for k, v in _condition_values(c, ones_s, ones_c).items()} for c in conditions}
    alpha = (1.0 - confidence) / 2.0
    rows = []
    for c in conditions:
        row = _condition_row(c, boot[c.name], point[c.name], boot[reference], point[reference], alpha)
        row.update(n_networks=n_net, n_clips=n_clips, confidence=confidence)
        rows.append({k: row[k] for k in TABLE_FIELDS})
    return rows


# --------------------------------------------------------------------------- the study
@dataclass(frozen=True)
class InformationOptions:
    """What :func:`run_information_study` measures.

    Attributes
    ----------
    design : path
        TOML design (its kernel, ``[sensor]`` thresholds/placement/positivity, realisation options).
    out : path
        Output folder.
    n_networks : int
        Reconstruction networks per condition (training seeds 0 … n−1).
    n_train, n_test : int
        Training clips per network; held-out test clips (shared by every network and condition).
    epochs : int
        Training epochs per network.
    width : int
        Network width (channels at full resolution).
    realisations : sequence of str
        Hardware realisations to add (fitted with the design's options).
    matched_rate : bool
        Add ``w/o @ matched rate`` (w/o retrained at the threshold where it fires as many events as
        the learned kernel at the design's threshold).
    rate_thresholds : sequence of float
        Thresholds along which the w/o rate is measured for the match (log units).
    n_bins : int
        Equal-mass bins per axis of the MI estimator.
    n_resamples : int
    confidence : float
    progress : bool or None
    command : str
        The command line, recorded in the provenance.
    """

    design: Path
    out: Path
    n_networks: int = 3
    n_train: int = 512
    n_test: int = 64
    epochs: int = 16
    width: int = 16
    realisations: tuple[str, ...] = ("mesh", "asic", "metalens")
    matched_rate: bool = True
    rate_thresholds: tuple[float, ...] = DEFAULT_RATE_THRESHOLDS
    n_bins: int = DEFAULT_BINS
    n_resamples: int = 2000
    confidence: float = 0.95
    progress: bool | None = None
    command: str = ""

    def __post_init__(self) -> None:
        for name, lo, hi in (
            ("n_networks", 2, 1000),
            ("n_train", 2, 100_000),
            ("n_test", 2, 100_000),
            ("epochs", 1, 10_000),
            ("width", 4, 256),
            ("n_bins", 2, 4096),
            ("n_resamples", 100, 1_000_000),
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                raise InputError(f"InformationOptions.{name}={v!r}; allowed: an integer in [{lo}, {hi}]")


@dataclass(frozen=True)
class InformationStudy:
    """What :func:`run_information_study` measured: the table, the evidence, the files written."""

    rows: list[dict[str, Any]]
    conditions: dict[str, ConditionEvidence]
    matched_threshold: float | None
    files: dict[str, Path]
    #: Each condition against ``w/o @ matched rate`` (:data:`MATCHED_FIELDS`); empty without it.
    vs_matched: list[dict[str, Any]] = dataclasses.field(default_factory=list)

    @property
    def text(self) -> str:
        """One line per condition: MI, events per pixel, bits per event, gain over w/o, with CIs."""
        lines = []
        for r in self.rows:
            lines.append(
                f"{r['condition']:<20} MI {r['mi']:.3f} [{r['mi_low']:.3f}, {r['mi_high']:.3f}] {MI_UNIT}; "
                f"{r['events_per_pixel']:.3f} events/pixel; {r['bits_per_event']:.3f} "
                f"[{r['bits_per_event_low']:.3f}, {r['bits_per_event_high']:.3f}] bits/event; vs w/o "
                f"{r['mi_gain']:+.3f} [{r['mi_gain_low']:+.3f}, {r['mi_gain_high']:+.3f}] bits/pixel "
                f"({r['mi_gain_pct']:+.1f} %)"
            )
        for r in self.vs_matched:
            if r["condition"] == "learned":
                lines.append(
                    f"learned vs w/o @ matched rate: {r['mi_gain']:+.3f} [{r['mi_gain_low']:+.3f}, "
                    f"{r['mi_gain_high']:+.3f}] bits/pixel ({r['mi_gain_pct']:+.1f} % [{r['mi_gain_pct_low']:+.1f}, "
                    f"{r['mi_gain_pct_high']:+.1f}]); {r['bits_per_event_gain']:+.3f} [{r['bits_per_event_gain_low']:+.3f}, "
                    f"{r['bits_per_event_gain_high']:+.3f}] bits/event"
                )
        return "\n".join(lines)


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def _fingerprint(**parts: Any) -> str:
    return fingerprint(parts, length=16)


def _sensor_for(design: Any, scene: Any, threshold: float | None = None) -> Any:
    """The training simulator (:func:`~fsdvs_hw.tasks.learn.default_sensor`) with the design's sensor fields."""
    from ..explore.scoring import DESIGN_SENSOR_FIELDS
    from ..tasks.learn import default_sensor

    fields = {k: design.section("sensor")[k] for k in DESIGN_SENSOR_FIELDS}
    if threshold is not None:
        fields.update(threshold_on=threshold, threshold_off=threshold)
    return dataclasses.replace(default_sensor(scene), **fields)


def _events_per_pixel(video: Any, kernel: Kernel | None, sensor: Any, timestamps_s: np.ndarray) -> np.ndarray:
    """ON + OFF events per pixel of each clip (N,)."""
    import torch

    from ..sensor import event_frames

    taps = None if kernel is None else torch.as_tensor(np.array(kernel.taps), dtype=video.dtype)
    with torch.no_grad():
        ev = torch.cat(
            [
                event_frames(video[s : s + 64], taps, timestamps_s=timestamps_s, config=sensor)
                for s in range(0, video.shape[0], 64)
            ]
        )
    return ev.reshape(ev.shape[0], -1).sum(dim=1).double().numpy() / (ev.shape[-2] * ev.shape[-1])


def _matched_threshold(
    design: Any, scene: Any, target: Kernel, n_test: int, thresholds: Sequence[float], out: Path
) -> tuple[float, dict[str, Any]]:
    """The w/o threshold at which its event rate equals the learned kernel's at the design's threshold."""
    import torch

    from ..scenes.synthetic import make_scenes
    from ..tasks.learn import TEST_SEED

    t_ref = float(design.section("sensor")["threshold_on"])
    ts = sorted(set(float(t) for t in thresholds) | {t_ref})
    fp = _fingerprint(
        scene=scene.to_dict(),
        n_test=n_test,
        thresholds=ts,
        taps=np.asarray(target.taps).tolist(),
        sensor=_sensor_for(design, scene).to_dict(),
    )
    file = out / "matched_rate.json"
    if file.is_file():
        stored = json.loads(file.read_text())
        if stored.get("fingerprint") == fp:
            return float(stored["matched_threshold"]), stored
    video = torch.from_numpy(make_scenes(scene, n_test, seed=TEST_SEED).video).float()
    span = float(scene.timestamps_s[-1] - scene.timestamps_s[0])
    wo = [
        float(_events_per_pixel(video, None, _sensor_for(design, scene, t), scene.timestamps_s).mean()) / span
        for t in ts
    ]
    learned = (
        float(_events_per_pixel(video, target, _sensor_for(design, scene, t_ref), scene.timestamps_s).mean()) / span
    )
    matched = interpolate_log_rate(wo, ts, learned)
    if not math.isfinite(matched):
        raise InputError(
            f"matched rate: the learned kernel's rate {learned:.4g} {EVENT_RATE_UNIT} lies outside the "
            f"w/o rates {[round(r, 3) for r in wo]} at thresholds {ts}; widen --rate-thresholds"
        )
    record = {
        "fingerprint": fp,
        "matched_threshold": matched,
        "reference_threshold": t_ref,
        "learned_rate": learned,
        "wo_thresholds": ts,
        "wo_rates": wo,
        "rate_unit": EVENT_RATE_UNIT,
        "n_test": n_test,
    }
    write_output(file, json.dumps(record, indent=1))
    return matched, record


def _train(
    name: str, kernel: Kernel | None, sensor: Any, scene: Any, seed: int, opts: InformationOptions, folder: Path
) -> Path:
    """One reconstruction network (resumed when its checkpoint and fingerprint exist); its checkpoint path."""
    from ..tasks.learn import TrainingSettings, learn_kernel

    stem = folder / f"{_slug(name)}_s{seed}"
    settings = TrainingSettings(epochs_frozen=0, epochs_joint=opts.epochs, width=opts.width)
    fp = _fingerprint(
        taps=None if kernel is None else np.asarray(kernel.taps).round(15).tolist(),
        sensor=sensor.to_dict(),
        scene=scene.to_dict(),
        seed=seed,
        n_train=opts.n_train,
        n_test=opts.n_test,
        settings=settings.to_dict(),
    )
    done = Path(str(stem) + ".fingerprint")
    ckpt = Path(str(stem) + ".safetensors")
    if ckpt.is_file() and done.is_file() and done.read_text().strip() == fp:
        return ckpt
    learn_kernel(
        "reconstruction",
        1 if kernel is None else kernel.size,
        seed=seed,
        n_train=opts.n_train,
        n_test=opts.n_test,
        settings=settings,
        scene=scene,
        sensor=sensor,
        learn_filter=False,
        init_kernel=kernel,
        out=stem,
        name=f"{name} (frozen) with reconstruction network s{seed}",
    )
    write_output(done, fp + "\n")
    return ckpt


def _score(
    name: str,
    kernel: Kernel | None,
    threshold: float,
    checkpoints: Sequence[Path],
    scene: Any,
    ground_truth: np.ndarray,
    x_edges: np.ndarray,
    n_bins: int,
) -> ConditionEvidence:
    """Reconstruct the test clips with each network; per-clip joint histograms and events per pixel."""
    from ..tasks.learn import evaluate_kernel

    span = float(scene.timestamps_s[-1] - scene.timestamps_s[0])
    hists, epp, r2, shuffled = [], [], [], []
    for ckpt in checkpoints:
        ev = evaluate_kernel(kernel, "reconstruction", ckpt, keep_predictions=True)
        recon = ev.predictions["image"]
        y_edges = quantile_edges(recon, n_bins)
        padded = np.zeros((len(ground_truth), n_bins, n_bins), dtype=np.int64)  # tied values merge bins
        for c, (g, r) in enumerate(zip(ground_truth, recon)):
            h = joint_histogram(g, r, x_edges, y_edges)
            padded[c, : h.shape[0], : h.shape[1]] = h
        hists.append(padded)
        shuffled.append(float(histogram_mi(joint_histogram(np.roll(ground_truth, 1, axis=0), recon, x_edges, y_edges))))
        epp.append(np.asarray(ev.clip_event_rates) * span)
        r2.append(ev.metrics["r2"])
    return ConditionEvidence(
        name=name,
        kernel="w/o (1x1 delta)" if kernel is None else kernel.name,
        kernel_size=1 if kernel is None else kernel.size,
        threshold=threshold,
        histograms=np.stack(hists),
        events_per_pixel=np.stack(epp),
        span_s=span,
        r2=np.asarray(r2),
        mi_shuffled=float(np.mean(shuffled)),
    )


def _realisation_kernel(name: str, design: Any, folder: Path) -> Kernel:
    from ..explore.scoring import fit_realisation

    file = folder / f"{_slug(name)}.json"
    fp = _fingerprint(taps=np.asarray(design.target.taps).round(15).tolist(), options=design.realisation_options(name))
    if file.is_file():
        stored = json.loads(file.read_text())
        if stored.get("fingerprint") == fp:
            return Kernel(np.asarray(stored["taps"]), name=stored["name"])
    real, _ = fit_realisation(name, design.target, design.realisation_options(name), seed=design.spec.run.seed)
    k = real.kernel()
    write_output(file, json.dumps({"fingerprint": fp, "name": k.name, "taps": np.asarray(k.taps).tolist()}))
    return k


def _csv(rows: Sequence[Mapping[str, Any]]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(TABLE_FIELDS))
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _check_realisations(realisations: Sequence[str]) -> None:
    """Refuse names that are not registered hardware realisations (``--realisations``)."""
    from ..realise.registry import realisation_names

    unknown = [r for r in realisations if r not in realisation_names() or r in ("learned", "delta")]
    if unknown:
        raise InputError(
            f"--realisations {unknown}: unknown; allowed: "
            f"{[r for r in realisation_names() if r not in ('learned', 'delta')]}"
        )


def _design_threshold(design: Any) -> float:
    """The design's contrast threshold (log units); its ON and OFF thresholds must be equal."""
    sensor_section = design.section("sensor")
    if sensor_section["threshold_on"] != sensor_section["threshold_off"]:
        raise InputError(
            f"sensor.threshold_on={sensor_section['threshold_on']} != threshold_off="
            f"{sensor_section['threshold_off']}; allowed: equal thresholds"
        )
    return float(sensor_section["threshold_on"])


def _condition_evidence(
    name: str,
    kernel: Kernel | None,
    threshold: float,
    sensor: Any,
    scene: Any,
    truth: np.ndarray,
    x_edges: np.ndarray,
    options: InformationOptions,
    out: Path,
    bar: Any,
) -> ConditionEvidence:
    """One condition's evidence: loaded from ``out/evidence`` when its fingerprint matches, else measured.

    Measuring trains (or resumes) ``options.n_networks`` networks in ``out/networks`` and scores
    them (:func:`_score`); the evidence and its fingerprint are then saved.

    Parameters
    ----------
    name : str
        The condition.
    kernel : Kernel or None
        None: w/o (1×1 delta).
    threshold : float
        ON = OFF contrast threshold (log units).
    sensor : SensorConfig
        The simulator at that threshold.
    scene : SceneConfig
    truth : ndarray
        Ground truth of the test clips.
    x_edges : ndarray
        Its MI bin edges (shared by every condition).
    options : InformationOptions
    out : path
        The study's output folder.
    bar : progress bar
        Advanced by one per network.

    Returns
    -------
    ConditionEvidence
    """
    file = out / "evidence" / f"{_slug(name)}.npz"
    fp = _fingerprint(
        taps=None if kernel is None else np.asarray(kernel.taps).round(15).tolist(),
        sensor=sensor.to_dict(),
        n=[options.n_networks, options.n_train, options.n_test, options.epochs, options.width, options.n_bins],
    )
    stamp = Path(str(file) + ".fingerprint")
    if file.is_file() and stamp.is_file() and stamp.read_text().strip() == fp:
        bar.update(options.n_networks)
        return ConditionEvidence.from_npz(file)
    ckpts = []
    for s in range(options.n_networks):
        ckpts.append(_train(name, kernel, sensor, scene, s, options, out / "networks"))
        bar.update(1)
    evidence = _score(name, kernel, threshold, ckpts, scene, truth, x_edges, options.n_bins)
    write_output(file, evidence.to_npz())
    write_output(stamp, fp + "\n")
    return evidence


def _study_settings(
    options: InformationOptions,
    design: Any,
    scene: Any,
    conditions: list[str],
    t_ref: float,
    matched: float | None,
    matched_record: dict[str, Any] | None,
) -> dict[str, Any]:
    """The ``settings`` of ``information.json``: what was measured, how, and the networks' files.

    Parameters
    ----------
    options : InformationOptions
    design : Design
    scene : SceneConfig
    conditions : list of str
    t_ref : float
        The design's threshold (log units).
    matched, matched_record
        The matched w/o threshold (log units) and its record, or None.

    Returns
    -------
    dict
    """
    from ..tasks.learn import TEST_SEED

    seeds = range(options.n_networks)
    return {
        "design": str(options.design),
        "conditions": conditions,
        "reference_threshold": t_ref,
        "matched_threshold": matched,
        "matched_rate": matched_record,
        "n_networks": options.n_networks,
        "training_seeds": list(seeds),
        "n_train": options.n_train,
        "n_test": options.n_test,
        "test_seed": TEST_SEED,
        "epochs": options.epochs,
        "width": options.width,
        "scene": scene.to_dict(),
        "sensor": _sensor_for(design, scene).to_dict(),
        "estimator": f"equal-mass {options.n_bins}x{options.n_bins} joint histogram, plug-in entropies "
        "(scipy.stats.entropy), Miller-Madow correction; ground truth = noise-free last frame",
        "mi_unit": MI_UNIT,
        "rate_unit": EVENT_RATE_UNIT,
        "n_resamples": options.n_resamples,
        "confidence": options.confidence,
        "bootstrap": BOOTSTRAP_METHOD,
        "networks": {n: [f"{_slug(n)}_s{s}.safetensors" for s in seeds] for n in conditions},
    }


def run_information_study(options: InformationOptions) -> InformationStudy:
    """Train reconstruction networks per kernel condition and measure MI and bits per event with CIs.

    Parameters
    ----------
    options : InformationOptions

    Returns
    -------
    InformationStudy

    Raises
    ------
    InputError
        Unknown realisation, a design with unequal ON/OFF thresholds, a matched rate outside the
        measured w/o rates, an unwritable ``out``.

    Examples
    --------
    >>> study = run_information_study(InformationOptions(design=Path("designs/default.toml"),
    ...                                                  out=Path("out/info")))  # doctest: +SKIP
    >>> print(study.text)  # doctest: +SKIP
    """
    from ..design import load_design
    from ..resources import resolve_design
    from ..scenes.synthetic import make_scenes
    from ..tasks.learn import TEST_SEED
    from ..tasks.reconstruction import ReconstructionEvaluator, clean_last_frame

    if not isinstance(options, InformationOptions):
        raise InputError(f"run_information_study: options must be InformationOptions, got {type(options).__name__}")
    _check_realisations(options.realisations)
    design = load_design(resolve_design(options.design))
    t_ref = _design_threshold(design)
    out = output_dir(options.out, flag="--out")
    for sub in ("networks", "evidence", "kernels"):
        (out / sub).mkdir(exist_ok=True)
    scene = ReconstructionEvaluator().default_scene()
    conditions: dict[str, tuple[Kernel | None, float]] = {"w/o": (None, t_ref), "learned": (design.target, t_ref)}
    for name in options.realisations:
        conditions[name] = (_realisation_kernel(name, design, out / "kernels"), t_ref)
    matched, matched_record = None, None
    if options.matched_rate:
        matched, matched_record = _matched_threshold(
            design, scene, design.target, options.n_test, options.rate_thresholds, out
        )
        conditions[MATCHED] = (None, matched)
    truth = clean_last_frame(make_scenes(scene, options.n_test, seed=TEST_SEED))
    x_edges = quantile_edges(truth, options.n_bins)
    evidence: dict[str, ConditionEvidence] = {}
    with progress_bar(
        total=len(conditions) * options.n_networks, desc="information", unit="network", progress=options.progress
    ) as bar:
        for name, (kernel, threshold) in conditions.items():
            sensor = _sensor_for(design, scene, threshold)
            evidence[name] = _condition_evidence(
                name, kernel, threshold, sensor, scene, truth, x_edges, options, out, bar
            )
    rows = information_table(
        list(evidence.values()), confidence=options.confidence, n_resamples=options.n_resamples, rng=0
    )
    vs_matched = []
    if MATCHED in evidence:
        vs_matched = [
            {k: r[k] for k in MATCHED_FIELDS}
            for r in information_table(
                list(evidence.values()),
                reference=MATCHED,
                confidence=options.confidence,
                n_resamples=options.n_resamples,
                rng=0,
            )
        ]
    settings = _study_settings(options, design, scene, list(conditions), t_ref, matched, matched_record)
    provenance = {
        "command": options.command,
        "versions": library_versions(),
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    }
    files = {
        "information.json": write_output(
            out / "information.json",
            json.dumps(
                {"settings": settings, "rows": rows, "vs_matched_rate": vs_matched, "provenance": provenance},
                indent=1,
                default=str,
            ),
        ),
        "information.csv": write_output(out / "information.csv", _csv(rows)),
    }
    return InformationStudy(
        rows=rows, conditions=evidence, matched_threshold=matched, files=files, vs_matched=vs_matched
    )
