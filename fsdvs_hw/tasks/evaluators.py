"""Task evaluators: what a kernel is scored on. A plug-in interface plus three built-in tasks.

A :class:`TaskEvaluator` turns a :class:`~fsdvs_hw.scenes.synthetic.SceneBatch` into targets,
builds a network with ``backbone`` and ``head`` parameter groups, gives the training loss, and
scores predictions with a maintained metric library (:mod:`fsdvs_hw.tasks.metrics`). The kernel
learning code (:mod:`fsdvs_hw.tasks.learn`) only talks to this interface, so a user plugs in a new
task with :func:`register_evaluator`:

>>> class MyTask(DetectionEvaluator):          # doctest: +SKIP
...     name = "my_detection"
>>> register_evaluator(MyTask())                # doctest: +SKIP
>>> learn_kernel("my_detection", size=7)        # doctest: +SKIP

Built-in tasks (the FS-DVS paper's three):

``detection``
    Shapes (:data:`~fsdvs_hw.scenes.synthetic.SHAPE_CLASSES`) moving in random directions; boxes
    of the last frame; CenterNet-style detector; COCO mAP / AP50 / AP75 (pycocotools).
``recognition``
    One object per clip performing one of :data:`~fsdvs_hw.scenes.synthetic.MOTION_CLASSES`; top-1
    accuracy (torchmetrics).
``segmentation``
    Per-pixel shape class of the last frame (0 = background); mIoU / mAcc / pixel accuracy
    (torchmetrics).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from ..errors import InputError
from ..scenes.synthetic import MOTION_CLASSES, SHAPE_CLASSES, SceneBatch, SceneConfig, scene_regime
from .metrics import (
    DETECTION_METRICS,
    RECOGNITION_METRICS,
    SEGMENTATION_METRICS,
    detection_map,
    segmentation_scores,
    top1_accuracy,
)
from .networks import CenterNetDetector, Classifier, Segmenter

__all__ = [
    "EVALUATORS",
    "DetectionEvaluator",
    "RecognitionEvaluator",
    "SegmentationEvaluator",
    "TaskEvaluator",
    "concat_predictions",
    "get_evaluator",
    "register_evaluator",
]

Targets = dict[str, torch.Tensor]


class TaskEvaluator(ABC):
    """Interface of a task on event frames (subclass it to plug in your own).

    Class attributes
    ----------------
    name : str
        Registry key.
    metric_names : tuple of str
        Keys of the dict :meth:`score` returns.
    primary_metric : str
        The metric that :func:`~fsdvs_hw.tasks.learn.learn_kernel` reports and ablations compare.
    staged : bool
        True: train in two stages (frozen filter, then joint); False: joint from the start.
    joint_lr_ratios : (float, float, float)
        Learning rates of filter, backbone and head in the joint stage of a staged task, relative
        to the filter's rate. The paper's (FS-DVS, Sec. IV-A): detection 5e-4 / 1e-6 / 1e-5 (after
        a frozen-filter stage), recognition 5e-4 / 5e-5 / 1e-4 (a pretrained MViT fine-tuned
        jointly; here the frozen-filter stage stands in for the pretraining).
    """

    name: ClassVar[str] = "task"
    metric_names: ClassVar[tuple[str, ...]] = ()
    primary_metric: ClassVar[str] = ""
    staged: ClassVar[bool] = False
    joint_lr_ratios: ClassVar[tuple[float, float, float]] = (1.0, 1e-6 / 5e-4, 1e-5 / 5e-4)

    @abstractmethod
    def default_scene(self, regime: str = "clutter") -> SceneConfig:
        """The scene family this task is trained and scored on by default.

        ``regime`` names a :data:`~fsdvs_hw.scenes.synthetic.SCENE_REGIMES` entry: ``"clutter"``
        (default: textured ego-motion clutter, photon noise, near-threshold edges) or ``"legacy"``.
        """

    @abstractmethod
    def build_network(self, in_channels: int, width: int = 16) -> nn.Module:
        """A fresh network with ``.backbone`` and ``.head`` sub-modules."""

    @abstractmethod
    def targets(self, batch: SceneBatch) -> Targets:
        """Training/scoring targets; every tensor's first axis indexes the clips."""

    @abstractmethod
    def loss(self, output: Any, target: Targets) -> torch.Tensor:
        """Scalar training loss of a network output against a batch of targets."""

    @abstractmethod
    def predict(self, output: Any) -> dict[str, torch.Tensor]:
        """Detached predictions (first axis = clips) for :meth:`score`."""

    @abstractmethod
    def score(self, prediction: dict[str, torch.Tensor], target: Targets) -> dict[str, float]:
        """Metrics in [0, 1] with keys :attr:`metric_names`."""

    def check_scene(self, scene: SceneConfig) -> None:  # noqa: B027 - optional hook, no-op by default
        """Raise :class:`InputError` if ``scene`` cannot provide this task's ground truth."""


