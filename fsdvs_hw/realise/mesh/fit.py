r"""Dual resistive-mesh realisation of a centre-surround kernel, fitted with IPOPT.

The circuit
-----------
Every pixel injects its (linear) signal as a **current** into its own node of two square resistive
meshes, a narrow one and a wide one (lateral conductance :math:`g_l`, vertical conductance
:math:`g_v` per mesh, space constant :math:`\lambda = \sqrt{g_l/g_v}` pixel pitches; see
:mod:`fsdvs_hw.realise.mesh.response`). Each node voltage is read out through a transconductor
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
(:mod:`fsdvs_hw.realise.mesh.dynamics`).
"""

from __future__ import annotations

import functools
import itertools
import math
import time
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ...errors import InputError
from ...kernels import DEFAULT_PITCH_M, MAX_KERNEL_SIZE, Kernel, validate_pitch
from ...validation import check_fit_arguments
from ..base import CostItem, kernel_error
from .bounds import MeshBounds
from .options import MeshOptions
from .response import (
    dct_basis,
    finite_grid_response,
    green_terms,
    lattice_green_quarter,
    quadrature_nodes,
    space_constant_px,
    unfold_quarter,
)

__all__ = [
    "GAIN_MODES",
    "MESH_MODELS",
    "MeshAsymmetryWarning",
    "MeshDesign",
    "MeshFitWarning",
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
    group = [
        taps,
        taps.T,
        taps[::-1],
        taps[:, ::-1],
        taps[::-1, ::-1],
        taps.T[::-1],
        taps.T[:, ::-1],
        taps.T[::-1, ::-1],
    ]
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

    Examples
    --------
    Space constants λ = √(g_lateral / g_vertical) pixels and settling times τ = C / g_vertical, by hand:

    >>> from fsdvs_hw import MeshDesign
    >>> d = MeshDesign(1e-8, 1e-8, 4e-8, 1e-8, gain_narrow=1.0, gain_wide=0.5, pixel_weight=0.0)
    >>> d.lambda_narrow_px, d.lambda_wide_px, d.tau_narrow_s
    (1.0, 2.0, 1e-05)
    >>> d.whole_dc_gain, d.kernel(7).size  # a − b over the whole plane; the 7×7 window of it
    (0.5, 7)
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
        object.__setattr__(self, "pitch_m", validate_pitch(self.pitch_m, source="MeshDesign.pitch_m"))
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
                h = self._grid_half_width()
                out.append(np.pad(finite_grid_response(lam, min(radius, h), h), max(0, radius - h)))
            else:
                out.append(unfold_quarter(np.asarray(lattice_green_quarter(lam, radius))))
        return out[0], out[1]

    def _grid_half_width(self) -> int:
        """``grid_half_width`` of a ``"grid"`` design (an integer: checked in ``__post_init__``)."""
        assert self.grid_half_width is not None  # model "grid": __post_init__ refuses None
        return int(self.grid_half_width)

    @property
    def whole_dc_gain(self) -> float:
        """DC gain of the whole circuit, :math:`w_p + a - b`: the response to a uniform input.

        Exact for both models (an infinite lattice and a finite open-edge chip both return all
        injected current through their vertical conductances). It is what a bright uniform scene
        drives into the pixel; a negative value means negative pre-log current.
        """
        return self.pixel_weight + self.gain_narrow - self.gain_wide

    def _whole_energy(self) -> float:
        """Σ K² over the whole circuit response (infinite lattice: closed form; finite chip: exact sum)."""
        if self.model == "grid":
            k = self._taps(self._grid_half_width())
            return float((k * k).sum())
        gram = _lattice_gram(self.lambda_narrow_px, self.lambda_wide_px)
        x = np.array([self.pixel_weight, self.gain_narrow, self.gain_wide])
        return float(max(x @ gram @ x, 0.0))

    def response_size(self, energy_tol: float = 1e-6) -> int:
        """Smallest odd window holding all but ``energy_tol`` of the response's energy (≤ 63 px).

        The finite-grid model returns its whole chip (capped at :data:`MAX_KERNEL_SIZE`).
        """
        if self.model == "grid":
            return min(MAX_KERNEL_SIZE, 2 * self._grid_half_width() + 1)
        total = self._whole_energy()
        rmax = MAX_KERNEL_SIZE // 2
        k = self.kernel_taps(MAX_KERNEL_SIZE)
        ring = np.maximum(*np.abs(np.mgrid[-rmax : rmax + 1, -rmax : rmax + 1]))
        inside = np.cumsum(np.bincount(ring.ravel(), weights=(k * k).ravel(), minlength=rmax + 1))
        if total <= 0:
            return self.size
        ok = np.nonzero(total - inside <= energy_tol * total)[0]
        r = int(ok[0]) if ok.size else rmax
        return max(self.size, 2 * r + 1)

    def kernel_taps(self, size: int | None = None) -> np.ndarray:
        """Taps of the realised response on a ``size`` × ``size`` window (default :meth:`response_size`)."""
        size = self.response_size() if size is None else size
        if not (isinstance(size, (int, np.integer)) and size % 2 == 1 and 1 <= size <= MAX_KERNEL_SIZE):
            raise InputError(f"size: must be odd in 1..{MAX_KERNEL_SIZE}, got {size!r}")
        return self._taps(size // 2)

    def _taps(self, r: int) -> np.ndarray:
        """Response on the (2r+1)² window, any r (no Kernel size limit)."""
        hn, hw = self.mesh_responses(r)
        k = self.gain_narrow * hn - self.gain_wide * hw
        k[r, r] += self.pixel_weight
        return k

    def kernel(self, size: int | None = None) -> Kernel:
        """The kernel the circuit really applies: its whole response, or a ``size`` × ``size`` crop.

        By default the window is :meth:`response_size` (all but 1e-6 of the energy, ≤ 63 px), so
        the pixel's DC gain, spectrum and events are those of the whole circuit and not of the
        target's window (:attr:`size`); ``kernel(design.size)`` is the crop to the target window.
        """
        taps = self.kernel_taps(size)
        prov = {
            "realisation": "mesh",
            "lambda_narrow_px": self.lambda_narrow_px,
            "lambda_wide_px": self.lambda_wide_px,
            "gain_narrow": self.gain_narrow,
            "gain_wide": self.gain_wide,
            "pixel_weight": self.pixel_weight,
            "whole_dc_gain": self.whole_dc_gain,
            "model": self.model,
        }
        name = f"mesh({self.target.name})" if self.target is not None else "mesh"
        return Kernel(taps, pitch_m=self.pitch_m, name=name, provenance=prov)

    def tail_energy_fraction(self, size: int | None = None) -> float:
        """Fraction of the whole response's energy (Σ K²) outside the ``size`` window (default :attr:`size`)."""
        size = self.size if size is None else size
        tot = self._whole_energy()
        if tot <= 0:
            return 0.0
        inner = self.kernel_taps(size)
        return float(min(1.0, max(0.0, 1.0 - float((inner * inner).sum()) / tot)))

    def kernel_error(self, target: Kernel | np.ndarray | None = None, *, fit_scale: bool = False) -> float:
        r"""Relative L2 error of the whole circuit response against ``target`` (the one definition).

        :math:`e = \lVert s K - T\rVert_2 / \lVert T \rVert_2` summed over the *whole* response
        (the target is zero outside its window; the infinite-lattice energy is exact, in closed
        form), with :math:`s = 1` or, with ``fit_scale``, the least-squares gain. This is the number
        the fit reports as ``fit["error"]`` and the scorer reports as ``kernel_error``.
        """
        t = self.target if target is None else target
        if t is None:
            raise InputError("kernel_error: this design has no target; pass one")
        tt = t.taps if isinstance(t, Kernel) else np.asarray(t, dtype=np.float64)
        n_t = float((tt * tt).sum())
        if n_t == 0:
            raise InputError("kernel_error: target kernel is all zeros")
        kw = self.kernel_taps(tt.shape[0])
        c = float((kw * tt).sum())
        n_k = max(self._whole_energy(), float((kw * kw).sum()))
        if fit_scale:
            e2 = 1.0 - (c * c / (n_k * n_t) if n_k > 0 else 0.0)
        else:
            e2 = (n_k - 2.0 * c + n_t) / n_t
        return float(math.sqrt(max(e2, 0.0)))

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
            "mismatch_sensitivity": CostItem(
                mismatch_sensitivity(self), "1", "relative kernel error per unit relative die-level mismatch"
            ),
            "tail_energy_fraction": CostItem(
                self.tail_energy_fraction(), "1", "response energy outside the target window"
            ),
            "whole_dc_gain": CostItem(self.whole_dc_gain, "1", "whole-circuit DC gain w_p + a - b (uniform input)"),
            "response_size": CostItem(
                self.response_size(), "px", "window holding all but a millionth (10⁻⁶) of the response energy"
            ),
        }
        if self.target is not None:
            c["kernel_error"] = CostItem(self.kernel_error(), "1", "relative L2 error of the whole response vs target")
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
        n = self.response_size()
        win_dc = float(self.kernel_taps(self.size).sum())
        lines.append(
            f"  the pixel sees the whole circuit response ({n}x{n} px holds all but 1e-6 of its energy):"
            f" DC gain {self.whole_dc_gain:.4g} (uniform scene; the {self.size}x{self.size} window alone sums to"
            f" {win_dc:.4g}), {100 * self.tail_energy_fraction():.3g} % of its energy outside the {self.size}x{self.size} window"
        )
        if self.whole_dc_gain < 0:
            lines.append(
                "  WARNING: negative whole-circuit DC gain: a bright uniform scene drives negative pre-log current"
            )
        if self.fit:
            f = self.fit
            lines.append(
                f"  fit to '{self.target.name if self.target is not None else '?'}': kernel error {f.get('error', float('nan')):.3g}"
                f" (whole response), {f.get('error_window', float('nan')):.3g} (window crop); gain {f.get('gain', '?')};"
                f" {f.get('status')} after {f.get('iterations')} iterations, {f.get('wall_s', float('nan')):.3g} s"
            )
            if f.get("on_bound"):
                lines.append(f"  at a bound: {', '.join(f['on_bound'])}")
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
            "g_lateral_narrow_s",
            "g_vertical_narrow_s",
            "g_lateral_wide_s",
            "g_vertical_wide_s",
            "gain_narrow",
            "gain_wide",
            "pixel_weight",
            "size",
            "pitch_m",
            "node_capacitance_f",
            "model",
            "grid_half_width",
        }
        missing = {
            "g_lateral_narrow_s",
            "g_vertical_narrow_s",
            "g_lateral_wide_s",
            "g_vertical_wide_s",
            "gain_narrow",
            "gain_wide",
        } - set(data)
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
    tt = (
        t.taps
        if t.size == design.size
        else t.padded(design.size).taps
        if t.size < design.size
        else t.cropped(design.size).taps
    )
    s2 = _sensitivity_sq(
        design.gain_narrow, design.gain_wide, design.pixel_weight, hn, hw, dhn, dhw, 1.0, float((tt * tt).sum())
    )
    return math.sqrt(s2)


