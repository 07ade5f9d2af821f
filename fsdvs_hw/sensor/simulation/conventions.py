"""Another simulator's event-generation conventions, for recordings that must compare with it.

``SensorConfig(conventions="native")`` (the default) is this package's pixel model
(:mod:`fsdvs_hw.sensor.simulation.events`): every threshold crossing at its own interpolated time,
crossings inside the refractory period lost, shot noise at a constant rate that leaves the
reference where it is. ``conventions="v2e"`` generates events by the rules of the v2e emulator
(Hu, Liu & Delbruck 2021 [1]_, ``v2ecore/emulator.py`` ``generate_events``, read at commit
``cac6384``), so that a recording of v2e and one of this simulator can be compared, and a
calibration can be told which rules a recording follows:

*Frame-grid timestamps.* Per frame interval ``(t_prev, t]`` a pixel emits ``floor(ΔL / C)``
events of one polarity (``ΔL``: comparator input minus reference at the frame); the ``i``-th
event of every pixel is stamped ``t_prev + i · Δt / M`` (``M``: the most events any pixel emits
in that interval), not at its crossing time.
*Refractory period that delays.* An event closer than ``refractory_s`` to the pixel's previous
one is not emitted and the reference does not move, so the crossing is emitted at a later frame
(native: lost, the reference follows the signal). As in v2e, the period applies only when it is
longer than the interval's grid step ``Δt / M``.
*Intensity-dependent shot noise that resets the reference.* At most one noise event per pixel
and frame, stamped at the frame time, ON with probability ``(r / 2) Δt · (1 - 0.75 i) ·
C_on,nominal / C_on,pixel`` (``i = clip((I + dark_intensity) / full_scale_intensity, 0, 1)``,
v2e's ``(DN + 20) / 275`` with the v2e presets), OFF alike; a noise event sets the pixel's
reference to the present comparator input, which also clears its leak drift.
*Forward-Euler photoreceptor.* One low-pass update per frame with factor ``min(2π f_c(I) Δt,
1)`` (native: the exact exponential on sub-steps).
*Reference at the first frame*, leak drift ``leak_rate_hz · C_on`` per second applied at each
frame (``random_reference_phase`` is honoured as in the native model).

The spatial kernel, the response (``response="v2e"`` for v2e's chord) and the per-pixel
threshold mismatch are the native model's (same seeds, same maps). Not reproduced: v2e's
per-pixel leak-rate jitter and noise-rate spread, its photoreceptor-noise mode, its random
order of the events of one grid time (here by pixel). Only event lists: ``event_frames``,
plans and streams refuse these conventions.

References
----------
.. [1] Y. Hu, S.-C. Liu, T. Delbruck, "v2e: From Video Frames to Realistic DVS Events", CVPR
   Workshops 2021.

Examples
--------
>>> import torch
>>> from fsdvs_hw.sensor import SensorConfig, event_list
>>> video = torch.ones(1, 2, 1, 2)
>>> video[:, 1, :, 1] = 2.0  # log 2 = 0.69: three ON events at C = 0.2
>>> ev = event_list(video, config=SensorConfig.ideal(0.2, conventions="v2e"), timestamps_s=[0.0, 0.03])
>>> [round(v, 3) for v in ev.t.tolist()]  # on the frame's grid, not at the crossings
[0.01, 0.02, 0.03]
"""

from __future__ import annotations

import math
from typing import Any

from ...errors import InputError
from .config import CONVENTIONS, SensorConfig
from .filtering import filtered_log_signal
from .pixel import effect_generator, photoreceptor_cutoff_hz, threshold_maps

__all__ = ["CONVENTIONS", "V2E_SHOT_NOISE_INTENSITY_FACTOR", "check_native", "frame_grid_events"]

#: v2e's shot-noise rate at full intensity as a fraction of its rate in the dark
#: (``EventEmulator.SHOT_NOISE_INTEN_FACTOR``).
V2E_SHOT_NOISE_INTENSITY_FACTOR = 0.25


def check_native(config: SensorConfig, what: str) -> None:
    """Refuse ``config`` unless its conventions are the native ones (``what``: the caller)."""
    if config.conventions != "native":
        raise InputError(
            f"{what}: SensorConfig.conventions={config.conventions!r} is available for event lists "
            "only (fsdvs_hw.sensor.event_list); use conventions='native' here"
        )


