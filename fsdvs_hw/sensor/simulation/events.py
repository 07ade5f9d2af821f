"""Event generation: differentiable event frames and the exact event list (voxel grids: :mod:`.voxels`).

The pixel keeps a memorised reference ``r`` of its comparator input ``L`` (log units). Between
two time points the input is taken as linear (ESIM's model); with leak the reference drifts down
by ``leak_rate_hz · C_on`` per second. Every crossing of ``r + j·C_on`` (ON) or ``r - j·C_off``
(OFF) is an event, and the reference moves by one threshold per crossing. So the number of
crossings in a step has the closed form ``n = floor(ΔL / C)`` with ``ΔL = L_end - r`` and each
crossing has its own interpolated time ``t_j = t_a + (j·C - ΔL_a) / v`` — unlike v2e, whose i-th
event of every pixel in a sub-step gets the same timestamp.

Refractory period ``R``: crossings closer than ``R`` to the pixel's previous event are lost (the
reference still moves past them); given the previous event time the emitted crossings are the
indices ``j0, j0 + m, j0 + 2m, ...`` with ``m = ceil(R v / C)``, again closed form.

Time stepping
    Without a temporal filter one step per frame interval is exact (the crossings of a linear
    signal are closed-form). The photoreceptor low-pass and the mesh-surround transient need
    sub-steps: fixed (``substeps``), ESIM-style adaptive (``adaptive_fraction``: no pixel's input
    moves more than that fraction of the threshold per step), chosen per frame interval and, with
    ``adaptive_region_px``, per square region (pixels are independent after the spatial filter, so
    regions needing the same count run together), or from a :func:`~fsdvs_hw.sensor.plan_model`
    plan.

Surrogate gradient (``SensorConfig.surrogate``)
    Forward counts are the integers above. Backward uses the straight-through estimator of the
    floor: ``∂n/∂ΔL = 1 / C`` on the polarity's side (``ΔL > 0`` for ON, ``< 0`` for OFF), zero on
    the other, and ``∂n/∂C = -ΔL / C²``; the reference update then carries the gradient as if
    ``r`` tracked ``L`` exactly. With a refractory period the count's gradient is scaled by the share
    of crossings actually emitted in that step (``emitted / crossings``: the gradient follows the
    emitted events, so 1 of 3 emitted gives ``1 / (3C)``); the reference update, which moves past
    every crossing whether emitted or not, keeps its gradient. Noise events have no gradient. This is the
    recipe of Neural Ganglion Sensors (So et al. 2025): a straight-through floor, clipped to
    [-1, 1] at the dark-current floor (see :mod:`.filtering`). ``surrogate="relaxed"`` emits the
    continuous counts ``relu(±ΔL) / C`` with a reference that tracks ``L`` exactly (so ``ΔL`` is
    the frame difference): a smooth model whose exact gradient applies the same rule; in the first
    interval it equals the straight-through gradient (used by gradcheck).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import torch

from ...errors import InputError
from ...limits import check_allocation
from ...validation import check_bool, check_instance
from ..native.chunk_steps import advance_chunk, chunk_applies
from ..native.fused import fused_substep, fused_substep_applies
from .config import SATURATION_INTENSITY, SensorConfig
from .conventions import check_native, frame_grid_events
from .crossings import ComparatorStep, crossing_step, noise_step, shot_noise_pixels, sort_interval, to_event_columns
from .event_pipeline import EventPipeline, events_pipelined, noise_event_count
from .filtering import FilteredSignal, filtered_log_signal, kernel_tensor
from .pixel import effect_generator, lowpass_step, threshold_maps

__all__ = [
    "EventList",
    "EventSimulator",
    "SimulationInfo",
    "event_frames",
    "event_list",
    "prepare_timestamps",
    "prepare_video",
    "saturate",
]

_COUNT_EPS = {"float32": 1e-4, "float64": 1e-9, "float16": 1e-2, "bfloat16": 1e-2}


# ---------------------------------------------------------------------------- input checks
def prepare_video(video: Any) -> Any:
    """Check a (B, T, H, W) linear-intensity video and return it as a floating torch tensor.

    Half-precision videos (float16, bfloat16) are promoted to float32: event counts above 65504
    overflow float16 to inf, and CPU FFT correlation has no float16 kernel, so the simulation
    runs (and returns its frames) in float32.

    A numpy array or a nested list is converted (float64 stays float64, other numeric dtypes
    become float32); strings, objects, complex values and ``None`` are refused. The event frames
    the video would give (its largest array) are checked against the allocation limit
    (:mod:`fsdvs_hw.limits`) from the shape alone, before any conversion or pass over the data.
    """
    import numpy as np
    import torch

    if (
        video is None
        or isinstance(video, (str, bytes, dict))
        or (not isinstance(video, (torch.Tensor, np.ndarray, list, tuple)) and not hasattr(video, "__array__"))
    ):
        raise InputError(
            f"video: wrong type {type(video).__name__}; allowed: a (B, T, H, W) torch tensor or "
            "numpy array of linear intensities >= 0"
        )
    if not isinstance(video, torch.Tensor):
        try:
            arr = np.asarray(video)
        except (TypeError, ValueError) as exc:
            raise InputError(f"video: must be a torch tensor or numpy array ({exc})") from None
        if arr.dtype.kind not in "fiub":
            raise InputError(f"video: must be numeric (real), got dtype {arr.dtype}")
        if arr.ndim == 4:
            _check_video_size(arr.shape, 8 if arr.dtype == np.float64 else 4)
        video = torch.from_numpy(np.ascontiguousarray(arr, dtype=np.float64 if arr.dtype == np.float64 else np.float32))
    if video.is_complex():
        raise InputError(f"video: must be real, got dtype {video.dtype}; allowed: real linear intensities >= 0")
    if video.ndim != 4:
        hint = " (add a batch axis: video[None])" if video.ndim == 3 else ""
        raise InputError(f"video: must have shape (B, T, H, W), got {video.ndim}-D shape {tuple(video.shape)}{hint}")
    _check_video_size(tuple(video.shape), 8 if video.dtype == torch.float64 else 4)
    if not video.is_floating_point() or video.dtype in (torch.float16, torch.bfloat16):
        video = video.float()
    B, T, H, W = video.shape
    if T < 2 or B < 1 or H < 1 or W < 1:
        raise InputError(f"video: needs B >= 1, T >= 2 frames, H, W >= 1; got shape {tuple(video.shape)}")
    with torch.no_grad():
        total = video.sum(dtype=torch.float64)  # one pass; finite iff every value is finite
        if not bool(torch.isfinite(total)) and not bool(torch.isfinite(video).all()):
            raise InputError("video: contains NaN or inf intensities")
        vmin = float(video.min())
        if vmin < 0:
            raise InputError(f"video: linear intensities must be >= 0, got minimum {vmin:g}")
    return video


def _check_video_size(shape: tuple[int, ...], itemsize: int) -> None:
    """Refuse a video whose event frames (B, T-1, 2, H, W) would exceed the allocation limit."""
    B, T, H, W = (int(n) for n in shape)
    check_allocation(
        f"event frames of video shape (B={B}, T={T}, H={H}, W={W}): (B, T-1, 2, H, W) of {itemsize}-byte values",
        float(itemsize) * B * max(T - 1, 1) * 2 * H * W,
    )


def saturate(video: Any) -> tuple[Any, int]:
    """Clip intensities above :data:`~fsdvs_hw.sensor.simulation.config.SATURATION_INTENSITY` (a saturated pixel).

    Returns ``(video, n)``: ``video`` itself when nothing exceeds the saturation intensity (so a
    valid video runs bit-identically), else a clipped copy (zero gradient where clipped), and the
    number ``n`` of clipped pixel-frames.
    """
    with torch.no_grad():
        n = int(torch.count_nonzero(video > SATURATION_INTENSITY)) if float(video.max()) > SATURATION_INTENSITY else 0
    if n == 0:
        return video, 0
    return torch.clamp(video, max=SATURATION_INTENSITY), n


def prepare_timestamps(timestamps_s: Any, video: Any, config: SensorConfig) -> Any:
    """Frame times as a float64 (B, T) tensor on the video's device (strictly increasing)."""
    import numpy as np
    import torch

    B, T = video.shape[:2]
    if timestamps_s is None:
        ts = torch.arange(T, dtype=torch.float64, device=video.device) / config.frame_rate_hz
        return ts.expand(B, T)
    if isinstance(timestamps_s, torch.Tensor):
        if timestamps_s.device != video.device:
            raise InputError(
                f"timestamps_s: on device {timestamps_s.device} but the video is on "
                f"{video.device}; move both to the same device"
            )
        ts = timestamps_s.detach().to(torch.float64)
    else:
        if isinstance(timestamps_s, (str, bytes, dict)):
            raise InputError(
                f"timestamps_s: wrong type {type(timestamps_s).__name__}; allowed: (T,) or (B, T) "
                "frame times in seconds, finite and strictly increasing"
            )
        try:
            ts = torch.as_tensor(np.asarray(timestamps_s, dtype=np.float64), device=video.device)
        except (TypeError, ValueError) as exc:
            raise InputError(f"timestamps_s: must be numeric ({exc})") from None
    if ts.ndim == 1:
        ts = ts.expand(B, -1)
    if ts.shape != (B, T):
        raise InputError(f"timestamps_s: must have shape (T,) = ({T},) or (B, T) = ({B}, {T}), got {tuple(ts.shape)}")
    if not bool(torch.isfinite(ts).all()):
        raise InputError("timestamps_s: contains NaN or inf")
    steps = ts[:, 1:] - ts[:, :-1]
    if not bool((steps > 0).all()):
        bad = int(torch.nonzero(steps <= 0)[0, 1]) + 1
        raise InputError(f"timestamps_s: must be strictly increasing; frame {bad} is not later than frame {bad - 1}")
    return ts


