"""Score a realisation: kernel error, CSF agreement, task accuracy, hardware cost and wall times.

:func:`fit_realisation` builds one realisation of a target kernel by its name in the registry
(:mod:`fsdvs_hw.realise.registry`: the ideal references ``"learned"`` and ``"delta"``, the hardware
fits ``"mesh"``, ``"asic"``, ``"metalens"``, and any realisation registered from outside the
package); :func:`score` measures it. A score is a typed :class:`fsdvs_hw.records.Score` whose
one serialisation (``to_dict``) the results store, the CSV/JSON tables and the report all read.

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
    Per clip, in every trained network of every task (one checkpoint per training seed), with the
    realised kernel swapped zero-shot into the network trained with the design's kernel
    (:mod:`fsdvs_hw.explore.paired`): every kernel sees the same clips, noise draws and mismatch
    patterns. Once every point has run, :func:`paired_losses` computes each point's loss against
    the learned row with a 95 % bootstrap CI over clips and seeds (:mod:`fsdvs_hw.stats`) and the
    weighted task loss (``[scoring] task_weights``). When a checkpoint or task is missing, the score
    says so (``status``) instead of a number.
sensor-in-the-loop emulation
    The realised kernel applied to synthetic video, shown on an emulated display and recaptured by
    the noisy simulator, compared with the kernel inside the pixel
    (:mod:`fsdvs_hw.explore.emulation`).
costs and wall times
    The realisation's :meth:`cost` items with units, and the seconds spent fitting, analysing and
    evaluating.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..csf import Geometry, csf_agreement
from ..errors import InputError
from ..kernels import Kernel
from ..realise.base import Realisation, realised_kernel_error
from ..realise.registry import fit_realisation as _fit_registered
from ..realise.registry import realisation_names
from ..records import Cost, Score, ScoredPoint, TaskScores, WallTimes
from ..spectra import spectral_summary

__all__ = [
    "PRIMARY_CSF_METHOD",
    "TRACK_PREFIX",
    "accuracy_losses",
    "fit_realisation",
    "paired_losses",
    "score",
    "task_scores",
    "with_paired_losses",
]

#: How a task's networks share test clips (:func:`task_scores`' ``test_clips``).
TEST_CLIPS: tuple[str, ...] = ("per_network", "shared")

#: Column prefix of each task track in the flat tables (the simulator track is unprefixed).
TRACK_PREFIX: dict[str, str] = {"simulator": "", "emulation": "emu_"}

#: The CSF model every headline number refers to (the FS-DVS paper's reference).
PRIMARY_CSF_METHOD = "mannos_sakrison_1974"


def fit_realisation(
    name: str, target: Kernel, options: Mapping[str, Any] | None = None, *, seed: int = 0
) -> tuple[Realisation, float]:
    """Fit one realisation of ``target`` by name.

    Parameters
    ----------
    name : str
        A registered realisation (:func:`fsdvs_hw.realise.registry.realisation_names`):
        ``learned``: the target applied ideally; ``delta``: the "w/o" baseline (no filter);
        the others call their registered fit function.
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
    InputError
        ``name`` is not registered, or an option is invalid.
    """
    t0 = time.perf_counter()
    real = _fit_registered(name, target, options, seed=seed)
    return real, time.perf_counter() - t0


def _csf_scores(kernel: Kernel, methods: Sequence[str], focal_length_m: float) -> dict[str, Any]:
    geometry = Geometry(pitch_m=kernel.pitch_m, focal_length_m=focal_length_m)
    out: dict[str, Any] = {"status": "ok"}
    for m in methods:
        out[m] = dict(csf_agreement(kernel, method=m, geometry=geometry).to_dict())
    # shape agreement at the best viewing geometry (the paper compares shapes, not absolute scale)
    out["fitted_scale"] = dict(csf_agreement(kernel, method=PRIMARY_CSF_METHOD).to_dict())
    return out


def _spectral(kernel: Kernel) -> dict[str, Any]:
    return {"status": "ok", **spectral_summary(kernel).to_dict()}


#: Fields of the design's ``[sensor]`` section that replace a checkpoint's simulator settings.
DESIGN_SENSOR_FIELDS = ("threshold_on", "threshold_off", "threshold_sigma", "placement", "positivity")


def task_sensor(checkpoint: Path, design_sensor: Mapping[str, Any] | None) -> tuple[Any, dict[str, Any]]:
    """The sensor a task evaluation runs and a record of what it is.

    Parameters
    ----------
    checkpoint : Path
        The task network's checkpoint (its own simulator settings are the default).
    design_sensor : mapping, optional
        The design's ``[sensor]`` settings; those in :data:`DESIGN_SENSOR_FIELDS` replace the
        checkpoint's. None: the checkpoint's sensor.

    Returns
    -------
    (SensorConfig or None, dict)
        The configuration (None = the checkpoint's) and ``{"source", <DESIGN_SENSOR_FIELDS>}``
        (thresholds in log units).
    """
    if design_sensor is None:
        try:
            from ..tasks.checkpoints import load_checkpoint

            settings = dict(load_checkpoint(checkpoint)[0].get("sensor", {}))
        except InputError:  # the evaluator itself will say what is wrong
            return None, {"source": "checkpoint"}
        return None, {"source": "checkpoint", **{k: settings.get(k) for k in DESIGN_SENSOR_FIELDS}}
    from ..sensor import SensorConfig
    from ..tasks.checkpoints import load_checkpoint

    settings = dict(load_checkpoint(checkpoint)[0].get("sensor", {}))

    settings.update({k: design_sensor[k] for k in DESIGN_SENSOR_FIELDS})
    return SensorConfig(**settings), {"source": "design", **{k: settings[k] for k in DESIGN_SENSOR_FIELDS}}


def task_scores(
    kernel: Kernel,
    checkpoints: Mapping[str, str | Path | Sequence[str | Path]],
    *,
    n_test: int | Mapping[str, int] = 0,
    n_test_emulation: int | Mapping[str, int] = 0,
    finetune_epochs: int = 0,
    tracks: Sequence[str] = ("simulator",),
    design_sensor: Mapping[str, Any] | None = None,
    display: Any = None,
    keep_evidence: bool = True,
    test_clips: str = "per_network",
    datasets: Mapping[str, Mapping[str, Any]] | None = None,
    base_dir: str | Path = ".",
) -> dict[str, Any]:
    """Evaluate ``kernel`` per clip in every trained network of every task (zero-shot swap).

    Parameters
    ----------
    kernel : Kernel
        The realised kernel.
    checkpoints : mapping
        Task name → checkpoint, or a list of checkpoints (one network per training seed), written
        by ``fsdvs_hw.tasks.learn_kernel``.
    n_test, n_test_emulation : int or mapping
        Test clips per network (0 = the checkpoint's own test-set size), for every task or per task;
        of the emulation track (0 = as ``n_test``: the first clips of the same test sets).
    finetune_epochs : int
        Must be 0: the paired per-clip scoring is zero-shot (a fine-tune would give every kernel
        its own network, and the loss would no longer be paired by network).
    tracks : sequence of {"simulator", "emulation"}
        ``simulator``: the in-pixel simulator with the checkpoint's settings. ``emulation``: the
        test clips filtered by the kernel, shown on ``display`` and recaptured by the same
        simulator without an in-pixel filter (:func:`fsdvs_hw.explore.emulation.recapture`), fed to
        the same frozen network.
    design_sensor : mapping, optional
        A design's ``[sensor]`` section: its thresholds, mismatch, placement and positivity replace
        the checkpoint's simulator settings (None: the checkpoint's own). Recorded as ``"sensor"``.
    display : DisplaySettings, optional
        The emulation track's display (default ``DisplaySettings()``).
    test_clips : {"per_network", "shared"}
        ``"per_network"`` (default): network ``s`` scores its own held-out clips (clip set ``s``,
        :func:`fsdvs_hw.explore.paired.clip_evidence`): clips nested in networks, so the same
        simulation budget samples many networks and mismatch patterns. ``"shared"``: every network
        scores the same clips (crossed).
    datasets : mapping, optional
        Task name → a validated ``[tasks.datasets.<task>]`` table: the task is scored on the user's
        clips with the user's network (:func:`fsdvs_hw.explore.user_data.dataset_evidence`), one
        network, so its CI resamples clips only (``n_seeds = 1``, said in ``"ci_note"``); its
        record names ``"dataset"`` and ``"network"`` instead of ``"checkpoints"``, and the clips
        skipped because they failed to read (``"failed_clips"``, ``"failed_clip_files"``,
        ``"failed_clip_indices"``, ``"n_clips_drawn"``; also on a task that failed because too many did).
    base_dir : path
        The design file's folder (the user datasets' ``root``, network imports and weights).
    keep_evidence : bool
        Keep each network's per-clip evidence (base64 ``.npz``, :func:`fsdvs_hw.explore.paired.encode_evidence`)
        under ``"evidence"`` so :func:`paired_losses` can pair it with the reference kernel's.

    Returns
    -------
    dict
        ``{"status", task: {track: record}}``: each record has the fields of
        :class:`fsdvs_hw.records.TrackScore` (``metric`` the mean over networks, ``n_clips`` the
        total, ``event_rate`` in events per pixel and frame interval, ``event_rate_unit``) and
        ``test_seeds``, ``checkpoints``, ``sensor_seeds``, ``evidence``, ``sensor`` and
        ``event_rate_per_s`` (events/pixel/s with its 95 % bootstrap CI over networks × clips,
        :func:`fsdvs_hw.explore.paired.event_rate_ci`: ``mean, low, high, unit, n_clips, n_networks``);
        ``status`` names what is missing instead of inventing a number. Network ``s`` of a task is
        scored with sensor seed ``checkpoint seed + s`` (its own mismatch pattern, :mod:`fsdvs_hw.explore.paired`).
    """
    datasets = dict(datasets or {})
    if not checkpoints and not datasets:
        return {"status": "not requested"}
    if test_clips not in TEST_CLIPS:
        raise InputError(f"test_clips {test_clips!r} unknown; allowed: {', '.join(TEST_CLIPS)}")
    out: dict[str, Any] = {"status": "ok"}
    entry: Any  # a checkpoint (or a list of them), or a user dataset's table
    for task, entry in [*checkpoints.items(), *datasets.items()]:
        user = task in datasets and entry is datasets[task]
        paths = [] if user else [Path(p) for p in (entry if isinstance(entry, (list, tuple)) else [entry])]
        n_sim, n_emu = _of_task(n_test, task), _of_task(n_test_emulation, task)
        out[task] = {}
        for track in tracks:
            if track not in ("simulator", "emulation"):
                raise InputError(f"task track {track!r} unknown; allowed 'simulator', 'emulation'")
            out[task][track] = rec = _track_score(
                kernel,
                task,
                entry if user else paths,
                track,
                n_test=(n_emu or n_sim) if track == "emulation" else n_sim,
                finetune_epochs=finetune_epochs,
                design_sensor=design_sensor,
                display=display,
                keep_evidence=keep_evidence,
                test_clips=test_clips,
                base_dir=base_dir,
            )
            out["status"] = out["status"] if rec["status"] == "ok" else "partial"
    return out


def _of_task(n: int | Mapping[str, int], task: str) -> int:
    """A per-task setting given for every task or per task (0 when the task is not named)."""
    return int(n.get(task, 0)) if isinstance(n, Mapping) else int(n)


def _track_score(
    kernel: Kernel,
    task: str,
    networks: Mapping[str, Any] | list[Path],
    track: str,
    *,
    n_test: int,
    finetune_epochs: int,
    design_sensor: Mapping[str, Any] | None,
    display: Any,
    keep_evidence: bool,
    test_clips: str,
    base_dir: str | Path,
) -> dict[str, Any]:
    """One task's record on one track (:func:`task_scores`); ``networks`` is a user dataset's
    table, or the task's checkpoints (one network per training seed)."""
    if finetune_epochs:
        return {"status": "unavailable: paired per-clip scoring is zero-shot (finetune_epochs must be 0)"}
    events_fn = _recaptured_events(kernel, display) if track == "emulation" else None
    t0 = time.perf_counter()
    try:
        evid, sensor_rec = _network_evidence(
            kernel, task, networks, n_test, design_sensor, events_fn, test_clips=test_clips, base_dir=base_dir
        )
    except (InputError, FileNotFoundError) as exc:
        return {"status": f"unavailable: {exc}", **_failed_clips_record(exc)}
    return _evidence_record(evid, sensor_rec, networks, test_clips=test_clips, keep_evidence=keep_evidence, t0=t0)