def _responses_and_derivatives(
    lam: float, radius: int, model: str, half_width: int | None
) -> tuple[np.ndarray, np.ndarray]:
    """Full-window H and ∂H/∂ln(λ²) for one mesh."""
    if model == "grid":
        assert half_width is not None  # model "grid" carries its half-width
        h = max(int(half_width), radius)
        eps = 1e-5
        hp = finite_grid_response(lam * math.exp(eps / 2), radius, h)
        hm = finite_grid_response(lam * math.exp(-eps / 2), radius, h)
        return finite_grid_response(lam, radius, h), (hp - hm) / (2 * eps)
    q, dq = lattice_green_quarter(lam, radius, derivative=True)
    return unfold_quarter(q), unfold_quarter(dq * lam * lam)


# ---------------------------------------------------------------------- casadi models of H on orbits
def _casadi_orbit_response(u, radius: int, model: str, lam_max: float, half_width: int | None):
    """SX expression: unit-sum mesh response on the D4 orbits as a function of u = ln λ²."""
    import casadi as ca

    ii, jj, _ = _orbits(radius)
    lam2 = ca.exp(u)
    if model == "lattice":
        k, w = quadrature_nodes(lam_max, radius)
        c = ca.DM(2.0 - 2.0 * np.cos(k))
        rho, inv_sq = green_terms(lam2, c, xp=ca)
        cos_w = ca.DM(np.cos(np.outer(np.arange(radius + 1), k)) * w)  # (m, node)
        pows = ca.horzcat(*[rho**j for j in range(radius + 1)])  # (node, n)
        q = ca.mtimes(cos_w, pows * ca.repmat(inv_sq, 1, radius + 1))
    else:
        assert half_width is not None  # model "grid" carries its half-width
        n = 2 * half_width + 1
        phi, s = dct_basis(n)
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


