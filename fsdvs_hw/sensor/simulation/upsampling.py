"""Frame upsampling before simulation: new frames between the video's, so that event times follow motion.

The simulator interpolates each pixel's log intensity linearly between two frames, which is
exact for a slow change but wrong for motion: at 25 fps an edge that crosses a pixel 5 ms into a
40 ms interval makes events spread evenly over the whole 40 ms. Inserting motion-compensated
frames first (v2e uses SuperSloMo, the FS-DVS paper RIFE to 400 Hz) puts the change where the
edge is. :func:`upsample_frames` does that with a maintained classical optical flow instead of a
learned network: OpenCV's DIS flow (Kroeger et al. 2016), no downloaded weights.

Modes (:data:`UPSAMPLE_MODES`):

``"none"``
    the frames as they are;
``"linear"``
    new frames linear in log intensity between neighbours (what the simulator already assumes
    between two frames, so the events are the same up to sub-step effects: a control);
``"flow"``
    bidirectional flow between each pair of frames in log intensity, every new frame warped from
    both neighbours and blended with occlusion weights.

Flow interpolation, for a new frame at fraction ``τ`` of the interval (``L = log(I + ε)``,
``ε = 1e-4 ×`` the pair's brightest pixel, so the result does not depend on the intensity unit):

1. forward flow ``F01`` (frame 0 → 1) and backward flow ``F10`` by DIS on the pair's log
   intensity, quantised to 8 bits over the pair's common range; flow vectors shorter than
   0.5 px are set to zero: a sub-pixel shift of a smooth image changes each pixel nearly
   linearly, which linear-in-log interpolation already follows, while the flow's own error is as
   large as such a motion (measured: without this, flow frames at 0.2–0.8 px per frame time
   events worse than no upsampling);
2. flows from the new frame back to its neighbours under locally linear motion (Jiang et al.,
   CVPR 2018, eq. 4): ``Ft0 = −(1 − τ) τ F01 + τ² F10`` and ``Ft1 = (1 − τ)² F01 − τ (1 − τ) F10``;
3. **occlusion rule** (forward–backward consistency, Sundaram, Brox & Keutzer, ECCV 2010): a
   pixel ``x`` of frame 0 is *visible* in frame 1 when its flow and the backward flow at its
   destination cancel, ``|F01(x) + F10(x + F01(x))|² ≤ 0.01 (|F01(x)|² + |F10(x + F01(x))|²) + 0.5``
   (px²); likewise for frame 1 with the flows swapped. A pixel visible in only one neighbour
   takes its value from that neighbour alone (it is being covered or uncovered); one visible in
   both (or in neither) is the time-weighted blend ``(1 − τ) L0(x + Ft0) + τ L1(x + Ft1)``;
4. back to intensity, ``I = exp(L) − ε``, clipped at 0.

References
----------
.. [1] T. Kroeger, R. Timofte, D. Dai, L. Van Gool, "Fast Optical Flow using Dense Inverse
   Search", ECCV 2016 (OpenCV's ``DISOpticalFlow``).
.. [2] H. Jiang, D. Sun, V. Jampani, M.-H. Yang, E. Learned-Miller, J. Kautz, "Super SloMo: High
   Quality Estimation of Multiple Intermediate Frames for Video Interpolation", CVPR 2018, eq. 4.
.. [3] N. Sundaram, T. Brox, K. Keutzer, "Dense Point Trajectories by GPU-Accelerated Large
   Displacement Optical Flow", ECCV 2010, sec. 4 (forward–backward consistency).
.. [4] Y. Hu, S.-C. Liu, T. Delbruck, "v2e: From Video Frames to Realistic DVS Events", CVPR
   Workshops 2021 (SuperSloMo upsampling before the emulator).

Examples
--------
>>> import numpy as np
>>> from fsdvs_hw.sensor.simulation.upsampling import upsample_frames
>>> frames = [np.full((8, 8), 0.5), np.full((8, 8), 2.0)]
>>> out = list(upsample_frames(frames, mode="linear", rate_hz=100.0, frame_rate_hz=25.0))
>>> [round(t, 3) for t, _ in out]
[0.0, 0.01, 0.02, 0.03, 0.04]
>>> round(float(out[2][1][0, 0]), 4)  # half way in log: sqrt(0.5 * 2.0)
1.0
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np

from ...errors import InputError

__all__ = [
    "MAX_UPSAMPLE_RATE_HZ",
    "UPSAMPLE_MODES",
    "UPSAMPLE_MOTION_PX",
    "interpolate_frames",
    "motion_px_per_frame",
    "upsample_frames",
    "visible_masks",
]

#: The upsampling modes (module documentation).
UPSAMPLE_MODES = ("none", "linear", "flow")
#: Largest output frame rate accepted (Hz): 10 µs steps, far below any event camera's latency.
MAX_UPSAMPLE_RATE_HZ = 100_000.0
#: The plan's rule (:func:`fsdvs_hw.sensor.plan_model`): flow upsampling is needed when the scene's
#: motion (99th-percentile DIS flow) exceeds this many pixels per frame and some pixel's log
#: intensity changes by more than a threshold in a frame. Measured (``fsdvs-hw bench upsampling``,
#: docs/upsampling.md): flow frames bring event times and counts closer to a 400 Hz reference at
#: 1.8 and 4 px per frame, and change nothing measurable at 0.8 px and below (where they cost 3-20x
#: the simulation time); the limit lies between those measured points.
UPSAMPLE_MOTION_PX = 1.5
#: Smallest frame side (px) DIS measures motion on (its finest patch is 8 px; two levels).
_MIN_FLOW_SIDE = 16
# ε of L = log(I + ε), relative to the pair's brightest pixel
_LOG_OFFSET = 1e-4
# flow vectors shorter than this (px) are zeroed: sub-pixel motion is left to linear-in-log interpolation
_MIN_FLOW_PX = 0.5
# forward-backward consistency constants (Sundaram et al. 2010): relative and absolute (px²)
_CONSISTENCY_REL, _CONSISTENCY_ABS = 0.01, 0.5


def _check_mode(mode: Any) -> str:
    if mode not in UPSAMPLE_MODES:
        raise InputError(f"upsample mode {mode!r} unknown; allowed: {', '.join(UPSAMPLE_MODES)}")
    return str(mode)


def _check_rate(rate_hz: Any, name: str = "rate_hz") -> float:
    try:
        r = float(rate_hz)
    except (TypeError, ValueError):
        raise InputError(f"{name}: must be a number of hertz, got {rate_hz!r}") from None
    if not (math.isfinite(r) and 0 < r <= MAX_UPSAMPLE_RATE_HZ):
        raise InputError(f"{name}: {rate_hz!r} Hz outside the allowed range (0, {MAX_UPSAMPLE_RATE_HZ:g}]")
    return r


def _dis() -> Any:
    try:
        import cv2
    except ImportError:  # pragma: no cover - opencv-python-headless is a core dependency
        raise InputError("upsample mode 'flow' needs OpenCV: pip install opencv-python-headless") from None
    return cv2


def _flows(l0: np.ndarray, l1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """DIS forward and backward flow (H, W, 2) in pixels (x, y) between two log frames."""
    cv2 = _dis()
    lo = min(float(l0.min()), float(l1.min()))
    span = max(max(float(l0.max()), float(l1.max())) - lo, 1e-12)
    u0, u1 = (np.clip(np.rint((v - lo) / span * 255.0), 0, 255).astype(np.uint8) for v in (l0, l1))
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return dis.calc(u0, u1, None), dis.calc(u1, u0, None)


def _resolvable(flow: np.ndarray) -> np.ndarray:
    """``flow`` with vectors shorter than :data:`_MIN_FLOW_PX` set to zero."""
    return np.where((np.hypot(flow[..., 0], flow[..., 1]) < _MIN_FLOW_PX)[..., None], np.float32(0), flow)


def _warp(image: np.ndarray, flow: np.ndarray, *, cubic: bool = False) -> np.ndarray:
    """``image(x + flow(x))``, bilinear (bicubic with ``cubic``: less blur of fine texture), borders replicated."""
    cv2 = _dis()
    h, w = image.shape
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    flow = flow.astype(np.float32, copy=False)
    return cv2.remap(
        image.astype(np.float32),
        gx + flow[..., 0],
        gy + flow[..., 1],
        interpolation=cv2.INTER_CUBIC if cubic else cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )


def visible_masks(flow_fw: np.ndarray, flow_bw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which pixels of each frame are visible in the other, by forward–backward consistency.

    Parameters
    ----------
    flow_fw, flow_bw : numpy.ndarray, shape (H, W, 2)
        Flow from frame 0 to frame 1 and from frame 1 to frame 0, pixels, (x, y) order.

    Returns
    -------
    visible0, visible1 : numpy.ndarray of bool, shape (H, W)
        ``visible0[x]``: ``|F01(x) + F10(x + F01(x))|² ≤ 0.01 (|F01(x)|² + |F10(x + F01(x))|²) + 0.5``
        px² (the module's occlusion rule, Sundaram et al. 2010); ``visible1`` with the flows swapped.

    Examples
    --------
    >>> import numpy as np
    >>> fw = np.zeros((4, 6, 2), np.float32); fw[..., 0] = 2.0   # everything moves 2 px right
    >>> bw = -fw.copy(); bw[:, 4:] = 0.0                          # but columns 4-5 of frame 1 stay put
    >>> v0, v1 = visible_masks(fw, bw)
    >>> v0[0].astype(int).tolist(), v1[0].astype(int).tolist()
    ([1, 1, 0, 0, 0, 0], [1, 1, 1, 1, 0, 0])
    """
    fw = np.asarray(flow_fw, dtype=np.float32)
    bw = np.asarray(flow_bw, dtype=np.float32)
    if fw.ndim != 3 or fw.shape[-1] != 2 or fw.shape != bw.shape:
        raise InputError(f"visible_masks: flows must both be (H, W, 2), got {fw.shape} and {bw.shape}")

    def one(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        b_at = np.stack([_warp(b[..., k], a) for k in range(2)], axis=-1)
        err = ((a + b_at) ** 2).sum(-1)
        return err <= _CONSISTENCY_REL * ((a**2).sum(-1) + (b_at**2).sum(-1)) + _CONSISTENCY_ABS

    return one(fw, bw), one(bw, fw)


def motion_px_per_frame(frames: Any, *, max_pairs: int = 8) -> float | None:
    """The scene's motion: 99th percentile of the DIS flow magnitude between neighbouring frames (px).

    Parameters
    ----------
    frames : array_like, shape (T, H, W)
        Linear intensity (>= 0); T >= 2.
    max_pairs : int
        At most this many neighbouring pairs, evenly spaced over the clip, are measured (cost).

    Returns
    -------
    float or None
        Pixels per frame interval; None for frames smaller than 16 px on a side (DIS needs them).

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.ndimage import gaussian_filter
    >>> tex = np.exp(3 * gaussian_filter(np.random.default_rng(0).normal(size=(48, 48)), 2.0, mode="wrap"))
    >>> round(motion_px_per_frame(np.stack([np.roll(tex, 3 * k, axis=1) for k in range(3)])))
    3
    """
    v = np.asarray(frames, dtype=np.float64)
    if v.ndim != 3 or v.shape[0] < 2:
        raise InputError(f"frames: must be (T, H, W) with T >= 2, got shape {v.shape}")
    if min(v.shape[1:]) < _MIN_FLOW_SIDE:
        return None
    picks = np.unique(np.linspace(0, v.shape[0] - 2, min(max_pairs, v.shape[0] - 1)).round().astype(int))
    mags = []
    for i in picks:
        l0, l1, _ = _log_pair(v[i], v[i + 1])
        f01, _ = _flows(l0, l1)
        mags.append(np.hypot(f01[..., 0], f01[..., 1]).ravel())
    return float(np.percentile(np.concatenate(mags), 99))


def _log_pair(frame0: np.ndarray, frame1: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    eps = _LOG_OFFSET * max(float(frame0.max()), float(frame1.max()), 1e-30)
    return np.log(frame0 + eps), np.log(frame1 + eps), eps


def _check_frame_pair(frame0: Any, frame1: Any) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.asarray(frame0, dtype=np.float64), np.asarray(frame1, dtype=np.float64)
    if a.ndim != 2 or a.shape != b.shape:
        raise InputError(f"frames: must be two (H, W) frames of one size, got shapes {a.shape} and {b.shape}")
    if not (np.isfinite(a).all() and np.isfinite(b).all()) or a.min() < 0 or b.min() < 0:
        raise InputError("frames: intensities must be finite and >= 0 (linear intensity, video units)")
    return a, b


def interpolate_frames(frame0: Any, frame1: Any, fractions: Iterable[float], *, mode: str = "flow") -> np.ndarray:
    """Frames between two frames at the given fractions of the interval.

    Parameters
    ----------
    frame0, frame1 : array_like, shape (H, W)
        Linear intensity (>= 0, video units) at the interval's start and end.
    fractions : iterable of float
        Where the new frames lie, each in [0, 1] (0 = ``frame0``, 1 = ``frame1``).
    mode : {"linear", "flow"}
        Linear in log intensity, or flow-based with occlusion handling (module documentation).

    Returns
    -------
    numpy.ndarray, shape (len(fractions), H, W), float64
        Linear intensity.

    Raises
    ------
    InputError
        Unknown mode (or ``"none"``), frames of different shapes, negative or non-finite values,
        a fraction outside [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> a = np.ones((16, 16))
    >>> bool(np.allclose(interpolate_frames(a, a, [0.25, 0.5]), 1.0))  # equal frames: identity
    True
    """
    mode = _check_mode(mode)
    if mode == "none":
        raise InputError("interpolate_frames: mode 'none' makes no frames; use 'linear' or 'flow'")
    a, b = _check_frame_pair(frame0, frame1)
    taus = np.asarray(list(fractions), dtype=np.float64).ravel()
    if not (np.isfinite(taus).all() and ((taus >= 0) & (taus <= 1)).all()):
        raise InputError(f"fractions: each must be in [0, 1], got {taus.tolist()}")
    l0, l1, eps = _log_pair(a, b)
    out = np.empty((taus.size, *a.shape))
    f01 = f10 = None
    if mode == "flow" and not np.array_equal(a, b):
        f01, f10 = (_resolvable(f) for f in _flows(l0, l1))
    if f01 is None or f10 is None or not (f01.any() or f10.any()):  # linear, or no resolvable motion
        for k, tau in enumerate(taus):
            out[k] = (1 - tau) * l0 + tau * l1
        return np.clip(np.exp(out) - eps, 0.0, None)
    vis0, vis1 = (v.astype(np.float32) for v in visible_masks(f01, f10))
    l0f, l1f = l0.astype(np.float32), l1.astype(np.float32)
    for k, tau in enumerate(taus):
        ft0 = -(1 - tau) * tau * f01 + tau * tau * f10
        ft1 = (1 - tau) ** 2 * f01 - tau * (1 - tau) * f10
        w0 = (1 - tau) * _warp(vis0, ft0)
        w1 = tau * _warp(vis1, ft1)
        # both or neither visible: the plain time weights; one visible: that one alone
        none_visible = (w0 + w1) < 1e-6
        w0 = np.where(none_visible, 1 - tau, w0)
        w1 = np.where(none_visible, tau, w1)
        out[k] = (w0 * _warp(l0f, ft0, cubic=True) + w1 * _warp(l1f, ft1, cubic=True)) / (w0 + w1)
    return np.clip(np.exp(out) - eps, 0.0, None)


def _timed(frames: Any, timestamps_s: Any, frame_rate_hz: float | None) -> Iterator[tuple[float, np.ndarray]]:
    times = iter(timestamps_s) if timestamps_s is not None else None
    for i, item in enumerate(frames):
        if isinstance(item, tuple) and len(item) == 2:
            t, frame = item
        else:
            frame = item
            if times is not None:
                t = next(times, None)
                if t is None:
                    raise InputError("timestamps_s: fewer times than frames")
            elif frame_rate_hz is not None:
                t = i / frame_rate_hz
            else:
                raise InputError("upsample_frames: frames without times need timestamps_s or frame_rate_hz")
        yield float(t), np.asarray(frame, dtype=np.float64)


def upsample_frames(
    frames: Iterable[Any],
    *,
    mode: str = "flow",
    rate_hz: float = 400.0,
    timestamps_s: Iterable[float] | None = None,
    frame_rate_hz: float | None = None,
) -> Iterator[tuple[float, np.ndarray]]:
    """Frames at (at least) ``rate_hz``: each interval split into ``ceil(Δt · rate_hz)`` equal steps.

    Streams: one pair of frames in memory at a time, so a video of any length can be upsampled
    on its way into :func:`fsdvs_hw.sensor.simulate`.

    Parameters
    ----------
    frames : iterable
        (H, W) linear-intensity frames, or ``(t_s, frame)`` pairs (as
        :func:`fsdvs_hw.scenes.video.iter_video` yields).
    mode : {"none", "linear", "flow"}
        :data:`UPSAMPLE_MODES` (module documentation); ``"none"`` passes the frames through.
    rate_hz : float
        Output frame rate in hertz, in (0, 100 000] (default 400, the FS-DVS paper's rate). An
        interval already shorter than ``1 / rate_hz`` is left as it is.
    timestamps_s : iterable of float, optional
        Times of bare frames in seconds (strictly increasing).
    frame_rate_hz : float, optional
        Frame rate of bare frames when ``timestamps_s`` is not given (times ``i / frame_rate_hz``).

    Yields
    ------
    (float, numpy.ndarray)
        Time in seconds and (H, W) float64 linear intensity; the original frames keep their
        times and values.

    Raises
    ------
    InputError
        Unknown mode, rate out of range, frames without times, times not strictly increasing.

    Examples
    --------
    >>> import numpy as np
    >>> frames = [(0.0, np.ones((4, 4))), (0.1, np.ones((4, 4)))]
    >>> len(list(upsample_frames(frames, mode="flow", rate_hz=50.0)))  # 0.1 s at 50 Hz: 5 steps
    6
    """
    mode = _check_mode(mode)
    rate = _check_rate(rate_hz)
    if frame_rate_hz is not None:
        _check_rate(frame_rate_hz, "frame_rate_hz")
    return _upsampled(_timed(frames, timestamps_s, frame_rate_hz), mode, rate)


def _upsampled(items: Iterator[tuple[float, np.ndarray]], mode: str, rate: float) -> Iterator[tuple[float, np.ndarray]]:
    previous: tuple[float, np.ndarray] | None = None
    for t, frame in items:
        if previous is not None:
            t0, f0 = previous
            if not t > t0:
                raise InputError(f"frame times must be strictly increasing, got {t0!r} then {t!r}")
            n = max(int(math.ceil((t - t0) * rate - 1e-9)), 1)
            if mode != "none" and n > 1:
                taus = np.arange(1, n) / n
                for tau, mid in zip(taus, interpolate_frames(f0, frame, taus, mode=mode), strict=True):
                    yield t0 + float(tau) * (t - t0), mid
        yield t, frame
        previous = (t, frame)
