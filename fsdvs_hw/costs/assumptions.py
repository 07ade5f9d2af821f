"""The ``[costs]`` section of a design file: every assumption a physical cost rests on.

Each key is a named, documented parameter (type, SI unit, range, default) so that a sweep can vary
it (``[sweep] axes = { "costs.process_node_m" = [45e-9, 180e-9] }``) and so that every cost figure
can say which assumption it used. Bad values are refused naming the key, the value and the range
(:mod:`fsdvs_hw.schema`).

Defaults and their sources
--------------------------
* ``process_node_m = 45e-9``, ``digital_supply_v = 0.9``: the node and supply of Horowitz's energy
  and area tables (M. Horowitz, "Computing's energy problem (and what we can do about it)",
  ISSCC 2014, pp. 10-14), so that the default ASIC figures are the published ones unscaled.
* ``array_resolution = [720, 1280]`` and ``readout_limit_eps = 1.066e9``: the Sony/Prophesee
  IMX636 event sensor (1280 × 720 pixels, 4.86 µm pitch, peak readout 1.066 Geps; T. Finateu et
  al., "A 1280×720 back-illuminated stacked temporal contrast event-based vision sensor with
  4.86 µm pixels, 1.066 GEPS readout, ...", ISSCC 2020, paper 5.10).
* ``sram_cell_area_f2 = 171``: Intel's 45 nm 6T SRAM cell of 0.346 µm² (K. Mistry et al., IEDM
  2007) divided by (45 nm)².
* ``transistor_area_f2 = 80``: Horowitz's 8-bit adder (36 µm² at 45 nm) over the 224 transistors
  of 8 mirror full adders (28 each): 0.16 µm² = 79 F² per transistor, laid out. Analog devices
  sized for matching are larger; raise it for them.
* ``mesh_mismatch_sigma = 0.05``: a stated 5 % relative conductance mismatch, the order of
  subthreshold current mismatch of small devices (M. Pelgrom et al., "Matching properties of MOS
  transistors", IEEE JSSC 24(5), 1989, gives the area law; the value is the user's to set).
* ``latency_budget_s = 1e-3`` and ``power_budget_w = 0.1``: hard limits (a realisation beyond
  either is never recommended; :mod:`fsdvs_hw.costs.limits` says what would meet them). Stated
  assumptions: a millisecond is the order of an event camera's latency in dim light, 100 mW the
  order of a whole event sensor's power; set them to the product's budget.
* The others (analog supply, bias model, capacitor density, clock, sample rate, photon budget,
  loss budget) are stated assumptions: typical values, no single source.

Examples
--------
>>> from fsdvs_hw.costs.assumptions import CostAssumptions
>>> CostAssumptions().process_node_m
4.5e-08
>>> CostAssumptions(process_node_m=180e-9).digital_supply_v
0.9
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from ..schema import StrictModel, field

__all__ = ["CostAssumptions"]


class CostAssumptions(StrictModel):
    """``[costs]``: assumptions of the physical cost model (fsdvs_hw.costs)."""

    process_node_m: float = field(
        45e-9,
        "m",
        "CMOS feature size F of the ASIC and the mesh; energies scale "
        "as F·V², areas as F² from Horowitz's 45 nm tables",
        ge=3e-9,
        le=1e-6,
    )
    digital_supply_v: float = field(
        0.9, "V", "supply of the digital filter (ASIC); Horowitz's tables are at 0.9 V", ge=0.3, le=5.0
    )
    analog_supply_v: float = field(1.8, "V", "supply the mesh's bias currents are drawn from", ge=0.3, le=5.0)
    mesh_mismatch_sigma: float = field(
        0.05,
        "",
        "relative die-level mismatch σ of the mesh's conductances (the "
        "mismatch-driven kernel error is the fit's sensitivity times it)",
        ge=0.0,
        le=1.0,
    )
    temperature_k: float = field(300.0, "K", "die temperature (sets the thermal voltage kT/q)", ge=200.0, le=450.0)
    subthreshold_slope: float = field(0.7, "", "subthreshold slope factor κ of the mesh's transistors", gt=0.3, le=1.0)
    transistor_area_f2: float = field(
        80.0,
        "F^2",
        "laid-out area of one transistor in units of F² (80: from Horowitz's 8-bit adder area)",
        ge=10.0,
        le=10000.0,
    )
    capacitor_density_f_m2: float = field(
        2e-3, "F/m^2", "capacitance per area of the mesh's node capacitors (2 fF/µm²: a MIM capacitor)", ge=1e-5, le=1.0
    )
    sram_cell_area_f2: float = field(
        171.0,
        "F^2",
        "6T SRAM cell of the ASIC's line buffers in units of F² (Intel 45 nm: 0.346 µm²)",
        ge=20.0,
        le=2000.0,
    )
    clock_hz: float = field(200e6, "Hz", "ASIC clock (one pixel per cycle and lane)", ge=1e3, le=1e10)
    sample_rate_hz: float = field(
        1e3,
        "Hz",
        "rate at which the ASIC refilters every pixel (the digital filter sees sampled intensity)",
        ge=1.0,
        le=1e7,
    )
    array_resolution: list[Annotated[int, Field(ge=1, le=100000)]] = field(
        [720, 1280], "px", "sensor array [H, W] the costs are given for (IMX636)", min_length=2, max_length=2
    )
    readout_limit_eps: float = field(
        1.066e9, "events/s", "largest event rate the readout carries (IMX636: 1.066 Geps)", gt=0.0, le=1e13
    )
    sensor_illuminance_lux: float = field(
        10.0, "lx", "illuminance at the sensor plane for the photon budget", gt=0.0, le=1e6
    )
    integration_time_s: float = field(1e-3, "s", "photoreceptor integration time of the photon budget", gt=0.0, le=10.0)
    quantum_efficiency: float = field(0.5, "", "photodiode quantum efficiency of the photon budget", gt=0.0, le=1.0)
    latency_budget_s: float = field(
        1e-3,
        "s",
        "largest added event latency a realisation may have (a hard limit: beyond it, never 'build')",
        gt=0.0,
        le=10.0,
    )
    power_budget_w: float = field(
        0.1,
        "W",
        "largest array power of the filter (a hard limit: beyond it, never 'build')",
        gt=0.0,
        le=1e3,
    )
    loss_budget: float = field(
        0.02,
        "",
        "largest accuracy loss (upper CI bound, metric fraction; kernel error "
        "when no task ran) the cost verdict accepts",
        ge=0.0,
        le=10.0,
    )
