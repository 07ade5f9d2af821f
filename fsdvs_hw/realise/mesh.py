r"""Dual resistive-mesh realisation of a centre-surround kernel, fitted with IPOPT.

The circuit
-----------
Every pixel injects its (linear) signal as a **current** into its own node of two square resistive
meshes, a narrow one and a wide one (lateral conductance :math:`g_l`, vertical conductance
:math:`g_v` per mesh, space constant :math:`\lambda = \sqrt{g_l/g_v}` pixel pitches; see
:mod:`fsdvs_hw.realise.mesh_response`). Each node voltage is read out through a transconductor
whose gain is normalised so that a uniform input gives that mesh path a DC gain of exactly
:math:`a` (narrow) or :math:`b` (wide); the pixel's own signal is added with weight :math:`w_p`.
The realised kernel is

.. math:: K = w_p\,\delta + a\,H_{\lambda_n} - b\,H_{\lambda_w},

with :math:`H_\lambda` the mesh impulse response normalised to unit sum (lattice Green's function).
The DC gain of :math:`K` is :math:`w_p + a - b`. The paper's sketch fixes :math:`w_p = 1`; a
free :math:`w_p` (``pixel_weight=None``) lets the mesh pair act as a plain difference of meshes.

The fit
-------
:func:`fit_resistive_mesh` minimises, with IPOPT through casadi's ``nlpsol``, the expected
squared relative kernel error under a die-level conductance mismatch of relative standard
deviation σ (``mismatch_sigma``):

.. math:: J = \frac{\lVert K - T\rVert^2}{\lVert T\rVert^2} + \sigma^2 S^2, \qquad
   S^2 = \frac{1}{\lVert T\rVert^2}\sum_p \Big\lVert \frac{\partial K}{\partial \ln p}\Big\rVert^2,

over :math:`p \in \{g_{l,n}, g_{v,n}, g_{l,w}, g_{v,w}, a, b, w_p\}`. Without the σ term the best
fits often collapse to :math:`\lambda_n \approx \lambda_w` with huge opposing gains: numerically
excellent, physically unbuildable (1 % mismatch then gives tens of % kernel error). Variables are
logarithms (:math:`\ln\lambda^2 = \ln(g_l/g_v)`, :math:`\ln a`, :math:`\ln b`, :math:`\ln w_p`)
inside physical bounds (:class:`MeshBounds`), with :math:`\lambda_w / \lambda_n \ge`
``min_lambda_ratio``. With both λ fixed the kernel is linear in the gains, so IPOPT starts from
the best bounded least-squares solution over a coarse (λ_n, λ_w) grid. Mesh kernels are
D4-symmetric; an asymmetric target is fitted in the least-squares sense (its symmetric part) and
:class:`MeshAsymmetryWarning` says how much of it cannot be realised.

Absolute conductances: the lateral conductance of both meshes is ``g_lateral_s`` (default 10 nS,
a subthreshold diffusor transistor); :math:`g_v = g_l/\lambda^2`. With a node capacitance
:math:`C` the uniform mode settles with :math:`\tau = C/g_v = C\lambda^2/g_l`
(:mod:`fsdvs_hw.realise.mesh_dynamics`).
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..kernels import DEFAULT_PITCH_M, MAX_KERNEL_SIZE, Kernel, _validate_pitch
from ..validation import check_fit_arguments
from .base import CostItem, kernel_error
from .mesh_response import (
    LAMBDA_RANGE_PX,
    _dct_basis,
    _green_terms,
    _unfold_quarter,
    finite_grid_response,
    lattice_green_quarter,
    quadrature_nodes,
    space_constant_px,
)

__all__ = [
    "MeshBounds",
    "MeshDesign",
    "MeshAsymmetryWarning",
    "MeshFitWarning",
    "MESH_MODELS",
    "fit_resistive_mesh",
    "mismatch_sensitivity",
]

#: Single-mesh models: "lattice" = infinite lattice (exact Green's function, the default);
#: "grid" = finite open-edge grid of half-width ``grid_half_width`` (DCT, exact).
MESH_MODELS = ("lattice", "grid")

_DEFAULT_G_LATERAL_S = 1e-8
_DEFAULT_C_NODE_F = 100e-15


class MeshAsymmetryWarning(UserWarning):
    """The target kernel is not D4-symmetric; only its symmetric part can be realised by a mesh."""


class MeshFitWarning(UserWarning):
    """The fit is unusable: worse than no kernel at all, or IPOPT did not converge."""


@dataclass(frozen=True)
class MeshBounds:
    """Physical bounds of the dual-mesh fit.

    Parameters
    ----------
    lambda_px : (float, float)
        Allowed space constants in pixel pitches (both meshes).
    gain : (float, float)
        Allowed DC gains a, b of the mesh paths and, when free, the pixel weight (dimensionless,
        positive: transconductor / current-mirror ratios).
    min_lambda_ratio : float
        Smallest λ_wide / λ_narrow (≥ 1).
    conductance_s : (float, float)
        Allowed conductances in siemens; with ``g_lateral_s`` fixed this bounds λ as well.
    """

    lambda_px: tuple[float, float] = (0.1, 20.0)
    gain: tuple[float, float] = (1e-4, 10.0)
    min_lambda_ratio: float = 1.5
    conductance_s: tuple[float, float] = (1e-13, 1e-3)

    def __post_init__(self) -> None:
        for name in ("lambda_px", "gain", "conductance_s"):
            v = getattr(self, name)
            try:
                lo, hi = (float(x) for x in v)
            except (TypeError, ValueError):
                raise InputError(f"bounds.{name}: must be a (low, high) pair of numbers, got {v!r}") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
                raise InputError(f"bounds.{name}: need 0 < low < high (finite), got ({lo!r}, {hi!r})")
            object.__setattr__(self, name, (lo, hi))
        lo, hi = self.lambda_px
        if lo < LAMBDA_RANGE_PX[0] or hi > LAMBDA_RANGE_PX[1]:
            raise InputError(f"bounds.lambda_px=({lo:g}, {hi:g}) px exceeds the modelled range {LAMBDA_RANGE_PX} px")
        r = self.min_lambda_ratio
        if not (isinstance(r, (int, float)) and math.isfinite(r) and 1.0 <= r < hi / lo):
            raise InputError(
                f"bounds.min_lambda_ratio={r!r}: must be ≥ 1 and below lambda_px high/low = {hi / lo:g}"
            )


# ---------------------------------------------------------------------- orbits (D4 symmetry)
def _orbits(radius: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orbit representatives (i ≥ j ≥ 0) of the D4 group on the (2r+1)² window, and multiplicities."""
    ii, jj, mult = [], [], []
    for i in range(radius + 1):
        for j in range(i + 1):
            ii.append(i)
            jj.append(j)
            mult.append(1 if i == 0 else (4 if (j == 0 or i == j) else 8))
    return np.array(ii), np.array(jj), np.array(mult, dtype=np.float64)


