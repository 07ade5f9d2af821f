"""Spatial filtering in front of the event comparator: placement, positivity, mesh surround.

Two placements are real hardware options (see DESIGN.md):

``pre_log`` (FS-DVS, the paper's Eq. for ``I_agg``)
    ``L = linlog(W * I)``. A kernel with negative lobes can make ``W * I <= 0``; the
    ``positivity`` mode says what the circuit does about it (floor / pedestal / differential) and
    the fraction of pixels that hit the floor is reported.
``post_log`` (centre-surround DVS, Delbruck et al. 2022; v2e's csdvs mode)
    ``L = W * linlog(I) - s * S`` where the surround ``S = (1 - λ²∇²)⁻¹ (W * linlog(I))`` is the
    steady state of a resistive mesh with space constant λ pixels. v2e reaches it by explicit Euler
    diffusion (80–800 steps per frame); here the discrete Neumann problem is solved exactly in one
    step by a DCT (a real FFT of the mirror-extended image, which diagonalises the 5-point
    Laplacian with reflecting borders).

The kernel is applied as a PyTorch ``conv2d`` weight (cross-correlation: ``out[y, x] =
Σ W[i, j] I[y + i - r, x + j - r]``), the way the paper's learnable filter is a conv layer; borders
are replicated (no dark frame around the image). A :class:`~fsdvs_hw.kernels.Kernel`'s centre tap
lands on the output pixel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ...errors import InputError, KernelError
from .config import SensorConfig
from .pixel import log_response

__all__ = [
    "FilteredSignal",
    "apply_kernel",
    "filtered_log_signal",
    "kernel_tensor",
    "mesh_surround_steady_state",
]


def kernel_tensor(kernel: Any, like: Any) -> Any:
    """Return ``kernel`` as a (k, k) tensor on ``like``'s device and dtype (differentiable).

    Accepts a :class:`~fsdvs_hw.kernels.Kernel`, a torch tensor, an array-like, or ``None``
    (no filter: the 1×1 delta). Raises :class:`KernelError` for a non-square, even-sized,
    non-finite or all-zero kernel, and :class:`InputError` for a kernel on another device.
    """
    import numpy as np
    import torch

    from ...kernels import Kernel, check_tap_magnitude

    if kernel is None:
        return torch.ones((1, 1), dtype=like.dtype, device=like.device)
    if isinstance(kernel, Kernel):
        if like.dtype != torch.float64:  # 1e300 taps are finite in float64, inf/NaN in float32
            check_tap_magnitude(kernel, source=f"kernel '{kernel.name}'")
        return torch.tensor(np.array(kernel.taps), dtype=like.dtype, device=like.device)
    if not isinstance(kernel, torch.Tensor):
        try:
            kernel = torch.as_tensor(np.asarray(kernel, dtype=np.float64))
        except (TypeError, ValueError) as exc:
            raise KernelError(f"kernel: must be a Kernel, a tensor or a 2-D array ({exc})") from None
    elif kernel.device != like.device:
        raise InputError(
            f"kernel: on device {kernel.device} but the video is on {like.device}; move both to the same device"
        )
    if kernel.ndim == 4 and kernel.shape[:2] == (1, 1):  # conv weight
        kernel = kernel[0, 0]
    if kernel.ndim != 2 or kernel.shape[0] != kernel.shape[1]:
        raise KernelError(f"kernel: must be a square 2-D (k, k) array, got shape {tuple(kernel.shape)}")
    if kernel.shape[0] % 2 == 0:
        raise KernelError(f"kernel: size must be odd (a centre tap), got {kernel.shape[0]}x{kernel.shape[1]}")
    if kernel.is_complex():
        raise KernelError("kernel: taps must be real")
    with torch.no_grad():
        if not bool(torch.isfinite(kernel).all()):
            raise KernelError("kernel: taps contain NaN or inf")
        if not bool((kernel != 0).any()):
            raise KernelError("kernel: all taps are zero (the sensor would see nothing)")
        if like.dtype != torch.float64:
            check_tap_magnitude(kernel.detach().double().cpu().numpy())
    return kernel.to(dtype=like.dtype, device=like.device)


#: Kernel sizes and frame areas from which ``method="auto"`` correlates by FFT instead of directly
#: (measured on CPU: a 7×7 FFT correlation of 17×480×640 frames is ~2× faster than ``conv2d``).
FFT_MIN_KERNEL_SIZE = 5
FFT_MIN_PIXELS = 64 * 64


def apply_kernel(frames: Any, kernel: Any, method: str = "auto") -> Any:
    """Correlate every frame of ``frames`` (..., H, W) with the (k, k) ``kernel`` (replicated borders).

    ``method``: ``"direct"`` (``conv2d``), ``"fft"`` (real FFT of the padded frame; exact up to
    rounding, ~1e-7 relative in float32) or ``"auto"`` (FFT for kernels of at least
    :data:`FFT_MIN_KERNEL_SIZE` taps on frames of at least :data:`FFT_MIN_PIXELS` pixels).
    """
    import torch
    import torch.nn.functional as F

    k = kernel.shape[-1]
    if k == 1:
        return frames * kernel[0, 0]
    r = k // 2
    shape = frames.shape
    H, W = shape[-2], shape[-1]
    x = frames.reshape(-1, 1, H, W)
    x = F.pad(x, (r, r, r, r), mode="replicate")
    if method == "auto":
        method = "fft" if (k >= FFT_MIN_KERNEL_SIZE and H * W >= FFT_MIN_PIXELS) else "direct"
    if method == "direct":
        y = F.conv2d(x, kernel.reshape(1, 1, k, k))
    elif method == "fft":
        from scipy.fft import next_fast_len

        # transform sizes with small prime factors (pocketfft: 2, 3, 5, 7, 11): 278 × 646 for a
        # 272 × 640 frame runs ~3× slower than 280 × 648. The circular wrap of the larger size
        # still only touches the first k - 1 rows and columns, which are cut off.
        s = (next_fast_len(H + 2 * r), next_fast_len(W + 2 * r, real=True))
        spec = torch.fft.rfft2(kernel.flip(0, 1), s=s)
        y = torch.fft.irfft2(torch.fft.rfft2(x, s=s) * spec, s=s)[..., 2 * r : 2 * r + H, 2 * r : 2 * r + W]
    else:
        raise InputError(f"convolution method {method!r} unknown; allowed: auto, direct, fft")
    return y.reshape(shape)


def mesh_surround_steady_state(signal: Any, lambda_px: float) -> Any:
    """Solve ``(1 - λ² ∇²) u = signal`` exactly on each (H, W) frame (Neumann borders).

    ``∇²`` is the 5-point lattice Laplacian; the solution is the steady state of a resistive mesh
    with lateral/vertical conductance ratio ``λ²`` driven by ``signal``. Computed by an FFT of the
    mirror-extended image (equivalent to a DCT-II), so it costs O(HW log HW) regardless of λ.
    Differentiable; ``λ = 0`` returns the input.
    """
    import torch

    from ...validation import check_instance, check_real

    check_instance("signal", signal, torch.Tensor, "a real torch tensor (..., H, W)")
    if signal.ndim < 2 or not signal.is_floating_point():
        raise InputError(
            f"signal: shape {tuple(signal.shape)}, dtype {signal.dtype}; allowed: a floating "
            "tensor of at least 2 dimensions (..., H, W)"
        )
    lambda_px = check_real("lambda_px", lambda_px, 0.0, 1e4, unit="px")
    if lambda_px == 0:
        return signal
    H, W = signal.shape[-2:]
    ext = torch.cat([signal, signal.flip(-2)], dim=-2)
    ext = torch.cat([ext, ext.flip(-1)], dim=-1)
    real_dtype = signal.dtype
    ky = torch.arange(2 * H, device=signal.device, dtype=real_dtype)
    kx = torch.arange(W + 1, device=signal.device, dtype=real_dtype)
    eig = (4 * torch.sin(math.pi * ky / (2 * H)) ** 2)[:, None] + (4 * torch.sin(math.pi * kx / (2 * W)) ** 2)[None, :]
    spec = torch.fft.rfft2(ext) / (1.0 + lambda_px**2 * eig)
    out = torch.fft.irfft2(spec, s=(2 * H, 2 * W))
    return out[..., :H, :W]


class _FloorSTE:
    """max(x, floor) forward; straight-through gradient clipped to [-1, 1] where the floor holds."""

    _fn = None

    @classmethod
    def apply(cls, x: Any, floor: float) -> Any:
        if cls._fn is None:
            import torch

            class Fn(torch.autograd.Function):
                @staticmethod
                def forward(ctx, inp, fl):  # noqa: ANN001
                    below = inp < fl
                    ctx.save_for_backward(below)
                    return torch.clamp(inp, min=fl)

                @staticmethod
                def backward(ctx, grad):  # noqa: ANN001
                    (below,) = ctx.saved_tensors
                    return torch.where(below, grad.clamp(-1.0, 1.0), grad), None

            cls._fn = Fn
        return cls._fn.apply(x, floor)


@dataclass
class FilteredSignal:
    """What the comparator sees, per frame.

    Attributes
    ----------
    log_signal : torch.Tensor (B, T, H, W)
        Comparator input in log units (centre minus steady surround where there is no transient).
    surround : torch.Tensor or None (B, T, H, W)
        Steady-state mesh surround when it must be lagged in time (``surround_tau_s > 0``);
        then ``log_signal`` is the centre only.
    cutoff_intensity : torch.Tensor (B, T, H, W)
        Photocurrent (video units) that sets each pixel's photoreceptor bandwidth.
    floor_fraction : float
        Fraction of pixel-frames whose aggregated photocurrent was below ``floor_intensity``
        (0 for ``post_log`` and ``differential``).
    """

    log_signal: Any
    surround: Any
    cutoff_intensity: Any
    floor_fraction: float


def _is_identity(kernel: Any) -> bool:
    """A 1×1 kernel of weight 1 that needs no gradient."""
    import torch

    return (
        tuple(kernel.shape[-2:]) == (1, 1)
        and kernel.numel() == 1
        and not (kernel.requires_grad and torch.is_grad_enabled())
        and bool(kernel.reshape(()) == 1.0)
    )


def filtered_log_signal(video: Any, kernel: Any, config: SensorConfig) -> FilteredSignal:
    """Apply the kernel at ``config.placement`` with ``config.positivity``; return the log signal."""
    import torch

    surround = None
    floor_fraction = 0.0
    if config.placement == "pre_log":
        if config.positivity == "differential":
            # each channel sums photocurrents with non-negative weights, so it is >= 0; the clamp
            # removes only FFT rounding below 0 (which the linear part of the response would turn
            # into huge negative log values next to a very bright pixel)
            pos = torch.clamp(apply_kernel(video, torch.clamp(kernel, min=0.0), config.convolution), min=0.0)
            neg = torch.clamp(apply_kernel(video, torch.clamp(-kernel, min=0.0), config.convolution), min=0.0)
            log_signal = log_response(pos, config) - log_response(neg, config)
            cutoff_intensity = pos + neg
        else:
            # the 1×1 identity (no kernel): frames × 1 is the frames themselves, bit for bit, so no
            # pass over them (nothing below writes into agg)
            agg = video if _is_identity(kernel) else apply_kernel(video, kernel, config.convolution)
            if config.positivity == "pedestal":
                agg = agg + config.pedestal_intensity
            from ..native.fused import fused_applies, fused_floor

            if fused_applies(agg):  # the same bits in one compiled pass (no gradient wanted)
                agg, n_below = fused_floor(agg, float(config.floor_intensity))
            else:
                with torch.no_grad():
                    n_below = int(torch.count_nonzero(agg < config.floor_intensity))
                if n_below:  # identity otherwise: skip the pass
                    agg = _FloorSTE.apply(agg, float(config.floor_intensity))
            floor_fraction = n_below / agg.numel()
            log_signal = log_response(agg, config)
            cutoff_intensity = agg
    else:
        centre = apply_kernel(log_response(video, config), kernel, config.convolution)
        cutoff_intensity = video
        if config.surround_weight > 0 and config.surround_lambda_px > 0:
            steady = mesh_surround_steady_state(centre, config.surround_lambda_px)
            if config.surround_tau_s > 0:
                log_signal, surround = centre, steady
            else:
                log_signal = centre - config.surround_weight * steady
        else:
            log_signal = centre
    return FilteredSignal(log_signal, surround, cutoff_intensity, floor_fraction)
