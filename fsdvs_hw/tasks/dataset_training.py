"""Train a network (and learn its kernel) on a user clip dataset with the FS-DVS two-stage protocol.

:func:`train_on_dataset` is :func:`fsdvs_hw.tasks.learn.learn_kernel`'s protocol on the user's
clips and network, through the same training engine (:func:`fsdvs_hw.tasks.training.train_epochs`):

1. **stage one** (``epochs_frozen``): the spatial kernel is frozen (a Dirac delta plus small
   Gaussian noise, or ``init_kernel``) and the network trains alone with AdamW at
   ``lr_network``; the events never change, so they are simulated once;
2. **stage two** (``epochs_joint``): kernel and network train jointly with decoupled AdamW rates:
   ``lr_kernel`` for the kernel taps, ``lr_backbone`` and ``lr_head`` for the network's
   ``backbone`` and ``head`` sub-modules (a network without them trains as one group at
   ``lr_head``). Unset, the network rates follow the paper's ratios to the kernel rate
   (:attr:`~fsdvs_hw.tasks.evaluators.TaskEvaluator.joint_lr_ratios`: detection 5e-4 / 1e-6 /
   1e-5, recognition 5e-4 / 5e-5 / 1e-4).

From scratch, the network starts from the factory's initialisation; **fine-tuning** starts it
from the user's weights (the caller loads them) and is the same two stages. With
``learn_filter=False`` the kernel stays frozen in both stages (a network for a fixed kernel).
With ``realisation`` (a fitted record with a differentiable form), stage two trains the
realisation's physical parameters instead of free taps
(:func:`fsdvs_hw.tasks.learn.differentiable_realisation`), so the kernel stays buildable at
every step: the co-designed row of :mod:`fsdvs_hw.explore.codesign` on user data.

Train / test clips
    The caller passes the training clips' indices; :func:`disjoint_train_indices` draws them
    (seeded) from the clips NOT scored, so the two sets are disjoint by construction.
Streamed training
    With ``stream`` (:class:`~fsdvs_hw.tasks.clip_stream.StreamSpec`), ``sampling``
    (:class:`~fsdvs_hw.tasks.clip_sampling.SamplingSpec`) or ``val_fraction`` > 0 the training
    clips are not held in memory: a DataLoader decodes them per batch (``workers`` processes; at
    most ``memory_mb`` of clips held, default 1024 MB), and a frozen kernel's events are simulated
    per batch too. ``sampling`` (a ``video_folder`` dataset with a ``size``) trains on
    ``train_clips_per_video`` random clips of each video per epoch with a seeded crop and flip and
    validates on ``clips_per_video`` evenly spaced, centre-cropped ones. ``val_fraction`` (0 … 0.9)
    of the training videos (seeded with ``seed``, :func:`validation_split`) are held out and scored
    after every epoch with the task's primary metric (recognition per video: the mean of its
    clips' probabilities): the history's ``val_metric`` / ``val_loss``; the result and the
    checkpoint are the **best** epoch's network and kernel (the first of equal bests;
    ``provenance["streaming"]["best_epoch"]``; ``STEM.best.pt`` holds it while training).
Resume
    With ``out``, the state after every epoch (network, kernel, optimiser, batch-order generator,
    history) is written atomically to ``STEM.partial.pt``; the finished run writes the checkpoint
    files of :func:`~fsdvs_hw.tasks.learn.learn_kernel` (``STEM.json`` kernel,
    ``STEM.safetensors`` network + kernel, ``STEM.provenance.json``) and removes the partial file.
    A rerun with the same ``fingerprint`` reuses the finished checkpoint (no epoch trained) or
    continues from the last finished epoch; a different fingerprint is refused.

References
----------
FS-DVS paper, Sec. IV-A (two-stage training, decoupled learning rates, delta initialisation).
Loshchilov & Hutter, "Decoupled weight decay regularization" (AdamW), ICLR (2019).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from ..errors import InputError
from ..kernels import Kernel
from ..limits import MAX_CLIPS, MAX_EPOCHS, MAX_SEED, check_allocation, check_count
from ..validation import check_real
from .checkpoints import (
    check_fingerprint,
    checkpoint_paths,
    checkpoint_stem,
    load_checkpoint,
    load_partial,
    save_checkpoint,
    save_partial,
)
from .dataset_eval import evaluator_for_dataset, torch_device
from .event_inputs import simulated_events
from .training import (
    TrainingConfig,
    TrainingData,
    adamw_optimizer,
    delta_init,
    kernel_taps,
    print_progress,
    train_epochs,
)

__all__ = [
    "RESULT_NEUTRAL_TRAIN_KEYS",
    "DatasetTrainingResult",
    "disjoint_train_indices",
    "load_trained",
    "streaming_arguments",
    "train_on_dataset",
    "validation_split",
]

#: ``train`` keys that change no trained weight (how the clips are loaded): left out of fingerprints.
RESULT_NEUTRAL_TRAIN_KEYS = ("memory_mb", "workers")

_STAGES = ("frozen_filter", "joint")


@dataclass(frozen=True)
class DatasetTrainingResult:
    """What :func:`train_on_dataset` returns.

    Attributes
    ----------
    kernel : Kernel
        The kernel after training (the initial one if it was frozen).
    network : torch.nn.Module
        The trained network, in eval mode, on the CPU.
    history : list of dict
        Per epoch: ``stage``, ``epoch``, ``loss`` (mean training loss), ``seconds``,
        ``kernel_change_l1`` (sum of ``|taps - initial taps|``).
    train_indices : numpy.ndarray, int64
        The dataset clips trained on.
    provenance : dict
    paths : dict of str to Path
        ``kernel``, ``checkpoint``, ``provenance`` when ``out`` was given.
    epochs_trained : int
        Epochs trained by this call (0 when a finished checkpoint was reused).
    """

    kernel: Kernel
    network: Any
    history: list[dict[str, Any]]
    train_indices: np.ndarray
    provenance: dict[str, Any]
    paths: dict[str, Path] = field(default_factory=dict)
    epochs_trained: int = 0


def disjoint_train_indices(n_total: int, test_indices: Any, n_train: int, seed: int) -> np.ndarray:
    """``n_train`` clip indices drawn with ``seed`` from the ``n_total`` clips not in ``test_indices``.

    Parameters
    ----------
    n_total : int
        Clips in the dataset.
    test_indices : array of int
        The clips scored (never trained on).
    n_train : int
        Clips wanted; 0 = every clip not scored.
    seed : int

    Returns
    -------
    numpy.ndarray, int64
        Sorted, disjoint from ``test_indices``.

    Raises
    ------
    InputError
        Fewer than ``n_train`` (or than 2) clips left once the scored ones are set aside.

    Examples
    --------
    >>> disjoint_train_indices(6, [0, 3], 0, seed=1).tolist()
    [1, 2, 4, 5]
    >>> sorted(set(disjoint_train_indices(100, range(50), 10, seed=0)) & set(range(50)))
    []
    """
    n_total = check_count("n_total", n_total, 1, MAX_CLIPS)
    seed = check_count("train.seed", seed, 0, MAX_SEED)
    free = np.setdiff1d(np.arange(n_total), np.asarray(list(test_indices), dtype=np.int64))
    n_train = check_count("train.n_train", n_train, 0, MAX_CLIPS)
    want = len(free) if n_train == 0 else n_train
    if len(free) < max(2, want):
        raise InputError(
            f"train.n_train = {n_train}: {len(free)} of the {n_total} clips are left once the "
            f"{n_total - len(free)} scored clips are set aside; allowed: 0 (all of them) or 2 to "
            f"{len(free)} (score fewer clips: n_clips)"
        )
    return np.sort(np.random.default_rng(seed).choice(free, size=want, replace=False)).astype(np.int64)


def _training_targets(evaluator: Any, targets: dict[str, np.ndarray], h: int, w: int) -> dict[str, Any]:
    """The evaluator's training targets (detection: CenterNet heatmaps from the boxes) as tensors."""
    import torch

    if evaluator.name == "detection":
        batch = SimpleNamespace(
            boxes=targets["boxes"][:, None],
            labels=targets["labels"].copy(),
            config=SimpleNamespace(height_px=h, width_px=w),
        )
        return evaluator.targets(batch)
    return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in targets.items()}


