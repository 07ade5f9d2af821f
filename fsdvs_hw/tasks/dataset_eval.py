"""Score a kernel on a user dataset with a network: simulator → event representation → evaluator.

:func:`evaluate_on_dataset` runs each drawn clip of a :class:`~fsdvs_hw.scenes.datasets.ClipDataset`
through the in-pixel simulator (:func:`fsdvs_hw.sensor.event_frames`, the same path
:func:`~fsdvs_hw.tasks.learn.evaluate_kernel` scores with), the network's event representation
(:mod:`fsdvs_hw.tasks.user_networks`) and the network, and scores the predictions with the task's
built-in evaluator (its ``predict`` and ``score``: pycocotools mAP, torchmetrics top-1 / mIoU),
set to the dataset's class count (and ignore index). No metric is computed here.

A clip that cannot be read (a video that does not decode, a mask label beyond the class count, a
frame size other than the first readable clip's) is skipped, counted and named
(:class:`ClipFailure`), up to ``max_failed_fraction`` of the drawn clips; beyond it the evaluation
fails with :class:`ClipFailuresError`, naming the first few files and reasons. A problem of the
task rather than of one clip (the network's output, an odd frame size for the stride-2 detector, a
kernel larger than the frames) fails the evaluation at once.
"""

from __future__ import annotations

import copy
import dataclasses
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

from ..errors import InputError, KernelError, one_line
from ..kernels import Kernel, as_kernel
from ..limits import MAX_CLIPS, MAX_SEED, check_count

__all__ = [
    "MAX_NAMED_FAILURES",
    "ClipFailure",
    "ClipFailuresError",
    "DatasetEvaluation",
    "NetworkOutputError",
    "evaluate_on_dataset",
    "evaluate_sampled",
    "evaluator_for_dataset",
    "mean_over_videos",
    "per_video_evaluation",
    "read_clip",
]

#: Failed clips a record or a message names one by one (the count covers them all).
MAX_NAMED_FAILURES = 20

#: Failed clips an error message names before "and N more".
_SHOWN_IN_MESSAGE = 3


@dataclass(frozen=True)
class ClipFailure:
    """A drawn clip that was not scored, and why.

    Attributes
    ----------
    index : int
        The clip's index in the dataset.
    file : str
        The file the reader named (the video, the frame image or the label mask), else the clip's
        first file, else ``"clip <index>"``.
    reason : str
        The reader's message (field, value, allowed range).

    Example
    -------
    >>> ClipFailure(3, "ucf/Run/v_Run_g01.mp4", "field 'frames': the video does not decode").to_dict()["file"]
    'ucf/Run/v_Run_g01.mp4'
    """

    index: int
    file: str
    reason: str

    def to_dict(self) -> dict[str, Any]:
        """``{"index", "file", "reason"}`` (JSON)."""
        return {"index": int(self.index), "file": self.file, "reason": self.reason}


def _short(text: str, limit: int = 240) -> str:
    """``text`` on one line, cut to ``limit`` characters."""
    flat = " ".join(str(text).split())
    return flat if len(flat) <= limit else flat[: limit - 1] + "…"


def _describe_failures(failures: list[ClipFailure], limit: int = _SHOWN_IN_MESSAGE) -> str:
    shown = "; ".join(
        _short(f.reason) if f.file in f.reason else f"{f.file!r}: {_short(f.reason)}" for f in failures[:limit]
    )
    more = f"; and {len(failures) - limit} more" if len(failures) > limit else ""
    return shown + more


class ClipFailuresError(InputError):
    """More clips failed than the allowed fraction (or every clip did); ``failures`` lists them all.

    Attributes
    ----------
    failures : tuple of ClipFailure
    n_drawn : int
        The clips drawn for scoring.
    max_failed_fraction : float
        The fraction that was allowed to fail.
    detail : str
        The message without the name of the setting ("2 of the 4 drawn clips failed to read ...:
        'file': reason; ..."), for callers that name it their own way.
    """

    def __init__(
        self, detail: str, failures: Sequence[ClipFailure], n_drawn: int, max_failed_fraction: float, *, setting: str
    ) -> None:
        super().__init__(f"{setting} = {max_failed_fraction:g} (allowed: a fraction in [0, 1]): {detail}")
        self.detail = detail
        self.failures = tuple(failures)
        self.n_drawn = int(n_drawn)
        self.max_failed_fraction = float(max_failed_fraction)


