"""Model only what the scene requires: a plan that names every effect, included or skipped, with
the numbers behind the decision.

:func:`plan_model` measures a clip (or takes :class:`SceneStats`) and compares, for each effect,
the size of its influence with ``tolerance``:

=====================  ==========================================================================
effect                 criterion (included when the value exceeds the limit)
=====================  ==========================================================================
photoreceptor          worst low-pass lag ``τ(I)·|dL/dt|`` over pixels and intervals, in units of
                       the threshold C, versus ``tolerance`` (τ = 1 / 2π f_c(I); dim pixels are slow)
sub-steps              only needed when a temporal filter (photoreceptor, surround transient) runs:
                       then ESIM-style, per interval, ``ceil(max|ΔL| / (tolerance·C))``; otherwise
                       1, because crossings of a linearly interpolated signal are closed-form
threshold mismatch     event-frame error of leaving it out, measured by a probe run (ideal pixel with
                       and without the mismatch on a central crop), versus ``tolerance``
refractory period      highest crossing rate × refractory time versus 1 (below 1 no crossing is
                       ever lost: exact)
leak events            the larger of: expected leak events ``rate · pixels · duration`` / expected
                       signal events ``Σ|ΔL| / C``, and twice the reference drift ``rate · duration``
                       (in thresholds; it shifts signal events in time), versus ``tolerance``
shot noise             the same with the shot-noise rate
surround transient     mesh lag ``τ_s · |dS/dt| · s`` in units of C versus ``tolerance``
frame upsampling       scene motion (99th-percentile DIS optical flow, px per frame) versus
                       :data:`~fsdvs_hw.sensor.simulation.upsampling.UPSAMPLE_MOTION_PX` (1.5 px), and the largest
                       per-frame log change versus C: both above → event times need flow frames
                       between the video's (``ModelPlan.upsample_rate_hz``; measured in
                       ``fsdvs-hw bench upsampling``, docs/upsampling.md)
=====================  ==========================================================================

The simulator runs from the plan (``event_frames(video, kernel, plan=plan)``), and the tests check
that the planned model stays within ``tolerance`` of the full model in event count and event-frame
error while running faster where it skips.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from ...errors import InputError
from .config import SensorConfig

__all__ = ["ModelPlan", "PlanDecision", "SceneStats", "plan_model"]


@dataclass(frozen=True)
class SceneStats:
    """What the planner needs to know about a clip (log units, seconds, video intensity units).

    Attributes
    ----------
    n_pixels : int
        Pixels per frame times batch size.
    duration_s : float
        Clip duration (first to last frame).
    interval_max_abs_change : tuple of float
        Largest ``|ΔL|`` of any pixel in each frame interval (log units); its length is T-1.
    max_log_rate_per_s : float
        Largest ``|dL/dt|`` of any pixel (log units per second).
    total_abs_change : float
        ``Σ |ΔL|`` over all pixels and intervals (log units); ``/ C`` estimates the signal events.
    max_lowpass_lag : float
        Worst photoreceptor lag ``|dL/dt| / (2π f_c(I))`` (log units) with the config's cut-off.
    max_surround_lag : float
        Worst surround-mesh lag ``s · τ_s · |dS/dt|`` (log units).
    min_intensity, max_intensity : float
        Range of the comparator's photocurrent (video units).
    floor_fraction : float
        Fraction of pixel-frames at the positivity floor.
    mismatch_frame_error : float or None
        Measured event-frame L1 error (relative to the event count) of leaving the threshold
        mismatch out: a probe run of the ideal pixel with and without the config's mismatch on a
        central crop of at most 64×64 pixels. ``None`` when only statistics are given (the plan then
        uses the upper estimate ``4 σ / C``).
    motion_px_per_frame : float or None
        Scene motion: 99th percentile of the DIS optical-flow magnitude between neighbouring frames
        (first clip of the batch, at most 8 pairs; :func:`fsdvs_hw.sensor.simulation.upsampling.motion_px_per_frame`),
        pixels per frame interval. ``None`` when not measured (frames under 16 px, or statistics given).
    """

    n_pixels: int
    duration_s: float
    interval_max_abs_change: tuple[float, ...]
    max_log_rate_per_s: float
    total_abs_change: float
    max_lowpass_lag: float = 0.0
    max_surround_lag: float = 0.0
    min_intensity: float = float("nan")
    max_intensity: float = float("nan")
    floor_fraction: float = 0.0
    mismatch_frame_error: float | None = None
    motion_px_per_frame: float | None = None

    @classmethod
    def from_video(
        cls, video: Any, kernel: Any = None, *, timestamps_s: Any = None, config: SensorConfig | None = None
    ) -> SceneStats:
        """Measure a (B, T, H, W) linear-intensity clip through the kernel and the config's pixel."""
        import torch

        from .events import prepare_timestamps, prepare_video
        from .filtering import filtered_log_signal, kernel_tensor

        config = SensorConfig() if config is None else config
        with torch.no_grad():
            v = prepare_video(video)
            ts = prepare_timestamps(timestamps_s, v, config)
            w = kernel_tensor(kernel.detach() if isinstance(kernel, torch.Tensor) else kernel, v)
            sig = filtered_log_signal(v, w, config)
            L = sig.log_signal.double()
            dL = (L[:, 1:] - L[:, :-1]).abs()
            dt = (ts[:, 1:] - ts[:, :-1]).view(ts.shape[0], -1, 1, 1)
            rate = dL / dt
            inten = torch.minimum(sig.cutoff_intensity[:, 1:], sig.cutoff_intensity[:, :-1]).double()
            lp_lag = 0.0
            if config.has_photoreceptor:
                fc = config.cutoff_hz * torch.clamp((inten + config.dark_intensity) / config.full_scale_intensity, 0, 1)
                lp_lag = float((rate / (2 * math.pi * fc)).max())
            s_lag = 0.0
            if sig.surround is not None:
                dS = (sig.surround[:, 1:] - sig.surround[:, :-1]).abs().double() / dt
                s_lag = float(config.surround_weight * config.surround_tau_s * dS.max())
            mm_err = _mismatch_probe(v, w, ts, config) if config.threshold_sigma > 0 else 0.0
            from .upsampling import motion_px_per_frame

            motion = motion_px_per_frame(v[0].double().cpu().numpy()) if v.shape[1] >= 2 else None
            return cls(
                n_pixels=int(v.shape[0] * v.shape[2] * v.shape[3]),
                duration_s=float((ts[:, -1] - ts[:, 0]).max()),
                interval_max_abs_change=tuple(float(x) for x in dL.amax(dim=(0, 2, 3))),
                max_log_rate_per_s=float(rate.max()),
                total_abs_change=float(dL.sum()),
                max_lowpass_lag=lp_lag,
                max_surround_lag=s_lag,
                min_intensity=float(sig.cutoff_intensity.min()),
                max_intensity=float(sig.cutoff_intensity.max()),
                floor_fraction=sig.floor_fraction,
                mismatch_frame_error=mm_err,
                motion_px_per_frame=motion,
            )