def _load_clips(dataset: Any, indices: np.ndarray, evaluator: Any) -> tuple[Any, dict[str, Any], np.ndarray]:
    """(video (N, T, H, W) float32, training targets, timestamps of the first clip) of ``indices``."""
    import torch

    from ..scenes.datasets import stack_targets

    first = dataset[int(indices[0])]
    t, h, w = first.frames.shape
    try:
        check_allocation(
            f"training clips (N={len(indices)}, T={t}, H={h}, W={w}, float32)", 4 * len(indices) * t * h * w
        )
    except InputError as exc:
        raise InputError(f"{exc}; or stream them from disk with bounded memory: train.memory_mb = 1024") from None
    video = torch.empty((len(indices), t, h, w), dtype=torch.float32)
    clips = []
    for n, i in enumerate(indices):
        clip = first if n == 0 else dataset[int(i)]
        if clip.frames.shape != (t, h, w):
            raise InputError(
                f"train_on_dataset: clip {int(i)} ({clip.source!r}) has shape {clip.frames.shape}, "
                f"clip {int(indices[0])} {(t, h, w)}; field 'size': give the dataset a size=(H, W)"
            )
        video[n] = torch.from_numpy(clip.frames)
        clips.append(clip)
    return video, _training_targets(evaluator, stack_targets(clips), h, w), first.timestamps_s


def load_trained(
    out: str | Path, network: Any, *, fingerprint: dict[str, Any] | None = None, who: str = "load_trained"
) -> tuple[Any, Kernel, dict[str, Any]] | None:
    """A finished :func:`train_on_dataset` checkpoint at ``out`` loaded into ``network``, or None if absent.

    Parameters
    ----------
    out : path
        The file stem the training wrote (``STEM.safetensors``).
    network : torch.nn.Module
        A network of the same architecture (its weights are replaced).
    fingerprint : dict, optional
        Must equal the stored one (the run's data, network and settings).

    Returns
    -------
    (network, kernel, provenance) or None

    Raises
    ------
    InputError
        The checkpoint was trained with another fingerprint, or does not fit ``network``.

    Examples
    --------
    >>> load_trained("nets/does_not_exist", None) is None
    True
    """
    stem = checkpoint_stem(out)
    ckpt = checkpoint_paths(stem)["checkpoint"]
    if not ckpt.is_file():
        return None
    provenance, state, kernel = load_checkpoint(stem)
    check_fingerprint(provenance.get("fingerprint"), fingerprint, ckpt)
    try:
        network.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        raise InputError(
            f"{who}: checkpoint {stem!s}.safetensors does not fit the network ({str(exc).splitlines()[0]})"
        ) from None
    return network.eval(), kernel, provenance


