"""Sensor parameters of the FS-DVS event simulator, with documented defaults and their sources.

:class:`SensorConfig` is an immutable record of every number the pixel model uses. Defaults follow
the v2e emulator's command-line defaults (Hu, Liu & Delbruck 2021) where v2e has one, and say so;
the rest are stated with their reasoning. Intensities are in the units of the input video
("linear intensity", full scale 1.0 for a normalised clip), times in seconds, rates in hertz,
thresholds in natural-log units.

References
----------
.. [1] Y. Hu, S.-C. Liu, T. Delbruck, "v2e: From Video Frames to Realistic DVS Events", CVPR
   Workshops 2021 (v2e command-line defaults: ``--pos_thres 0.2 --neg_thres 0.2 --sigma_thres
   0.03 --cutoff_hz 300 --leak_rate_hz 0.01 --shot_noise_rate_hz 0.001 --refractory_period
   0.0005``; linear-log response below 20 DN of 255).
.. [2] H. Rebecq, D. Gehrig, D. Scaramuzza, "ESIM: an Open Event Camera Simulator", CoRL 2018
   (adaptive sampling: time step so that no pixel's log intensity moves more than a set fraction
   of the contrast threshold).
.. [3] T. Delbruck, C. Li, R. Graca, B. McReynolds, "Utility and Feasibility of a Center Surround
   Event Camera", ICIP 2022 (surround subtracted from the log signal after a resistive-mesh
   diffusion).
.. [4] Y. Lichtsteiner, C. Posch, T. Delbruck, "A 128x128 120 dB 15 µs Latency Asynchronous
   Temporal Contrast Vision Sensor", IEEE JSSC 43(2), 2008 (photoreceptor bandwidth proportional
   to photocurrent).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from ...errors import InputError, one_line
from ...limits import MAX_SEED, MAX_SUBSTEPS

__all__ = [
    "CONVENTIONS",
    "MAX_SEED",
    "PLACEMENTS",
    "POSITIVITY_MODES",
    "PRESETS",
    "RESPONSES",
    "SATURATION_INTENSITY",
    "SURROGATES",
    "SensorConfig",
]

#: Where the spatial kernel sits: before the log (FS-DVS) or on the log signal (centre-surround DVS).
# MAX_SEED (fsdvs_hw.limits): numpy's classic 32-bit seed range; each effect's torch seed
# (``seed * 1_000_003 + stream``) then stays far inside torch's 64-bit range.
PLACEMENTS = ("pre_log", "post_log")
#: How a pre-log kernel with negative lobes is kept in the log's domain.
POSITIVITY_MODES = ("floor", "pedestal", "differential")
#: Gradient through the threshold crossing: hard counts with a straight-through gradient, or the
#: relaxed (continuous) count whose gradient the straight-through estimator uses.
SURROGATES = ("straight_through", "relaxed")
#: Photoreceptor response below the linear-log knee: the tangent line (default) or v2e's chord.
RESPONSES = ("tangent", "v2e")
#: Named settings for :meth:`SensorConfig.preset` (the ``--preset`` of ``fsdvs-hw simulate``).
PRESETS = ("default", "ideal", "v2e-clean", "v2e-default", "v2e-noisy")
#: Saturation intensity of the pixel, in video units: brighter input is clipped to it before the
#: kernel and the log, as a real photodiode saturates (its photocurrent cannot grow without bound).
#: 1e20 is 200 dB above a full scale of 1.0 (real event pixels span about 120 dB), far above any
#: scene the library makes (``SceneConfig.illuminance`` <= 1e12), and low enough that a kernel sum
#: or an FFT of a saturated frame stays finite in float32. The simulator reports how many
#: pixel-frames it clipped (``SimulationInfo.saturated``); valid videos below it are untouched.
SATURATION_INTENSITY: float = 1e20
#: Named event-generation conventions (``SensorConfig.conventions``): this package's pixel model,
#: or the v2e emulator's rules (:mod:`fsdvs_hw.sensor.simulation.conventions`).
CONVENTIONS = ("native", "v2e")
#: How shot-noise counts are drawn (``SensorConfig.shot_noise_draw``).
SHOT_NOISE_DRAWS = ("per_pixel", "sparse")

# v2e's --dvs_params sets and command-line defaults (v2ecore/emulator.py set_dvs_params,
# v2ecore/v2e_args.py); leak_jitter_fraction and noise_rate_cov_decades are not modelled here
_V2E_SETTINGS: dict[str, dict[str, Any]] = {
    "v2e-clean": dict(threshold_sigma=0.02, cutoff_hz=0.0, leak_rate_hz=0.0, shot_noise_rate_hz=0.0, refractory_s=0.0),
    "v2e-default": dict(
        threshold_sigma=0.03, cutoff_hz=300.0, leak_rate_hz=0.01, shot_noise_rate_hz=0.001, refractory_s=5e-4
    ),
    "v2e-noisy": dict(threshold_sigma=0.05, cutoff_hz=30.0, leak_rate_hz=0.1, shot_noise_rate_hz=5.0, refractory_s=0.0),
}


def _check_number(name: str, value: Any, *, low: float = 0.0, high: float = math.inf, low_open: bool = False) -> None:
    try:
        v = float(value.detach()) if hasattr(value, "detach") else float(value)  # numbers, 0-d tensors
    except (TypeError, ValueError):
        raise InputError(f"SensorConfig.{name}: must be a real number, got {value!r}") from None
    ok = (v > low if low_open else v >= low) and v <= high and math.isfinite(v)
    if not ok:
        bracket = "(" if low_open else "["
        raise InputError(f"SensorConfig.{name}: {v!r} outside the allowed range {bracket}{low}, {high}]")


@dataclass(frozen=True)
class SensorConfig:
    """Every parameter of the event-pixel model (SI units; intensities in video units).

    Parameters
    ----------
    threshold_on, threshold_off : float or 0-d torch.Tensor
        Nominal ON/OFF contrast thresholds C in natural-log units (default 0.2 each, v2e [1]_).
        A tensor with ``requires_grad`` lets gradients reach the thresholds.
    threshold_sigma : float
        Per-pixel threshold mismatch, standard deviation in log units (default 0.03, v2e [1]_).
        Sampled once per pixel from the seeded generator; thresholds are clipped below at
        ``threshold_min_fraction`` of nominal.
    threshold_min_fraction : float
        Smallest per-pixel threshold as a fraction of nominal after mismatch (default 0.05; v2e
        clips at 0.01 log units absolute).
    refractory_s : float
        Refractory (dead) time after each event in seconds (default 0.5 ms, v2e [1]_). Crossings
        inside it are lost; the reference still moves with the signal (reset at release).
    leak_rate_hz : float
        Leak-event rate of a pixel under constant light in Hz (default 0.01, v2e [1]_). Modelled,
        as in v2e, as a downward drift of the memorised reference by ``leak_rate_hz * C_on`` per
        second (desynchronised across pixels by ``random_reference_phase``).
    shot_noise_rate_hz : float
        Shot-noise event rate per pixel in Hz, both polarities together, half each (default
        0.001, v2e [1]_). Poisson in time, added to the output; a noise event does not move the
        memorised reference (the excursion that fired it decays), so the measured rate equals
        the configured one.
    shot_noise_draw : {"per_pixel", "sparse"}
        How shot-noise counts are drawn; both give every pixel independent Poisson counts (the same
        law) but different realisations. ``"per_pixel"`` (default): ``torch.poisson`` over the
        frame each step, the stream every stored result (shipped checkpoints, design results) was
        made with. ``"sparse"``: the frame's total from one Poisson draw, then that many uniform
        pixels: O(events) instead of O(pixels), 0.7 CPU s less per 43.5 M pixel-frames at
        0.001 Hz; the v2e presets use it.
    cutoff_hz : float
        Photoreceptor first-order low-pass cut-off at full-scale intensity, Hz (default 300, v2e
        [1]_). The cut-off scales with intensity (bandwidth ∝ photocurrent [4]_):
        ``f_c(I) = cutoff_hz * clip((I + dark_intensity) / full_scale_intensity, 0, 1)``.
        ``0`` or ``inf`` disables the filter.
    full_scale_intensity : float
        Intensity at which the photoreceptor reaches ``cutoff_hz`` (default 1.0: a normalised clip).
    dark_intensity : float
        Dark-current equivalent intensity, where the response turns from log to linear
        (linear-log knee). Default 20/255 ≈ 0.0784 of full scale: v2e's 20 DN of 255 [1]_.
        The response is ``log(I)`` above the knee and its tangent line below (continuous value
        and slope, unlike v2e's chord through the origin), so it is finite at ``I = 0``.
    response : {"tangent", "v2e"}
        The linear part of the photoreceptor response below the knee. ``"tangent"`` (default):
        the log's tangent (:func:`~fsdvs_hw.sensor.simulation.pixel.linlog`), continuous in value and slope,
        scale-invariant (a dimmer copy of a scene gives the same events above the knee and
        proportionally fewer below it). ``"v2e"``: v2e's chord through the origin in 8-bit code
        values (:func:`~fsdvs_hw.sensor.simulation.pixel.linlog_v2e`), for event counts comparable with
        v2e; its slope below the knee is ``log(20)`` = 3.0× the log's at the knee, a contrast gain
        that jumps at the knee and depends on the arbitrary DN scale.
    placement : {"pre_log", "post_log"}
        ``"pre_log"`` (FS-DVS): ``L = log(W * I)``. ``"post_log"`` (centre-surround DVS [3]_):
        ``L = W * log(I)``, then minus the mesh surround if ``surround_weight > 0``.
    positivity : {"floor", "pedestal", "differential"}
        How ``W * I <= 0`` (negative lobes) is kept in the log's domain, pre-log only.
        ``"floor"``: the aggregated photocurrent cannot go below ``floor_intensity`` (a dark
        current floor; gradient passes straight through, clipped to [-1, 1], as in Neural
        Ganglion Sensors). ``"pedestal"``: a bias current ``pedestal_intensity`` is added before
        the log (lowers contrast gain); values still below the floor are floored and counted.
        ``"differential"``: two photoreceptor channels ``W+ * I`` and ``W- * I`` (each
        non-negative); the comparator sees ``log(W+ * I) - log(W- * I)`` (both through the
        linear-log response).
    floor_intensity : float
        Floor of the aggregated photocurrent for ``"floor"``/``"pedestal"`` (default 1e-3 of full
        scale, a dark-current floor well below the linear-log knee).
    pedestal_intensity : float
        Bias added in ``"pedestal"`` mode (default 0.1 of full scale).
    surround_lambda_px : float
        Space constant λ of the post-log resistive-mesh surround in pixels (default 0: no mesh).
        Steady state ``(1 - λ²∇²)⁻¹ L`` solved exactly by a DCT (Neumann boundaries) [3]_.
    surround_weight : float
        Surround gain s: output ``L - s · surround`` (default 0). 0 gives the plain DVS.
    surround_tau_s : float
        Settling time constant of the surround mesh in seconds (default 0: instantaneous). When
        > 0 the surround follows its steady state through a first-order lag.
    random_reference_phase : bool
        Start each pixel's memorised reference a uniform random fraction of ``C_on`` below the
        first frame's signal, as after an unknown earlier reset (desynchronises leak events; the
        camera presets of :mod:`fsdvs_hw.sensor.cameras.presets` use it). Default False: the reference is
        the first frame (ESIM, and v2e 1.5.1, whose random start is commented out in
        ``v2ecore/emulator.py``).
    convolution : {"auto", "direct", "fft"}
        How the kernel is applied: ``conv2d``, FFT, or FFT for kernels >= 5×5 on frames >= 64×64
        (default ``"auto"``; both exact up to floating-point rounding).
    frame_rate_hz : float
        Frame rate assumed when no timestamps are given (default 25 Hz: UCF101, as in the FS-DVS
        paper; 17 frames span 0.64 s).
    substeps : int
        Fixed time sub-steps per frame interval (default 1). Ignored if ``adaptive_fraction`` is set.
    adaptive_fraction : float or None
        ESIM-style [2]_ adaptive stepping: sub-steps per interval chosen so that no pixel's log
        signal moves by more than this fraction of the threshold per sub-step (per frame interval,
        not one global step). ``None`` (default) uses ``substeps``. Sub-steps only refine a
        temporal filter (photoreceptor low-pass, surround-mesh transient); without one the
        crossings of the linear signal are exact in one step, so none are added.
    max_substeps : int
        Upper bound of adaptive sub-steps per interval (default 256).
    adaptive_region_px : int
        With adaptive stepping (``adaptive_fraction`` or a plan), choose the sub-steps per square
        region of this many pixels instead of one count for the whole frame (ESIM's choice is
        global): still regions are not stepped at the rate of the fastest (default 32; 0 = global).
    surrogate : {"straight_through", "relaxed"}
        Gradient through the threshold crossing. ``"straight_through"`` (default): forward emits
        integer event counts ``floor(ΔL / C)``; backward uses ``d count / d ΔL = 1 / C`` on the
        side of the crossing's polarity (the floor's straight-through estimator).
        ``"relaxed"``: forward emits the continuous count ``relu(±ΔL) / C`` of a reference that
        tracks the signal exactly (smooth, for gradcheck and analysis); in the first interval its
        gradient is exactly the straight-through one.
    conventions : {"native", "v2e"}
        Event-generation rules (:mod:`fsdvs_hw.sensor.simulation.conventions`). ``"native"``
        (default): this model, every crossing at its interpolated time. ``"v2e"``: the v2e
        emulator's rules, for recordings compared with v2e's: events stamped on a grid inside
        each frame interval, a refractory period that delays a crossing instead of dropping it,
        shot noise whose rate falls with intensity and that resets the reference, one
        forward-Euler photoreceptor update per frame (event lists only). Left out of
        :meth:`to_dict` when native, so stored fingerprints do not change.
    seed : int
        Seed for every random draw (mismatch, leak phase, shot noise); each effect draws from its
        own stream derived from this seed, so switching one effect off does not change the others.
        In [0, :data:`MAX_SEED`] (2**32 - 1).

    Examples
    --------
    >>> from fsdvs_hw import SensorConfig
    >>> SensorConfig().threshold_sigma, SensorConfig.ideal().threshold_sigma   # v2e's mismatch; none
    (0.03, 0.0)
    """

    threshold_on: Any = 0.2
    threshold_off: Any = 0.2
    threshold_sigma: float = 0.03
    threshold_min_fraction: float = 0.05
    refractory_s: float = 5e-4
    leak_rate_hz: float = 0.01
    shot_noise_rate_hz: float = 0.001
    shot_noise_draw: str = "per_pixel"
    cutoff_hz: float = 300.0
    full_scale_intensity: float = 1.0
    dark_intensity: float = 20.0 / 255.0
    response: str = "tangent"
    placement: str = "pre_log"
    positivity: str = "floor"
    floor_intensity: float = 1e-3
    pedestal_intensity: float = 0.1
    surround_lambda_px: float = 0.0
    surround_weight: float = 0.0
    surround_tau_s: float = 0.0
    random_reference_phase: bool = False
    convolution: str = "auto"
    frame_rate_hz: float = 25.0
    substeps: int = 1
    adaptive_fraction: float | None = None
    max_substeps: int = 256
    adaptive_region_px: int = 32
    surrogate: str = "straight_through"
    conventions: str = "native"
    seed: int = 0

    def __post_init__(self) -> None:
        _check_number("threshold_on", self.threshold_on, low=0.0, high=1e3, low_open=True)
        _check_number("threshold_off", self.threshold_off, low=0.0, high=1e3, low_open=True)
        _check_number("threshold_sigma", self.threshold_sigma, high=1e3)
        _check_number("threshold_min_fraction", self.threshold_min_fraction, low=0.0, high=1.0, low_open=True)
        _check_number("refractory_s", self.refractory_s, high=1e3)
        _check_number("leak_rate_hz", self.leak_rate_hz, high=1e6)
        _check_number("shot_noise_rate_hz", self.shot_noise_rate_hz, high=1e6)
        if not (isinstance(self.cutoff_hz, (int, float)) and (self.cutoff_hz >= 0)):
            raise InputError(f"SensorConfig.cutoff_hz: must be >= 0 Hz (0 or inf: no filter), got {self.cutoff_hz!r}")
        _check_number("full_scale_intensity", self.full_scale_intensity, low=0.0, high=1e30, low_open=True)
        _check_number("dark_intensity", self.dark_intensity, low=0.0, high=1e30, low_open=True)
        _check_number("floor_intensity", self.floor_intensity, low=0.0, high=1e30, low_open=True)
        _check_number("pedestal_intensity", self.pedestal_intensity, high=1e30)
        _check_number("surround_lambda_px", self.surround_lambda_px, high=1e4)
        _check_number("surround_weight", self.surround_weight, high=1.0)
        _check_number("surround_tau_s", self.surround_tau_s, high=1e3)
        _check_number("frame_rate_hz", self.frame_rate_hz, low=0.0, high=1e9, low_open=True)
        for name in (
            "response",
            "placement",
            "positivity",
            "shot_noise_draw",
            "convolution",
            "surrogate",
            "conventions",
        ):
            if not isinstance(getattr(self, name), str):
                raise InputError(
                    f"SensorConfig.{name}: must be a string, got {type(getattr(self, name)).__name__} "
                    f"{one_line(getattr(self, name))}"
                )
        if not isinstance(self.random_reference_phase, bool):
            raise InputError(
                f"SensorConfig.random_reference_phase: must be True or False, got "
                f"{one_line(self.random_reference_phase)}"
            )
        self._check_choices()
        if (
            not isinstance(self.adaptive_region_px, int)
            or isinstance(self.adaptive_region_px, bool)
            or not 0 <= self.adaptive_region_px <= 100_000
        ):
            raise InputError(
                f"SensorConfig.adaptive_region_px: must be an integer >= 0, got {self.adaptive_region_px!r}"
            )
        for name in ("substeps", "max_substeps"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= MAX_SUBSTEPS:
                raise InputError(
                    f"SensorConfig.{name}: must be an integer in [1, {MAX_SUBSTEPS}] "
                    f"(fsdvs_hw.limits.MAX_SUBSTEPS), got {v!r}"
                )
        if self.adaptive_fraction is not None:
            _check_number("adaptive_fraction", self.adaptive_fraction, low=0.0, high=100.0, low_open=True)
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or not 0 <= self.seed <= MAX_SEED:
            raise InputError(f"SensorConfig.seed: must be an integer in [0, {MAX_SEED}] (2**32 - 1), got {self.seed!r}")

    def _check_choices(self) -> None:
        """Each named option is one of its allowed values (the message lists them)."""
        if self.response not in RESPONSES:
            raise InputError(f"SensorConfig.response: {self.response!r} unknown; allowed: {', '.join(RESPONSES)}")
        if self.placement not in PLACEMENTS:
            raise InputError(f"SensorConfig.placement: {self.placement!r} unknown; allowed: {', '.join(PLACEMENTS)}")
        if self.positivity not in POSITIVITY_MODES:
            raise InputError(
                f"SensorConfig.positivity: {self.positivity!r} unknown; allowed: {', '.join(POSITIVITY_MODES)}"
            )
        if self.shot_noise_draw not in SHOT_NOISE_DRAWS:
            raise InputError(
                f"SensorConfig.shot_noise_draw: {self.shot_noise_draw!r} unknown; allowed: "
                f"{', '.join(SHOT_NOISE_DRAWS)}"
            )
        if self.convolution not in ("auto", "direct", "fft"):
            raise InputError(f"SensorConfig.convolution: {self.convolution!r} unknown; allowed: auto, direct, fft")
        if self.conventions not in CONVENTIONS:
            raise InputError(
                f"SensorConfig.conventions: {self.conventions!r} unknown; allowed: {', '.join(CONVENTIONS)}"
            )
        if self.surrogate not in SURROGATES:
            raise InputError(f"SensorConfig.surrogate: {self.surrogate!r} unknown; allowed: {', '.join(SURROGATES)}")

    # ---------------------------------------------------------------- presets
    @classmethod
    def ideal(cls, threshold: Any = 0.2, **overrides: Any) -> SensorConfig:
        """The noiseless ideal sensor used for training (the paper's simulation track).

        Equal ON/OFF thresholds ``threshold``, no mismatch, no refractory period, no leak or shot
        noise, no photoreceptor low-pass, one sub-step per frame interval, pre-log placement with
        a dark-current floor. ``overrides`` replace any field.
        """
        base = dict(
            threshold_on=threshold,
            threshold_off=threshold,
            threshold_sigma=0.0,
            refractory_s=0.0,
            leak_rate_hz=0.0,
            shot_noise_rate_hz=0.0,
            cutoff_hz=0.0,
            substeps=1,
            adaptive_fraction=None,
        )
        base.update(overrides)
        return cls(**base)

    @classmethod
    def v2e_defaults(cls, **overrides: Any) -> SensorConfig:
        """v2e's command-line defaults [1]_ (the class defaults), with ESIM-style adaptive steps."""
        base: dict[str, Any] = dict(adaptive_fraction=0.5)
        base.update(overrides)
        return cls(**base)

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> SensorConfig:
        """A named setting (see :data:`PRESETS`); ``overrides`` replace any field.

        ``"default"``: the class defaults (v2e's command-line noise figures, this model's
        tangent response and exact photoreceptor). ``"ideal"``: :meth:`ideal`.
        ``"v2e-clean"``, ``"v2e-default"``, ``"v2e-noisy"``: v2e's ``--dvs_params clean``, its
        command-line defaults and ``--dvs_params noisy`` [1]_, with v2e's intensity mapping:
        the chord response (``response="v2e"``) and its photoreceptor bandwidth
        ``cutoff_hz · (DN + 20) / 275`` (``full_scale_intensity = 275/255``, ``dark_intensity =
        20/255``), one update per frame as v2e without frame interpolation, and the reference
        starting at the first frame (v2e 1.5.1 has no random leak phase: its random start is
        commented out; with it, carphone.mp4 gave 2.4 % more events than v2e); shot noise drawn
        sparsely (``shot_noise_draw="sparse"``: same law, O(events)). From a video file,
        ``fsdvs-hw simulate`` feeds these presets v2e's gray code values
        (:func:`fsdvs_hw.sensor.cameras.presets.preset_input_mapping`).
        Not modelled: v2e's leak-rate jitter (``leak_jitter_fraction``), shot-noise rate spread
        (``noise_rate_cov_decades``) and its forward-Euler low-pass step (exact here).
        """
        if name not in PRESETS:
            raise InputError(f"sensor preset {name!r} unknown; allowed: {', '.join(PRESETS)}")
        if name == "default":
            return cls(**overrides)
        if name == "ideal":
            return cls.ideal(**overrides)
        base = dict(
            threshold_on=0.2,
            threshold_off=0.2,
            response="v2e",
            full_scale_intensity=275.0 / 255.0,
            dark_intensity=20.0 / 255.0,
            substeps=1,
            adaptive_fraction=None,
            shot_noise_draw="sparse",
            **_V2E_SETTINGS[name],
        )
        base.update(overrides)
        return cls(**base)

    def replace(self, **changes: Any) -> SensorConfig:
        """A copy with ``changes`` applied (validated)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise InputError(f"SensorConfig: unknown field(s) {sorted(unknown)}")
        return replace(self, **changes)

    # ---------------------------------------------------------------- helpers
    @property
    def has_photoreceptor(self) -> bool:
        """True if the photoreceptor low-pass is active (finite, non-zero cut-off)."""
        return 0.0 < self.cutoff_hz < math.inf

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, source: str = "dict") -> SensorConfig:
        """Build from a dict (e.g. a design file's ``[sensor]`` table); unknown keys are an error."""
        if not isinstance(data, dict):
            raise InputError(f"{source}: sensor config must be a table/dict, got {type(data).__name__}")
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise InputError(
                f"{source}: unknown sensor field(s) {sorted(unknown)}; "
                f"allowed: {', '.join(f.name for f in fields(cls))}"
            )
        return cls(**data)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (tensor thresholds become floats)."""
        d = asdict(self)
        if d["conventions"] == "native":  # the default: absent, as before the field existed
            del d["conventions"]
        for k in ("threshold_on", "threshold_off"):
            d[k] = float(d[k].detach()) if hasattr(d[k], "detach") else float(d[k])
        return d