# ---------------------------------------------------------------------------- results
@dataclass
class EventList:
    """Exact events, sorted by time within each batch element.

    Attributes (1-D torch tensors on the CPU, one entry per event)
    ----------
    An event of frame interval k has ``t_k < t <= t_k+1`` (a crossing reached exactly at a frame
    time belongs to the interval that ends there).

    b : int64 batch index; x, y : int64 pixel column / row; t : float64 time in seconds;
    p : int8 polarity (+1 ON, -1 OFF).
    """

    b: Any
    x: Any
    y: Any
    t: Any
    p: Any

    def __len__(self) -> int:
        return int(self.t.numel())

    def select(self, batch: int) -> EventList:
        """Events of one batch element."""
        m = self.b == batch
        return EventList(self.b[m], self.x[m], self.y[m], self.t[m], self.p[m])


@dataclass
class SimulationInfo:
    """Diagnostics of one simulation run.

    floor_fraction : fraction of pixel-frames whose aggregated photocurrent hit the floor.
    substeps : sub-steps used in each frame interval (the largest of any region).
    noise_events : number of shot-noise events emitted (ON + OFF).
    refractory_lost : crossings lost to the refractory period.
    pixel_steps : pixel sub-steps computed (the work; smaller with region stepping).
    saturated : pixel-frames of the input above
        :data:`~fsdvs_hw.sensor.simulation.config.SATURATION_INTENSITY`, clipped to it (0 for a valid scene).
    """

    floor_fraction: float
    substeps: tuple[int, ...]
    noise_events: int
    refractory_lost: int
    pixel_steps: int = 0
    saturated: int = 0


# ---------------------------------------------------------------------------- core loop
def _choose_substeps(log_signal: Any, step: float | None, config: SensorConfig) -> list[int]:
    T = log_signal.shape[1]
    if step is None:
        return [config.substeps] * (T - 1)
    with torch.no_grad():
        jumps = (log_signal[:, 1:] - log_signal[:, :-1]).abs().flatten(2).amax(dim=(0, 2))
    out = []
    for j in jumps.tolist():
        n = math.ceil(j / step) if j > 0 else 1
        out.append(int(min(max(n, 1), config.max_substeps)))
    return out


def _substep_times(tsd: Any, k: int, s: int, S: int) -> tuple[Any, Any]:
    """Start and end time (B, 1, 1) of sub-step s (1..S) of interval k; exact at frame times."""
    B = tsd.shape[0]
    t0, t1 = tsd[:, k], tsd[:, k + 1]
    t_a = t0 if s == 1 else t0 + (t1 - t0) * ((s - 1) / S)
    t_b = t1 if s == S else t0 + (t1 - t0) * (s / S)
    return t_a.view(B, 1, 1), t_b.view(B, 1, 1)


def _refractory_surrogate(n: Any, h: Any, emitted: Any) -> Any:
    """Emitted counts whose straight-through gradient is scaled by the emitted share.

    Forward value: ``emitted`` exactly (``n == h`` in the forward pass). Backward:
    ``(emitted / h) · ∂n``, so when the refractory period keeps 1 of 3 crossings the count's
    gradient is ``1 / (3C)``, not ``1 / C``. Where no crossing happened the share is 1.
    """
    return _EmittedShare.apply(n, h, emitted)