def _network_evidence(
    kernel: Kernel,
    task: str,
    networks: Mapping[str, Any] | list[Path],
    n_test: int,
    design_sensor: Mapping[str, Any] | None,
    events_fn: Any,
    *,
    test_clips: str,
    base_dir: str | Path,
) -> tuple[list[Any], dict[str, Any]]:
    """Every network's per-clip evidence of one task and track, and the record of the sensor it ran."""
    from .paired import clip_evidence  # torch: imported only when tasks are scored
    from .user_data import dataset_evidence

    evid = []
    sensor_rec: dict[str, Any] = {}
    if isinstance(networks, Mapping):
        fields = None if design_sensor is None else {k: design_sensor[k] for k in DESIGN_SENSOR_FIELDS}
        ev, sensor_rec = dataset_evidence(
            kernel, task, networks, base_dir, design_sensor=fields, events_fn=events_fn, confine=False
        )
        evid.append(ev)
        return evid, sensor_rec
    for s, ckpt in enumerate(networks):
        sensor_cfg, sensor_rec = task_sensor(ckpt, design_sensor)
        evid.append(
            clip_evidence(
                kernel,
                task,
                ckpt,
                n_test=n_test or None,
                sensor=sensor_cfg,
                seed_offset=s,
                clip_set=s if test_clips == "per_network" else 0,
                events_fn=events_fn,
            )
        )
    return evid, sensor_rec