def train_on_dataset(
    dataset: Any,
    task: Any,
    network: Any = None,
    *,
    train_indices: Any,
    kernel_size: int = 7,
    init_kernel: Any = None,
    learn_filter: bool = True,
    realisation: Any = None,
    epochs_frozen: int = 2,
    epochs_joint: int = 2,
    lr_network: float = 3e-3,
    lr_kernel: float = 1e-2,
    lr_backbone: float | None = None,
    lr_head: float | None = None,
    weight_decay: float = 1e-4,
    batch_size: int = 8,
    seed: int = 0,
    init_noise: float = 1e-2,
    sensor: Any = None,
    device: str = "cpu",
    out: str | Path | None = None,
    fingerprint: dict[str, Any] | None = None,
    verbose: bool = False,
    sampling: Any = None,
    stream: Any = None,
    val_fraction: float = 0.0,
) -> DatasetTrainingResult:
    """Train ``network`` and learn a k×k kernel on clips of a user dataset (two stages, decoupled rates).

    Parameters
    ----------
    dataset : ClipDataset
        :mod:`fsdvs_hw.scenes.datasets`; its task must be ``task``'s.
    task : str or TaskEvaluator
    network : None, str or torch.nn.Module
        None: the task's built-in network; ``"package.module:factory"``; or a module (weights already loaded for
        fine-tuning). Its ``event_input`` picks the representation.
    train_indices : array of int
        The clips trained on (:func:`disjoint_train_indices`); held in memory as float32 unless streamed.
    kernel_size : int
        Odd kernel side in pixels, 1 … 15 (ignored with ``init_kernel``).
    init_kernel : Kernel, path or array, optional
        Start from this kernel instead of delta + ``init_noise``.
    learn_filter : bool
        False: the kernel stays frozen in both stages. ``init_noise``: the delta's noise (standard deviation).
    realisation : Realisation, optional
        A fitted realisation record with a differentiable form: its kernel is the start (instead of ``init_kernel`` /
        the delta) and stage two trains its physical parameters at ``lr_kernel``; the provenance adds ``realisation``,
        ``realisation_initial`` and ``realisation_design`` (the record after training).
    epochs_frozen, epochs_joint : int
        Epochs of stage one (kernel frozen) and stage two (joint).
    batch_size, seed : int
        Clips per step; seeds the kernel noise, the torch initialisation and the batch order.
    lr_network, lr_kernel, lr_backbone, lr_head : float
        AdamW rates (1/step): of the network in stage one; of the kernel, the backbone and the head in stage two
        (``lr_backbone`` / ``lr_head`` None = ``lr_kernel`` times the evaluator's :attr:`joint_lr_ratios`, the paper's).
    weight_decay : float
        AdamW weight decay of the network (the kernel has none).
    sensor, device : SensorConfig, str
        Default: the training sensor (:func:`~fsdvs_hw.tasks.learn.default_sensor`) at the clips' frame rate;
        ``"cpu"`` or ``"cuda"`` / ``"cuda:N"``: where the simulator and the network train.
    out, fingerprint : path, dict, optional
        File stem of the checkpoint (and of ``STEM.partial.pt`` while training; resumes); the JSON-able identity
        of the run (data, network, settings) stored and compared on resume.
    verbose : bool
        One line per epoch on stderr (with the validation metric).
    sampling, stream, val_fraction : SamplingSpec, StreamSpec, float
        Clips per video, crop and flip; the loader's memory bound and workers; the fraction of the training videos
        validated after every epoch (the best epoch kept): the module text's *Streamed training*.

    Returns
    -------
    DatasetTrainingResult

    Raises
    ------
    InputError
        Bad counts or rates, a task / dataset mismatch, clips of different sizes, a kernel larger than the frames, a
        checkpoint or partial file trained with another fingerprint.

    Examples
    --------
    >>> idx = disjoint_train_indices(len(ds), ds.draw(8, seed=0), 0, seed=0)         # doctest: +SKIP
    >>> res = train_on_dataset(ds, "recognition", "mynets:tiny", train_indices=idx)  # doctest: +SKIP
    >>> res.kernel.size, res.history[-1]["stage"]                                    # doctest: +SKIP
    (7, 'joint')
    """
    t_start = time.perf_counter()
    evaluator = evaluator_for_dataset(task, dataset)
    dev = torch_device(device)
    rates = (lr_network, lr_kernel, lr_backbone, lr_head, weight_decay, init_noise)
    schedule = _checked_schedule(evaluator, epochs_frozen, epochs_joint, batch_size, seed, rates)
    indices = _checked_indices(train_indices, len(dataset))
    kernel = (kernel_size, init_kernel, learn_filter, realisation)
    args = (dataset, evaluator, network, indices, schedule, kernel, sensor, dev, out, fingerprint, verbose, t_start)
    streaming = _streaming_options(sampling, stream, val_fraction)
    return _train(*args) if streaming is None else _train_streamed(*args, streaming)


@dataclass(frozen=True)
class _Schedule:
    """:func:`train_on_dataset`'s checked schedule: epochs per stage, batch size, seed, AdamW rates
    (``network`` stage one; ``kernel``, ``backbone``, ``head`` stage two; 1/step), weight decay and
    the delta's noise."""

    epochs: dict[str, int]
    batch_size: int
    seed: int
    rates: dict[str, float]
    weight_decay: float
    init_noise: float