class _EmittedShare(torch.autograd.Function):
    """``emitted`` forward, ``∂n · emitted / h`` backward (one fused op instead of ten passes)."""

    @staticmethod
    def forward(ctx, n, h, emitted):  # noqa: ANN001, ANN205
        share = torch.where(h > 0, emitted / h, 1.0)  # 0 / 0 = NaN where h == 0 is replaced
        ctx.save_for_backward(share)
        return emitted.view_as(emitted)  # the counts themselves, no copy

    @staticmethod
    def backward(ctx, grad):  # noqa: ANN001, ANN205
        (share,) = ctx.saved_tensors
        return grad * share, None, None


def _sum_to(t: Any, like: Any) -> Any:
    return t.sum_to_size(like.shape) if t.shape != like.shape else t


class _Comparator(torch.autograd.Function):
    """One comparator step with the straight-through surrogate, fused for speed and memory.

    Forward: ``d = L - r``; ``n_on = floor(relu(d) / C_on)``, ``n_off = floor(relu(-d) / C_off)``;
    ``r' = r + n_on C_on - n_off C_off``. Backward: the floor is replaced by the identity
    (see the module docstring). Returns ``(n_on, n_off, r', d)``; ``d`` carries no gradient.
    """

    @staticmethod
    def forward(ctx, target, ref, c_on, c_off, eps):  # noqa: ANN001, ANN205
        d = target - ref
        h_on = torch.floor_(torch.clamp(d, min=0.0).div_(c_on).add_(eps))
        h_off = torch.floor_(torch.clamp(d, max=0.0).div_(c_off).neg_().add_(eps))
        ref_new = torch.addcmul(ref, h_on, c_on)
        ref_new.addcmul_(h_off, c_off, value=-1.0)
        ctx.save_for_backward(d, h_on, h_off, c_on, c_off)
        ctx.mark_non_differentiable(d)
        return h_on, h_off, ref_new, d

    @staticmethod
    def backward(ctx, g_on, g_off, g_ref, _g_d):  # noqa: ANN001, ANN205
        d, h_on, h_off, c_on, c_off = ctx.saved_tensors
        pos, neg = d > 0, d < 0
        g_d = torch.where(pos, g_on / c_on + g_ref, torch.where(neg, g_ref - g_off / c_off, torch.zeros_like(g_ref)))
        g_target = g_d if ctx.needs_input_grad[0] else None
        g_refin = (g_ref - g_d) if ctx.needs_input_grad[1] else None
        gc_on = gc_off = None
        if ctx.needs_input_grad[2]:
            x_on = torch.clamp(d, min=0.0) / c_on
            gc_on = _sum_to(-g_on * x_on / c_on + g_ref * (h_on - x_on), c_on)
        if ctx.needs_input_grad[3]:
            x_off = torch.clamp(d, max=0.0).neg() / c_off
            gc_off = _sum_to(-g_off * x_off / c_off - g_ref * (h_off - x_off), c_off)
        return g_target, g_refin, gc_on, gc_off, None


@dataclass
class PixelState:
    """Everything a pixel carries from one frame interval to the next (one simulation run).

    Streaming (:mod:`.stream`) keeps one of these across chunks of frames, so a clip simulated
    chunk by chunk steps through exactly the operations of a whole-clip run.
    """

    c_on: Any
    c_off: Any
    eps: float
    ref: Any  # memorised reference (log units)
    lp: Any  # photoreceptor low-pass output (None without photoreceptor)
    sur: Any  # lagged mesh surround (None without a transient surround)
    sig_prev: Any  # comparator input at the end of the previous step
    last_t: Any  # time of each pixel's last event (None without refractory period)
    shot_g: Any  # shot-noise count stream
    time_g: Any  # shot-noise time stream (event lists only)
    noise_events: int = 0
    lost: float = 0.0


def initial_pixel_state(
    L0: Any,
    SU0: Any,
    config: SensorConfig,
    thresholds: tuple[Any, Any] | None,
    phase: Any,
    generator: Any,
    collect_events: bool,
) -> PixelState:
    """Pixel state at the first frame ``L0`` (B, H, W) (``SU0``: its settled surround or None)."""
    B, H, W = L0.shape
    dev = L0.device
    c_on, c_off = thresholds if thresholds is not None else threshold_maps(config, (H, W), L0, generator=generator)
    eps = _COUNT_EPS.get(str(L0.dtype).split(".")[-1], 1e-6)
    transient = SU0 is not None
    # the comparator's initial input (centre minus the settled surround in transient mode)
    ref = (L0 - config.surround_weight * SU0) if transient else L0
    if config.random_reference_phase:  # reference starts at a random point of its cycle
        if phase is None:
            phase = _reference_phase(config, H, W, L0)
        ref = ref - phase * c_on
    refr = float(config.refractory_s)
    shot = float(config.shot_noise_rate_hz)
    last_t = torch.full((B, H, W), -math.inf, dtype=torch.float64, device=dev) if refr > 0 else None
    shot_g = effect_generator(config.seed, "shot", dev) if shot > 0 else None
    # noise-event times draw from their own stream so event_list and event_frames agree
    time_g = effect_generator(config.seed, "shot_time", dev) if shot > 0 and collect_events else None
    sig_prev = (L0 - config.surround_weight * SU0) if transient else L0
    return PixelState(
        c_on, c_off, eps, ref, L0 if config.has_photoreceptor else None, SU0, sig_prev, last_t, shot_g, time_g
    )


def advance_pixels(
    st: PixelState,
    Ls: Any,
    CI: Any,
    SU: Any,
    tsd: Any,
    config: SensorConfig,
    substeps: list[int],
    collect_events: bool,
    events: list,
    want_counts: bool = True,
    bar: Any = None,
    pipe: EventPipeline | None = None,
) -> list:
    """Step the pixels of ``st`` through frames ``Ls[0] → Ls[1] → ...`` (tuples of (B, H, W));
    ``Ls[0]`` is the frame the state is at. Returns the [on, off, on, off, ...] interval counts
    (``None`` entries unless ``want_counts``); each interval's time-sorted ``(flat, t, p)`` events
    (:func:`.crossings.sort_interval`, or None) are appended to ``events``. ``tsd``: (B, len(Ls))
    float64 frame times. ``bar`` (tqdm, optional) advances by one per frame interval.

    ``pipe``: a caller-owned :class:`EventPipeline` (:mod:`.stream` keeps one across chunks);
    then ``events`` receives futures and the refractory losses stay in ``pipe`` (``take_lost``),
    for the caller to collect. Without it the event work of a CPU event list still runs on a
    pipeline of its own, collected before returning.
    """
    if pipe is not None:
        return _advance_steps(st, Ls, CI, SU, tsd, config, substeps, collect_events, events, want_counts, bar, pipe)
    if collect_events and events_pipelined(Ls[0].device, config, want_counts):
        pipe = EventPipeline()
    first_event = len(events)
    try:
        frames = _advance_steps(st, Ls, CI, SU, tsd, config, substeps, collect_events, events, want_counts, bar, pipe)
        if pipe is not None:
            for i in range(first_event, len(events)):
                events[i] = events[i].result()
            st.lost += pipe.take_lost()
            st.noise_events += noise_event_count(pipe.take_noise())
    finally:
        if pipe is not None:
            pipe.close()
    return frames


