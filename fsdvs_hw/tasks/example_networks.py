"""Example user networks, one per task: what a ``network = "module:factory"`` must take and return.

Copy this module next to your design file and change the layers; the *contract* is what the
evaluators (:mod:`fsdvs_hw.tasks.evaluators`) read, and it is tested
(``tests/test_example_networks.py``): each example runs through its task's ``predict`` and a
hand-made output decodes to the box, class or mask written here. A design names one as
``network = "fsdvs_hw.tasks.example_networks:detector"`` (or ``"my_nets:detector"`` for your copy).

The factory
-----------
Called as ``factory(in_channels=2 (T - 1), num_classes=C, **network_options)``; it returns a
``torch.nn.Module``. Give it ``backbone`` and ``head`` sub-modules to get the FS-DVS paper's
decoupled stage-two learning rates (``train.lr_backbone``, ``train.lr_head``); without them the
network trains as one group.

The input
---------
``x`` of shape ``(B, 2 (T - 1), H, W)``, float32: the ON and OFF event counts of each of the
``T - 1`` frame intervals of a clip of ``T`` frames, ``log1p``-compressed, interleaved by interval
(channel ``2k`` = ON events of interval ``k``, ``2k + 1`` = OFF events;
:func:`fsdvs_hw.tasks.networks.event_representation`). ``H × W`` is the dataset's frame size
(``dataset.size``). A module attribute ``event_input = "voxel:N"`` asks for a signed voxel grid
``(B, N, H, W)`` instead (:mod:`fsdvs_hw.tasks.user_networks`).

The outputs
-----------
**recognition** — logits ``(B, C)``, one row per clip, *before* softmax. The prediction is the
arg-max; with several clips per video the video's score is the mean of its clips' softmax
probabilities, so the logits must be comparable across clips (no temperature of your own).

**segmentation** — logits ``(B, C, H, W)`` at the *input* resolution, before softmax; the
prediction is the arg-max per pixel. Pixels labelled ``ignore_index`` are not scored.

**detection** — a dict of three tensors on a grid of **stride 2** (``H/2 × W/2`` cells; ``H`` and
``W`` must be even), CenterNet's layout (Zhou et al. 2019):

* ``"heatmap"``: ``(B, C, H/2, W/2)`` **logits** of an object centre of class ``c`` in each
  cell — the evaluator applies the sigmoid (do not), keeps 3 × 3 local maxima and the top
  ``max_detections`` (10) of them; the sigmoid is the box's score;
* ``"size"``: ``(B, 2, H/2, W/2)`` the box's **width and height in input pixels** (not cells),
  read at the peak's cell, ≥ 0;
* ``"offset"``: ``(B, 2, H/2, W/2)`` the centre's sub-cell position **in cells** (x then y, in
  [0, 1)): the centre is ``((ix + offset_x) · 2, (iy + offset_y) · 2)`` pixels for the peak at
  column ``ix``, row ``iy``.

The box is ``(cx − w/2, cy − h/2, cx + w/2, cy + h/2)`` in input pixels (scored by pycocotools
against the dataset's boxes, scaled with the frames). The training loss is the CenterNet focal
loss on ``sigmoid(heatmap)`` and L1 on ``size`` (weight 0.1) and ``offset`` at the object centres.

References
----------
X. Zhou, D. Wang, P. Krähenbühl, "Objects as Points", arXiv:1904.07850 (2019).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .networks import conv_block

__all__ = ["ExampleClassifier", "ExampleDetector", "ExampleSegmenter", "classifier", "detector", "segmenter"]


class ExampleClassifier(nn.Module):
    """Recognition: ``(B, 2(T-1), H, W)`` events → logits ``(B, C)``.

    Examples
    --------
    >>> classifier(in_channels=6, num_classes=4)(torch.zeros(2, 6, 32, 32)).shape
    torch.Size([2, 4])
    """

    def __init__(self, in_channels: int, num_classes: int, width: int = 16) -> None:
        super().__init__()
        self.backbone = nn.Sequential(conv_block(in_channels, width), conv_block(width, 2 * width, stride=2))
        self.head = nn.Linear(2 * width, num_classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.backbone(x).mean(dim=(2, 3)))  # logits, no softmax


class ExampleSegmenter(nn.Module):
    """Segmentation: ``(B, 2(T-1), H, W)`` events → logits ``(B, C, H, W)`` at the input size.

    Examples
    --------
    >>> segmenter(in_channels=4, num_classes=3)(torch.zeros(1, 4, 16, 24)).shape
    torch.Size([1, 3, 16, 24])
    """

    def __init__(self, in_channels: int, num_classes: int, width: int = 16) -> None:
        super().__init__()
        self.backbone = nn.Sequential(conv_block(in_channels, width), conv_block(width, width))
        self.head = nn.Conv2d(width, num_classes, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.backbone(x))


class ExampleDetector(nn.Module):
    """Detection: ``(B, 2(T-1), H, W)`` events → ``{"heatmap", "size", "offset"}`` at stride 2.

    Examples
    --------
    >>> out = detector(in_channels=6, num_classes=2)(torch.zeros(1, 6, 32, 48))
    >>> {k: tuple(v.shape) for k, v in out.items()}
    {'heatmap': (1, 2, 16, 24), 'size': (1, 2, 16, 24), 'offset': (1, 2, 16, 24)}
    """

    stride = 2

    def __init__(self, in_channels: int, num_classes: int, width: int = 16, typical_size_px: float = 8.0) -> None:
        super().__init__()
        self.backbone = nn.Sequential(conv_block(in_channels, width), conv_block(width, 2 * width, stride=2))
        self.head = nn.Conv2d(2 * width, num_classes + 4, 1)
        self.num_classes, self.typical_size_px = num_classes, float(typical_size_px)
        assert self.head.bias is not None  # a Conv2d with its default bias
        with torch.no_grad():  # start every centre at p = sigmoid(-2.94) = 0.05 (focal-loss prior)
            self.head.bias[:num_classes].fill_(-2.94)

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        y = self.head(self.backbone(x))
        c = self.num_classes
        return {
            "heatmap": y[:, :c],  # logits: the evaluator applies the sigmoid
            "size": F.softplus(y[:, c : c + 2]) * self.typical_size_px,  # width, height in input pixels, >= 0
            "offset": torch.sigmoid(y[:, c + 2 : c + 4]),  # centre within its cell, in cells, in (0, 1)
        }


def classifier(in_channels: int, num_classes: int, width: int = 16) -> nn.Module:
    """``network = "fsdvs_hw.tasks.example_networks:classifier"`` (recognition)."""
    return ExampleClassifier(in_channels, num_classes, width)


def segmenter(in_channels: int, num_classes: int, width: int = 16) -> nn.Module:
    """``network = "fsdvs_hw.tasks.example_networks:segmenter"`` (segmentation)."""
    return ExampleSegmenter(in_channels, num_classes, width)


def detector(in_channels: int, num_classes: int, width: int = 16, typical_size_px: float = 8.0) -> nn.Module:
    """``network = "fsdvs_hw.tasks.example_networks:detector"`` (detection; ``network_options =
    { typical_size_px = 12 }`` sets the box size, in pixels, an untrained network starts near)."""
    return ExampleDetector(in_channels, num_classes, width, typical_size_px)