# --------------------------------------------------------------------------- detection
class DetectionEvaluator(TaskEvaluator):
    """Object detection of shape classes; COCO mAP@[.5:.95] (primary), AP50, AP75."""

    name = "detection"
    metric_names = DETECTION_METRICS
    primary_metric = "map"
    staged = True
    num_classes = len(SHAPE_CLASSES)
    max_detections = 10

    def default_scene(self, regime: str = "clutter") -> SceneConfig:
        return scene_regime(regime, motion="random", n_objects=(1, 2))

    def check_scene(self, scene: SceneConfig) -> None:
        if scene.motion != "random":
            raise InputError(f"task 'detection' needs SceneConfig.motion='random', got {scene.motion!r}")
        if scene.height_px % 2 or scene.width_px % 2:
            raise InputError(
                f"task 'detection' needs an even frame size (stride 2), got {scene.height_px}x{scene.width_px}"
            )

    def build_network(self, in_channels: int, width: int = 16) -> nn.Module:
        return CenterNetDetector(in_channels, self.num_classes, width)

    def targets(self, batch: SceneBatch) -> Targets:
        boxes = np.nan_to_num(batch.boxes[:, -1], nan=-1.0)  # last frame, (N, M, 4)
        labels = batch.labels.copy()
        labels[~np.isfinite(batch.boxes[:, -1]).all(axis=-1)] = -1  # objects fully outside
        n, m = labels.shape
        s = CenterNetDetector.stride
        gh, gw = batch.config.height_px // s, batch.config.width_px // s
        heat = np.zeros((n, self.num_classes, gh, gw), np.float32)
        size = np.zeros((n, 2, gh, gw), np.float32)
        offset = np.zeros((n, 2, gh, gw), np.float32)
        regmask = np.zeros((n, 1, gh, gw), np.float32)
        yy, xx = np.mgrid[0:gh, 0:gw]
        for i in range(n):
            for j in range(m):
                c = labels[i, j]
                if c < 0:
                    continue
                x0, y0, x1, y1 = boxes[i, j]
                cx, cy = 0.5 * (x0 + x1) / s, 0.5 * (y0 + y1) / s
                ix, iy = min(int(cx), gw - 1), min(int(cy), gh - 1)
                sigma = max(0.5, 0.15 * math.sqrt((x1 - x0) * (y1 - y0)) / s)
                g = np.exp(-((xx - ix) ** 2 + (yy - iy) ** 2) / (2 * sigma**2))
                heat[i, c] = np.maximum(heat[i, c], g)
                size[i, :, iy, ix] = (x1 - x0, y1 - y0)
                offset[i, :, iy, ix] = (cx - ix, cy - iy)
                regmask[i, 0, iy, ix] = 1.0
        return {
            "heatmap": torch.from_numpy(heat),
            "size": torch.from_numpy(size),
            "offset": torch.from_numpy(offset),
            "regmask": torch.from_numpy(regmask),
            "boxes": torch.from_numpy(boxes),
            "labels": torch.from_numpy(labels),
        }

    def loss(self, output: dict[str, torch.Tensor], target: Targets) -> torch.Tensor:
        # CenterNet penalty-reduced focal loss (Zhou et al. 2019) + L1 on size and offset
        p = torch.sigmoid(output["heatmap"]).clamp(1e-4, 1 - 1e-4)
        y = target["heatmap"]
        pos = (y >= 1.0 - 1e-6).float()
        pos_loss = -(torch.log(p) * (1 - p) ** 2 * pos).sum()
        neg_loss = -(torch.log(1 - p) * p**2 * (1 - y) ** 4 * (1 - pos)).sum()
        n_pos = pos.sum().clamp(min=1.0)
        mask = target["regmask"]
        l_size = (F.l1_loss(output["size"], target["size"], reduction="none") * mask).sum() / n_pos
        l_off = (F.l1_loss(output["offset"], target["offset"], reduction="none") * mask).sum() / n_pos
        return (pos_loss + neg_loss) / n_pos + 0.1 * l_size + l_off

    def predict(self, output: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        heat = torch.sigmoid(output["heatmap"].detach())
        b, c, gh, gw = heat.shape
        peaks = heat * (F.max_pool2d(heat, 3, stride=1, padding=1) == heat)
        k = min(self.max_detections, c * gh * gw)
        scores, idx = peaks.reshape(b, -1).topk(k, dim=1)
        cls = idx // (gh * gw)
        cell = idx % (gh * gw)
        iy, ix = cell // gw, cell % gw
        size = output["size"].detach().reshape(b, 2, -1)
        off = output["offset"].detach().reshape(b, 2, -1)
        w = torch.gather(size[:, 0], 1, cell)
        h = torch.gather(size[:, 1], 1, cell)
        s = CenterNetDetector.stride
        cx = (ix + torch.gather(off[:, 0], 1, cell)) * s
        cy = (iy + torch.gather(off[:, 1], 1, cell)) * s
        boxes = torch.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], dim=-1)
        return {"boxes": boxes, "scores": scores, "labels": cls}

    def score(self, prediction: dict[str, torch.Tensor], target: Targets) -> dict[str, float]:
        return detection_map(
            prediction["boxes"],
            prediction["scores"],
            prediction["labels"],
            target["boxes"],
            target["labels"],
            num_classes=self.num_classes,
        )