def _with_noise_counts(
    e_on: Any, e_off: Any, on_px: Any, off_px: Any, shape: tuple[int, int, int], dtype: Any
) -> tuple[Any, Any]:
    """The step's ON and OFF counts plus the shot-noise events at the flat pixel indices ``on_px``, ``off_px``."""
    n = shape[0] * shape[1] * shape[2]
    if len(on_px):
        e_on = e_on + torch.bincount(on_px, minlength=n).view(*shape).to(dtype)
    if len(off_px):
        e_off = e_off + torch.bincount(off_px, minlength=n).view(*shape).to(dtype)
    return e_on, e_off


def _substep_target(
    Ls: Any, CI: Any, SU: Any, k: int, s: int, S: int, lp: Any, sur: Any, dt_sub: Any, config: SensorConfig
) -> tuple[Any, Any, Any]:
    """The log signal the comparator sees at sub-step ``s`` of ``S`` in interval ``k`` (frames interpolated),
    after the photoreceptor low-pass (``CI`` given) and the surround transient (``SU`` given); with the
    new low-pass and surround states ``(target, lp, sur)``."""
    frac = s / S
    target = Ls[k + 1] if s == S else torch.lerp(Ls[k], Ls[k + 1], frac)
    if CI is not None:
        inten = CI[k + 1] if s == S else torch.lerp(CI[k], CI[k + 1], frac)
        fc = config.cutoff_hz * torch.clamp((inten + config.dark_intensity) / config.full_scale_intensity, 0.0, 1.0)
        lp = lowpass_step(lp, target, fc, dt_sub)
        target = lp
    if SU is not None:
        stt = SU[k + 1] if s == S else torch.lerp(SU[k], SU[k + 1], frac)
        alpha = -torch.expm1(-dt_sub / config.surround_tau_s)
        sur = sur + alpha * (stt - sur)
        target = target - config.surround_weight * sur
    return target, lp, sur


class ComparatorOutput(NamedTuple):
    """One sub-step of every pixel up to the comparator's output (what :func:`_compare` returns).

    Attributes
    ----------
    target : torch.Tensor (B, H, W)
        The comparator's input (log units) at the sub-step's end.
    lp, sur : torch.Tensor (B, H, W) or None
        Photoreceptor low-pass and post-log transient states after the sub-step.
    ref : torch.Tensor (B, H, W)
        The reference after the leak.
    ref_next : torch.Tensor (B, H, W)
        The reference after the sub-step's crossings.
    n_on, n_off : torch.Tensor (B, H, W)
        Crossing counts; with the relaxed surrogate its fractional counts.
    d_b : torch.Tensor (B, H, W)
        Comparator input minus reference (after the leak) at the sub-step's end.
    """

    target: Any
    lp: Any
    sur: Any
    ref: Any
    ref_next: Any
    n_on: Any
    n_off: Any
    d_b: Any


def _compare(
    Ls: Any,
    CI: Any,
    SU: Any,
    k: int,
    s: int,
    S: int,
    lp: Any,
    sur: Any,
    ref: Any,
    st: PixelState,
    dt_sub: Any,
    config: SensorConfig,
    fused: bool,
) -> ComparatorOutput:
    """Sub-step ``s`` of ``S`` in interval ``k`` up to the comparator's output: the target
    (:func:`_substep_target`), the leak, then :class:`_Comparator` (or the relaxed surrogate).
    ``fused``: the same arithmetic through :func:`~fsdvs_hw.sensor.native.fused.fused_substep` (no gradient wanted)."""
    c_on, c_off = st.c_on, st.c_off
    if fused:
        target = Ls[k + 1] if s == S else torch.lerp(Ls[k], Ls[k + 1], s / S)
        inten = (CI[k + 1] if s == S else torch.lerp(CI[k], CI[k + 1], s / S)) if CI is not None else None
        lp_new, ref_next, n_on, n_off, d_b = fused_substep(target, inten, lp, ref, c_on, c_off, dt_sub, st.eps, config)
        if CI is not None:
            lp = target = lp_new
        return ComparatorOutput(target, lp, sur, ref, ref_next, n_on, n_off, d_b)
    target, lp, sur = _substep_target(Ls, CI, SU, k, s, S, lp, sur, dt_sub, config)
    leak = float(config.leak_rate_hz)
    if leak > 0:
        ref = ref - leak * c_on * dt_sub
    if config.surrogate == "relaxed":
        d_b = target - ref
        e_on = torch.relu(d_b) / c_on
        e_off = torch.relu(-d_b) / c_off
        return ComparatorOutput(target, lp, sur, ref, ref + e_on * c_on - e_off * c_off, e_on, e_off, d_b)
    n_on, n_off, ref_next, d_b = _Comparator.apply(target, ref, c_on, c_off, st.eps)
    return ComparatorOutput(target, lp, sur, ref, ref_next, n_on, n_off, d_b)


def _call(fn: Any, *args: Any) -> Any:
    """``fn(*args)`` (the in-process twin of :meth:`EventPipeline.emit`)."""
    return fn(*args)


