"""Frequency analysis of a kernel: 2-D magnitude spectrum, radial response, band summary.

Spatial frequency inside fsdvs_hw is in **cycles per pixel** (cpp, Nyquist = 0.5) unless a name
says otherwise; :func:`pixels_per_degree` and :func:`cpp_to_cpd` convert to **cycles per degree**
of visual angle (cpd), the unit of the human contrast sensitivity function, given the pixel pitch
and the focal length of the lens in front of the sensor.

The kernel's frequency response is its discrete-time Fourier transform (DTFT)

.. math:: H(f_x, f_y) = \\sum_{m,n} K[m, n]\\, e^{-2\\pi i (f_x x_n + f_y y_m)},

with pixel coordinates :math:`x_n, y_m` centred on the centre tap. The *radial response* is the
angular mean of :math:`|H|` over a circle of radius f (the rotational average used in the FS-DVS
paper's Fig. 6). Two ways to compute it are offered, and their speed/accuracy trade is measured
by ``fsdvs-hw bench csf``:

``"angular"`` (default)
    exact DTFT evaluated on ``n_angles`` directions per frequency (no binning error);
``"fft"``
    the paper's recipe: zero-padded 2-D FFT, averaged over annular bins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError
from .kernels import Kernel

__all__ = [
    "NYQUIST_CPP",
    "RadialResponse",
    "SpectralSummary",
    "cpd_to_cpp",
    "cpp_to_cpd",
    "frequency_response",
    "magnitude_spectrum",
    "pixels_per_degree",
    "radial_response",
    "spectral_summary",
]

#: Nyquist frequency of the pixel grid, cycles/pixel.
NYQUIST_CPP: float = 0.5


def _taps(kernel: Kernel | np.ndarray) -> np.ndarray:
    if isinstance(kernel, Kernel):
        return kernel.taps
    return Kernel(kernel).taps  # validates


def frequency_response(kernel: Kernel | np.ndarray, fx_cpp: np.ndarray, fy_cpp: np.ndarray) -> np.ndarray:
    """Complex DTFT :math:`H(f_x, f_y)` of the kernel at arbitrary frequencies (cycles/pixel).

    ``fx_cpp`` and ``fy_cpp`` broadcast against each other; the result has their broadcast shape.
    """
    k = _taps(kernel)
    r = k.shape[0] // 2
    coords = np.arange(-r, r + 1, dtype=np.float64)
    fx, fy = np.broadcast_arrays(np.asarray(fx_cpp, dtype=np.float64), np.asarray(fy_cpp, dtype=np.float64))
    shape = fx.shape
    ex = np.exp(-2j * np.pi * fx.reshape(-1, 1) * coords)  # (N, k) over columns x
    ey = np.exp(-2j * np.pi * fy.reshape(-1, 1) * coords)  # (N, k) over rows y
    h = np.einsum("fm,mn,fn->f", ey, k, ex)
    return h.reshape(shape)


def magnitude_spectrum(kernel: Kernel | np.ndarray, n_fft: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Zero-padded 2-D FFT magnitude, centred (DC in the middle).

    Parameters
    ----------
    kernel : Kernel or (k, k) array
    n_fft : int
        FFT size per axis (≥ k). Larger values interpolate the spectrum more finely.

    Returns
    -------
    f_cpp : ndarray, shape (n_fft,)
        Frequency axis in cycles/pixel (fftshifted, from -0.5 up).
    magnitude : ndarray, shape (n_fft, n_fft)
        :math:`|H|` with rows along f_y and columns along f_x.
    """
    k = _taps(kernel)
    if not isinstance(n_fft, (int, np.integer)) or n_fft < k.shape[0]:
        raise InputError(f"n_fft must be an integer ≥ kernel size {k.shape[0]}, got {n_fft!r}")
    r = k.shape[0] // 2
    padded = np.zeros((n_fft, n_fft))
    padded[: k.shape[0], : k.shape[1]] = k
    padded = np.roll(padded, (-r, -r), axis=(0, 1))  # centre tap at the origin: zero phase for even kernels
    mag = np.abs(np.fft.fftshift(np.fft.fft2(padded)))
    f = np.fft.fftshift(np.fft.fftfreq(n_fft))
    return f, mag


