"""User datasets and networks at run time: training a ``[tasks.datasets.<task>]`` network and its paired evidence.

The table itself (its keys and their checks) is :mod:`fsdvs_hw.design.user_data_section`; the
dataset and network it names are opened by :mod:`fsdvs_hw.design.user_data_inputs`.
:func:`train_user_task` trains the table's network on the clips not scored (or on its
``train.split``), :func:`finetune_user_network` trains it further with a realised kernel, and
:func:`open_network` is the network a table scores with (trained where it has a ``train`` table).

:func:`dataset_evidence` scores a kernel on the drawn clips (:func:`fsdvs_hw.tasks.dataset_eval.
evaluate_on_dataset`) and keeps each clip's contribution as the same :mod:`fsdvs_hw.stats` metric
object :func:`fsdvs_hw.explore.paired.clip_evidence` keeps for a trained checkpoint, so
:func:`fsdvs_hw.explore.scoring.paired_losses` pairs every kernel with the learned one clip by clip.
Pairing: every kernel meets the same clips (one seeded draw) and the same noise draws (the
simulator is reseeded for every clip). A clip that fails to read (a video that does not decode, a
mask label beyond ``num_classes``, another frame size) is skipped, counted and named, up to
``max_failed_clip_fraction`` of the drawn clips; whether it fails is decided from its files alone
(:func:`fsdvs_hw.tasks.dataset_eval.read_clip`), so every kernel skips the same clips and the
comparison stays paired (the record's ``failed_clip_indices`` are compared again when losses are
paired). Beyond the fraction, or on a problem of the task (the network's output, an odd frame size
for the stride-2 detector), the task fails with a message naming the key, the file and the reason.
With one user network the loss CI resamples clips only (``n_seeds = 1``: network-to-network
variance cannot enter), which the track record says.

References
----------
Soomro, Zamir & Shah, "UCF101", CRCV-TR-12-01 (2012) — the class-folder layout.
Lin et al., "Microsoft COCO", ECCV (2014) — the annotation JSON.
Cordts et al., "The Cityscapes Dataset", CVPR (2016) — label-mask PNGs with an ignore index.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..design.design_paths import resolve_design_path
from ..design.user_data_inputs import (
    build_user_network,
    check_disjoint_files,
    network_cache_key,
    open_dataset,
    open_untrained_network,
    train_split_dataset,
)
from ..design.user_data_section import DEFAULT_MAX_FAILED_CLIP_FRACTION, FORMAT_TASK, TrainSpec
from ..errors import InputError
from ..paths import Confinement

__all__ = [
    "ONE_NETWORK_NOTE",
    "dataset_evidence",
    "finetune_user_network",
    "open_network",
    "train_user_task",
    "user_network_identity",
    "user_task_record",
]

#: What a user-data task's record says about its loss CIs.
ONE_NETWORK_NOTE = (
    "one user network: the loss CI resamples the clips only (n_seeds = 1); network-to-network variance is not in it"
)


@functools.lru_cache(maxsize=16)
def _open_network(blob: str, base: str, confine: Confinement, key: str, in_channels: int, num_classes: int) -> Any:
    """A new network of the table (:func:`~fsdvs_hw.design.user_data_inputs.build_user_network`),
    trained on the clips not scored where the table has a ``train`` table, in eval mode."""
    entry = json.loads(blob)
    net = build_user_network(entry, Path(base), confine, key, in_channels, num_classes)
    if entry.get("train") is not None:
        net = _train(FORMAT_TASK[entry["dataset"]["format"]], entry, Path(base), confine, key, net, False).network
    return net.eval()


def _file_digest(path: Path) -> str:
    """SHA-256 of a file (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _training_clips(
    entry: Mapping[str, Any], spec: Mapping[str, Any], base: Path, confine: Confinement, key: str
) -> tuple[Any, np.ndarray]:
    """(dataset, clip indices) a table trains on: ``spec["split"]`` (the dataset's own training split,
    disjoint files checked) or a draw of ``spec["n_train"]`` with ``spec["seed"]`` from the clips not scored."""
    from ..tasks.dataset_training import disjoint_train_indices

    ds = open_dataset(entry["dataset"], base, confine=confine, key=f"{key}.dataset")
    scored = ds.draw(entry["n_clips"], entry["seed"]) if entry["n_clips"] else np.arange(len(ds))
    train_ds, train_idx = ds, None
    if spec.get("split") is not None:
        train_ds = train_split_dataset(entry, base, confine=confine, key=key)
        train_idx = (
            train_ds.draw(spec["n_train"], spec["seed"])
            if spec["n_train"]
            else np.arange(len(train_ds), dtype=np.int64)
        )
        if len(train_idx) < 2:
            raise InputError(
                f"{key}.train.split = {spec['split']!r}: {len(train_idx)} training clip; allowed: 2 or "
                "more (train.n_train = 0: all of the split)"
            )
        check_disjoint_files(train_ds, train_idx, ds, scored, what=f"{key}.train.split = {spec['split']!r}")
    elif len(scored) >= len(ds):
        raise InputError(
            f"{key}.n_clips = {entry['n_clips']}: every one of the {len(ds)} clips is scored, none is "
            f"left to train on ({key}.train); allowed: 1 to {len(ds) - 2}, or a training split "
            f"({key}.train.split)"
        )
    else:
        train_idx = disjoint_train_indices(len(ds), scored, spec["n_train"], spec["seed"])
    return train_ds, train_idx


def _scored_source(entry: Mapping[str, Any]) -> dict[str, Any]:
    """The table's dataset without its disk cache (which changes no clip): what fingerprints hold."""
    return {k: v for k, v in entry["dataset"].items() if k != "cache"}


def _train_on_clips(
    train_ds: Any,
    train_indices: np.ndarray | None,
    task: str,
    net: Any,
    spec: Mapping[str, Any],
    device: str,
    *,
    out: Path | str | None,
    fingerprint: dict[str, Any] | None,
    verbose: bool,
    **stages: Any,
) -> Any:
    """Train a copy of ``net`` on a table's training clips with its ``train`` table's common settings.

    Parameters
    ----------
    train_ds : ClipDataset
        The dataset trained on (:func:`_training_clips`).
    train_indices : ndarray or None
        Its training clips.
    task : str
    net : torch.nn.Module
        Copied; the original is left as it is.
    spec : mapping
        The ``train`` table: ``weight_decay``, ``batch_size`` and ``seed`` are used.
    device : str
    out : path, optional
        File stem of the trained network (resumes; a finished one is reused).
    fingerprint : dict, optional
        Identity of the run stored with the checkpoint and compared on resume.
    verbose : bool
        One line per epoch on stderr.
    **stages
        The stages and their rates (:func:`fsdvs_hw.tasks.dataset_training.train_on_dataset`).

    Returns
    -------
    DatasetTrainingResult
    """
    from ..tasks.dataset_training import train_on_dataset

    return train_on_dataset(
        train_ds,
        task,
        copy.deepcopy(net),
        train_indices=train_indices,
        weight_decay=spec["weight_decay"],
        batch_size=spec["batch_size"],
        seed=spec["seed"],
        device=device,
        out=out,
        fingerprint=fingerprint,
        verbose=verbose,
        **stages,
    )


def _train(
    task: str,
    entry: Mapping[str, Any],
    base: Path,
    confine: Confinement,
    key: str,
    net: Any,
    verbose: bool,
    out_stem: Path | None = None,
) -> Any:
    """Train ``net`` (a copy) on the task's clips not scored (or reuse / resume ``train.out``)."""
    spec = dict(entry["train"])
    train_ds, train_idx = _training_clips(entry, spec, base, confine, key)
    out = out_stem or resolve_design_path(
        base, spec["out"] or f"trained/{task}", what=f"{key}.train.out", confine=confine
    )
    weights = (
        resolve_design_path(base, entry["weights"], what=f"{key}.weights", confine=confine)
        if entry["weights"]
        else None
    )
    fingerprint = {
        "dataset": _scored_source(entry),
        "network": entry["network"],
        "options": entry["network_options"],
        "weights_sha256": _file_digest(weights) if weights else None,
        "scored": [entry["n_clips"], entry["seed"]],
        "sensor": "default",
        # train.split only when set: checkpoints trained before the key existed keep their fingerprint
        "train": {k: v for k, v in spec.items() if k != "out" and not (k == "split" and v is None)},
    }
    _add_streaming_keys(fingerprint, entry)
    return _train_on_clips(
        train_ds,
        train_idx,
        task,
        net,
        spec,
        entry["device"],
        out=out,
        fingerprint=fingerprint,
        verbose=verbose,
        kernel_size=spec["kernel_size"],
        learn_filter=spec["learn_kernel"],
        epochs_frozen=spec["epochs_frozen"],
        epochs_joint=spec["epochs_joint"],
        lr_network=spec["lr_network"],
        lr_kernel=spec["lr_kernel"],
        lr_backbone=spec["lr_backbone"],
        lr_head=spec["lr_head"],
        **_streaming_arguments(entry, spec),
    )


def _streaming_arguments(entry: Mapping[str, Any], spec: Mapping[str, Any]) -> dict[str, Any]:
    """The table's sampling and the train table's loader keys as train_on_dataset's arguments."""
    from ..tasks.dataset_training import streaming_arguments

    return streaming_arguments(entry.get("sampling"), spec)


def _add_streaming_keys(fingerprint: dict[str, Any], entry: Mapping[str, Any]) -> None:
    """The sampling table and val_fraction in a training fingerprint when set, and ``streamed`` when the
    clips stream; the loader's memory_mb and workers never (streamed runs give the same weights whatever
    they are), so checkpoints trained before these keys existed keep their fingerprint."""
    from ..tasks.dataset_training import RESULT_NEUTRAL_TRAIN_KEYS

    train = fingerprint["train"]
    streamed = train.get("memory_mb") is not None or bool(train.get("workers"))
    for k in (*RESULT_NEUTRAL_TRAIN_KEYS, "val_fraction"):
        if k in RESULT_NEUTRAL_TRAIN_KEYS or not train.get(k):
            train.pop(k, None)
    if streamed:  # the simulator's noise is drawn per batch, not per chunk of held clips: other weights
        train["streamed"] = True
    if entry.get("sampling") is not None:
        fingerprint["sampling"] = dict(entry["sampling"])


def train_user_task(
    task: str,
    entry: Mapping[str, Any],
    base_dir: str | Path,
    *,
    confine: Confinement = True,
    verbose: bool = False,
    overrides: Mapping[str, Any] | None = None,
    out: str | Path | None = None,
) -> Any:
    """Train (or reuse / resume) the network of a ``[tasks.datasets.<task>]`` table with a ``train`` table.

    The training clips are drawn with ``train.seed`` from the clips the table does not score
    (``n_clips`` drawn with ``seed``), so training and scoring never share a clip; the network
    starts from the factory (from scratch) or from ``weights`` (fine-tuning). The result is
    written to ``train.out`` (inside the design's folder) and reused by a rerun with the same
    data, network and settings (:func:`fsdvs_hw.tasks.dataset_training.train_on_dataset`).

    Parameters
    ----------
    task : str
    entry : mapping
        A validated :class:`~fsdvs_hw.design.user_data_section.UserTask` dumped, with ``train`` set.
    base_dir : path
        The design file's folder.
    verbose : bool
        One line per epoch on stderr.
    overrides : mapping, optional
        ``train`` keys replaced for this run (the ablation's ``kernel_size`` and ``seed``).
    out : path, optional
        File stem used instead of ``train.out`` (a command's own output folder).

    Returns
    -------
    DatasetTrainingResult
        The learned kernel (``paths["kernel"]``: what ``[kernel] path`` can name) and the network.

    Raises
    ------
    InputError
        No ``train`` table, every clip scored (none left to train on), too few clips for
        ``n_train``, a checkpoint at ``train.out`` trained with other settings.

    Examples
    --------
    >>> res = train_user_task("recognition", design.spec.tasks.datasets["recognition"].model_dump(), "designs")  # doctest: +SKIP
    >>> res.paths["kernel"].name                                                                         # doctest: +SKIP
    'recognition.json'
    """
    key = f"tasks.datasets.{task}"
    if entry.get("train") is None:
        raise InputError(f"{key}.train is not set; allowed: a train = {{...}} table to train on the user's clips")
    base = Path(base_dir).resolve()
    ds = open_dataset(entry["dataset"], base, confine=confine, key=f"{key}.dataset")
    net = open_untrained_network(entry, ds, base, confine=confine, key=key)
    if overrides:
        entry = {**entry, "train": TrainSpec.model_validate({**entry["train"], **overrides}).model_dump()}
    return _train(task, entry, base, confine, key, net, verbose, None if out is None else Path(out))


def user_network_identity(
    entry: Mapping[str, Any], base_dir: str | Path, *, confine: Confinement = True
) -> dict[str, Any]:
    """What determines a table's scores besides the kernel: data, clip draw, network, weights, training.

    JSON-able, for result keys (:mod:`fsdvs_hw.explore.codesign` units): the dataset (its disk
    cache left out: it changes no clip), ``n_clips`` and ``seed``, the factory and its options, the
    SHA-256 of ``weights`` and the ``train`` table.

    Examples
    --------
    >>> from fsdvs_hw.design.user_data_section import UserTask
    >>> entry = UserTask(dataset={"format": "video_folder", "root": "ucf"}).model_dump()
    >>> sorted(user_network_identity(entry, "."))[:3]
    ['clip_seed', 'dataset', 'device']
    """
    weights = (
        resolve_design_path(Path(base_dir).resolve(), entry["weights"], what="weights", confine=confine)
        if entry["weights"]
        else None
    )
    return {
        "dataset": _scored_source(entry),
        "n_test": entry["n_clips"],
        "clip_seed": entry["seed"],
        "network": entry["network"] or "built-in",
        "options": dict(entry["network_options"]),
        "weights_sha256": _file_digest(weights) if weights else None,
        "device": entry["device"],
        **_streaming_identity(entry),
    }


def _streaming_identity(entry: Mapping[str, Any]) -> dict[str, Any]:
    """The ``train`` table as a training fingerprint holds it (:func:`_add_streaming_keys`), and ``sampling``
    when set: what :func:`user_network_identity` keys on."""
    ident: dict[str, Any] = {"train": None if entry.get("train") is None else dict(entry["train"])}
    if ident["train"] is not None:
        _add_streaming_keys(ident, entry)
    elif entry.get("sampling") is not None:
        ident["sampling"] = dict(entry["sampling"])
    return ident


def _finetune_stages(kernel: Any, realisation: Any, epochs: int, lr_network: float, lr_filter: float) -> dict[str, Any]:
    """The training stages of :func:`finetune_user_network`: frozen ``kernel``, or co-designed ``realisation``.

    Parameters
    ----------
    kernel : Kernel or None
        Trained frozen (stage one only) when ``realisation`` is None.
    realisation : Realisation or None
        Otherwise co-designed (stage two only).
    epochs : int
    lr_network, lr_filter : float
        AdamW rates (1/step) of the network and of the realisation's parameters.

    Returns
    -------
    dict
        Keyword arguments of :func:`fsdvs_hw.tasks.dataset_training.train_on_dataset`.
    """
    if realisation is None:
        return {"init_kernel": kernel, "learn_filter": False, "epochs_frozen": epochs, "epochs_joint": 0}
    return {
        "realisation": realisation,
        "epochs_frozen": 0,
        "epochs_joint": epochs,
        "lr_kernel": lr_filter,
        "lr_backbone": lr_network,
        "lr_head": lr_network,
    }


def finetune_user_network(
    task: str,
    entry: Mapping[str, Any],
    base_dir: str | Path,
    *,
    kernel: Any = None,
    realisation: Any = None,
    epochs: int = 4,
    n_train: int = 0,
    lr_network: float = 1e-3,
    lr_filter: float = 1e-2,
    out: str | Path | None = None,
    fingerprint: Mapping[str, Any] | None = None,
    confine: Confinement = True,
    verbose: bool = False,
) -> Any:
    """Train a table's network further with a realised kernel: frozen, or co-designed (user data).

    The user-data counterpart of :func:`fsdvs_hw.tasks.learn.finetune_network` (the
    ``finetune`` and ``codesign`` rows of :mod:`fsdvs_hw.explore.codesign`): the network the table
    scores (:func:`open_network`: ``weights``, or the ``train`` table's checkpoint) trains on the
    clips :func:`train_user_task` trains on (``train.split``, or the seeded draw from the clips not
    scored: never a scored clip), through
    :func:`~fsdvs_hw.tasks.dataset_training.train_on_dataset`'s loop:

    * ``kernel`` given: stage one only, ``epochs`` epochs, the kernel frozen, the whole network at
      ``lr_network``;
    * ``realisation`` given: stage two only, ``epochs`` epochs, the realisation's physical
      parameters at ``lr_filter`` and the network (backbone and head) at ``lr_network``.

    Parameters
    ----------
    task : str
    entry : mapping
        A validated :class:`~fsdvs_hw.design.user_data_section.UserTask` dumped.
    base_dir : path
        The design file's folder.
    kernel : Kernel, optional
        The frozen kernel (exactly one of ``kernel`` and ``realisation``).
    realisation : Realisation, optional
        The fitted realisation to co-design (a differentiable form).
    epochs : int
        Training epochs (≥ 1).
    n_train : int
        Training clips; 0 = ``train.n_train`` (0 there: every clip not scored).
    lr_network, lr_filter : float
        AdamW rates (1/step) of the network and of the realisation's parameters.
    out : path, optional
        File stem of the trained network (resumes; a finished one is reused).
    fingerprint : mapping, optional
        Identity of the run stored with the checkpoint and compared on resume.

    Returns
    -------
    DatasetTrainingResult
        ``network`` (CPU, eval mode) and the kernel it ends with; co-designed, the provenance's
        ``realisation_design`` is the realisation after training.

    Raises
    ------
    InputError
        Both or neither of ``kernel`` / ``realisation``, too few clips left to train on, a
        checkpoint at ``out`` trained with another fingerprint.

    Examples
    --------
    >>> res = finetune_user_network("segmentation", entry, "designs", kernel=fitted.kernel(), epochs=1)  # doctest: +SKIP
    >>> res.history[-1]["stage"]                                                                         # doctest: +SKIP
    'frozen_filter'
    """
    if (kernel is None) == (realisation is None):
        raise InputError("finetune_user_network: give exactly one of kernel= (frozen) and realisation= (co-designed)")
    key = f"tasks.datasets.{task}"
    base = Path(base_dir).resolve()
    spec = dict(entry.get("train") or TrainSpec().model_dump())
    spec["n_train"] = n_train or spec["n_train"]
    try:
        train_ds, train_idx = _training_clips(entry, spec, base, confine, key)
    except InputError as exc:  # name the key that asked for the clips
        raise InputError(
            f"{key} trained further with codesign.n_train = {n_train} (0 = its train.n_train): {exc}"
        ) from None
    ds = open_dataset(entry["dataset"], base, confine=confine, key=f"{key}.dataset")
    net = open_network(entry, ds, base, confine=confine, key=key)
    stages = _finetune_stages(kernel, realisation, epochs, lr_network, lr_filter)
    # the table's sampling and loader (no validation split: codesign trains a fixed number of epochs)
    stages.update(_streaming_arguments(entry, {**spec, "val_fraction": 0.0}))
    return _train_on_clips(
        train_ds,
        train_idx,
        task,
        net,
        spec,
        entry["device"],
        out=out,
        fingerprint=None if fingerprint is None else dict(fingerprint),
        verbose=verbose,
        lr_network=lr_network,
        **stages,
    )


def open_network(
    entry: Mapping[str, Any],
    dataset: Any,
    base_dir: str | Path,
    *,
    confine: Confinement = True,
    key: str = "network",
    trained: bool = True,
) -> Any:
    """The network a ``[tasks.datasets.<task>]`` table names, built for ``dataset`` (cached per process).

    Parameters
    ----------
    entry : mapping
        A validated :class:`~fsdvs_hw.design.user_data_section.UserTask` dumped.
    dataset : ClipDataset
        Sets ``in_channels = 2 (T - 1)`` and ``num_classes``.
    base_dir : path
        The design file's folder (factory import, ``weights``).
    trained : bool
        With a ``train`` table: True returns the network trained on the clips not scored (trained
        now, or reused from ``train.out``: :func:`train_user_task`); False the untrained one.

    Returns
    -------
    torch.nn.Module
        In eval mode, with the weights loaded.

    Raises
    ------
    InputError
        The factory does not import, fails or returns no module; a weights file that is missing
        or does not fit (naming the file and parameter).

    Examples
    --------
    >>> net = open_network(entry, open_dataset(entry["dataset"], "."), ".")   # doctest: +SKIP
    """
    if not trained:
        return open_untrained_network(entry, dataset, base_dir, confine=confine, key=key)
    return _open_network(*network_cache_key(entry, dataset, base_dir, confine=confine, key=key))


#: ``SensorConfig`` fields recorded with a user-data task's scores.
_RECORDED_SENSOR_FIELDS = ("threshold_on", "threshold_off", "threshold_sigma", "placement", "positivity")


def _design_sensor(frame_rate_hz: float, design_sensor: Mapping[str, Any] | None) -> tuple[Any, dict[str, Any]]:
    """The simulator of a user-data task and its record: the training default at the clips' rate,
    with the given ``SensorConfig`` fields (the design's ``[sensor]`` thresholds, ...) where asked."""
    from types import SimpleNamespace

    from ..tasks.learn import default_sensor

    cfg = default_sensor(SimpleNamespace(frame_rate_hz=frame_rate_hz))
    if design_sensor is not None:
        cfg = dataclasses.replace(cfg, **dict(design_sensor))
    return cfg, {
        "source": "design" if design_sensor is not None else "default",
        **{k: getattr(cfg, k) for k in _RECORDED_SENSOR_FIELDS},
    }


def _evaluate_table(
    kernel: Any,
    task: str,
    entry: Mapping[str, Any],
    dataset: Any,
    network: Any,
    evaluator: Any,
    sensor: Any,
    events_fn: Any,
    max_failed_fraction: float,
) -> Any:
    """Evaluate ``kernel`` on a table's drawn clips, its errors naming the table's keys.

    Parameters
    ----------
    kernel : Kernel or None
    task : str
        The table's name.
    entry : mapping
        A validated :class:`~fsdvs_hw.design.user_data_section.UserTask` dumped (``n_clips``, ``seed``,
        ``device``, ``network``).
    dataset : ClipDataset
    network : torch.nn.Module
    evaluator : Evaluator
        The dataset's task evaluator (its ``name`` enters the messages).
    sensor : SensorConfig
    events_fn : callable or None
    max_failed_fraction : float
        Drawn clips that may fail to read (fraction).

    Returns
    -------
    DatasetEvaluation
        As :func:`fsdvs_hw.tasks.dataset_eval.evaluate_on_dataset`.

    Raises
    ------
    ClipFailuresError
        Naming ``tasks.datasets.<task>.max_failed_clip_fraction``.
    NetworkOutputError, InputError
        Prefixed with the table's key (and its network, or its dataset).
    """
    from ..tasks.dataset_eval import ClipFailuresError, NetworkOutputError, evaluate_on_dataset

    key = f"tasks.datasets.{task}"
    try:
        return evaluate_on_dataset(
            kernel,
            task,
            dataset,
            network,
            sensor=sensor,
            n_clips=entry["n_clips"] or None,
            seed=entry["seed"],
            events_fn=events_fn,
            device=entry["device"],
            max_failed_fraction=max_failed_fraction,
        )
    except ClipFailuresError as exc:
        raise ClipFailuresError(
            exc.detail, exc.failures, exc.n_drawn, max_failed_fraction, setting=f"{key}.max_failed_clip_fraction"
        ) from None
    except NetworkOutputError as exc:
        name = entry["network"] or f"built-in {evaluator.name} network"
        raise NetworkOutputError(f"{key}.network = {name!r}: {exc}") from None
    except InputError as exc:
        raise InputError(f"{key} ({entry['dataset']['format']} at {entry['dataset']['root']!r}): {exc}") from None


def dataset_evidence(
    kernel: Any,
    task: str,
    entry: Mapping[str, Any],
    base_dir: str | Path,
    *,
    design_sensor: Mapping[str, Any] | None = None,
    events_fn: Any = None,
    confine: Confinement = True,
    network: Any = None,
) -> tuple[Any, dict[str, Any]]:
    """Score ``kernel`` on a user dataset with the user network and keep every clip's contribution.

    The counterpart of :func:`fsdvs_hw.explore.paired.clip_evidence` for a
    ``[tasks.datasets.<task>]`` table: the same per-clip metric objects
    (:data:`fsdvs_hw.explore.paired.PER_CLIP_METRICS`: COCO matches, top-1 per clip, per-clip
    confusion matrices with the dataset's ignore index) and per-clip event rates.

    Parameters
    ----------
    kernel : Kernel or None
        The realised kernel (None: a 1×1 delta, a conventional DVS).
    task : str
        ``"detection"``, ``"recognition"`` or ``"segmentation"`` (the table's name).
    entry : mapping
        A validated :class:`~fsdvs_hw.design.user_data_section.UserTask` dumped.
    base_dir : path
        The design file's folder.
    design_sensor : mapping, optional
        ``SensorConfig`` fields replacing the training default's (``tasks.sensor = "design"``: the
        design's ``[sensor]`` thresholds, mismatch, placement and positivity); None: the training
        default (:func:`fsdvs_hw.tasks.learn.default_sensor`) at the clips' frame rate.
    events_fn : callable, optional
        Event frames instead of the in-pixel simulator (the emulation track).
    network : torch.nn.Module, optional
        Score this network instead of the table's (a fine-tuned or co-designed one,
        :func:`finetune_user_network`).

    Returns
    -------
    evidence : ClipEvidence
        ``checkpoint`` names the network; ``test_seed`` is the clip-draw seed; ``failures`` the
        drawn clips skipped (at most ``max_failed_clip_fraction`` of ``n_drawn``).
    sensor_record : dict
        Which simulator settings were used.

    Raises
    ------
    ClipFailuresError
        More than ``max_failed_clip_fraction`` of the drawn clips failed to read (naming the key,
        the first files and reasons; ``failures`` lists them all).
    InputError
        Any dataset or network problem, or a problem of the task (the network's output, an odd
        frame size for the detector), naming the key, the file and the field.

    Examples
    --------
    >>> ev, _ = dataset_evidence(None, "recognition", entry, "designs")   # doctest: +SKIP
    >>> ev.metric_name, ev.n_clips                                       # doctest: +SKIP
    ('top1', 4)
    """
    from ..tasks.dataset_eval import evaluator_for_dataset, per_video_evaluation, read_clip
    from .paired import PER_CLIP_METRICS, ClipEvidence

    t0 = time.perf_counter()
    key = f"tasks.datasets.{task}"
    ds = open_dataset(entry["dataset"], base_dir, confine=confine, key=f"{key}.dataset")
    net = open_network(entry, ds, base_dir, confine=confine, key=key) if network is None else network
    evaluator = evaluator_for_dataset(task, ds)
    fraction = float(entry.get("max_failed_clip_fraction", DEFAULT_MAX_FAILED_CLIP_FRACTION))
    drawn = ds.draw(entry["n_clips"], entry["seed"]) if entry["n_clips"] else np.arange(len(ds))
    ds, entry, probe = _clips_per_video(ds, entry, drawn)
    first = next((c for c in (read_clip(ds, int(i))[0] for i in probe) if c is not None), None)
    # the first readable clip's frame rate (none readable: evaluate_on_dataset names every failure)
    rate_hz = 1.0 if first is None else 1.0 / float(np.diff(first.timestamps_s)[0])
    sensor, sensor_rec = _design_sensor(rate_hz, design_sensor)
    ev = _evaluate_table(kernel, task, entry, ds, net, evaluator, sensor, events_fn, fraction)
    if entry.get("sampling") is not None:
        ev = per_video_evaluation(ev, ds.video_of, task, ds.num_classes)
    metric = PER_CLIP_METRICS[evaluator.name](ev.predictions, ev.targets, evaluator)
    n = len(ev.clip_indices)
    t, h, w = (first if first is not None else ds[int(ev.clip_indices[0])]).frames.shape
    evidence = ClipEvidence(
        task=evaluator.name,
        metric_name=evaluator.primary_metric,
        value=float(metric.weighted(np.ones((1, n)))[0]),
        n_clips=n,
        metric=metric,
        checkpoint=entry["network"] or f"built-in {evaluator.name} network",
        sensor_seed=int(sensor.seed),
        seconds=time.perf_counter() - t0,
        test_seed=int(entry["seed"]),
        event_rate=float(np.mean(ev.event_counts)) / (h * w * (t - 1)),
        clip_event_rates=np.asarray(ev.event_counts, dtype=np.float64) / (h * w * ev.durations_s),
        failures=ev.failures,
        n_drawn=len(drawn),
        details=_task_details(metric, ds, ev, entry, evaluator, rate_hz if first is not None else None),
    )
    return evidence, sensor_rec


def _clips_per_video(ds: Any, entry: Mapping[str, Any], drawn: np.ndarray) -> tuple[Any, Mapping[str, Any], Any]:
    """With a ``sampling`` table: the drawn videos' clips (several per video, scored per video), the table
    scoring all of them, and the clips to probe for the frame rate; without: as given."""
    from ..tasks.clip_sampling import SampledVideoClips, SamplingSpec

    if entry.get("sampling") is None:
        return ds, entry, drawn
    clips = SampledVideoClips(ds, ds.size, SamplingSpec(**entry["sampling"]), video_indices=drawn)
    return clips, {**entry, "n_clips": 0}, range(len(clips))


def _task_details(
    metric: Any, ds: Any, ev: Any, entry: Mapping[str, Any], evaluator: Any, fps: float | None
) -> dict[str, Any]:
    """The track's per-class metrics with CIs (seeded with the clip draw's seed: every kernel gets the
    same resamples) and the dataset's summary (:mod:`fsdvs_hw.tasks.per_class`)."""
    from ..tasks.per_class import dataset_summary, per_class_metrics

    logits = ev.predictions.get("logits") if evaluator.name == "recognition" else None
    predicted = None if logits is None else np.asarray(logits).argmax(axis=1)
    train = entry.get("train") or {}
    return {
        "per_class": per_class_metrics(metric, ds.class_names, predicted=predicted, seed=int(entry["seed"])),
        "dataset_summary": dataset_summary(
            ds, ev.clip_indices, train_size=(train.get("n_train") or None) if train else None, fps=fps
        ),
    }


def user_task_record(entry: Mapping[str, Any]) -> dict[str, Any]:
    """What a task track's record says about a user-data task: the dataset, the network, the CI.

    Examples
    --------
    >>> from fsdvs_hw.design.user_data_section import UserTask
    >>> rec = user_task_record(UserTask(dataset={"format": "video_folder", "root": "ucf"}).model_dump())
    >>> rec["dataset"]["format"], rec["network"]["factory"]
    ('video_folder', 'built-in')
    """
    src = entry["dataset"]
    return {
        "dataset": {k: src.get(k) for k in ("format", "root", "split", "n_frames", "size")}
        | {"n_clips": entry["n_clips"], "seed": entry["seed"]},
        "network": {
            "factory": entry["network"] or "built-in",
            "options": dict(entry["network_options"]),
            "weights": entry["weights"],
            "device": entry["device"],
        },
        "train": dict(entry["train"]) if entry.get("train") else None,
        "ci_note": ONE_NETWORK_NOTE,
    }
