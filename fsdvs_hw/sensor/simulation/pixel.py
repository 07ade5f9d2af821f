"""The event pixel: linear-log response, photoreceptor low-pass, per-pixel thresholds.

All functions are pure torch, differentiable, device- and dtype-following.

References
----------
.. [1] Y. Hu, S.-C. Liu, T. Delbruck, "v2e: From Video Frames to Realistic DVS Events", CVPR
   Workshops 2021 (linear-log response below 20 DN; intensity-dependent photoreceptor cut-off).
.. [2] P. Lichtsteiner, C. Posch, T. Delbruck, IEEE JSSC 43(2):566-576, 2008 (logarithmic
   photoreceptor whose bandwidth is proportional to photocurrent).
"""

from __future__ import annotations

import math
from typing import Any

from .config import SensorConfig

__all__ = [
    "effect_generator",
    "linlog",
    "linlog_v2e",
    "log_response",
    "lowpass_step",
    "photoreceptor_cutoff_hz",
    "threshold_maps",
]

# distinct streams per random effect, so switching one effect off leaves the others unchanged
_STREAMS = {"mismatch": 1, "leak_phase": 2, "shot": 3, "shot_time": 4}


def linlog(intensity: Any, knee: float) -> Any:
    """Linear-log photoreceptor response in natural-log units.

    ``log(I)`` for ``I >= knee``; below the knee the tangent line
    ``log(knee) + (I - knee) / knee`` (continuous value and slope). Finite and differentiable for
    every finite ``I``, including 0 (value ``log(knee) - 1``) and negative values.

    Parameters
    ----------
    intensity : torch.Tensor
        Linear intensity (video units).
    knee : float
        Dark-current equivalent intensity where the response turns linear (> 0).
    """
    import torch

    from ...validation import check_instance, check_real

    check_instance("intensity", intensity, torch.Tensor, "a torch tensor of linear intensities")
    knee = check_real("knee", knee, 0.0, lo_open=True, unit="(video units)")
    # log of the part above the knee plus the linear part below it (3 passes, no branches)
    return torch.log(torch.clamp(intensity, min=knee)) + torch.clamp(intensity - knee, max=0.0) / knee


#: v2e's code-value scale: intensity 1.0 (display white) is 255 DN.
V2E_DN_PER_FULL_SCALE = 255.0


def linlog_v2e(intensity: Any, knee: float) -> Any:
    """v2e's linear-log response [1]_ (``lin_log``), in natural-log units of DN.

    With ``x = 255 I`` (DN, white = 255) and ``k = 255 knee``: ``log(x)`` for ``x > k``, the
    chord through the origin ``x log(k) / k`` for ``x <= k`` (continuous in value, not in slope:
    its slope ``log(k)/k`` is ``log(k)`` times the log's slope ``1/k`` at the knee, 3.0× for
    k = 20 DN), rounded to 1e-8 as v2e does (the rounding's gradient is passed straight through).
    The result differs from :func:`linlog` by the constant ``log 255`` above the knee, which no
    event sees; below the knee the contrast gain is higher.
    """
    import torch

    from ..native.fused import fused_applies, fused_linlog_v2e

    if isinstance(knee, float) and knee > 0 and fused_applies(intensity):
        return fused_linlog_v2e(intensity, knee, V2E_DN_PER_FULL_SCALE)  # the same bits in two compiled passes
    x = intensity * V2E_DN_PER_FULL_SCALE
    k = knee * V2E_DN_PER_FULL_SCALE
    y = torch.where(x <= k, x * (math.log(k) / k), torch.log(torch.clamp(x, min=k)))
    with torch.no_grad():
        rounded = _round_half_even(y.double() * 1e8).div_(1e8).to(y.dtype)
    if not (torch.is_grad_enabled() and y.requires_grad):
        return rounded  # = y + (rounded - y) exactly: y >= 0 and the two within a factor 2 (Sterbenz)
    # straight-through rounding; where 255·I overflows float32 (I > 1.3e36) y is inf and stays inf
    return y + torch.where(torch.isinf(y), 0.0, rounded - y.detach())


def _round_half_even(v: Any) -> Any:
    """``torch.round`` of a float64 tensor with ``|v| < 2**51`` (here: log responses × 1e8 < 1e11)."""
    from ..native.fused import ROUND_MAGIC

    return v.add_(ROUND_MAGIC).sub_(ROUND_MAGIC)


def log_response(intensity: Any, config: SensorConfig) -> Any:
    """The photoreceptor response ``config.response`` selects: :func:`linlog` (``"tangent"``)
    or :func:`linlog_v2e` (``"v2e"``), with knee ``config.dark_intensity``."""
    if config.response == "v2e":
        return linlog_v2e(intensity, config.dark_intensity)
    return linlog(intensity, config.dark_intensity)


def photoreceptor_cutoff_hz(intensity: Any, config: SensorConfig) -> Any:
    """Photoreceptor cut-off in Hz, proportional to photocurrent (plus dark current), capped.

    ``f_c = cutoff_hz * clip((I + dark_intensity) / full_scale_intensity, 0, 1)``; the dark
    current keeps the bandwidth finite in the dark.
    """
    import torch

    frac = (intensity + config.dark_intensity) / config.full_scale_intensity
    return config.cutoff_hz * torch.clamp(frac, 0.0, 1.0)


def lowpass_step(state: Any, target: Any, cutoff_hz: Any, dt_s: float) -> Any:
    """One exact step of a first-order low-pass: ``y += (1 - exp(-2π f_c dt)) (x - y)``.

    Exact for a target held over the step, unconditionally stable for any ``dt_s`` (v2e uses the
    forward-Euler factor ``2π f_c dt`` clipped at 1).
    """
    import torch

    alpha = -torch.expm1(-2.0 * math.pi * cutoff_hz * dt_s)
    return state + alpha * (target - state)


def effect_generator(seed: int, effect: str, device: Any) -> Any:
    """A torch Generator for one random effect, derived from the config seed."""
    import torch

    g = torch.Generator(device=device if str(device).startswith("cuda") else "cpu")
    g.manual_seed(int(seed) * 1_000_003 + _STREAMS[effect])
    return g


def _randn(shape: tuple[int, ...], generator: Any, like: Any) -> Any:
    import torch

    z = torch.randn(shape, generator=generator, device=generator.device, dtype=torch.float64)
    return z.to(device=like.device, dtype=like.dtype)


def threshold_maps(config: SensorConfig, shape: tuple[int, ...], like: Any, generator: Any = None) -> tuple[Any, Any]:
    """Per-pixel ON and OFF thresholds (log units) of shape ``shape`` = (H, W).

    ``C_pixel = C + σ z`` with ``z ~ N(0, 1)`` drawn from the mismatch stream, clipped below at
    ``threshold_min_fraction * C``. Gradients reach ``config.threshold_on/off`` when they are
    tensors. Without mismatch the nominal thresholds are returned as 0-d tensors (broadcast).
    """
    import torch

    c_on = torch.as_tensor(config.threshold_on, dtype=like.dtype, device=like.device)
    c_off = torch.as_tensor(config.threshold_off, dtype=like.dtype, device=like.device)
    if config.threshold_sigma <= 0:
        return c_on, c_off
    g = generator if generator is not None else effect_generator(config.seed, "mismatch", like.device)
    z_on = _randn(tuple(shape), g, like)
    z_off = _randn(tuple(shape), g, like)
    f = config.threshold_min_fraction
    on = torch.maximum(c_on + config.threshold_sigma * z_on, f * c_on)
    off = torch.maximum(c_off + config.threshold_sigma * z_off, f * c_off)
    return on, off