def _d4_symmetrise(taps: np.ndarray) -> np.ndarray:
    group = [taps, taps.T, taps[::-1], taps[:, ::-1], taps[::-1, ::-1], taps.T[::-1], taps.T[:, ::-1], taps.T[::-1, ::-1]]
    return np.mean(group, axis=0)


# ---------------------------------------------------------------------- the design
@dataclass(frozen=True, eq=False)
class MeshDesign:
    """A dual resistive mesh: what to build, and what kernel it really applies.

    Parameters
    ----------
    g_lateral_narrow_s, g_vertical_narrow_s : float
        Narrow mesh conductances (node to neighbour, node to reference), siemens.
    g_lateral_wide_s, g_vertical_wide_s : float
        Wide mesh conductances, siemens.
    gain_narrow, gain_wide : float
        DC gains a, b of the narrow (added) and wide (subtracted) paths.
    pixel_weight : float
        Weight w_p of the pixel's own signal.
    size : int
        Odd side of the kernel window (pixels) that :meth:`kernel` returns by default.
    pitch_m : float
        Pixel pitch in metres.
    node_capacitance_f : float
        Capacitance of each mesh node to the reference, farads (sets the settling time).
    model : {"lattice", "grid"}
        Infinite lattice (pixel far from the array edge), or a finite grid of ``grid_half_width``.
    grid_half_width : int or None
        Half-width (pixels) of the finite grid when ``model == "grid"``.
    target : Kernel or None
        The kernel this design was fitted to.
    fit : dict
        Fit report (errors, solver status, iterations, wall time, starts); empty if not fitted.
    """

    g_lateral_narrow_s: float
    g_vertical_narrow_s: float
    g_lateral_wide_s: float
    g_vertical_wide_s: float
    gain_narrow: float
    gain_wide: float
    pixel_weight: float = 1.0
    size: int = 7
    pitch_m: float = DEFAULT_PITCH_M
    node_capacitance_f: float = _DEFAULT_C_NODE_F
    model: str = "lattice"
    grid_half_width: int | None = None
    target: Kernel | None = None
    fit: Mapping[str, Any] = field(default_factory=dict)
    kind: str = field(default="mesh", init=False)

    def __post_init__(self) -> None:
        self.lambda_narrow_px  # validates conductances  # noqa: B018
        self.lambda_wide_px  # noqa: B018
        for name in ("g_lateral_narrow_s", "g_vertical_narrow_s", "g_lateral_wide_s", "g_vertical_wide_s"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "pitch_m", _validate_pitch(self.pitch_m, source="MeshDesign.pitch_m"))
        for name in ("gain_narrow", "gain_wide", "pixel_weight", "node_capacitance_f"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v >= 0):
                raise InputError(f"MeshDesign.{name}: must be a finite number ≥ 0, got {v!r}")
            object.__setattr__(self, name, float(v))
        if not (isinstance(self.size, (int, np.integer)) and self.size % 2 == 1 and 1 <= self.size <= MAX_KERNEL_SIZE):
            raise InputError(f"MeshDesign.size: must be odd in 1..{MAX_KERNEL_SIZE}, got {self.size!r}")
        if self.model not in MESH_MODELS:
            raise InputError(f"MeshDesign.model={self.model!r} unknown; allowed {MESH_MODELS}")
        if self.model == "grid":
            h = self.grid_half_width
            if not (isinstance(h, (int, np.integer)) and self.size // 2 <= h <= 512):
                raise InputError(
                    f"MeshDesign.grid_half_width: model 'grid' needs an integer in {self.size // 2}..512, got {h!r}"
                )
        object.__setattr__(self, "fit", dict(self.fit))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_space_constants(
        cls,
        lambda_narrow_px: float,
        lambda_wide_px: float,
        gain_narrow: float,
        gain_wide: float,
        *,
        pixel_weight: float = 1.0,
        g_lateral_s: float = _DEFAULT_G_LATERAL_S,
        **kwargs: Any,
    ) -> MeshDesign:
        """A design from λ (pixels) and gains; both meshes use lateral conductance ``g_lateral_s`` (S)."""
        for name, lam in (("lambda_narrow_px", lambda_narrow_px), ("lambda_wide_px", lambda_wide_px)):
            if not (isinstance(lam, (int, float, np.floating)) and math.isfinite(lam) and lam > 0):
                raise InputError(f"{name}: must be a positive number of pixels, got {lam!r}")
        g = float(g_lateral_s)
        return cls(
            g_lateral_narrow_s=g,
            g_vertical_narrow_s=g / lambda_narrow_px**2,
            g_lateral_wide_s=g,
            g_vertical_wide_s=g / lambda_wide_px**2,
            gain_narrow=gain_narrow,
            gain_wide=gain_wide,
            pixel_weight=pixel_weight,
            **kwargs,
        )

    # ------------------------------------------------------------------ physics
    @property
    def lambda_narrow_px(self) -> float:
        """Space constant of the narrow mesh, pixel pitches."""
        return space_constant_px(self.g_lateral_narrow_s, self.g_vertical_narrow_s)

    @property
    def lambda_wide_px(self) -> float:
        """Space constant of the wide mesh, pixel pitches."""
        return space_constant_px(self.g_lateral_wide_s, self.g_vertical_wide_s)

    @property
    def tau_narrow_s(self) -> float:
        """Settling time constant C/g_v of the narrow mesh's uniform mode, seconds."""
        return self.node_capacitance_f / self.g_vertical_narrow_s

    @property
    def tau_wide_s(self) -> float:
        """Settling time constant C/g_v of the wide mesh's uniform mode, seconds."""
        return self.node_capacitance_f / self.g_vertical_wide_s

    def mesh_responses(self, radius: int) -> tuple[np.ndarray, np.ndarray]:
        """Unit-sum impulse responses (H_narrow, H_wide) on the (2r+1)² window, this design's model."""
        out = []
        for lam in (self.lambda_narrow_px, self.lambda_wide_px):
            if self.model == "grid":
                # a finite chip: taps beyond its edge do not exist (zero)
                h = int(self.grid_half_width)
                out.append(np.pad(finite_grid_response(lam, min(radius, h), h), max(0, radius - h)))
            else:
                out.append(_unfold_quarter(np.asarray(lattice_green_quarter(lam, radius))))
        return out[0], out[1]

    def kernel_taps(self, size: int | None = None) -> np.ndarray:
        """Taps of the realised kernel on a ``size`` × ``size`` window (default :attr:`size`)."""
        size = self.size if size is None else size
        if not (isinstance(size, (int, np.integer)) and size % 2 == 1 and 1 <= size <= MAX_KERNEL_SIZE):
            raise InputError(f"size: must be odd in 1..{MAX_KERNEL_SIZE}, got {size!r}")
        r = size // 2
        hn, hw = self.mesh_responses(r)
        k = self.gain_narrow * hn - self.gain_wide * hw
        k[r, r] += self.pixel_weight
        return k

    def kernel(self, size: int | None = None) -> Kernel:
        """The kernel the circuit really applies, on a ``size`` × ``size`` window (default :attr:`size`).

        The mesh response has infinite support; :meth:`cost` reports the energy outside the window
        (``tail_energy_fraction``).
        """
        taps = self.kernel_taps(size)
        prov = {
            "realisation": "mesh",
            "lambda_narrow_px": self.lambda_narrow_px,
            "lambda_wide_px": self.lambda_wide_px,
            "gain_narrow": self.gain_narrow,
            "gain_wide": self.gain_wide,
            "pixel_weight": self.pixel_weight,
            "model": self.model,
        }
        name = f"mesh({self.target.name})" if self.target is not None else "mesh"
        return Kernel(taps, pitch_m=self.pitch_m, name=name, provenance=prov)

    def tail_energy_fraction(self, size: int | None = None) -> float:
        """Fraction of the kernel's energy (Σ K²) outside the ``size`` window (default :attr:`size`)."""
        size = self.size if size is None else size
        big = min(MAX_KERNEL_SIZE, size + 2 * int(math.ceil(5 * self.lambda_wide_px)))
        kb = self.kernel_taps(big)
        c = (big - size) // 2
        inner = kb[c : c + size, c : c + size]
        tot = float((kb * kb).sum())
        return float(max(0.0, 1.0 - (inner * inner).sum() / tot)) if tot > 0 else 0.0

    # ------------------------------------------------------------------ protocol
    def cost(self) -> dict[str, CostItem]:
        """Conductances (S), space constants (px, m), settling times (s), component counts, errors."""
        c = {
            "g_lateral_narrow": CostItem(self.g_lateral_narrow_s, "S", "narrow mesh, node-to-neighbour conductance"),
            "g_vertical_narrow": CostItem(self.g_vertical_narrow_s, "S", "narrow mesh, node-to-reference conductance"),
            "g_lateral_wide": CostItem(self.g_lateral_wide_s, "S", "wide mesh, node-to-neighbour conductance"),
            "g_vertical_wide": CostItem(self.g_vertical_wide_s, "S", "wide mesh, node-to-reference conductance"),
            "lambda_narrow_px": CostItem(self.lambda_narrow_px, "px", "narrow space constant sqrt(g_l/g_v)"),
            "lambda_wide_px": CostItem(self.lambda_wide_px, "px", "wide space constant sqrt(g_l/g_v)"),
            "lambda_narrow_m": CostItem(self.lambda_narrow_px * self.pitch_m, "m", "narrow space constant"),
            "lambda_wide_m": CostItem(self.lambda_wide_px * self.pitch_m, "m", "wide space constant"),
            "tau_narrow": CostItem(self.tau_narrow_s, "s", "narrow mesh settling time constant C/g_v"),
            "tau_wide": CostItem(self.tau_wide_s, "s", "wide mesh settling time constant C/g_v"),
            "node_capacitance": CostItem(self.node_capacitance_f, "F", "capacitance per mesh node"),
            "gain_narrow": CostItem(self.gain_narrow, "1", "DC gain of the narrow path"),
            "gain_wide": CostItem(self.gain_wide, "1", "DC gain of the wide path"),
            "pixel_weight": CostItem(self.pixel_weight, "1", "weight of the pixel's own signal"),
            "resistors_per_pixel": CostItem(6, "count", "2 meshes x (2 lateral + 1 vertical) conductances"),
            "capacitors_per_pixel": CostItem(2, "count", "one node capacitance per mesh"),
            "transconductors_per_pixel": CostItem(
                5, "count", "2 input injections + 3 weighted outputs (pixel, narrow, wide)"
            ),
            "mismatch_sensitivity": CostItem(mismatch_sensitivity(self), "1", "relative kernel error per unit relative die-level mismatch"),
            "tail_energy_fraction": CostItem(self.tail_energy_fraction(), "1", "kernel energy outside the window"),
        }
        if "error" in self.fit:
            c["kernel_error"] = CostItem(self.fit["error"], "1", "relative L2 error vs target on the window")
        return c

    def describe(self) -> str:
        lines = [
            f"dual resistive mesh ({self.model}{'' if self.model == 'lattice' else f', half-width {self.grid_half_width} px'}):"
            f" K = {self.pixel_weight:.4g} d + {self.gain_narrow:.4g} H(lambda={self.lambda_narrow_px:.4g} px)"
            f" - {self.gain_wide:.4g} H(lambda={self.lambda_wide_px:.4g} px)",
            f"  narrow: g_l = {self.g_lateral_narrow_s:.3g} S, g_v = {self.g_vertical_narrow_s:.3g} S,"
            f" lambda = {self.lambda_narrow_px * self.pitch_m * 1e6:.3g} um, tau = {self.tau_narrow_s:.3g} s",
            f"  wide:   g_l = {self.g_lateral_wide_s:.3g} S, g_v = {self.g_vertical_wide_s:.3g} S,"
            f" lambda = {self.lambda_wide_px * self.pitch_m * 1e6:.3g} um, tau = {self.tau_wide_s:.3g} s",
        ]
        if self.fit:
            f = self.fit
            lines.append(
                f"  fit to '{self.target.name if self.target is not None else '?'}': kernel error {f.get('error', float('nan')):.3g}"
                f" (window), {f.get('error_full', float('nan')):.3g} (with tail); {f.get('status')} after"
                f" {f.get('iterations')} iterations, {f.get('wall_s', float('nan')):.3g} s"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        d = {k: v for k, v in asdict(self).items() if k not in ("target", "fit", "kind")}
        d["kind"] = self.kind
        d["target"] = None if self.target is None else self.target.to_dict()
        d["fit"] = dict(self.fit)
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MeshDesign:
        if not isinstance(data, Mapping) or data.get("kind") != "mesh":
            raise InputError("MeshDesign.from_dict: expected a dict with kind 'mesh'")
        fields = {
            "g_lateral_narrow_s", "g_vertical_narrow_s", "g_lateral_wide_s", "g_vertical_wide_s",
            "gain_narrow", "gain_wide", "pixel_weight", "size", "pitch_m", "node_capacitance_f",
            "model", "grid_half_width",
        }
        missing = {"g_lateral_narrow_s", "g_vertical_narrow_s", "g_lateral_wide_s", "g_vertical_wide_s", "gain_narrow", "gain_wide"} - set(data)
        if missing:
            raise InputError(f"MeshDesign.from_dict: missing field(s) {sorted(missing)}")
        kw = {k: data[k] for k in fields if k in data}
        t = data.get("target")
        kw["target"] = None if t is None else Kernel.from_dict(t, source="mesh.target")
        return cls(**kw, fit=data.get("fit", {}))


# ---------------------------------------------------------------------- sensitivity
def _sensitivity_sq(gn, gw, wp, hn, hw, dhn, dhw, weights, norm2) -> float:
    """S² from window responses (weights: orbit multiplicities or ones)."""
    s = (
        2 * gn * gn * (weights * dhn * dhn).sum()
        + 2 * gw * gw * (weights * dhw * dhw).sum()
        + gn * gn * (weights * hn * hn).sum()
        + gw * gw * (weights * hw * hw).sum()
        + wp * wp
    )
    return float(s / norm2)


def mismatch_sensitivity(design: MeshDesign, target: Kernel | None = None) -> float:
    r"""Relative kernel error per unit relative (die-level) mismatch of each parameter.

    :math:`S = \sqrt{\sum_p \lVert \partial K / \partial \ln p \rVert^2} / \lVert T \rVert` over the
    four conductances, the two path gains and the pixel weight, on the design's window; ``T`` is
    ``target`` (default: the design's target, else its own kernel). A die-level mismatch of σ
    (relative, independent per parameter) then gives an expected relative error of about σ·S.
    """
    r = design.size // 2
    hn, dhn = _responses_and_derivatives(design.lambda_narrow_px, r, design.model, design.grid_half_width)
    hw, dhw = _responses_and_derivatives(design.lambda_wide_px, r, design.model, design.grid_half_width)
    t = target if target is not None else (design.target if design.target is not None else design.kernel())
    tt = t.taps if t.size == design.size else t.padded(design.size).taps if t.size < design.size else t.cropped(design.size).taps
    s2 = _sensitivity_sq(design.gain_narrow, design.gain_wide, design.pixel_weight, hn, hw, dhn, dhw, 1.0, float((tt * tt).sum()))
    return math.sqrt(s2)


def _responses_and_derivatives(lam: float, radius: int, model: str, half_width: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Full-window H and ∂H/∂ln(λ²) for one mesh."""
    if model == "grid":
        h = max(int(half_width), radius)
        eps = 1e-5
        hp = finite_grid_response(lam * math.exp(eps / 2), radius, h)
        hm = finite_grid_response(lam * math.exp(-eps / 2), radius, h)
        return finite_grid_response(lam, radius, h), (hp - hm) / (2 * eps)
    q, dq = lattice_green_quarter(lam, radius, derivative=True)
    return _unfold_quarter(q), _unfold_quarter(dq * lam * lam)


# ---------------------------------------------------------------------- casadi models of H on orbits
def _casadi_orbit_response(u, radius: int, model: str, lam_max: float, half_width: int | None):
    """SX expression: unit-sum mesh response on the D4 orbits as a function of u = ln λ²."""
    import casadi as ca

    ii, jj, _ = _orbits(radius)
    lam2 = ca.exp(u)
    if model == "lattice":
        k, w = quadrature_nodes(lam_max, radius)
        c = ca.DM(2.0 - 2.0 * np.cos(k))
        rho, inv_sq = _green_terms(lam2, c, xp=ca)
        cos_w = ca.DM(np.cos(np.outer(np.arange(radius + 1), k)) * w)  # (m, node)
        pows = ca.horzcat(*[rho**j for j in range(radius + 1)])  # (node, n)
        q = ca.mtimes(cos_w, pows * ca.repmat(inv_sq, 1, radius + 1))
    else:
        n = 2 * half_width + 1
        phi, s = _dct_basis(n)
        c0 = phi[half_width]
        m = ca.DM(np.outer(c0, c0)) / (1.0 + lam2 * ca.DM(s[:, None] + s[None, :]))
        p = ca.DM(phi[half_width : half_width + radius + 1])
        q = ca.mtimes([p, m, p.T])
    return ca.vertcat(*[q[int(i), int(j)] for i, j in zip(ii, jj)])


def _numpy_orbit_response(lam: float, radius: int, model: str, half_width: int | None, nodes=None):
    """(H, ∂H/∂ln λ²) on the D4 orbits, numpy."""
    ii, jj, _ = _orbits(radius)
    if model == "lattice":
        q, dq = lattice_green_quarter(lam, radius, derivative=True, nodes=nodes)
        return q[ii, jj], dq[ii, jj] * lam * lam
    h, dh = _responses_and_derivatives(lam, radius, model, half_width)
    return h[radius + ii, radius + jj], dh[radius + ii, radius + jj]


# ---------------------------------------------------------------------- the fit
@functools.lru_cache(maxsize=32)
def _mesh_solver(radius: int, model: str, lam_max: float, half_width: int | None, free_wp: bool, max_iter: int, tol: float):
    """IPOPT solver of the dual-mesh fit for one problem structure; target and weights are parameters."""
    import casadi as ca

    ii, jj, mult = _orbits(radius)
    n_orb = len(ii)
    # one mesh as a scalar-expression (SX) function of u = ln λ², with its derivative; the NLP
    # graph (MX) calls it twice, so the exact Hessian is built from this small function's AD
    u = ca.SX.sym("u")
    h_u = _casadi_orbit_response(u, radius, model, lam_max, half_width)
    mesh_h = ca.Function("mesh_h", [u], [h_u, ca.jacobian(h_u, u)])
    nx = 5 if free_wp else 4
    x = ca.MX.sym("x", nx)
    p = ca.MX.sym("p", n_orb + 3)  # target on the orbits, 1/||T||^2, sigma^2, fixed pixel weight
    t_orb, inv_norm2, sigma2, wp_fixed = p[:n_orb], p[n_orb], p[n_orb + 1], p[n_orb + 2]
    hn, dhn = mesh_h(x[0])
    hw, dhw = mesh_h(x[1])
    a, b = ca.exp(x[2]), ca.exp(x[3])
    wp = ca.exp(x[4]) if free_wp else wp_fixed
    m = ca.DM(mult)
    resid = wp * ca.DM((ii == 0).astype(float)) + a * hn - b * hw - t_orb
    err2 = ca.dot(m, resid**2) * inv_norm2
    sens2 = (
        2 * a**2 * ca.dot(m, dhn**2)
        + 2 * b**2 * ca.dot(m, dhw**2)
        + a**2 * ca.dot(m, hn**2)
        + b**2 * ca.dot(m, hw**2)
        + wp**2
    ) * inv_norm2
    opts = {
        "ipopt.print_level": 0,
        "print_time": False,
        "ipopt.sb": "yes",
        "ipopt.max_iter": max_iter,
        "ipopt.tol": tol,
        "ipopt.acceptable_tol": 1e-10,
        "ipopt.mu_strategy": "adaptive",
    }
    return ca.nlpsol("mesh_fit", "ipopt", {"x": x, "p": p, "f": err2 + sigma2 * sens2, "g": x[1] - x[0]}, opts)


def _coerce_kernel(kernel: Any, pitch_m: float | None) -> Kernel:
    if isinstance(kernel, Kernel):
        return kernel if pitch_m is None else Kernel(kernel.taps, pitch_m=pitch_m, name=kernel.name, provenance=kernel.provenance)
    if isinstance(kernel, (str, bytes)) or kernel is None:
        raise InputError(f"kernel: expected a fsdvs_hw Kernel or a 2-D array of taps, got {type(kernel).__name__}")
    return Kernel(kernel, pitch_m=DEFAULT_PITCH_M if pitch_m is None else pitch_m, name="target")


def _check_scalar(name: str, v: Any, lo: float, hi: float) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{name}: must be a number, got {v!r}") from None
    if not (math.isfinite(f) and lo <= f <= hi):
        raise InputError(f"{name}={v!r} outside the allowed range [{lo:g}, {hi:g}]")
    return f


def fit_resistive_mesh(
    kernel: Kernel | np.ndarray,
    *,
    bounds: MeshBounds | Mapping[str, Any] | None = None,
    pitch_m: float | None = None,
    pixel_weight: float | str | None = 1.0,
    mismatch_sigma: float = 0.01,
    g_lateral_s: float = _DEFAULT_G_LATERAL_S,
    node_capacitance_f: float = _DEFAULT_C_NODE_F,
    model: str = "lattice",
    grid_half_width: int | None = None,
    fit_size: int | None = None,
    n_init: int = 10,
    max_iter: int = 200,
    tol: float = 1e-14,
) -> MeshDesign:
    r"""Fit a dual resistive mesh to ``kernel`` with IPOPT (casadi ``nlpsol``).

    Parameters
    ----------
    kernel : Kernel or array_like
        Target kernel (odd square taps). Its absolute scale matters (no free overall gain) unless
        ``pixel_weight=None``.
    bounds : MeshBounds or mapping, optional
        λ range (px), gain range, minimum λ_wide/λ_narrow, conductance range (S); a mapping of
        :class:`MeshBounds` fields is accepted (design files).
    pitch_m : float, optional
        Pixel pitch in metres (default: the kernel's).
    pixel_weight : float, None or "free"
        Fixed weight of the pixel's own signal (1.0: the paper's sketch), or None / "free" to fit
        it within ``bounds.gain``.
    mismatch_sigma : float
        Relative die-level conductance/gain mismatch σ (0 … 0.5) whose expected error the fit
        adds to the objective (0 disables the penalty: best nominal fit, possibly unbuildable).
    g_lateral_s : float
        Lateral conductance of both meshes, siemens; g_v = g_l / λ².
    node_capacitance_f : float
        Node capacitance (F) of both meshes, for the settling time.
    model : {"lattice", "grid"}
        Single-mesh model used in the fit: infinite lattice (exact lattice Green's function), or a
        finite open-edge grid of half-width ``grid_half_width`` pixels (exact DCT form).
    grid_half_width : int, optional
        Required with ``model="grid"``.
    fit_size : int, optional
        Odd window (pixels, ≥ the target's size) on which the error is minimised, the target being
        zero outside its own window. Default: the target's size (the mesh tail outside it is then
        free; ``fit["error_full"]`` reports what it costs). A larger window also penalises the tail.
    n_init : int
        λ values per mesh in the least-squares initialisation grid (2 … 40).
    max_iter, tol : int, float
        IPOPT iteration limit and tolerance.

    Returns
    -------
    MeshDesign
        With ``fit`` = {"error", "error_full", "error_symmetric_part", "asymmetry",
        "mismatch_sensitivity", "objective", "status", "success", "iterations", "wall_s",
        "init_objective", "model", "mismatch_sigma", "pixel_weight_free"} (objectives: J above, on
        the symmetric part of the target).

    Raises
    ------
    InputError
        Invalid kernel, bounds or options (the message names the argument and allowed range).

    Warns
    -----
    MeshAsymmetryWarning
        The target is not D4-symmetric (relative asymmetric part > 1e-6).
    MeshFitWarning
        The fit is no better than a zero kernel (error ≥ 0.999: target scale out of reach), or
        IPOPT did not report success.
    """
    check_fit_arguments("mesh", locals())  # fsdvs_hw.validation: same limits as design files
    import casadi as ca
    from scipy.optimize import lsq_linear

    t0 = time.perf_counter()
    target = _coerce_kernel(kernel, pitch_m)
    if bounds is None:
        bounds = MeshBounds()
    elif isinstance(bounds, Mapping):  # e.g. a [realisations.mesh.bounds] table of a design file
        unknown = set(bounds) - set(MeshBounds.__dataclass_fields__)
        if unknown:
            raise InputError(f"bounds: unknown key(s) {sorted(unknown)}; allowed {sorted(MeshBounds.__dataclass_fields__)}")
        bounds = MeshBounds(**{k: (tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in bounds.items()})
    if not isinstance(bounds, MeshBounds):
        raise InputError(f"bounds: expected a MeshBounds or a mapping of its fields, got {type(bounds).__name__}")
    if isinstance(pixel_weight, str):
        if pixel_weight != "free":
            raise InputError(f"pixel_weight: a number, None or 'free', got {pixel_weight!r}")
        pixel_weight = None
    sigma = _check_scalar("mismatch_sigma", mismatch_sigma, 0.0, 0.5)
    g_l = _check_scalar("g_lateral_s", g_lateral_s, *bounds.conductance_s)
    c_node = _check_scalar("node_capacitance_f", node_capacitance_f, 1e-18, 1e-6)
    if model not in MESH_MODELS:
        raise InputError(f"model={model!r} unknown; allowed {MESH_MODELS}")
    if fit_size is None:
        fit_size = target.size
    if not (isinstance(fit_size, (int, np.integer)) and fit_size % 2 == 1 and target.size <= fit_size <= MAX_KERNEL_SIZE):
        raise InputError(f"fit_size: must be odd in {target.size}..{MAX_KERNEL_SIZE}, got {fit_size!r}")
    fit_target = target if fit_size == target.size else target.padded(int(fit_size))
    radius = fit_target.radius
    if model == "grid":
        if not (isinstance(grid_half_width, (int, np.integer)) and radius <= grid_half_width <= 60):
            raise InputError(f"grid_half_width: model 'grid' needs an integer in {radius}..60, got {grid_half_width!r}")
        grid_half_width = int(grid_half_width)
    else:
        grid_half_width = None
    if not (isinstance(n_init, (int, np.integer)) and 2 <= n_init <= 40):
        raise InputError(f"n_init: must be an integer in 2..40, got {n_init!r}")
    if not (isinstance(max_iter, (int, np.integer)) and 1 <= max_iter <= 10000):
        raise InputError(f"max_iter: must be an integer in 1..10000, got {max_iter!r}")
    free_wp = pixel_weight is None
    glo, ghi = bounds.gain
    wp_fixed = 0.0 if free_wp else _check_scalar("pixel_weight", pixel_weight, 0.0, 1e3)

    # λ range from the λ bounds and the conductance bounds (g_v = g_l / λ² within conductance_s)
    gmin, gmax = bounds.conductance_s
    lam_lo = max(bounds.lambda_px[0], math.sqrt(g_l / gmax))
    lam_hi = min(bounds.lambda_px[1], math.sqrt(g_l / gmin))
    if not lam_hi / lam_lo > bounds.min_lambda_ratio:
        raise InputError(
            f"bounds: with g_lateral_s={g_l:g} S and conductance_s={bounds.conductance_s} the feasible λ range "
            f"[{lam_lo:g}, {lam_hi:g}] px is narrower than min_lambda_ratio={bounds.min_lambda_ratio:g}"
        )

    asym = target.asymmetry()
    if asym > 1e-6:
        warnings.warn(
            f"target '{target.name}' is not D4-symmetric (asymmetric part {asym:.3g} of its L2 norm); a resistive "
            "mesh realises only the symmetric part, fitted in the least-squares sense",
            MeshAsymmetryWarning,
            stacklevel=2,
        )
    t_sym = _d4_symmetrise(fit_target.taps)
    ii, jj, mult = _orbits(radius)
    t_orb = t_sym[radius + ii, radius + jj]
    norm2 = float((target.taps**2).sum())
    delta = (ii == 0).astype(np.float64)
    sw = np.sqrt(mult / norm2)

    # ---- least-squares initialisation over a coarse (λ_n, λ_w) grid
    lams = np.geomspace(lam_lo, lam_hi, int(n_init))
    nodes = quadrature_nodes(lam_hi, radius) if model == "lattice" else None
    resp = [_numpy_orbit_response(float(lam), radius, model, grid_half_width, nodes) for lam in lams]
    starts = []
    ncol = 3 if free_wp else 2
    for a_i, lam_n in enumerate(lams):
        hn, dhn = resp[a_i]
        for b_i in range(a_i + 1, len(lams)):
            lam_w = lams[b_i]
            if lam_w < bounds.min_lambda_ratio * lam_n * (1 - 1e-12):
                continue
            hw, dhw = resp[b_i]
            cols = [hn, -hw] + ([delta] if free_wp else [])
            a_fit = np.column_stack(cols) * sw[:, None]
            pen = np.zeros((ncol, ncol))
            pen[0, 0] = sigma * math.sqrt((2 * (mult * dhn**2).sum() + (mult * hn**2).sum()) / norm2)
            pen[1, 1] = sigma * math.sqrt((2 * (mult * dhw**2).sum() + (mult * hw**2).sum()) / norm2)
            if free_wp:
                pen[2, 2] = sigma / math.sqrt(norm2)
            rhs = (t_orb - wp_fixed * delta) * sw
            res = lsq_linear(np.vstack([a_fit, pen]), np.concatenate([rhs, np.zeros(ncol)]), bounds=(glo, ghi), method="bvls")
            starts.append((2 * res.cost + (0.0 if free_wp else (sigma * wp_fixed) ** 2 / norm2), lam_n, lam_w, res.x))
    if not starts:
        raise InputError("bounds: no (λ_narrow, λ_wide) pair on the initial grid satisfies min_lambda_ratio")
    starts.sort(key=lambda s: s[0])

    # ---- IPOPT in log-parameters (the solver is cached per problem structure)
    nx = 5 if free_wp else 4
    solver = _mesh_solver(radius, model, float(lam_hi), grid_half_width, free_wp, int(max_iter), float(tol))
    p_val = np.concatenate([t_orb, [1.0 / norm2, sigma * sigma, wp_fixed]])
    lbx = [2 * math.log(lam_lo)] * 2 + [math.log(glo)] * (nx - 2)
    ubx = [2 * math.log(lam_hi)] * 2 + [math.log(ghi)] * (nx - 2)
    best = None
    total_iter = 0
    for s in starts[:2]:
        _, lam_n, lam_w, gains = s
        gains = np.clip(gains, glo, ghi)
        x0 = [2 * math.log(lam_n), 2 * math.log(lam_w)] + [math.log(v) for v in gains]
        sol = solver(x0=x0, p=p_val, lbx=lbx, ubx=ubx, lbg=2 * math.log(bounds.min_lambda_ratio), ubg=ca.inf)
        st = solver.stats()
        total_iter += int(st.get("iter_count", 0))
        f = float(sol["f"])
        if best is None or f < best[0]:
            best = (f, np.array(sol["x"]).ravel(), st)
    f_opt, xo, st = best
    # IPOPT may relax bounds by ~1e-8 relative; the built circuit must respect them exactly
    xo = np.clip(xo, lbx, ubx)
    xo[1] = min(max(xo[1], xo[0] + 2 * math.log(bounds.min_lambda_ratio)), ubx[1])
    lam_n, lam_w = math.exp(xo[0] / 2), math.exp(xo[1] / 2)
    design = MeshDesign(
        g_lateral_narrow_s=g_l,
        g_vertical_narrow_s=g_l / lam_n**2,
        g_lateral_wide_s=g_l,
        g_vertical_wide_s=g_l / lam_w**2,
        gain_narrow=math.exp(xo[2]),
        gain_wide=math.exp(xo[3]),
        pixel_weight=math.exp(xo[4]) if free_wp else wp_fixed,
        size=target.size,
        pitch_m=target.pitch_m,
        node_capacitance_f=c_node,
        model=model,
        grid_half_width=grid_half_width,
        target=target,
    )
    realised = design.kernel()
    full_size = min(MAX_KERNEL_SIZE, max(int(fit_size), target.size + 2 * int(math.ceil(4 * lam_w))))
    fit = {
        "error": kernel_error(realised, target),
        "error_full": kernel_error(design.kernel(full_size), target),
        "error_full_size": full_size,
        "error_symmetric_part": kernel_error(realised, _d4_symmetrise(target.taps)),
        "fit_size": int(fit_size),
        "asymmetry": asym,
        "mismatch_sensitivity": mismatch_sensitivity(design, target),
        "objective": f_opt,
        "init_objective": float(starts[0][0]),
        "status": str(st.get("return_status")),
        "success": bool(st.get("success")),
        "iterations": total_iter,
        "starts": min(2, len(starts)),
        "wall_s": time.perf_counter() - t0,
        "model": model,
        "mismatch_sigma": sigma,
        "pixel_weight_free": free_wp,
    }
    if fit["error"] >= 0.999:
        peak = float(np.abs(target.taps).max())
        warnings.warn(
            f"mesh fit of '{target.name}' has kernel error {fit['error']:.6g} (a zero kernel has 1): the "
            f"target's scale (max |tap| = {peak:.3g}) is out of reach of bounds.gain={bounds.gain}"
            f"{'' if free_wp else f' with pixel_weight fixed at {wp_fixed:g}'}; normalise the target or widen the bounds",
            MeshFitWarning,
            stacklevel=2,
        )
    elif not fit["success"]:
        warnings.warn(f"mesh fit of '{target.name}': IPOPT ended with status {fit['status']}", MeshFitWarning, stacklevel=2)
    return MeshDesign(**{**{k: getattr(design, k) for k in design.__dataclass_fields__ if k not in ("fit", "kind")}, "fit": fit})
