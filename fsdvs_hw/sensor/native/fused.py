"""Compiled no-grad CPU paths of the pixel model: v2e's response, the positivity floor and one pixel sub-step.

The differentiable pixel model of :mod:`~fsdvs_hw.sensor.simulation.pixel` and :mod:`~fsdvs_hw.sensor.simulation.events` is written as torch
operations, each of which reads and writes whole frames: v2e's linear-log response takes about a
dozen (half in float64, for v2e's rounding to 1e-8) and every comparator sub-step about twenty
(the low-pass cut-off from the intensity, its exponent, the low-pass update, the leak, the
comparator's difference, counts and new reference). On a CPU an event list spends most of its
stepping thread moving that memory. When no gradient is wanted (an event list,
``torch.no_grad()``), :func:`fused_linlog_v2e` and :func:`fused_substep` do the same arithmetic in
passes of compiled C (``_fused.c``) around torch's own ``log`` and ``expm1``.

Results are bit-identical to the torch path, not merely close: the C code performs the same IEEE
operations in the same order and precision (the Python scalars rounded to the tensor's dtype as
torch rounds them; ``torch.addcmul`` is one fused multiply-add in torch's CPU kernels, so
``fma`` here), built without FMA contraction or fast-math; the transcendentals stay torch's (its
vectorised and scalar lanes differ in the last bit, so they are not reimplemented). The event
list is therefore the same, event for event, with or without these paths;
``tests/test_fused.py`` checks each output bit for bit against the torch operations on random
and extreme inputs, and whole event lists on both paths.

Not fused (the torch path runs): a gradient is wanted, a device other than the CPU, a dtype other
than float32/float64, the transient surround, the relaxed surrogate, or no C compiler (see
:func:`~fsdvs_hw.sensor.native.library.why_unavailable`).
"""

from __future__ import annotations

import ctypes
import math
from typing import Any

import torch

from ...errors import InputError
from ..simulation.config import SensorConfig
from . import library

__all__ = ["ROUND_MAGIC", "fused_applies", "fused_floor", "fused_linlog_v2e", "fused_substep", "fused_substep_applies"]

DTYPE_SUFFIX = {torch.float32: "f32", torch.float64: "f64"}


def fused_applies(like: Any) -> bool:
    """Whether the compiled paths can stand in for the torch operations on tensors like ``like``:
    CPU, float32 or float64, no gradient wanted (grad mode off, or ``like`` needs none), and the
    compiled kernels available.

    Examples
    --------
    >>> import torch
    >>> fused_applies(torch.zeros(3)) == library.available()
    True
    >>> fused_applies(torch.zeros(3, requires_grad=True))
    False
    """
    return (
        not (torch.is_grad_enabled() and like.requires_grad)
        and like.device.type == "cpu"
        and like.dtype in DTYPE_SUFFIX
        and library.available()
    )


def fused_substep_applies(like: Any, config: SensorConfig, transient: bool) -> bool:
    """Whether :func:`fused_substep` can replace the torch sub-step for signals like ``like``.

    CPU tensors of float32 or float64, no gradient wanted (``torch.is_grad_enabled()`` is False),
    no transient surround, the straight-through comparator, and the compiled kernels available.

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw.sensor import SensorConfig
    >>> with torch.no_grad():
    ...     ok = fused_substep_applies(torch.zeros(1, 4, 4), SensorConfig(), transient=False)
    >>> ok == library.available()
    True
    >>> fused_substep_applies(torch.zeros(1, 4, 4), SensorConfig(), transient=False)  # grad enabled
    False
    """
    return not torch.is_grad_enabled() and not transient and config.surrogate != "relaxed" and fused_applies(like)


def _flat(t: Any, dtype: Any) -> Any:
    """``t``'s values as one contiguous block of ``dtype`` for the C kernels (``t`` itself when it
    already is one: only its data pointer and size are read)."""
    if t.dtype == dtype and t.is_contiguous():
        return t
    return t.reshape(-1).to(dtype).contiguous()


def threshold_values(c: Any, hw: int, n: int, dtype: Any, name: str) -> Any:
    """Thresholds as H·W (shared by the batch) or B·H·W contiguous values (a single value expanded)."""
    flat = _flat(c, dtype)
    if flat.numel() == 1:
        return flat.reshape(1).expand(hw).contiguous()
    if flat.numel() not in (hw, n):
        raise ValueError(f"{name}: needs 1, H*W={hw} or B*H*W={n} values, got {flat.numel()}")
    return flat


