"""Score a realisation: kernel error, CSF agreement, task accuracy, hardware cost and wall times.

:func:`fit_realisation` builds one realisation of a target kernel by name (the ideal references
``"learned"`` and ``"delta"``, or the hardware fits ``"mesh"``, ``"asic"``, ``"metalens"`` through
:data:`~fsdvs_hw.explore.design.REALISATION_FITTERS`); :func:`score` measures it. A score is a
flat, JSON-ready record so that the results store, the CSV/JSON tables and the report all read
the same thing.

What is measured
----------------
kernel error
    :func:`fsdvs_hw.realise.base.realised_kernel_error`: the realisation's own error (the one
    definition: what the sensor applies, whole mesh response, metalens pedestal included) against
    the target, as is and with the least-squares gain (a gain folded into the threshold is free).
CSF agreement
    :func:`fsdvs_hw.csf.csf_agreement` for each requested CSF model (Mannos–Sakrison 1974 first)
    at the design's optics geometry (pixel pitch and focal length set pixels per degree), and
    for Mannos–Sakrison once more with the pixels-per-degree scale fitted (``fitted_scale``):
    the shape agreement at the best viewing geometry, which is what the FS-DVS paper compares.
task accuracy
    The task evaluators' metric (``fsdvs_hw.tasks.evaluate_kernel``) with the realised kernel
    swapped zero-shot into the network trained with the learned kernel; the loss against the
    learned kernel is computed by :func:`accuracy_losses` once the learned row exists. When the
    tasks module or a checkpoint is missing, the score says so (``status``) instead of a number.
sensor-in-the-loop emulation
    The realised kernel applied to synthetic video, shown on an emulated display and recaptured by
    the noisy simulator, compared with the kernel inside the pixel
    (:mod:`fsdvs_hw.explore.emulation`).
costs and wall times
    The realisation's :meth:`cost` items with units, and the seconds spent fitting, analysing and
    evaluating.
"""

from __future__ import annotations

import importlib
import inspect
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..kernels import Kernel, reference_kernel
from ..realise.base import Realisation, ReferenceRealisation, realised_kernel_error
from .design import REALISATION_FITTERS, REFERENCE_REALISATIONS

__all__ = [
    "RealisationUnavailable",
    "fit_realisation",
    "score",
    "task_scores",
    "accuracy_losses",
    "PRIMARY_CSF_METHOD",
]

#: The CSF model every headline number refers to (the FS-DVS paper's reference).
PRIMARY_CSF_METHOD = "mannos_sakrison_1974"


class RealisationUnavailable(InputError):
    """A realisation's module is not part of this installation; the point is reported as skipped."""


def fit_realisation(name: str, target: Kernel, options: Mapping[str, Any] | None = None, *,
                    seed: int = 0) -> tuple[Realisation, float]:
    """Fit one realisation of ``target`` by name.

    Parameters
    ----------
    name : {"learned", "delta", "mesh", "asic", "metalens"}
        ``learned``: the target applied ideally; ``delta``: the "w/o" baseline (no filter);
        the others call the fit function in :data:`REALISATION_FITTERS`.
    target : Kernel
        The kernel to realise (pitch in metres is passed on as ``pitch_m`` where the fitter takes it).
    options : mapping, optional
        Keyword options of the fit function (from ``[realisations.<name>]``).
    seed : int
        Passed as ``seed`` where the fitter takes one.

    Returns
    -------
    realisation, fit_wall_s
        The realisation and the seconds its fit took.

    Raises
    ------
    RealisationUnavailable
        The fitter's module is not installed in this checkout.
    """
    options = dict(options or {})
    t0 = time.perf_counter()
    if name == "learned":
        real: Realisation = ReferenceRealisation(target, label="learned")
    elif name == "delta":
        real = ReferenceRealisation(reference_kernel("delta", target.size, pitch_m=target.pitch_m), label="delta")
    elif name in REALISATION_FITTERS:
        module, func = REALISATION_FITTERS[name].split(":")
        try:
            fitter = getattr(importlib.import_module(module), func)
        except (ImportError, AttributeError) as exc:
            raise RealisationUnavailable(f"realisation {name!r}: {module}.{func} is not available ({exc})") from None
        params = inspect.signature(fitter).parameters
        if "pitch_m" in params and "pitch_m" not in options:
            options["pitch_m"] = target.pitch_m
        if "seed" in params and "seed" not in options:
            options["seed"] = seed
        real = fitter(target, **options)
    else:
        allowed = ", ".join([*REFERENCE_REALISATIONS, *REALISATION_FITTERS])
        raise InputError(f"realisation {name!r} unknown; allowed: {allowed}")
    return real, time.perf_counter() - t0