class NetworkOutputError(InputError):
    """The network's output cannot be read or scored by the task's evaluator: a problem of the
    network (every clip), never skipped as a clip failure."""


def _failed_file(dataset: Any, i: int, reason: str) -> str:
    """The file of clip ``i`` that ``reason`` names, else its first file, else ``"clip i"``."""
    try:
        files = [str(p) for p in dataset.clip_files(i)]
    except (NotImplementedError, IndexError, OSError):
        files = []
    return next((f for f in files if f in reason), files[0] if files else f"clip {i}")


def read_clip(dataset: Any, i: int, shape: tuple[int, int] | None = None) -> tuple[Any, ClipFailure | None]:
    """Decode clip ``i``, or say why it cannot be scored: ``(clip, None)`` or ``(None, failure)``.

    A failure depends on the clip's files only (the reader's checks: decoding, labels, boxes, and
    the frame size against ``shape``, the first readable clip's (H, W)), never on a kernel or a
    network, so every kernel scored on a draw skips the same clips.

    Example
    -------
    >>> clip, failed = read_clip(ds, 0)   # doctest: +SKIP
    """
    try:
        clip = dataset[int(i)]
    except (InputError, OSError) as exc:
        reason = str(exc)
        return None, ClipFailure(int(i), _failed_file(dataset, int(i), reason), reason)
    if shape is not None and tuple(clip.frames.shape[1:]) != tuple(shape):
        h, w = clip.frames.shape[1:]
        reason = (
            f"clip {int(i)} ({clip.source!r}) is {h}x{w}, the first readable clip {shape[0]}x{shape[1]}; "
            "field 'size': give the dataset a size=(H, W)"
        )
        return None, ClipFailure(int(i), str(clip.source), reason)
    return clip, None


def _check_failures(failures: list[ClipFailure], n_drawn: int, max_failed_fraction: float, n_scored: int) -> None:
    """Refuse more failed clips than ``floor(max_failed_fraction * n_drawn)``, or no clip scored."""
    allowed = int(np.floor(max_failed_fraction * n_drawn + 1e-9))
    if failures and (len(failures) > allowed or n_scored == 0):
        why = "none is left to score" if n_scored == 0 else f"at most {allowed} may be skipped"
        raise ClipFailuresError(
            f"{len(failures)} of the {n_drawn} drawn clips failed to read ({why}): {_describe_failures(failures)}",
            failures,
            n_drawn,
            max_failed_fraction,
            setting="evaluate_on_dataset: max_failed_fraction",
        )


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
    failures : tuple of ClipFailure
        The drawn clips that were skipped (in draw order); ``clip_indices`` holds the others.
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
    failures: tuple[ClipFailure, ...] = ()

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


def _check_frames(kernel: Any, task: str, clip: Any, shape: tuple[int, int]) -> None:
    """Problems of the task, not of one clip: a kernel larger than the frames, an odd frame size for the
    stride-2 detector (both fail the evaluation, naming the clip's file and the field)."""
    h, w = shape
    if kernel.size > min(h, w):
        raise KernelError(
            f"evaluate_on_dataset: a {kernel.size}x{kernel.size} kernel is larger than the {h}x{w} frames of "
            f"clip {clip.index} ({clip.source!r}); field 'size': allowed: frames of at least "
            f"{kernel.size}x{kernel.size} px"
        )
    if task == "detection" and (h % 2 or w % 2):
        raise InputError(
            f"evaluate_on_dataset: detection needs an even frame size (its network works at stride 2): "
            f"clip {clip.index} ({clip.source!r}) is {h}x{w}; field 'size' = [{h}, {w}]; allowed: even H "
            f"and W, e.g. size = [{h + h % 2}, {w + w % 2}]"
        )