def _evidence_record(
    evid: Sequence[Any],
    sensor_rec: dict[str, Any],
    networks: Mapping[str, Any] | list[Path],
    *,
    test_clips: str,
    keep_evidence: bool,
    t0: float,
) -> dict[str, Any]:
    """A scored track's record from its networks' evidence (:func:`task_scores`' Returns)."""
    from ..design.user_data_section import DEFAULT_MAX_FAILED_CLIP_FRACTION
    from .paired import encode_evidence, event_rate_ci
    from .user_data import user_task_record

    per_seed = [e.value for e in evid]
    rec: dict[str, Any] = {
        "status": "ok",
        "metric": float(np.mean(per_seed)),
        "metric_name": evid[0].metric_name,
        "per_seed": per_seed,
        "n_seeds": len(evid),
        "test_clips": test_clips,
        "n_clips": (sum(e.n_clips for e in evid) if test_clips == "per_network" else evid[0].n_clips),
        "n_clips_per_network": evid[0].n_clips,
        "test_seeds": [e.test_seed for e in evid],
        **(
            user_task_record(networks) if isinstance(networks, Mapping) else {"checkpoints": [str(p) for p in networks]}
        ),
        "sensor_seeds": [e.sensor_seed for e in evid],
        "event_rate": float(np.mean([e.event_rate for e in evid])),
        "sensor": sensor_rec,
        "event_rate_unit": "events/pixel/frame interval",
        "event_rate_per_s": event_rate_ci(evid, test_clips=test_clips),
        "wall_s": time.perf_counter() - t0,
    }
    if isinstance(networks, Mapping):
        rec.update(evid[0].details)  # per_class, dataset_summary (explore.user_data.dataset_evidence)
        rec.update(_failed_clips_record(evid[0]))
        rec["max_failed_clip_fraction"] = float(
            networks.get("max_failed_clip_fraction", DEFAULT_MAX_FAILED_CLIP_FRACTION)
        )
    if keep_evidence:
        rec["evidence"] = [encode_evidence(e.metric) for e in evid]
        if all(e.clip_event_rates is not None for e in evid):  # matched-rate losses (explore.matched)
            rec["clip_event_rates"] = [np.asarray(e.clip_event_rates, dtype=np.float64).tolist() for e in evid]
    return rec


