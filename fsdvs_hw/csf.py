"""Human contrast sensitivity functions (CSF) and a kernel's agreement with them.

Models form a registry, :data:`CSF_METHODS`, behind one dispatcher,
:func:`contrast_sensitivity` (the pattern of colour-science's
``contrast_sensitivity_function(method=...)``). Every model takes spatial frequency in **cycles
per degree** of visual angle (cpd) and returns contrast sensitivity (1 / threshold contrast,
dimensionless) — except Mannos–Sakrison, whose published form is normalised (peak ≈ 0.981).

:func:`csf_agreement` compares a kernel's radial response with a CSF as the FS-DVS paper does:
each curve normalised to its own maximum, compared over the band both cover. A kernel lives in
cycles/pixel; the CSF in cycles/degree. With a :class:`Geometry` (pixel pitch and focal length)
the axes are tied physically; without one, the frequency scale (pixels per degree) that best
aligns the curves is fitted and reported, together with the focal length it implies.

References
----------
.. [MS74] J. L. Mannos and D. J. Sakrison, "The effects of a visual fidelity criterion on the
   encoding of images," IEEE Trans. Inf. Theory 20(4):525–536, 1974.
.. [B99] P. G. J. Barten, *Contrast Sensitivity of the Human Eye and Its Effects on Image
   Quality*, SPIE Press, 1999 (implementation: colour-science ``contrast_sensitivity_function_Barten1999``).
.. [D93] S. Daly, "The visible differences predictor: an algorithm for the assessment of image
   fidelity," in *Digital Images and Human Vision*, A. B. Watson (ed.), MIT Press, 1993, pp. 179–206.
.. [WA05] A. B. Watson and A. J. Ahumada, "A standard model for foveal detection of spatial
   contrast," J. Vision 5(9):717–740, 2005 (ModelFest; hyperbolic-secant CSF).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from .errors import InputError
from .kernels import Kernel
from .spectra import (
    NYQUIST_CPP,
    RadialResponse,
    SpectralSummary,
    pixels_per_degree,
    radial_response,
    spectral_summary,
)

__all__ = [
    "CSF_METHODS",
    "CsfAgreement",
    "Geometry",
    "barten_1999",
    "contrast_sensitivity",
    "csf_agreement",
    "csf_peak",
    "daly_1993",
    "mannos_sakrison_1974",
    "watson_ahumada_2005",
]


def _frequencies(f_cpd: Any) -> np.ndarray:
    f = np.asarray(f_cpd, dtype=np.float64)
    if not np.all(np.isfinite(f)):
        raise InputError("spatial frequency must be finite (cycles/degree)")
    if np.any(f < 0):
        raise InputError(f"spatial frequency must be ≥ 0 cycles/degree, got min {float(f.min())}")
    return f


def mannos_sakrison_1974(f_cpd: Any) -> np.ndarray:
    r"""Mannos–Sakrison (1974) CSF [MS74], normalised form.

    :math:`A(f) = 2.6\,(0.0192 + 0.114 f)\,\exp(-(0.114 f)^{1.1})`, f in cycles/degree.
    Peak ≈ 0.981 at ≈ 7.89 cpd; :math:`A(0) = 0.0499`.
    """
    f = _frequencies(f_cpd)
    return 2.6 * (0.0192 + 0.114 * f) * np.exp(-((0.114 * f) ** 1.1))


def barten_1999(f_cpd: Any, **parameters: Any) -> np.ndarray:
    """Barten (1999) CSF [B99], delegated to colour-science.

    Parameters
    ----------
    f_cpd : array_like
        Spatial frequency u in cycles/degree (u = 0 gives 0).
    **parameters
        Passed to ``colour.contrast.contrast_sensitivity_function_Barten1999`` (e.g. ``E`` retinal
        illuminance in Td, ``X_0`` field size in degrees, ``sigma`` in degrees); colour's
        defaults otherwise.
    """
    from colour.contrast import contrast_sensitivity_function_Barten1999

    f = _frequencies(f_cpd)
    out = np.zeros_like(f)
    pos = f > 0
    if np.any(pos):
        out[pos] = contrast_sensitivity_function_Barten1999(u=f[pos], **parameters)
    return out


def daly_1993(
    f_cpd: Any,
    *,
    luminance_cd_m2: float = 100.0,
    image_area_deg2: float = 1.0,
    viewing_distance_m: float = 0.5,
    eccentricity_deg: float = 0.0,
    orientation_rad: float = 0.0,
) -> np.ndarray:
    r"""Daly (1993) visible-differences-predictor CSF [D93].

    .. math::
        S = P \min[S_1(\rho / (r_a r_e r_\theta)),\ S_1(\rho)],\quad
        S_1(\rho) = \left[(3.23(\rho^2 i^2)^{-0.3})^5 + 1\right]^{-1/5}
                    A_l \varepsilon\rho\, e^{-B_l\varepsilon\rho}\sqrt{1 + 0.06\, e^{B_l\varepsilon\rho}}

    with :math:`A_l = 0.801(1 + 0.7/l)^{-0.2}`, :math:`B_l = 0.3(1 + 100/l)^{0.15}`, ε = 0.9,
    P = 250, :math:`r_a = 0.856 d^{0.14}` (accommodation, d in metres),
    :math:`r_e = 1/(1 + 0.24 e)` (eccentricity e in degrees),
    :math:`r_\theta = 0.11\cos 4\theta + 0.89`. ρ in cycles/degree, l adapting luminance in
    cd/m², i² image area in deg². S(0) = 0.
    """
    f = _frequencies(f_cpd)
    for name, v in (
        ("luminance_cd_m2", luminance_cd_m2),
        ("image_area_deg2", image_area_deg2),
        ("viewing_distance_m", viewing_distance_m),
    ):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"daly_1993: {name} must be positive, got {v!r}")
    if not (math.isfinite(eccentricity_deg) and eccentricity_deg >= 0):
        raise InputError(f"daly_1993: eccentricity_deg must be ≥ 0 degrees, got {eccentricity_deg!r}")
    eps, peak = 0.9, 250.0
    a_l = 0.801 * (1 + 0.7 / luminance_cd_m2) ** -0.2
    b_l = 0.3 * (1 + 100.0 / luminance_cd_m2) ** 0.15
    r_a = 0.856 * viewing_distance_m**0.14
    r_e = 1.0 / (1.0 + 0.24 * eccentricity_deg)
    r_t = 0.11 * math.cos(4 * orientation_rad) + 0.89

    def s1(rho: np.ndarray) -> np.ndarray:
        out = np.zeros_like(rho)
        pos = rho > 0
        r = rho[pos]
        low = ((3.23 * (r * r * image_area_deg2) ** -0.3) ** 5 + 1.0) ** -0.2
        out[pos] = low * a_l * eps * r * np.exp(-b_l * eps * r) * np.sqrt(1.0 + 0.06 * np.exp(b_l * eps * r))
        return out

    return peak * np.minimum(s1(f / (r_a * r_e * r_t)), s1(f))


def watson_ahumada_2005(
    f_cpd: Any,
    *,
    gain: float = 373.08,
    f0_cpd: float = 4.1726,
    f1_cpd: float = 1.3625,
    a: float = 0.8493,
    p: float = 0.7786,
) -> np.ndarray:
    r"""Watson–Ahumada (2005) ModelFest CSF [WA05], difference of hyperbolic secants.

    :math:`S(f) = \gamma\,[\operatorname{sech}((f/f_0)^p) - a\,\operatorname{sech}(f/f_1)]`
    with the published best-fit parameters γ = 373.08, f₀ = 4.1726 cpd, f₁ = 1.3625 cpd,
    a = 0.8493, p = 0.7786 (f in cycles/degree).
    """
    f = _frequencies(f_cpd)
    with np.errstate(over="ignore"):  # cosh overflows to inf far beyond 100 cpd: sech -> 0, as it should
        return gain * (1.0 / np.cosh((f / f0_cpd) ** p) - a / np.cosh(f / f1_cpd))


#: Registry of CSF models: canonical name → function ``f(f_cpd, **kwargs)``.
CSF_METHODS: dict[str, Callable[..., np.ndarray]] = {
    "mannos_sakrison_1974": mannos_sakrison_1974,
    "barten_1999": barten_1999,
    "daly_1993": daly_1993,
    "watson_ahumada_2005": watson_ahumada_2005,
}

_ALIASES = {
    "mannos_sakrison": "mannos_sakrison_1974",
    "mannos1974": "mannos_sakrison_1974",
    "ms": "mannos_sakrison_1974",
    "barten": "barten_1999",
    "daly": "daly_1993",
    "watson_ahumada": "watson_ahumada_2005",
    "modelfest": "watson_ahumada_2005",
}


def _method_name(method: str) -> str:
    key = str(method).strip().lower().replace("-", "_").replace(" ", "_").replace("–", "_")
    key = _ALIASES.get(key, key)
    if key not in CSF_METHODS:
        raise InputError(f"CSF method {method!r} unknown; allowed: {', '.join(CSF_METHODS)}")
    return key


def contrast_sensitivity(f_cpd: Any, method: str = "mannos_sakrison_1974", **kwargs: Any) -> np.ndarray:
    """Contrast sensitivity at spatial frequency ``f_cpd`` (cycles/degree) by the named model.

    Parameters
    ----------
    f_cpd : array_like
        Spatial frequency in cycles/degree, ≥ 0.
    method : str
        One of :data:`CSF_METHODS` (aliases: "mannos_sakrison", "barten", "daly",
        "watson_ahumada"/"modelfest").
    **kwargs
        Model parameters (see each model).

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw import contrast_sensitivity
    >>> np.round(contrast_sensitivity(np.array([1.0, 7.89, 30.0])), 3).tolist()   # cycles/degree; peak 0.981
    [0.316, 0.981, 0.187]
    """
    return CSF_METHODS[_method_name(method)](f_cpd, **kwargs)


def csf_peak(method: str = "mannos_sakrison_1974", *, f_max_cpd: float = 100.0, **kwargs: Any) -> tuple[float, float]:
    """(peak frequency in cpd, peak value) of a CSF, by dense log grid + bounded refinement.

    Results for numeric model parameters are cached (the peak of a model does not change).
    """
    name = _method_name(method)
    try:
        return _csf_peak_cached(name, float(f_max_cpd), tuple(sorted(kwargs.items())))
    except TypeError:  # unhashable parameter values: compute directly
        return _csf_peak(name, float(f_max_cpd), kwargs)


@lru_cache(maxsize=64)
def _csf_peak_cached(name: str, f_max_cpd: float, items: tuple[tuple[str, Any], ...]) -> tuple[float, float]:
    return _csf_peak(name, f_max_cpd, dict(items))


def _csf_peak(name: str, f_max_cpd: float, kwargs: dict[str, Any]) -> tuple[float, float]:
    from scipy.optimize import minimize_scalar

    fn = CSF_METHODS[name]
    grid = np.geomspace(0.01, f_max_cpd, 2001)
    vals = fn(grid, **kwargs)
    i = int(np.argmax(vals))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    res = minimize_scalar(
        lambda x: -float(fn(np.array([x]), **kwargs)[0]), bounds=(lo, hi), method="bounded", options={"xatol": 1e-9}
    )
    return float(res.x), float(-res.fun)


@dataclass(frozen=True)
class Geometry:
    """Sensor-plus-lens geometry tying cycles/pixel to cycles/degree.

    Parameters
    ----------
    pitch_m : float
        Pixel pitch in metres.
    focal_length_m : float
        Focal length of the imaging lens in metres.

    Examples
    --------
    >>> from fsdvs_hw import Geometry
    >>> round(Geometry(pitch_m=4.86e-6, focal_length_m=12e-3).pixels_per_degree, 2)
    43.09
    """

    pitch_m: float
    focal_length_m: float

    def __post_init__(self) -> None:
        pixels_per_degree(self.pitch_m, self.focal_length_m)  # validates both

    @property
    def pixels_per_degree(self) -> float:
        """Pixels per degree of visual angle on axis."""
        return pixels_per_degree(self.pitch_m, self.focal_length_m)


@dataclass(frozen=True)
class CsfAgreement:
    """How well a kernel's radial response agrees with a CSF (see :func:`csf_agreement`).

    Attributes
    ----------
    method : str
        CSF model name.
    pixels_per_degree : float
        Frequency scale used (from the geometry, or fitted).
    scale_fitted : bool
        True when ``pixels_per_degree`` was fitted (no geometry given).
    implied_focal_length_m : float or None
        Focal length that gives ``pixels_per_degree`` at the kernel's pitch (fitted case), else
        the geometry's focal length.
    kernel_peak_cpd, csf_peak_cpd : float
        Peak frequencies in cycles/degree (kernel peak is 0 for a low-pass kernel).
    peak_ratio : float
        ``kernel_peak_cpd / csf_peak_cpd`` (1 is ideal; 0 for a low-pass kernel).
    correlation : float
        Pearson correlation of the two peak-normalised curves sampled log-uniformly over the
        band both cover (0 when either curve is constant there, e.g. a delta kernel).
    log_rms_error_dec : float
        Root-mean-square difference of log10 of the peak-normalised curves over that band, in
        decades; each curve is floored at ``floor`` (default 1e-3, i.e. −60 dB) before the log,
        so zero-DC kernels and spectral zeros stay finite.
    rms_error : float
        Root-mean-square difference of the (linear) peak-normalised curves over the band, in
        units of the peak (0 … 1); this is what the scale fit minimises, because it weights the
        pass band, where the shapes matter, rather than the stop-band floor.
    band_cpd : (float, float)
        The compared band in cycles/degree.
    f_cpd, kernel_curve, csf_curve : ndarray
        The sampled curves (peak-normalised).
    """

    method: str
    pixels_per_degree: float
    scale_fitted: bool
    implied_focal_length_m: float | None
    kernel_peak_cpd: float
    csf_peak_cpd: float
    peak_ratio: float
    correlation: float
    log_rms_error_dec: float
    rms_error: float
    band_cpd: tuple[float, float]
    f_cpd: np.ndarray = field(repr=False)
    kernel_curve: np.ndarray = field(repr=False)
    csf_curve: np.ndarray = field(repr=False)

    def to_dict(self, *, curves: bool = False) -> dict[str, Any]:
        """JSON-ready metrics (and the sampled curves when ``curves=True``)."""
        d: dict[str, Any] = {
            "method": self.method,
            "pixels_per_degree": self.pixels_per_degree,
            "scale_fitted": self.scale_fitted,
            "implied_focal_length_m": self.implied_focal_length_m,
            "kernel_peak_cpd": self.kernel_peak_cpd,
            "csf_peak_cpd": self.csf_peak_cpd,
            "peak_ratio": self.peak_ratio,
            "correlation": self.correlation,
            "log_rms_error_dec": self.log_rms_error_dec,
            "rms_error": self.rms_error,
            "band_cpd": list(self.band_cpd),
        }
        if curves:
            d.update(
                f_cpd=self.f_cpd.tolist(), kernel_curve=self.kernel_curve.tolist(), csf_curve=self.csf_curve.tolist()
            )
        return d


def _focal_length_for(ppd: float, pitch_m: float) -> float:
    return pitch_m / (2.0 * math.tan(math.radians(1.0 / ppd) / 2.0))


@lru_cache(maxsize=128)
def _kernel_spectrum(taps_bytes: bytes, size: int) -> tuple[RadialResponse, SpectralSummary]:
    """Radial response and band summary of a kernel, cached by its exact taps.

    Scoring one realisation asks for the agreement with several CSF models; the kernel's
    spectrum is the expensive part and is the same for all of them.
    """
    taps = np.frombuffer(taps_bytes, dtype=np.float64).reshape(size, size)
    return radial_response(taps, n_freq=1025), spectral_summary(taps)


def _compare(
    f_cpp: np.ndarray,
    rr_f: np.ndarray,
    k_norm: np.ndarray,
    csf_fn: Callable[[np.ndarray], np.ndarray],
    csf_max: float,
    ppd: float,
    floor: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    f = f_cpp * ppd
    kc = np.interp(f_cpp, rr_f, k_norm)
    cc = csf_fn(f) / csf_max
    lk = np.log10(np.maximum(kc, floor))
    lc = np.log10(np.maximum(cc, floor))
    log_err = float(np.sqrt(np.mean((lk - lc) ** 2)))
    lin_err = float(np.sqrt(np.mean((kc - cc) ** 2)))
    return f, kc, cc, log_err, lin_err


def _check_band(f_low_cpp: float, n_samples: int, floor: float) -> None:
    """Refuse a compared band outside (0, 0.25) cycles/pixel, under 8 samples, or a floor outside (0, 1)."""
    if not (0 < f_low_cpp < NYQUIST_CPP / 2):
        raise InputError(f"f_low_cpp must be in (0, 0.25) cycles/pixel, got {f_low_cpp}")
    if n_samples < 8:
        raise InputError(f"n_samples must be ≥ 8, got {n_samples}")
    if not (0 < floor < 1):
        raise InputError(f"floor must be in (0, 1), got {floor}")


def _fitted_pixels_per_degree(cost: Callable[[float], float], ppd_bounds: tuple[float, float]) -> float:
    """The pixels-per-degree scale minimising ``cost(ln ppd)`` within ``ppd_bounds``.

    A grid of 121 log-spaced scales, then a bounded refinement between the best one's neighbours
    (kept only where it does better than the grid).

    Parameters
    ----------
    cost : callable
        ln(pixels per degree) → the error to minimise.
    ppd_bounds : (float, float)
        Lowest and highest scale (pixels/degree), ``0 < low < high``.

    Returns
    -------
    float
        Pixels per degree.

    Raises
    ------
    InputError
        Bounds not ``0 < low < high``.
    """
    from scipy.optimize import minimize_scalar

    lo, hi = float(ppd_bounds[0]), float(ppd_bounds[1])
    if not 0 < lo < hi:
        raise InputError(f"ppd_bounds must satisfy 0 < low < high, got {ppd_bounds}")
    grid = np.linspace(math.log(lo), math.log(hi), 121)
    errs = [cost(g) for g in grid]
    i = int(np.argmin(errs))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    res = minimize_scalar(cost, bounds=(a, b), method="bounded", options={"xatol": 1e-6})
    best = float(res.x) if res.fun <= errs[i] else float(grid[i])
    return math.exp(best)


def csf_agreement(
    kernel: Kernel,
    *,
    method: str = "mannos_sakrison_1974",
    geometry: Geometry | None = None,
    f_low_cpp: float = 0.01,
    n_samples: int = 200,
    floor: float = 1e-3,
    ppd_bounds: tuple[float, float] = (1.0, 2000.0),
    csf_kwargs: dict[str, Any] | None = None,
) -> CsfAgreement:
    """Agreement between a kernel's peak-normalised radial response and a peak-normalised CSF.

    The compared band is the kernel's own band, ``f_low_cpp`` … 0.5 cycles/pixel (Nyquist),
    sampled log-uniformly and mapped to cycles/degree with the pixels-per-degree scale; the CSF
    is defined at every f > 0, so this is the band both cover. Keeping the band fixed in the
    kernel's units means a fitted scale cannot improve the score by shrinking the band.
    Both curves are normalised to their own maximum (the kernel over [0, 0.5] cpp, the CSF
    over all frequencies), as in the FS-DVS paper.

    Parameters
    ----------
    kernel : Kernel
        The kernel (any positive scaling gives the same result).
    method : str
        CSF model (see :data:`CSF_METHODS`).
    geometry : Geometry, optional
        Pixel pitch and focal length. Without it, the pixels-per-degree scale that minimises the
        linear RMS difference of the peak-normalised curves (``rms_error``) is fitted within ``ppd_bounds``
        (grid search, then bounded refinement), and the focal length it implies at the kernel's pitch is reported.
    f_low_cpp : float
        Lower end of the compared band, cycles/pixel (default 0.01: one cycle per 100 pixels).
    n_samples : int
        Log-spaced frequency samples in the band.
    floor : float
        Floor applied to both normalised curves before taking log10 (default 1e-3 = −60 dB).
    csf_kwargs : dict, optional
        Parameters passed to the CSF model.

    Returns
    -------
    CsfAgreement

    Examples
    --------
    >>> from fsdvs_hw import Geometry, csf_agreement, reference_kernel
    >>> a = csf_agreement(reference_kernel("dog", 7), geometry=Geometry(4.86e-6, 12e-3))
    >>> round(a.peak_ratio, 3), round(a.correlation, 3)
    (1.037, 0.906)
    """
    if not isinstance(kernel, Kernel):
        kernel = Kernel(kernel)
    name = _method_name(method)
    kw = dict(csf_kwargs or {})
    _check_band(f_low_cpp, n_samples, floor)

    def csf_fn(f: np.ndarray) -> np.ndarray:
        return CSF_METHODS[name](f, **kw)

    csf_peak_cpd, csf_max = csf_peak(name, **kw)
    rr, summary = _kernel_spectrum(kernel.taps.tobytes(), kernel.size)
    k_norm = rr.normalised()
    f_cpp = np.geomspace(f_low_cpp, NYQUIST_CPP, n_samples)

    if geometry is not None:
        ppd = geometry.pixels_per_degree
        fitted, focal = False, geometry.focal_length_m
    else:

        def cost(log_ppd: float) -> float:
            return _compare(f_cpp, rr.f_cpp, k_norm, csf_fn, csf_max, math.exp(log_ppd), floor)[4]

        ppd = _fitted_pixels_per_degree(cost, ppd_bounds)
        fitted, focal = True, _focal_length_for(ppd, kernel.pitch_m)

    f, kc, cc, err, lin_err = _compare(f_cpp, rr.f_cpp, k_norm, csf_fn, csf_max, ppd, floor)
    if np.std(kc) > 0 and np.std(cc) > 0:
        corr = float(np.corrcoef(kc, cc)[0, 1])
    else:
        corr = 0.0
    k_peak_cpd = summary.peak_frequency_cpp * ppd
    return CsfAgreement(
        method=name,
        pixels_per_degree=float(ppd),
        scale_fitted=fitted,
        implied_focal_length_m=float(focal),
        kernel_peak_cpd=float(k_peak_cpd),
        csf_peak_cpd=csf_peak_cpd,
        peak_ratio=float(k_peak_cpd / csf_peak_cpd),
        correlation=corr,
        log_rms_error_dec=err,
        rms_error=lin_err,
        band_cpd=(float(f[0]), float(f[-1])),
        f_cpd=f,
        kernel_curve=kc,
        csf_curve=cc,
    )