def _output_shape(out: Any) -> str:
    """A network output's shapes, for messages: ``"(1, 3, 32, 32)"`` or ``"{heatmap: (1, 2, 16, 16), ...}"``."""
    if isinstance(out, dict):
        return "{" + ", ".join(f"{k}: {_output_shape(v)}" for k, v in out.items()) + "}"
    shape = getattr(out, "shape", None)
    return str(tuple(int(n) for n in shape)) if shape is not None else type(out).__name__


def torch_device(device: Any) -> Any:
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
    max_failed_fraction: float = 0.0,
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
        None: the built-in network of the task; ``"package.module:factory"``: called as ``factory(in_channels=...,
        num_classes=...)``; or a module. Its ``event_input`` (``"frames"`` / ``"voxel:N"``) picks the representation.
        Scored in eval mode.
    sensor : SensorConfig, optional
        Default: the task training sensor (:func:`~fsdvs_hw.tasks.learn.default_sensor`) at the first clip's frame
        rate.
    n_clips : int, optional
        Score ``n_clips`` clips drawn with ``seed`` (:meth:`ClipDataset.draw`); default all.
    weights : path, optional
        ``.pt`` / ``.safetensors`` state dict loaded into the network (shapes checked).
    events_fn : callable, optional
        ``events_fn(video (1, T, H, W), kernel_taps, sensor, timestamps_s) -> (1, T-1, 2, H, W)`` instead of the
        in-pixel simulator.
    device : str
        ``"cpu"`` (default) or ``"cuda"`` / ``"cuda:N"``: where the simulator and the network run (the network is
        moved there); predictions come back to the CPU for the metric. On CUDA the simulator's random streams
        (mismatch, noise) differ from the CPU's, so only a noise-free sensor gives the same events to rounding.
    max_failed_fraction : float
        Fraction in [0, 1] of the drawn clips that may fail to read (:func:`read_clip`) and be skipped; 0 (default):
        any failed clip fails the evaluation.

    Returns
    -------
    DatasetEvaluation
        ``failures`` names the skipped clips.

    Raises
    ------
    InputError
        Task / dataset mismatch, bad ``n_clips`` / ``seed``, a kernel larger than the frames, a network that does not
        load, an odd frame size for the stride-2 detector.
    NetworkOutputError
        The network's output cannot be read or scored by the evaluator (a problem of the task).
    ClipFailuresError
        More than ``max_failed_fraction`` of the drawn clips (or all of them) failed to read, naming the first few
        files and reasons.

    Notes
    -----
    Pairing: which clips are skipped is decided by :func:`read_clip` before the simulator runs,
    from the clip's files alone, never from the kernel, the sensor or the network's output (an
    unreadable output fails the whole evaluation instead of skipping the clip). Every kernel scored
    on the same draw therefore skips the same clips, and its per-clip metrics stay paired with every
    other kernel's clip by clip.

    Example
    -------
    >>> ds = VideoFolderDataset("clips", n_frames=5, size=(32, 32))            # doctest: +SKIP
    >>> evaluate_on_dataset(None, "recognition", ds, "mynets:tiny").value     # doctest: +SKIP
    0.5
    """
    import torch

    t0 = time.perf_counter()
    dev = torch_device(device)
    evaluator, indices = _evaluation_request(task, dataset, sensor, events_fn, seed, max_failed_fraction, n_clips)
    k = Kernel(np.ones((1, 1)), name="w/o (1x1 delta)") if kernel is None else as_kernel(kernel, name="kernel")
    kernel_t = torch.as_tensor(np.array(k.taps), dtype=torch.float64, device=dev)
    run = _ClipScoring(evaluator, k, kernel_t, network, weights, sensor, events_fn, dev)
    for i in indices:
        clip, failed = read_clip(dataset, int(i), run.shape)
        if failed is not None:
            run.failures.append(failed)
            continue
        run.predict(clip, int(i))
    _check_failures(run.failures, len(indices), float(max_failed_fraction), len(run.clips))
    return _dataset_evaluation(run, t0)


def _evaluation_request(
    task: Any, dataset: Any, sensor: Any, events_fn: Any, seed: Any, max_failed_fraction: Any, n_clips: Any
) -> tuple[Any, np.ndarray]:
    """:func:`evaluate_on_dataset`'s arguments checked, in order: (the evaluator, the drawn clip indices)."""
    from ..scenes.datasets import ClipDataset
    from ..sensor import SensorConfig

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
    if not (isinstance(max_failed_fraction, (int, float)) and 0.0 <= max_failed_fraction <= 1.0):
        raise InputError(
            f"evaluate_on_dataset: max_failed_fraction={one_line(max_failed_fraction)}; allowed: a fraction in [0, 1]"
        )
    if n_clips is None:
        return evaluator, np.arange(len(dataset))
    check_count("evaluate_on_dataset: n_clips", n_clips, 1, min(MAX_CLIPS, len(dataset)))
    return evaluator, dataset.draw(n_clips, seed)