def _checked_schedule(
    evaluator: Any, epochs_frozen: Any, epochs_joint: Any, batch_size: Any, seed: Any, rates: tuple[Any, ...]
) -> _Schedule:
    """The schedule of :func:`train_on_dataset`, each value checked in turn (InputError naming its key);
    ``rates`` = (lr_network, lr_kernel, lr_backbone, lr_head, weight_decay, init_noise)."""
    lr_network, lr_kernel, lr_backbone, lr_head, weight_decay, init_noise = rates
    epochs = {
        "frozen_filter": check_count("train.epochs_frozen", epochs_frozen, 0, MAX_EPOCHS),
        "joint": check_count("train.epochs_joint", epochs_joint, 0, MAX_EPOCHS),
    }
    batch_size = check_count("train.batch_size", batch_size, 1, 100_000)
    seed = check_count("train.seed", seed, 0, MAX_SEED)
    lr_network = check_real("train.lr_network", lr_network, 0.0, 10.0)
    lr_kernel = check_real("train.lr_kernel", lr_kernel, 0.0, 10.0)
    ratios = getattr(evaluator, "joint_lr_ratios", (1.0, 1e-6 / 5e-4, 1e-5 / 5e-4))
    lr_backbone = _rate_or_default("train.lr_backbone", lr_backbone, lr_kernel * ratios[1])
    lr_head = _rate_or_default("train.lr_head", lr_head, lr_kernel * ratios[2])
    return _Schedule(
        epochs=epochs,
        batch_size=batch_size,
        seed=seed,
        rates={"network": lr_network, "kernel": lr_kernel, "backbone": lr_backbone, "head": lr_head},
        weight_decay=check_real("train.weight_decay", weight_decay, 0.0, 10.0),
        init_noise=check_real("train.init_noise", init_noise, 0.0, 10.0),
    )


def _train(
    dataset: Any,
    evaluator: Any,
    network: Any,
    indices: np.ndarray,
    schedule: _Schedule,
    kernel: tuple[Any, Any, bool, Any],
    sensor: Any,
    dev: Any,
    out: str | Path | None,
    fingerprint: dict[str, Any] | None,
    verbose: bool,
    t_start: float,
) -> DatasetTrainingResult:
    """:func:`train_on_dataset` once its arguments are checked; ``kernel`` = (kernel_size,
    init_kernel, learn_filter, realisation)."""
    import torch

    from .learn import default_sensor
    from .user_networks import event_input_of, network_for

    kernel_size, init_kernel, learn_filter, realisation = kernel
    torch.manual_seed(schedule.seed)
    gen = torch.Generator().manual_seed(schedule.seed)
    module, realised, taps0 = _kernel_start(realisation, init_kernel, kernel_size, schedule.init_noise, gen)
    learn_filter = bool(learn_filter and taps0.shape[0] > 1)

    video, targets, ts = _load_clips(dataset, indices, evaluator)
    h, w = video.shape[-2:]
    if taps0.shape[0] > min(h, w):
        raise InputError(
            f"train_on_dataset: a {taps0.shape[0]}x{taps0.shape[0]} kernel is larger than the {h}x{w} frames"
        )
    net = network_for(network, evaluator.name, 2 * (video.shape[1] - 1), evaluator.num_classes)
    rep = event_input_of(net)
    sensor = default_sensor(SimpleNamespace(frame_rate_hz=1.0 / float(np.diff(ts)[0]))) if sensor is None else sensor
    video, net = video.to(dev), net.to(dev).train()
    targets = {k: v.to(dev) for k, v in targets.items()}
    kernel_param = _kernel_parameter(module, taps0, learn_filter, dev)

    def input_fn(v: Any, k: Any, s: Any, t: Any) -> Any:
        return rep(simulated_events(v, k, s, t).float(), t)

    fingerprint = None if fingerprint is None else json.loads(json.dumps(fingerprint))
    stem = None if out is None else checkpoint_stem(out)
    if stem is not None:
        finished = _finished_run(stem, net, fingerprint, indices)
        if finished is not None:
            return finished
        net = net.to(dev)
    data = TrainingData(video, targets, sensor, ts, input_fn)
    run = _Run(evaluator, net, kernel_param, gen, schedule, learn_filter, taps0.to(dev), fingerprint, verbose)
    history, trained = _train_stages(run, data, None if stem is None else Path(str(stem) + ".partial.pt"))
    net = net.cpu().eval()
    with torch.no_grad():
        taps = kernel_taps(kernel_param).detach().cpu().numpy()
    realised.update(_realisation_after(module, evaluator.name))
    facts = {"dataset": type(dataset).__name__, "network": type(net).__name__, "device": str(dev)}
    provenance = _provenance(
        evaluator, schedule, learn_filter, indices, facts, rep, sensor, history, fingerprint, t_start, realised
    )
    return _result(dataset, evaluator, taps, net, history, indices, provenance, stem, trained)


def _provenance(
    evaluator: Any,
    schedule: _Schedule,
    learn_filter: bool,
    indices: np.ndarray,
    facts: dict[str, str],
    rep: Any,
    sensor: Any,
    history: list[dict[str, Any]],
    fingerprint: Any,
    t_start: float,
    realised: dict[str, Any],
) -> dict[str, Any]:
    """The provenance of a training run (``facts``: the dataset's, the network's and the device's names)."""
    from ..provenance import library_versions

    return {
        "task": evaluator.name,
        "dataset": facts["dataset"],
        "num_classes": evaluator.num_classes,
        "protocol": "frozen kernel, then joint (decoupled rates)" if learn_filter else "kernel frozen",
        "epochs_frozen": schedule.epochs["frozen_filter"],
        "epochs_joint": schedule.epochs["joint"],
        "learning_rates": {
            "network_stage_one": schedule.rates["network"],
            "kernel": schedule.rates["kernel"] if learn_filter else 0.0,
            "backbone": schedule.rates["backbone"],
            "head": schedule.rates["head"],
        },
        "weight_decay": schedule.weight_decay,
        "batch_size": schedule.batch_size,
        "seed": schedule.seed,
        "init_noise": schedule.init_noise,
        "learn_filter": learn_filter,
        "n_train": int(len(indices)),
        "train_indices": indices.tolist(),
        "network": facts["network"],
        "event_input": rep.kind if rep.n_bins is None else f"voxel:{rep.n_bins}",
        "sensor": sensor.to_dict(),
        "history": history,
        "fingerprint": fingerprint,
        "train_seconds": time.perf_counter() - t_start,
        "device": facts["device"],
        "versions": library_versions(),
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        **realised,
    }


