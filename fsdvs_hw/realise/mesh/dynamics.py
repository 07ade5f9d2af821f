r"""Dynamics of a dual resistive mesh: settling times, moving scenes, and when to model them.

Each mesh node has a capacitance :math:`C` to the reference, so KCL becomes
:math:`C\,\dot V = I - g_v V - g_l L V`. In normalised form (:math:`h = g_v V`,
:math:`\tau = C / g_v`) every spatial mode :math:`k` relaxes with its own time constant

.. math:: \tau(k) = \frac{\tau}{1 + \lambda^2 s(k)}, \qquad s(k) = 4 - 2\cos k_x - 2\cos k_y,

so the uniform mode is the slowest: :math:`\tau = C/g_v = C\lambda^2/g_l` (with :math:`g_l` and
:math:`C` fixed, τ grows as λ²). For a scene drifting at velocity :math:`\mathbf v` (px/s) the
steady-state (co-moving) response is exactly

.. math:: \hat H_{\mathbf v}(k) = \frac{1}{1 + \lambda^2 s(k) - i\,\tau\,\mathbf v\cdot k},

so the kernel a moving scene really sees is :func:`drift_kernel`; its relative L2 distance from
the static kernel decides whether the simulator must model the transient
(:func:`mesh_needs_transient`). When it must, :func:`moving_edge_response` integrates the two
meshes in time for a straight edge crossing the array (an edge uniform along y reduces the 2-D
mesh exactly to a 1-D chain with the same conductances).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import InputError

__all__ = [
    "EdgeTransient",
    "TransientDecision",
    "drift_kernel",
    "mesh_needs_transient",
    "mesh_step_response",
    "moving_edge_response",
]


def _check_design(design: Any):
    from .fit import MeshDesign

    if not isinstance(design, MeshDesign):
        raise InputError(f"design: expected a MeshDesign, got {type(design).__name__}")
    return design


def _check_speed(v: Any, name: str = "edge_speed_px_per_s") -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{name}: must be a speed in pixels per second, got {v!r}") from None
    if not (math.isfinite(f) and 0 <= f <= 1e9):
        raise InputError(f"{name}={v!r} outside the allowed range [0, 1e9] px/s")
    return f


def drift_kernel(design: Any, velocity_px_per_s: tuple[float, float], *, size: int | None = None) -> np.ndarray:
    r"""Steady-state kernel of ``design`` for a scene drifting at ``(v_x, v_y)`` px/s.

    Computed exactly on the lattice by a 2-D FFT of :math:`w_p + a\hat H_{v,n} - b\hat H_{v,w}`
    on a periodic grid large enough (≥ 16 λ_wide + size, ≤ 2048) that wrap-around is negligible.

    Returns
    -------
    ndarray, shape (size, size)
        Taps (row y, column x); equals ``design.kernel_taps(size)`` at zero velocity (lattice model).
    """
    design = _check_design(design)
    try:
        vx, vy = (float(c) for c in velocity_px_per_s)
    except (TypeError, ValueError):
        raise InputError(f"velocity_px_per_s: expected (v_x, v_y) in px/s, got {velocity_px_per_s!r}") from None
    for c in (vx, vy):
        _check_speed(abs(c), "velocity_px_per_s component")
    size = design.size if size is None else int(size)
    n = int(2 ** math.ceil(math.log2(max(64, 16 * design.lambda_wide_px + size))))
    n = min(n, 2048)
    k = 2 * np.pi * np.fft.fftfreq(n)
    kx, ky = np.meshgrid(k, k)  # kx varies along columns (x), ky along rows (y)
    s = 4.0 - 2.0 * np.cos(kx) - 2.0 * np.cos(ky)
    # steady state u(ξ) for ξ = x - v t: the phase term uses the continuous wavenumber
    kc = (kx + np.pi) % (2 * np.pi) - np.pi
    kyc = (ky + np.pi) % (2 * np.pi) - np.pi
    vk = vx * kc + vy * kyc
    spec = np.full(s.shape, design.pixel_weight, dtype=np.complex128)
    for gain, lam, tau, sign in (
        (design.gain_narrow, design.lambda_narrow_px, design.tau_narrow_s, 1.0),
        (design.gain_wide, design.lambda_wide_px, design.tau_wide_s, -1.0),
    ):
        spec += sign * gain / (1.0 + lam * lam * s - 1j * tau * vk)
    taps = np.fft.fftshift(np.real(np.fft.ifft2(spec)))
    c, r = n // 2, size // 2
    return taps[c - r : c + r + 1, c - r : c + r + 1]


@dataclass(frozen=True)
class TransientDecision:
    """Whether a scene's motion requires the mesh transient, and why (in numbers).

    Attributes
    ----------
    needed : bool
        True when the drift kernel differs from the static kernel by more than ``tolerance``.
    kernel_error : float
        Worst relative L2 difference between drift and static kernel (axis and diagonal motion).
    tolerance : float
        The threshold used.
    edge_speed_px_per_s : float
        Scene speed.
    tau_max_s : float
        Slowest mesh time constant C/g_v (seconds).
    lag_px : float
        Distance the scene moves in one slowest time constant, ``speed · tau_max_s`` (pixels).
    reason : str
        One line with the numbers.
    """

    needed: bool
    kernel_error: float
    tolerance: float
    edge_speed_px_per_s: float
    tau_max_s: float
    lag_px: float
    reason: str


def mesh_needs_transient(design: Any, edge_speed_px_per_s: float, tolerance: float = 0.01) -> TransientDecision:
    """Decide whether a scene moving at ``edge_speed_px_per_s`` needs the mesh transient modelled.

    The static kernel is the steady state; a moving scene sees :func:`drift_kernel`. If the
    relative L2 difference (worst of motion along an axis and along the diagonal) is at most
    ``tolerance``, the simulator may use the static kernel.

    Parameters
    ----------
    design : MeshDesign
    edge_speed_px_per_s : float
        Fastest image speed in the scene, pixels per second (0 … 1e9).
    tolerance : float
        Allowed relative kernel error (0 < tolerance < 1).

    Examples
    --------
    >>> from fsdvs_hw import fit_resistive_mesh, mesh_needs_transient, reference_kernel
    >>> d = fit_resistive_mesh(reference_kernel("dog", 5))
    >>> mesh_needs_transient(d, edge_speed_px_per_s=1000.0).needed
    False
    """
    design = _check_design(design)
    v = _check_speed(edge_speed_px_per_s)
    if not (isinstance(tolerance, (int, float)) and 0 < tolerance < 1):
        raise InputError(f"tolerance: must be in (0, 1), got {tolerance!r}")
    static = drift_kernel(design, (0.0, 0.0))
    err = 0.0
    for vel in ((v, 0.0), (v / math.sqrt(2), v / math.sqrt(2))):
        dyn = drift_kernel(design, vel)
        err = max(err, float(np.linalg.norm(dyn - static) / np.linalg.norm(static)))
    tau = max(design.tau_narrow_s, design.tau_wide_s)
    needed = err > tolerance
    reason = (
        f"mesh transient {'modelled' if needed else 'skipped'}: at {v:.4g} px/s the scene moves "
        f"{v * tau:.3g} px per slowest time constant tau = C/g_v = {tau:.3g} s; the moving-scene kernel differs "
        f"from the static one by {err:.3g} (relative L2) {'>' if needed else '<='} tolerance {tolerance:g}"
    )
    return TransientDecision(needed, err, float(tolerance), v, tau, v * tau, reason)


@dataclass(frozen=True)
class EdgeTransient:
    """Time-domain response of the dual mesh to a straight edge moving along x.

    Attributes
    ----------
    t_s : ndarray, shape (T,)
        Sample times, seconds.
    x_px : ndarray, shape (N,)
        Pixel positions (columns) of the 1-D chain, pixels.
    output : ndarray, shape (T, N)
        Kernel output ``w_p f + a h_n − b h_w`` with the mesh transient.
    static_output : ndarray, shape (T, N)
        The same with meshes in steady state at every instant (the static kernel).
    edge_speed_px_per_s : float
    """

    t_s: np.ndarray
    x_px: np.ndarray
    output: np.ndarray
    static_output: np.ndarray
    edge_speed_px_per_s: float

    def max_relative_error(self) -> float:
        """max |output − static| / max |static| over the whole run."""
        return float(np.abs(self.output - self.static_output).max() / np.abs(self.static_output).max())


def moving_edge_response(
    design: Any,
    edge_speed_px_per_s: float,
    *,
    n_pixels: int | None = None,
    n_samples: int = 200,
) -> EdgeTransient:
    r"""Integrate both meshes in time for a unit edge sweeping across a 1-D chain of pixels.

    The edge starts left of the chain, at ``x = -0.5`` px, and moves right; pixel ``j`` sees the
    fraction of its area covered, :math:`f_j(t) = \mathrm{clip}(v t - j + 0.5, 0, 1)` (linear
    photocurrent). Each mesh obeys :math:`\tau\dot h = f - (1 + \lambda^2 L_1) h` (open chain
    ends), integrated per DCT mode with an exponential integrator that is exact for an input linear
    over each step (steps of at most 0.02 px of edge travel; stable for any τ).

    Parameters
    ----------
    design : MeshDesign
    edge_speed_px_per_s : float
        Edge speed, pixels per second (> 0).
    n_pixels : int, optional
        Chain length (default ``2·ceil(6 λ_wide) + 21``).
    n_samples : int
        Output samples over the run (edge crossing the whole chain).
    """
    from .response import dct_basis

    design = _check_design(design)
    v = _check_speed(edge_speed_px_per_s)
    if v <= 0:
        raise InputError("edge_speed_px_per_s: must be > 0 for a moving edge")
    if n_pixels is None:
        n_pixels = 2 * int(math.ceil(6 * design.lambda_wide_px)) + 21
    if not (isinstance(n_pixels, (int, np.integer)) and 3 <= n_pixels <= 4096):
        raise InputError(f"n_pixels: must be an integer in 3..4096, got {n_pixels!r}")
    if not (isinstance(n_samples, (int, np.integer)) and 2 <= n_samples <= 100000):
        raise InputError(f"n_samples: must be an integer in 2..100000, got {n_samples!r}")
    phi, s = dct_basis(int(n_pixels))
    x = np.arange(n_pixels, dtype=np.float64)
    t_end = (n_pixels + 1.0) / v
    meshes = []
    for gain, lam, tau, sign in (
        (design.gain_narrow, design.lambda_narrow_px, design.tau_narrow_s, 1.0),
        (design.gain_wide, design.lambda_wide_px, design.tau_wide_s, -1.0),
    ):
        mu = (1.0 + lam * lam * s) / tau  # per-mode decay rate, 1/s
        meshes.append((sign * gain, mu, 1.0 / (1.0 + lam * lam * s)))
    dt = min(0.02 / v, t_end / n_samples)
    n_steps = int(math.ceil(t_end / dt))
    dt = t_end / n_steps
    sample_every = max(1, n_steps // n_samples)
    cover = lambda t: np.clip(v * t - x + 0.5, 0.0, 1.0)  # noqa: E731
    states = [np.zeros(n_pixels) for _ in meshes]
    # exact one-step propagators for an input linear in time over the step (first-order hold)
    props = []
    for _, mu, _dc in meshes:
        z = mu * dt
        e0 = -np.expm1(-z)  # 1 - exp(-z)
        e1 = np.where(z > 1e-8, 1.0 - e0 / np.where(z > 1e-8, z, 1.0), z / 2)  # 1 - (1 - exp(-z))/z
        props.append((1.0 - e0, e0, e1))
    ts, outs, stats = [], [], []
    f_prev = phi.T @ cover(0.0)
    for step in range(1, n_steps + 1):
        f_next = phi.T @ cover(step * dt)
        for i, (_, _mu, dc) in enumerate(meshes):
            # mode equation dy/dt = mu (dc f(t) - y), f linear over the step: exact update
            decay, e0, e1 = props[i]
            states[i] = decay * states[i] + dc * (e0 * f_prev + e1 * (f_next - f_prev))
        f_prev = f_next
        if step % sample_every == 0 or step == n_steps:
            t = step * dt
            f = cover(t)
            fm = phi.T @ f
            out = design.pixel_weight * f
            stat = design.pixel_weight * f
            for (g, _, dc), y in zip(meshes, states):
                out = out + g * (phi @ y)
                stat = stat + g * (phi @ (dc * fm))
            ts.append(t)
            outs.append(out)
            stats.append(stat)
    return EdgeTransient(np.array(ts), x, np.array(outs), np.array(stats), v)


def mesh_step_response(
    g_lateral_s: float, g_vertical_s: float, node_capacitance_f: float, half_width: int, t_s: Any
) -> np.ndarray:
    r"""Exact node voltages of a finite mesh after a unit current step into its centre node.

    Solves :math:`C\dot V = e_c\,H(t) - (g_v + g_l L) V`, :math:`V(0) = 0`, on the open-edge
    (2h+1)² grid by its DCT modes:
    :math:`V(t) = \sum_{ij} \phi_{ij}(c)\,\phi_{ij}\,(1 - e^{-G_{ij} t / C}) / G_{ij}` with
    :math:`G_{ij} = g_v + g_l (s_i + s_j)`.

    Parameters
    ----------
    g_lateral_s, g_vertical_s : float
        Conductances in siemens.
    node_capacitance_f : float
        Node capacitance in farads (> 0).
    half_width : int
        Grid half-width h in pixels.
    t_s : array_like
        Times in seconds (≥ 0).

    Returns
    -------
    ndarray, shape (T, 2h+1, 2h+1)
        Node voltage per ampere of step (V/A = Ω).
    """
    from .response import check_radius, dct_basis, space_constant_px

    space_constant_px(g_lateral_s, g_vertical_s)  # validates both conductances
    c = float(node_capacitance_f)
    if not (math.isfinite(c) and c > 0):
        raise InputError(f"node_capacitance_f: must be a positive capacitance in farads, got {node_capacitance_f!r}")
    h = check_radius(half_width, "half_width")
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    if np.any(~np.isfinite(t)) or np.any(t < 0):
        raise InputError("t_s: times must be finite and ≥ 0 seconds")
    n = 2 * h + 1
    phi, s = dct_basis(n)
    g = g_vertical_s + g_lateral_s * (s[:, None] + s[None, :])
    c0 = np.outer(phi[h], phi[h])
    out = np.empty((t.size, n, n))
    for k, tk in enumerate(t):
        out[k] = phi @ (c0 * (-np.expm1(-g * tk / c)) / g) @ phi.T
    return out
