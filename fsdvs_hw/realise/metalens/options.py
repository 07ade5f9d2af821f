"""Fit options of :func:`~fsdvs_hw.realise.metalens.fit_metalens`: type, unit, range, default, meaning.

The design loader checks a ``[realisations.metalens]`` table against :class:`MetalensOptions` and
:func:`fit_metalens` checks its own arguments against it at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words. The ranges are the fit function's own (see its docstring).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from ...schema import PyObject, StrictModel, field
from ...validation import PITCH_RANGE_M

__all__ = ["MetalensOptions"]


class MetalensOptions(StrictModel):
    """Keyword options of :func:`~fsdvs_hw.realise.metalens.fit_metalens`."""

    unknown_key = "unknown option of fit_metalens"

    pitch_m: float | None = field(
        None, "m", "pixel pitch (default: the kernel's)", ge=PITCH_RANGE_M[0], le=PITCH_RANGE_M[1]
    )
    illuminant: str | Annotated[float, Field(ge=1e-7, le=2e-5)] | PyObject = field(
        "D65", "m", "colour illuminant name, a spectral distribution, or one wavelength in metres"
    )
    response: str | PyObject | None = field(None, "", "sensor spectral response (default photopic V(λ))")
    strategy: Literal["pedestal", "differential"] = field("pedestal", "", "signed-kernel strategy")
    aperture_m: float | None = field(100e-6, "m", "lens aperture diameter", gt=1e-7, le=1e-1)
    focal_length_m: float | None = field(200e-6, "m", "lens focal length", ge=1e-7, le=1.0)
    design_wavelength_m: float = field(555e-9, "m", "design wavelength", ge=1e-7, le=2e-5)
    dispersion: Literal["diffractive", "achromatic"] = field("diffractive", "", "dispersion model")
    n_terms: int = field(4, "", "polynomial phase terms", ge=0, le=12)
    n_wavelengths: Annotated[int, Field(ge=1, le=200)] | Literal["auto"] = field(24, "", "spectral samples, or 'auto'")
    guard_px: int = field(2, "px", "ring of pixels where spilled light counts as error", ge=0, le=8)
    max_iter: int = field(150, "", "L-BFGS iterations of the final refinement", ge=1, le=100000)
    n_starts: int = field(6, "", "defocus starting points", ge=1, le=1000)
    n_sub: int | None = field(
        None, "", "pixel-integration nodes per axis (None: from the PSF's bandwidth)", ge=1, le=4096
    )
    window_pad: float = field(2.0, "", "radial-model window padding factor", ge=1.0, le=16.0)
    na_max: float | None = field(None, "", "largest local numerical aperture of the phase", gt=0.0, lt=1.0)
    progress: bool | None = field(None, "", "progress bar of the fit's iterations (None: when stderr is a terminal)")