@dataclass(frozen=True)
class _Run:
    """What :func:`_train_stages` trains: the network and the kernel (taps or a realisation module),
    on ``dev``, with the batch-order generator, the schedule, whether the kernel learns, its initial
    taps, the run's fingerprint and whether progress is printed."""

    evaluator: Any
    net: Any
    kernel_param: Any
    gen: Any
    schedule: _Schedule
    learn_filter: bool
    taps_init: Any
    fingerprint: Any
    verbose: bool


def _train_stages(run: _Run, data: TrainingData, partial: Path | None) -> tuple[list[dict[str, Any]], int]:
    """Both stages from the last finished epoch of ``partial`` (if any), saving it after each epoch:
    (history, epochs trained by this call)."""
    history, start, opt_state = load_partial(partial, run.fingerprint, run.net, run.kernel_param, run.gen)
    trained = 0
    for s_idx, stage in enumerate(_STAGES):
        epochs = run.schedule.epochs[stage]
        if s_idx < start[0] or epochs == 0:
            continue
        first_epoch = start[1] if s_idx == start[0] else 0
        if first_epoch >= epochs:
            continue
        rates = run.schedule.rates
        if stage == "frozen_filter":
            opt = adamw_optimizer(run.net, run.schedule.weight_decay, {"network": rates["network"]})
        else:
            trained_kernel = run.kernel_param if run.learn_filter else None
            joint_rates = {k: rates[k] for k in ("kernel", "backbone", "head")}
            opt = adamw_optimizer(run.net, run.schedule.weight_decay, joint_rates, trained_kernel)
        if opt_state is not None and s_idx == start[0]:
            opt.load_state_dict(opt_state)
        frozen = stage == "frozen_filter" or not run.learn_filter  # a frozen kernel: the events never change
        config = TrainingConfig(
            stage if run.learn_filter or stage == "frozen_filter" else "joint_frozen_filter",
            epochs,
            run.schedule.batch_size,
            first_epoch=first_epoch,
            progress=print_progress if run.verbose else None,
            progress_stage=stage,
            on_epoch_end=_partial_saver(partial, run, opt, history, s_idx),
        )
        trained += train_epochs(
            config,
            evaluator=run.evaluator,
            network=run.net,
            kernel=run.kernel_param,
            data=data.with_frozen_kernel(kernel_taps(run.kernel_param), chunk=64) if frozen else data,
            optimizer=opt,
            generator=run.gen,
            history=history,
            kernel_init=run.taps_init,
        )
    return history, trained


def _partial_saver(
    partial: Path | None, run: _Run, opt: Any, history: list[dict[str, Any]], stage_index: int
) -> Callable[[int], None] | None:
    """The ``on_epoch_end`` of a stage: the state after the epoch to ``partial`` (None: no file)."""
    if partial is None:
        return None

    def save(epoch: int) -> None:
        save_partial(
            partial, run.net, run.kernel_param, run.gen, opt, history, (stage_index, epoch + 1), run.fingerprint
        )

    return save


def _result(
    dataset: Any,
    evaluator: Any,
    taps: np.ndarray,
    net: Any,
    history: list[dict[str, Any]],
    indices: np.ndarray,
    provenance: dict[str, Any],
    stem: Path | None,
    trained: int,
) -> DatasetTrainingResult:
    """The learned kernel, the checkpoint files at ``stem`` (the partial file removed) and the result."""
    seed = provenance["seed"]
    kernel = Kernel(
        taps,
        name=f"learned {evaluator.name} {taps.shape[0]}x{taps.shape[0]} on {type(dataset).__name__} (seed {seed})",
        provenance={k: v for k, v in provenance.items() if k not in ("history", "train_indices")},
    )
    paths: dict[str, Path] = {}
    if stem is not None:
        paths = save_checkpoint(stem, kernel, net, provenance)
        partial = Path(str(stem) + ".partial.pt")
        if partial.is_file():
            partial.unlink()
    return DatasetTrainingResult(
        kernel=kernel,
        network=net,
        history=history,
        train_indices=indices,
        provenance=provenance,
        paths=paths,
        epochs_trained=trained,
    )


def _checked_indices(train_indices: Any, n_clips: int) -> np.ndarray:
    """``train_indices`` as distinct int64 clip indices in ``[0, n_clips)`` (InputError otherwise)."""
    indices = np.asarray(list(train_indices), dtype=np.int64)
    if len(indices) < 1 or len(set(indices.tolist())) != len(indices) or indices.min() < 0 or indices.max() >= n_clips:
        raise InputError(
            f"train_on_dataset: train_indices must be distinct clip indices in [0, {n_clips}), "
            f"got {len(indices)} of them"
        )
    return indices


def _rate_or_default(key: str, value: float | None, default: float) -> float:
    """A checked learning rate in [0, 10] (1/step), or ``default`` when ``value`` is None."""
    return default if value is None else check_real(key, value, 0.0, 10.0)


def _finished_run(stem: Path, net: Any, fingerprint: Any, indices: np.ndarray) -> DatasetTrainingResult | None:
    """The finished checkpoint at ``stem`` trained with ``fingerprint`` (loaded into ``net``), or None."""
    stem.parent.mkdir(parents=True, exist_ok=True)
    done = load_trained(stem, net.cpu(), fingerprint=fingerprint, who="train_on_dataset")
    if done is None:
        return None
    net, kernel, prov = done
    return DatasetTrainingResult(
        kernel=kernel,
        network=net.cpu(),
        history=prov.get("history", []),
        train_indices=np.asarray(prov.get("train_indices", indices)),
        provenance=prov,
        paths=checkpoint_paths(stem),
        epochs_trained=0,
    )


