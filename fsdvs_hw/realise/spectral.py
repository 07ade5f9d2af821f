"""Spectral weights for an optical kernel: illuminant SPD × sensor spectral response.

A pixel integrates the point-spread function over wavelength, weighted by the light that
arrives (the illuminant's spectral power distribution, SPD) and by how strongly the sensor
responds to it. This module turns colour-science data into a small set of representative
wavelengths and weights for that integral.

The quadrature is *equal-weight centroid bins*: the product :math:`w(\\lambda) = S(\\lambda)
R(\\lambda)` is tabulated on a 1 nm grid (linear interpolation of the colour-science tables), its
cumulative integral is split into ``n`` bins that each carry ``1/n`` of the weight, and each bin is
represented by its weighted mean wavelength. Broad, flat spectra get widely spaced samples; a
narrow-band source collapses onto a few nanometres, so the number of samples a scene needs
follows from its spectrum (see :func:`spectral_samples` and the convergence table of
``fsdvs-hw bench metalens``).

colour-science pitfalls handled here: ``SpectralDistribution.align`` works in place, so the
library's shared dataset objects are copied first; and the default Sprague interpolator can
overshoot below zero on sparse data, so a linear interpolator is set before aligning.

References
----------
CIE 1924 photopic luminous efficiency function V(λ) and CIE standard illuminants, as tabulated by
colour-science (Mansencal et al., https://www.colour-science.org/).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["PHOTOPIC", "SpectralSamples", "sampled_spectrum", "spectral_samples", "weighted_spectrum"]

#: Name of the default sensor response: the CIE 1924 photopic luminous efficiency V(λ).
PHOTOPIC = "CIE 1924 Photopic Standard Observer"

_STEP_NM = 1.0


@dataclass(frozen=True)
class SpectralSamples:
    """Representative wavelengths and their weights for a spectral integral.

    Attributes
    ----------
    wavelengths_m : numpy.ndarray, shape (n,)
        Wavelengths in metres, ascending.
    weights : numpy.ndarray, shape (n,)
        Non-negative weights summing to 1.
    illuminant : str
        The illuminant's name (or ``"monochromatic"``).
    response : str
        The sensor response's name.
    """

    wavelengths_m: np.ndarray
    weights: np.ndarray
    illuminant: str
    response: str

    @property
    def n(self) -> int:
        """Number of wavelength samples."""
        return int(self.wavelengths_m.size)

    def to_dict(self) -> dict[str, Any]:
        return {
            "wavelengths_m": [float(x) for x in self.wavelengths_m],
            "weights": [float(x) for x in self.weights],
            "illuminant": self.illuminant,
            "response": self.response,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SpectralSamples:
        return cls(
            np.asarray(data["wavelengths_m"], float),
            np.asarray(data["weights"], float),
            str(data["illuminant"]),
            str(data["response"]),
        )


def _linear_copy(sd: Any) -> Any:
    """A copy of a colour SpectralDistribution with a linear (non-overshooting) interpolator."""
    from colour.algebra import LinearInterpolator

    out = sd.copy()
    out.interpolator = LinearInterpolator
    return out


def _lookup_sd(value: Any, table: Any, what: str) -> tuple[Any, str]:
    from colour import SpectralDistribution

    if isinstance(value, SpectralDistribution):
        return value, str(value.name)
    if isinstance(value, str):
        if value not in table:
            some = ", ".join(list(table)[:12])
            raise InputError(f"{what} {value!r} unknown; allowed: a colour SpectralDistribution or one of {some}, ...")
        return table[value], value
    raise InputError(f"{what} must be a name or a colour.SpectralDistribution, got {type(value).__name__}")


def weighted_spectrum(illuminant: Any = "D65", response: Any = PHOTOPIC) -> tuple[np.ndarray, np.ndarray, str, str]:
    """The product illuminant × response on a 1 nm grid over the tables' common range.

    Returns
    -------
    wavelengths_nm, weight, illuminant_name, response_name
        ``weight`` is normalised to unit sum and is non-negative.
    """
    from colour import SDS_ILLUMINANTS, SpectralShape
    from colour.colorimetry import SDS_LEFS

    sd_s, name_s = _lookup_sd(illuminant, SDS_ILLUMINANTS, "illuminant")
    sd_r, name_r = _lookup_sd(response, SDS_LEFS, "response")
    lo = max(sd_s.shape.start, sd_r.shape.start)
    hi = min(sd_s.shape.end, sd_r.shape.end)
    if hi - lo < _STEP_NM:
        raise InputError(f"illuminant {name_s!r} ({sd_s.shape}) and response {name_r!r} ({sd_r.shape}) do not overlap")
    shape = SpectralShape(lo, hi, _STEP_NM)
    s = _linear_copy(sd_s).align(shape)  # align() is in place: operate on copies only
    r = _linear_copy(sd_r).align(shape)
    w = np.clip(np.asarray(s.values, float), 0, None) * np.clip(np.asarray(r.values, float), 0, None)
    total = float(w.sum())
    if not np.isfinite(total) or total <= 0:
        raise InputError(f"illuminant {name_s!r} × response {name_r!r} has no weight (all zero or not finite)")
    return np.asarray(s.wavelengths, float), w / total, name_s, name_r


def spectral_samples(illuminant: Any = "D65", response: Any = PHOTOPIC, n: int = 8) -> SpectralSamples:
    """Equal-weight centroid samples of illuminant × response.

    Parameters
    ----------
    illuminant : str, colour.SpectralDistribution or float
        A name in ``colour.SDS_ILLUMINANTS`` (default ``"D65"``), a spectral distribution, or a
        single wavelength in metres (monochromatic light; ``response`` and ``n`` are then ignored).
    response : str or colour.SpectralDistribution
        Sensor spectral response; default the CIE 1924 photopic luminous efficiency V(λ).
    n : int
        Number of wavelength samples (1 … 200).

    Returns
    -------
    SpectralSamples
        ``n`` wavelengths (m), each carrying weight ``1/n`` up to the 1 nm tabulation.
    """
    if isinstance(illuminant, (int, float, np.floating)) and not isinstance(illuminant, bool):
        lam = float(illuminant)
        if not (np.isfinite(lam) and 100e-9 <= lam <= 20e-6):
            raise InputError(
                f"illuminant: a monochromatic wavelength must be in metres within [100 nm, 20 µm], got {lam!r}"
            )
        return SpectralSamples(np.array([lam]), np.array([1.0]), "monochromatic", "none")
    if not isinstance(n, (int, np.integer)) or not 1 <= n <= 200:
        raise InputError(f"n_wavelengths must be an integer in 1..200, got {n!r}")
    lam_nm, w, name_s, name_r = weighted_spectrum(illuminant, response)
    # Each 1 nm tabulated sample is a cell [λ-0.5, λ+0.5] of mass w; split the cumulative mass
    # into n equal bins (cells are divided between neighbouring bins where a boundary cuts them).
    edges_mass = np.concatenate([[0.0], np.cumsum(w)])
    edges_nm = np.concatenate([lam_nm - 0.5 * _STEP_NM, [lam_nm[-1] + 0.5 * _STEP_NM]])
    targets = np.linspace(0.0, 1.0, n + 1)
    cuts = np.interp(targets, edges_mass, edges_nm)
    centroids = np.empty(n)
    weights = np.empty(n)
    for i in range(n):
        a, b = cuts[i], cuts[i + 1]
        lo = np.clip(edges_nm[:-1], a, b)
        hi = np.clip(edges_nm[1:], a, b)
        frac = (hi - lo) / _STEP_NM
        m = w * frac
        weights[i] = m.sum()
        centroids[i] = (m * 0.5 * (lo + hi)).sum() / m.sum() if m.sum() > 0 else 0.5 * (a + b)
    weights = weights / weights.sum()
    return SpectralSamples(centroids * 1e-9, weights, name_s, name_r)


def sampled_spectrum(illuminant: Any, response: Any, n_wavelengths: Any) -> SpectralSamples:
    """``illuminant`` itself when it is already :class:`SpectralSamples`, else
    :func:`spectral_samples` of it (``response`` None: the default, :data:`PHOTOPIC`)."""
    if isinstance(illuminant, SpectralSamples):
        return illuminant
    kwargs = {} if response is None else {"response": response}
    return spectral_samples(illuminant, n=n_wavelengths, **kwargs)
