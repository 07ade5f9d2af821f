r"""Published energies and areas of digital operations, and their scaling to another process.

The reference is M. Horowitz, "Computing's energy problem (and what we can do about it)", ISSCC
2014, pp. 10-14: energy per operation and area at 45 nm and 0.9 V. The values used here
(:data:`HOROWITZ_2014`) are its integer-add, integer-multiply and 8 KB SRAM entries:

==========================  ===========  ===========
operation (45 nm, 0.9 V)    energy (pJ)  area (µm²)
==========================  ===========  ===========
8-bit add                   0.03         36
32-bit add                  0.1          137
8-bit multiply              0.2          282
32-bit multiply             3.1          3495
8 KB SRAM, 64-bit read      10           –
==========================  ===========  ===========

Scaling rule (stated, and the user's to change through the ``[costs]`` keys): dynamic energy is
:math:`C V^2` with the switched capacitance :math:`C \propto F` (feature size), so

.. math:: E(F, V) = E_{45} \cdot \frac{F}{45\,\mathrm{nm}} \cdot \left(\frac{V}{0.9\,\mathrm{V}}\right)^2,
          \qquad A(F) = A_{45} \cdot \left(\frac{F}{45\,\mathrm{nm}}\right)^2 .

This is classical (Dennard) scaling; below about 28 nm wires and leakage make it optimistic for
energy. An adder of ``b`` bits between the two published widths is interpolated linearly in
``b`` (a ripple-carry adder's energy and area grow linearly with its width) and extrapolated
linearly outside them. An SRAM access costs the 64-bit read's energy per bit (10 pJ / 64 bits).

Examples
--------
>>> from fsdvs_hw.costs.process import adder_energy_j, scaled_energy_j
>>> round(adder_energy_j(8) * 1e12, 4)
0.03
>>> round(scaled_energy_j(1e-12, node_m=90e-9, supply_v=1.8) * 1e12, 3)
8.0
"""

from __future__ import annotations

from types import MappingProxyType

__all__ = [
    "HOROWITZ_2014",
    "HOROWITZ_SOURCE",
    "REFERENCE_NODE_M",
    "REFERENCE_SUPPLY_V",
    "adder_area_m2",
    "adder_energy_j",
    "scaled_area_m2",
    "scaled_energy_j",
    "sram_energy_per_bit_j",
]

#: Node and supply of :data:`HOROWITZ_2014` (metres, volts).
REFERENCE_NODE_M = 45e-9
REFERENCE_SUPPLY_V = 0.9

#: Horowitz, ISSCC 2014 (45 nm, 0.9 V): energy in joules and area in m² per operation.
HOROWITZ_2014 = MappingProxyType(
    {
        "add_8bit_j": 0.03e-12,
        "add_32bit_j": 0.1e-12,
        "mult_8bit_j": 0.2e-12,
        "mult_32bit_j": 3.1e-12,
        "sram_8kb_read_64bit_j": 10e-12,
        "add_8bit_m2": 36e-12,
        "add_32bit_m2": 137e-12,
        "mult_8bit_m2": 282e-12,
        "mult_32bit_m2": 3495e-12,
    }
)

#: Where :data:`HOROWITZ_2014` comes from (shown with every figure built on it).
HOROWITZ_SOURCE = "Horowitz, ISSCC 2014 (45 nm, 0.9 V energy and area tables)"


def scaled_energy_j(energy_45_j: float, *, node_m: float, supply_v: float) -> float:
    """Energy at node ``node_m`` (m) and supply ``supply_v`` (V) of one given at 45 nm, 0.9 V (J).

    ``E · (F / 45 nm) · (V / 0.9 V)²`` (module docstring).
    """
    return energy_45_j * (node_m / REFERENCE_NODE_M) * (supply_v / REFERENCE_SUPPLY_V) ** 2


def scaled_area_m2(area_45_m2: float, *, node_m: float) -> float:
    """Area at node ``node_m`` (m) of one given at 45 nm (m²): ``A · (F / 45 nm)²``."""
    return area_45_m2 * (node_m / REFERENCE_NODE_M) ** 2


def _adder_line(bits: float, at8: float, at32: float) -> float:
    return at8 + (at32 - at8) * (float(bits) - 8.0) / 24.0


def adder_energy_j(bits: float, *, node_m: float = REFERENCE_NODE_M, supply_v: float = REFERENCE_SUPPLY_V) -> float:
    """Energy of one ``bits``-wide addition (J): Horowitz's 8- and 32-bit adds, linear in width, scaled."""
    e45 = _adder_line(bits, HOROWITZ_2014["add_8bit_j"], HOROWITZ_2014["add_32bit_j"])
    return scaled_energy_j(e45, node_m=node_m, supply_v=supply_v)


def adder_area_m2(bits: float, *, node_m: float = REFERENCE_NODE_M) -> float:
    """Area of one ``bits``-wide adder (m²): Horowitz's 8- and 32-bit adders, linear in width, scaled."""
    return scaled_area_m2(_adder_line(bits, HOROWITZ_2014["add_8bit_m2"], HOROWITZ_2014["add_32bit_m2"]), node_m=node_m)


def sram_energy_per_bit_j(*, node_m: float = REFERENCE_NODE_M, supply_v: float = REFERENCE_SUPPLY_V) -> float:
    """Energy of reading or writing one SRAM bit (J): the 8 KB 64-bit read over 64, scaled."""
    return scaled_energy_j(HOROWITZ_2014["sram_8kb_read_64bit_j"] / 64.0, node_m=node_m, supply_v=supply_v)