def _failed_clips_record(source: Any) -> dict[str, Any]:
    """A user-data track's skipped clips: ``failed_clips`` (count), ``failed_clip_files`` (the first
    :data:`~fsdvs_hw.tasks.dataset_eval.MAX_NAMED_FAILURES` as ``{index, file, reason}``),
    ``failed_clip_indices`` (all, for the pairing check of :func:`paired_losses`) and ``n_clips_drawn``;
    ``{}`` for anything without clip failures (a checkpoint task, another error)."""
    from ..tasks.dataset_eval import MAX_NAMED_FAILURES

    failures = tuple(getattr(source, "failures", ()) or ())
    n_drawn = int(getattr(source, "n_drawn", 0) or 0)
    if not failures and not n_drawn:
        return {}
    return {
        "failed_clips": len(failures),
        "failed_clip_files": [f.to_dict() for f in failures[:MAX_NAMED_FAILURES]],
        "failed_clip_indices": sorted(int(f.index) for f in failures),
        "n_clips_drawn": n_drawn,
        **(
            {"max_failed_clip_fraction": float(source.max_failed_fraction)}
            if hasattr(source, "max_failed_fraction")
            else {}
        ),
    }


def _record_networks(tasks: dict[str, Any], target: Kernel) -> None:
    """Say, per task, which networks scored it and whether they were trained with ``target``."""
    from .paired import network_info  # torch: imported only when tasks are scored

    for _task, tracks in tasks.items():
        if not isinstance(tracks, dict):
            continue
        for rec in tracks.values():
            if isinstance(rec, dict) and rec.get("status") == "ok" and "checkpoints" in rec:
                try:
                    rec["networks"] = [network_info(c, target) for c in rec["checkpoints"]]
                except InputError as exc:
                    rec["networks"] = [{"status": f"unavailable: {exc}"}]


