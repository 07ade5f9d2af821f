"""A user network from outside the package, loaded by import path in tests/test_user_datasets.py.

``"toy_network:make"`` (with tests/plugins on sys.path) builds a tiny network for any of the three tasks (the output the
task's evaluator reads); ``"toy_network:make_voxel"`` the same on a 4-bin voxel grid.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["make", "make_voxel", "not_a_module"]


class _Toy(nn.Module):
    def __init__(self, in_channels: int, num_classes: int, task: str) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.task = task
        self.conv = nn.Conv2d(in_channels, 8, 3, padding=1)
        self.out = nn.Conv2d(8, num_classes + (4 if task == "detection" else 0), 1)
        self.num_classes = num_classes

    def forward(self, x: torch.Tensor):
        y = self.out(torch.relu(self.conv(x)))
        if self.task == "recognition":
            return y.mean(dim=(2, 3))
        if self.task == "segmentation":
            return y
        y = nn.functional.avg_pool2d(y, 2)  # CenterNet layout at stride 2
        c = self.num_classes
        return {
            "heatmap": y[:, :c],
            "size": nn.functional.softplus(y[:, c : c + 2]) * 4.0,
            "offset": torch.sigmoid(y[:, c + 2 :]),
        }


def make(in_channels: int, num_classes: int, task: str = "recognition") -> nn.Module:
    """A tiny network reading event frames."""
    return _Toy(in_channels, num_classes, task)


def make_voxel(in_channels: int, num_classes: int, task: str = "recognition") -> nn.Module:
    """A tiny network declaring a 4-bin voxel grid input (``in_channels`` is ignored)."""
    net = _Toy(4, num_classes, task)
    net.event_input = "voxel:4"
    return net


def not_a_module(**kwargs):
    """Returns a dict: load_network_factory must refuse it."""
    return {"weights": 1}
