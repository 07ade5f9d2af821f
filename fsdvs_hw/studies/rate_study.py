"""The bandwidth-matched study of a design (phase 1, fixed networks): rate curves and matched differences.

:func:`run_rate_study` measures the rate curves (:func:`fsdvs_hw.explore.rate.rate_curve`) of the
plain DVS (w/o, 1×1 delta), the design's learned kernel and optionally its hardware realisations,
for one task, in the design's trained networks, and writes to ``out``:

``points/``
    One JSON file per finished (kernel, threshold) point, per-clip evidence included; a rerun
    with the same settings loads them instead of recomputing (resume).
``rate_curves.json`` / ``rate_curves.csv``
    One row per (kernel, threshold): event rate (events/pixel/s) and Mev/s at ``resolution_px``
    with 95 % CIs, the task metric with its CI, n clips, n networks.
``matched_rate.json``
    The comparisons, each a :class:`fsdvs_hw.explore.rate.MatchedRateDifference`, with the
    settings and provenance (command, library versions, date):

    * ``learned_vs_wo_at_learned_rate``: learned at the design's threshold minus w/o with its
      threshold moved to the learned kernel's event rate (the headline: the filter's gain over a
      plain DVS with a lowered threshold);
    * ``wo_vs_learned_at_wo_rate``: w/o at the design's threshold minus the learned kernel at the
      w/o rate (the learned gain at a plain DVS's bandwidth is minus this);
    * ``{realisation}_vs_wo_at_{realisation}_rate`` for each realisation asked for.
``interpolation_sensitivity.json`` / ``.csv`` (with ``interpolation_sensitivity=True``)
    Every comparison again under each interpolation of
    :data:`fsdvs_hw.explore.rate.INTERPOLATIONS` (linear, pchip, quadratic in log rate), with the
    same bootstrap resamples: how much a matched-rate difference depends on how the curve is read
    between its thresholds. A rerun on a finished ``out`` folder reuses ``points/`` (seconds).
"""

from __future__ import annotations

import csv
import datetime as _dt
import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..explore.rate import DEFAULT_THRESHOLDS, INTERPOLATIONS, RateCurve, matched_rate_difference, rate_curve
from ..paths import output_dir, write_output
from ..provenance import library_versions

__all__ = ["RateOptions", "RateStudy", "interpolation_sensitivity", "run_rate_study"]


@dataclass(frozen=True)
class RateOptions:
    """What :func:`run_rate_study` measures.

    Attributes
    ----------
    design : path
        TOML design (kernel, sensor, ``[tasks] checkpoints``).
    task : str
        One task of the design's checkpoints.
    out : path
        Output folder.
    thresholds : sequence of float
        ON = OFF contrast thresholds (log units); the design's threshold is added.
    n_networks : int or None
        The first N networks of the task (None: all).
    n_test : int or None
        Test clips per network (None: the design's ``tasks.n_test`` for the task, else the checkpoint's).
    realisations : sequence of str
        Hardware realisations to add (``"mesh"``, ``"asic"``, ``"metalens"``; fitted with the design's options).
    protocol : {"fixed", "retrained"}
        ``"fixed"``: every kernel zero-shot in the design's networks; ``"retrained"``: networks trained
        per kernel, threshold and seed (:mod:`fsdvs_hw.studies.rate_retrained`; w/o and learned only).
    seeds : sequence of int
        Training seeds of the retrained protocol (one network per seed and threshold).
    n_train : int
        Training clips per retrained network.
    zero_shot : bool
        Retrained protocol: also swap the learned kernel zero-shot into the w/o networks trained at the
        design's threshold, with its threshold swept (the paper's transfer experiment at matched rate).
    illuminance_lux : float or None
        Fixed protocol: add photon shot noise of the scene at this sensor-plane illuminance (lx) at
        full scale (:mod:`fsdvs_hw.sensor.simulation.photon_noise`, the design's pixel pitch, one frame interval
        of integration), and write ``noise_budget.json``/``.csv`` (:func:`fsdvs_hw.studies.noise_budget.noise_budget`:
        which noise fires the events at each threshold). None: no photon noise.
    quantum_efficiency : float
        Photoelectrons per photon for ``illuminance_lux``.
    resolution_px : (int, int)
        Sensor size for the Mev/s column (default 720 × 1280, the IMX636 whose pitch the design uses).
    n_resamples : int
        Bootstrap resamples per CI.
    confidence : float
    interpolation_sensitivity : bool
        Also write ``interpolation_sensitivity.json``/``.csv``: every comparison under each of
        :data:`fsdvs_hw.explore.rate.INTERPOLATIONS` (the headline comparisons stay linear).
    progress : bool or None
    command : str
        The command line, recorded in the provenance.
    """

    design: Path
    task: str
    out: Path
    thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS
    n_networks: int | None = None
    n_test: int | None = None
    realisations: tuple[str, ...] = ()
    protocol: str = "fixed"
    seeds: tuple[int, ...] = (0, 1, 2)
    n_train: int = 2048
    zero_shot: bool = False
    illuminance_lux: float | None = None
    quantum_efficiency: float = 0.5
    resolution_px: tuple[int, int] = (720, 1280)
    n_resamples: int = 2000
    confidence: float = 0.95
    interpolation_sensitivity: bool = False
    progress: bool | None = None
    command: str = ""


