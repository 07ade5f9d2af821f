"""Score a kernel on a user dataset with a network: simulator → event representation → evaluator.

:func:`evaluate_on_dataset` runs each drawn clip of a :class:`~fsdvs_hw.scenes.datasets.ClipDataset`
through the in-pixel simulator (:func:`fsdvs_hw.sensor.event_frames`, the same path
:func:`~fsdvs_hw.tasks.learn.evaluate_kernel` scores with), the network's event representation
(:mod:`fsdvs_hw.tasks.user_networks`) and the network, and scores the predictions with the task's
built-in evaluator (its ``predict`` and ``score``: pycocotools mAP, torchmetrics top-1 / mIoU),
set to the dataset's class count (and ignore index). No metric is computed here.
"""

from __future__ import annotations

import copy
import re
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

from ..errors import InputError, KernelError, one_line
from ..limits import MAX_CLIPS, MAX_SEED, check_count

__all__ = ["DatasetEvaluation", "evaluate_on_dataset", "evaluator_for_dataset"]


@dataclass(frozen=True)
class DatasetEvaluation:
    """A kernel's score on user clips.

    Attributes
    ----------
    task : str
    metrics : dict of str to float
        The evaluator's metrics over all scored clips, in [0, 1].
    primary_metric : str
    per_clip : numpy.ndarray, float64, shape (N,)
        The primary metric of each clip alone (NaN where undefined: a detection clip without boxes).
    clip_indices : numpy.ndarray, int64, shape (N,)
        Which dataset clips were scored, in order.
    event_counts : numpy.ndarray, float64, shape (N,)
        ON + OFF events of each clip.
    predictions, targets : dict of str to numpy.ndarray
        Per-clip predictions and ground truth (first axis = clips), for paired statistics.
    seconds : float
        Wall time of the call.
    durations_s : numpy.ndarray, float64, shape (N,)
        Each scored clip's span in seconds (last minus first timestamp).
    """

    task: str
    metrics: dict[str, float]
    primary_metric: str
    per_clip: np.ndarray
    clip_indices: np.ndarray
    event_counts: np.ndarray
    predictions: dict[str, np.ndarray] = field(repr=False)
    targets: dict[str, np.ndarray] = field(repr=False)
    seconds: float = 0.0
    durations_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def value(self) -> float:
        """The primary metric."""
        return self.metrics[self.primary_metric]


def evaluator_for_dataset(task: Any, dataset: Any) -> Any:
    """The built-in evaluator of ``task`` set to ``dataset``'s class count (and ignore index).

    Raises
    ------
    InputError
        Unknown task, or a dataset holding another task's targets.

    Examples
    --------
    >>> evaluator_for_dataset("recognition", ds).num_classes   # doctest: +SKIP
    101
    """
    from .evaluators import get_evaluator

    base = get_evaluator(task)
    if base.name != dataset.task:
        raise InputError(
            f"evaluate_on_dataset: task {base.name!r} but the dataset {type(dataset).__name__} "
            f"holds {dataset.task!r} targets"
        )
    ev: Any = copy.copy(base)  # the built-in evaluator's code, the dataset's class count (set on any evaluator)
    ev.num_classes = int(dataset.num_classes)
    if dataset.task == "segmentation":
        ev.ignore_index = dataset.ignore_index
        ev.background_weight = 1.0  # class 0 of a user's masks is a class (Cityscapes: road), not background
    return ev


def _network_for(network: Any, task: str, in_channels: int, num_classes: int) -> Any:
    from torch import nn

    from .user_networks import builtin_network, load_network_factory

    if network is None:
        return builtin_network(task, in_channels, num_classes)
    if isinstance(network, str):
        return load_network_factory(network, in_channels=in_channels, num_classes=num_classes)
    if isinstance(network, nn.Module):
        return network
    raise InputError(
        f"evaluate_on_dataset: network={one_line(network)}; allowed: None (built-in), "
        "'package.module:factory', or a torch.nn.Module"
    )