# ---------------------------------------------------------------------- whole-response energy
def _lattice_norm_terms(lam: float, nodes=None) -> tuple[float, float]:
    r"""Centre tap :math:`G_0(\alpha)` and energy :math:`\sum H^2 = G_0 + \alpha\,dG_0/d\alpha` (α = λ²).

    On the infinite lattice :math:`\hat H = 1/(1 + \alpha s(k))`, so
    :math:`\sum_x H^2 = \int \hat H^2 = \frac{d}{d\alpha}[\alpha G_0(\alpha)]` (Parseval).
    """
    q, dq = lattice_green_quarter(lam, 0, derivative=True, nodes=nodes)
    g0 = float(q[0, 0])
    return g0, g0 + lam * lam * float(dq[0, 0])


def _cross_energy(al_n: float, g0n: float, q_n: float, al_w: float, g0w: float) -> float:
    r""":math:`\sum_x H_n H_w = (\alpha_n G_0(\alpha_n) - \alpha_w G_0(\alpha_w)) / (\alpha_n - \alpha_w)` (partial fractions)."""
    if abs(al_n - al_w) <= 1e-9 * max(al_n, al_w):
        return q_n
    return (al_n * g0n - al_w * g0w) / (al_n - al_w)


def _lattice_gram(lam_n: float, lam_w: float, nodes=None) -> np.ndarray:
    """Gram matrix of (δ, H_n, −H_w) over the whole infinite lattice (exact): Σ K² = xᵀ G x, x = (w_p, a, b)."""
    g0n, qn = _lattice_norm_terms(lam_n, nodes)
    g0w, qw = _lattice_norm_terms(lam_w, nodes)
    pnw = _cross_energy(lam_n**2, g0n, qn, lam_w**2, g0w)
    return np.array([[1.0, g0n, -g0w], [g0n, qn, -pnw], [-g0w, -pnw, qw]])


def _small_qp(gram: np.ndarray, c: np.ndarray, x_fixed: np.ndarray, free: list[int], dc: bool) -> np.ndarray:
    """Exact minimiser of xᵀGx − 2cᵀx over x_i ≥ 0 (i in ``free``; others fixed), with w_p + a − b ≥ 0 if ``dc``.

    A convex QP in ≤ 3 variables: every active set is tried (the optimum is the best feasible
    stationary point among them).
    """
    d = np.array([1.0, 1.0, -1.0])
    best, best_x = math.inf, None
    for mask in itertools.product((False, True), repeat=len(free)):
        f_idx = [free[k] for k in range(len(free)) if mask[k]]
        base = x_fixed.copy()
        base[free] = 0.0
        for active in (False, True) if dc else (False,):
            x = base.copy()
            if f_idx:
                g_ff = gram[np.ix_(f_idx, f_idx)]
                rhs = c[f_idx] - gram[f_idx] @ base
                if active:
                    kkt = np.block([[g_ff, d[f_idx, None] / 2], [d[None, f_idx], np.zeros((1, 1))]])
                    sol = np.linalg.lstsq(kkt, np.concatenate([rhs, [-(d @ base)]]), rcond=None)[0]
                    x[f_idx] = sol[:-1]
                else:
                    x[f_idx] = np.linalg.lstsq(g_ff, rhs, rcond=None)[0]
            elif active:
                continue
            if np.any(x[free] < -1e-12) or (dc and d @ x < -1e-12 * max(1.0, np.abs(x).max())):
                continue
            val = float(x @ gram @ x - 2 * c @ x)
            if val < best:
                best, best_x = val, np.maximum(x, 0.0)
    return best_x if best_x is not None else x_fixed.copy()


