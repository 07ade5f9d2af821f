"""The training engine of the task networks: epochs of optimiser steps over shuffled clip batches.

:func:`train_epochs` is the one epoch loop of :func:`~fsdvs_hw.tasks.learn.learn_kernel`,
:func:`~fsdvs_hw.tasks.learn.finetune_network`, :func:`~fsdvs_hw.tasks.learn.evaluate_kernel`
(fine-tuning) and :func:`~fsdvs_hw.tasks.dataset_training.train_on_dataset`. A stage is described
by a :class:`TrainingConfig` (name, epochs, batch size, progress, checkpointing) and trains on a
:class:`TrainingData` (the clips, their targets, the simulator and how a batch becomes the
network's input). Each epoch draws one permutation of the clips from the run's batch-order
generator and takes one optimiser step per batch, in order; the kernel (free taps, or a
realisation's module called for its taps at every step) trains when it is in the optimiser.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from .event_inputs import inputs_once, network_input

__all__ = [
    "TrainingConfig",
    "TrainingData",
    "adamw_optimizer",
    "delta_init",
    "kernel_taps",
    "print_progress",
    "select_clips",
    "train_epoch",
    "train_epochs",
]


@dataclass(frozen=True)
class TrainingConfig:
    """How one training stage runs.

    Parameters
    ----------
    stage : str
        The stage's name in the history (``"frozen_filter"``, ``"joint"``,
        ``"joint_frozen_filter"``, ``"finetune"``, ``"codesign"``).
    epochs : int
        Epochs of the stage, 0 … 100 000; epochs ``first_epoch … epochs - 1`` are trained.
    batch_size : int
        Clips per optimiser step, ≥ 1 (the last batch of an epoch holds the rest).
    first_epoch : int
        The first epoch trained, ≥ 0 (> 0 when a stage resumes from a checkpoint).
    progress : callable, optional
        Called with one line per finished epoch:
        ``"[learn] TASK STAGE epoch E/N: loss L (S s)"`` (E from 1, L the mean training loss, S
        the epoch's wall time in seconds).
    progress_stage : str, optional
        The stage's name in progress lines (default: ``stage``).
    on_epoch_end : callable, optional
        Called with the epoch index after each finished epoch, once the history holds it and the
        progress line is out (checkpointing).
    """

    stage: str
    epochs: int
    batch_size: int
    first_epoch: int = 0
    progress: Callable[[str], None] | None = None
    progress_stage: str | None = None
    on_epoch_end: Callable[[int], None] | None = None

    def __post_init__(self) -> None:
        for name, lo in (("epochs", 0), ("batch_size", 1), ("first_epoch", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= 100_000:
                raise InputError(f"TrainingConfig.{name} must be an integer in [{lo}, 100000], got {v!r}")


@dataclass(frozen=True)
class TrainingData:
    """The clips a stage trains on and how a batch of them becomes the network's input.

    Parameters
    ----------
    video : torch.Tensor, shape (N, T, H, W)
        Linear intensity of the training clips.
    targets : dict of str to torch.Tensor
        The evaluator's training targets, first axis = clips.
    sensor : SensorConfig
        Simulator settings.
    timestamps_s : numpy.ndarray, shape (T,)
        Frame times in seconds.
    input_fn : callable
        ``input_fn(clips, kernel_taps, sensor, timestamps_s)``: the network input of a batch
        (default :func:`~fsdvs_hw.tasks.event_inputs.network_input`, log1p event frames).
    cached_inputs : torch.Tensor, optional
        Every clip's input, computed once for a frozen kernel (:meth:`with_frozen_kernel`);
        replaces ``input_fn``.
    """

    video: Any
    targets: dict[str, Any]
    sensor: Any
    timestamps_s: np.ndarray
    input_fn: Callable[..., Any] = network_input
    cached_inputs: Any = None

    def with_frozen_kernel(self, kernel: Any, chunk: int = 128) -> TrainingData:
        """This data with every clip's input through ``kernel`` computed once (``chunk`` clips at a time)."""
        cached = inputs_once(self.input_fn, self.video, kernel, self.sensor, self.timestamps_s, chunk=chunk)
        return TrainingData(self.video, self.targets, self.sensor, self.timestamps_s, self.input_fn, cached)


def print_progress(message: str) -> None:
    """One progress line on stderr, flushed (the ``progress`` of a verbose run)."""
    print(message, file=sys.stderr, flush=True)


def select_clips(targets: dict[str, Any], idx: Any) -> dict[str, Any]:
    """The targets of the clips ``idx`` (an index tensor or a slice) of every entry."""
    return {k: v[idx] for k, v in targets.items()}


def kernel_taps(kernel: Any) -> Any:
    """The taps of a trained kernel: the tensor itself, or a realisation module called for them."""
    return kernel() if callable(kernel) else kernel


def delta_init(size: int, noise: float, generator: Any) -> Any:
    """A ``size`` × ``size`` Dirac delta plus Gaussian noise of standard deviation ``noise`` (float64).

    The noise is drawn from ``generator`` (all taps, then the centre is set to 1).
    """
    import torch

    taps = torch.randn((size, size), generator=generator, dtype=torch.float64) * noise
    taps[size // 2, size // 2] = 1.0
    return taps


def adamw_optimizer(network: Any, weight_decay: float, rates: dict[str, float], kernel: Any = None) -> Any:
    """AdamW over a network's parameters in groups, and the kernel's first when it trains.

    Parameters
    ----------
    network : torch.nn.Module
    weight_decay : float
        AdamW weight decay of the network's groups (the kernel's group has none: a prior-free
        kernel).
    rates : dict of str to float
        Learning rates (1/step): ``{"network": lr}`` trains the whole network as one group;
        ``{"backbone": lr, "head": lr}`` its ``backbone`` and ``head`` sub-modules as two
        (a network without both trains as one group at the ``head`` rate); ``"kernel"``: the
        kernel's rate.
    kernel : torch.Tensor or torch.nn.Module, optional
        The trained kernel: free taps (a Parameter) or a realisation module's parameters.

    Returns
    -------
    torch.optim.AdamW
    """
    import torch

    wd = weight_decay
    backbone, head = getattr(network, "backbone", None), getattr(network, "head", None)
    if "network" in rates:
        groups = [{"params": list(network.parameters()), "lr": rates["network"], "weight_decay": wd}]
    elif isinstance(backbone, torch.nn.Module) and isinstance(head, torch.nn.Module):
        groups = [
            {"params": list(backbone.parameters()), "lr": rates["backbone"], "weight_decay": wd},
            {"params": list(head.parameters()), "lr": rates["head"], "weight_decay": wd},
        ]
    else:
        groups = [{"params": list(network.parameters()), "lr": rates["head"], "weight_decay": wd}]
    if kernel is not None:
        params = list(kernel.parameters()) if isinstance(kernel, torch.nn.Module) else [kernel]
        groups.insert(0, {"params": params, "lr": rates["kernel"], "weight_decay": 0.0})
    return torch.optim.AdamW(groups)


def train_epoch(
    config: TrainingConfig,
    epoch: int,
    evaluator: Any,
    network: Any,
    kernel: Any,
    data: TrainingData,
    optimizer: Any,
    generator: Any,
    kernel_init: Any = None,
) -> dict[str, Any]:
    """One epoch: a permutation of the clips from ``generator``, one ``optimizer`` step per batch.

    Returns
    -------
    dict
        ``stage``, ``epoch``, ``loss`` (mean training loss over the clips), ``seconds`` (wall
        time), and ``kernel_change_l1`` (sum of ``|taps - kernel_init|``) when ``kernel_init`` is
        given.

    Raises
    ------
    FloatingPointError
        A batch's loss is not finite.
    """
    import torch

    t0 = time.perf_counter()
    n = data.video.shape[0]
    perm = torch.randperm(n, generator=generator)
    total, count = 0.0, 0
    for s in range(0, n, config.batch_size):
        idx = perm[s : s + config.batch_size]
        if data.cached_inputs is not None:
            x = data.cached_inputs[idx]
        else:  # a realisation module is called for its kernel at every step (co-design)
            x = data.input_fn(data.video[idx], kernel_taps(kernel), data.sensor, data.timestamps_s)
        loss = evaluator.loss(network(x), select_clips(data.targets, idx))
        value = float(loss.detach())
        if not math.isfinite(value):
            raise FloatingPointError(f"{config.stage} epoch {epoch}: training loss is not finite ({value})")
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        total += value * len(idx)
        count += len(idx)
    record = {"stage": config.stage, "epoch": epoch, "loss": total / count, "seconds": time.perf_counter() - t0}
    if kernel_init is not None:
        with torch.no_grad():
            taps = kernel_taps(kernel)
        record["kernel_change_l1"] = float((taps.detach() - kernel_init).abs().sum())
    return record


def train_epochs(
    config: TrainingConfig,
    *,
    evaluator: Any,
    network: Any,
    kernel: Any,
    data: TrainingData,
    optimizer: Any,
    generator: Any,
    history: list[dict[str, Any]],
    kernel_init: Any = None,
) -> int:
    """Train ``network`` (and the kernel, if it is in ``optimizer``) for the epochs of one stage.

    Parameters
    ----------
    config : TrainingConfig
        The stage: name, epochs, batch size, progress and checkpointing.
    evaluator : TaskEvaluator
        Its ``loss(output, targets)`` is minimised; its ``name`` is in progress lines.
    network : torch.nn.Module
    kernel : torch.Tensor or torch.nn.Module
        The kernel taps (k, k), or a realisation module returning them (called at every step).
    data : TrainingData
        The clips and how they become the network's input.
    optimizer : torch.optim.Optimizer
        Steps once per batch.
    generator : torch.Generator
        Batch order: one ``randperm`` per epoch (the run's seeded generator, shared by its stages).
    history : list of dict
        Each epoch's record (:func:`train_epoch`) is appended.
    kernel_init : torch.Tensor, optional
        The initial taps: the records then hold ``kernel_change_l1``.

    Returns
    -------
    int
        Epochs trained.
    """
    label = config.progress_stage or config.stage
    for epoch in range(config.first_epoch, config.epochs):
        record = train_epoch(config, epoch, evaluator, network, kernel, data, optimizer, generator, kernel_init)
        history.append(record)
        if config.progress is not None:
            config.progress(
                f"[learn] {evaluator.name} {label} epoch {epoch + 1}/{config.epochs}: loss {record['loss']:.4f} "
                f"({record['seconds']:.1f} s)"
            )
        if config.on_epoch_end is not None:
            config.on_epoch_end(epoch)
    return max(config.epochs - config.first_epoch, 0)