def _recaptured_events(kernel: Kernel, display: Any) -> Any:
    """``events_fn`` for ``evaluate_kernel``: the sensor-in-the-loop emulation of ``kernel``."""
    from ..design.display_settings import DisplaySettings
    from .emulation import recapture

    shown = display if display is not None else DisplaySettings()

    def events_fn(video: Any, _kernel_taps: Any, sensor: Any, timestamps_s: Any) -> Any:
        frames, _ = recapture(video, np.asarray(timestamps_s, dtype=np.float64), kernel, display=shown, sensor=sensor)
        return frames

    return events_fn


def score(
    realisation: Realisation,
    *,
    target: Kernel,
    csf_methods: Sequence[str] = (PRIMARY_CSF_METHOD,),
    focal_length_m: float = 4.0e-3,
    checkpoints: Mapping[str, str | Path | Sequence[str | Path]] | None = None,
    task_options: Mapping[str, Any] | None = None,
    emulation: Mapping[str, Any] | None = None,
    fit_wall_s: float = float("nan"),
) -> Score:
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
        ``n_test``, ``n_test_emulation``, ``test_clips``, ``finetune_epochs``, ``tracks`` for
        :func:`task_scores`.
    emulation : mapping, optional
        ``{"sensor": [sensor] section, "emulation": [emulation] section, "seed": int}`` to score the
        sensor-in-the-loop emulation track (:func:`fsdvs_hw.explore.emulation.emulation_scores`).
    fit_wall_s : float
        Seconds the realisation's fit took (recorded as given).

    Returns
    -------
    Score
        The typed record (:class:`fsdvs_hw.records.Score`); :meth:`~fsdvs_hw.records.Score.to_dict`
        is what the store, ``scores.json`` and the report read.
    """
    realised = realisation.kernel()
    t0 = time.perf_counter()
    kernel_error = realised_kernel_error(realisation, target)
    kernel_error_gain_free = realised_kernel_error(realisation, target, fit_scale=True)
    spectral = _spectral(realised)
    csf = _csf_scores(realised, list(csf_methods), focal_length_m)
    cost = Cost(dict(realisation.cost()))
    t1 = time.perf_counter()
    opts = dict(task_options or {})
    if "emulation" in opts.get("tracks", ()) and emulation is not None and "display" not in opts:
        from ..design.display_settings import DisplaySettings

        opts["display"] = DisplaySettings.from_design(emulation["emulation"])
    tasks = task_scores(realised, dict(checkpoints or {}), **opts)
    _record_networks(tasks, target)
    t2 = time.perf_counter()
    if emulation is not None and emulation["emulation"].get("enabled", True):
        from .emulation import emulation_scores

        emu = emulation_scores(
            realised, sensor=emulation["sensor"], emulation=emulation["emulation"], seed=int(emulation.get("seed", 0))
        )
    else:
        emu = {"status": "not requested"}
    return Score(
        kind=realisation.kind,
        label=getattr(realisation, "label", realisation.kind),
        describe=realisation.describe(),
        kernel=realised,
        kernel_error=kernel_error,
        kernel_error_gain_free=kernel_error_gain_free,
        dc_gain=realised.dc_gain,
        asymmetry=realised.asymmetry(),
        spectral=spectral,
        csf=csf,
        cost=cost,
        tasks=TaskScores.from_dict(tasks),
        emulation=emu,
        wall=WallTimes(
            fit_s=float(fit_wall_s), analysis_s=t1 - t0, tasks_s=t2 - t1, emulation_s=time.perf_counter() - t2
        ),
    )


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
    tasks = result.get("tasks") if isinstance(result, Mapping) else None
    return TaskScores.from_dict(tasks).metrics() if isinstance(tasks, Mapping) else {}


def sweep_setting(point: Mapping[str, Any]) -> str:
    """The sweep setting a stored point shares with its reference, as sorted JSON.

    Parameters
    ----------
    point : mapping
        A stored point (its ``params``).

    Returns
    -------
    str
        Its params minus the realisation-scoped axes; points of one setting compare to one reference.
    """
    params = point.get("params") or {}
    scoped = set(realisation_names()) | {"realisations"}
    return json.dumps({k: v for k, v in params.items() if k.split(".")[0] not in scoped}, sort_keys=True, default=str)


def track_record(point: Mapping[str, Any], task: str, track: str) -> Mapping[str, Any]:
    """A stored point's record of one task on one track (``result.tasks[task][track]``; ``{}`` when absent)."""
    rec = (((point.get("result") or {}).get("tasks") or {}).get(task) or {}).get(track)
    return rec if isinstance(rec, Mapping) else {}


