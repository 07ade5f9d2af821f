"""A known source video for calibrating a sensor: a display-recapture test pattern.

:func:`calibration_video` makes what a display shown to the camera would play for
:func:`~fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor`: an oblique grating with soft-square bars
(``tanh`` of a sinusoid, so pixels see both slow ramps and steep edges) drifting at a speed that
sweeps between 5 and 35 cycles per second, under a slow brightness modulation, with a static
border (a quarter of the columns, constant intensity) where only noise and leak events occur.
Slow ramps give pairs of events one threshold apart; steep edges make the refractory period
bind; the border measures the noise rates.

Examples
--------
>>> video, ts = calibration_video(100, 16, 20)
>>> tuple(video.shape), float(ts[1] - ts[0])
((1, 100, 16, 20), 0.001)
>>> bool((video[0, :, :, :5] == 0.4).all())  # the static border
True
"""

from __future__ import annotations

import math
from typing import Any

from ...errors import InputError

__all__ = ["calibration_video"]


def calibration_video(
    n_frames: int, height: int, width: int, *, frame_rate_hz: float = 1000.0, static_fraction: float = 0.25
) -> tuple[Any, Any]:
    """The calibration pattern: ``(video (1, T, H, W) float32 intensities in (0, 1], times (T,) float64 s)``.

    Parameters
    ----------
    n_frames, height, width : int
        Frames and size in pixels (each >= 2).
    frame_rate_hz : float
        Display frame rate (default 1000 Hz: fast enough that the grating moves under a pixel per
        frame).
    static_fraction : float
        Share of the columns (from the left) held at a constant 0.4 (default 0.25).
    """
    import torch

    for name, v in (("n_frames", n_frames), ("height", height), ("width", width)):
        if not isinstance(v, int) or isinstance(v, bool) or v < 2:
            raise InputError(f"calibration_video: {name} must be an integer >= 2, got {v!r}")
    if not 0 <= static_fraction < 1 or not frame_rate_hz > 0:
        raise InputError(
            f"calibration_video: static_fraction in [0, 1) and frame_rate_hz > 0, got "
            f"{static_fraction!r}, {frame_rate_hz!r}"
        )
    ts = torch.arange(n_frames, dtype=torch.float64) / frame_rate_hz
    yy, xx = torch.meshgrid(
        torch.arange(height, dtype=torch.float64), torch.arange(width, dtype=torch.float64), indexing="ij"
    )
    bars = 2 * math.pi * (0.11 * xx + 0.05 * yy)
    speed = 2 * math.pi * (20 + 15 * torch.sin(2 * math.pi * 0.7 * ts))  # rad/s
    phase = torch.cumsum(speed / frame_rate_hz, 0)
    video = 0.5 * (1.05 + torch.tanh(2.5 * torch.sin(bars[None] - phase[:, None, None])))
    video = video * (0.6 + 0.4 * torch.sin(2 * math.pi * 1.3 * ts)[:, None, None] ** 2)
    video[:, :, : int(static_fraction * width)] = 0.4
    return video[None].float(), ts