def _kernel_start(
    realisation: Any, init_kernel: Any, kernel_size: Any, init_noise: float, gen: Any
) -> tuple[Any, dict[str, Any], Any]:
    """(realisation module or None, its provenance, the initial taps as a float64 CPU tensor)."""
    if realisation is None:
        return None, {}, _initial_taps(init_kernel, kernel_size, init_noise, gen)
    import torch

    from .learn import differentiable_realisation

    if init_kernel is not None:
        raise InputError("train_on_dataset: give at most one of init_kernel= and realisation=")
    module, realised = differentiable_realisation(realisation, who="train_on_dataset")
    with torch.no_grad():
        return module, realised, module().detach().to(torch.float64).cpu()


def _kernel_parameter(module: Any, taps0: Any, learn_filter: bool, dev: Any) -> Any:
    """What the optimiser trains, on ``dev``: free taps (a Parameter) or the realisation's module
    (called for the taps at every step, :func:`~fsdvs_hw.tasks.training.kernel_taps`)."""
    import torch

    if module is not None:
        return module.to(dev)
    return torch.nn.Parameter(taps0.clone().to(dev), requires_grad=learn_filter)


def _realisation_after(module: Any, task: str) -> dict[str, Any]:
    """``realisation_design``: the realisation record after training (``{}`` without a realisation)."""
    return {} if module is None else {"realisation_design": module.to_design(codesign_task=task).to_dict()}


def _initial_taps(init_kernel: Any, kernel_size: Any, init_noise: float, gen: Any) -> Any:
    """The kernel's start: ``init_kernel``, or a delta plus Gaussian noise (float64 tensor)."""
    import torch

    from ..kernels import as_kernel

    if init_kernel is not None:
        return torch.as_tensor(np.array(as_kernel(init_kernel, name="init_kernel").taps), dtype=torch.float64)
    if (
        isinstance(kernel_size, bool)
        or not isinstance(kernel_size, int)
        or not 1 <= kernel_size <= 15
        or kernel_size % 2 == 0
    ):
        raise InputError(f"train.kernel_size = {kernel_size!r}; allowed: an odd integer in [1, 15] (pixels)")
    return delta_init(kernel_size, init_noise if kernel_size > 1 else 0.0, gen)


# --------------------------------------------------------------------------- streamed training
@dataclass(frozen=True)
class _Streaming:
    """Streamed training's options: the sampling (or None), the loader's bound and the validation fraction."""

    sampling: Any
    stream: Any
    val_fraction: float


def _streaming_options(sampling: Any, stream: Any, val_fraction: Any) -> _Streaming | None:
    """The checked options of a streamed run, or None for the in-memory run (none of them given)."""
    from .clip_sampling import SamplingSpec
    from .clip_stream import StreamSpec

    val_fraction = check_real("train.val_fraction", val_fraction, 0.0, 0.9)
    if sampling is None and stream is None and val_fraction == 0.0:
        return None
    if sampling is not None and not isinstance(sampling, SamplingSpec):
        raise InputError(f"train_on_dataset: sampling is a {type(sampling).__name__}; allowed: a SamplingSpec")
    if stream is not None and not isinstance(stream, StreamSpec):
        raise InputError(f"train_on_dataset: stream is a {type(stream).__name__}; allowed: a StreamSpec")
    return _Streaming(sampling, StreamSpec() if stream is None else stream, val_fraction)


def streaming_arguments(sampling: Any, train: Any) -> dict[str, Any]:
    """:func:`train_on_dataset`'s ``sampling``, ``stream`` and ``val_fraction`` from a design's tables.

    Parameters
    ----------
    sampling : mapping or None
        ``[tasks.datasets.<task>] sampling`` dumped (:class:`~fsdvs_hw.design.user_data_section.SamplingTable`).
    train : mapping
        The ``train`` table dumped (``memory_mb``, ``workers``, ``val_fraction``; absent keys: their defaults).

    Examples
    --------
    >>> streaming_arguments(None, {"memory_mb": None, "workers": 0, "val_fraction": 0.0})
    {'sampling': None, 'stream': None, 'val_fraction': 0.0}
    >>> streaming_arguments(None, {"memory_mb": 256.0, "workers": 2})["stream"].memory_mb
    256.0
    """
    from .clip_sampling import SamplingSpec
    from .clip_stream import StreamSpec

    memory_mb, workers = train.get("memory_mb"), int(train.get("workers") or 0)
    stream = None
    if memory_mb is not None or workers:
        stream = StreamSpec(memory_mb=1024.0 if memory_mb is None else float(memory_mb), workers=workers)
    return {
        "sampling": None if sampling is None else SamplingSpec(**dict(sampling)),
        "stream": stream,
        "val_fraction": float(train.get("val_fraction") or 0.0),
    }