def _device(device: Any) -> Any:
    """``device`` as a ``torch.device``; CUDA only where it is available."""
    import torch

    if not isinstance(device, str) or not re.fullmatch(r"cpu|cuda(:\d{1,2})?", device):
        raise InputError(f"evaluate_on_dataset: device={one_line(device)}; allowed: 'cpu', 'cuda' or 'cuda:N'")
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(
            f"evaluate_on_dataset: device={device!r} but CUDA is not available on this machine "
            f"(torch {torch.__version__}); allowed here: 'cpu'"
        )
    return torch.device(device)


def evaluate_on_dataset(
    kernel: Any,
    task: Any,
    dataset: Any,
    network: Any = None,
    *,
    sensor: Any = None,
    n_clips: int | None = None,
    seed: int = 0,
    weights: Any = None,
    events_fn: Any = None,
    device: str = "cpu",
) -> DatasetEvaluation:
    """Score ``kernel`` on clips of a user dataset with a network.

    Parameters
    ----------
    kernel : Kernel, path, k×k array or None
        The pre-log spatial kernel; None is the 1×1 delta (a conventional DVS).
    task : str or TaskEvaluator
        Must match ``dataset.task``.
    dataset : ClipDataset
        :mod:`fsdvs_hw.scenes.datasets`.
    network : None, str or torch.nn.Module
        None: the built-in network of the task; ``"package.module:factory"``: called as
        ``factory(in_channels=..., num_classes=...)``; or a module. Its ``event_input``
        (``"frames"`` / ``"voxel:N"``) picks the representation. Scored in eval mode.
    sensor : SensorConfig, optional
        Default: the task training sensor (:func:`~fsdvs_hw.tasks.learn.default_sensor`) at the
        first clip's frame rate.
    n_clips : int, optional
        Score ``n_clips`` clips drawn with ``seed`` (:meth:`ClipDataset.draw`); default all.
    weights : path, optional
        ``.pt`` / ``.safetensors`` state dict loaded into the network (shapes checked).
    events_fn : callable, optional
        ``events_fn(video (1, T, H, W), kernel_taps, sensor, timestamps_s) -> (1, T-1, 2, H, W)``
        instead of the in-pixel simulator.
    device : str
        ``"cpu"`` (default) or ``"cuda"`` / ``"cuda:N"``: where the simulator and the network run
        (the network is moved there); predictions come back to the CPU for the metric. On CUDA the
        simulator's random streams (mismatch, noise) differ from the CPU's, so only a noise-free
        sensor gives the same events to rounding.

    Returns
    -------
    DatasetEvaluation

    Raises
    ------
    InputError
        Task / dataset mismatch, bad ``n_clips`` / ``seed``, a kernel larger than the frames, a
        network that does not load or whose output the evaluator cannot read, and any reader error.

    Example
    -------
    >>> ds = VideoFolderDataset("clips", n_frames=5, size=(32, 32))            # doctest: +SKIP
    >>> evaluate_on_dataset(None, "recognition", ds, "mynets:tiny").value     # doctest: +SKIP
    0.5
    """
    import torch

    from ..kernels import Kernel
    from ..scenes.datasets import ClipDataset, stack_targets
    from ..sensor import SensorConfig, event_frames
    from .learn import _as_kernel, _cat_predictions, default_sensor
    from .user_networks import event_input_of, load_weights

    t0 = time.perf_counter()
    dev = _device(device)
    if not isinstance(dataset, ClipDataset):
        raise InputError(
            f"evaluate_on_dataset: dataset is a {type(dataset).__name__}; allowed: a "
            "fsdvs_hw.scenes.datasets.ClipDataset"
        )
    evaluator = evaluator_for_dataset(task, dataset)
    if sensor is not None and not isinstance(sensor, SensorConfig):
        raise InputError(f"evaluate_on_dataset: sensor is a {type(sensor).__name__}; allowed: a SensorConfig")
    if events_fn is not None and not callable(events_fn):
        raise InputError(f"evaluate_on_dataset: events_fn={one_line(events_fn)} is not callable")
    seed = check_count("evaluate_on_dataset: seed", seed, 0, MAX_SEED)
    if n_clips is None:
        indices = np.arange(len(dataset))
    else:
        check_count("evaluate_on_dataset: n_clips", n_clips, 1, min(MAX_CLIPS, len(dataset)))
        indices = dataset.draw(n_clips, seed)
    k = Kernel(np.ones((1, 1)), name="w/o (1x1 delta)") if kernel is None else _as_kernel(kernel)
    kernel_t = torch.as_tensor(np.array(k.taps), dtype=torch.float64, device=dev)

    first = dataset[int(indices[0])]
    _, h, w = first.frames.shape
    if k.size > min(h, w):
        raise KernelError(f"evaluate_on_dataset: a {k.size}x{k.size} kernel is larger than the {h}x{w} frames")
    if evaluator.name == "detection" and (h % 2 or w % 2):
        raise InputError(
            f"evaluate_on_dataset: detection needs an even frame size (stride 2), got {h}x{w}; "
            "pass size=(H, W) to the dataset"
        )
    net = _network_for(network, evaluator.name, 2 * (first.frames.shape[0] - 1), evaluator.num_classes)
    if weights is not None:
        load_weights(net, weights)
    rep = event_input_of(net)
    net = net.to(dev)
    if sensor is None:
        sensor = default_sensor(SimpleNamespace(frame_rate_hz=1.0 / float(np.diff(first.timestamps_s)[0])))

    preds, clips, counts, spans = [], [], [], []
    net.eval()
    with torch.no_grad():
        for i in indices:
            clip = first if int(i) == first.index else dataset[int(i)]
            if clip.frames.shape[1:] != (h, w):
                raise InputError(
                    f"evaluate_on_dataset: clip {int(i)} ({clip.source!r}) is "
                    f"{clip.frames.shape[1]}x{clip.frames.shape[2]}, clip {first.index} {h}x{w}; "
                    "field 'size': give the dataset a size=(H, W)"
                )
            video = clip.as_batch(torch.float64).to(dev)
            ev = (
                events_fn(video, kernel_t, sensor, clip.timestamps_s)
                if events_fn is not None
                else event_frames(video, kernel_t, timestamps_s=clip.timestamps_s, config=sensor)
            )
            counts.append(float(ev.sum()))
            spans.append(float(clip.timestamps_s[-1] - clip.timestamps_s[0]))
            try:
                preds.append(
                    {key: v.cpu() for key, v in evaluator.predict(net(rep(ev.float(), clip.timestamps_s))).items()}
                )
            except (RuntimeError, KeyError, TypeError, IndexError) as exc:
                raise InputError(
                    f"evaluate_on_dataset: the network's output on clip {int(i)} cannot be read by "
                    f"the {evaluator.name} evaluator ({type(exc).__name__}: "
                    f"{one_line(str(exc), 120)}); input was {rep.kind} "
                    f"with {rep.channels(clip.frames.shape[0])} channels"
                ) from None
            clips.append(clip)
    cat = _cat_predictions(preds)
    targets = stack_targets(clips)
    t_torch = {key: torch.from_numpy(np.ascontiguousarray(v)) for key, v in targets.items()}
    metrics = evaluator.score(cat, t_torch)
    per_clip = np.full(len(clips), np.nan)
    for n in range(len(clips)):
        try:
            one = evaluator.score(
                {key: v[n : n + 1] for key, v in cat.items()}, {key: v[n : n + 1] for key, v in t_torch.items()}
            )
            per_clip[n] = one[evaluator.primary_metric]
        except InputError:  # undefined on this clip alone (no ground truth)
            pass
    return DatasetEvaluation(
        task=evaluator.name,
        metrics=metrics,
        primary_metric=evaluator.primary_metric,
        per_clip=per_clip,
        clip_indices=np.asarray(indices, dtype=np.int64),
        event_counts=np.asarray(counts),
        predictions={key: v.numpy() for key, v in cat.items()},
        targets=targets,
        seconds=time.perf_counter() - t0,
        durations_s=np.asarray(spans),
    )