def paired_losses(
    points: Iterable[Mapping[str, Any]],
    *,
    reference: str = "learned",
    task_weights: Mapping[str, float] | None = None,
    n_resamples: int = 2000,
    confidence: float = 0.95,
    rng: int = 0,
) -> dict[str, dict[str, Any]]:
    """Paired accuracy loss of every point against the reference kernel, with bootstrap CIs.

    For every track and task, the reference row (``learned``: the kernel being realised, in the
    same sweep setting) and each point were scored per clip on the same test clips, noise draws and
    networks (:func:`task_scores`); the loss is ``metric(reference) − metric(point)`` (positive =
    accuracy lost) and its CI comes from :func:`fsdvs_hw.stats.task_difference_cis`, resampling test
    clips and training seeds (with each seed's own mismatch pattern).

    Parameters
    ----------
    points : iterable of mappings
        Stored points (``key``, ``realisation``, ``params``, ``status``, ``result``) whose task
        records keep their ``evidence``.
    reference : str
        The realisation every loss is measured against.
    task_weights : mapping, optional
        Task → weight of the weighted task loss (default: equal weights over the tasks scored).
    n_resamples, confidence, rng
        Bootstrap settings (``rng`` seeds the resampling; every point shares the draws).

    Returns
    -------
    dict
        ``{point key: {"reference": key, track: {task: DifferenceCI dict + "text", "weighted": ...}}}``;
        a point without paired evidence maps to ``{"status": reason}``.
    """
    from ..stats import task_difference_cis
    from .paired import decode_evidence

    points = [p for p in points if p.get("status") == "ok"]
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for p in points:
        groups.setdefault(sweep_setting(p), []).append(p)
    decoded: dict[tuple[str, str, str], list[Any]] = {}

    def arm(p: Mapping[str, Any], task: str, track: str) -> list[Any] | None:
        rec = track_record(p, task, track)
        if not isinstance(rec, Mapping) or rec.get("status") != "ok" or not rec.get("evidence"):
            return None
        key = (p["key"], task, track)
        if key not in decoded:
            decoded[key] = [decode_evidence(e) for e in rec["evidence"]]
        return decoded[key]

    out: dict[str, dict[str, Any]] = {
        p["key"]: {"status": f"no {reference!r} row in its sweep setting"} for p in points
    }
    for group in groups.values():
        ref = next((p for p in group if p["realisation"] == reference), None)
        if ref is None:
            continue
        for p in group:
            out[p["key"]] = {"status": "ok", "reference": ref["key"]}
        tasks_of_ref = [t for t, v in ((ref.get("result") or {}).get("tasks") or {}).items() if isinstance(v, Mapping)]
        for track in TRACK_PREFIX:
            all_arms = {t: arm(ref, t, track) for t in tasks_of_ref}
            ref_arms = {t: a for t, a in all_arms.items() if a is not None}
            if not ref_arms:
                continue
            nested = {t: track_record(ref, t, track).get("test_clips") == "per_network" for t in ref_arms}
            ok: list[Mapping[str, Any]] = []
            missing: list[Mapping[str, Any]] = []
            for p in group:
                arms = {t: arm(p, t, track) for t in ref_arms}
                (ok if _pairs_with(p, ref, track, arms, ref_arms) else missing).append(p)
            for p in missing:
                out[p["key"]][track] = {"status": "no paired evidence on every task of the reference"}
            if not ok:
                continue
            weights = {t: float((task_weights or {}).get(t, 0.0 if task_weights else 1.0)) for t in ref_arms}
            if not any(w > 0 for w in weights.values()):
                weights = {t: 1.0 for t in ref_arms}
            cis = task_difference_cis(
                {t: (ref_arms[t], {p["key"]: decoded[(p["key"], t, track)] for p in ok}) for t in ref_arms},
                weights=weights,
                nested_clips=nested,
                n_resamples=n_resamples,
                confidence=confidence,
                rng=rng,
            )
            for p in ok:
                rec = {t: {**ci.to_dict(), "text": ci.describe()} for t, ci in cis[p["key"]].items()}
                rec["weights"] = weights
                out[p["key"]][track] = rec
    return out