# --------------------------------------------------------------------------- recognition
class RecognitionEvaluator(TaskEvaluator):
    """Motion ("action") recognition of a clip; top-1 accuracy."""

    name = "recognition"
    metric_names = RECOGNITION_METRICS
    primary_metric = "top1"
    staged = True  # the paper fine-tunes a pretrained MViT; the frozen-filter stage is the pretraining
    joint_lr_ratios = (1.0, 5e-5 / 5e-4, 1e-4 / 5e-4)
    num_classes = len(MOTION_CLASSES)

    def default_scene(self, regime: str = "clutter") -> SceneConfig:
        # legacy recognition used a 0.2 edge (the clutter regime's edge contrast)
        return scene_regime(regime, motion="classes", contrast_sign="positive", edge_contrast=0.2)

    def check_scene(self, scene: SceneConfig) -> None:
        if scene.motion != "classes":
            raise InputError(f"task 'recognition' needs SceneConfig.motion='classes', got {scene.motion!r}")

    def build_network(self, in_channels: int, width: int = 16) -> nn.Module:
        return Classifier(in_channels, self.num_classes, width)

    def targets(self, batch: SceneBatch) -> Targets:
        return {"motion": torch.from_numpy(batch.motion)}

    def loss(self, output: torch.Tensor, target: Targets) -> torch.Tensor:
        return F.cross_entropy(output, target["motion"])

    def predict(self, output: torch.Tensor) -> dict[str, torch.Tensor]:
        return {"logits": output.detach()}

    def score(self, prediction: dict[str, torch.Tensor], target: Targets) -> dict[str, float]:
        return top1_accuracy(prediction["logits"], target["motion"], num_classes=self.num_classes)