def fused_substep(
    target: Any,
    intensity: Any,
    lp: Any,
    ref: Any,
    c_on: Any,
    c_off: Any,
    dt_sub: Any,
    eps: float,
    config: SensorConfig,
) -> tuple[Any, Any, Any, Any, Any]:
    """One sub-step of every pixel, as ``events._substep_target`` then ``events._Comparator`` compute it.

    Parameters
    ----------
    target : torch.Tensor
        (B, H, W) log signal at the end of the sub-step (frames already interpolated), log units.
    intensity : torch.Tensor or None
        (B, H, W) intensity that sets the photoreceptor cut-off (relative units); None without
        photoreceptor (``config.has_photoreceptor`` False).
    lp : torch.Tensor or None
        (B, H, W) low-pass state (log units); None without photoreceptor.
    ref : torch.Tensor
        (B, H, W) memorised reference before the leak (log units).
    c_on, c_off : torch.Tensor
        ON and OFF thresholds (log units), of 1, H·W or B·H·W values.
    dt_sub : torch.Tensor
        (B, 1, 1) sub-step length (s), in the signal's dtype.
    eps : float
        The count rounding guard added before the floor (``events._COUNT_EPS``).
    config : SensorConfig
        ``cutoff_hz``, ``dark_intensity``, ``full_scale_intensity`` (photoreceptor) and
        ``leak_rate_hz`` are read.

    Returns
    -------
    tuple of torch.Tensor
        ``(lp_new, ref_new, n_on, n_off, d)``, each (B, H, W) and new: the low-pass output (what the
        comparator saw; None without photoreceptor), the reference after the step, the ON and OFF
        crossing counts and the comparator's difference ``target - ref`` after the leak.

    Examples
    --------
    >>> import torch
    >>> from fsdvs_hw.sensor import SensorConfig
    >>> cfg = SensorConfig(leak_rate_hz=0.0, cutoff_hz=0.0)
    >>> ref = torch.zeros(1, 1, 2)
    >>> target = torch.tensor([[[0.45, -0.25]]])
    >>> c = torch.full((1, 1, 2), 0.2)
    >>> with torch.no_grad():
    ...     _, ref_new, n_on, n_off, d = fused_substep(target, None, None, ref, c, c, torch.ones(1, 1, 1), 1e-4, cfg)
    >>> n_on.tolist(), n_off.tolist()
    ([[[2.0, 0.0]]], [[[0.0, 1.0]]])
    """
    lib = library.loaded()
    dtype = target.dtype
    suffix = DTYPE_SUFFIX[dtype]
    B = target.shape[0]
    shape = tuple(target.shape)
    n = target.numel()
    hw = n // B if B else 0
    # every flattened input stays bound to a name until the C call returns: a temporary copy (a
    # non-contiguous input) freed before the call would hand the kernel freed memory
    tgt, ref_flat = _flat(target, dtype), _flat(ref, dtype)
    dt = _flat(dt_sub, dtype)
    if dt.numel() != B:
        raise ValueError(f"dt_sub: needs {B} values (one per batch element), got {dt.numel()}")
    con, coff = threshold_values(c_on, hw, n, dtype, "c_on"), threshold_values(c_off, hw, n, dtype, "c_off")
    real = ctypes_real(dtype)
    em1 = lp_flat = lp_new = None
    if intensity is not None:
        em1 = _lowpass_expm1(lib, intensity, dt, n, hw, config, dtype)
        lp_flat = _flat(lp, dtype)
        lp_new = torch.empty(n, dtype=dtype)
    ref_new, n_on, n_off, d = (torch.empty(n, dtype=dtype) for _ in range(4))
    leak = float(config.leak_rate_hz)
    getattr(lib, f"fsdvs_pixel_step_{suffix}")(
        tgt.data_ptr(),
        lp_flat.data_ptr() if lp_flat is not None else None,
        em1.data_ptr() if em1 is not None else None,
        ref_flat.data_ptr(),
        con.data_ptr(),
        con.numel(),
        coff.data_ptr(),
        coff.numel(),
        dt.data_ptr(),
        real(leak),  # 0 leaves the reference exactly as it is: r - (0 c) dt = r
        real(eps),
        n,
        hw,
        lp_new.data_ptr() if lp_new is not None else None,
        ref_new.data_ptr(),
        n_on.data_ptr(),
        n_off.data_ptr(),
        d.data_ptr(),
    )
    view = (lambda t: t.view(shape)) if n else (lambda t: t.reshape(shape))
    return (view(lp_new) if lp_new is not None else None, view(ref_new), view(n_on), view(n_off), view(d))


#: 1.5 · 2**52: adding and subtracting it rounds a float64 of magnitude below 2**51 to an integer,
#: ties to even (IEEE round-to-nearest), as ``torch.round`` does, in two vectorised passes
#: (:func:`.pixel.linlog_v2e`'s rounding to 1e-8, here and in its torch path).
ROUND_MAGIC = 6755399441055744.0


