r"""The dual resistive mesh's kernel as a torch function of its circuit parameters.

For co-design a realisation exposes its kernel as a differentiable function of its
physical parameters, inside their bounds, on the same numerics as the fit. For the mesh (the
infinite-lattice model of :class:`MeshDesign`) the kernel on a (2r+1)² window is

.. math:: K = w_p\,\delta + a\,H(\lambda_n) - b\,H(\lambda_w),
   \qquad \lambda = \sqrt{g_l / g_v},

with :math:`H` the lattice Green's function, evaluated here by the same quadrature as
:func:`~fsdvs_hw.realise.mesh.response.lattice_green_quarter` (fixed nodes for the largest λ the
bounds allow, so the rule is exact to ~1e-13 for every λ reached and differentiable in λ).

Bounds are kept by reparametrisation, never by clipping: each space constant is a sigmoid of a
free parameter between the bounds' λ range (the wide one above ``min_lambda_ratio`` × the
narrow one), each gain a sigmoid in log space between the gain bounds, and the whole-circuit DC
gain :math:`w_p + a - b \ge 0` (a negative DC gain would drive negative pre-log current) by writing
:math:`b = (w_p + a)\,\sigma(u)` — which also keeps :math:`b` below its upper bound only when
the bounds allow it, so :meth:`MeshKernel.to_design` checks the result. Vertical conductances stay
at the fitted values; lateral ones follow from λ (:math:`g_l = \lambda^2 g_v`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import torch

from ...errors import InputError
from .fit import MeshBounds, MeshDesign
from .response import green_terms, quadrature_nodes

__all__ = ["MeshKernel"]


def _logit(p: float) -> float:
    p = min(max(p, 1e-12), 1 - 1e-12)
    return math.log(p / (1 - p))


class MeshKernel(torch.nn.Module):
    """A fitted :class:`MeshDesign` as a differentiable kernel of its space constants and gains.

    Parameters
    ----------
    design : MeshDesign
        A lattice-model design from :func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh` (the
        initial point).
    size : int, optional
        Odd window side of the kernel (default: the design's :meth:`~MeshDesign.response_size`,
        its whole response).
    bounds : MeshBounds, optional
        The reachable ranges (default ``MeshBounds()``, the fit's defaults).
    """

    # buffers (register_buffer in __init__), declared for the type checker
    c: torch.Tensor
    m: torch.Tensor
    cos_w: torch.Tensor
    pixel_weight: torch.Tensor

    def __init__(self, design: MeshDesign, *, size: int | None = None, bounds: MeshBounds | None = None) -> None:
        super().__init__()
        if not isinstance(design, MeshDesign):
            raise InputError(
                f"MeshKernel: expected a MeshDesign (from fit_resistive_mesh), got {type(design).__name__}"
            )
        if design.model != "lattice":
            raise InputError(f"MeshKernel: model {design.model!r} unsupported; allowed: 'lattice' (the fit's default)")
        self.design = design
        self.bounds = bounds if bounds is not None else MeshBounds()
        self.size = design.response_size() if size is None else int(size)
        if self.size % 2 != 1 or self.size < 1:
            raise InputError(f"MeshKernel: size must be a positive odd integer, got {size!r}")
        b = self.bounds
        self.lam_lo, self.lam_hi = (float(v) for v in b.lambda_px)
        self.g_lo, self.g_hi = (float(v) for v in b.gain)
        self.ratio = float(b.min_lambda_ratio)
        ln, lw = design.lambda_narrow_px, design.lambda_wide_px
        if not (self.lam_lo <= ln <= self.lam_hi and ln * self.ratio <= lw <= self.lam_hi):
            raise InputError(
                f"MeshKernel: the design's λ = ({ln:.4g}, {lw:.4g}) px lies outside the bounds "
                f"{b.lambda_px} with ratio ≥ {self.ratio}"
            )
        if design.whole_dc_gain < 0:
            raise InputError(f"MeshKernel: the design's whole DC gain {design.whole_dc_gain:.4g} is negative")
        r = self.size // 2
        k, w = quadrature_nodes(self.lam_hi, r)
        self.register_buffer("c", torch.as_tensor(2.0 - 2.0 * np.cos(k)), persistent=False)
        m = torch.arange(r + 1, dtype=torch.float64)
        self.register_buffer("m", m, persistent=False)
        self.register_buffer("cos_w", torch.as_tensor(np.cos(np.outer(np.arange(r + 1), k)) * w), persistent=False)
        dtype = torch.float64
        self.lam_narrow_hi = self.lam_hi / self.ratio  # so that the wide mesh's range is never empty
        self.u_narrow = torch.nn.Parameter(
            torch.tensor(_logit((ln - self.lam_lo) / (self.lam_narrow_hi - self.lam_lo)), dtype=dtype)
        )
        lo_w = ln * self.ratio
        self.u_wide = torch.nn.Parameter(torch.tensor(_logit((lw - lo_w) / (self.lam_hi - lo_w)), dtype=dtype))
        # with gain="free" the fit scales every gain by one overall factor (it folds into the event
        # threshold) and its bounds hold for the gains before that factor: parametrise those
        self.overall = float(design.fit.get("overall_gain", 1.0)) if design.fit.get("gain") == "free" else 1.0
        if not (math.isfinite(self.overall) and self.overall > 0):
            raise InputError(f"MeshKernel: the design's overall gain {self.overall!r} must be positive")
        a0, b0, wp0 = (v / self.overall for v in (design.gain_narrow, design.gain_wide, design.pixel_weight))
        if not self.g_lo * (1 - 1e-9) <= a0 <= self.g_hi * (1 + 1e-9):
            raise InputError(
                f"MeshKernel: the design's narrow gain {a0:.4g} (before its overall gain) lies outside "
                f"the gain bounds {b.gain}"
            )
        lg = (math.log(self.g_lo), math.log(self.g_hi))
        self.u_gain = torch.nn.Parameter(torch.tensor(_logit((math.log(a0) - lg[0]) / (lg[1] - lg[0])), dtype=dtype))
        self.u_dc = torch.nn.Parameter(torch.tensor(_logit(b0 / (wp0 + a0)), dtype=dtype))
        self.register_buffer("pixel_weight", torch.tensor(wp0, dtype=dtype), persistent=False)

    # ---------------------------------------------------------------- parameters
    def lambdas(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(λ_narrow, λ_wide) in pixel pitches, inside the bounds and ratio."""
        ln = self.lam_lo + (self.lam_narrow_hi - self.lam_lo) * torch.sigmoid(self.u_narrow)
        lo_w = ln * self.ratio
        return ln, lo_w + (self.lam_hi - lo_w) * torch.sigmoid(self.u_wide)

    def gains(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(a, b) before the overall gain: narrow gain in the gain bounds; wide gain ``(w_p + a) σ(u)``
        so the whole-circuit DC gain is ≥ 0."""
        lg0, lg1 = math.log(self.g_lo), math.log(self.g_hi)
        a = torch.exp(lg0 + (lg1 - lg0) * torch.sigmoid(self.u_gain))
        return a, (self.pixel_weight + a) * torch.sigmoid(self.u_dc)

    def _green(self, lam: torch.Tensor) -> torch.Tensor:
        rho, inv_sq = green_terms(lam * lam, self.c, xp=torch)
        quarter = (self.cos_w * inv_sq) @ (rho[:, None] ** self.m[None, :])  # (m, n)
        full = torch.cat([quarter.flip(0)[:-1], quarter], dim=0)
        return torch.cat([full.flip(1)[:, :-1], full], dim=1)

    def forward(self) -> torch.Tensor:
        """The ``size`` × ``size`` kernel (float64), differentiable in every parameter."""
        ln, lw = self.lambdas()
        a, b = self.gains()
        k = a * self._green(ln) - b * self._green(lw)
        r = self.size // 2
        delta = torch.zeros_like(k)
        delta[r, r] = 1.0
        return self.overall * (k + self.pixel_weight * delta)

    def to_design(self, **fit_info: Any) -> MeshDesign:
        """The current parameters as a :class:`MeshDesign` (vertical conductances as fitted)."""
        with torch.no_grad():
            ln, lw = (float(v) for v in self.lambdas())
            a, b = (float(v) for v in self.gains())
        d = self.design
        if not self.g_lo <= b <= self.g_hi:
            raise InputError(f"MeshKernel.to_design: wide gain {b:.4g} outside the gain bounds {self.bounds.gain}")
        o = self.overall
        return dataclasses.replace(
            d,
            g_lateral_narrow_s=ln * ln * d.g_vertical_narrow_s,
            g_lateral_wide_s=lw * lw * d.g_vertical_wide_s,
            gain_narrow=o * a,
            gain_wide=o * b,
            pixel_weight=o * float(self.pixel_weight),
            fit={**dict(d.fit), "codesigned": True, **fit_info},
        )