# ---------------------------------------------------------------------- the fit
#: Overall-gain modes of :func:`fit_resistive_mesh`.
GAIN_MODES = ("free", "fixed")


@functools.lru_cache(maxsize=32)
def _mesh_solver(
    radius: int,
    model: str,
    lam_max: float,
    half_width: int | None,
    free_wp: bool,
    gain_free: bool,
    whole: bool,
    max_iter: int,
    tol: float,
):
    """IPOPT solver of the dual-mesh fit for one problem structure; target and weights are parameters.

    Constraints ``g``: [ln λ_w² − ln λ_n², whole-circuit DC w_p + a − b, (σS / max error)², ⟨K, T⟩ (gain free),
    w_p + a + b (gain and pixel weight free: the normalisation)].
    """
    import casadi as ca

    ii, _jj, mult = _orbits(radius)
    n_orb = len(ii)
    nx = 5 if free_wp else 4
    x = ca.MX.sym("x", nx)
    p = ca.MX.sym("p", n_orb + 3)  # target on the orbits, 1/||T||^2, fixed pixel weight, sigma^2 / max_err^2
    t_orb, inv_norm2, wp_fixed, sigma2 = p[:n_orb], p[n_orb], p[n_orb + 1], p[n_orb + 2]
    a, b = ca.exp(x[2]), ca.exp(x[3])
    wp = ca.exp(x[4]) if free_wp else wp_fixed
    m = ca.DM(mult)
    # one mesh as a scalar-expression (SX) function of u = ln λ² (and the target); the NLP graph
    # (MX) calls it twice, so the exact Hessian is built from this small function's AD
    u = ca.SX.sym("u")
    h_u = _casadi_orbit_response(u, radius, model, lam_max, half_width)
    dh_u = ca.jacobian(h_u, u)
    if whole and model == "lattice":
        mesh_h = ca.Function("mesh_h", [u], [h_u, dh_u])
        hn, dhn = mesh_h(x[0])
        hw, dhw = mesh_h(x[1])
        e0 = ca.DM((ii == 0).astype(float))
        c = ca.dot(m, (wp * e0 + a * hn - b * hw) * t_orb)
        g0n, g0w = hn[0], hw[0]
        # the whole infinite-lattice energy in closed form (Parseval + partial fractions)
        qn, qw = g0n + dhn[0], g0w + dhw[0]
        al_n, al_w = ca.exp(x[0]), ca.exp(x[1])
        pnw = ca.if_else(ca.fabs(x[1] - x[0]) < 1e-9, qn, (al_n * g0n - al_w * g0w) / (al_n - al_w + 1e-300))
        n_k = wp**2 + 2 * wp * (a * g0n - b * g0w) + a**2 * qn + b**2 * qw - 2 * a * b * pnw
        sens_raw = (
            2 * a**2 * ca.dot(m, dhn**2)
            + 2 * b**2 * ca.dot(m, dhw**2)
            + a**2 * ca.dot(m, hn**2)
            + b**2 * ca.dot(m, hw**2)
            + wp**2
        )
    else:  # the fit window (or the whole finite chip) holds the response
        mesh_h = ca.Function("mesh_h", [u], [h_u, dh_u])
        hn, dhn = mesh_h(x[0])
        hw, dhw = mesh_h(x[1])
        e0 = ca.DM((ii == 0).astype(float))
        k_orb = wp * e0 + a * hn - b * hw
        c = ca.dot(m, k_orb * t_orb)
        n_k = ca.dot(m, k_orb**2)
        sens_raw = (
            2 * a**2 * ca.dot(m, dhn**2)
            + 2 * b**2 * ca.dot(m, dhw**2)
            + a**2 * ca.dot(m, hn**2)
            + b**2 * ca.dot(m, hw**2)
            + wp**2
        )
    g2: ca.MX | float
    if gain_free:
        f = 1.0 - c**2 / n_k * inv_norm2
        g2 = (c / n_k) ** 2
    else:
        f = (n_k - 2 * c) * inv_norm2 + 1.0
        g2 = 1.0
    sens2 = g2 * sens_raw * inv_norm2
    g = [x[1] - x[0], wp + a - b, sigma2 * sens2]
    if gain_free:
        g.append(c * ca.sqrt(inv_norm2))
        if free_wp:
            g.append(wp + a + b)
    opts: dict[str, str | int | float | bool] = {
        "ipopt.print_level": 0,
        "print_time": False,
        "ipopt.sb": "yes",
        "ipopt.max_iter": max_iter,
        "ipopt.tol": tol,
        "ipopt.acceptable_tol": 1e-10,
        "ipopt.mu_strategy": "adaptive",
    }
    return ca.nlpsol("mesh_fit", "ipopt", {"x": x, "p": p, "f": f, "g": ca.vertcat(*g)}, opts)


