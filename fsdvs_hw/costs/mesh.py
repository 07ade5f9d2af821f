r"""Physical cost of a dual resistive mesh: bias power, device area, settling latency.

Model (stated; every parameter a ``[costs]`` key of :class:`~fsdvs_hw.costs.assumptions.CostAssumptions`):

* **Conductances as subthreshold transistors.** Each mesh conductance ``g`` is Mead's horizontal
  resistor (HRes), whose current is :math:`I = I_b \tanh(\Delta V / 2U_T)`, so its small-signal
  conductance is :math:`g = I_b / 2U_T` and it draws the bias :math:`I_b = 2 U_T g` from the
  analog supply (C. Mead, *Analog VLSI and Neural Systems*, Addison-Wesley 1989, ch. 7;
  M. Mahowald & C. Mead, "The silicon retina", Sci. Am. 1991). :math:`U_T = kT/q`.
  A pixel carries two lateral conductances per mesh (to its right and lower neighbours; each
  edge belongs to one pixel) and one vertical conductance per mesh.
* **Transconductors.** The fit's five transconductors per pixel (two injections, three weighted
  outputs) are simple subthreshold OTAs, :math:`g_m = \kappa I_b / 2U_T`, each biased so its
  :math:`g_m` equals the mean vertical conductance of the two meshes (what sets the node's
  gain): :math:`I_b = 2 U_T \bar g_v / \kappa`.
* **Static power per pixel** :math:`P = V_{dd,a}\,(\sum_g 2U_T g + 5 \cdot 2U_T \bar g_v/\kappa)`,
  the array's :math:`P \cdot H W`.
* **Area per pixel**: transistors × ``transistor_area_f2`` · F² (4 per HRes conductance: two pass
  transistors and their two gate-bias transistors, Mead 1989; 5 per OTA: differential pair, current
  mirror, tail) plus the two node capacitors at ``capacitor_density_f_m2`` (the fit's node
  capacitance realised as a MIM capacitor, a worst case: part of it may be parasitic). The
  photodiode keeps :math:`1 - A / p^2` of the pixel (``fill_factor``); the mesh does not fit when
  :math:`A > p^2`.
* **Mismatch**: the relative kernel error expected from a relative die-level conductance mismatch
  σ (``costs.mesh_mismatch_sigma``) is the fit's ``mismatch_sensitivity`` times σ (first order).
* **Latency**: the slower mesh's settling time constant :math:`\tau = C / g_v` (one time constant,
  63 % settled), as the fit reports it.

Examples
--------
>>> from fsdvs_hw.costs.assumptions import CostAssumptions
>>> from fsdvs_hw.costs.mesh import mesh_cost
>>> items = {"g_lateral_narrow": 1e-8, "g_vertical_narrow": 4e-8, "g_lateral_wide": 1e-8,
...          "g_vertical_wide": 2e-8, "node_capacitance": 1e-13, "tau_narrow": 2.5e-6, "tau_wide": 5e-6}
>>> figs, flags = mesh_cost(items, CostAssumptions(), pitch_m=4.86e-6)
>>> f"{figs['power_per_pixel_w'].value:.3e}"
'2.925e-08'
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from .assumptions import CostAssumptions
from .record import CostFigure

__all__ = ["HRES_TRANSISTORS", "OTA_TRANSISTORS", "mesh_cost", "process_mesh_cost", "thermal_voltage_v"]

#: Transistors of one Mead HRes conductance and of one simple OTA.
HRES_TRANSISTORS = 4
OTA_TRANSISTORS = 5

_BOLTZMANN_J_K = 1.380649e-23
_ELEMENTARY_CHARGE_C = 1.602176634e-19
_MEAD = "Mead, Analog VLSI and Neural Systems, 1989 (HRes g = I_b/2U_T; OTA g_m = κI_b/2U_T)"


def thermal_voltage_v(temperature_k: float) -> float:
    """:math:`U_T = kT/q` in volts (25.85 mV at 300 K)."""
    return _BOLTZMANN_J_K * temperature_k / _ELEMENTARY_CHARGE_C


def mesh_cost(
    items: Mapping[str, float], a: CostAssumptions, *, pitch_m: float, transconductors: int = 5
) -> tuple[dict[str, CostFigure], list[str]]:
    """Power, area and latency figures of a fitted dual mesh (module docstring).

    Parameters
    ----------
    items : mapping
        The mesh's stored cost items by name, values in their SI units: ``g_lateral_narrow``,
        ``g_vertical_narrow``, ``g_lateral_wide``, ``g_vertical_wide`` (S), ``node_capacitance``
        (F), ``tau_narrow``, ``tau_wide`` (s); optionally ``mismatch_sensitivity`` (1).
    a : CostAssumptions
        The ``[costs]`` section.
    pitch_m : float
        Pixel pitch (m).
    transconductors : int
        Transconductors per pixel (the fit's count).

    Returns
    -------
    figures, flags
        ``power_w`` (array), ``power_per_pixel_w``, ``area_m2`` (per pixel), ``fill_factor``,
        ``latency_s``, ``mismatch_error`` (when ``items`` has ``mismatch_sensitivity``); flags in
        words (the mesh does not fit in the pixel).
    """
    ut = thermal_voltage_v(a.temperature_k)
    g_l = [items["g_lateral_narrow"], items["g_lateral_wide"]]
    g_v = [items["g_vertical_narrow"], items["g_vertical_wide"]]
    sum_g = 2.0 * sum(g_l) + sum(g_v)
    i_mesh = 2.0 * ut * sum_g
    i_ota = transconductors * 2.0 * ut * (sum(g_v) / 2.0) / a.subthreshold_slope
    p_pixel = a.analog_supply_v * (i_mesh + i_ota)
    n_pixels = a.array_resolution[0] * a.array_resolution[1]
    src_p = (
        f"{_MEAD}; bias currents at costs.analog_supply_v = {a.analog_supply_v:g} V, "
        f"costs.temperature_k = {a.temperature_k:g} K, costs.subthreshold_slope = {a.subthreshold_slope:g}"
    )
    n_transistors = 6 * HRES_TRANSISTORS + transconductors * OTA_TRANSISTORS
    a_transistors = n_transistors * a.transistor_area_f2 * a.process_node_m**2
    a_caps = 2.0 * items["node_capacitance"] / a.capacitor_density_f_m2
    area = a_transistors + a_caps
    pixel_area = pitch_m**2
    src_a = (
        f"{n_transistors} transistors x costs.transistor_area_f2 = {a.transistor_area_f2:g} F² at "
        f"costs.process_node_m = {a.process_node_m:g} m, 2 node capacitors at costs.capacitor_density_f_m2 = "
        f"{a.capacitor_density_f_m2:g} F/m²"
    )
    tau = max(items["tau_narrow"], items["tau_wide"])
    figs = {
        "power_w": CostFigure(p_pixel * n_pixels, "W", src_p + f"; x {n_pixels} pixels (costs.array_resolution)"),
        "power_per_pixel_w": CostFigure(p_pixel, "W", src_p),
        "area_m2": CostFigure(area, "m^2", src_a),
        "fill_factor": CostFigure(
            max(0.0, 1.0 - area / pixel_area), "1", f"1 - mesh area / pixel area ({pitch_m:g} m pitch)"
        ),
        "latency_s": CostFigure(tau, "s", "the slower mesh's settling time constant C/g_v (fit)"),
    }
    if "mismatch_sensitivity" in items:
        figs["mismatch_error"] = CostFigure(
            items["mismatch_sensitivity"] * a.mesh_mismatch_sigma,
            "1",
            "fit's mismatch_sensitivity x costs.mesh_mismatch_sigma = "
            f"{a.mesh_mismatch_sigma:g} (relative kernel error)",
        )
    flags = []
    if area > pixel_area:
        flags.append(f"the mesh ({area * 1e12:.3g} µm²) does not fit in the {pixel_area * 1e12:.3g} µm² pixel")
    if not math.isfinite(p_pixel):
        flags.append("the mesh's conductances are not finite")
    return figs, flags


def process_mesh_cost(
    items: Mapping[str, float],
    a: CostAssumptions,
    *,
    pitch_m: float,
    sources: Mapping[str, str],
    transconductors: int = 5,
    nominal_g_vertical_s: tuple[float, float] | None = None,
) -> tuple[dict[str, CostFigure], list[str]]:
    """Power, area and latency of a mesh built in a process (``mesh_process``), from its simulations.

    The mesh's own figures come from the process (the realisation's cost items and their sources:
    ``mesh_area_m2`` from the devices' W·L with stated layout rules and the PDK's MIM density,
    ``power_w`` from the operating point's supply current, ``tau_*`` from the scored condition's
    conductances, ``mismatch_error_vs_nominal`` from the Monte Carlo); the transconductors (injection
    and readout, not built in the process) keep the literature model of :func:`mesh_cost`, and every
    figure's source says which part came from where.

    Parameters
    ----------
    items : mapping
        The realisation's cost items by name (SI units).
    a : CostAssumptions
        The ``[costs]`` section (array size; the transconductors' literature model).
    pitch_m : float
        Pixel pitch (m).
    sources : mapping
        Cost item name → its description (which holds its source, e.g. "sky130 tt 27 °C, ngspice 39").
    transconductors : int
        Transconductors per pixel.
    nominal_g_vertical_s : (float, float), optional
        The vertical conductances (narrow, wide) at the nominal condition (S), where the mesh's
        own power is taken; the transconductors are biased to match them. Default: the items'.
    """
    ut = thermal_voltage_v(a.temperature_k)
    g_vn, g_vw = nominal_g_vertical_s or (items["g_vertical_narrow"], items["g_vertical_wide"])
    g_v_mean = (g_vn + g_vw) / 2.0
    p_ota = a.analog_supply_v * transconductors * 2.0 * ut * g_v_mean / a.subthreshold_slope
    a_ota = transconductors * OTA_TRANSISTORS * a.transistor_area_f2 * a.process_node_m**2
    p_pixel = items["power_w"] + p_ota
    area = items["mesh_area_m2"] + a_ota
    n_pixels = a.array_resolution[0] * a.array_resolution[1]
    lit = f"{transconductors} transconductors: {_MEAD} at the [costs] assumptions"
    src_p = f"mesh: {sources.get('power_w', 'process')}; {lit}"
    src_a = (
        f"mesh: {sources.get('mesh_area_m2', 'process')}; {lit}, costs.transistor_area_f2 = {a.transistor_area_f2:g} F²"
    )
    if "settling_s" in items:
        tau, src_t = items["settling_s"], sources.get("settling_s", "process transient")
    else:
        tau = max(items["tau_narrow"], items["tau_wide"])
        src_t = f"the slower mesh's C/g_v at the scored condition's conductances ({sources.get('kernel_error_worst_corner', 'process')})"
    figs = {
        "power_w": CostFigure(p_pixel * n_pixels, "W", src_p + f"; x {n_pixels} pixels (costs.array_resolution)"),
        "power_per_pixel_w": CostFigure(p_pixel, "W", src_p),
        "area_m2": CostFigure(area, "m^2", src_a),
        "fill_factor": CostFigure(
            max(0.0, 1.0 - area / pitch_m**2), "1", f"1 - mesh area / pixel area ({pitch_m:g} m pitch)"
        ),
        "latency_s": CostFigure(
            tau,
            "s",
            src_t,
        ),
    }
    if "mismatch_error_vs_nominal" in items:
        figs["mismatch_error"] = CostFigure(
            items["mismatch_error_vs_nominal"], "1", sources.get("mismatch_error_vs_nominal", "process Monte Carlo")
        )
    flags = []
    if area > pitch_m**2:
        flags.append(f"the mesh ({area * 1e12:.3g} µm², process) does not fit in the {pitch_m**2 * 1e12:.3g} µm² pixel")
    return figs, flags