@dataclass(frozen=True)
class RateStudy:
    """What :func:`run_rate_study` measured: the curves, the comparisons and the files written."""

    curves: dict[str, RateCurve]
    comparisons: dict[str, Any]
    rows: list[dict[str, Any]]
    files: dict[str, Path]

    @property
    def text(self) -> str:
        """The comparisons, one line each."""
        return "\n".join(c.describe() for c in self.comparisons.values())


def _csv(rows: Sequence[dict[str, Any]]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def run_rate_study(options: RateOptions) -> RateStudy:
    """Measure the rate curves of a design's kernels for one task and compare them at matched rate.

    Parameters
    ----------
    options : RateOptions

    Returns
    -------
    RateStudy

    Raises
    ------
    InputError
        Unknown task, unequal ON/OFF thresholds in the design, bad counts, unknown realisation.
    """
    from ..design import load_design
    from ..explore.scoring import fit_realisation
    from ..resources import resolve_design

    design = load_design(resolve_design(options.design))
    if options.protocol == "retrained":
        return _retrained_study(design, options)
    if options.protocol != "fixed":
        raise InputError(f"--protocol {options.protocol!r}; allowed: 'fixed', 'retrained'")
    if options.zero_shot:
        raise InputError("--zero-shot needs networks trained on a plain DVS: allowed with --protocol retrained only")
    ckpts = design.checkpoints()
    if options.task not in ckpts:
        raise InputError(f"--task {options.task!r}: not in the design's tasks.checkpoints; allowed: {', '.join(ckpts)}")
    paths = ckpts[options.task]
    if options.n_networks is not None:
        if not 1 <= options.n_networks <= len(paths):
            raise InputError(
                f"--networks {options.n_networks}: allowed 1..{len(paths)} (the design's {options.task} networks)"
            )
        paths = paths[: options.n_networks]
    t_ref, thresholds = _thresholds(design, options)
    n_test = options.n_test
    if n_test is None:
        n_test = design.n_test(options.task)
    tasks = design.spec.tasks
    design_sensor = design.section("sensor") if tasks.sensor == "design" else None
    test_clips = tasks.test_clips
    out = output_dir(options.out, flag="--out")
    photon = _photon_noise(options, design, paths[0])
    common: dict[str, Any] = dict(
        n_test=n_test,
        design_sensor=design_sensor,
        test_clips=test_clips,
        cache_dir=out / "points",
        progress=options.progress,
        events_fn=photon,
    )
    kernels: dict[str, Any] = {"w/o": None, "learned": design.target}
    for name in options.realisations:
        real, _ = fit_realisation(name, design.target, design.realisation_options(name), seed=design.spec.run.seed)
        kernels[name] = real.kernel()
    curves = {name: rate_curve(k, options.task, paths, thresholds, label=name, **common) for name, k in kernels.items()}
    pairs = {
        "learned_vs_wo_at_learned_rate": (curves["w/o"], curves["learned"]),
        "wo_vs_learned_at_wo_rate": (curves["learned"], curves["w/o"]),
    }
    for name in options.realisations:
        pairs[f"{name}_vs_wo_at_{name}_rate"] = (curves["w/o"], curves[name])
    comparisons = _compare(pairs, t_ref, options)
    settings = {
        "design": str(options.design),
        "task": options.task,
        "thresholds": list(thresholds),
        "reference_threshold": t_ref,
        "n_networks": len(paths),
        "n_test_per_network": n_test,
        "test_clips": test_clips,
        "sensor": "design" if design_sensor else "checkpoint",
        "networks": [p.name for p in paths],
        "resolution_px": list(options.resolution_px),
        "n_resamples": options.n_resamples,
        "confidence": options.confidence,
        "protocol": "fixed networks (phase 1): every kernel zero-shot in the shipped networks trained with "
        "the learned kernel",
        "photon_noise": None
        if photon is None
        else {
            "illuminance_lux": options.illuminance_lux,
            "quantum_efficiency": options.quantum_efficiency,
            "photoelectrons_full_scale": photon.photoelectrons_full_scale,
            "pitch_m": float(design.spec.sensor.pitch_m),
            "model": "Poisson photoelectrons per frame interval before the kernel (fsdvs_hw.sensor.simulation.photon_noise)",
        },
    }
    study = _write_study(options, out, curves, comparisons, settings)
    if options.interpolation_sensitivity:
        study.files.update(_write_sensitivity(options, out, pairs, t_ref, settings))
    if photon is not None:
        study.files.update(
            _write_noise_budget(options, out, design.target, paths[0], thresholds, photon, n_test or 64, settings)
        )
    return study


def _photon_noise(options: RateOptions, design: Any, checkpoint: Path) -> Any:
    """The photon-noise ``events_fn`` of ``--illuminance-lux`` (None without it)."""
    if options.illuminance_lux is None:
        return None
    from ..sensor.simulation.photon_noise import PhotonNoise, photoelectrons_per_frame
    from ..tasks.checkpoints import load_checkpoint

    fps = float(load_checkpoint(checkpoint)[0]["scene"].get("frame_rate_hz", 100.0))
    n = photoelectrons_per_frame(
        illuminance_lux=options.illuminance_lux,
        pitch_m=float(design.spec.sensor.pitch_m),
        quantum_efficiency=options.quantum_efficiency,
        frame_interval_s=1.0 / fps,
    )
    return PhotonNoise(photoelectrons_full_scale=n, seed=int(design.spec.run.seed))


def _write_noise_budget(
    options: RateOptions,
    out: Path,
    target: Any,
    checkpoint: Path,
    thresholds: Sequence[float],
    photon: Any,
    n_test: int,
    settings: dict[str, Any],
) -> dict[str, Path]:
    from .noise_budget import noise_budget

    rows = [
        {"kernel": name, **r}
        for name, k in (("w/o", None), ("learned", target))
        for r in noise_budget(
            k,
            options.task,
            checkpoint,
            thresholds,
            photoelectrons_full_scale=photon.photoelectrons_full_scale,
            n_test=n_test,
            seed=photon.seed,
        )
    ]
    meta = {
        "settings": settings,
        "checkpoint": checkpoint.name,
        "n_clips": n_test,
        "provenance": {
            "command": options.command,
            "versions": library_versions(),
            "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        },
    }
    return {
        "noise_budget.json": write_output(out / "noise_budget.json", json.dumps({**meta, "rows": rows}, indent=1)),
        "noise_budget.csv": write_output(out / "noise_budget.csv", _csv(rows)),
    }


def _write_study(
    options: RateOptions, out: Path, curves: dict[str, RateCurve], comparisons: dict[str, Any], settings: dict[str, Any]
) -> RateStudy:
    rows = [
        r
        for c in curves.values()
        for r in c.summary(
            confidence=options.confidence, n_resamples=options.n_resamples, rng=0, resolution_px=options.resolution_px
        )
    ]
    provenance = {
        "command": options.command,
        "versions": library_versions(),
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    }
    files = {
        "rate_curves.json": write_output(
            out / "rate_curves.json",
            json.dumps({"settings": settings, "rows": rows, "provenance": provenance}, indent=1),
        ),
        "rate_curves.csv": write_output(out / "rate_curves.csv", _csv(rows)),
        "matched_rate.json": write_output(
            out / "matched_rate.json",
            json.dumps(
                {
                    "settings": settings,
                    "comparisons": {k: v.to_dict() for k, v in comparisons.items()},
                    "provenance": provenance,
                },
                indent=1,
                default=str,
            ),
        ),
    }
    return RateStudy(curves=curves, comparisons=comparisons, rows=rows, files=files)


def _compare(pairs: dict[str, tuple[RateCurve, RateCurve]], t_ref: float, options: RateOptions) -> dict[str, Any]:
    """``matched_rate_difference(curve, reference, t_ref)`` (linear) for every named (curve, reference) pair."""
    kw: dict[str, Any] = dict(confidence=options.confidence, n_resamples=options.n_resamples, rng=0)
    return {name: matched_rate_difference(curve, ref, t_ref, **kw) for name, (curve, ref) in pairs.items()}


def interpolation_sensitivity(
    pairs: dict[str, tuple[RateCurve, RateCurve]],
    reference_threshold: float,
    *,
    confidence: float = 0.95,
    n_resamples: int = 2000,
    rng: int = 0,
) -> list[dict[str, Any]]:
    """Every comparison under each interpolation of :data:`~fsdvs_hw.explore.rate.INTERPOLATIONS`.

    Parameters
    ----------
    pairs : dict of str to (RateCurve, RateCurve)
        Comparison name → (curve read at the matched rate, reference), as in ``matched_rate.json``.
    reference_threshold : float
        The references' operating threshold (log units).
    confidence : float
        Two-sided CI level in (0, 1).
    n_resamples : int
        Bootstrap resamples; the same resamples (seed ``rng``) for every interpolation.
    rng : int
        Seed of the resamples.

    Returns
    -------
    list of dict
        One row per (comparison, interpolation): ``comparison``, ``interpolation``, ``status``,
        ``estimate``/``low``/``high`` (metric units, fraction), ``shift_vs_linear`` (estimate minus
        the linear estimate), ``matched_threshold`` (log units), ``n_clips``, ``n_networks``,
        ``confidence``, ``metric_name``, ``task``. A curve with too few points for an
        interpolation (quadratic needs 3) gives a row whose ``status`` says so, with NaN numbers.

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw.explore.rate import RateCurve, RatePoint
    >>> from fsdvs_hw.stats import ClipMeans
    >>> def curve(name, ts, rates, metrics):
    ...     pts = tuple(RatePoint(threshold=t, metrics=(ClipMeans(np.full(4, m)),),
    ...                           clip_rates=np.full((1, 4), r), test_seeds=(0,), sensor_seeds=(0,))
    ...                 for t, r, m in zip(ts, rates, metrics))
    ...     return RateCurve(kernel_name=name, task="recognition", metric_name="top1",
    ...                      test_clips="per_network", points=pts)
    >>> wo = curve("w/o", [0.1, 0.2, 0.3], [np.e**2, np.e, 1.0], [0.0, 1.0, 0.0])
    >>> learned = curve("learned", [0.2], [np.e**1.5], [1.0])
    >>> rows = interpolation_sensitivity({"learned_vs_wo": (wo, learned)}, 0.2, n_resamples=100)
    >>> [(r["interpolation"], round(r["estimate"], 3)) for r in rows]
    [('linear', 0.5), ('pchip', 0.25), ('quadratic', 0.25)]
    """
    rows: list[dict[str, Any]] = []
    for name, (curve, ref) in pairs.items():
        linear = math.nan
        for how in INTERPOLATIONS:
            base = {"comparison": name, "interpolation": how, "task": curve.task, "metric_name": curve.metric_name}
            if how == "quadratic" and len(curve.points) < 3:
                nan = math.nan
                rows.append(
                    {
                        **base,
                        "status": f"not computed: quadratic needs 3 points, the curve of {curve.kernel_name!r} "
                        f"has {len(curve.points)}",
                        "estimate": nan,
                        "low": nan,
                        "high": nan,
                        "shift_vs_linear": nan,
                        "matched_threshold": nan,
                        "n_clips": curve.n_clips,
                        "n_networks": curve.n_networks,
                        "confidence": confidence,
                    }
                )
                continue
            d = matched_rate_difference(
                curve,
                ref,
                reference_threshold,
                confidence=confidence,
                n_resamples=n_resamples,
                rng=rng,
                interpolation=how,
            )
            if how == "linear":
                linear = d.estimate
            rows.append(
                {
                    **base,
                    "status": d.status,
                    "estimate": d.estimate,
                    "low": d.low,
                    "high": d.high,
                    "shift_vs_linear": d.estimate - linear,
                    "matched_threshold": d.matched_threshold,
                    "n_clips": d.n_clips,
                    "n_networks": d.n_networks,
                    "confidence": confidence,
                }
            )
    return rows


def _write_sensitivity(
    options: RateOptions,
    out: Path,
    pairs: dict[str, tuple[RateCurve, RateCurve]],
    t_ref: float,
    settings: dict[str, Any],
) -> dict[str, Path]:
    """``interpolation_sensitivity.json``/``.csv``: every comparison under each interpolation."""
    rows = interpolation_sensitivity(
        pairs, t_ref, confidence=options.confidence, n_resamples=options.n_resamples, rng=0
    )
    meta = {
        "settings": {
            **settings,
            "interpolations": list(INTERPOLATIONS),
            "interpolation_note": "x = ln(event rate); linear: np.interp (the default of matched_rate.json); "
            "pchip: scipy.interpolate.PchipInterpolator (monotone piecewise cubic); quadratic: the parabola "
            "through the two bracketing points and the nearer outer neighbour; the same interpolation in the "
            "estimate, the matched threshold and every bootstrap resample, the same resamples for all three",
        },
        "provenance": {
            "command": options.command,
            "versions": library_versions(),
            "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        },
    }
    return {
        "interpolation_sensitivity.json": write_output(
            out / "interpolation_sensitivity.json", json.dumps({**meta, "rows": rows}, indent=1)
        ),
        "interpolation_sensitivity.csv": write_output(out / "interpolation_sensitivity.csv", _csv(rows)),
    }


def _thresholds(design: Any, options: RateOptions) -> tuple[float, tuple[float, ...]]:
    """The design's operating threshold (ON = OFF, log units) and the study's thresholds with it."""
    sensor = design.spec.sensor
    if sensor.threshold_on != sensor.threshold_off:
        raise InputError(
            f"sensor.threshold_on={sensor.threshold_on} != threshold_off={sensor.threshold_off}: the "
            "rate curve sets both together; allowed: equal thresholds"
        )
    t_ref = float(sensor.threshold_on)
    return t_ref, tuple(sorted(set(options.thresholds) | {t_ref}))


def _retrained_study(design: Any, options: RateOptions) -> RateStudy:
    """The retrained protocol (and the zero-shot swap at matched rate) for one task."""
    from .rate_retrained import network_stem, networks_dir, retrained_rate_curve

    if options.illuminance_lux is not None:
        raise InputError(
            f"--illuminance-lux {options.illuminance_lux}: photon noise is measured with the fixed "
            "protocol only; allowed: --protocol fixed, or no --illuminance-lux"
        )
    if options.realisations:
        raise InputError(
            "--realisations: the retrained protocol trains networks for w/o and the learned kernel only; "
            "allowed: none (use the fixed protocol for realisations)"
        )
    t_ref, thresholds = _thresholds(design, options)
    n_test = options.n_test or 256
    out = output_dir(options.out, flag="--out")
    common: dict[str, Any] = dict(n_train=options.n_train, n_test=n_test, progress=options.progress)
    curves = {
        "w/o": retrained_rate_curve(None, options.task, thresholds, options.seeds, out, label="w/o", **common),
        "learned": retrained_rate_curve(
            design.target, options.task, thresholds, options.seeds, out, label="learned", **common
        ),
    }
    pairs = {
        "learned_vs_wo_at_learned_rate": (curves["w/o"], curves["learned"]),
        "wo_vs_learned_at_wo_rate": (curves["learned"], curves["w/o"]),
    }
    if options.zero_shot:  # the learned kernel swapped into the w/o networks trained at t_ref, threshold swept
        wo_nets = [
            networks_dir(out, options.n_train) / f"{network_stem('w/o', t_ref, s)}.safetensors" for s in options.seeds
        ]
        swap_ts = tuple(t for t in thresholds if t >= t_ref)
        curves["learned swapped into w/o networks"] = rate_curve(
            design.target,
            options.task,
            wo_nets,
            swap_ts,
            n_test=n_test,
            label="learned swapped into w/o networks",
            cache_dir=out / "points_zero_shot",
            progress=options.progress,
        )
        wo_point = RateCurve(
            kernel_name="w/o",
            task=options.task,
            metric_name=curves["w/o"].metric_name,
            test_clips="per_network",
            points=(curves["w/o"].point(t_ref),),
        )
        pairs["wo_vs_swapped_learned_at_wo_rate"] = (curves["learned swapped into w/o networks"], wo_point)
    comparisons = _compare(pairs, t_ref, options)
    settings = {
        "design": str(options.design),
        "task": options.task,
        "thresholds": list(thresholds),
        "reference_threshold": t_ref,
        "n_networks": len(options.seeds),
        "seeds": list(options.seeds),
        "n_train": options.n_train,
        "n_test_per_network": n_test,
        "test_clips": "per_network",
        "resolution_px": list(options.resolution_px),
        "n_resamples": options.n_resamples,
        "confidence": options.confidence,
        "protocol": "retrained: a network per kernel, threshold and seed, trained at that threshold with the "
        "kernel frozen (tasks.learn_kernel, shipped settings); network i scores clip set i with "
        "sensor seed offset i at every threshold"
        + (
            "; zero-shot: the learned kernel swapped into the w/o networks trained at the reference threshold"
            if options.zero_shot
            else ""
        ),
    }
    study = _write_study(options, out, curves, comparisons, settings)
    if options.interpolation_sensitivity:
        study.files.update(_write_sensitivity(options, out, pairs, t_ref, settings))
    return study
