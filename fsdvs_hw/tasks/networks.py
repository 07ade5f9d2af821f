"""Small CPU networks that read event frames: a shared backbone and one head per task.

The FS-DVS paper uses RT-DETR (detection), MViT (recognition) and Mask2Former (segmentation) on
GPUs. Here every network is a few ten thousand parameters so that a full kernel-size ablation
runs on a laptop CPU; the *protocol* (frozen-filter stage, decoupled learning rates per
parameter group: filter / backbone / head) is the paper's.

Input representation: event frames ``(B, T-1, 2, H, W)`` (ON/OFF counts per frame interval) are
stacked as ``2(T-1)`` channels and compressed with ``log1p`` (counts from a high-gain kernel can be
large; ``log1p`` keeps the input scale bounded and the map differentiable).

Networks expose two parameter groups, ``backbone`` and ``head`` (module attributes of those
names), which the learning code gives separate learning rates.
"""

from __future__ import annotations

from typing import cast

import torch
from torch import nn
from torch.nn import functional as F

__all__ = ["CenterNetDetector", "Classifier", "EventBackbone", "Segmenter", "event_representation"]


def event_representation(frames: torch.Tensor) -> torch.Tensor:
    """``(B, T-1, 2, H, W)`` event counts → ``(B, 2(T-1), H, W)`` network input (``log1p``).

    Raises
    ------
    InputError
        ``frames`` not a floating 5-D tensor with 2 polarity channels.
    """
    if (
        not isinstance(frames, torch.Tensor)
        or frames.ndim != 5
        or frames.shape[2] != 2
        or not frames.is_floating_point()
    ):
        from ..errors import InputError

        what = (
            f"shape {tuple(frames.shape)}, dtype {frames.dtype}"
            if isinstance(frames, torch.Tensor)
            else f"type {type(frames).__name__}"
        )
        raise InputError(
            f"frames: {what}; allowed: a floating (B, T-1, 2, H, W) tensor of event counts "
            "(fsdvs_hw.sensor.event_frames)"
        )
    b, t, p, h, w = frames.shape
    return torch.log1p(frames.clamp(min=0.0).reshape(b, t * p, h, w))


def conv_block(cin: int, cout: int, *, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    """3×3 convolution (padding = ``dilation``: same size at stride 1), GroupNorm of 4 groups, ReLU."""
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride=stride, padding=dilation, dilation=dilation),
        nn.GroupNorm(4, cout),
        nn.ReLU(inplace=True),
    )


class EventBackbone(nn.Module):
    """Conv backbone: full-resolution features (``width`` ch) and stride-2 features (``2·width`` ch)."""

    def __init__(self, in_channels: int, width: int = 16) -> None:
        super().__init__()
        self.stem = conv_block(in_channels, width)
        self.down = conv_block(width, 2 * width, stride=2)
        self.context = nn.Sequential(conv_block(2 * width, 2 * width), conv_block(2 * width, 2 * width, dilation=2))
        self.out_channels = 2 * width
        self.fine_channels = width

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        fine = self.stem(x)
        coarse = self.context(self.down(fine))
        return fine, coarse


class CenterNetDetector(nn.Module):
    """CenterNet-style detector (Zhou et al. 2019, "Objects as Points") at stride 2.

    Outputs a dict: ``heatmap`` logits ``(B, C, H/2, W/2)``, ``size`` (box width/height in input
    pixels, ``(B, 2, H/2, W/2)``) and ``offset`` (sub-cell centre offset in cells).
    """

    stride = 2

    def __init__(self, in_channels: int, num_classes: int, width: int = 16) -> None:
        super().__init__()
        self.backbone = EventBackbone(in_channels, width)
        c = self.backbone.out_channels
        self.head = nn.ModuleDict(
            {
                "heatmap": nn.Sequential(conv_block(c, c), nn.Conv2d(c, num_classes, 1)),
                "regress": nn.Sequential(conv_block(c, c), nn.Conv2d(c, 4, 1)),
            }
        )
        # focal-loss prior: start at p = 0.05 everywhere (Lin et al. 2017)
        heat_out = cast(nn.Conv2d, cast(nn.Sequential, self.head["heatmap"])[-1])
        assert heat_out.bias is not None  # a Conv2d with its default bias
        nn.init.constant_(heat_out.bias, -2.94)

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        _, coarse = self.backbone(x)
        reg = self.head["regress"](coarse)
        return {
            "heatmap": self.head["heatmap"](coarse),
            "size": F.softplus(reg[:, :2]) * 4.0,
            "offset": torch.sigmoid(reg[:, 2:]),
        }


class Classifier(nn.Module):
    """Clip classifier: backbone, global average + max pooling, linear head → logits (B, C)."""

    def __init__(self, in_channels: int, num_classes: int, width: int = 16) -> None:
        super().__init__()
        self.backbone = EventBackbone(in_channels, width)
        c = self.backbone.out_channels
        self.head = nn.Sequential(nn.Linear(2 * c, c), nn.ReLU(inplace=True), nn.Linear(c, num_classes))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _, coarse = self.backbone(x)
        pooled = torch.cat([coarse.mean(dim=(2, 3)), coarse.amax(dim=(2, 3))], dim=1)
        return self.head(pooled)


class Segmenter(nn.Module):
    """Per-pixel classifier: coarse features upsampled ×2 and fused with full-res features."""

    def __init__(self, in_channels: int, num_classes: int, width: int = 16) -> None:
        super().__init__()
        self.backbone = EventBackbone(in_channels, width)
        c = self.backbone.out_channels + self.backbone.fine_channels
        self.head = nn.Sequential(conv_block(c, width), nn.Conv2d(width, num_classes, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        fine, coarse = self.backbone(x)
        up = F.interpolate(coarse, size=fine.shape[-2:], mode="bilinear", align_corners=False)
        return self.head(torch.cat([fine, up], dim=1))
