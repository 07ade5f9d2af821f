"""Training clips streamed from disk by a torch DataLoader, with the clips in memory bounded by a key.

Holding a dataset's training clips in RAM grows with the dataset (UCF101's trainlist01 at
64×64×8 frames is about 1.25 GB of float32, at 240×320 about 23 GB). A :class:`ClipStream`
instead decodes each clip when a batch asks for it (through the dataset's disk cache of decoded
clips when it has one), in ``workers`` processes of a :class:`torch.utils.data.DataLoader`, and
:func:`loader_plan` sizes the loader so that the clips it holds at once stay under
``memory_mb``:

    held = (workers × prefetch + 1) × batch_size × 4 T H W  +  max(workers, 1) × 2 × 8 T H W

bytes: the float32 batches queued by the workers and the one training, plus one float64 clip
being decoded per process and its resize (a clip of T frames of H × W pixels). The prefetch
depth is 2, lowered to 1 and then fewer workers until ``held`` fits; when not even one batch in
one process fits, :class:`~fsdvs_hw.errors.InputError` names the key and what would fit. The
network, its gradients and the simulator's batch are the training step's memory, not the
loader's, and come on top (they grow with ``batch_size`` and the frame size, never with the
dataset).

Batch order is a ``randperm`` per epoch from the run's seeded generator (as
:func:`fsdvs_hw.tasks.training.train_epoch`); what a clip looks like (a sampled start frame, a
crop, a flip: :mod:`fsdvs_hw.tasks.clip_sampling`) depends on the seed, the epoch and the clip
only, so any number of workers gives the same batches.

Example
-------
>>> loader_plan(clip_bytes=131072, batch_size=8, memory_mb=16.0, workers=2)["prefetch"]
2
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..validation import check_real

__all__ = [
    "ClipStream",
    "EpochSampler",
    "StreamSpec",
    "clip_loader",
    "loader_plan",
    "predict_stream",
    "train_epoch_streamed",
]

#: Most loader worker processes.
MAX_STREAM_WORKERS = 64


@dataclass(frozen=True)
class StreamSpec:
    """How training clips are streamed.

    Attributes
    ----------
    memory_mb : float
        Most megabytes (10⁶ bytes) of clips the loader holds at once, (0, 10⁶].
    workers : int
        Decoding processes, 0 … 64 (0: decoded in the training process).

    Example
    -------
    >>> StreamSpec(memory_mb=512.0, workers=2).workers
    2
    """

    memory_mb: float = 1024.0
    workers: int = 0

    def __post_init__(self) -> None:
        check_real("train.memory_mb", self.memory_mb, 0.0, 1e6)
        if not self.memory_mb > 0:
            raise InputError(f"train.memory_mb = {self.memory_mb!r}; allowed: a size in (0, 1e6] MB")
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or not 0 <= self.workers <= 64:
            raise InputError(f"train.workers = {self.workers!r}; allowed: an integer in [0, {MAX_STREAM_WORKERS}]")


def loader_plan(clip_bytes: int, batch_size: int, memory_mb: float, workers: int) -> dict[str, int]:
    """Workers and prefetch depth whose clips in memory stay under ``memory_mb`` (see the module text).

    Parameters
    ----------
    clip_bytes : int
        One clip as float32, ``4 T H W`` bytes.
    batch_size : int
    memory_mb : float
        The bound, MB (10⁶ bytes).
    workers : int
        Processes wanted (fewer when they do not fit).

    Returns
    -------
    dict
        ``workers``, ``prefetch`` (batches queued per worker; 0 without workers) and
        ``held_bytes`` (the bound's left-hand side).

    Raises
    ------
    InputError
        Not even one batch decoded in the training process fits.

    Examples
    --------
    >>> loader_plan(4 * 8 * 64 * 64, 8, 4.0, 4)
    {'workers': 1, 'prefetch': 2, 'held_bytes': 3670016}
    """
    bound = memory_mb * 1e6
    batch = batch_size * clip_bytes
    for w in range(workers, 0, -1):
        for prefetch in (2, 1):
            held = (w * prefetch + 1) * batch + w * 4 * clip_bytes
            if held <= bound:
                return {"workers": w, "prefetch": prefetch, "held_bytes": held}
    held = batch + 4 * clip_bytes
    if held > bound:
        raise InputError(
            f"train.memory_mb = {memory_mb:g}: one batch of {batch_size} clips of {clip_bytes / 1e6:.3g} MB "
            f"(float32) and one clip being decoded need {held / 1e6:.3g} MB; allowed: memory_mb >= "
            f"{math.ceil(held / 1e5) / 10:g}, or a smaller train.batch_size"
        )
    return {"workers": 0, "prefetch": 0, "held_bytes": held}


class ClipStream:
    """Clips ``indices`` of a dataset as a map-style torch dataset: item ``n`` = (frames float32 (T, H, W), targets).

    Parameters
    ----------
    dataset : ClipDataset
        Decoded on demand (:mod:`fsdvs_hw.scenes.datasets`, or sampled:
        :class:`~fsdvs_hw.tasks.clip_sampling.SampledVideoClips`).
    indices : array of int
        The clips streamed, in this order.

    Example
    -------
    >>> stream = ClipStream(ds, [0, 3, 5]); len(stream)    # doctest: +SKIP
    3
    """

    def __init__(self, dataset: Any, indices: Any) -> None:
        self.dataset = dataset
        self.indices = np.asarray(list(indices), dtype=np.int64)
        self.shape: tuple[int, int, int] | None = None

    def __len__(self) -> int:
        return len(self.indices)

    def set_epoch(self, epoch: int) -> None:
        """Seeded sampling draws new clips for ``epoch`` (a dataset with an ``epoch`` attribute)."""
        if hasattr(self.dataset, "epoch"):
            self.dataset.epoch = int(epoch)

    def __getitem__(self, item: int) -> tuple[Any, dict[str, np.ndarray]]:
        """Clip ``item % len`` of epoch ``item // len`` (:class:`EpochSampler`'s items reach persistent workers)."""
        import torch

        epoch, n = divmod(int(item), len(self))
        self.set_epoch(epoch)
        clip = self.dataset[int(self.indices[n])]
        if self.shape is not None and tuple(clip.frames.shape) != self.shape:
            raise InputError(
                f"train_on_dataset: clip {int(self.indices[n])} ({clip.source!r}) has shape {clip.frames.shape}, "
                f"the first {self.shape}; field 'size': give the dataset a size=(H, W)"
            )
        frames = torch.from_numpy(np.ascontiguousarray(clip.frames, dtype=np.float32))
        return frames, {k: np.asarray(v) for k, v in clip.targets.items()}


class EpochSampler:
    """A seeded shuffle (one ``randperm`` of the clips per epoch from ``generator``, as
    :class:`torch.utils.data.RandomSampler`) or the clips in order, each item offset by ``epoch × N``
    so that persistent worker processes learn the epoch from the items they are given."""

    def __init__(self, n: int, generator: Any = None) -> None:
        self.n, self.generator, self.epoch = int(n), generator, 0

    def __len__(self) -> int:
        return self.n

    def __iter__(self) -> Any:
        import torch

        order = (
            torch.randperm(self.n, generator=self.generator).tolist() if self.generator is not None else range(self.n)
        )
        offset = self.epoch * self.n
        return iter([offset + i for i in order])


def _collate(items: list[tuple[Any, dict[str, np.ndarray]]]) -> tuple[Any, dict[str, np.ndarray]]:
    import torch

    video = torch.stack([f for f, _ in items])
    return video, {k: np.stack([t[k] for _, t in items]) for k in items[0][1]}


def clip_loader(
    stream: ClipStream, batch_size: int, spec: StreamSpec, generator: Any = None
) -> tuple[Any, dict[str, int]]:
    """A DataLoader over ``stream`` sized by :func:`loader_plan`: (loader, plan).

    ``generator`` given: shuffled with it (one ``randperm`` per epoch); None: in order
    (:class:`EpochSampler`). With workers, they persist across epochs.
    """
    import torch

    first = stream.dataset[int(stream.indices[0])]
    stream.shape = tuple(first.frames.shape)
    t, h, w = first.frames.shape
    plan = loader_plan(4 * t * h * w, batch_size, spec.memory_mb, spec.workers)
    sampler = EpochSampler(len(stream), generator)
    extra: dict[str, Any] = {}
    if plan["workers"]:  # persistent: each worker keeps what it read once (a video's frame count) across epochs
        extra = {
            "num_workers": plan["workers"],
            "prefetch_factor": plan["prefetch"],
            "multiprocessing_context": "fork",
            "persistent_workers": True,
        }
    loader: Any = torch.utils.data.DataLoader(
        stream,  # type: ignore[arg-type]  # a map-style dataset (len + getitem) is what DataLoader reads
        batch_size=batch_size,
        sampler=sampler,
        collate_fn=_collate,
        **extra,
    )
    return loader, plan


def train_epoch_streamed(
    stage: str,
    epoch: int,
    evaluator: Any,
    network: Any,
    kernel: Any,
    loader: Any,
    batch_input: Callable[[Any, Any], Any],
    targets_fn: Callable[[dict[str, np.ndarray]], dict[str, Any]],
    optimizer: Any,
    kernel_init: Any = None,
) -> dict[str, Any]:
    """One epoch over a streamed loader, one ``optimizer`` step per batch (as :func:`~fsdvs_hw.tasks.training.train_epoch`).

    Parameters
    ----------
    batch_input : callable
        ``batch_input(video (B, T, H, W) float32, kernel taps)``: the network input.
    targets_fn : callable
        The stacked numpy targets of a batch → the evaluator's training targets (tensors on the device).

    Returns
    -------
    dict
        ``stage``, ``epoch``, ``loss`` (mean over the clips), ``seconds``, ``clips``, and
        ``kernel_change_l1`` with ``kernel_init``.
    """
    import torch

    from .training import kernel_taps

    t0 = time.perf_counter()
    loader.dataset.set_epoch(epoch)  # in this process (no workers)
    loader.sampler.epoch = epoch  # in the workers: the items carry it
    total, count = 0.0, 0
    for video, targets in loader:
        loss = evaluator.loss(network(batch_input(video, kernel_taps(kernel))), targets_fn(targets))
        value = float(loss.detach())
        if not math.isfinite(value):
            raise FloatingPointError(f"{stage} epoch {epoch}: training loss is not finite ({value})")
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        total += value * video.shape[0]
        count += video.shape[0]
    record = {
        "stage": stage,
        "epoch": epoch,
        "loss": total / count,
        "seconds": time.perf_counter() - t0,
        "clips": count,
    }
    if kernel_init is not None:
        with torch.no_grad():
            record["kernel_change_l1"] = float((kernel_taps(kernel).detach() - kernel_init).abs().sum())
    return record


def predict_stream(
    evaluator: Any,
    network: Any,
    kernel: Any,
    loader: Any,
    batch_input: Callable[[Any, Any], Any],
    targets_fn: Callable[[dict[str, np.ndarray]], dict[str, Any]],
) -> tuple[dict[str, Any], dict[str, np.ndarray], float]:
    """The network's predictions on every clip of an in-order loader, in eval mode, without gradients.

    Returns
    -------
    (predictions, targets, mean loss)
        Predictions concatenated over batches (CPU tensors), the stacked numpy targets, and the
        evaluator's training loss averaged over the clips.
    """
    import torch

    from .evaluators import concat_predictions
    from .training import kernel_taps

    was_training = network.training
    network.eval()
    preds, targets, total, count = [], [], 0.0, 0
    with torch.no_grad():
        taps = kernel_taps(kernel)
        for video, tgt in loader:
            out = network(batch_input(video, taps))
            total += float(evaluator.loss(out, targets_fn(tgt))) * video.shape[0]
            count += video.shape[0]
            preds.append({k: v.cpu() for k, v in evaluator.predict(out).items()})
            targets.append(tgt)
    network.train(was_training)
    stacked = {k: np.concatenate([t[k] for t in targets]) for k in targets[0]}
    return concat_predictions(preds), stacked, total / max(count, 1)