@dataclass
class _ClipScoring:
    """The state of :func:`evaluate_on_dataset` while it runs the drawn clips: the kernel, the network
    (built, loaded and put on ``dev`` at the first readable clip, which also sets the frame size and the
    default sensor), and per scored clip its predictions, event count and span."""

    evaluator: Any
    kernel: Any
    kernel_t: Any
    network: Any
    weights: Any
    sensor: Any
    events_fn: Any
    dev: Any
    shape: tuple[int, int] | None = None
    net: Any = None
    rep: Any = None
    output_shape: str = ""
    failures: list[ClipFailure] = field(default_factory=list)
    preds: list[dict[str, Any]] = field(default_factory=list)
    clips: list[Any] = field(default_factory=list)
    counts: list[float] = field(default_factory=list)
    spans: list[float] = field(default_factory=list)

    def _first_clip(self, clip: Any) -> None:
        """The frame size, the network and the sensor, from the first readable clip."""
        from .learn import default_sensor
        from .user_networks import event_input_of, load_weights, network_for

        self.shape = (int(clip.frames.shape[1]), int(clip.frames.shape[2]))
        _check_frames(self.kernel, self.evaluator.name, clip, self.shape)
        ev = self.evaluator
        net = network_for(self.network, ev.name, 2 * (clip.frames.shape[0] - 1), ev.num_classes)
        if self.weights is not None:
            load_weights(net, self.weights)
        self.rep = event_input_of(net)
        self.net = net.to(self.dev).eval()
        if self.sensor is None:
            self.sensor = default_sensor(SimpleNamespace(frame_rate_hz=1.0 / float(np.diff(clip.timestamps_s)[0])))

    def predict(self, clip: Any, i: int) -> None:
        """Simulate clip ``i``, run the network and keep its predictions (NetworkOutputError if unreadable)."""
        import torch

        from ..sensor import event_frames

        if self.shape is None:
            self._first_clip(clip)
        video = clip.as_batch(torch.float64).to(self.dev)
        with torch.no_grad():
            ev = (
                self.events_fn(video, self.kernel_t, self.sensor, clip.timestamps_s)
                if self.events_fn is not None
                else event_frames(video, self.kernel_t, timestamps_s=clip.timestamps_s, config=self.sensor)
            )
            self.counts.append(float(ev.sum()))
            self.spans.append(float(clip.timestamps_s[-1] - clip.timestamps_s[0]))
            try:
                out = self.net(self.rep(ev.float(), clip.timestamps_s))
                self.output_shape = self.output_shape or _output_shape(out)
                self.preds.append({key: v.cpu() for key, v in self.evaluator.predict(out).items()})
            except (RuntimeError, KeyError, TypeError, IndexError, ValueError, AttributeError) as exc:
                raise NetworkOutputError(
                    f"evaluate_on_dataset: the network's output on clip {i} ({clip.source!r}) cannot be "
                    f"read by the {self.evaluator.name} evaluator ({type(exc).__name__}: "
                    f"{one_line(str(exc), 120)}); input was {self.rep.kind} "
                    f"with {self.rep.channels(clip.frames.shape[0])} channels; a problem of the network, not of "
                    "the clip: the task fails"
                ) from None
        # its targets and index, not its frames (a view would keep them): memory bounded whatever the clips
        self.clips.append(dataclasses.replace(clip, frames=np.empty((0, *clip.frames.shape[1:]))))