def _csf_scores(kernel: Kernel, methods: Sequence[str], focal_length_m: float) -> dict[str, Any]:
    try:
        from ..csf import Geometry, csf_agreement
    except ImportError as exc:
        return {"status": f"unavailable: fsdvs_hw.csf not importable ({exc})"}
    geometry = Geometry(pitch_m=kernel.pitch_m, focal_length_m=focal_length_m)
    out: dict[str, Any] = {"status": "ok"}
    for m in methods:
        out[m] = dict(csf_agreement(kernel, method=m, geometry=geometry).to_dict())
    # shape agreement at the best viewing geometry (the paper compares shapes, not absolute scale)
    out["fitted_scale"] = dict(csf_agreement(kernel, method=PRIMARY_CSF_METHOD).to_dict())
    return out


def _spectral(kernel: Kernel) -> dict[str, Any]:
    try:
        from ..spectra import spectral_summary
    except ImportError as exc:
        return {"status": f"unavailable: fsdvs_hw.spectra not importable ({exc})"}
    return {"status": "ok", **spectral_summary(kernel).to_dict()}


#: Fields of the design's ``[sensor]`` section that replace a checkpoint's simulator settings.
_DESIGN_SENSOR_FIELDS = ("threshold_on", "threshold_off", "threshold_sigma", "placement", "positivity")


def _task_sensor(checkpoint: Path, design_sensor: Mapping[str, Any] | None) -> tuple[Any, dict[str, Any]]:
    """The SensorConfig for a task evaluation (None = the checkpoint's) and a record of what it is."""
    if design_sensor is None:
        try:
            from ..tasks.learn import load_checkpoint

            settings = dict(load_checkpoint(checkpoint)[0].get("sensor", {}))
        except (ImportError, InputError):  # the evaluator itself will say what is wrong
            return None, {"source": "checkpoint"}
        return None, {"source": "checkpoint", **{k: settings.get(k) for k in _DESIGN_SENSOR_FIELDS}}
    from ..sensor import SensorConfig
    from ..tasks.learn import load_checkpoint

    settings = dict(load_checkpoint(checkpoint)[0].get("sensor", {}))

    settings.update({k: design_sensor[k] for k in _DESIGN_SENSOR_FIELDS})
    return SensorConfig(**settings), {"source": "design", **{k: settings[k] for k in _DESIGN_SENSOR_FIELDS}}