def validation_split(indices: Any, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(training, validation) clip indices: ``round(val_fraction × N)`` of ``indices`` (at least 1) held out with ``seed``.

    Examples
    --------
    >>> tr, va = validation_split(range(10), 0.2, seed=0)
    >>> len(tr), len(va), sorted(set(tr) & set(va))
    (8, 2, [])
    >>> validation_split(range(10), 0.0, seed=0)[1].tolist()
    []
    """
    indices = np.asarray(list(indices), dtype=np.int64)
    if val_fraction <= 0:
        return indices, indices[:0]
    n_val = max(1, int(round(val_fraction * len(indices))))
    if n_val >= len(indices):
        raise InputError(
            f"train.val_fraction = {val_fraction:g}: {n_val} of the {len(indices)} training videos would be held "
            "out, none left to train on; allowed: a smaller fraction or more training clips (train.n_train)"
        )
    held = np.random.default_rng([seed, 1]).choice(len(indices), size=n_val, replace=False)
    mask = np.zeros(len(indices), dtype=bool)
    mask[held] = True
    return indices[~mask], indices[mask]


def _streams(dataset: Any, indices: np.ndarray, options: _Streaming, seed: int) -> tuple[Any, Any, np.ndarray]:
    """(training stream, validation stream or None, video of each validation clip)."""
    from .clip_sampling import SampledVideoClips
    from .clip_stream import ClipStream

    train_idx, val_idx = validation_split(indices, options.val_fraction, seed)
    spec = options.sampling
    if spec is None:
        val = ClipStream(dataset, val_idx) if len(val_idx) else None
        return ClipStream(dataset, train_idx), val, val_idx
    if dataset.size is None:
        raise InputError(
            "train_on_dataset: sampling crops to the dataset's size; field 'size': give dataset.size = [H, W]"
        )
    train_ds = SampledVideoClips(dataset, dataset.size, spec, train=True)
    val_ds = SampledVideoClips(dataset, dataset.size, spec, train=False)
    k, kv = spec.train_clips_per_video, spec.clips_per_video
    train = ClipStream(train_ds, (train_idx[:, None] * k + np.arange(k)).ravel())
    val_clips = (val_idx[:, None] * kv + np.arange(kv)).ravel()
    return train, (ClipStream(val_ds, val_clips) if len(val_idx) else None), np.repeat(val_idx, kv)


def _val_metric(evaluator: Any, preds: dict[str, Any], targets: dict[str, np.ndarray], videos: np.ndarray) -> float:
    """The primary metric on the validation clips (recognition: per video, the mean over its clips)."""
    import torch

    from .dataset_eval import mean_over_videos

    if evaluator.name == "recognition":
        vids, scores = mean_over_videos(preds["logits"], videos)
        first = [int(np.flatnonzero(videos == v)[0]) for v in vids]
        preds, targets = {"logits": scores.float()}, {"motion": targets["motion"][first]}
    t = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in targets.items()}
    return float(evaluator.score(preds, t)[evaluator.primary_metric])


@dataclass
class _Validation:
    """The validation loader, each clip's video, and the best epoch so far (its state kept in memory
    and in ``STEM.best.pt``)."""

    loader: Any
    videos: np.ndarray
    path: Path | None
    best_metric: float = -np.inf
    best_epoch: int | None = None
    state: dict[str, Any] | None = None


def _keep_if_best(val: _Validation, run: _Run, record: dict[str, Any], epoch_number: int) -> None:
    """Record ``val_metric`` is the best so far (ties keep the earlier epoch): keep the network and kernel."""
    import os

    import torch

    if not record["val_metric"] > val.best_metric:
        return
    val.best_metric, val.best_epoch = record["val_metric"], epoch_number
    kernel = run.kernel_param
    val.state = {
        "network": {k: v.detach().cpu().clone() for k, v in run.net.state_dict().items()},
        "kernel": {k: v.detach().cpu().clone() for k, v in kernel.state_dict().items()}
        if isinstance(kernel, torch.nn.Module)
        else kernel.detach().cpu().clone(),
        "epoch": epoch_number,
        "val_metric": val.best_metric,
    }
    if val.path is not None:
        tmp = val.path.with_name(val.path.name + ".tmp")
        torch.save(val.state, tmp)
        os.replace(tmp, val.path)


def _restore_best(val: _Validation, run: _Run) -> None:
    """Load the best epoch's network and kernel into the run (from memory or ``STEM.best.pt`` on a resume)."""
    import torch

    state = val.state
    if state is None and val.path is not None and val.path.is_file():
        state = torch.load(val.path, map_location="cpu", weights_only=True)
    if state is None:
        return
    run.net.load_state_dict(state["network"])
    with torch.no_grad():
        if isinstance(run.kernel_param, torch.nn.Module):
            run.kernel_param.load_state_dict(state["kernel"])
        else:
            run.kernel_param.copy_(state["kernel"].to(run.kernel_param.device))
    val.best_epoch, val.best_metric = int(state["epoch"]), float(state["val_metric"])


def _stream_stages(
    run: _Run, loader: Any, batch_input: Any, targets_fn: Any, val: _Validation | None, partial: Path | None
) -> tuple[list[dict[str, Any]], int]:
    """Both stages over the streamed loader (as :func:`_train_stages`), validating after every epoch."""
    from .clip_stream import predict_stream, train_epoch_streamed

    history, start, opt_state = load_partial(partial, run.fingerprint, run.net, run.kernel_param, run.gen)
    if val is not None:  # a resumed run: the best so far from the history
        done = [h.get("val_metric", -np.inf) for h in history]
        val.best_metric = max(done, default=-np.inf)
    trained = 0
    for s_idx, stage in enumerate(_STAGES):
        epochs = run.schedule.epochs[stage]
        first_epoch = start[1] if s_idx == start[0] else 0
        if s_idx < start[0] or epochs == 0 or first_epoch >= epochs:
            continue
        rates = run.schedule.rates
        trains_kernel = stage == "joint" and run.learn_filter
        if stage == "frozen_filter":
            opt = adamw_optimizer(run.net, run.schedule.weight_decay, {"network": rates["network"]})
        else:
            joint_rates = {k: rates[k] for k in ("kernel", "backbone", "head")}
            opt = adamw_optimizer(
                run.net, run.schedule.weight_decay, joint_rates, run.kernel_param if trains_kernel else None
            )
        if opt_state is not None and s_idx == start[0]:
            opt.load_state_dict(opt_state)
        name = stage if run.learn_filter or stage == "frozen_filter" else "joint_frozen_filter"
        save = _partial_saver(partial, run, opt, history, s_idx)
        for epoch in range(first_epoch, epochs):
            record = train_epoch_streamed(
                name,
                epoch,
                run.evaluator,
                run.net,
                run.kernel_param,
                loader,
                batch_input,
                targets_fn,
                opt,
                run.taps_init,
            )
            if val is not None:
                preds, targets, loss = predict_stream(
                    run.evaluator, run.net, run.kernel_param, val.loader, batch_input, targets_fn
                )
                record["val_metric"] = _val_metric(run.evaluator, preds, targets, val.videos)
                record["val_loss"] = loss
                record["val_metric_name"] = run.evaluator.primary_metric
                _keep_if_best(val, run, record, len(history))
            history.append(record)
            trained += 1
            if run.verbose:
                extra = f", val {record['val_metric_name']} {record['val_metric']:.4f}" if val is not None else ""
                print_progress(
                    f"[learn] {run.evaluator.name} {stage} epoch {epoch + 1}/{epochs}: loss {record['loss']:.4f}"
                    f"{extra} ({record['seconds']:.1f} s)"
                )
            if save is not None:
                save(epoch)
    return history, trained