def _dataset_evaluation(run: _ClipScoring, t0: float) -> DatasetEvaluation:
    """The metrics over the scored clips and per clip (NetworkOutputError if the predictions cannot be scored)."""
    import torch

    from ..scenes.datasets import stack_targets
    from .evaluators import concat_predictions

    evaluator, clips = run.evaluator, run.clips
    cat = concat_predictions(run.preds)
    targets = stack_targets(clips)
    t_torch = {key: torch.from_numpy(np.ascontiguousarray(v)) for key, v in targets.items()}
    try:
        metrics = evaluator.score(cat, t_torch)
    except (InputError, RuntimeError, KeyError, TypeError, IndexError, ValueError) as exc:
        raise NetworkOutputError(
            f"evaluate_on_dataset: the network's predictions cannot be scored by the {evaluator.name} evaluator "
            f"({one_line(str(exc), 160)}); the network returned {run.output_shape} for frames of "
            f"{clips[0].frames.shape[1]}x{clips[0].frames.shape[2]} px: a problem of the network, not of the "
            "clips: the task fails"
        ) from None
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
        clip_indices=np.asarray([c.index for c in clips], dtype=np.int64),
        event_counts=np.asarray(run.counts),
        predictions={key: v.numpy() for key, v in cat.items()},
        targets=targets,
        seconds=time.perf_counter() - t0,
        durations_s=np.asarray(run.spans),
        failures=tuple(run.failures),
    )


# --------------------------------------------------------------------------- several clips per video
def mean_over_videos(logits: Any, video_of: Any) -> tuple[np.ndarray, Any]:
    """Each video's class scores: the log of its clips' mean softmax probability.

    The multi-clip test of action recognition (several clips per video, the video's prediction the
    mean of its clips' class probabilities; Wang et al., TSN, ECCV 2016; Feichtenhofer et al.,
    SlowFast, ICCV 2019).

    Parameters
    ----------
    logits : torch.Tensor, shape (N, C)
        Per-clip logits.
    video_of : array of int, shape (N,)
        The video of each clip.

    Returns
    -------
    (videos, log mean probabilities)
        The distinct videos in order of first appearance, and a (V, C) tensor: its argmax is the
        video's class.

    Example
    -------
    >>> import torch
    >>> v, p = mean_over_videos(torch.tensor([[2.0, 0.0], [0.0, 1.0], [0.0, 3.0]]), [4, 4, 9])
    >>> v.tolist(), p.argmax(dim=1).tolist()
    ([4, 9], [0, 1])
    """
    import torch

    video_of = np.asarray(video_of, dtype=np.int64)
    if len(video_of) != int(logits.shape[0]):
        raise InputError(f"mean_over_videos: {len(video_of)} video indices for {int(logits.shape[0])} clips")
    videos = np.asarray(list(dict.fromkeys(video_of.tolist())), dtype=np.int64)
    probs = torch.softmax(logits.double(), dim=1)
    means = torch.stack([probs[torch.from_numpy(np.flatnonzero(video_of == v))].mean(dim=0) for v in videos])
    return videos, torch.log(means)