def task_scores(kernel: Kernel, checkpoints: Mapping[str, str | Path], *, n_test: int = 0,
                finetune_epochs: int = 0, tracks: Sequence[str] = ("simulator",),
                design_sensor: Mapping[str, Any] | None = None, display: Any = None) -> dict[str, Any]:
    """Evaluate ``kernel`` on each trained task by a zero-shot swap into its frozen network.

    Parameters
    ----------
    kernel : Kernel
        The realised kernel.
    checkpoints : mapping
        Task name → checkpoint written by ``fsdvs_hw.tasks.learn_kernel``.
    n_test : int
        Test clips (0 = the checkpoint's own test-set size).
    finetune_epochs : int
        Optional fine-tune of the network with the kernel frozen (0 = zero-shot).
    tracks : sequence of {"simulator", "emulation"}
        ``simulator``: ``evaluate_kernel`` with the checkpoint's simulator settings.
        ``emulation``: the sensor-in-the-loop emulation — the test clips are filtered by the
        kernel, shown on ``display`` and recaptured by the same simulator without an in-pixel
        filter (:func:`fsdvs_hw.explore.emulation.recapture`), then fed to the same frozen network.
    display : DisplaySettings, optional
        The emulation track's display (default ``DisplaySettings()``).
    design_sensor : mapping, optional
        A design's ``[sensor]`` section: its thresholds, mismatch, placement and positivity replace
        the checkpoint's simulator settings. None (default) evaluates under the checkpoint's own
        settings. Each result records which (``"sensor"``).

    Returns
    -------
    dict
        ``{"status": ..., task: {track: {"metric": value, "metrics": {...}, ...}}}``; ``status``
        names what is missing (tasks module, checkpoint, track) instead of inventing a number.
    """
    if not checkpoints:
        return {"status": "not requested"}
    try:
        tasks_mod = importlib.import_module("fsdvs_hw.tasks")
        evaluate_kernel = tasks_mod.evaluate_kernel
    except (ImportError, AttributeError) as exc:
        return {"status": f"unavailable: fsdvs_hw.tasks.evaluate_kernel not importable ({exc})"}
    sig = inspect.signature(evaluate_kernel).parameters
    out: dict[str, Any] = {"status": "ok"}
    for task, ckpt in checkpoints.items():
        out[task] = {}
        for track in tracks:
            kw: dict[str, Any] = {}
            if n_test and "n_test" in sig:
                kw["n_test"] = n_test
            if finetune_epochs and "finetune_epochs" in sig:
                kw["finetune_epochs"] = finetune_epochs
            if track == "emulation":
                if "events_fn" not in sig:
                    out[task][track] = {"status": f"unavailable: evaluate_kernel has no {track!r} track hook"}
                    out["status"] = "partial"
                    continue
                kw["events_fn"] = _recaptured_events(kernel, display)
            elif track != "simulator":
                raise InputError(f"task track {track!r} unknown; allowed 'simulator', 'emulation'")
            t0 = time.perf_counter()
            try:
                sensor_cfg, sensor_rec = _task_sensor(Path(ckpt), design_sensor)
                if sensor_cfg is not None:
                    kw["sensor"] = sensor_cfg
                res = evaluate_kernel(kernel, task, Path(ckpt), **kw)
            except (InputError, FileNotFoundError, ImportError) as exc:
                out[task][track] = {"status": f"unavailable: {exc}"}
                out["status"] = "partial"
                continue
            out[task][track] = {"status": "ok", **_metric_dict(res), "sensor": sensor_rec,
                                "wall_s": time.perf_counter() - t0}
    return out


def _recaptured_events(kernel: Kernel, display: Any) -> Any:
    """``events_fn`` for ``evaluate_kernel``: the sensor-in-the-loop emulation of ``kernel``."""
    from .emulation import DisplaySettings, recapture

    shown = display if display is not None else DisplaySettings()

    def events_fn(video: Any, _kernel_taps: Any, sensor: Any, timestamps_s: Any) -> Any:
        frames, _ = recapture(video, np.asarray(timestamps_s, dtype=np.float64), kernel, display=shown, sensor=sensor)
        return frames

    return events_fn


def _metric_dict(res: Any) -> dict[str, Any]:
    """Normalise what an evaluator returns (a float, a dict, or an object with to_dict)."""
    if isinstance(res, (int, float, np.floating)):
        return {"metric": float(res)}
    if hasattr(res, "to_dict"):
        res = res.to_dict()
    elif not isinstance(res, Mapping) and hasattr(res, "__dict__"):
        res = vars(res)
    d = {k: (float(v) if isinstance(v, (int, float, np.floating)) and not isinstance(v, bool) else v)
         for k, v in dict(res).items()}
    if "metric" not in d:
        for k in ("value", "map", "top1", "miou", "score"):
            if k in d:
                d["metric"] = d[k]
                break
    return d