class _SubstepNoise:
    """The shot noise of one stepping run's sub-steps: drawn and emitted on the pipeline's workers
    (events only), or drawn here, its counts added to the comparator's and its events emitted.

    Parameters
    ----------
    pipe : EventPipeline or None
        The run's pipeline, if any.
    st : PixelState
        Its shot-noise count and time streams are drawn from.
    config : SensorConfig
        ``shot_noise_rate_hz`` and ``shot_noise_draw`` are read.
    like : torch.Tensor
        A (B, H, W) frame: the shape, device and dtype of the counts.
    tsd : torch.Tensor
        (B, T) float64 frame times (s).
    want_counts, collect_events : bool
        Whether counts and events are made.
    """

    def __init__(
        self,
        pipe: Any,
        st: PixelState,
        config: SensorConfig,
        like: Any,
        tsd: Any,
        want_counts: bool,
        collect_events: bool,
    ) -> None:
        self.pipe, self.tsd, self.want_counts, self.collect_events = pipe, tsd, want_counts, collect_events
        self.shape = tuple(like.shape)
        self.dev, self.dtype = like.device, like.dtype
        self.shot = float(config.shot_noise_rate_hz)
        self.sparse = config.shot_noise_draw == "sparse"
        self.shot_g, self.time_g = st.shot_g, st.time_g

    def step(
        self, step_parts: list, e_on: Any, e_off: Any, k: int, s: int, S: int, dt_sub64: Any
    ) -> tuple[Any, Any, int]:
        """Sub-step ``s`` of ``S`` in interval ``k`` (``dt_sub64``: (B, 1, 1) float64 length, s):
        ``(e_on, e_off)`` with the noise counts added (if counts are wanted) and the noise events
        drawn here (0 when they are drawn on the workers); its events go to ``step_parts``."""
        B, H, W = self.shape
        pipe, tsd = self.pipe, self.tsd
        if pipe is not None and not self.want_counts:  # draws and events on the workers
            lam = (0.5 * self.shot) * dt_sub64.reshape(B)
            pipe.noise(
                shot_noise_pixels,
                noise_step,
                (B, H * W, lam, self.shot_g, self.sparse),
                (step_parts, (B, H, W), *_substep_times(tsd, k, s, S), dt_sub64, self.time_g),
            )
            return e_on, e_off, 0
        on_px, off_px = shot_noise_pixels(B, H * W, (0.5 * self.shot) * dt_sub64.reshape(B), self.shot_g, self.sparse)
        on_px, off_px = on_px.to(self.dev), off_px.to(self.dev)
        n_noise = len(on_px) + len(off_px)
        if self.want_counts:
            e_on, e_off = _with_noise_counts(e_on, e_off, on_px, off_px, (B, H, W), self.dtype)
        if self.collect_events:
            noise_args = (step_parts, on_px, off_px, (B, H, W), *_substep_times(tsd, k, s, S), dt_sub64, self.time_g)
            (pipe.emit if pipe is not None else _call)(noise_step, *noise_args)
        return e_on, e_off, n_noise


def _advance_steps(
    st: PixelState,
    Ls: Any,
    CI: Any,
    SU: Any,
    tsd: Any,
    config: SensorConfig,
    substeps: list[int],
    collect_events: bool,
    events: list,
    want_counts: bool,
    bar: Any,
    pipe: EventPipeline | None,
) -> list:
    """The stepping loop of :func:`advance_pixels` (same arguments and result); with ``pipe`` the event
    work is submitted to it (each interval's sort future appended to ``events``), by
    :func:`~fsdvs_hw.sensor.native.chunk_steps.advance_chunk` where :func:`~fsdvs_hw.sensor.native.chunk_steps.chunk_applies`."""
    if pipe is not None and chunk_applies(Ls[0], substeps, config, SU is not None, collect_events, want_counts):
        return advance_chunk(st, Ls, CI if config.has_photoreceptor else None, tsd, config, events, pipe, bar)
    B = Ls[0].shape[0]
    dt_ = Ls[0].dtype
    c_on, c_off = st.c_on, st.c_off
    relaxed = config.surrogate == "relaxed"
    has_lp = config.has_photoreceptor
    refr = float(config.refractory_s)
    shot = float(config.shot_noise_rate_hz)
    transient = SU is not None
    exact_times = collect_events or refr > 0
    fused = fused_substep_applies(Ls[0], config, transient)
    ref, lp, sur, sig_prev, last_t = st.ref, st.lp, st.sur, st.sig_prev, st.last_t
    noise = _SubstepNoise(pipe, st, config, Ls[0], tsd, want_counts, collect_events)
    noise_events, lost = st.noise_events, st.lost
    frames = []
    t_lo, t_hi = tsd.amin(0).tolist(), tsd.amax(0).tolist()  # each frame time over the batch
    for k in range(len(Ls) - 1):
        step_parts: list = []
        S = substeps[k]
        dt_int = tsd[:, k + 1] - tsd[:, k]  # (B,)
        dt_sub64 = (dt_int / S).view(B, 1, 1)
        dt_sub = dt_sub64.to(dt_)
        on_acc = off_acc = None
        for s in range(1, S + 1):
            ref_a = ref
            target, lp, sur, ref, ref_next, n_on, n_off, d_b = _compare(
                Ls, CI if has_lp else None, SU if transient else None, k, s, S, lp, sur, ref, st, dt_sub, config, fused
            )
            e_on, e_off = n_on, n_off
            if not relaxed:
                h_on, h_off = n_on.detach(), n_off.detach()
                lost_s = 0.0
                if exact_times:
                    with torch.no_grad():
                        t_a, t_b = _substep_times(tsd, k, s, S)
                        step = ComparatorStep(
                            h_on,
                            h_off,
                            sig_prev.detach(),
                            ref_a.detach(),
                            d_b,
                            c_on.detach(),
                            c_off.detach(),
                            t_a,
                            t_b,
                            dt_sub64,
                            last_t,
                            refr,
                        )
                        args = (step_parts, step, collect_events, refr > 0 and want_counts)
                        if pipe is not None:
                            pipe.emit(crossing_step, *args, crossing=True)
                        else:
                            lost_s, em_on, em_off = crossing_step(*args)
                            lost += lost_s
                    # refractory losses: emitted counts, gradient of the emitted share (a step that lost
                    # nothing emitted every crossing: the counts are n itself, share 1)
                    if refr > 0 and want_counts and lost_s > 0:
                        e_on = _refractory_surrogate(n_on, h_on, em_on)
                        e_off = _refractory_surrogate(n_off, h_off, em_off)
            ref = ref_next
            if shot > 0:
                e_on, e_off, n_noise = noise.step(step_parts, e_on, e_off, k, s, S, dt_sub64)
                noise_events += n_noise
            sig_prev = target
            if want_counts:
                on_acc = e_on if on_acc is None else on_acc + e_on
                off_acc = e_off if off_acc is None else off_acc + e_off
        frames += [on_acc, off_acc]
        if collect_events:
            events.append((pipe.sort if pipe is not None else sort_interval)(step_parts, t_lo[k], t_hi[k + 1]))
        if bar is not None:
            bar.update(1)
    st.ref, st.lp, st.sur, st.sig_prev, st.last_t = ref, lp, sur, sig_prev, last_t
    st.noise_events, st.lost = noise_events, lost
    return frames


