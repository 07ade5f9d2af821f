"""Clip batches through the differentiable simulator to a task network's input.

:func:`simulated_events` gives the event frames of a video batch seen through a pre-log kernel
(:func:`fsdvs_hw.sensor.event_frames`, differentiable in the kernel); :func:`network_input` turns
them into the built-in networks' representation (log1p event counts, 2(T-1) channels);
:func:`inputs_once` computes the inputs of every clip once, for a kernel that does not train.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["inputs_once", "network_input", "simulated_events"]


def simulated_events(video: Any, kernel: Any, sensor: Any, timestamps_s: np.ndarray) -> Any:
    """Event frames of a video batch through the simulator (differentiable in ``kernel``).

    Parameters
    ----------
    video : torch.Tensor, shape (B, T, H, W)
        Linear intensity.
    kernel : torch.Tensor, shape (k, k)
        The pre-log spatial kernel's taps.
    sensor : SensorConfig
        Simulator settings.
    timestamps_s : numpy.ndarray, shape (T,)
        Frame times in seconds.

    Returns
    -------
    torch.Tensor, shape (B, T-1, 2, H, W)
        ON / OFF event counts per frame interval.
    """
    from ..sensor import event_frames

    return event_frames(video, kernel, timestamps_s=timestamps_s, config=sensor)


def network_input(video: Any, kernel: Any, sensor: Any, timestamps_s: np.ndarray) -> Any:
    """The built-in networks' input of a video batch: log1p event counts, shape (B, 2(T-1), H, W), float32.

    Parameters as :func:`simulated_events`.
    """
    from .networks import event_representation

    return event_representation(simulated_events(video, kernel, sensor, timestamps_s).float())


def inputs_once(
    input_fn: Callable[..., Any], video: Any, kernel: Any, sensor: Any, timestamps_s: Any, chunk: int = 128
) -> Any:
    """The network inputs of every clip through a frozen kernel, computed once without gradients.

    Parameters
    ----------
    input_fn : callable
        ``input_fn(clips, kernel, sensor, timestamps_s)``: the network input of a batch
        (:func:`network_input` or a user network's representation).
    video : torch.Tensor, shape (N, T, H, W)
    kernel, sensor, timestamps_s
        As :func:`simulated_events`.
    chunk : int
        Clips simulated at a time (the simulator's noise draws depend on the batch: callers keep
        their chunk size).

    Returns
    -------
    torch.Tensor
        The inputs of the ``N`` clips, concatenated along the first axis.
    """
    import torch

    with torch.no_grad():
        return torch.cat(
            [input_fn(video[s : s + chunk], kernel, sensor, timestamps_s) for s in range(0, video.shape[0], chunk)]
        )
