"""The lens of the metalens realisation: its fixed geometry, its phase profile and the local NA.

:class:`LensGeometry` holds what the fit does not vary (aperture, focal length, design wavelength,
dispersion model); :func:`design_phase` is the phase φ0(r) at the design wavelength, a hyperbolic
focusing term plus the fitted polynomial; :func:`local_numerical_aperture` is the largest local
NA the phase asks of the metasurface over the spectrum.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ...errors import InputError

__all__ = ["DISPERSION_MODELS", "LensGeometry", "design_phase", "local_numerical_aperture"]

#: dispersion model -> exponent p in φ(r, λ) = φ0(r) (λ0/λ)^p
DISPERSION_MODELS: dict[str, float] = {"diffractive": 0.0, "achromatic": 1.0}


@dataclass(frozen=True)
class LensGeometry:
    """Fixed lens parameters (the fit varies only the phase polynomial and the sensor distance).

    Parameters
    ----------
    aperture_m : float
        Aperture diameter D (m).
    focal_length_m : float
        Focal length f of the hyperbolic term at the design wavelength (m).
    design_wavelength_m : float
        λ0 (m) at which the phase coefficients are defined.
    dispersion : {"diffractive", "achromatic"}
        How the phase scales with wavelength (see module docstring).
    """

    aperture_m: float = 100e-6
    focal_length_m: float = 200e-6
    design_wavelength_m: float = 555e-9
    dispersion: str = "diffractive"

    def __post_init__(self) -> None:
        for name in ("aperture_m", "focal_length_m", "design_wavelength_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a positive finite length in metres, got {v!r}")
        if not (100e-9 <= self.design_wavelength_m <= 20e-6):
            raise InputError(f"design_wavelength_m must be in [100 nm, 20 µm], got {self.design_wavelength_m!r}")
        if self.dispersion not in DISPERSION_MODELS:
            raise InputError(f"dispersion {self.dispersion!r} unknown; allowed: {', '.join(DISPERSION_MODELS)}")

    @property
    def radius_m(self) -> float:
        return 0.5 * self.aperture_m

    @property
    def numerical_aperture(self) -> float:
        """Geometric NA of the hyperbolic focusing term, a/√(a² + f²)."""
        return self.radius_m / math.hypot(self.radius_m, self.focal_length_m)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def design_phase(r: np.ndarray, geometry: LensGeometry, coefficients: Any) -> Any:
    """φ0(r) in rad at λ0; ``coefficients`` may be a torch tensor (then the result is one)."""
    a, f, lam0 = geometry.radius_m, geometry.focal_length_m, geometry.design_wavelength_m
    hyp = -(2 * math.pi / lam0) * (np.sqrt(r * r + f * f) - f)
    rho2 = (r / a) ** 2
    n = len(coefficients)
    if n == 0:
        if hasattr(coefficients, "detach"):
            import torch

            return torch.from_numpy(hyp)
        return hyp
    powers = np.stack([rho2 ** (k + 1) for k in range(n)], axis=-1)  # (M, K)
    if hasattr(coefficients, "detach"):
        import torch

        return torch.from_numpy(hyp) + torch.from_numpy(powers) @ coefficients
    return hyp + powers @ np.asarray(coefficients, dtype=float)


def local_numerical_aperture(
    geometry: LensGeometry, coefficients: Sequence[float] | np.ndarray, wavelengths_m: Sequence[float] | np.ndarray
) -> float:
    r"""Largest local NA of the phase, :math:`\max_{r,\lambda} \lambda |\partial_r\phi(r,\lambda)|/(2\pi)`.

    The lens-plane sampling (and the metasurface unit cell) must satisfy
    :math:`\Delta x \le \lambda_{min}/(2\,NA)`; a value ≥ 1 means the phase asks for evanescent
    waves and cannot be built.
    """
    a = geometry.radius_m
    r = np.linspace(0, a, 2049)
    phi = design_phase(r, geometry, np.asarray(coefficients, dtype=float))
    grad = np.abs(np.gradient(phi, r)).max()
    p = DISPERSION_MODELS[geometry.dispersion]
    lam = np.asarray(wavelengths_m, dtype=float)
    scale = (geometry.design_wavelength_m / lam) ** p
    return float(np.max(lam * grad * scale) / (2 * math.pi))