def per_video_evaluation(
    evaluation: DatasetEvaluation, video_of: Any, task: Any, num_classes: int
) -> DatasetEvaluation:
    """A recognition evaluation of several clips per video scored per video (the mean over its clips).

    Parameters
    ----------
    evaluation : DatasetEvaluation
        Of the clips (:func:`evaluate_on_dataset` on a
        :class:`~fsdvs_hw.tasks.clip_sampling.SampledVideoClips`); skipped clips are left out of
        their video's mean (a video with none scored is left out).
    video_of : array of int
        The video of every clip of the dataset (``SampledVideoClips.video_of``).
    task : str or TaskEvaluator
        ``"recognition"`` (the other tasks' targets differ from clip to clip).
    num_classes : int

    Returns
    -------
    DatasetEvaluation
        One entry per video: ``per_clip`` is each video's top-1, ``clip_indices`` the video indices,
        ``event_counts`` and ``durations_s`` the means over its clips, ``predictions["logits"]`` the
        log mean probabilities; ``metrics`` over the videos.

    Example
    -------
    >>> ev = evaluate_on_dataset(k, "recognition", clips, net)                          # doctest: +SKIP
    >>> per_video_evaluation(ev, clips.video_of, "recognition", clips.num_classes).value  # doctest: +SKIP
    0.75
    """
    import torch

    from .evaluators import get_evaluator

    ev: Any = copy.copy(get_evaluator(task))
    if ev.name != "recognition":
        raise InputError(
            f"per_video_evaluation: task {ev.name!r}; allowed: 'recognition' (clips_per_video > 1 averages a "
            "video's class probabilities; detection and segmentation clips each have their own targets)"
        )
    ev.num_classes = int(num_classes)
    vid = np.asarray(video_of, dtype=np.int64)[evaluation.clip_indices]
    logits = torch.as_tensor(evaluation.predictions["logits"])
    videos, scores = mean_over_videos(logits, vid)
    first = np.asarray([np.flatnonzero(vid == v)[0] for v in videos])
    labels = np.asarray(evaluation.targets["motion"])[first]
    per_video = (scores.argmax(dim=1).numpy() == labels).astype(np.float64)
    means = {
        name: np.asarray([arr[vid == v].mean() for v in videos])
        for name, arr in (("events", evaluation.event_counts), ("durations", evaluation.durations_s))
    }
    return DatasetEvaluation(
        task=ev.name,
        metrics=ev.score({"logits": scores.float()}, {"motion": torch.from_numpy(labels)}),
        primary_metric=ev.primary_metric,
        per_clip=per_video,
        clip_indices=videos,
        event_counts=means["events"],
        predictions={"logits": scores.numpy()},
        targets={"motion": labels},
        seconds=evaluation.seconds,
        durations_s=means["durations"],
        failures=evaluation.failures,
    )


def evaluate_sampled(
    kernel: Any,
    task: Any,
    dataset: Any,
    network: Any = None,
    *,
    sampling: Any = None,
    n_clips: int | None = None,
    seed: int = 0,
    **options: Any,
) -> DatasetEvaluation:
    """:func:`evaluate_on_dataset`, or with ``sampling`` several clips per video scored per video.

    Parameters
    ----------
    kernel, task, dataset, network
        As :func:`evaluate_on_dataset` (with ``sampling``: a ``VideoFolderDataset`` with a ``size``).
    sampling : SamplingSpec or mapping, optional
        ``[tasks.datasets.<task>] sampling`` (:class:`fsdvs_hw.tasks.clip_sampling.SamplingSpec`):
        ``n_clips`` videos are drawn with ``seed`` (None: every video), each scored on its
        ``clips_per_video`` evenly spaced, centre-cropped clips (:func:`per_video_evaluation`).
        None: :func:`evaluate_on_dataset` as it is.
    n_clips, seed
        The draw (of videos with ``sampling``).
    **options
        :func:`evaluate_on_dataset`'s other keywords (``sensor``, ``device``, ``max_failed_fraction``, ...).

    Returns
    -------
    DatasetEvaluation
        Per clip, or per video with ``sampling``.

    Example
    -------
    >>> evaluate_sampled(k, "recognition", videos, net, sampling={"clips_per_video": 5}, n_clips=100)  # doctest: +SKIP
    """
    if sampling is None:
        return evaluate_on_dataset(kernel, task, dataset, network, n_clips=n_clips, seed=seed, **options)
    from .clip_sampling import SampledVideoClips, SamplingSpec

    spec = sampling if isinstance(sampling, SamplingSpec) else SamplingSpec(**dict(sampling))
    if dataset.size is None:
        raise InputError(
            "evaluate_sampled: sampling crops to the dataset's size; field 'size': give dataset.size = [H, W]"
        )
    videos = dataset.draw(n_clips, seed) if n_clips else np.arange(len(dataset))
    clips = SampledVideoClips(dataset, dataset.size, spec, video_indices=videos)
    ev = evaluate_on_dataset(kernel, task, clips, network, **options)
    return per_video_evaluation(ev, clips.video_of, task, dataset.num_classes)