# ---------------------------------------------------------------------------- the fit, in steps
@dataclass(frozen=True, eq=False)
class _MeshProblem:
    """The window the fit sums over and the target on its D4 orbits (step 2: the model)."""

    radius: int
    whole: bool
    lattice_whole: bool
    t_sym: np.ndarray
    t_orb: np.ndarray
    mult: np.ndarray
    delta: np.ndarray
    norm2: float
    asymmetry: float


def _mesh_problem(o: MeshOptions) -> _MeshProblem:
    """The window the NLP sums over: the target's (whole lattice energy in closed form), the fit
    window, or the whole finite chip; the D4-symmetric target on its orbits."""
    target = o.target
    whole = o.fit_size is None
    if o.model == "grid" and whole:
        assert o.grid_half_width is not None  # model "grid": required by MeshOptions
        radius = o.grid_half_width
    else:
        radius = target.radius if o.fit_size is None else o.fit_size // 2  # whole: fit_size is None
    t_sym = _d4_symmetrise(np.pad(target.taps, radius - target.radius))  # plain array: the chip may exceed 63 px
    ii, jj, mult = _orbits(radius)
    return _MeshProblem(
        radius=radius,
        whole=whole,
        lattice_whole=whole and o.model == "lattice",
        t_sym=t_sym,
        t_orb=t_sym[radius + ii, radius + jj],
        mult=mult,
        delta=(ii == 0).astype(np.float64),
        norm2=float((target.taps**2).sum()),
        asymmetry=target.asymmetry(),
    )


def _initial_starts(
    o: MeshOptions, p: _MeshProblem
) -> tuple[np.ndarray, list[tuple[float, float, int, int, np.ndarray]]]:
    """Step 3, the objective on a grid: exact constrained least-squares gains at every (λ_n, λ_w)
    pair; return the λ grid and the best distinct starts ``(penalised f, f, i_n, i_w, gains)``."""
    glo, ghi = o.mesh_bounds.gain
    radius, mult, delta, norm2 = p.radius, p.mult, p.delta, p.norm2
    lam_lo, lam_hi = o.lambda_range_px
    lams = np.geomspace(lam_lo, lam_hi, o.n_init)
    nodes = quadrature_nodes(lam_hi, radius) if o.model == "lattice" else None
    resp = [_numpy_orbit_response(float(lam), radius, o.model, o.model_half_width, nodes) for lam in lams]
    norms = [_lattice_norm_terms(float(lam), nodes) for lam in lams] if p.lattice_whole else None
    sens_parts = [(float((mult * dh * dh).sum()), float((mult * h * h).sum())) for h, dh in resp]
    sig2 = o.mismatch_sigma * o.mismatch_sigma
    maxerr2 = math.inf if o.max_mismatch_error is None else o.max_mismatch_error * o.max_mismatch_error

    def evaluate(gram: np.ndarray, cvec: np.ndarray, x: np.ndarray, sp_n, sp_w) -> tuple[float, float]:
        n_k = float(x @ gram @ x)
        cx = float(cvec @ x)
        if o.gain_free:
            f = 1.0 - (cx * cx / (n_k * norm2) if n_k > 0 and cx > 0 else 0.0)
            g2 = (cx / n_k) ** 2 if n_k > 0 else 0.0
        else:
            f, g2 = (n_k - 2 * cx) / norm2 + 1.0, 1.0
        s2 = (
            g2
            * (
                2 * x[1] ** 2 * sp_n[0]
                + 2 * x[2] ** 2 * sp_w[0]
                + x[1] ** 2 * sp_n[1]
                + x[2] ** 2 * sp_w[1]
                + x[0] ** 2
            )
            / norm2
        )
        return f, sig2 * s2

    starts = []
    for i_n, lam_n in enumerate(lams):
        hn, _ = resp[i_n]
        for i_w in range(i_n + 1, len(lams)):
            lam_w = lams[i_w]
            if lam_w < o.mesh_bounds.min_lambda_ratio * lam_n * (1 - 1e-12):
                continue
            hw, _ = resp[i_w]
            basis = np.column_stack([delta, hn, -hw])
            if p.lattice_whole:
                assert norms is not None  # computed when p.lattice_whole
                g0n, qn = norms[i_n]
                g0w, qw = norms[i_w]
                pnw = _cross_energy(lam_n**2, g0n, qn, lam_w**2, g0w)
                gram = np.array([[1.0, g0n, -g0w], [g0n, qn, -pnw], [-g0w, -pnw, qw]])
            else:
                gram = basis.T @ (mult[:, None] * basis)
            cvec = basis.T @ (mult * p.t_orb)
            if o.free_pixel_weight or o.gain_free:
                x = _small_qp(gram, cvec, np.zeros(3), [0, 1, 2], o.nonnegative_dc)
                if not o.free_pixel_weight:  # gain free, pixel path is the reference
                    x = (
                        x / x[0] * o.fixed_pixel_weight
                        if x[0] > 0
                        else np.array([o.fixed_pixel_weight, ghi * o.fixed_pixel_weight, ghi * o.fixed_pixel_weight])
                    )
                    x[1:] = np.clip(x[1:], glo, ghi)
                elif o.gain_free:  # normalised to w_p + a + b = 1
                    x = np.maximum(x / x.sum() if x.sum() > 0 else np.full(3, 1 / 3), glo)
                    x /= x.sum()
                else:
                    x = np.clip(x, glo, ghi)
            else:
                x = _small_qp(gram, cvec, np.array([o.fixed_pixel_weight, 0.0, 0.0]), [1, 2], o.nonnegative_dc)
                x[1:] = np.clip(x[1:], glo, ghi)
            if o.nonnegative_dc and x[0] + x[1] - x[2] < 0:
                x[2] = max(x[0] + x[1], glo)
            f, mm2 = evaluate(gram, cvec, x, sens_parts[i_n], sens_parts[i_w])
            starts.append((f + max(0.0, mm2 - maxerr2), f, i_n, i_w, x))
    if not starts:
        raise InputError("bounds: no (λ_narrow, λ_wide) pair on the initial grid satisfies min_lambda_ratio")
    starts.sort(key=lambda st: st[0])
    chosen: list = []
    for st in starts:  # the best distinct grid points (not neighbours of one already chosen)
        if all(abs(st[2] - c[2]) > 1 or abs(st[3] - c[3]) > 1 for c in chosen):
            chosen.append(st)
        if len(chosen) == o.n_starts:
            break
    return lams, chosen


