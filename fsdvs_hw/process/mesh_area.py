r"""Area, power and pixel fit of the transistor mesh in a process, and the sharing that makes it fit.

Area per pixel (stated layout rules, sky130 drawn values): each of the six mesh transistors
(two meshes × two lateral + one vertical) occupies its gate plus a contacted source and drain and
the spacing to its neighbour, :math:`(W + s_d)(L + 2 c + s_d)` with :math:`c` = 0.29 µm (licon
0.17 µm + poly and diffusion enclosures) and :math:`s_d` = 0.27 µm (diffusion spacing), times a
routing overhead of :data:`ROUTING_OVERHEAD`; the two node capacitors are MIM capacitors at the
PDK's density (2 fF/µm² in sky130, read from its models), placed above the devices (metal 3/4), so
the mesh needs :math:`\max(A_{devices}, A_{MIM})` per pixel. The injection and readout stages are
not counted.

Does it fit a pixel of pitch p? If :math:`A \le p^2`. If not, the smallest pitch is
:math:`\sqrt{A}`, and sharing one mesh node per k×k pixels (the smallest k with
:math:`A \le (k p)^2`) fits at the pixel's pitch: each node then collects its k² pixels' inputs
and every pixel reads its node, so the kernel becomes the mesh's response on the coarser node grid
(space constants λ/k in node units, conductances refitted to keep λ in pixels) box-averaged over
k×k pixels; :func:`shared_kernel` gives it and its error against the target.

Power (per pixel): at rest every device has V_ds = 0 and carries nothing; the largest uniform
signal that keeps each node within U_T/2 of V_r draws :math:`I = g_v U_T / 2` per mesh from the supply,
:math:`P = (g_{v,n} + g_{v,w}) U_T V_{dd} / 2`.

Examples
--------
>>> from fsdvs_hw.process.mesh_area import device_footprint_um2
>>> round(device_footprint_um2(1.0, 2.0), 3)
7.239
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = [
    "CONTACT_UM",
    "DIFF_SPACING_UM",
    "ROUTING_OVERHEAD",
    "device_footprint_um2",
    "mesh_area_per_pixel",
    "mesh_power_w",
    "shared_kernel",
    "sharing_factor",
]

#: Contacted source or drain length beyond the gate (µm): licon 0.17 µm plus enclosures.
CONTACT_UM = 0.29
#: Diffusion-to-diffusion spacing between neighbouring devices (µm).
DIFF_SPACING_UM = 0.27
#: Multiplier for wiring (gate bias lines, node straps) on the device area.
ROUTING_OVERHEAD = 2.0
#: Devices per pixel: two meshes × (two lateral + one vertical).
DEVICES_PER_PIXEL = 6
_BOLTZMANN_OVER_Q = 8.617333262e-5  # V/K


def device_footprint_um2(w_um: float, l_um: float) -> float:
    """Layout area (µm²) of one mesh transistor with its contacts, spacing and routing overhead."""
    return float((w_um + DIFF_SPACING_UM) * (l_um + 2 * CONTACT_UM + DIFF_SPACING_UM) * ROUTING_OVERHEAD)


def mesh_area_per_pixel(
    w_um: float, l_um: float, node_capacitance_f: float, capacitor_f_per_m2: float
) -> dict[str, float]:
    """``devices_m2``, ``capacitor_m2`` and ``total_m2`` (the larger: the MIM lies above the devices)."""
    if capacitor_f_per_m2 <= 0:
        raise InputError(f"capacitor density must be > 0 F/m², got {capacitor_f_per_m2!r}")
    dev = DEVICES_PER_PIXEL * device_footprint_um2(w_um, l_um) * 1e-12
    cap = 2 * float(node_capacitance_f) / capacitor_f_per_m2
    return {"devices_m2": dev, "capacitor_m2": cap, "total_m2": max(dev, cap)}


def sharing_factor(area_m2: float, pitch_m: float, max_k: int = 16) -> int:
    """Smallest k (1 … ``max_k``) with ``area_m2 ≤ (k · pitch_m)²``; ``max_k + 1`` when none is."""
    for k in range(1, max_k + 1):
        if area_m2 <= (k * pitch_m) ** 2:
            return k
    return max_k + 1


def mesh_power_w(
    g_vertical_narrow_s: float, g_vertical_wide_s: float, supply_v: float, temperature_c: float = 27.0
) -> float:
    """Supply power per pixel (W) at the largest uniform signal within U_T/2 per node (see the module text)."""
    u_t = _BOLTZMANN_OVER_Q * (temperature_c + 273.15)
    return float((g_vertical_narrow_s + g_vertical_wide_s) * u_t / 2 * supply_v)


def shared_kernel(design: Any, k: int) -> np.ndarray:
    """The pixel kernel (design window) of ``design`` built with one mesh node per k×k pixels.

    The node mesh keeps λ in pixels (λ/k in nodes: :math:`g_v` scaled by k²); a pixel at offset
    d from the impulse reads node :math:`\\lfloor (u + d)/k \\rfloor` for the impulse's position u
    inside its block, averaged over the k² positions (the shift-averaged kernel).
    """
    import dataclasses

    if not (isinstance(k, int) and k >= 1):
        raise InputError(f"sharing k must be an integer ≥ 1, got {k!r}")
    size = design.size
    if k == 1:
        return np.asarray(design.kernel_taps(size))
    r = size // 2
    node = dataclasses.replace(
        design,
        g_vertical_narrow_s=design.g_vertical_narrow_s * k * k,
        g_vertical_wide_s=design.g_vertical_wide_s * k * k,
        pixel_weight=0.0,
        target=None,
        fit={},
    )
    m = r // k + 2
    taps = np.asarray(node.kernel_taps(2 * m + 1))
    out = np.zeros((size, size))
    for uy in range(k):
        for ux in range(k):
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    ny, nx = math.floor((uy + dy) / k), math.floor((ux + dx) / k)
                    out[dy + r, dx + r] += taps[ny + m, nx + m]
    out /= k * k
    out[r, r] += design.pixel_weight
    return out