def _pairs_with(
    point: Mapping[str, Any],
    ref: Mapping[str, Any],
    track: str,
    arms: Mapping[str, list[Any] | None],
    ref_arms: Mapping[str, list[Any]],
) -> bool:
    """Whether ``point``'s per-clip evidence (``arms``, by task) pairs with the reference's on every
    task: as many networks, as many clips per network, the same test seeds and skipped clips."""
    return all(
        a is not None
        and len(a) == len(ref_arms[t])
        and [m.n_clips for m in a] == [m.n_clips for m in ref_arms[t]]
        and track_record(point, t, track).get("test_seeds") == track_record(ref, t, track).get("test_seeds")
        # user data: the same clips skipped (decided from the clips' files, so always so)
        and (track_record(point, t, track).get("failed_clip_indices") or [])
        == (track_record(ref, t, track).get("failed_clip_indices") or [])
        for t, a in arms.items()
    )


#: A task track's per-clip fields: kept in ``results.sqlite``, dropped from ``scores.json`` and the report.
EVIDENCE_FIELDS = frozenset({"evidence", "clip_event_rates"})


def with_paired_losses(
    points: Sequence[ScoredPoint], *, keep_evidence: bool = False, **options: Any
) -> list[ScoredPoint]:
    """Copies of ``points`` with their paired losses (:func:`paired_losses`) and, unless asked, the
    bulky per-clip fields (:data:`EVIDENCE_FIELDS`) removed (what the report and ``scores.json`` carry).

    Parameters
    ----------
    points : sequence of ScoredPoint
        Stored points with their per-clip evidence.
    keep_evidence : bool
        Keep the per-clip fields in the copies.
    **options
        :func:`paired_losses`'s bootstrap settings.

    Returns
    -------
    list of ScoredPoint
        The points, each with :attr:`~fsdvs_hw.records.ScoredPoint.paired_loss` (``{"status":
        "not scored"}`` for a point :func:`paired_losses` gave none).
    """
    rows = [p.to_dict() for p in points]
    losses = paired_losses(rows, **options)
    out = []
    for row in rows:
        row["paired_loss"] = losses.get(row["key"], {"status": "not scored"})
        if (
            not keep_evidence
            and isinstance(row.get("result"), Mapping)
            and isinstance(row["result"].get("tasks"), Mapping)
        ):
            res = dict(row["result"])
            res["tasks"] = {
                t: (
                    {
                        k: ({f: v for f, v in r.items() if f not in EVIDENCE_FIELDS} if isinstance(r, Mapping) else r)
                        for k, r in tracks.items()
                    }
                    if isinstance(tracks, Mapping)
                    else tracks
                )
                for t, tracks in res["tasks"].items()
            }
            row["result"] = res
        out.append(ScoredPoint.from_dict(row))
    return out
