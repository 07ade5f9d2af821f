r"""Physical cost of a metalens: no power, no silicon, a photon budget and the pedestal's range.

The lens applies the kernel in the optics, so it adds no electrical power, no silicon area and
no latency. What it costs is light (model stated):

* **Photon budget.** Of the light entering the aperture, the fraction ``optical_efficiency``
  (:mod:`fsdvs_hw.realise.metalens`: power inside the kernel window, worst lens) reaches the
  pixels; of that, the share ``pedestal_fraction`` is the uniform pedestal, which carries no
  contrast, and the log-contrast the sensor sees is scaled by ``contrast_factor``. In the
  shot-noise limit, the SNR of a contrast step is :math:`\mathrm{SNR} = c\sqrt{N}`, with
  :math:`N` photoelectrons per pixel, so against an ideal lens of the same aperture (all light
  into the kernel, no pedestal)

  .. math:: \Delta\mathrm{SNR} = 20\log_{10}(\mathrm{contrast\_factor}) + 10\log_{10}(\eta)\ \mathrm{dB},

  independent of the light level. The absolute figure at the stated light level: :math:`N = E_v
  / (683\,\mathrm{lm/W}) / (hc/\lambda) \cdot p^2 \cdot QE \cdot t` at 555 nm (the photopic peak,
  where 1 W = 683 lm), for illuminance ``costs.sensor_illuminance_lux`` on a pixel of pitch
  ``p``, ``costs.quantum_efficiency`` and ``costs.integration_time_s``.
* **Dynamic range.** The pedestal takes ``pedestal_fraction`` of the collected light at every
  pixel, so the signal range above it shrinks by :math:`-20\log_{10}(1 - \mathrm{pedestal\_fraction})` dB.
* **Thickness**: the lens-to-sensor distance (the fit's ``sensor_distance``).
* **Layout** (the ``metalens_layout`` realisation, :mod:`fsdvs_hw.realise.metalens.layout_design`):
  the efficiency above is then the layout PSF's, whose taps are fractions of the power on the ideal
  aperture, so the library's transmission losses are in it; the record adds the pillar count and
  radius levels (the GDS), the mean library power transmission over the used sites and the
  spectrum, the pillar height and lattice period (the meta-atom library), and the kernel errors of
  the ideal-phase and library steps beside the layout's.

Examples
--------
>>> from fsdvs_hw.costs.assumptions import CostAssumptions
>>> from fsdvs_hw.costs.metalens import metalens_cost
>>> figs, _ = metalens_cost({"optical_efficiency": 0.5, "contrast_factor": 1.0, "pedestal_fraction": 0.0},
...                         CostAssumptions(), pitch_m=4.86e-6)
>>> round(figs["photon_snr_change_db"].value, 3)
-3.01
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from .assumptions import CostAssumptions
from .record import CostFigure

__all__ = ["PHOTONS_PER_LUX_S_M2", "metalens_cost"]

_PLANCK_J_S = 6.62607015e-34
_LIGHT_M_S = 299792458.0
#: Photons per second per m² per lux at 555 nm: (1/683 W/m²) / (hc/555 nm) = 4.09e15.
PHOTONS_PER_LUX_S_M2 = (1.0 / 683.0) / (_PLANCK_J_S * _LIGHT_M_S / 555e-9)


def metalens_cost(
    items: Mapping[str, float], a: CostAssumptions, *, pitch_m: float
) -> tuple[dict[str, CostFigure], list[str]]:
    """Zero electrical figures, the photon budget and the pedestal's dynamic range (module docstring).

    Parameters
    ----------
    items : mapping
        The metalens's stored cost items by name: ``optical_efficiency``, ``contrast_factor``
        (1 when absent: a differential pair has no pedestal), ``pedestal_fraction`` (0 when
        absent), ``sensor_distance`` (m, optional).
    a : CostAssumptions
        The ``[costs]`` section.
    pitch_m : float
        Pixel pitch (m).

    Returns
    -------
    figures, flags
        ``power_w``, ``power_per_pixel_w``, ``area_m2``, ``latency_s`` (all 0), ``fill_factor``
        (1), ``photon_snr_change_db``, ``photon_snr_db``, ``photoelectrons``,
        ``dynamic_range_cost_db``, ``thickness_m``.
    """
    eta = float(items["optical_efficiency"])
    cf = float(items.get("contrast_factor", 1.0))
    ped = float(items.get("pedestal_fraction", 0.0))
    n_ideal = a.sensor_illuminance_lux * PHOTONS_PER_LUX_S_M2 * pitch_m**2 * a.quantum_efficiency * a.integration_time_s
    n = n_ideal * eta
    d_snr = 20.0 * math.log10(cf) + 10.0 * math.log10(eta) if eta > 0 and cf > 0 else -math.inf
    light = (
        f"costs.sensor_illuminance_lux = {a.sensor_illuminance_lux:g} lx at 555 nm, costs.quantum_efficiency = "
        f"{a.quantum_efficiency:g}, costs.integration_time_s = {a.integration_time_s:g} s, {pitch_m:g} m pitch"
    )
    none = "optics: no electrical power, silicon or latency"
    figs = {
        "power_w": CostFigure(0.0, "W", none),
        "power_per_pixel_w": CostFigure(0.0, "W", none),
        "area_m2": CostFigure(0.0, "m^2", none),
        "fill_factor": CostFigure(1.0, "1", none),
        "latency_s": CostFigure(0.0, "s", none),
        "photon_snr_change_db": CostFigure(
            d_snr,
            "dB",
            "shot-noise SNR of a contrast step vs an ideal lens: "
            "20 log10(contrast_factor) + 10 log10(optical_efficiency) (fit)",
        ),
        "photon_snr_db": CostFigure(
            20.0 * math.log10(cf * math.sqrt(n)) if n > 0 and cf > 0 else -math.inf,
            "dB",
            "shot-noise SNR of a unit log-contrast step, 20 log10(contrast_factor sqrt(N)), " + light,
        ),
        "photoelectrons": CostFigure(
            n, "1", "photoelectrons per pixel and integration time through the lens, " + light
        ),
        "dynamic_range_cost_db": CostFigure(
            -20.0 * math.log10(1.0 - ped) if ped < 1 else math.inf,
            "dB",
            "-20 log10(1 - pedestal_fraction): signal range taken by the pedestal",
        ),
    }
    figs.update(_layout_figures(items))
    distance = items.get("sensor_distance", items.get("sensor_distance_plus"))
    if distance is not None:
        figs["thickness_m"] = CostFigure(float(distance), "m", "lens-to-sensor distance (fit)")
    return figs, []


#: The layout's items (when present) → (figure name, unit, source).
_LAYOUT_ITEMS = {
    "pillar_count": ("pillars", "1", "pillars in the GDS, one per lattice site in the aperture (layout)"),
    "radius_levels": ("radius_levels", "1", "distinct pillar radii used (layout, meta-atom library)"),
    "library_transmission": (
        "library_transmission",
        "1",
        "mean power transmission |t|² of the used pillars over the spectrum (meta-atom library, RCWA)",
    ),
    "pillar_height": ("pillar_height_m", "m", "pillar height (meta-atom library)"),
    "lattice_period": ("lattice_period_m", "m", "lattice period (meta-atom library)"),
    "ideal_kernel_error": ("ideal_kernel_error", "1", "kernel error of the ideal-phase lens (fit)"),
    "library_kernel_error": ("library_kernel_error", "1", "kernel error with the library's pillars, radial (fit)"),
}


def _layout_figures(items: Mapping[str, float]) -> dict[str, CostFigure]:
    """The metalens layout's own figures, with their sources (none for an ideal-phase lens)."""
    return {
        name: CostFigure(float(items[key]), unit, source)
        for key, (name, unit, source) in _LAYOUT_ITEMS.items()
        if items.get(key) is not None
    }