def fused_linlog_v2e(intensity: Any, knee: float, dn_per_full_scale: float = 255.0) -> Any:
    """:func:`.pixel.linlog_v2e` without its gradient: ``log(dn I)`` above the knee, the chord
    below it, rounded to 1e-8 (natural-log units of DN), bit for bit as the torch operations.

    Parameters
    ----------
    intensity : torch.Tensor
        Intensity (relative units, white = 1) of any shape; CPU, float32 or float64.
    knee : float
        The knee (relative units; ``config.dark_intensity``), > 0.
    dn_per_full_scale : float
        Digital numbers (DN) of white (:data:`.pixel.V2E_DN_PER_FULL_SCALE`, v2e's 255).

    Returns
    -------
    torch.Tensor
        The response, a new tensor of ``intensity``'s shape and dtype.

    Raises
    ------
    InputError
        ``knee`` or ``dn_per_full_scale`` not a finite number > 0 (the chord's slope is log(k)/k).

    Examples
    --------
    >>> import torch
    >>> y = fused_linlog_v2e(torch.tensor([1.0, 0.0]), 20 / 255)
    >>> [round(v, 6) for v in y.tolist()]  # log(255) at white, 0 at black
    [5.541264, 0.0]
    """
    for name, v in (("knee", knee), ("dn_per_full_scale", dn_per_full_scale)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"{name}: must be a finite number > 0, got {v!r}")
    lib = library.loaded()
    dtype = intensity.dtype
    suffix = DTYPE_SUFFIX[dtype]
    real = ctypes_real(dtype)
    flat = _flat(intensity, dtype)
    n = flat.numel()
    k = float(knee) * dn_per_full_scale
    out = torch.empty(n, dtype=dtype)
    getattr(lib, f"fsdvs_linlog_clamp_{suffix}")(flat.data_ptr(), n, real(dn_per_full_scale), real(k), out.data_ptr())
    out.log_()  # torch's own log: see the module docstring
    getattr(lib, f"fsdvs_linlog_finish_{suffix}")(
        flat.data_ptr(),
        out.data_ptr(),
        n,
        real(dn_per_full_scale),
        real(k),
        real(math.log(k) / k),
        ROUND_MAGIC,
        out.data_ptr(),
    )
    return out.view(intensity.shape) if n else out.reshape(intensity.shape)


def fused_floor(x: Any, floor: float) -> tuple[Any, int]:
    """The positivity floor without its gradient: ``torch.clamp(x, min=floor)`` and the number of
    values below ``floor``, in one compiled pass (``filtering._FloorSTE`` and its count).

    Parameters
    ----------
    x : torch.Tensor
        Aggregated intensities (relative units) of any shape; CPU, float32 or float64.
    floor : float
        The floor (relative units; ``config.floor_intensity``).

    Returns
    -------
    tuple
        ``(clamped, n_below)``: a new tensor of ``x``'s shape and dtype, and the count (int).

    Examples
    --------
    >>> import torch
    >>> y, n = fused_floor(torch.tensor([0.0, 0.5, 2e-4]), 1e-3)
    >>> y.tolist() == [torch.tensor(1e-3).item(), 0.5, torch.tensor(1e-3).item()], n
    (True, 2)
    """
    lib = library.loaded()
    dtype = x.dtype
    flat = _flat(x, dtype)
    out = torch.empty(flat.numel(), dtype=dtype)
    n_below = getattr(lib, f"fsdvs_floor_count_{DTYPE_SUFFIX[dtype]}")(
        flat.data_ptr(), flat.numel(), ctypes_real(dtype)(floor), out.data_ptr()
    )
    return out.reshape(x.shape), int(n_below)


def _lowpass_expm1(lib: Any, intensity: Any, dt: Any, n: int, hw: int, config: SensorConfig, dtype: Any) -> Any:
    """``expm1`` of every pixel's low-pass exponent ``-2π f_c(I) dt`` over one sub-step (flat, in
    ``dtype``): the exponent by the compiled kernel, then torch's own ``expm1`` (see the module
    docstring). ``dt``: (B,) flat sub-step lengths (s); ``n``: pixels in all, ``hw`` per batch element."""
    em1 = torch.empty(n, dtype=dtype)
    inten = _flat(intensity, dtype)
    real = ctypes_real(dtype)
    getattr(lib, f"fsdvs_lowpass_exponent_{DTYPE_SUFFIX[dtype]}")(
        inten.data_ptr(),
        n,
        hw,
        dt.data_ptr(),
        real(config.dark_intensity),
        real(config.full_scale_intensity),
        real(config.cutoff_hz),
        real(-2.0 * math.pi),
        em1.data_ptr(),
    )
    em1.expm1_()
    return em1


def ctypes_real(dtype: Any) -> Any:
    """The ctypes scalar type of a float32 or float64 torch dtype (rounds a Python float like torch)."""
    return ctypes.c_float if dtype == torch.float32 else ctypes.c_double
