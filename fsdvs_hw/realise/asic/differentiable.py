"""Quantisation-aware ASIC taps: the ASIC kernel as a torch function of its own parameters.

For co-design a realisation must expose its kernel as a differentiable function of its
physical parameters, on the same numerics as the fit. For the ASIC those parameters are the
integer coefficients of the symmetry classes and the output scale of an :class:`AsicDesign`:

``K = s · q[labels]``, ``q_c = clamp(round(θ_c), −2^(b−1), 2^(b−1) − 1)``

with θ the continuous ("latent") coefficients. Rounding has zero gradient almost everywhere, so the
backward pass uses the straight-through estimator (Bengio, Léonard & Courville 2013): the
gradient of ``round`` is taken as 1 inside the two's-complement range and 0 where the clamp
saturates. The scale is a free positive number (learned as ``log s``), a power of two
(``s = 2^−round(e)``, the exponent learned straight-through, as in learned-step quantisation,
Esser et al. 2020) or fixed — the fitted design's ``scale_mode``. The integer model is the one
:class:`AsicDesign` already builds, so :meth:`QuantisedAsicKernel.to_design` hands back a design
whose RTL stays bit-exact.

References
----------
Y. Bengio, N. Léonard and A. Courville, "Estimating or propagating gradients through stochastic
neurons for conditional computation", arXiv:1308.3432, 2013.
S. K. Esser et al., "Learned step size quantization", ICLR 2020.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import torch

from ...errors import InputError
from .arith import tap_range
from .fit import AsicDesign

__all__ = ["QuantisedAsicKernel"]


def _round_ste(x: torch.Tensor) -> torch.Tensor:
    """``round(x)`` forward, identity backward (straight-through)."""
    return x + (torch.round(x) - x).detach()


class QuantisedAsicKernel(torch.nn.Module):
    """An ASIC design's kernel as a differentiable function of its class coefficients and scale.

    Parameters
    ----------
    design : AsicDesign
        The fitted design (``fit_asic_taps``): bit width, symmetry, scale mode and the initial
        integer coefficients and scale.
    learn_scale : bool
        Let the scale move (``"free"``: ``log s``; ``"pow2"``: the exponent). A ``"fixed"`` scale
        never moves.

    Attributes
    ----------
    latent : torch.nn.Parameter, shape (n_classes,)
        Continuous coefficients θ in integer units (initialised to the design's integers).
    """

    # buffers or parameters set in __init__, declared for the type checker
    labels: torch.Tensor
    scale_param: torch.Tensor

    def __init__(self, design: AsicDesign, *, learn_scale: bool = True) -> None:
        super().__init__()
        if not isinstance(design, AsicDesign):
            raise InputError(
                f"QuantisedAsicKernel: expected an AsicDesign (from fit_asic_taps), got {type(design).__name__}"
            )
        self.design = design
        cls = design.classes
        self.register_buffer("labels", torch.as_tensor(cls.labels, dtype=torch.long), persistent=False)
        reps = tuple(np.array(cls.representatives).T)
        self.latent = torch.nn.Parameter(torch.as_tensor(design.taps[reps], dtype=torch.float64))
        self.qmin, self.qmax = (float(v) for v in tap_range(design.bits))
        mode = design.scale_mode
        if mode == "pow2":
            init = -math.log2(design.scale)
            if abs(init - round(init)) > 1e-9:
                raise InputError(
                    f"QuantisedAsicKernel: scale_mode 'pow2' but scale {design.scale!r} is not a power of 2"
                )
        elif mode in ("free", "fixed"):
            init = math.log(design.scale)
        else:
            raise InputError(f"QuantisedAsicKernel: scale_mode {mode!r} unknown; allowed: free, pow2, fixed")
        p = torch.tensor(float(round(init) if mode == "pow2" else init), dtype=torch.float64)
        if learn_scale and mode != "fixed":
            self.scale_param = torch.nn.Parameter(p)
        else:
            self.register_buffer("scale_param", p)

    def integer_coefficients(self) -> torch.Tensor:
        """Class coefficients clamped to the two's-complement range and rounded (straight-through)."""
        return _round_ste(torch.clamp(self.latent, self.qmin, self.qmax))

    def scale(self) -> torch.Tensor:
        """The output scale ``s`` (a power of two in ``pow2`` mode)."""
        if self.design.scale_mode == "pow2":
            return torch.pow(torch.tensor(2.0, dtype=torch.float64), -_round_ste(self.scale_param))
        return torch.exp(self.scale_param)

    def forward(self) -> torch.Tensor:
        """The realised ``(k, k)`` kernel ``s · q[labels]`` (float64), differentiable in θ and s."""
        return self.scale() * self.integer_coefficients()[self.labels]

    def to_design(self, **fit_info: Any) -> AsicDesign:
        """The current integer taps and scale as an :class:`AsicDesign` (same bits, symmetry, RTL).

        Raises
        ------
        InputError
            Every coefficient rounds to 0 (the design would pass nothing).
        """
        with torch.no_grad():
            q = self.integer_coefficients()[self.labels].numpy().astype(np.int64)
            s = float(self.scale())
        info = {**dict(self.design.fit_info), "codesigned": True, **fit_info}
        return dataclasses.replace(self.design, taps=q, scale=s, fit_info=info, synthesis=None)