@dataclass(frozen=True, eq=False)
class _MeshSolution:
    """The best IPOPT run (step 4): log-parameters clipped into their bounds, and the run's record."""

    xo: np.ndarray
    lbx: list[float]
    ubx: list[float]
    objective: float
    stats: dict[str, Any]
    iterations: int
    runs: int


def _solve(o: MeshOptions, p: _MeshProblem, lams: np.ndarray, chosen: list) -> _MeshSolution:
    """IPOPT in log-parameters from each start (the solver is cached per problem structure)."""
    import casadi as ca

    glo, ghi = o.mesh_bounds.gain
    sig2 = o.mismatch_sigma * o.mismatch_sigma
    maxerr2 = math.inf if o.max_mismatch_error is None else o.max_mismatch_error * o.max_mismatch_error
    nx = 5 if o.free_pixel_weight else 4
    lam_lo, lam_hi = o.lambda_range_px
    solver = _mesh_solver(
        p.radius,
        o.model,
        float(lam_hi),
        o.model_half_width,
        o.free_pixel_weight,
        o.gain_free,
        p.whole,
        o.max_iter,
        float(o.tol),
    )
    p_val = np.concatenate(
        [p.t_orb, [1.0 / p.norm2, o.fixed_pixel_weight, sig2 / (maxerr2 if o.max_mismatch_error is not None else 1.0)]]
    )
    g_hi = 0.0 if (o.gain_free and o.free_pixel_weight) else math.log(ghi)
    lbx = [2 * math.log(lam_lo)] * 2 + [math.log(glo)] * (nx - 2)
    ubx = [2 * math.log(lam_hi)] * 2 + [g_hi] * (nx - 2)
    lbg = [2 * math.log(o.mesh_bounds.min_lambda_ratio), 0.0 if o.nonnegative_dc else -ca.inf, -ca.inf]
    ubg = [ca.inf, ca.inf, 1.0 if o.max_mismatch_error is not None else ca.inf]
    if o.gain_free:
        lbg.append(0.0)
        ubg.append(ca.inf)
        if o.free_pixel_weight:
            lbg.append(1.0)
            ubg.append(1.0)
    best = None
    total_iter = 0
    runs = 0
    for _, _f0, i_n, i_w, x in chosen:
        runs += 1
        gains = np.clip(x, glo, ghi if not (o.gain_free and o.free_pixel_weight) else 1.0)
        x0 = [2 * math.log(lams[i_n]), 2 * math.log(lams[i_w]), math.log(gains[1]), math.log(gains[2])]
        if o.free_pixel_weight:
            x0.append(math.log(gains[0]))
        sol = solver(x0=x0, p=p_val, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        st = solver.stats()
        total_iter += int(st.get("iter_count", 0))
        f = float(sol["f"])
        gv = np.array(sol["g"]).ravel()
        feasible = (gv[1] >= -1e-9 or not o.nonnegative_dc) and (o.max_mismatch_error is None or gv[2] <= 1 + 1e-6)
        key = (not feasible, f)
        if best is None or key < best[0]:
            best = (key, np.array(sol["x"]).ravel(), st, f)
        if feasible and f <= 1e-12:  # an exact fit (relative error ≤ 1e-6): no start needs to beat it
            break
    assert best is not None  # chosen is never empty: _initial_starts raises instead
    _, xo, st, f_opt = best
    # IPOPT may relax bounds by ~1e-8 relative; the built circuit must respect them exactly
    xo = np.clip(xo, lbx, ubx)
    xo[1] = min(max(xo[1], xo[0] + 2 * math.log(o.mesh_bounds.min_lambda_ratio)), ubx[1])
    return _MeshSolution(xo=xo, lbx=lbx, ubx=ubx, objective=f_opt, stats=st, iterations=total_iter, runs=runs)


def _build_design(o: MeshOptions, p: _MeshProblem, sol: _MeshSolution) -> tuple[MeshDesign, float, float, float, float]:
    """The circuit from the solution (step 5): conductances from λ, gains scaled by the
    least-squares overall gain when it is free; return the design, w_p, a, b (unscaled) and the gain."""
    target, xo = o.target, sol.xo
    lam_n, lam_w = math.exp(xo[0] / 2), math.exp(xo[1] / 2)
    a, b = math.exp(xo[2]), math.exp(xo[3])
    wp = math.exp(xo[4]) if o.free_pixel_weight else o.fixed_pixel_weight
    if o.nonnegative_dc and wp + a - b < 0:  # solver tolerance: never ship a negative whole-circuit DC
        b = wp + a
    common: dict[str, Any] = dict(
        g_lateral_narrow_s=o.g_lateral_s,
        g_vertical_narrow_s=o.g_lateral_s / lam_n**2,
        g_lateral_wide_s=o.g_lateral_s,
        g_vertical_wide_s=o.g_lateral_s / lam_w**2,
        size=target.size,
        pitch_m=target.pitch_m,
        node_capacitance_f=o.node_capacitance_f,
        model=o.model,
        grid_half_width=o.model_half_width,
        target=target,
    )
    overall = 1.0
    if o.gain_free:  # the least-squares overall gain (it folds into the event threshold)
        unit = MeshDesign(gain_narrow=a, gain_wide=b, pixel_weight=wp, **common)
        kw = unit._taps(p.radius)
        n_k = unit._whole_energy() if p.whole else float((kw * kw).sum())
        cx = float((kw * p.t_sym).sum())
        overall = cx / n_k if n_k > 0 and cx > 0 else 0.0
    wp_s, a_s, b_s = overall * wp, overall * a, overall * b
    if o.nonnegative_dc and wp_s + a_s - b_s < 0:  # rounding of the scaling: keep the whole-circuit DC ≥ 0 exactly
        b_s = wp_s + a_s
    return MeshDesign(gain_narrow=a_s, gain_wide=b_s, pixel_weight=wp_s, **common), wp, a, b, overall


def _fit_report(
    o: MeshOptions,
    p: _MeshProblem,
    sol: _MeshSolution,
    design: MeshDesign,
    wp: float,
    a: float,
    b: float,
    overall: float,
    init_objective: float,
) -> dict[str, Any]:
    """The fit record (step 6): errors, what sits on a bound, mismatch and solver status
    (``wall_s`` is added by the caller, so it covers the whole fit)."""
    target, xo, lbx, ubx = o.target, sol.xo, sol.lbx, sol.ubx
    on_bound = []
    names = ["lambda_narrow_px", "lambda_wide_px", "gain_narrow", "gain_wide"] + (
        ["pixel_weight"] if o.free_pixel_weight else []
    )
    for k, name in enumerate(names):
        for side, lim in (("low", lbx[k]), ("high", ubx[k])):
            if abs(xo[k] - lim) <= 1e-6 * max(1.0, abs(lim)):
                on_bound.append(
                    f"{name} at its {side} bound"
                    + (" (relative to the reference path)" if o.gain_free and k >= 2 else "")
                )
    if abs((xo[1] - xo[0]) - 2 * math.log(o.mesh_bounds.min_lambda_ratio)) <= 1e-6:
        on_bound.append(f"lambda_wide/lambda_narrow at min_lambda_ratio={o.mesh_bounds.min_lambda_ratio:g}")
    if o.nonnegative_dc and wp + a - b <= 1e-6 * max(wp, a, b):
        on_bound.append("whole-circuit DC gain at 0 (nonnegative_dc)")
    sens = mismatch_sensitivity(design, target)
    if o.max_mismatch_error is not None and o.mismatch_sigma * sens >= o.max_mismatch_error * (1 - 1e-4):
        on_bound.append(f"mismatch error sigma*S at max_mismatch_error={o.max_mismatch_error:g}")
    return {
        "error": design.kernel_error(target),
        "error_window": kernel_error(design.kernel(target.size), target),
        "error_gain_free": design.kernel_error(target, fit_scale=True),
        "error_symmetric_part": design.kernel_error(target.with_taps(_d4_symmetrise(target.taps))),
        "tail_energy_fraction": design.tail_energy_fraction(),
        "whole_dc_gain": design.whole_dc_gain,
        "window_dc_gain": float(design.kernel_taps(target.size).sum()),
        "overall_gain": overall,
        "gain": o.gain,
        "fit_size": "whole" if p.whole else o.fit_size,
        "asymmetry": p.asymmetry,
        "mismatch_sensitivity": sens,
        "expected_mismatch_error": o.mismatch_sigma * sens,
        "on_bound": on_bound,
        "objective": sol.objective,
        "init_objective": init_objective,
        "status": str(sol.stats.get("return_status")),
        "success": bool(sol.stats.get("success")),
        "iterations": sol.iterations,
        "starts": sol.runs,
        "wall_s": math.nan,
        "model": o.model,
        "mismatch_sigma": o.mismatch_sigma,
        "max_mismatch_error": o.max_mismatch_error,
        "nonnegative_dc": bool(o.nonnegative_dc),
        "pixel_weight_free": o.free_pixel_weight,
    }


def fit_resistive_mesh(
    kernel: Kernel | np.ndarray,
    *,
    bounds: MeshBounds | Mapping[str, Any] | None = None,
    pitch_m: float | None = None,
    pixel_weight: float | str | None = "free",
    gain: str = "free",
    nonnegative_dc: bool = True,
    mismatch_sigma: float = 0.01,
    max_mismatch_error: float | None = 0.05,
    g_lateral_s: float = _DEFAULT_G_LATERAL_S,
    node_capacitance_f: float = _DEFAULT_C_NODE_F,
    model: str = "lattice",
    grid_half_width: int | None = None,
    fit_size: int | None = None,
    n_init: int = 16,
    n_starts: int = 3,
    max_iter: int = 200,
    tol: float = 1e-14,
) -> MeshDesign:
    r"""Fit a dual resistive mesh to ``kernel`` with IPOPT (casadi ``nlpsol``).

    The error minimised and reported is that of the **whole circuit response** against the target
    (zero outside its window): on the infinite lattice its energy is exact in closed form, on the
    finite grid the whole chip is summed. The options are validated once, at entry, into a
    :class:`~fsdvs_hw.realise.mesh.MeshOptions` (the same model and rules a design file's
    ``[realisations.mesh]`` table is checked against) that every step of the fit reads.

    Parameters
    ----------
    kernel : Kernel or array_like
        Target kernel (odd square taps).
    bounds, pitch_m, pixel_weight, gain, nonnegative_dc, mismatch_sigma, max_mismatch_error, \
g_lateral_s, node_capacitance_f, model, grid_half_width, fit_size, n_init, n_starts, max_iter, tol
        The fit's options: each one's type, unit, range, default and meaning, and the rules between
        them, are those of :class:`~fsdvs_hw.realise.mesh.MeshOptions`.

    Returns
    -------
    MeshDesign
        With ``fit`` = {"error" (whole response, :meth:`MeshDesign.kernel_error`), "error_window",
        "error_gain_free", "error_symmetric_part", "tail_energy_fraction", "whole_dc_gain",
        "window_dc_gain", "overall_gain", "asymmetry", "mismatch_sensitivity",
        "expected_mismatch_error", "on_bound", "objective", "init_objective", "status",
        "success", "iterations", "starts", "wall_s", "model", "gain", "fit_size", ...}.

    Raises
    ------
    InputError
        Invalid kernel, bounds or options (the message names the argument and allowed range).

    Warns
    -----
    MeshAsymmetryWarning
        The target is not D4-symmetric (relative asymmetric part > 1e-6).
    MeshFitWarning
        The fit is no better than a zero kernel (error ≥ 0.999), or IPOPT did not report success.

    Examples
    --------
    >>> from fsdvs_hw import fit_resistive_mesh, reference_kernel
    >>> d = fit_resistive_mesh(reference_kernel("dog", 5))
    >>> d.kernel_error() < 0.5, d.lambda_narrow_px < d.lambda_wide_px
    (True, True)
    """
    o = check_fit_arguments(MeshOptions, locals())
    t0 = time.perf_counter()
    problem = _mesh_problem(o)
    if problem.asymmetry > 1e-6:
        warnings.warn(
            f"target '{o.target.name}' is not D4-symmetric (asymmetric part {problem.asymmetry:.3g} of its L2 norm); "
            "a resistive mesh realises only the symmetric part, fitted in the least-squares sense",
            MeshAsymmetryWarning,
            stacklevel=2,
        )
    lams, chosen = _initial_starts(o, problem)
    sol = _solve(o, problem, lams, chosen)
    design, wp, a, b, overall = _build_design(o, problem, sol)
    fit = _fit_report(o, problem, sol, design, wp, a, b, overall, float(chosen[0][1]))
    fit["wall_s"] = time.perf_counter() - t0
    _warn_if_unusable(o, fit, stacklevel=3)
    return MeshDesign(
        **{**{k: getattr(design, k) for k in design.__dataclass_fields__ if k not in ("fit", "kind")}, "fit": fit}
    )


def _warn_if_unusable(o: MeshOptions, fit: Mapping[str, Any], *, stacklevel: int) -> None:
    """:class:`MeshFitWarning` when the fit is no better than a zero kernel or IPOPT did not succeed."""
    target = o.target
    if fit["error"] >= 0.999:
        peak = float(np.abs(target.taps).max())
        warnings.warn(
            f"mesh fit of '{target.name}' has kernel error {fit['error']:.6g} (a zero kernel has 1): "
            + (
                f"the target's scale (max |tap| = {peak:.3g}) is out of reach of bounds.gain={o.mesh_bounds.gain}"
                f"{'' if o.free_pixel_weight else f' with pixel_weight fixed at {o.fixed_pixel_weight:g}'}; normalise "
                "the target, widen the bounds or use gain='free'"
                if not o.gain_free
                else "no dual mesh with these bounds correlates with the target"
            ),
            MeshFitWarning,
            stacklevel=stacklevel,
        )
    elif not fit["success"]:
        warnings.warn(
            f"mesh fit of '{target.name}': IPOPT ended with status {fit['status']}",
            MeshFitWarning,
            stacklevel=stacklevel,
        )
