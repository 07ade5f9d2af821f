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
"""

from __future__ import annotations

import csv
import datetime as _dt
import io
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..paths import output_dir, write_output
from ..provenance import library_versions
from .rate import DEFAULT_THRESHOLDS, RateCurve, matched_rate_difference, rate_curve

__all__ = ["RateOptions", "RateStudy", "run_rate_study"]


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
        per kernel, threshold and seed (:mod:`fsdvs_hw.explore.rate_retrained`; w/o and learned only).
    seeds : sequence of int
        Training seeds of the retrained protocol (one network per seed and threshold).
    n_train : int
        Training clips per retrained network.
    zero_shot : bool
        Retrained protocol: also swap the learned kernel zero-shot into the w/o networks trained at the
        design's threshold, with its threshold swept (the paper's transfer experiment at matched rate).
    illuminance_lux : float or None
        Fixed protocol: add photon shot noise of the scene at this sensor-plane illuminance (lx) at
        full scale (:mod:`fsdvs_hw.sensor.photon_noise`, the design's pixel pitch, one frame interval
        of integration), and write ``noise_budget.json``/``.csv`` (:func:`fsdvs_hw.explore.noise_budget.noise_budget`:
        which noise fires the events at each threshold). None: no photon noise.
    quantum_efficiency : float
        Photoelectrons per photon for ``illuminance_lux``.
    resolution_px : (int, int)
        Sensor size for the Mev/s column (default 720 × 1280, the IMX636 whose pitch the design uses).
    n_resamples : int
        Bootstrap resamples per CI.
    confidence : float
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
    from ..resources import resolve_design
    from .design import load_design
    from .scoring import fit_realisation

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
    kw: dict[str, Any] = dict(confidence=options.confidence, n_resamples=options.n_resamples, rng=0)
    comparisons = {
        "learned_vs_wo_at_learned_rate": matched_rate_difference(curves["w/o"], curves["learned"], t_ref, **kw),
        "wo_vs_learned_at_wo_rate": matched_rate_difference(curves["learned"], curves["w/o"], t_ref, **kw),
    }
    for name in options.realisations:
        comparisons[f"{name}_vs_wo_at_{name}_rate"] = matched_rate_difference(curves["w/o"], curves[name], t_ref, **kw)
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
            "model": "Poisson photoelectrons per frame interval before the kernel (fsdvs_hw.sensor.photon_noise)",
        },
    }
    study = _write_study(options, out, curves, comparisons, settings)
    if photon is not None:
        study.files.update(
            _write_noise_budget(options, out, design.target, paths[0], thresholds, photon, n_test or 64, settings)
        )
    return study


def _photon_noise(options: RateOptions, design: Any, checkpoint: Path) -> Any:
    """The photon-noise ``events_fn`` of ``--illuminance-lux`` (None without it)."""
    if options.illuminance_lux is None:
        return None
    from ..sensor.photon_noise import PhotonNoise, photoelectrons_per_frame
    from ..tasks.learn import load_checkpoint

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
    kw: dict[str, Any] = dict(confidence=options.confidence, n_resamples=options.n_resamples, rng=0)
    comparisons: dict[str, Any] = {
        "learned_vs_wo_at_learned_rate": matched_rate_difference(curves["w/o"], curves["learned"], t_ref, **kw),
        "wo_vs_learned_at_wo_rate": matched_rate_difference(curves["learned"], curves["w/o"], t_ref, **kw),
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
        comparisons["wo_vs_swapped_learned_at_wo_rate"] = matched_rate_difference(
            curves["learned swapped into w/o networks"], wo_point, t_ref, **kw
        )
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
    return _write_study(options, out, curves, comparisons, settings)
