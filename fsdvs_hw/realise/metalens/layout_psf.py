r"""The PSF of what would be fabricated: the layout's per-site complex transmission, propagated.

Two steps between the ideal phase profile and the layout, each its own PSF:

* **library** (:func:`library_psf`): the radially symmetric pupil whose field at radius r is the
  library's transmission :math:`t_{l(r)}(\lambda)` of the radius level chosen there — radius
  quantisation, amplitude dips and the pillars' own dispersion, on a continuous radius; radial
  angular spectrum (:class:`~fsdvs_hw.realise.metalens.fit.RadialKernelModel`), the ideal lens's
  propagation, spectral weights and pixel integration.
* **layout** (:func:`layout_psf`): the lattice itself — one complex transmission per site, held
  over the site's unit cell (for a square lattice the cell is the grid sample; a hexagonal lattice
  is resampled on a square grid of half its period, each sample taking its nearest site), the
  aperture filled by whole cells — propagated by the 2-D band-limited angular spectrum
  (:func:`~fsdvs_hw.realise.optics.angular_spectrum_2d`) to the sensor and integrated over each
  pixel (exact box overlaps of the samples) and over the spectrum. A period below the shortest
  wavelength sends every lattice diffraction order but the zero order evanescent, so the site
  samples carry all the propagating field (the local-periodicity approximation of the library).

Taps are fractions of the power falling on the ideal aperture (π a², unit intensity), so the
library's transmission losses lower them: the efficiency comes from the library.

Example
-------
>>> import numpy as np
>>> from fsdvs_hw.realise.metalens.layout_psf import pixel_overlaps
>>> w = pixel_overlaps(np.array([-1.0, 0.0, 1.0]), 1.0, 3, 1.0)  # samples on pixel centres
>>> w.sum(axis=0).tolist()
[1.0, 1.0, 1.0]
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..optics import angular_spectrum_2d
from ..spectral import SpectralSamples
from .layout import lattice_sites

__all__ = ["layout_psf", "library_psf", "pixel_overlaps"]


def pixel_overlaps(x_m: np.ndarray, dx_m: float, n_pixels: int, pitch_m: float) -> np.ndarray:
    """(samples, pixels): the fraction of each sample's cell [x − dx/2, x + dx/2] inside each pixel.

    Pixels of side ``pitch_m`` are centred on the axis (pixel ``n_pixels // 2`` at x = 0).
    """
    lo = x_m[:, None] - dx_m / 2
    hi = x_m[:, None] + dx_m / 2
    centres = (np.arange(n_pixels) - n_pixels // 2) * pitch_m
    p_lo, p_hi = centres[None, :] - pitch_m / 2, centres[None, :] + pitch_m / 2
    return np.clip(np.minimum(hi, p_hi) - np.maximum(lo, p_lo), 0.0, None) / dx_m


def _fft_size(n: int) -> int:
    """The smallest 2^a·3^b·5^c ≥ ``n``: the propagator's FFTs (of twice this size) run fastest there."""
    best = 2 ** math.ceil(math.log2(max(n, 1)))
    for p3 in range(int(math.log(best, 3)) + 1):
        for p5 in range(int(math.log(best, 5)) + 1):
            m = 3**p3 * 5**p5
            m *= 2 ** max(0, math.ceil(math.log2(n / m)))
            if n <= m < best:
                best = m
    return best


def _grid_field_index(
    sites: np.ndarray, x: np.ndarray, period_m: float, lattice: str, aperture_radius_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Grid samples that lie in a lens cell and the index of their site: (flat sample index, site index)."""
    from scipy.spatial import cKDTree

    xx, yy = np.meshgrid(x, x, indexing="ij")
    near = np.hypot(xx, yy).ravel() <= aperture_radius_m + 2 * period_m
    pts = np.stack([xx.ravel()[near], yy.ravel()[near]], axis=-1)
    # every lattice site around the aperture, the lens's own ones first (the others transmit nothing)
    outer = lattice_sites(aperture_radius_m + 3 * period_m, period_m, lattice)
    inside = np.hypot(outer[:, 0], outer[:, 1]) <= aperture_radius_m * (1 + 1e-12)
    tree = cKDTree(outer)
    _, nearest = tree.query(pts)
    own = cKDTree(sites)
    dist, site_index = own.query(outer[nearest])
    keep = inside[nearest] & (dist < 1e-3 * period_m)
    return np.flatnonzero(near)[keep], site_index[keep]


def layout_psf(
    sites: np.ndarray,
    site_transmission: np.ndarray,
    *,
    period_m: float,
    lattice: str,
    aperture_radius_m: float,
    spectral: SpectralSamples,
    sensor_distance_m: float,
    pitch_m: float,
    n_pixels: int,
    window_pad: float = 1.5,
    focal_length_m: float | None = None,
) -> tuple[np.ndarray, float]:
    """Pixel taps (n, n) and whole-plane power of a lattice of complex transmitters (module docstring).

    Parameters
    ----------
    sites : numpy.ndarray, shape (N, 2)
        Site centres (m), from :func:`~fsdvs_hw.realise.metalens.layout.lattice_sites`.
    site_transmission : numpy.ndarray, complex, shape (L, N)
        Per wavelength of ``spectral``, each site's transmission.
    period_m, lattice, aperture_radius_m
        The lattice and the aperture it fills.
    spectral : SpectralSamples
        Wavelengths and weights.
    sensor_distance_m, pitch_m, n_pixels
        Sensor plane distance (m), pixel pitch (m) and the odd side of the pixel window.
    window_pad : float
        Grid half-width / max(aperture radius, window half-diagonal, diffraction spread).

    Returns
    -------
    taps : numpy.ndarray
        Fractions of the power on the ideal aperture (π a²) landing on each pixel.
    total : float
        Fraction reaching the sensor plane inside the grid (what a uniform scene delivers).
    """
    import torch

    q = 1 if lattice == "square" else 2
    dx = period_m / q
    f = sensor_distance_m if focal_length_m is None else focal_length_m
    spread = 1.22 * float(spectral.wavelengths_m.max()) * f / aperture_radius_m
    half = window_pad * max(aperture_radius_m, (n_pixels / 2) * pitch_m * math.sqrt(2), spread)
    n = _fft_size(2 * int(math.ceil(half / dx)) + 1)
    x = (np.arange(n) - n // 2) * dx  # a sample on the axis; an even grid has one more on the negative side
    flat, index = _grid_field_index(sites, x, period_m, lattice, aperture_radius_m)
    w = torch.from_numpy(pixel_overlaps(x, dx, n_pixels, pitch_m))
    intensity = torch.zeros((n, n), dtype=torch.float64)
    with torch.no_grad():
        for lam, weight, t in zip(spectral.wavelengths_m, spectral.weights, site_transmission):
            field = np.zeros(n * n, dtype=complex)
            field[flat] = t[index]
            out = angular_spectrum_2d(torch.from_numpy(field.reshape(1, n, n)), dx, np.array([lam]), sensor_distance_m)
            intensity += float(weight) * (out[0].real ** 2 + out[0].imag ** 2)
    p_in = math.pi * aperture_radius_m**2
    taps = (w.T @ intensity @ w).numpy() * dx * dx / p_in
    return taps, float(intensity.sum()) * dx * dx / p_in


def library_psf(model: Any, pupil_transmission: np.ndarray, sensor_distance_m: float) -> tuple[np.ndarray, float]:
    """Pixel taps and whole-plane power of a radial pupil of library transmissions.

    ``model`` is a :class:`~fsdvs_hw.realise.metalens.fit.RadialKernelModel`;
    ``pupil_transmission`` (L, M) the field at its pupil radii ``model.prop.r_pupil`` per wavelength.
    """
    import torch

    field = torch.from_numpy(np.asarray(pupil_transmission, dtype=complex))
    with torch.no_grad():
        return model.psf_of_field(field, sensor_distance_m).numpy(), float(
            model.total_of_field(field, sensor_distance_m)
        )