def _run(
    signal: FilteredSignal,
    ts: Any,
    config: SensorConfig,
    substeps: list[int],
    generator: Any,
    collect_events: bool,
    thresholds: tuple[Any, Any] | None = None,
    phase: Any = None,
    bar: Any = None,
) -> tuple[Any, SimulationInfo, EventList | None]:
    """Step every pixel through time; return counts (B, T-1, 2, H, W), info and events.

    ``thresholds`` and ``phase`` (per-pixel maps) are drawn here unless given (region stepping
    passes the full-frame draws gathered to its pixels).
    """
    L = signal.log_signal
    B, T, H, W = L.shape
    transient = signal.surround is not None
    Ls = L.unbind(1)  # one unbind: its backward is one stack, not T full-size zero tensors
    CI = signal.cutoff_intensity.unbind(1) if config.has_photoreceptor else None
    SU = signal.surround.unbind(1) if transient else None
    st = initial_pixel_state(
        Ls[0], SU[0] if SU is not None else None, config, thresholds, phase, generator, collect_events
    )
    if (
        float(config.refractory_s) > 0
        and not config.has_photoreceptor
        and not transient
        and _refractory_never_binds(Ls, ts, st.c_on, st.c_off, config)
    ):
        config = config.replace(refractory_s=0.0)  # nothing can be lost: skip the refractory path
    events: list = []
    frames = advance_pixels(
        st, Ls, CI, SU, ts.to(dtype=torch.float64), config, substeps, collect_events, events, bar=bar
    )
    out = torch.stack(frames, dim=1).view(B, T - 1, 2, H, W)
    ev = None
    if collect_events:
        ev = EventList(*to_event_columns(events, H, W, B))
    info = SimulationInfo(
        signal.floor_fraction, tuple(substeps), st.noise_events, int(round(st.lost)), B * H * W * sum(substeps)
    )
    return out, info, ev


def config_from_plan(config: SensorConfig | None, plan: Any) -> SensorConfig:
    """The configuration to simulate with: the plan's (checked against ``config``) or ``config``."""
    if plan is not None:
        # checked by what it carries, not by importing plan.py (which imports this module)
        if not (
            isinstance(getattr(plan, "config", None), SensorConfig)
            and isinstance(getattr(plan, "base_config", None), SensorConfig)
        ):
            raise InputError(f"plan: must be a ModelPlan from plan_model(), got {type(plan).__name__}")
        if config is not None and config is not plan.base_config and config != plan.base_config:
            raise InputError("config and plan disagree: pass either config or plan (the plan carries its config)")
        config = plan.config
    config = SensorConfig() if config is None else config
    if not isinstance(config, SensorConfig):
        raise InputError(f"config: must be a SensorConfig, got {type(config).__name__}")
    return config


def resolve_inputs(
    video: Any, kernel: Any, timestamps_s: Any, config: SensorConfig | None, plan: Any
) -> tuple[Any, Any, Any, SensorConfig, list[int] | None, int]:
    """The checked inputs of a simulation: ``(video, kernel tensor, frame times, config, planned
    sub-steps or None, saturated pixel count)``, the configuration taken from ``plan`` if given."""
    config = config_from_plan(config, plan)
    video = prepare_video(video)
    ts = prepare_timestamps(timestamps_s, video, config)
    video, saturated = saturate(video)
    w = kernel_tensor(kernel, video)
    if plan is not None and len(plan.substeps) not in (0, video.shape[1] - 1):
        raise InputError(f"plan: made for {len(plan.substeps) + 1} frames, video has {video.shape[1]}")
    subs = list(plan.substeps) if plan is not None and plan.substeps else None
    return video, w, ts, config, subs, saturated


def _as_float(x: Any) -> float:
    return float(x.detach()) if isinstance(x, torch.Tensor) else float(x)


def _simulate(
    video: Any,
    kernel: Any,
    timestamps_s: Any,
    config: SensorConfig | None,
    plan: Any,
    generator: Any,
    collect_events: bool,
    bar: Any = None,
) -> tuple[Any, SimulationInfo, EventList | None]:
    check_instance("generator", generator, torch.Generator, "a torch.Generator", nullable=True)
    video, w, ts, config, subs, saturated = resolve_inputs(video, kernel, timestamps_s, config, plan)
    if config.conventions != "native":  # another simulator's rules: event lists only
        if not collect_events or plan is not None or generator is not None:
            check_native(config, "event_frames" if not collect_events else "plan/generator")
        columns, n_noise = frame_grid_events(video, w, ts, config)
        ev = EventList(*(torch.from_numpy(c) for c in columns))
        return None, SimulationInfo(0.0, (1,) * (video.shape[1] - 1), n_noise, 0, saturated=saturated), ev
    out = _simulate_resolved(video, w, ts, config, subs, plan, generator, collect_events, bar)
    out[1].saturated = saturated
    return out


def _simulate_resolved(
    video: Any,
    w: Any,
    ts: Any,
    config: SensorConfig,
    subs: list[int] | None,
    plan: Any,
    generator: Any,
    collect_events: bool,
    bar: Any,
) -> tuple[Any, SimulationInfo, EventList | None]:
    signal = filtered_log_signal(video, w, config)
    step = None  # log-signal change allowed per sub-step (adaptive stepping)
    if subs is None:
        step = _adaptive_step(config, signal.surround is not None)
        subs = substeps_per_interval(signal.log_signal, config, signal.surround is not None)
    elif plan is not None:
        step = plan.step_log_units
    if step is not None and config.adaptive_region_px > 0 and max(subs) > 1:
        return _run_regions(signal, ts, config, subs, step, generator, collect_events, bar)
    return _run(signal, ts, config, subs, generator, collect_events, bar=bar)


def _adaptive_step(config: SensorConfig, transient: bool) -> float | None:
    """Log-signal change allowed per adaptive sub-step, or None for no sub-steps.

    Sub-steps only refine a temporal filter (photoreceptor low-pass, surround-mesh transient):
    without one the comparator input is linear between frames and one step per interval is exact,
    so ``adaptive_fraction`` then adds none (and ``substeps``, which it replaces, is ignored).
    """
    if config.adaptive_fraction is None or not (config.has_photoreceptor or transient):
        return None
    return config.adaptive_fraction * _low_threshold(config)


def substeps_per_interval(log_signal: Any, config: SensorConfig, transient: bool) -> list[int]:
    """Sub-steps per interval of ``log_signal``: (B, T, H, W), or a list of its T (B, H, W) frames
    (stacked only when the adaptive rule reads them)."""
    step = _adaptive_step(config, transient)
    T = len(log_signal) if isinstance(log_signal, list) else log_signal.shape[1]
    if step is None:
        return [1 if config.adaptive_fraction is not None else config.substeps] * (T - 1)
    if isinstance(log_signal, list):
        log_signal = torch.stack(log_signal, dim=1)
    return _choose_substeps(log_signal, step, config)


