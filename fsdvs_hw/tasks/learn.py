"""End-to-end kernel learning (the FS-DVS protocol) and scoring any kernel on a trained task.

:func:`learn_kernel` follows the FS-DVS paper (Sec. IV-A):

1. the spatial filter ``W`` (k×k, applied to linear intensity before the log, through the
   differentiable event simulator :func:`fsdvs_hw.sensor.event_frames`) starts as a Dirac delta
   plus small Gaussian noise (``init_noise``; "1 at the centre and near-zero random values
   elsewhere", to break symmetry while starting from a conventional DVS);
2. staged tasks train the network with the filter frozen, then jointly: detection as in the
   paper; recognition too, because the paper fine-tunes a *pretrained* MViT jointly with the
   filter and here the frozen-filter stage stands in for that pretraining;
3. in the joint phase the learning rates are decoupled per parameter group (AdamW) with the
   paper's ratios (:attr:`TaskEvaluator.joint_lr_ratios`): filter / backbone / head =
   5e-4 / 1e-6 / 1e-5 (detection) and 5e-4 / 5e-5 / 1e-4 (recognition).

The paper trains 50 epochs on large datasets, i.e. tens of thousands of filter updates at 5e-4.
Here a run is 16 + 16 epochs of 2048 clips (64 batches of 32: ~1000 joint updates), so the filter
rate is raised to ``lr_filter`` = 1e-2 (20x the paper's) with the network rates following the
paper's ratios. AdamW moves a parameter by at most about its rate per update, so at 5e-4 x 1000
updates the taps could move by ~0.5 at most and in practice stay near the delta (the first shipped
detection kernel, at 1e-3 x 128 updates, kept a centre of 0.91 and surround taps <= 0.10); at
1e-2 they move by O(1) (the shipped kernels' centre 1.4-2.5, surround lobes down to -0.5).
The frozen-filter stage trains backbone and head from scratch at ``lr_network`` (3e-3).

The "w/o" baselines run the same schedule with the filter frozen at the delta, so every row of an
ablation has the same network learning rates and epochs.

:func:`evaluate_kernel` loads a checkpoint written by :func:`learn_kernel`, swaps a kernel into the
frozen network (zero-shot; optionally fine-tunes the network for a few epochs with that kernel
frozen) and scores it on the checkpoint's test set, regenerated bit-identically from its seed. With
the training kernel it reproduces the stored metric.

Checkpoint files (written next to each other from one stem, e.g. ``designs/kernels/learned_detection_7x7``,
by :func:`fsdvs_hw.tasks.checkpoints.save_checkpoint`; read by
:func:`~fsdvs_hw.tasks.checkpoints.load_checkpoint`):

``STEM.json``
    The kernel (:class:`~fsdvs_hw.kernels.Kernel` JSON) with the provenance inside.
``STEM.safetensors``
    Network weights (``network.*``) and the kernel taps (``kernel``); metadata ``format``
    (``fsdvs_hw.task_checkpoint``), ``version`` and ``provenance`` (JSON).
``STEM.provenance.json``
    Task, seed, data sizes, epochs, learning rates, scene and simulator settings, final metrics,
    loss history, wall time, library versions.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, KernelError, one_line
from ..kernels import Kernel
from ..validation import check_bool, check_instance, check_real
from .checkpoints import load_checkpoint, save_checkpoint
from .evaluators import concat_predictions
from .event_inputs import simulated_events
from .synthetic_data import synthetic_dataset
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
    "TEST_SEED",
    "Evaluation",
    "LearnResult",
    "TrainingSettings",
    "default_sensor",
    "differentiable_realisation",
    "evaluate_kernel",
    "finetune_network",
    "heldout_targets",
    "learn_kernel",
    "load_network",
]

#: Seed of every task's test clips (fixed, so that runs with different training seeds and kernel
#: sizes are scored on the same clips).
TEST_SEED: int = 1_000_003

#: Joint-phase learning-rate ratios (filter, backbone, head) relative to the filter rate after a
#: frozen-filter stage, from the FS-DVS paper's detection protocol: 5e-4 / 1e-6 / 1e-5.
PAPER_LR_RATIOS: tuple[float, float, float] = (1.0, 1e-6 / 5e-4, 1e-5 / 5e-4)


@dataclass(frozen=True)
class TrainingSettings:
    """Training knobs of :func:`learn_kernel` (defaults: the shipped kernels' settings).

    Parameters
    ----------
    epochs_frozen : int
        Epochs with the filter frozen (staged tasks only; ignored for joint tasks).
    epochs_joint : int
        Epochs of joint training (filter + network).
    batch_size : int
    lr_network : float
        AdamW rate of backbone and head when they train from scratch: the frozen-filter stage,
        joint-from-start tasks, and the baselines.
    lr_filter : float
        Filter rate; in the joint phase of staged tasks backbone and head follow
        :data:`PAPER_LR_RATIOS`.
    weight_decay : float
        AdamW weight decay of the network (the filter has none: a prior-free kernel).
    width : int
        Network width (channels of the first layer).
    init_noise : float
        Standard deviation of the Gaussian noise added to the delta initialisation.
    dtype : {"float32", "float64"}
        Precision of the video and the simulator (float32 halves the joint-epoch time; the
        kernel parameter itself stays float64).
    """

    epochs_frozen: int = 16
    epochs_joint: int = 16
    batch_size: int = 32
    lr_network: float = 3e-3
    lr_filter: float = 1e-2
    weight_decay: float = 1e-4
    width: int = 12
    init_noise: float = 1e-2
    dtype: str = "float32"

    def __post_init__(self) -> None:
        if self.dtype not in ("float32", "float64"):
            raise InputError(f"TrainingSettings.dtype must be 'float32' or 'float64', got {self.dtype!r}")
        for name in ("epochs_frozen", "epochs_joint", "batch_size", "width"):
            v = getattr(self, name)
            lo = 1 if name in ("batch_size", "width") else 0
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= 100_000:
                raise InputError(f"TrainingSettings.{name} must be an integer >= {lo}, got {v!r}")
        for name in ("lr_network", "lr_filter", "weight_decay", "init_noise"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= 10):
                raise InputError(f"TrainingSettings.{name} must be a finite number in [0, 10], got {v!r}")

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class LearnResult:
    """What :func:`learn_kernel` returns.

    Attributes
    ----------
    kernel : Kernel
        The learned kernel (provenance inside).
    metrics : dict
        Final test metrics (keys: the evaluator's ``metric_names``), in [0, 1].
    primary_metric : str
    history : list of dict
        Per epoch: ``stage``, ``epoch``, ``loss`` (mean training loss), ``seconds``.
    provenance : dict
    paths : dict
        ``kernel``, ``checkpoint``, ``provenance`` file paths when ``out`` was given.
    """

    kernel: Kernel
    metrics: dict[str, float]
    primary_metric: str
    history: list[dict[str, Any]]
    provenance: dict[str, Any]
    paths: dict[str, Path] = field(default_factory=dict)
    predictions: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def value(self) -> float:
        """The primary metric."""
        return self.metrics[self.primary_metric]


@dataclass(frozen=True)
class Evaluation:
    """What :func:`evaluate_kernel` returns: metrics of one kernel on one trained task.

    ``predictions`` holds the per-clip test predictions (the evaluator's :meth:`predict` output
    as numpy arrays, first axis = clips) when ``keep_predictions=True``; empty otherwise.
    """

    task: str
    metrics: dict[str, float]
    primary_metric: str
    kernel_name: str
    kernel_size: int
    n_test: int
    finetune_epochs: int
    seconds: float
    event_rate: float
    predictions: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    #: Events per pixel per second of each test clip (ON and OFF together, over the clip's duration).
    clip_event_rates: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def value(self) -> float:
        """The primary metric."""
        return self.metrics[self.primary_metric]

    def to_dict(self) -> dict[str, Any]:
        return {
            **{k: v for k, v in self.__dict__.items() if k not in ("predictions", "clip_event_rates")},
            "value": self.value,
        }


# --------------------------------------------------------------------------- simulator glue
def default_sensor(scene: Any) -> Any:
    """The simulator settings used for training: the simulator's calibrated pixel noise.

    Pre-log placement (FS-DVS) with a bias pedestal of 0.1 full scale added to ``W * I`` before
    the log (a learned kernel's negative lobes can drive ``W * I`` to or below zero; with a bare
    dark-current floor the whole frame then clamps and stops producing events, which stalls
    learning), ON/OFF thresholds 0.2, and the pixel noise at the simulator's calibrated (v2e)
    levels: per-pixel threshold mismatch σ = 0.03 (fixed pattern, seeded), leak events 0.01 Hz,
    shot-noise events 0.001 Hz (seeded: every kernel sees the same draws). Over a 40 ms clip the
    leak and shot-noise events are negligible (≈ 0.05 per 32×32 clip); the noise that matters in
    the default scenes is the photon shot noise of the image itself
    (:attr:`~fsdvs_hw.scenes.synthetic.SceneConfig.photon_count`), which acts *before* the kernel.
    No refractory period or photoreceptor low-pass (the scene's 100 Hz frames do not need them:
    see the sensor's plan).
    """
    from ..sensor import SensorConfig

    return SensorConfig.ideal(
        threshold=0.2,
        threshold_sigma=0.03,
        leak_rate_hz=0.01,
        shot_noise_rate_hz=0.001,
        positivity="pedestal",
        pedestal_intensity=0.1,
        frame_rate_hz=float(scene.frame_rate_hz),
    )


def _score(
    evaluator: Any,
    network: Any,
    kernel_t: Any,
    video: Any,
    targets: dict[str, Any],
    sensor: Any,
    timestamps_s: np.ndarray,
    batch_size: int = 64,
    events_fn: Any = None,
    keep: dict[str, Any] | None = None,
    clip_rates: list[np.ndarray] | None = None,
) -> tuple[dict[str, float], float]:
    """Metrics of ``network`` with ``kernel_t`` on a test set, and the mean event count per pixel-frame.

    If ``keep`` is a dict, the concatenated per-clip predictions are stored in it (numpy arrays).
    If ``clip_rates`` is a list, each batch's per-clip event rates (events per pixel per second,
    ON + OFF, over the span of ``timestamps_s``) are appended to it.
    """
    import torch

    network.eval()
    preds, n_events, n_px = [], 0.0, 0
    with torch.no_grad():
        for s in range(0, video.shape[0], batch_size):
            ev = (events_fn or simulated_events)(video[s : s + batch_size], kernel_t, sensor, timestamps_s)
            n_events += float(ev.sum())
            n_px += ev[:, :, 0].numel()
            if clip_rates is not None:
                span_s = float(timestamps_s[-1] - timestamps_s[0])
                per_clip = ev.reshape(ev.shape[0], -1).sum(dim=1).double().numpy()
                clip_rates.append(per_clip / (ev.shape[-2] * ev.shape[-1] * span_s))
            from .networks import event_representation

            preds.append(evaluator.predict(network(event_representation(ev.float()))))
    network.train()
    cat = concat_predictions(preds)
    if keep is not None:
        keep.update({k: v.numpy() for k, v in cat.items()})
    return evaluator.score(cat, targets), n_events / max(n_px, 1)


def _check_common(*, who: str, scene: Any = None, sensor: Any = None) -> None:
    """Types of the ``scene`` and ``sensor`` arguments (None = the default), before any work."""
    from ..scenes.synthetic import SceneConfig
    from ..sensor import SensorConfig

    check_instance(f"{who}: scene", scene, SceneConfig, "a SceneConfig (fsdvs_hw.scenes.synthetic)", nullable=True)
    check_instance(f"{who}: sensor", sensor, SensorConfig, "a SensorConfig (fsdvs_hw.sensor)", nullable=True)


def _as_kernel(kernel: Any, *, source: str = "kernel") -> Kernel:
    from ..kernels import as_kernel

    return as_kernel(kernel, name=source)


# --------------------------------------------------------------------------- public API
def _check_learn_arguments(
    settings: TrainingSettings | None, size: Any, n_train: Any, n_test: Any, seed: Any
) -> TrainingSettings:
    """:func:`learn_kernel`'s settings (default ``TrainingSettings()``) once size, clip counts and seed are valid."""
    settings = settings or TrainingSettings()
    if not isinstance(settings, TrainingSettings):
        raise InputError(f"learn_kernel: settings must be a TrainingSettings, got {type(settings).__name__}")
    if isinstance(size, bool) or not isinstance(size, int) or size < 1 or size % 2 == 0 or size > 15:
        raise InputError(f"learn_kernel: size must be an odd integer in [1, 15], got {size!r}")
    for nm, v in (("n_train", n_train), ("n_test", n_test)):
        if isinstance(v, bool) or not isinstance(v, int) or not 2 <= v <= 100_000:
            raise InputError(f"learn_kernel: {nm} must be an integer in [2, 100000], got {v!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InputError(f"learn_kernel: seed must be a non-negative integer, got {seed!r}")
    return settings


def _realisation_kernel(realisation: str, init_kernel: Any, learn_filter: bool) -> tuple[Any, dict[str, Any]]:
    """Co-design's kernel: ``realisation`` fitted to ``init_kernel``, as a module of its parameters, and
    the record of the starting design."""
    from ..realise.registry import fit_realisation, get_realisation

    if init_kernel is None or not learn_filter:
        raise InputError(
            "learn_kernel: realisation=... needs init_kernel (the kernel the realisation is first "
            "fitted to) and learn_filter=True"
        )
    spec = get_realisation(realisation)
    record = fit_realisation(realisation, _as_kernel(init_kernel, source="init_kernel"))
    return spec.differentiable_kernel(record), {"realisation": realisation, "realisation_initial": record.to_dict()}


def learn_kernel(
    task: Any,
    size: int = 7,
    *,
    seed: int = 0,
    n_train: int = 2048,
    n_test: int = 2048,
    settings: TrainingSettings | None = None,
    scene: Any = None,
    sensor: Any = None,
    learn_filter: bool = True,
    init_kernel: Any = None,
    out: str | Path | None = None,
    name: str | None = None,
    verbose: bool = False,
    realisation: str | None = None,
) -> LearnResult:
    """Learn a k×k FS-DVS kernel end to end with a task network (the paper's protocol).

    Parameters
    ----------
    task : str or TaskEvaluator
        ``"detection"``, ``"recognition"``, ``"segmentation"`` or a registered/plug-in evaluator.
    size : int
        Odd kernel side in pixels (1 … 15). ``size=1`` is the paper's "w/o" baseline: a 1×1 kernel before the log is a
        pure gain and cannot change any event, so it is not learned.
    seed : int
        Seeds the training clips, the kernel's initial noise, the network initialisation and the batch order. The test
        clips always use :data:`TEST_SEED`.
    n_train, n_test : int
        Numbers of training and test clips.
    settings : TrainingSettings, optional
        Epochs, batch size, learning rates, network width, initial noise.
    scene : SceneConfig, optional
        Scene family (default: the evaluator's :meth:`default_scene`).
    sensor : SensorConfig, optional
        Simulator settings (default :func:`default_sensor`).
    learn_filter : bool
        False keeps the filter fixed at its initial value (delta + noise, or ``init_kernel``) and trains the network
        only — the baseline rows and the zero-shot transfer (a kernel learned on one task, frozen, with a network
        trained on another).
    init_kernel : Kernel or array, optional
        Start from this kernel instead of delta + noise; its size must equal ``size``.
    out : path, optional
        File stem; writes ``STEM.json`` (kernel), ``STEM.safetensors`` (checkpoint) and ``STEM.provenance.json``.
    name : str, optional
        Kernel name (default ``"learned {task} {k}x{k} (seed s)"``).
    verbose : bool
        Print one progress line per epoch to stderr.
    realisation : str, optional
        Co-design: a registered realisation with a differentiable form
        (:attr:`fsdvs_hw.realise.registry.RealisationSpec.differentiable`: ``mesh``, ``asic``, ``metalens``). It is
        first fitted to ``init_kernel``; training then moves the realisation's own parameters (conductance ratios and
        gains; integer taps and scale, straight-through; phase, distance and gains) with the network, at the filter
        learning rate, so the kernel is buildable at every step. The provenance records the initial and the final
        design (``realisation_initial``, ``realisation_design``); the saved kernel is the design's.

    Returns
    -------
    LearnResult

    Raises
    ------
    InputError
        Unknown task, bad size / counts, an ``init_kernel`` of another size, a scene that cannot provide the task's
        ground truth, or a kernel larger than the frame.

    Examples
    --------
    A tiny run (16 clips, one epoch per stage, a narrow network; the defaults train for minutes):

    >>> import tempfile
    >>> from fsdvs_hw import learn_kernel
    >>> from fsdvs_hw.tasks.learn import TrainingSettings
    >>> quick = TrainingSettings(epochs_frozen=1, epochs_joint=1, batch_size=8, width=4)
    >>> with tempfile.TemporaryDirectory() as out:
    ...     res = learn_kernel("recognition", 3, n_train=16, n_test=16, settings=quick, out=out)
    ...     files = sorted(res.paths)
    >>> res.kernel.size, res.primary_metric, files
    (3, 'top1', ['checkpoint', 'kernel', 'provenance'])
    >>> bool(0 <= res.metrics["top1"] <= 1)
    True
    """
    return _learn(
        task,
        size,
        seed=seed,
        n_train=n_train,
        n_test=n_test,
        settings=settings,
        scene=scene,
        sensor=sensor,
        learn_filter=learn_filter,
        init_kernel=init_kernel,
        out=out,
        name=name,
        verbose=verbose,
        realisation=realisation,
    )


def _learn_setup(
    task: Any,
    size: Any,
    seed: Any,
    n_train: Any,
    n_test: Any,
    settings: TrainingSettings | None,
    scene: Any,
    sensor: Any,
    learn_filter: Any,
    verbose: Any,
    name: Any,
    out: Any,
    realisation: Any,
) -> tuple[Any, TrainingSettings, Any, Any, bool, Callable[[str], None] | None]:
    """:func:`learn_kernel`'s arguments checked, in order: (evaluator, settings, scene, sensor,
    learn_filter, progress printer or None); the defaults of ``scene`` and ``sensor`` filled in."""
    from .evaluators import get_evaluator

    evaluator = get_evaluator(task)
    settings = _check_learn_arguments(settings, size, n_train, n_test, seed)
    _check_common(scene=scene, sensor=sensor, who="learn_kernel")
    learn_filter = check_bool("learn_filter", learn_filter)
    verbose = check_bool("verbose", verbose)
    check_instance("name", name, str, "a string", nullable=True)
    check_instance("out", out, (str, Path), "a path (str or pathlib.Path)", nullable=True)
    check_instance("realisation", realisation, str, "a registered realisation name", nullable=True)
    scene = scene if scene is not None else evaluator.default_scene()
    evaluator.check_scene(scene)
    if size > min(scene.height_px, scene.width_px):
        raise InputError(
            f"learn_kernel: a {size}x{size} kernel is larger than the {scene.height_px}x{scene.width_px} frame"
        )
    sensor = sensor if sensor is not None else default_sensor(scene)
    return evaluator, settings, scene, sensor, learn_filter, print_progress if verbose else None


def _learn_start(
    size: int, settings: TrainingSettings, init_kernel: Any, learn_filter: bool, realisation: str | None, gen: Any
) -> tuple[Any, Any, bool, dict[str, Any]]:
    """(initial taps, the trained kernel — a Parameter or a realisation's module —, whether it
    learns, the realisation's record ``{}`` without one); the delta's noise is drawn from ``gen``."""
    import torch

    if init_kernel is not None:
        k0 = _as_kernel(init_kernel, source="init_kernel")
        if k0.size != size:
            raise KernelError(f"learn_kernel: init_kernel is {k0.size}x{k0.size} but size={size}")
        taps0 = torch.as_tensor(np.array(k0.taps), dtype=torch.float64)
    else:
        taps0 = delta_init(size, settings.init_noise if size > 1 else 0.0, gen)
    learn_filter = bool(learn_filter and size > 1)
    kernel: Any = torch.nn.Parameter(taps0.clone(), requires_grad=learn_filter)
    realised: dict[str, Any] = {}
    if realisation is not None:  # co-design: the kernel is the realisation's, a function of its parameters
        kernel, realised = _realisation_kernel(realisation, init_kernel, learn_filter)
    return taps0, kernel, learn_filter, realised


def _joint_rates(evaluator: Any, settings: TrainingSettings, learn_filter: bool) -> dict[str, float]:
    """Joint-stage rates of ``filter``, ``backbone`` and ``head`` (1/step): staged tasks follow the
    evaluator's :attr:`joint_lr_ratios` to the filter rate, joint-from-start tasks ``lr_network``."""
    if evaluator.staged:
        ratios = getattr(evaluator, "joint_lr_ratios", PAPER_LR_RATIOS)
        lrs = {
            "filter": settings.lr_filter,
            "backbone": settings.lr_filter * ratios[1],
            "head": settings.lr_filter * ratios[2],
        }
    else:
        lrs = {"filter": settings.lr_filter, "backbone": settings.lr_network, "head": settings.lr_network}
    if not learn_filter:
        lrs["filter"] = 0.0
    return lrs


def _learn_stages(
    evaluator: Any,
    network: Any,
    kernel: Any,
    data: TrainingData,
    settings: TrainingSettings,
    gen: Any,
    learn_filter: bool,
    kernel_init: Any,
    progress: Callable[[str], None] | None,
) -> tuple[list[dict[str, Any]], int]:
    """The frozen-filter stage (staged tasks) and the joint stage: (history, frozen-stage epochs).

    ``kernel_init`` (the initial taps, or None) puts ``kernel_change_l1`` in the joint records.
    """
    history: list[dict[str, Any]] = []
    epochs_frozen = settings.epochs_frozen if evaluator.staged else 0
    common = {"evaluator": evaluator, "network": network, "kernel": kernel, "generator": gen, "history": history}
    if epochs_frozen:  # the frozen filter's network inputs, computed once
        frozen = TrainingConfig("frozen_filter", epochs_frozen, settings.batch_size, progress=progress)
        optimizer = adamw_optimizer(network, settings.weight_decay, {"network": settings.lr_network})
        train_epochs(frozen, data=data.with_frozen_kernel(kernel_taps(kernel)), optimizer=optimizer, **common)
    if settings.epochs_joint:
        lrs = _joint_rates(evaluator, settings, learn_filter)
        rates = {"kernel": lrs["filter"], "backbone": lrs["backbone"], "head": lrs["head"]}
        optimizer = adamw_optimizer(network, settings.weight_decay, rates, kernel if learn_filter else None)
        stage = "joint" if learn_filter else "joint_frozen_filter"
        joint = TrainingConfig(stage, settings.epochs_joint, settings.batch_size, progress=progress)
        joint_data = data if learn_filter else data.with_frozen_kernel(kernel)  # frozen: the events never change
        train_epochs(joint, data=joint_data, optimizer=optimizer, kernel_init=kernel_init, **common)
    return history, epochs_frozen


def _learn(
    task: Any,
    size: int,
    *,
    seed: int,
    n_train: int,
    n_test: int,
    settings: TrainingSettings | None,
    scene: Any,
    sensor: Any,
    learn_filter: bool,
    init_kernel: Any,
    out: str | Path | None,
    name: str | None,
    verbose: bool,
    realisation: str | None,
) -> LearnResult:
    """:func:`learn_kernel`: its arguments checked, the stages trained, the kernel scored and saved."""
    import torch

    from ..provenance import library_versions

    evaluator, settings, scene, sensor, learn_filter, progress = _learn_setup(
        task, size, seed, n_train, n_test, settings, scene, sensor, learn_filter, verbose, name, out, realisation
    )
    t_start = time.perf_counter()
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    taps0, kernel, learn_filter, realised = _learn_start(size, settings, init_kernel, learn_filter, realisation, gen)
    video, targets = synthetic_dataset(scene, n_train, seed, evaluator.name, settings.dtype)
    test_video, test_targets = synthetic_dataset(scene, n_test, TEST_SEED, evaluator.name, settings.dtype)
    ts = scene.timestamps_s
    in_channels = 2 * (scene.n_frames - 1)
    network: Any = evaluator.build_network(in_channels, settings.width)  # a Module with .backbone and .head
    data = TrainingData(video, targets, sensor, ts)
    kernel_init = taps0 if learn_filter and not realised else None
    history, epochs_frozen = _learn_stages(
        evaluator, network, kernel, data, settings, gen, learn_filter, kernel_init, progress
    )
    with torch.no_grad():
        kernel_final = kernel_taps(kernel).detach().clone()
    if realised:
        realised["realisation_design"] = kernel.to_design(codesign_task=evaluator.name).to_dict()
    predictions: dict[str, np.ndarray] = {}
    metrics, event_rate = _score(
        evaluator, network, kernel_final, test_video, test_targets, sensor, ts, keep=predictions
    )
    provenance = {
        "task": evaluator.name,
        "evaluator": f"{type(evaluator).__module__}:{type(evaluator).__qualname__}",
        "size": size,
        "seed": seed,
        "test_seed": TEST_SEED,
        "n_train": n_train,
        "n_test": n_test,
        "learn_filter": learn_filter,
        "init": "init_kernel" if init_kernel is not None else f"delta + N(0, {settings.init_noise}^2)",
        "init_kernel_name": _as_kernel(init_kernel).name if init_kernel is not None else None,
        "protocol": ("frozen filter, then joint" if evaluator.staged else "joint")
        + ("" if learn_filter else " (filter frozen)"),
        "epochs_frozen": epochs_frozen,
        "epochs_joint": settings.epochs_joint,
        "settings": settings.to_dict(),
        "learning_rates_joint": _joint_rates(evaluator, settings, learn_filter),
        "learning_rate_frozen_stage": settings.lr_network if epochs_frozen else None,
        "network": type(network).__name__,
        "in_channels": in_channels,
        "representation": "log1p(event counts), 2(T-1) channels",
        "scene": scene.to_dict(),
        "sensor": sensor.to_dict(),
        "metrics": metrics,
        "primary_metric": evaluator.primary_metric,
        "final_metric": metrics[evaluator.primary_metric],
        "test_event_rate_per_pixel_frame": event_rate,
        "history": history,
        "train_seconds": time.perf_counter() - t_start,
        **realised,
        "versions": library_versions(),
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    kname = name or f"learned {evaluator.name} {size}x{size} (seed {seed})"
    kernel_out = Kernel(
        kernel_final.numpy(), name=kname, provenance={k: v for k, v in provenance.items() if k != "history"}
    )
    paths = save_checkpoint(Path(out), kernel_out, network, provenance) if out is not None else {}
    return LearnResult(
        kernel=kernel_out,
        metrics=metrics,
        primary_metric=evaluator.primary_metric,
        history=history,
        provenance=provenance,
        paths=paths,
        predictions=predictions,
    )


def evaluate_kernel(
    kernel: Any,
    task: Any,
    checkpoint: str | Path,
    *,
    n_test: int | None = None,
    finetune_epochs: int = 0,
    finetune_lr: float = 1e-3,
    sensor: Any = None,
    events_fn: Any = None,
    keep_predictions: bool = False,
    test_seed: int | None = None,
) -> Evaluation:
    """Score ``kernel`` on a trained task: swap it into the checkpoint's frozen network.

    Parameters
    ----------
    kernel : Kernel, path or k×k array
        Any odd size that fits the frame (a realised kernel may be larger or smaller than the trained one: the filter
        acts on the image, not on the network). ``None`` or a 1×1 kernel is the "w/o" conventional DVS.
    task : str or TaskEvaluator
        Must equal the checkpoint's task.
    checkpoint : path
        ``STEM.safetensors`` (or its stem) written by :func:`learn_kernel`.
    n_test : int, optional
        Score on the first ``n_test`` test clips (default: the checkpoint's ``n_test``; clip ``i`` is the same for any
        ``n_test``). Smaller is faster but noisier: see ``fsdvs-hw bench tasks`` for the confidence interval versus
        ``n_test``.
    finetune_epochs : int
        0 (default) is zero-shot. ``> 0`` first trains the network (backbone and head, AdamW at ``finetune_lr``) for
        that many epochs on the checkpoint's training clips with ``kernel`` frozen.
    sensor : SensorConfig, optional
        Simulator settings (default: the checkpoint's). Another sensor tests robustness.
    events_fn : callable, optional
        How the test clips become event frames when scoring: ``events_fn(video (B, T, H, W), kernel_taps (k, k)
        tensor, sensor, timestamps_s) -> (B, T-1, 2, H, W)``. Default: the in-pixel simulator (kernel before the
        comparator). The exploration layer passes its sensor-in-the-loop emulation here (filtered video shown on a
        display and recaptured by a plain DVS). Fine-tuning, when asked for, always uses the in-pixel simulator.
    keep_predictions : bool
        Return the per-clip test predictions in :attr:`Evaluation.predictions` (for paired statistics,
        :mod:`fsdvs_hw.stats`).
    test_seed : int, optional
        Seed of the test clips (default: the checkpoint's ``test_seed``). Another seed draws another held-out set of
        the same scene family (the exploration gives each network its own, :mod:`fsdvs_hw.explore.paired`).

    Returns
    -------
    Evaluation

    Raises
    ------
    InputError
        Missing / unreadable checkpoint, task mismatch, weights that do not fit the network, a kernel larger than the
        frame, bad ``n_test``.

    Examples
    --------
    A shipped recognition network (trained with the learned 7×7 kernel) scored with a plain DVS
    (a delta kernel) on 8 test clips:

    >>> from fsdvs_hw import Kernel, evaluate_kernel
    >>> import numpy as np
    >>> delta = Kernel(np.pad([[1.0]], 3), name="delta")
    >>> ev = evaluate_kernel(delta, "recognition",
    ...                      "designs/kernels/networks/recognition_with_learned_detection_7x7_s0.safetensors", n_test=8)
    >>> ev.task, ev.n_test, ev.primary_metric, ev.kernel_size
    ('recognition', 8, 'top1', 7)
    >>> bool(0 <= ev.metrics["top1"] <= 1), bool(ev.event_rate > 0)
    (True, True)
    """
    t0 = time.perf_counter()
    checked = _evaluation_setup(
        kernel, task, checkpoint, n_test, finetune_epochs, finetune_lr, sensor, events_fn, keep_predictions
    )
    evaluator, network, provenance, k, scene, sensor, n_test, finetune_lr, keep_predictions = checked
    settings = TrainingSettings(**{"dtype": "float64", **provenance["settings"]})
    kernel_t = _kernel_tensor(k)
    ts = scene.timestamps_s
    if finetune_epochs:
        _finetune_for_evaluation(
            evaluator, network, provenance, settings, scene, sensor, kernel_t, finetune_epochs, finetune_lr
        )
    tseed = int(provenance["test_seed"]) if test_seed is None else _check_test_seed(test_seed, "evaluate_kernel")
    test_data = synthetic_dataset(scene, n_test, tseed, evaluator.name, settings.dtype)
    return _evaluation(evaluator, network, k, test_data, sensor, ts, events_fn, keep_predictions, finetune_epochs, t0)


def _evaluation(
    evaluator: Any,
    network: Any,
    k: Kernel,
    test_data: tuple[Any, Any],
    sensor: Any,
    ts: np.ndarray,
    events_fn: Any,
    keep_predictions: bool,
    finetune_epochs: int,
    t0: float,
) -> Evaluation:
    """:func:`evaluate_kernel`'s scores of ``network`` with ``k`` on the test clips ``test_data``
    (video, targets); ``t0`` the call's start (``time.perf_counter``)."""
    test_video, test_targets = test_data
    n_test = int(test_video.shape[0])
    kernel_t = _kernel_tensor(k)
    kept: dict[str, np.ndarray] | None = {} if keep_predictions else None
    rates: list[np.ndarray] = []
    metrics, event_rate = _score(
        evaluator,
        network,
        kernel_t,
        test_video,
        test_targets,
        sensor,
        ts,
        events_fn=events_fn,
        keep=kept,
        clip_rates=rates,
    )
    return Evaluation(
        task=evaluator.name,
        metrics=metrics,
        primary_metric=evaluator.primary_metric,
        kernel_name=k.name,
        kernel_size=k.size,
        n_test=n_test,
        finetune_epochs=finetune_epochs,
        seconds=time.perf_counter() - t0,
        event_rate=event_rate,
        predictions=kept or {},
        clip_event_rates=np.concatenate(rates),
    )


def _kernel_tensor(kernel: Kernel) -> Any:
    """A kernel's taps as a torch tensor (float64)."""
    import torch

    return torch.as_tensor(np.array(kernel.taps))


def _evaluation_setup(
    kernel: Any,
    task: Any,
    checkpoint: Any,
    n_test: Any,
    finetune_epochs: Any,
    finetune_lr: Any,
    sensor: Any,
    events_fn: Any,
    keep_predictions: Any,
) -> tuple[Any, Any, dict[str, Any], Kernel, Any, Any, int, float, bool]:
    """:func:`evaluate_kernel`'s arguments checked, in order, and the checkpoint's network loaded:
    (evaluator, network, provenance, kernel, scene, sensor, n_test, finetune_lr, keep_predictions)."""
    from ..scenes.synthetic import SceneConfig
    from ..sensor import SensorConfig
    from .evaluators import get_evaluator

    evaluator = get_evaluator(task)
    _check_common(sensor=sensor, who="evaluate_kernel")
    check_instance("checkpoint", checkpoint, (str, Path), "a path (str or pathlib.Path) to a .safetensors checkpoint")
    finetune_lr = check_real("finetune_lr", finetune_lr, 0.0, 10.0)
    keep_predictions = check_bool("keep_predictions", keep_predictions)
    if events_fn is not None and not callable(events_fn):
        raise InputError(
            f"events_fn={one_line(events_fn)}: not callable; allowed: a function "
            "(video, kernel_taps, sensor, timestamps_s) -> event frames, or None"
        )
    network, provenance = load_network(checkpoint, evaluator, who="evaluate_kernel")
    k = Kernel(np.ones((1, 1)), name="w/o (1x1 delta)") if kernel is None else _as_kernel(kernel)
    scene = SceneConfig.from_dict(provenance["scene"])
    if k.size > min(scene.height_px, scene.width_px):
        raise KernelError(
            f"evaluate_kernel: a {k.size}x{k.size} kernel is larger than the checkpoint's "
            f"{scene.height_px}x{scene.width_px} frames"
        )
    if sensor is None:
        sensor = SensorConfig(**provenance["sensor"])
    n_stored = int(provenance["n_test"])
    n_test = n_stored if n_test is None else n_test
    if isinstance(n_test, bool) or not isinstance(n_test, int) or not 1 <= n_test <= 100_000:
        raise InputError(f"evaluate_kernel: n_test must be an integer in [1, 100000], got {n_test!r}")
    if isinstance(finetune_epochs, bool) or not isinstance(finetune_epochs, int) or finetune_epochs < 0:
        raise InputError(f"evaluate_kernel: finetune_epochs must be a non-negative integer, got {finetune_epochs!r}")
    return evaluator, network, provenance, k, scene, sensor, n_test, finetune_lr, keep_predictions


def _finetune_for_evaluation(
    evaluator: Any,
    network: Any,
    provenance: dict[str, Any],
    settings: TrainingSettings,
    scene: Any,
    sensor: Any,
    kernel_t: Any,
    epochs: int,
    lr: float,
) -> None:
    """:func:`evaluate_kernel`'s fine-tuning: the network (AdamW at ``lr``) for ``epochs`` epochs on
    the checkpoint's training clips, with the kernel ``kernel_t`` frozen."""
    import torch

    seed = int(provenance["seed"])
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    video, targets = synthetic_dataset(scene, int(provenance["n_train"]), seed, evaluator.name, settings.dtype)
    data = TrainingData(video, targets, sensor, scene.timestamps_s).with_frozen_kernel(kernel_t)
    train_epochs(
        TrainingConfig("finetune", epochs, settings.batch_size),
        evaluator=evaluator,
        network=network,
        kernel=kernel_t,
        data=data,
        optimizer=adamw_optimizer(network, settings.weight_decay, {"network": lr}),
        generator=gen,
        history=[],
    )


def load_network(checkpoint: str | Path, task: Any, *, who: str = "load_network") -> tuple[Any, dict[str, Any]]:
    """The network of a task checkpoint, weights loaded, in eval mode, with its provenance.

    Parameters
    ----------
    checkpoint : path
        A ``.safetensors`` checkpoint written by :func:`learn_kernel`.
    task : str or TaskEvaluator
        The task it must have been trained for.
    who : str
        Name put in front of error messages.

    Raises
    ------
    InputError
        Unreadable checkpoint, trained for another task, or weights that do not fit the network.
    """
    from .evaluators import get_evaluator

    evaluator = get_evaluator(task)
    provenance, state, _ = load_checkpoint(checkpoint)
    if provenance.get("task") != evaluator.name:
        raise InputError(
            f"{who}: checkpoint {str(checkpoint)!r} was trained for task "
            f"{provenance.get('task')!r}, not {evaluator.name!r}"
        )
    settings = TrainingSettings(**{"dtype": "float64", **provenance["settings"]})
    network = evaluator.build_network(int(provenance["in_channels"]), settings.width)
    try:
        network.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        raise InputError(
            f"{who}: checkpoint {str(checkpoint)!r} does not fit the {evaluator.name} "
            f"network ({str(exc).splitlines()[0]})"
        ) from None
    network.eval()
    return network, provenance


def differentiable_realisation(
    realisation: Any, *, who: str = "differentiable_realisation"
) -> tuple[Any, dict[str, Any]]:
    """The trainable module of a fitted realisation record, and what a provenance says about it.

    Parameters
    ----------
    realisation : Realisation
        A fitted record of a registered realisation with a differentiable form
        (:attr:`fsdvs_hw.realise.registry.RealisationSpec.differentiable`: ``mesh``, ``asic``, ...).
    who : str
        The caller, for messages.

    Returns
    -------
    module : torch.nn.Module
        :meth:`~fsdvs_hw.realise.registry.RealisationSpec.differentiable_kernel`: called, it returns
        the kernel taps (float64); its parameters are the realisation's physical ones, and
        ``to_design(codesign_task=...)`` gives the record after training.
    provenance : dict
        ``realisation`` (the registered name) and ``realisation_initial`` (the fitted record).

    Raises
    ------
    InputError
        ``realisation`` is not a fitted record of a realisation with a differentiable form.

    Examples
    --------
    >>> module, info = differentiable_realisation(fit_realisation("mesh", target, {}))   # doctest: +SKIP
    >>> info["realisation"], module().shape                                              # doctest: +SKIP
    ('mesh', torch.Size([7, 7]))
    """
    from ..realise.registry import get_realisation, realisation_names

    kind = getattr(realisation, "kind", None)
    specs = [get_realisation(nm) for nm in realisation_names()]
    spec = next(
        (
            sp
            for sp in specs
            if sp.record_kind == kind
            and sp.differentiable
            and (sp.record_type is None or isinstance(realisation, sp.record_type))
        ),
        None,
    )
    if spec is None:
        raise InputError(
            f"{who}: realisation= must be a fitted realisation record, got {type(realisation).__name__} (kind {kind!r})"
        )
    return spec.differentiable_kernel(realisation), {
        "realisation": spec.name,
        "realisation_initial": realisation.to_dict(),
    }


def finetune_network(
    checkpoint: str | Path,
    task: Any,
    *,
    kernel: Any = None,
    realisation: Any = None,
    epochs: int = 4,
    lr_network: float = 1e-3,
    lr_filter: float = 1e-2,
    n_train: int | None = None,
    out: str | Path | None = None,
    verbose: bool = False,
) -> LearnResult:
    """Continue training a trained task network with a realised kernel: frozen, or co-designed.

    The network of ``checkpoint`` (trained with the ideal kernel) is trained further on the
    checkpoint's own training clips (its ``seed``; the first ``n_train`` of them), with AdamW on
    the backbone and head at ``lr_network``, for ``epochs`` epochs (the "fit then fine-tune"
    and "co-designed" rows of the exploration, :mod:`fsdvs_hw.explore.codesign`):

    * ``kernel`` given: the kernel is frozen (the realisation's fitted kernel); the events never
      change, so they are simulated once;
    * ``realisation`` given (a fitted :class:`~fsdvs_hw.realise.base.Realisation` with a
      differentiable form): the realisation's own physical parameters train with the network at
      ``lr_filter`` (:meth:`~fsdvs_hw.realise.registry.RealisationSpec.differentiable_kernel`, the
      kernel buildable at every step), starting from the fitted design.

    Parameters
    ----------
    checkpoint : path
        ``STEM.safetensors`` written by :func:`learn_kernel`.
    task : str or TaskEvaluator
        The checkpoint's task.
    kernel : Kernel or array, optional
        The frozen kernel (exactly one of ``kernel`` and ``realisation``).
    realisation : Realisation, optional
        The fitted realisation to co-design.
    epochs : int
        Training epochs (≥ 1).
    lr_network, lr_filter : float
        AdamW learning rates of the network and of the realisation's parameters.
    n_train : int, optional
        Training clips (default: the checkpoint's ``n_train``; at most that many).
    out : path, optional
        File stem: writes the checkpoint (``STEM.safetensors``, scored like any other by :func:`evaluate_kernel`), its
        kernel and provenance. The provenance is the original's with ``finetune`` (mode, epochs, rates, clips, the
        source checkpoint, history) and, co-designed, ``realisation``, ``realisation_initial`` and
        ``realisation_design``.
    verbose : bool
        One progress line per epoch on stderr.

    Returns
    -------
    LearnResult
        ``metrics`` is empty: the network is scored by the caller (per clip, on its own clips).

    Raises
    ------
    InputError
        Both or neither of ``kernel`` / ``realisation``, a realisation without a differentiable form, bad counts or
        rates, an unreadable checkpoint.
    """
    t0 = time.perf_counter()
    evaluator, network, prov, n = _finetune_setup(
        checkpoint, task, kernel, realisation, epochs, lr_network, lr_filter, n_train
    )
    taps, realised, history = _finetune_train(
        evaluator, network, prov, kernel, realisation, n, epochs, {"network": lr_network, "kernel": lr_filter}, verbose
    )
    finetune = {
        "mode": "codesign" if realised else "frozen kernel",
        "epochs": epochs,
        "lr_network": lr_network,
        "lr_filter": lr_filter if realised else 0.0,
        "n_train": n,
        "source_checkpoint": Path(checkpoint).name,
        "seconds": time.perf_counter() - t0,
    }
    provenance = _finetuned_provenance(prov, finetune, realised, history)
    name = (
        f"{realised['realisation']} co-designed with {evaluator.name} network s{int(prov['seed'])}"
        if realised
        else f"{_as_kernel(kernel).name} (network fine-tuned)"
    )
    out_kernel = Kernel(taps.numpy(), name=name, provenance={k: v for k, v in provenance.items() if k != "history"})
    paths = save_checkpoint(Path(out), out_kernel, network, provenance) if out is not None else {}
    return LearnResult(
        kernel=out_kernel,
        metrics={},
        primary_metric=evaluator.primary_metric,
        history=history,
        provenance=provenance,
        paths=paths,
    )


def _finetuned_provenance(
    prov: dict[str, Any], finetune: dict[str, Any], realised: dict[str, Any], history: list[dict[str, Any]]
) -> dict[str, Any]:
    """The source checkpoint's provenance less its history and metrics, with ``finetune``,
    ``learn_filter``, the new ``history``, the realisation's records and ``created_utc``."""
    provenance = {k: v for k, v in prov.items() if k not in ("history", "metrics", "final_metric")}
    provenance.update(
        {
            "finetune": finetune,
            "learn_filter": bool(realised),
            "history": history,
            **realised,
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
    )
    return provenance


def _finetune_train(
    evaluator: Any,
    network: Any,
    prov: dict[str, Any],
    kernel: Any,
    realisation: Any,
    n: int,
    epochs: int,
    rates: dict[str, float],
    verbose: bool,
) -> tuple[Any, dict[str, Any], list[dict[str, Any]]]:
    """:func:`finetune_network`'s training on the checkpoint's first ``n`` training clips: (the
    final taps, the realisation's records ``{}`` without one, the history); ``rates`` of the
    ``network`` and the realisation's parameters (``kernel``)."""
    import torch

    from ..scenes.synthetic import SceneConfig
    from ..sensor import SensorConfig

    settings = TrainingSettings(**prov["settings"])
    scene = SceneConfig.from_dict(prov["scene"])
    sensor = SensorConfig(**prov["sensor"])
    seed = int(prov["seed"])
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    realised: dict[str, Any] = {}
    if realisation is not None:
        kernel_param, realised = differentiable_realisation(realisation, who="finetune_network")
    else:
        kernel_param = torch.as_tensor(np.array(_as_kernel(kernel).taps), dtype=torch.float64)
    video, targets = synthetic_dataset(scene, n, seed, evaluator.name, settings.dtype)
    network.train()
    optimizer = adamw_optimizer(network, settings.weight_decay, rates, kernel_param if realised else None)
    data = TrainingData(video, targets, sensor, scene.timestamps_s)
    history: list[dict[str, Any]] = []
    train_epochs(
        TrainingConfig(
            "codesign" if realised else "finetune",
            epochs,
            settings.batch_size,
            progress=print_progress if verbose else None,
        ),
        evaluator=evaluator,
        network=network,
        kernel=kernel_param,
        data=data if realised else data.with_frozen_kernel(kernel_param),  # frozen: simulated once
        optimizer=optimizer,
        generator=gen,
        history=history,
    )
    network.eval()
    with torch.no_grad():
        taps = kernel_taps(kernel_param).detach().clone()
    if realised:
        realised["realisation_design"] = kernel_param.to_design(codesign_task=evaluator.name).to_dict()
    return taps, realised, history


def _finetune_setup(
    checkpoint: Any,
    task: Any,
    kernel: Any,
    realisation: Any,
    epochs: Any,
    lr_network: Any,
    lr_filter: Any,
    n_train: Any,
) -> tuple[Any, Any, dict[str, Any], int]:
    """:func:`finetune_network`'s arguments checked, in order, and the checkpoint's network loaded:
    (evaluator, network, provenance, training clips)."""
    from .evaluators import get_evaluator

    evaluator = get_evaluator(task)
    if (kernel is None) == (realisation is None):
        raise InputError("finetune_network: give exactly one of kernel= (frozen) and realisation= (co-designed)")
    if isinstance(epochs, bool) or not isinstance(epochs, int) or not 1 <= epochs <= 100_000:
        raise InputError(f"finetune_network: epochs must be an integer in [1, 100000], got {epochs!r}")
    for nm, v in (("lr_network", lr_network), ("lr_filter", lr_filter)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 <= v <= 10):
            raise InputError(f"finetune_network: {nm} must be a finite number in [0, 10], got {v!r}")
    network, prov = load_network(checkpoint, evaluator, who="finetune_network")
    n_stored = int(prov["n_train"])
    n = n_stored if n_train is None else n_train
    if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= n_stored:
        raise InputError(
            f"finetune_network: n_train must be an integer in [2, {n_stored}] (the checkpoint's "
            f"training clips), got {n_train!r}"
        )
    return evaluator, network, prov, n


def _check_test_seed(seed: Any, who: str) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) < 2**63:
        raise InputError(f"{who}: test_seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def heldout_targets(task: Any, scene: Any, n_test: int, *, test_seed: int | None = None) -> dict[str, np.ndarray]:
    """The ground truth of a task's test clips (default the fixed :data:`TEST_SEED` set), as numpy arrays.

    Parameters
    ----------
    task : str or TaskEvaluator
    scene : SceneConfig or dict
        The scene family (a checkpoint's ``provenance["scene"]`` dict is accepted).
    n_test : int
        Number of test clips (clip ``i`` does not depend on it).
    test_seed : int, optional
        Seed of the test set (as :func:`evaluate_kernel`'s ``test_seed``; default :data:`TEST_SEED`).

    Returns
    -------
    dict
        The evaluator's targets (detection: ``boxes``, ``labels``...; recognition: ``motion``;
        segmentation: ``mask``), first axis = clips.
    """
    from ..scenes.synthetic import SceneConfig
    from .evaluators import get_evaluator

    evaluator = get_evaluator(task)
    if isinstance(scene, dict):
        scene = SceneConfig.from_dict(scene)
    seed = TEST_SEED if test_seed is None else _check_test_seed(test_seed, "heldout_targets")
    _, targets = synthetic_dataset(scene, int(n_test), seed, evaluator.name, "float32")
    return {k: v.numpy() for k, v in targets.items()}
