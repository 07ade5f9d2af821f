"""Fit options of :func:`~fsdvs_hw.realise.metalens.fit_metalens`: type, unit, range, default, meaning.

The design loader checks a ``[realisations.metalens]`` table against :data:`OPTIONS` and
:func:`fit_metalens` checks its own arguments against it at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words. The ranges are the fit function's own (see its docstring).
"""

from __future__ import annotations

from ...validation import PITCH_RANGE_M, Option, option

__all__ = ["OPTIONS"]

#: option → schema
OPTIONS: dict[str, Option] = {
    "pitch_m": option("float", None, "m", "pixel pitch (default: the kernel's)", nullable=True,
                      lo=PITCH_RANGE_M[0], hi=PITCH_RANGE_M[1]),
    "illuminant": option("str|float|object", "D65", "m", "colour illuminant name, a spectral distribution, or "
                         "one wavelength in metres", lo=1e-7, hi=2e-5),
    "response": option("str|object", None, "", "sensor spectral response (default photopic V(λ))", nullable=True),
    "strategy": option("str", "pedestal", "", "signed-kernel strategy", choices=("pedestal", "differential")),
    "aperture_m": option("float", 100e-6, "m", "lens aperture diameter", lo=1e-7, hi=1e-1, lo_open=True,
                         nullable=True),
    "focal_length_m": option("float", 200e-6, "m", "lens focal length", lo=1e-7, hi=1.0, nullable=True),
    "design_wavelength_m": option("float", 555e-9, "m", "design wavelength", lo=1e-7, hi=2e-5),
    "dispersion": option("str", "diffractive", "", "dispersion model", choices=("diffractive", "achromatic")),
    "n_terms": option("int", 4, "", "polynomial phase terms", lo=0, hi=12),
    "n_wavelengths": option("int|str", 24, "", "spectral samples, or 'auto'", lo=1, hi=200, choices=("auto",)),
    "guard_px": option("int", 2, "px", "ring of pixels where spilled light counts as error", lo=0, hi=8),
    "max_iter": option("int", 150, "", "L-BFGS iterations of the final refinement", lo=1, hi=100000),
    "n_starts": option("int", 6, "", "defocus starting points", lo=1, hi=1000),
    "n_sub": option("int", None, "", "pixel-integration nodes per axis (None: from the PSF's bandwidth)",
                    lo=1, hi=4096, nullable=True),
    "window_pad": option("float", 2.0, "", "radial-model window padding factor", lo=1.0, hi=16.0),
    "na_max": option("float", None, "", "largest local numerical aperture of the phase", lo=0.0, hi=1.0,
                     lo_open=True, hi_open=True, nullable=True),
    "progress": option("bool", None, "", "progress bar of the fit's iterations (None: when stderr is a terminal)",
                       nullable=True),
}