def _refractory_never_binds(Ls: Any, ts: Any, c_on: Any, c_off: Any, config: SensorConfig) -> bool:
    """True if no threshold crossing can fall inside a refractory period anywhere in the clip.

    Valid without a temporal filter, where the comparator input is linear between frames: its
    slope is at most ``v = max |ΔL| / Δt + leak_rate_hz · C_on`` (the leak drifts the reference
    linearly), and two successive crossings of one pixel are at least one threshold apart in
    ``L - r`` (an ON after an ON needs ``C_on``, an OFF after it ``C_off``), so at least
    ``C_min / v`` apart in time. If that exceeds the refractory period (with a 0.1 % margin for
    rounding) the refractory path would emit every crossing: the clip runs without it, with
    identical counts and events and none lost.
    """
    refr = float(config.refractory_s)
    with torch.no_grad():
        dt = (ts[:, 1:] - ts[:, :-1]).to(torch.float64)  # (B, T-1)
        vmax = 0.0
        for k in range(len(Ls) - 1):
            jump = (Ls[k + 1] - Ls[k]).abs().flatten(1).amax(dim=1).to(torch.float64)  # (B,)
            vmax = max(vmax, float((jump / dt[:, k]).max()))
        c_max = float(torch.as_tensor(c_on).detach().max())
        vmax += float(config.leak_rate_hz) * c_max
        c_min = min(float(torch.as_tensor(c_on).detach().min()), float(torch.as_tensor(c_off).detach().min()))
    return vmax * refr < 0.999 * c_min


def _low_threshold(config: SensorConfig) -> float:
    """Smallest likely per-pixel threshold: nominal minus 3 σ (at least the clip floor)."""
    c = min(_as_float(config.threshold_on), _as_float(config.threshold_off))
    return max(c - 3 * config.threshold_sigma, config.threshold_min_fraction * c)


def _reference_phase(config: SensorConfig, H: int, W: int, like: Any) -> Any:
    g = effect_generator(config.seed, "leak_phase", like.device)
    return torch.rand((H, W), generator=g, device=g.device, dtype=torch.float64).to(like.device, like.dtype)