def score(realisation: Realisation, *, target: Kernel, csf_methods: Sequence[str] = (PRIMARY_CSF_METHOD,),
          focal_length_m: float = 4.0e-3, checkpoints: Mapping[str, str | Path] | None = None,
          task_options: Mapping[str, Any] | None = None, emulation: Mapping[str, Any] | None = None,
          fit_wall_s: float = float("nan")) -> dict[str, Any]:
    """Score one realisation against its target.

    Parameters
    ----------
    realisation : Realisation
        Anything satisfying :class:`fsdvs_hw.realise.base.Realisation`.
    target : Kernel
        The kernel the realisation was fitted to (the learned kernel).
    csf_methods : sequence of str
        CSF models to compare with (names of :data:`fsdvs_hw.csf.CSF_METHODS`).
    focal_length_m : float
        Imaging focal length in metres; with the pixel pitch it sets pixels per degree.
    checkpoints : mapping, optional
        Task name → trained checkpoint; empty or None for no task evaluation.
    task_options : mapping, optional
        ``n_test``, ``finetune_epochs``, ``tracks`` for :func:`task_scores`.
    emulation : mapping, optional
        ``{"sensor": [sensor] section, "emulation": [emulation] section, "seed": int}`` to score the
        sensor-in-the-loop emulation track (:func:`fsdvs_hw.explore.emulation.emulation_scores`).
    fit_wall_s : float
        Seconds the realisation's fit took (recorded as given).

    Returns
    -------
    dict
        ``kind, label, describe, kernel (dict), kernel_error, kernel_error_gain_free, dc_gain,
        asymmetry, spectral {...}, csf {method: {...}}, cost {name: {value, unit, description}},
        tasks {...}, wall_s {fit, analysis, tasks}``.
    """
    realised = realisation.kernel()
    t0 = time.perf_counter()
    label = getattr(realisation, "label", realisation.kind)
    rec: dict[str, Any] = {
        "kind": realisation.kind,
        "label": label,
        "describe": realisation.describe(),
        "kernel": realised.to_dict(),
        "kernel_error": realised_kernel_error(realisation, target),
        "kernel_error_gain_free": realised_kernel_error(realisation, target, fit_scale=True),
        "dc_gain": realised.dc_gain,
        "asymmetry": realised.asymmetry(),
        "spectral": _spectral(realised),
        "csf": _csf_scores(realised, list(csf_methods), focal_length_m),
        "cost": {k: v.to_dict() for k, v in realisation.cost().items()},
    }
    t1 = time.perf_counter()
    opts = dict(task_options or {})
    if "emulation" in opts.get("tracks", ()) and emulation is not None and "display" not in opts:
        from .emulation import DisplaySettings

        opts["display"] = DisplaySettings.from_design(emulation["emulation"])
    rec["tasks"] = task_scores(realised, dict(checkpoints or {}), **opts)
    t2 = time.perf_counter()
    if emulation is not None and emulation["emulation"].get("enabled", True):
        from .emulation import emulation_scores

        rec["emulation"] = emulation_scores(realised, sensor=emulation["sensor"], emulation=emulation["emulation"],
                                            seed=int(emulation.get("seed", 0)))
    else:
        rec["emulation"] = {"status": "not requested"}
    rec["wall_s"] = {"fit": float(fit_wall_s), "analysis": t1 - t0, "tasks": t2 - t1,
                     "emulation": time.perf_counter() - t2}
    return rec


def accuracy_losses(rows: Iterable[Mapping[str, Any]], *, reference: str = "learned") -> dict[str, dict[str, float]]:
    """Task metric loss of every row against the ``reference`` row (learned kernel).

    Parameters
    ----------
    rows : iterable of mappings
        Stored points with ``key``, ``realisation`` and ``result`` (a :func:`score` record).

    Returns
    -------
    dict
        ``{row key: {"task/track": metric(reference) - metric(row)}}``; positive = accuracy lost.
        Rows without a reference or without task metrics map to ``{}``.
    """
    rows = list(rows)
    ref = next((r for r in rows if r["realisation"] == reference and r.get("status") == "ok"), None)
    ref_metrics = _flat_metrics(ref["result"]) if ref is not None else {}
    out: dict[str, dict[str, float]] = {}
    for r in rows:
        m = _flat_metrics(r.get("result") or {})
        out[r["key"]] = {k: ref_metrics[k] - v for k, v in m.items() if k in ref_metrics}
    return out


def _flat_metrics(result: Mapping[str, Any]) -> dict[str, float]:
    tasks = result.get("tasks") or {}
    flat: dict[str, float] = {}
    for task, tracks in tasks.items():
        if not isinstance(tracks, Mapping):
            continue
        for track, res in tracks.items():
            if isinstance(res, Mapping) and isinstance(res.get("metric"), (int, float)):
                flat[f"{task}/{track}"] = float(res["metric"])
    return flat