def _mismatch_probe(video: Any, kernel: Any, ts: Any, config: SensorConfig, crop: int = 64) -> float:
    """Frame L1 error of dropping the threshold mismatch, measured on a central crop."""
    from .events import event_frames

    H, W = video.shape[-2:]
    y0, x0 = max((H - crop) // 2, 0), max((W - crop) // 2, 0)
    v = video[:, :, y0 : y0 + crop, x0 : x0 + crop]
    base = config.replace(
        cutoff_hz=0.0,
        refractory_s=0.0,
        leak_rate_hz=0.0,
        shot_noise_rate_hz=0.0,
        substeps=1,
        adaptive_fraction=None,
        surround_tau_s=0.0,
        random_reference_phase=False,
    )
    with_mm = event_frames(v, kernel, timestamps_s=ts, config=base)
    without = event_frames(v, kernel, timestamps_s=ts, config=base.replace(threshold_sigma=0.0))
    total = float(with_mm.sum())
    return float((with_mm - without).abs().sum()) / total if total > 0 else 0.0


@dataclass(frozen=True)
class PlanDecision:
    """One effect: included or skipped, the measured value, the limit it was compared with, why."""

    name: str
    included: bool
    value: float
    limit: float
    reason: str


@dataclass(frozen=True)
class ModelPlan:
    """The effects a scene requires, and the effective config the simulator runs.

    Attributes
    ----------
    base_config : SensorConfig
        The full sensor model asked for.
    config : SensorConfig
        ``base_config`` with skipped effects switched off.
    substeps : tuple of int
        Sub-steps for each frame interval.
    decisions : tuple of PlanDecision
    tolerance : float
    stats : SceneStats
    step_log_units : float or None
        Largest log-signal change per sub-step when a temporal filter runs (``tolerance`` × the
        lowest likely threshold); with ``config.adaptive_region_px`` the simulator refines the
        sub-steps per region with it. ``None`` when one step per interval is exact.
    upsample_rate_hz : float or None
        When the "frame upsampling" decision is included: the frame rate to upsample to with
        :func:`~fsdvs_hw.sensor.upsample_frames` (``mode="flow"``; ``simulate --upsample flow
        --upsample-rate``), the clip's rate times ``ceil(motion / 1 px)`` (about 1 px per new
        frame). ``None``: the video's frames suffice. The plan does not resample the clip itself.
    """

    base_config: SensorConfig
    config: SensorConfig
    substeps: tuple[int, ...]
    decisions: tuple[PlanDecision, ...]
    tolerance: float
    stats: SceneStats = field(repr=False)
    step_log_units: float | None = None
    upsample_rate_hz: float | None = None

    def decision(self, name: str) -> PlanDecision:
        """The decision for effect ``name``."""
        for d in self.decisions:
            if d.name == name:
                return d
        raise InputError(f"plan has no effect {name!r}; effects: {', '.join(d.name for d in self.decisions)}")

    @property
    def skipped(self) -> tuple[str, ...]:
        """Names of the effects left out."""
        return tuple(d.name for d in self.decisions if not d.included)

    def to_dict(self) -> dict[str, Any]:
        return {
            "tolerance": self.tolerance,
            "substeps": list(self.substeps),
            "upsample_rate_hz": self.upsample_rate_hz,
            "decisions": [d.__dict__ for d in self.decisions],
            "config": self.config.to_dict(),
        }

    def __str__(self) -> str:
        lines = [
            f"Model plan (tolerance {self.tolerance:g}; sub-steps per interval: {_summarise(self.substeps)})",
            f"{'effect':<20} {'':8} {'value':>10} {'limit':>10}  reason",
        ]
        for d in self.decisions:
            lines.append(
                f"{d.name:<20} {'INCLUDED' if d.included else 'skipped':8} {d.value:10.3g} {d.limit:10.3g}  {d.reason}"
            )
        return "\n".join(lines)


def _summarise(subs: tuple[int, ...]) -> str:
    if not subs:
        return "-"
    if min(subs) == max(subs):
        return f"{subs[0]} each"
    return f"{min(subs)}..{max(subs)} (total {sum(subs)})"


def _plan_arguments(tolerance: Any, config: SensorConfig | None) -> tuple[float, SensorConfig]:
    """:func:`plan_model`'s tolerance as a float in (0, 1) and its config (default ``SensorConfig()``)."""
    try:
        tol = float(tolerance)
    except (TypeError, ValueError):
        raise InputError(f"tolerance: must be a number in (0, 1), got {tolerance!r}") from None
    if not 0 < tol < 1:
        raise InputError(f"tolerance: must be in (0, 1), got {tol!r}")
    config = SensorConfig() if config is None else config
    if not isinstance(config, SensorConfig):
        raise InputError(f"config: must be a SensorConfig, got {type(config).__name__}")
    return tol, config


def _temporal_filter_decisions(
    st: SceneStats, config: SensorConfig, tol: float, c_nom: float, changes: dict[str, Any]
) -> list[PlanDecision]:
    """The photoreceptor low-pass and surround-transient decisions; ``changes`` receives the
    config fields that switch off a filter the scene does not need (``c_nom``: nominal threshold,
    log units)."""
    decisions: list[PlanDecision] = []
    if not config.has_photoreceptor:
        decisions.append(PlanDecision("photoreceptor", False, 0.0, tol, "disabled in config (cutoff_hz = 0 or inf)"))
    else:
        lag = st.max_lowpass_lag / c_nom
        inc = lag > tol
        decisions.append(
            PlanDecision(
                "photoreceptor",
                inc,
                lag,
                tol,
                f"worst low-pass lag {st.max_lowpass_lag:.3g} log units = {lag:.3g} C "
                f"(intensity {st.min_intensity:.3g}..{st.max_intensity:.3g}, cut-off {config.cutoff_hz:g} Hz at full scale)"
                + (" > tolerance" if inc else " <= tolerance"),
            )
        )
        if not inc:
            changes["cutoff_hz"] = 0.0
    if (
        config.placement != "post_log"
        or config.surround_tau_s <= 0
        or config.surround_weight <= 0
        or config.surround_lambda_px <= 0
    ):
        decisions.append(
            PlanDecision("surround transient", False, 0.0, tol, "no surround mesh with a time constant in config")
        )
    else:
        lag = st.max_surround_lag / c_nom
        inc = lag > tol
        decisions.append(
            PlanDecision(
                "surround transient",
                inc,
                lag,
                tol,
                f"mesh lag {st.max_surround_lag:.3g} log units = {lag:.3g} C"
                f" (tau {config.surround_tau_s:g} s)" + (" > tolerance" if inc else " <= tolerance"),
            )
        )
        if not inc:
            changes["surround_tau_s"] = 0.0
    return decisions


def _substep_decision(
    st: SceneStats, config: SensorConfig, tol: float, c_low: float, temporal: list[str]
) -> tuple[tuple[int, ...], PlanDecision]:
    """Sub-steps per frame interval and their decision: where a temporal filter runs
    (``temporal``: their names), ``ceil(max|ΔL| / (tol · c_low))`` per interval (``c_low``: the
    lowest likely threshold, log units), else one."""
    if temporal:
        subs = tuple(
            int(min(max(math.ceil(x / (tol * c_low)), 1), config.max_substeps)) for x in st.interval_max_abs_change
        )
        return subs, PlanDecision(
            "sub-steps",
            True,
            float(max(subs)),
            float(config.max_substeps),
            f"{' and '.join(temporal)} filter(s) run: per interval ceil(max|ΔL| / ({tol:g} C)), "
            f"max |ΔL| {max(st.interval_max_abs_change):.3g} log units -> {_summarise(subs)}",
        )
    subs = tuple(1 for _ in st.interval_max_abs_change)
    return subs, PlanDecision(
        "sub-steps",
        False,
        1.0,
        float(config.max_substeps),
        "no temporal filter: crossings of the linearly interpolated signal are "
        "exact in closed form, 1 step per interval",
    )


def _mismatch_decision(
    st: SceneStats, config: SensorConfig, tol: float, c_nom: float, changes: dict[str, Any]
) -> PlanDecision:
    """The threshold-mismatch decision: the measured (or estimated) frame error without it."""
    ratio = config.threshold_sigma / c_nom
    if st.mismatch_frame_error is not None:
        value = st.mismatch_frame_error
        how = f"measured frame error without it {value:.3g} (probe on a <= 64x64 crop; sigma/C = {ratio:.3g})"
    else:
        value = 4 * ratio
        how = f"estimated frame error without it 4 sigma/C = {value:.3g} (no video to probe)"
    inc = value > tol
    if not inc:
        changes["threshold_sigma"] = 0.0
    return PlanDecision("threshold mismatch", inc, value, tol, how + (" > tolerance" if inc else " <= tolerance"))


def _refractory_decision(st: SceneStats, config: SensorConfig, c_low: float, changes: dict[str, Any]) -> PlanDecision:
    """The refractory decision: whether two crossings can ever fall within one refractory period."""
    per_ref = st.max_log_rate_per_s / c_low * config.refractory_s
    inc = per_ref >= 1.0
    if not inc:
        changes["refractory_s"] = 0.0
    return PlanDecision(
        "refractory",
        inc,
        per_ref,
        1.0,
        f"max crossing rate {st.max_log_rate_per_s / c_low:.3g} /s x refractory {config.refractory_s:g} s = {per_ref:.3g}"
        + (" >= 1: crossings can be lost" if inc else " < 1: no crossing is ever lost"),
    )


def _noise_decisions(
    st: SceneStats, config: SensorConfig, tol: float, signal_events: float, changes: dict[str, Any]
) -> list[PlanDecision]:
    """The leak-event and shot-noise decisions: their expected events against the scene's."""
    decisions = []
    for name, key in (("leak events", "leak_rate_hz"), ("shot noise", "shot_noise_rate_hz")):
        rate = float(getattr(config, key))
        expected = rate * st.n_pixels * st.duration_s
        ratio = expected / max(signal_events, 1.0)
        text = (
            f"expected {expected:.3g} events ({rate:g} Hz x {st.n_pixels} px x {st.duration_s:.3g} s) vs "
            f"{signal_events:.3g} signal events: ratio {ratio:.3g}"
        )
        value = ratio
        if key == "leak_rate_hz":
            # the leak also drifts every reference by rate x duration thresholds, shifting signal
            # events in time; in event-frame L1 each shifted event counts twice
            drift = rate * st.duration_s
            value = max(ratio, 2 * drift)
            text += f"; reference drift {drift:.3g} C over the clip (frame error ~ {2 * drift:.3g})"
        inc = value > tol
        decisions.append(PlanDecision(name, inc, value, tol, text + (" > tolerance" if inc else " <= tolerance")))
        if not inc:
            changes[key] = 0.0
    return decisions


def plan_model(
    video_or_stats: Any,
    tolerance: float = 0.05,
    *,
    config: SensorConfig | None = None,
    kernel: Any = None,
    timestamps_s: Any = None,
) -> ModelPlan:
    """Decide which effects a scene requires and at what time resolution.

    Parameters
    ----------
    video_or_stats : (B, T, H, W) tensor/array or SceneStats
        The clip to simulate (linear intensity), or its measured statistics.
    tolerance : float
        Allowed relative error (fraction of a threshold, or of the signal event count), in (0, 1).
    config : SensorConfig, optional
        The full model (default ``SensorConfig()``); skipped effects are switched off in the
        plan's effective config.
    kernel, timestamps_s
        As for :func:`event_frames` (used to measure a video).

    Returns
    -------
    ModelPlan
        Printable (``print(plan)``): every effect with its value, limit and reason.

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw import plan_model
    >>> video = torch.rand(1, 5, 16, 16, generator=torch.Generator().manual_seed(0)) + 0.5
    >>> plan = plan_model(video, tolerance=0.05)
    >>> plan.decision("refractory").included, plan.decision("photoreceptor").included
    (False, True)
    """
    tol, config = _plan_arguments(tolerance, config)
    if isinstance(video_or_stats, SceneStats):
        st = video_or_stats
    else:
        st = SceneStats.from_video(video_or_stats, kernel, timestamps_s=timestamps_s, config=config)
    c_on, c_off = (
        float(x.detach()) if hasattr(x, "detach") else float(x) for x in (config.threshold_on, config.threshold_off)
    )
    c_nom = min(c_on, c_off)
    c_low = max(c_nom - 3 * config.threshold_sigma, config.threshold_min_fraction * c_nom)
    signal_events = st.total_abs_change / c_nom
    changes: dict[str, Any] = {}
    decisions = _temporal_filter_decisions(st, config, tol, c_nom, changes)
    temporal = [d.name for d in decisions if d.included]
    subs, substeps = _substep_decision(st, config, tol, c_low, temporal)
    decisions.append(substeps)
    decisions.append(_mismatch_decision(st, config, tol, c_nom, changes))
    decisions.append(_refractory_decision(st, config, c_low, changes))
    decisions.extend(_noise_decisions(st, config, tol, signal_events, changes))
    decisions.append(
        PlanDecision(
            "positivity floor",
            True,
            st.floor_fraction,
            0.0,
            f"{config.placement}/{config.positivity}: {100 * st.floor_fraction:.3g} % of pixel-frames at the floor "
            "(always modelled; reported)",
        )
    )
    upsample = _upsampling_decision(st, c_nom)
    decisions.append(upsample[0])
    eff = config.replace(adaptive_fraction=None, **changes)
    return ModelPlan(config, eff, subs, tuple(decisions), tol, st, (tol * c_low) if temporal else None, upsample[1])


def _upsampling_decision(st: SceneStats, c_nom: float) -> tuple[PlanDecision, float | None]:
    """Frame upsampling: needed when the scene moves more than UPSAMPLE_MOTION_PX per frame and
    some pixel's log intensity changes by more than a threshold in a frame."""
    from .upsampling import UPSAMPLE_MOTION_PX

    motion = st.motion_px_per_frame
    if motion is None:
        return PlanDecision(
            "frame upsampling",
            False,
            0.0,
            UPSAMPLE_MOTION_PX,
            "motion not measured (frames under 16 px, or statistics given without it)",
        ), None
    change = max(st.interval_max_abs_change, default=0.0)
    inc = motion > UPSAMPLE_MOTION_PX and change > c_nom
    fps = len(st.interval_max_abs_change) / st.duration_s if st.duration_s > 0 else float("nan")
    rate = fps * math.ceil(motion) if inc and math.isfinite(fps) else None
    text = (
        f"motion {motion:.3g} px/frame (99th percentile optical flow) {'>' if motion > UPSAMPLE_MOTION_PX else '<='} "
        f"{UPSAMPLE_MOTION_PX:g} px, largest log change per frame {change:.3g} {'>' if change > c_nom else '<='} "
        f"C = {c_nom:.3g}: "
    )
    text += (
        f"linear-in-log event times are off by a large part of a frame; upsample to {rate:.4g} Hz (mode 'flow')"
        if rate is not None
        else "the video's frames time events as well as upsampling would"
    )
    return PlanDecision("frame upsampling", inc, motion, UPSAMPLE_MOTION_PX, text), rate
