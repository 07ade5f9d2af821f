"""Sensor-in-the-loop emulation: filtered video shown on a display and recaptured by a noisy DVS.

The FS-DVS paper validates learned kernels physically: the source video is temporally upsampled
(RIFE, to 400 Hz), convolved with the kernel, shown on a 480 Hz monitor and recaptured by a
Prophesee EVK4. This module emulates that chain so that every realisation can be scored on the
same track:

1. **Filter** the linear-intensity video with the realised kernel (cross-correlation with
   replicated borders, :func:`fsdvs_hw.sensor.simulation.filtering.apply_kernel`, the simulator's own
   convention).
2. **Display**: a display cannot emit negative light or exceed its peak. The filtered clip is
   mapped affinely onto [black, peak] luminance with one gain per clip (so temporal contrast is
   kept): 0 → black, the clip's 99.9th percentile → peak; values outside are clipped and the
   clipped fractions are reported. The drive level is gamma-encoded (``code = v^(1/γ)``) and
   quantised to ``display_bits``; the panel emits ``black + (peak − black)·(code/max)^γ``.
   Luminance is expressed relative to the peak (the camera sees [black/peak, 1]).
3. **Temporal upsampling** by ``upsample_factor``: by default (``upsample = "linear_light"``)
   linear blending in linear light, standing in for RIFE's motion-compensated interpolation (a
   stated simplification: blending turns motion into a cross-fade between frames, which spreads
   the same log change over more sub-steps); with ``upsample = "flow"`` optical-flow
   interpolation in log intensity with occlusion handling
   (:func:`fsdvs_hw.sensor.simulation.upsampling.interpolate_frames`), closer to RIFE.
4. **Recapture** by the exact event simulator (:func:`fsdvs_hw.sensor.event_frames`) with no
   in-pixel kernel and the design's noisy sensor (thresholds, mismatch, v2e noise defaults); the
   upsampled intervals are summed back onto the source frame intervals.

:func:`emulation_scores` compares the recaptured event frames with the in-sensor FS-DVS (the
kernel inside the pixel, same noisy sensor): event-count ratio and correlation of the signed
(ON − OFF) frames. The gap is what the paper's physical track adds to the simulation track.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..design.display_settings import DisplaySettings
from ..errors import InputError
from ..kernels import Kernel

__all__ = ["camera_config", "display_luminance", "emulation_scores", "recapture", "upsample_linear"]


def display_luminance(filtered: np.ndarray, display: DisplaySettings) -> tuple[np.ndarray, dict[str, float]]:
    """Map a filtered linear clip (..., T, H, W) to emitted luminance relative to the peak.

    One gain per clip (axis 0 when 4-D): 0 → black, 99.9th percentile → peak. Returns the
    luminance in [black/peak, 1] and ``{"clipped_black", "clipped_peak"}`` fractions.
    """
    f = np.asarray(filtered, dtype=np.float64)
    if f.ndim != 4:
        raise InputError(f"display_luminance: expected (N, T, H, W), got shape {f.shape}")
    ref = np.percentile(f.reshape(f.shape[0], -1), 99.9, axis=1).reshape(-1, 1, 1, 1)
    ref = np.where(ref > 0, ref, 1.0)
    v = f / ref
    info = {"clipped_black": float(np.mean(v < 0)), "clipped_peak": float(np.mean(v > 1))}
    v = np.clip(v, 0.0, 1.0)
    levels = 2**display.bits - 1
    code = np.round(v ** (1.0 / display.gamma) * levels)
    lo = display.black_nits / display.peak_nits
    return lo + (1.0 - lo) * (code / levels) ** display.gamma, info


def upsample_linear(
    video: np.ndarray, timestamps_s: np.ndarray, factor: int, mode: str = "linear_light"
) -> tuple[np.ndarray, np.ndarray]:
    """Insert ``factor − 1`` frames between neighbours: T → (T−1)·factor + 1 frames.

    ``mode``: ``"linear_light"`` blends linearly in linear light; ``"flow"`` interpolates with
    optical flow in log intensity (:func:`fsdvs_hw.sensor.simulation.upsampling.interpolate_frames`).
    """
    if factor == 1:
        return video, timestamps_s
    t = np.asarray(timestamps_s, dtype=np.float64)
    w = np.arange(factor) / factor  # blend weights within one interval
    a, b = video[:, :-1], video[:, 1:]
    if mode == "flow":
        from ..sensor.simulation.upsampling import interpolate_frames

        mid = np.stack(
            [
                np.stack([interpolate_frames(a[i, k], b[i, k], w, mode="flow") for k in range(a.shape[1])])
                for i in range(a.shape[0])
            ]
        )
    else:
        mid = a[:, :, None] * (1 - w)[None, None, :, None, None] + b[:, :, None] * w[None, None, :, None, None]
    n, T = video.shape[:2]
    up = np.concatenate([mid.reshape(n, (T - 1) * factor, *video.shape[2:]), video[:, -1:]], axis=1)
    tu = np.concatenate([(t[:-1, None] * (1 - w) + t[1:, None] * w).ravel(), t[-1:]])
    return up, tu


def recapture(
    video: np.ndarray, timestamps_s: np.ndarray, kernel: Kernel, *, display: DisplaySettings, sensor: Any
) -> tuple[Any, dict[str, float]]:
    """Filter, display, upsample and recapture a clip; event frames on the source intervals.

    Returns
    -------
    frames : torch.Tensor, shape (N, T−1, 2, H, W)
        Recaptured ON/OFF counts per source frame interval.
    info : dict
        Clipped fractions of the display mapping.
    """
    import torch

    from ..sensor import event_frames
    from ..sensor.simulation.filtering import apply_kernel

    with torch.no_grad():
        filt = apply_kernel(torch.as_tensor(video, dtype=torch.float64), torch.as_tensor(np.array(kernel.taps)))
    lum, info = display_luminance(filt.numpy(), display)
    up, tu = upsample_linear(lum, np.asarray(timestamps_s, dtype=np.float64), display.upsample_factor, display.upsample)
    with torch.no_grad():
        fr = event_frames(torch.as_tensor(up), None, timestamps_s=torch.as_tensor(tu), config=sensor)
    n, tm1 = fr.shape[0], video.shape[1] - 1
    fr = fr.reshape(n, tm1, display.upsample_factor, *fr.shape[2:]).sum(dim=2)
    return fr, info


def _sensor_config(sensor: Mapping[str, Any], seed: int, frame_rate_hz: float) -> Any:
    from ..sensor import SensorConfig

    return SensorConfig(
        threshold_on=sensor["threshold_on"],
        threshold_off=sensor["threshold_off"],
        threshold_sigma=sensor["threshold_sigma"],
        placement=sensor["placement"],
        positivity=sensor["positivity"],
        frame_rate_hz=frame_rate_hz,
        seed=seed,
    )


def camera_config(camera: str, design_sensor: Any) -> Any:
    """The recapturing camera's SensorConfig: ``"design"`` (the design's sensor) or a preset name.

    A preset (:mod:`fsdvs_hw.sensor.cameras.presets`) brings its thresholds, mismatch, refractory period,
    bandwidth and noise; the frame rate and seed stay the design's.

    Examples
    --------
    >>> from fsdvs_hw.sensor import SensorConfig
    >>> camera_config("imx636", SensorConfig(seed=3)).seed
    3
    >>> camera_config("design", SensorConfig(threshold_on=0.3)).threshold_on
    0.3
    """
    if camera == "design":
        return design_sensor
    from ..sensor.cameras.presets import sensor_config

    return sensor_config(camera, frame_rate_hz=design_sensor.frame_rate_hz, seed=design_sensor.seed)


def emulation_scores(
    kernel: Kernel, *, sensor: Mapping[str, Any], emulation: Mapping[str, Any], seed: int = 0, camera: str | None = None
) -> dict[str, Any]:
    """Compare the in-sensor FS-DVS with its sensor-in-the-loop emulation on synthetic clips.

    Parameters
    ----------
    kernel : Kernel
        The realised kernel.
    sensor : mapping
        A design's ``[sensor]`` section (thresholds, mismatch, placement, positivity, resolution).
    emulation : mapping
        A design's ``[emulation]`` section (display, upsampling, ``n_clips``, ``n_frames``).
    camera : str, optional
        The recapturing camera: ``"design"`` (default: the design's sensor, as before) or a sensor
        preset name such as ``"imx636"`` (the paper's EVK4), see :func:`camera_config`; a
        ``camera`` entry of ``emulation`` is used when this is not given.
    seed : int
        Scene and sensor seed.

    Returns
    -------
    dict
        ``status``, ``events_in_sensor``, ``events_recaptured``, ``event_ratio`` (recaptured /
        in-sensor), ``signed_correlation`` (Pearson r of ON − OFF frames), ``clipped_black``,
        ``clipped_peak``, ``wall_s``.
    """
    t0 = time.perf_counter()
    import torch  # the simulator (torch) loads only when the emulation track runs

    from ..scenes.synthetic import SceneConfig, make_scenes
    from ..sensor import event_frames

    h, w = sensor["resolution"]
    scene = SceneConfig(height_px=int(h), width_px=int(w), n_frames=int(emulation["n_frames"]))
    if kernel.size > min(h, w):
        raise InputError(f"emulation: a {kernel.size}x{kernel.size} kernel does not fit the {h}x{w} sensor.resolution")
    clips = make_scenes(scene, int(emulation["n_clips"]), seed=seed)
    cfg = _sensor_config(sensor, seed, scene.frame_rate_hz)
    with torch.no_grad():
        ref = event_frames(
            torch.as_tensor(clips.video),
            torch.as_tensor(np.array(kernel.taps)),
            timestamps_s=torch.as_tensor(clips.timestamps_s),
            config=cfg,
        )
    display = DisplaySettings.from_design(emulation)
    rec, info = recapture(
        clips.video,
        clips.timestamps_s,
        kernel,
        display=display,
        sensor=camera_config(camera or emulation.get("camera", "design"), cfg),
    )
    a = (ref[:, :, 0] - ref[:, :, 1]).numpy().ravel()
    b = (rec[:, :, 0] - rec[:, :, 1]).numpy().ravel()
    corr = float(np.corrcoef(a, b)[0, 1]) if a.std() > 0 and b.std() > 0 else 0.0
    n_ref, n_rec = float(ref.sum()), float(rec.sum())
    return {
        "status": "ok",
        "events_in_sensor": n_ref,
        "events_recaptured": n_rec,
        "event_ratio": n_rec / n_ref if n_ref > 0 else float("nan"),
        "signed_correlation": corr,
        **info,
        "n_clips": int(emulation["n_clips"]),
        "resolution": [int(h), int(w)],
        "wall_s": time.perf_counter() - t0,
    }