@dataclass(frozen=True)
class RadialResponse:
    """Rotationally averaged magnitude response.

    Attributes
    ----------
    f_cpp : ndarray
        Radial frequencies, cycles/pixel, from 0 to 0.5 (Nyquist).
    gain : ndarray
        Mean :math:`|H|` over the circle of radius f (same units as the taps' gain).
    method : str
        "angular" or "fft".
    """

    f_cpp: np.ndarray
    gain: np.ndarray
    method: str

    def normalised(self) -> np.ndarray:
        """Gain divided by its maximum (the paper's peak normalisation)."""
        m = float(self.gain.max())
        return self.gain / m if m > 0 else np.zeros_like(self.gain)

    def at(self, f_cpp: np.ndarray | float) -> np.ndarray:
        """Gain linearly interpolated at ``f_cpp`` (clipped to [0, 0.5])."""
        return np.interp(np.clip(f_cpp, 0.0, NYQUIST_CPP), self.f_cpp, self.gain)


def radial_response(
    kernel: Kernel | np.ndarray,
    *,
    n_freq: int = 257,
    method: str = "angular",
    n_angles: int = 64,
    n_fft: int = 256,
) -> RadialResponse:
    """Radial (rotationally averaged) magnitude response on ``n_freq`` points in [0, 0.5] cpp.

    Parameters
    ----------
    kernel : Kernel or (k, k) array
    n_freq : int
        Number of radial frequencies, evenly spaced from 0 to Nyquist (0.5 cycles/pixel).
    method : {"angular", "fft"}
        ``angular``: exact DTFT on ``n_angles`` directions spread over [0, π) (|H| has
        point symmetry, so this covers the whole circle). ``fft``: zero-padded ``n_fft``-point
        2-D FFT averaged over annuli of width 0.5/(n_freq-1) centred on each frequency (empty
        annuli interpolated) — the recipe of the FS-DVS paper.

    Examples
    --------
    >>> from fsdvs_hw import radial_response, reference_kernel
    >>> r = radial_response(reference_kernel("dog", 7), n_freq=65)
    >>> float(r.f_cpp[0]), float(r.f_cpp[-1])        # cycles/pixel, DC to Nyquist
    (0.0, 0.5)
    >>> round(float(r.gain[0]), 4)                   # the DC gain is the sum of the taps
    0.2
    """
    if not isinstance(n_freq, (int, np.integer)) or n_freq < 2:
        raise InputError(f"n_freq must be an integer ≥ 2, got {n_freq!r}")
    f = np.linspace(0.0, NYQUIST_CPP, int(n_freq))
    if method == "angular":
        if n_angles < 1:
            raise InputError(f"n_angles must be ≥ 1, got {n_angles}")
        theta = np.arange(n_angles) * (np.pi / n_angles)
        fx = f[:, None] * np.cos(theta)[None, :]
        fy = f[:, None] * np.sin(theta)[None, :]
        gain = np.abs(frequency_response(kernel, fx, fy)).mean(axis=1)
    elif method == "fft":
        faxis, mag = magnitude_spectrum(kernel, n_fft)
        rho = np.hypot(*np.meshgrid(faxis, faxis, indexing="xy")).ravel()
        step = f[1] - f[0]
        idx = np.rint(rho / step).astype(int)
        keep = idx < f.size
        sums = np.bincount(idx[keep], weights=mag.ravel()[keep], minlength=f.size)
        counts = np.bincount(idx[keep], minlength=f.size)
        filled = counts > 0
        gain = np.interp(f, f[filled], sums[filled] / counts[filled])
    else:
        raise InputError(f"radial_response: method {method!r} unknown; allowed 'angular', 'fft'")
    return RadialResponse(f_cpp=f, gain=gain, method=method)


@dataclass(frozen=True)
class SpectralSummary:
    """Band summary of a kernel's radial response (frequencies in cycles/pixel).

    Attributes
    ----------
    dc_gain : float
        :math:`H(0) = \\sum K` (exact).
    peak_frequency_cpp : float
        Radial frequency of the maximum of the radial response (0 for a low-pass kernel).
    peak_gain : float
        Radial response at the peak.
    band_low_cpp, band_high_cpp : float
        Where the response crosses half of its peak below and above the peak (linear
        interpolation). ``band_low_cpp`` is 0 when the response never falls below half-maximum
        under the peak (low-pass); ``band_high_cpp`` is 0.5 when it stays above half-maximum up
        to Nyquist (then ``band_high_at_nyquist`` is True).
    q : float
        Quality factor ``peak_frequency / (band_high - band_low)``; 0 for a low-pass kernel.
    kind : str
        "all-pass" (above half-maximum everywhere, e.g. the delta), "low-pass" (half-max band
        starts at 0), "band-pass", or "high-pass" (half-max band reaches Nyquist).
    """

    dc_gain: float
    peak_frequency_cpp: float
    peak_gain: float
    band_low_cpp: float
    band_high_cpp: float
    band_high_at_nyquist: bool
    q: float
    kind: str

    def to_dict(self) -> dict[str, Any]:
        return {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in self.__dict__.items()}