def _run_regions(
    signal: FilteredSignal,
    ts: Any,
    config: SensorConfig,
    subs: list[int],
    step: float,
    generator: Any,
    collect_events: bool,
    bar: Any = None,
) -> tuple[Any, SimulationInfo, EventList | None]:
    """Adaptive stepping per square region: each region gets the sub-steps its own largest log
    change needs (rounded up to a power of two, at most the global count), so still regions are
    not stepped at the rate of the fastest one. Pixels are independent after the spatial filter,
    so regions with the same count are gathered and run together, then scattered back. The
    per-pixel thresholds and reference phases are the full-frame draws; shot-noise draws differ
    from a full-frame run (same statistics)."""
    L = signal.log_signal
    B, T, H, W = L.shape
    R = config.adaptive_region_px
    with torch.no_grad():
        jumps = (L[:, 1:] - L[:, :-1]).abs().amax(dim=(0, 1))  # (H, W)
        tiles = torch.nn.functional.max_pool2d(jumps[None, None].float(), R, R, ceil_mode=True)[0, 0]
        need = torch.ceil(tiles.double() / step).clamp(min=1, max=max(subs))
        level = torch.ceil(torch.log2(need)).long()  # power-of-two classes
        level_px = level.repeat_interleave(R, 0).repeat_interleave(R, 1)[:H, :W].reshape(-1)
    c_on, c_off = threshold_maps(config, (H, W), L, generator=generator)
    phase = _reference_phase(config, H, W, L) if config.random_reference_phase else None
    out = torch.zeros((B, T - 1, 2, H * W), dtype=L.dtype, device=L.device)
    infos, events = [], []
    levels = level_px.unique().tolist()
    if bar is not None:  # each group of regions steps through every frame interval
        bar.total = (T - 1) * len(levels)
        bar.refresh()
    for lv in levels:
        idx = torch.nonzero(level_px == lv)[:, 0].to(L.device)

        def take(x: Any) -> Any:
            return None if x is None else x.reshape(*x.shape[:-2], H * W).index_select(-1, idx).unsqueeze(-2)  # noqa: B023 - called in this iteration

        part = FilteredSignal(take(L), take(signal.surround), take(signal.cutoff_intensity), signal.floor_fraction)
        thr = tuple(take(c) if c.ndim else c for c in (c_on, c_off))
        sub_part = [min(s, 2**lv) for s in subs]
        f, info, ev = _run(part, ts, config, sub_part, generator, collect_events, thr, take(phase), bar)
        out = out.index_copy(-1, idx, f.reshape(B, T - 1, 2, -1))
        infos.append(info)
        if ev is not None and len(ev):
            flat = idx.cpu()[ev.x]
            events.append(EventList(ev.b, flat % W, flat // W, ev.t, ev.p))
    info = SimulationInfo(
        signal.floor_fraction,
        tuple(subs),
        sum(i.noise_events for i in infos),
        sum(i.refractory_lost for i in infos),
        sum(i.pixel_steps for i in infos),
    )
    ev_all = None
    if collect_events:
        ev_all = _merge_events(events)
    return out.view(B, T - 1, 2, H, W), info, ev_all


def _merge_events(parts: list[EventList]) -> EventList:
    if not parts:
        z = torch.zeros(0, dtype=torch.int64)
        return EventList(z, z.clone(), z.clone(), torch.zeros(0, dtype=torch.float64), torch.zeros(0, dtype=torch.int8))
    b, x, y, t, p = (torch.cat(c) for c in zip(*[(e.b, e.x, e.y, e.t, e.p) for e in parts]))
    # by batch element, then time (two stable sorts: exact, no float key mixing b and t)
    order = torch.argsort(t, stable=True)
    order = order[torch.argsort(b[order], stable=True)]
    return EventList(b[order], x[order], y[order], t[order], p[order])


# ---------------------------------------------------------------------------- public API
def event_frames(
    video: Any,
    kernel: Any = None,
    *,
    timestamps_s: Any = None,
    config: SensorConfig | None = None,
    plan: Any = None,
    generator: Any = None,
    return_info: bool = False,
) -> Any:
    """Differentiable event frames: ON/OFF event counts per frame interval.

    Parameters
    ----------
    video : torch.Tensor or numpy.ndarray, shape (B, T, H, W)
        Linear intensity (>= 0, video units; full scale 1.0 for a normalised clip).
        Differentiable. Intensities above
        :data:`~fsdvs_hw.sensor.simulation.config.SATURATION_INTENSITY` (1e20) saturate: they are clipped
        to it, as a photodiode saturates, and counted in ``SimulationInfo.saturated``, so any
        finite video gives finite event frames. Videos whose event frames would exceed the
        allocation limit (:mod:`fsdvs_hw.limits`) are refused from their shape before any work.
    kernel : Kernel, torch.Tensor (k, k) or None
        Spatial kernel (k odd), applied at ``config.placement``; ``None`` = no filter (plain DVS).
        Differentiable when a tensor with ``requires_grad``; must be on the video's device.
    timestamps_s : array_like, shape (T,) or (B, T), optional
        Frame times in seconds, strictly increasing; default ``arange(T) / config.frame_rate_hz``.
    config : SensorConfig, optional
        Sensor parameters (default ``SensorConfig()``: v2e-like noisy sensor with one step per
        frame interval; pass ``adaptive_fraction`` or a ``plan`` for an accurate photoreceptor).
        Use ``SensorConfig.ideal()`` for the noiseless training sensor.
    plan : ModelPlan, optional
        A plan from :func:`plan_model`; the simulator then runs the plan's effective config and
        sub-steps (pass either ``config`` or ``plan``).
    generator : torch.Generator, optional
        Overrides the threshold-mismatch stream (other streams derive from ``config.seed``).
    return_info : bool
        Also return a :class:`SimulationInfo` (floor fraction, sub-steps, noise events).

    Returns
    -------
    torch.Tensor, shape (B, T-1, 2, H, W)
        Channel 0 = ON counts, 1 = OFF counts (both >= 0) in each interval ``[t_k, t_k+1)``;
        17 frames → 16 bins as in the FS-DVS paper. Same dtype/device as the video.

    Raises
    ------
    InputError, KernelError
        Wrong type, rank or dtype (strings, objects, complex values), negative or non-finite
        intensities, non-increasing timestamps, even or invalid kernel, kernel/timestamps on
        another device, a generator that is not a ``torch.Generator``, a non-boolean
        ``return_info``, a video too large for the allocation limit.

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw import SensorConfig, event_frames
    >>> video = torch.ones(1, 3, 4, 4)
    >>> video[:, 1:, :, 2:] = 2.0                 # the right half doubles in brightness after frame 0
    >>> f = event_frames(video, config=SensorConfig.ideal())
    >>> f.shape                                   # (B, T-1, ON/OFF, H, W)
    torch.Size([1, 2, 2, 4, 4])
    >>> f[0, 0, 0, 0].tolist()                    # ON counts of a row: floor(log 2 / 0.2) = 3
    [0.0, 0.0, 3.0, 3.0]
    """
    return_info = check_bool("return_info", return_info)
    frames, info, _ = _simulate(video, kernel, timestamps_s, config, plan, generator, False)
    return (frames, info) if return_info else frames


def event_list(
    video: Any,
    kernel: Any = None,
    *,
    timestamps_s: Any = None,
    config: SensorConfig | None = None,
    plan: Any = None,
    generator: Any = None,
    progress: bool | None = None,
) -> EventList:
    """Exact, non-differentiable events (b, x, y, t, p) with per-event interpolated timestamps.

    Same model and arguments as :func:`event_frames` (the "realistic track"); counting the
    returned events per frame interval reproduces ``event_frames`` exactly. Each crossing of a
    threshold level gets its own time, linearly interpolated within its (sub-)step.
    ``progress``: a bar over the frame intervals on stderr (True, False, or None: when stderr is a
    terminal; :mod:`fsdvs_hw.progress`).

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw import SensorConfig, event_list
    >>> video = torch.ones(1, 3, 4, 4)
    >>> video[:, 1:, :, 2:] = 2.0
    >>> ev = event_list(video, config=SensorConfig.ideal(), timestamps_s=[0.0, 0.01, 0.02])
    >>> len(ev), int(ev.p.min()), int(ev.p.max())  # 8 pixels × 3 ON events
    (24, 1, 1)
    """
    import torch

    from ...progress import progress_bar

    progress = check_bool("progress", progress, nullable=True)
    n_intervals = max(int(getattr(video, "shape", (0, 1))[1]) - 1, 0) if getattr(video, "ndim", 0) >= 2 else None
    with (
        torch.no_grad(),
        progress_bar(total=n_intervals, desc="event_list", unit="frame", progress=progress, leave=False) as bar,
    ):
        _, _, ev = _simulate(video, kernel, timestamps_s, config, plan, generator, True, bar)
    assert ev is not None  # collect_events=True
    return ev


class EventSimulator(torch.nn.Module):
    """nn.Module wrapper of :func:`event_frames` (kernel as a Parameter or a buffer).

    Parameters
    ----------
    config : SensorConfig, optional
        Sensor parameters (default ``SensorConfig.ideal()``, the training sensor).
    kernel : Kernel, tensor or array (k, k), optional
        Initial kernel; ``None`` = 1×1 delta (plain DVS).
    learnable : bool
        Register the kernel as a ``Parameter`` (trainable) instead of a buffer.

    Notes
    -----
    ``forward(video, kernel=None, timestamps_s=None)`` returns (B, T-1, 2, H, W) event frames;
    a ``kernel`` given at call time replaces the stored one for that call (e.g. a realised
    kernel scored with the same module).

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw import EventSimulator, SensorConfig, reference_kernel
    >>> sim = EventSimulator(SensorConfig.ideal(), kernel=reference_kernel("delta", 3), learnable=True)
    >>> out = sim(torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(0)) + 0.5)
    >>> out.shape, sim.kernel.requires_grad
    (torch.Size([1, 2, 2, 8, 8]), True)
    """

    def __init__(self, config: SensorConfig | None = None, kernel: Any = None, learnable: bool = False) -> None:
        super().__init__()
        self.config = SensorConfig.ideal() if config is None else config
        if not isinstance(self.config, SensorConfig):
            raise InputError(f"config: must be a SensorConfig, got {type(self.config).__name__}")
        like = torch.zeros((), dtype=torch.float32)
        if isinstance(kernel, torch.Tensor):
            like = torch.zeros(
                (), dtype=kernel.dtype if kernel.is_floating_point() else torch.float32, device=kernel.device
            )
        w = kernel_tensor(kernel, like).detach().clone()
        if learnable:
            self.kernel = torch.nn.Parameter(w)
        else:
            self.register_buffer("kernel", w)

    def forward(self, video: Any, kernel: Any = None, timestamps_s: Any = None) -> Any:
        k = self.kernel if kernel is None else kernel
        return event_frames(video, k, timestamps_s=timestamps_s, config=self.config)

    def extra_repr(self) -> str:
        return f"kernel={tuple(self.kernel.shape)}, placement={self.config.placement}"
