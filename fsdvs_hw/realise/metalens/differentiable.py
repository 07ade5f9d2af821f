r"""The metalens kernel as a torch function of its phase profile, sensor distance and gains.

For co-design a realisation exposes its kernel as a differentiable function of its
physical parameters on the same numerics as the fit. For a :class:`MetalensDesign` those are, per
lens, the radial phase coefficients :math:`c_k` of :math:`(r/a)^{2k+2}` added to the hyperbolic
focusing phase, the lens-to-sensor distance :math:`z`, and the gain applied to the PSF taps. The
PSF comes from the fit's own forward model (the same radial propagation, spectral weights and
pixel integration as the report step of :func:`~fsdvs_hw.realise.metalens.fit_metalens`), so at
the fitted parameters the kernel equals the design's to floating-point accuracy.

The applied kernel is the design's: ``g·P`` for one lens with a pedestal, ``g₊P₊ − g₋P₋`` for a
differential pair. Gains stay positive by construction (``g = exp(u)``); an incoherent PSF is
non-negative by physics, so the pedestal lens's kernel is non-negative whatever the parameters.
The fabrication limit the fit enforces, a local numerical aperture at most the design's budget,
is returned as a differentiable penalty (:meth:`MetalensKernel.na_excess`) for a training loss,
since a phase profile's NA is not a box constraint on its coefficients.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import torch

from ...errors import InputError
from .fit import MetalensDesign, RadialKernelModel

__all__ = ["MetalensKernel"]


class MetalensKernel(torch.nn.Module):
    """A fitted :class:`MetalensDesign` as a differentiable kernel of its lens parameters.

    Parameters
    ----------
    design : MetalensDesign
        The fitted design (initial point, geometry, spectrum, strategy, guard band).
    window_pad : float
        The forward model's window padding; 3.0 is what ``fit_metalens`` evaluates its reported
        PSFs with (its default ``window_pad=2`` raised to 3 for the report).

    Attributes
    ----------
    coefficients : torch.nn.ParameterList
        Per lens, the phase coefficients (rad at the design wavelength).
    defocus_um : torch.nn.Parameter
        Per lens, the change of the lens-to-sensor distance from the fitted one, in µm (so that an
        optimiser's step is on the scale of the depth of focus, not of metres).
    log_gains : torch.nn.Parameter
        Log of each lens's gain.
    """

    # buffer (register_buffer in __init__), declared for the type checker
    z0_m: torch.Tensor

    def __init__(self, design: MetalensDesign, *, window_pad: float = 3.0) -> None:
        super().__init__()
        if not isinstance(design, MetalensDesign):
            raise InputError(
                f"MetalensKernel: expected a MetalensDesign (from fit_metalens), got {type(design).__name__}"
            )
        if not design.gains or design.gains[0] <= 0 or any(g < 0 for g in design.gains[1:]):
            raise InputError(
                f"MetalensKernel: the first lens's gain must be > 0 and a second lens's ≥ 0, got {design.gains}"
            )
        self.design = design
        target = design.target
        n_eval = target.size + 2 * design.guard_px
        budget = float(design.fit_info.get("na_budget", 0.9))
        self.model = RadialKernelModel(
            design.geometry,
            pitch_m=target.pitch_m,
            n_pixels=n_eval,
            spectral=design.spectral,
            n_sub=None,
            window_pad=window_pad,
            na_budget=budget,
        )
        self.na_budget = budget
        dt = torch.float64
        self.coefficients = torch.nn.ParameterList(
            [torch.nn.Parameter(torch.tensor(c, dtype=dt)) for c in design.coefficients]
        )
        self.register_buffer(
            "z0_m", torch.tensor([float(z) for z in design.sensor_distance_m], dtype=dt), persistent=False
        )
        self.defocus_um = torch.nn.Parameter(torch.zeros(len(design.sensor_distance_m), dtype=dt))
        # a differential pair's second gain may be 0 (the fit's fallback): keep it at a tiny value
        self.log_gains = torch.nn.Parameter(
            torch.log(torch.tensor([max(float(g), 1e-30) for g in design.gains], dtype=dt))
        )

    def distance_m(self) -> torch.Tensor:
        """Per lens, the lens-to-sensor distance (m)."""
        return self.z0_m + 1e-6 * self.defocus_um

    def psfs(self) -> list[torch.Tensor]:
        """Per lens, the pixel- and spectrum-integrated PSF on the realised window."""
        return [self.model.psf(c, z) for c, z in zip(self.coefficients, self.distance_m())]

    def forward(self) -> torch.Tensor:
        """The applied kernel on the (k + 2·guard)² window: ``g·P`` or ``g₊P₊ − g₋P₋``."""
        g = torch.exp(self.log_gains)
        p = self.psfs()
        k = g[0] * p[0]
        if self.design.strategy == "differential":
            k = k - g[1] * p[1]
        return k

    def local_na(self) -> torch.Tensor:
        r"""Largest local numerical aperture of the lenses' phase profiles over the spectrum.

        Local NA at radius r and wavelength λ: :math:`\lambda\,|\partial\phi_\lambda/\partial r| / (2\pi)`
        with :math:`\phi_\lambda` the phase at λ (the design's dispersion model), evaluated on the
        forward model's pupil radii by finite differences.
        """
        m = self.model
        lam = torch.as_tensor(self.design.spectral.wavelengths_m, dtype=torch.float64)[:, None]
        r = torch.as_tensor(m.prop.r_pupil, dtype=torch.float64)
        worst = []
        for c in self.coefficients:
            phi0 = m._hyp + m._powers[:, : c.shape[0]] @ c  # rad at the design wavelength
            slope = torch.abs(torch.diff(phi0) / torch.diff(r))[None, :] * m.phase_scale  # (L, R-1)
            worst.append((lam * slope / (2 * math.pi)).max())
        return torch.stack(worst).max()

    def na_excess(self) -> torch.Tensor:
        """``max(0, local NA − budget)²``: 0 while the phase stays buildable (a training penalty)."""
        return torch.clamp(self.local_na() - self.na_budget, min=0.0) ** 2

    def to_design(self, **fit_info: Any) -> MetalensDesign:
        """The current parameters as a :class:`MetalensDesign` (PSFs and totals re-evaluated)."""
        with torch.no_grad():
            psfs = tuple(p.numpy().copy() for p in self.psfs())
            totals = tuple(float(self.model.total(c, z)) for c, z in zip(self.coefficients, self.distance_m()))
            gains = tuple(float(v) for v in torch.exp(self.log_gains))
            coeffs = tuple(tuple(float(v) for v in c) for c in self.coefficients)
            dist = tuple(float(z) for z in self.distance_m())
        return dataclasses.replace(
            self.design,
            coefficients=coeffs,
            sensor_distance_m=dist,
            gains=gains,
            psfs=psfs,
            psf_totals=totals,
            fit_info={**dict(self.design.fit_info), "codesigned": True, **fit_info},
        )
