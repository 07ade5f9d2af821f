"""Event voxel grids (Zhu et al. 2019): events spread over time bins by linear (hat) interpolation.

:func:`voxel_grid` takes an exact :class:`~fsdvs_hw.sensor.simulation.events.EventList`, or
differentiable event frames whose events it spreads evenly over each frame interval and integrates
against each bin's hat in closed form (so the grid stays differentiable).
"""

from __future__ import annotations

from typing import Any

import torch

from ...errors import InputError
from ...limits import check_allocation
from ...validation import check_bool, check_increasing_times, check_int
from .events import EventList

__all__ = ["voxel_grid"]


def _hat_integral(u: Any) -> Any:
    """The unit hat ``1 - |v|`` on [-1, 1] integrated from -1 to ``u`` (0 below, 1 above)."""
    return torch.where(
        u < -1,
        torch.zeros_like(u),
        torch.where(u < 0, 0.5 * (u + 1) ** 2, torch.where(u < 1, 1 - 0.5 * (1 - u) ** 2, torch.ones_like(u))),
    )


def _events_voxel_grid(ev: EventList, n_bins: int, timestamps_s: Any, height: Any, width: Any) -> Any:
    """The (B, n_bins, 2, H, W) float64 ON/OFF voxel grid of an exact :class:`EventList`."""
    if height is None or width is None or timestamps_s is None:
        raise InputError("voxel_grid: an EventList needs height, width and timestamps_s")
    height = check_int("height", height, 1, None)
    width = check_int("width", width, 1, None)
    ts = torch.from_numpy(check_increasing_times("timestamps_s", timestamps_s))
    if len(ev) and (
        int(ev.x.max()) >= width or int(ev.y.max()) >= height or int(ev.x.min()) < 0 or int(ev.y.min()) < 0
    ):
        raise InputError(
            f"voxel_grid: events reach pixel (x={int(ev.x.max())}, y={int(ev.y.max())}) outside "
            f"height={height}, width={width}; allowed: the sensor size the events were made with"
        )
    t0, t1 = float(ts[0]), float(ts[-1])
    B = int(ev.b.max()) + 1 if len(ev) else 1
    check_allocation(
        f"voxel_grid (B={B}, n_bins={n_bins}, 2, H={height}, W={width}, float64)",
        8.0 * B * n_bins * 2 * height * width,
    )
    out = torch.zeros((B, n_bins, 2, height, width), dtype=torch.float64)
    if len(ev):
        pos = (ev.t - t0) / (t1 - t0) * (n_bins - 1) if n_bins > 1 else torch.zeros_like(ev.t)
        lo = torch.floor(pos).clamp(0, n_bins - 1)
        frac = pos - lo
        ch = (ev.p < 0).long()
        for off, wgt in ((0, 1 - frac), (1, frac)):
            bins = (lo.long() + off).clamp(max=n_bins - 1)
            out.index_put_((ev.b, bins, ch, ev.y, ev.x), wgt, accumulate=True)
    return out


def _frames_voxel_grid(frames: Any, n_bins: int, timestamps_s: Any) -> Any:
    """The (B, n_bins, 2, H, W) ON/OFF voxel grid of (B, T-1, 2, H, W) event frames, each
    interval's events spread evenly over it and integrated against each bin's hat (differentiable)."""
    if not isinstance(frames, torch.Tensor) or frames.ndim != 5 or frames.shape[2] != 2:
        raise InputError("voxel_grid: frames must be a (B, T-1, 2, H, W) tensor from event_frames")
    if not frames.is_floating_point():
        raise InputError(f"voxel_grid: frames must be a floating tensor (event counts), got dtype {frames.dtype}")
    n_int = frames.shape[1]
    if timestamps_s is None:
        ts = torch.arange(n_int + 1, dtype=torch.float64)
    else:
        ts = torch.from_numpy(check_increasing_times("timestamps_s", timestamps_s))
        if ts.numel() != n_int + 1:
            raise InputError(f"timestamps_s: needs {n_int + 1} frame times for {n_int} intervals")
    t0, t1 = float(ts[0]), float(ts[-1])
    B, _, _, H, W = frames.shape
    check_allocation(
        f"voxel_grid (B={B}, n_bins={n_bins}, 2, H={H}, W={W}, {frames.dtype})",
        float(frames.element_size()) * B * n_bins * 2 * H * W,
    )
    width_s = (t1 - t0) / max(n_bins - 1, 1)
    centres = torch.linspace(t0, t1, n_bins, dtype=torch.float64) if n_bins > 1 else torch.tensor([t0])
    a, b = ts[:-1, None], ts[1:, None]
    wgt = width_s / (b - a) * (_hat_integral((b - centres) / width_s) - _hat_integral((a - centres) / width_s))
    return torch.einsum("ij,bicyx->bjcyx", wgt.to(frames.dtype).to(frames.device), frames)


def voxel_grid(
    events_or_frames: Any,
    n_bins: int,
    *,
    timestamps_s: Any = None,
    height: int | None = None,
    width: int | None = None,
    signed: bool = True,
) -> Any:
    """Event voxel grid (Zhu et al. 2019): events spread over ``n_bins`` time bins by linear
    (hat) interpolation in time.

    Parameters
    ----------
    events_or_frames : EventList or torch.Tensor (B, T-1, 2, H, W)
        An exact :class:`EventList`, or differentiable event frames. For frames, each interval's
        events are taken as evenly spread over the interval and integrated against each bin's hat
        function in closed form (the splitting of Neural Ganglion Sensors), so the grid stays
        differentiable.
    n_bins : int
        Number of time bins (>= 1); bin centres span ``[t_0, t_{T-1}]`` end to end.
    timestamps_s : array_like (T,), optional
        Frame times (needed for an EventList: its time span; for frames default: uniform).
    height, width : int
        Sensor size (required for an EventList).
    signed : bool
        True: one channel ON − OFF, shape (B, n_bins, H, W). False: ON and OFF channels,
        shape (B, n_bins, 2, H, W).

    Raises
    ------
    InputError
        Bad arguments (timestamps that are not finite and strictly increasing: they would give a
        NaN grid), or a grid larger than the allocation limit (:mod:`fsdvs_hw.limits`, 1 GiB by
        default), refused with its size before anything is allocated.

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw import SensorConfig, event_frames, voxel_grid
    >>> video = torch.ones(1, 5, 4, 4)
    >>> video[:, 1:, :, 2:] = 2.0
    >>> voxel_grid(event_frames(video, config=SensorConfig.ideal()), 3).shape
    torch.Size([1, 3, 4, 4])
    """

    if not isinstance(n_bins, int) or isinstance(n_bins, bool) or n_bins < 1:
        raise InputError(f"n_bins: must be a positive integer, got {n_bins!r}")
    signed = check_bool("signed", signed)
    if isinstance(events_or_frames, EventList):
        out = _events_voxel_grid(events_or_frames, n_bins, timestamps_s, height, width)
    else:
        out = _frames_voxel_grid(events_or_frames, n_bins, timestamps_s)
    return out[:, :, 0] - out[:, :, 1] if signed else out