# --------------------------------------------------------------------------- segmentation
class SegmentationEvaluator(TaskEvaluator):
    """Semantic segmentation of the last frame (background + shape classes); mIoU, mAcc, PA.

    Trained with class-weighted cross-entropy (background weight :attr:`background_weight`):
    about 90 % of the pixels are background, and with plain cross-entropy a small network settles
    on the constant all-background predictor (mIoU = background fraction / classes present).
    Trained jointly from the start (the paper uses segmentation only for zero-shot transfer, with
    the filter frozen, so there is no filter to stage).
    """

    name = "segmentation"
    metric_names = SEGMENTATION_METRICS
    primary_metric = "miou"
    staged = False
    background_weight = 0.1
    num_classes = 1 + len(SHAPE_CLASSES)
    #: Target label left out of the scores (None: every pixel scored; user data sets it, e.g. 255).
    ignore_index: int | None = None

    def default_scene(self, regime: str = "clutter") -> SceneConfig:
        return scene_regime(regime, motion="random", n_objects=(1, 2))

    def check_scene(self, scene: SceneConfig) -> None:
        if scene.motion != "random":
            raise InputError(f"task 'segmentation' needs SceneConfig.motion='random', got {scene.motion!r}")

    def build_network(self, in_channels: int, width: int = 16) -> nn.Module:
        return Segmenter(in_channels, self.num_classes, width)

    def targets(self, batch: SceneBatch) -> Targets:
        return {"mask": torch.from_numpy(batch.masks[:, -1])}

    def loss(self, output: torch.Tensor, target: Targets) -> torch.Tensor:
        weight = torch.ones(self.num_classes, dtype=output.dtype, device=output.device)
        weight[0] = self.background_weight
        ignore = -100 if self.ignore_index is None else int(self.ignore_index)  # -100: torch's "none"
        return F.cross_entropy(output, target["mask"], weight=weight, ignore_index=ignore)

    def predict(self, output: torch.Tensor) -> dict[str, torch.Tensor]:
        return {"mask": output.detach().argmax(dim=1)}

    def score(self, prediction: dict[str, torch.Tensor], target: Targets) -> dict[str, float]:
        return segmentation_scores(
            prediction["mask"], target["mask"], num_classes=self.num_classes, ignore_index=self.ignore_index
        )


#: task name -> evaluator instance
EVALUATORS: dict[str, TaskEvaluator] = {}


def register_evaluator(evaluator: TaskEvaluator, *, overwrite: bool = False) -> TaskEvaluator:
    """Add ``evaluator`` to :data:`EVALUATORS` under ``evaluator.name``."""
    if not isinstance(evaluator, TaskEvaluator):
        raise InputError(f"register_evaluator: expected a TaskEvaluator instance, got {type(evaluator).__name__}")
    if evaluator.primary_metric not in evaluator.metric_names:
        raise InputError(
            f"register_evaluator: primary_metric {evaluator.primary_metric!r} not in metric_names "
            f"{evaluator.metric_names}"
        )
    if evaluator.name in EVALUATORS and not overwrite:
        raise InputError(f"register_evaluator: task {evaluator.name!r} already registered (pass overwrite=True)")
    EVALUATORS[evaluator.name] = evaluator
    return evaluator


def get_evaluator(task: str | TaskEvaluator) -> TaskEvaluator:
    """The evaluator for a task name (or the evaluator itself)."""
    if isinstance(task, TaskEvaluator):
        return task
    if not isinstance(task, str) or task not in EVALUATORS:
        raise InputError(f"task {task!r} unknown; allowed: {', '.join(EVALUATORS)}")
    return EVALUATORS[task]


def concat_predictions(preds: list[dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    """Batches of :meth:`TaskEvaluator.predict` output joined along the first axis (clips), key by key."""
    return {k: torch.cat([p[k] for p in preds]) for k in preds[0]}


for _ev in (DetectionEvaluator(), RecognitionEvaluator(), SegmentationEvaluator()):
    register_evaluator(_ev)