def _crossing(f: np.ndarray, g: np.ndarray, level: float, i0: int, i1: int) -> float:
    """Frequency where g crosses `level` between samples i0 and i1 (linear interpolation)."""
    g0, g1 = g[i0], g[i1]
    if g1 == g0:
        return float(f[i0])
    t = (level - g0) / (g1 - g0)
    return float(f[i0] + t * (f[i1] - f[i0]))


def spectral_summary(kernel: Kernel | np.ndarray, *, n_freq: int = 1025) -> SpectralSummary:
    """DC gain, peak frequency, half-maximum band and Q of the radial response (see :class:`SpectralSummary`).

    Examples
    --------
    >>> from fsdvs_hw import reference_kernel, spectral_summary
    >>> round(spectral_summary(reference_kernel("dog", 7)).peak_frequency_cpp, 3)   # band-pass peak
    0.19
    """
    taps = _taps(kernel)
    rr = radial_response(taps, n_freq=n_freq)
    f, g = rr.f_cpp, rr.gain
    ip = int(np.argmax(g))
    peak = float(g[ip])
    half = 0.5 * peak
    lo = 0.0
    below = np.nonzero(g[: ip + 1] < half)[0]
    if below.size:
        j = int(below[-1])
        lo = _crossing(f, g, half, j, j + 1)
    above = np.nonzero(g[ip:] < half)[0]
    at_nyq = above.size == 0
    if at_nyq:
        hi = NYQUIST_CPP
    else:
        j = ip + int(above[0])
        hi = _crossing(f, g, half, j - 1, j)
    fp = float(f[ip])
    q = fp / (hi - lo) if (hi > lo and below.size) else 0.0
    if not below.size:
        kind = "all-pass" if at_nyq else "low-pass"
    elif at_nyq:
        kind = "high-pass"
    else:
        kind = "band-pass"
    return SpectralSummary(
        dc_gain=float(taps.sum()),
        peak_frequency_cpp=fp,
        peak_gain=peak,
        band_low_cpp=lo,
        band_high_cpp=hi,
        band_high_at_nyquist=bool(at_nyq),
        q=float(q),
        kind=kind,
    )


# ---------------------------------------------------------------------- physical units
def _positive_length(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a length in metres, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} must be a positive finite length in metres, got {value!r}")
    return v


def pixels_per_degree(pitch_m: float, focal_length_m: float) -> float:
    """Pixels per degree of visual angle on the optical axis.

    One pixel of pitch p behind a lens of focal length F subtends
    :math:`2\\arctan(p / 2F)` radians, so ``ppd = 1 / degrees(2 atan(p / 2F))``.

    Parameters
    ----------
    pitch_m : float
        Pixel pitch in metres (e.g. 4.86e-6).
    focal_length_m : float
        Focal length in metres (e.g. 4e-3).

    Examples
    --------
    >>> from fsdvs_hw import pixels_per_degree
    >>> round(pixels_per_degree(4.86e-6, 12e-3), 2)   # 4.86 µm pixels behind a 12 mm lens
    43.09
    """
    p = _positive_length("pitch_m", pitch_m)
    fl = _positive_length("focal_length_m", focal_length_m)
    return 1.0 / math.degrees(2.0 * math.atan(p / (2.0 * fl)))


def cpp_to_cpd(f_cpp: np.ndarray | float, ppd: float) -> np.ndarray | float:
    """Cycles/pixel → cycles/degree, given pixels per degree."""
    return np.asarray(f_cpp) * float(ppd) if np.ndim(f_cpp) else float(f_cpp) * float(ppd)


def cpd_to_cpp(f_cpd: np.ndarray | float, ppd: float) -> np.ndarray | float:
    """Cycles/degree → cycles/pixel, given pixels per degree."""
    return np.asarray(f_cpd) / float(ppd) if np.ndim(f_cpd) else float(f_cpd) / float(ppd)