def frame_grid_events(video: Any, kernel: Any, timestamps_s: Any, config: SensorConfig) -> tuple[tuple[Any, ...], int]:
    """Events of ``video`` by v2e's rules (see the module docstring).

    Parameters
    ----------
    video : torch.Tensor (B, T, H, W)
        Checked intensities (as :func:`~fsdvs_hw.sensor.simulation.events.resolve_inputs` returns).
    kernel : torch.Tensor (k, k)
        The spatial kernel tensor.
    timestamps_s : torch.Tensor (B, T) float64
        Frame times, s.
    config : SensorConfig
        With ``conventions="v2e"``.

    Returns
    -------
    (columns, int)
        ``(b, x, y, t, p)`` int64, int64, int64, float64 s, int8 arrays sorted by time within each
        batch element (the columns of an :class:`~fsdvs_hw.sensor.simulation.events.EventList`),
        and the number of noise events.
    """
    import numpy as np
    import torch

    with torch.no_grad():
        sig = filtered_log_signal(video.to(torch.float64), kernel.to(torch.float64), config)
    B, T, H, W = sig.log_signal.shape
    cols: list[list[np.ndarray]] = [[], [], [], []]
    n_noise = 0
    for b in range(B):
        L = sig.log_signal[b].reshape(T, H * W).numpy()
        inten = sig.cutoff_intensity[b].reshape(T, H * W)
        ts = timestamps_s[b].to(torch.float64).numpy()
        events, noise = _one_clip(L, inten, ts, config, (H, W))
        n_noise += noise
        for c, v in zip(cols, (np.full(events[0].size, b), *events), strict=True):
            c.append(v)
    b_, pix, t, p = (np.concatenate(c) for c in cols)
    order = np.lexsort((pix, t, b_))
    pix = pix[order].astype(np.int64)
    columns = (b_[order].astype(np.int64), pix % W, pix // W, t[order].astype(np.float64), p[order].astype(np.int8))
    return columns, n_noise


def _one_clip(L: Any, inten: Any, ts: Any, config: SensorConfig, shape: tuple[int, int]) -> tuple[tuple[Any, ...], int]:
    """``((pixel, t, p), noise events)`` of one clip: ``L`` (T, P) comparator input per frame."""
    import numpy as np
    import torch

    T, P = L.shape
    like = torch.zeros((), dtype=torch.float64)
    c_on, c_off = (np.broadcast_to(np.asarray(c.numpy(), np.float64).reshape(-1), (P,)) for c in
                   threshold_maps(config, shape, like))  # fmt: skip
    nominal_on, nominal_off = float(config.threshold_on), float(config.threshold_off)
    frac = torch.clamp((inten + config.dark_intensity) / config.full_scale_intensity, 0.0, 1.0).numpy()
    f_c = photoreceptor_cutoff_hz(inten, config).numpy() if config.has_photoreceptor else None
    lp = L[0].copy()
    ref = lp.copy()
    if config.random_reference_phase:
        g = effect_generator(config.seed, "leak_phase", "cpu")
        ref = ref - torch.rand(shape, generator=g, dtype=torch.float64).numpy().reshape(-1) * c_on
    refr, leak, shot = float(config.refractory_s), float(config.leak_rate_hz), float(config.shot_noise_rate_hz)
    last = np.full(P, -math.inf)
    noise_rng = np.random.default_rng([int(config.seed), 1_000_003, 41])
    out: tuple[list[Any], list[Any], list[Any]] = ([], [], [])  # pixel, time, polarity pieces
    n_noise = 0
    for k in range(1, T):
        dt = float(ts[k] - ts[k - 1])
        if f_c is not None:  # v2e's forward-Euler IIR step, clipped at 1
            lp = lp + np.minimum(2 * math.pi * f_c[k] * dt, 1.0) * (L[k] - lp)
        else:
            lp = L[k].copy()
        if leak > 0:
            ref = ref - leak * c_on * dt
        diff = lp - ref
        n_on = np.floor(np.maximum(diff, 0) / c_on).astype(np.int64)
        n_off = np.floor(np.maximum(-diff, 0) / c_off).astype(np.int64)
        M = int(max(n_on.max(initial=0), n_off.max(initial=0)))
        emitted_on, emitted_off = np.zeros(P, np.int64), np.zeros(P, np.int64)
        step = dt / max(M, 1)
        for i in range(M):
            t_i = float(ts[k - 1]) + (i + 1) * step
            on, off = n_on > i, n_off > i
            if refr > step:  # v2e: only a period longer than the grid step binds
                on &= t_i - last > refr
                off &= t_i - last > refr
                last = np.where(on | off, t_i, last)
            emitted_on += on
            emitted_off += off
            _emit(out, on, off, t_i)
        ref = ref + emitted_on * c_on - emitted_off * c_off
        if shot > 0:
            lam = 0.5 * shot * dt * (1 + (V2E_SHOT_NOISE_INTENSITY_FACTOR - 1) * frac[k])
            u = noise_rng.random(P)
            on, off = u > 1 - lam * nominal_on / c_on, u < lam * nominal_off / c_off
            _emit(out, on, off, float(ts[k]))
            reset = on | off
            ref[reset] = lp[reset]
            n_noise += int(reset.sum())
    if not out[0]:
        return (np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int8)), 0
    return (np.concatenate(out[0]), np.concatenate(out[1]), np.concatenate(out[2])), n_noise


def _emit(out: tuple[list[Any], list[Any], list[Any]], on: Any, off: Any, t: float) -> None:
    """Append the ON pixels ``on`` and the OFF pixels ``off`` (boolean masks), all at time ``t``."""
    import numpy as np

    for sel, pol in ((on, 1), (off, -1)):
        idx = np.flatnonzero(sel)
        out[0].append(idx)
        out[1].append(np.full(idx.size, t))
        out[2].append(np.full(idx.size, pol))