def _train_streamed(
    dataset: Any,
    evaluator: Any,
    network: Any,
    indices: np.ndarray,
    schedule: _Schedule,
    kernel: tuple[Any, Any, bool, Any],
    sensor: Any,
    dev: Any,
    out: str | Path | None,
    fingerprint: dict[str, Any] | None,
    verbose: bool,
    t_start: float,
    options: _Streaming,
) -> DatasetTrainingResult:
    """:func:`_train` with the clips streamed (bounded memory), sampled and validated per epoch."""
    import torch

    from .clip_stream import clip_loader
    from .learn import default_sensor
    from .user_networks import event_input_of, network_for

    kernel_size, init_kernel, learn_filter, realisation = kernel
    torch.manual_seed(schedule.seed)
    gen = torch.Generator().manual_seed(schedule.seed)
    module, realised, taps0 = _kernel_start(realisation, init_kernel, kernel_size, schedule.init_noise, gen)
    learn_filter = bool(learn_filter and taps0.shape[0] > 1)
    train_stream, val_stream, val_videos = _streams(dataset, indices, options, schedule.seed)
    loader, plan = clip_loader(train_stream, schedule.batch_size, options.stream, generator=gen)
    first = train_stream.dataset[int(train_stream.indices[0])]
    t, h, w = first.frames.shape
    ts = first.timestamps_s
    if taps0.shape[0] > min(h, w):
        raise InputError(
            f"train_on_dataset: a {taps0.shape[0]}x{taps0.shape[0]} kernel is larger than the {h}x{w} frames"
        )
    net = network_for(network, evaluator.name, 2 * (t - 1), evaluator.num_classes)
    rep = event_input_of(net)
    sensor = default_sensor(SimpleNamespace(frame_rate_hz=1.0 / float(np.diff(ts)[0]))) if sensor is None else sensor
    net = net.to(dev).train()
    kernel_param = _kernel_parameter(module, taps0, learn_filter, dev)

    def batch_input(video: Any, taps: Any) -> Any:
        return rep(simulated_events(video.to(dev), taps, sensor, ts).float(), ts)

    def targets_fn(tgt: dict[str, np.ndarray]) -> dict[str, Any]:
        return {k: v.to(dev) for k, v in _training_targets(evaluator, tgt, h, w).items()}

    fingerprint = None if fingerprint is None else json.loads(json.dumps(fingerprint))
    stem = None if out is None else checkpoint_stem(out)
    if stem is not None:
        finished = _finished_run(stem, net, fingerprint, indices)
        if finished is not None:
            return finished
        net = net.to(dev)
    val = None
    if val_stream is not None:
        val_loader, _ = clip_loader(val_stream, schedule.batch_size, options.stream)
        val = _Validation(val_loader, val_videos, None if stem is None else Path(str(stem) + ".best.pt"))
    run = _Run(evaluator, net, kernel_param, gen, schedule, learn_filter, taps0.to(dev), fingerprint, verbose)
    partial = None if stem is None else Path(str(stem) + ".partial.pt")
    history, trained = _stream_stages(run, loader, batch_input, targets_fn, val, partial)
    if val is not None:
        _restore_best(val, run)
    net = net.cpu().eval()
    with torch.no_grad():
        taps = kernel_taps(kernel_param).detach().cpu().numpy()
    realised.update(_realisation_after(module, evaluator.name))
    facts = {"dataset": type(dataset).__name__, "network": type(net).__name__, "device": str(dev)}
    provenance = _provenance(
        evaluator, schedule, learn_filter, indices, facts, rep, sensor, history, fingerprint, t_start, realised
    )
    provenance["streaming"] = _streaming_record(options, plan, train_stream, val, val_stream)
    result = _result(dataset, evaluator, taps, net, history, indices, provenance, stem, trained)
    if val is not None and val.path is not None and val.path.is_file():
        val.path.unlink()
    return result


def _streaming_record(
    options: _Streaming, plan: dict[str, int], train: Any, val: Any, val_stream: Any
) -> dict[str, Any]:
    """What the provenance says of a streamed run: the loader's plan, the sampling, the validation."""
    from dataclasses import asdict

    return {
        "memory_mb": options.stream.memory_mb,
        "workers": plan["workers"],
        "prefetch": plan["prefetch"],
        "held_bytes_bound": plan["held_bytes"],
        "train_clips_per_epoch": len(train),
        "sampling": None if options.sampling is None else asdict(options.sampling),
        "val_fraction": options.val_fraction,
        "val_clips": 0 if val_stream is None else len(val_stream),
        "best_epoch": None if val is None else val.best_epoch,
        "best_val_metric": None if val is None or val.best_epoch is None else val.best_metric,
        "selected": "the best validation epoch" if val is not None else "the last epoch",
    }
