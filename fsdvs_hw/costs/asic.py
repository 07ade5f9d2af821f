r"""Physical cost of the ASIC filter: energy per pixel from Horowitz's table, area, pipeline latency.

The fitted datapath (:mod:`fsdvs_hw.realise.asic`) streams the sampled intensity image in raster
order, one pixel per clock, through line buffers holding ``k − 1`` rows, a k × k window and an
adder tree of ``adders`` two-input adders at the accumulator width. Model (stated):

* **Energy per filtered pixel** :math:`E = n_{add} E_{add}(b_{acc}) + (k - 1 + 1)\, b_{in}\, E_{bit}`:
  every adder at the accumulator width ``b_acc`` (an upper bound: early tree levels are narrower),
  plus the line-buffer traffic, one ``b_in``-bit write and ``k − 1`` reads per pixel at the 8 KB
  SRAM's energy per bit. Energies from Horowitz, ISSCC 2014, scaled to ``costs.process_node_m``
  and ``costs.digital_supply_v`` (:mod:`fsdvs_hw.costs.process`). Clock tree, window registers,
  control and the per-pixel intensity ADC a digital filter needs are not counted: the figure is
  a lower bound.
* **Power** :math:`P = E \cdot H W f_s` at the sample rate ``costs.sample_rate_hz`` over
  the array ``costs.array_resolution``.
* **Lanes.** One lane filters one pixel per clock; :math:`L = \lceil H W f_s / f_{clk} \rceil`
  lanes (``costs.clock_hz``) work side by side on the columns of a row.
* **Area**: the adders of every lane (Horowitz's adder areas, linear in width, scaled as F²) plus
  the line buffers, :math:`(k-1) W b_{in}` SRAM cells of ``costs.sram_cell_area_f2`` · F². The
  datapath serves the array from its periphery, so ``area_m2`` is the total over the pixel count
  and the pixel's fill factor is unchanged.
* **Latency**: a pixel's output waits for its window to fill, :math:`(k-1)/2` rows of
  :math:`W/L` cycles and :math:`(k-1)/2` pixels, plus :math:`\lceil \log_2 n_{taps} \rceil`
  adder-tree stages, at ``costs.clock_hz``; and on average half a sample period,
  :math:`1 / 2 f_s`, for the next sample.

**Built in a process** (``[realisations.asic] pdk = "sky130"``: the fit's items carry
``max_clock_hz``, ``energy_per_pixel_j``, ``datapath_area_m2``, ``flip_flop_area_m2`` from
:mod:`fsdvs_hw.realise.asic.sky130_flow`), :func:`asic_process_cost` replaces the literature figures
with the process's, each with its source: the energy per pixel from the gate-level toggles of the
mapped netlist (a build with lines of the build's width), the clock from OpenSTA's critical path
(so the lanes), the area from the mapped cells — every lane's arithmetic and k × k window, plus the
array's line buffers as sky130 flip-flops, :math:`(k-1) W b_{in}` ``dfxtp_1`` cells (a standard-cell
build; an SRAM macro would be smaller) — and the supply is the process's 1.8 V.

Examples
--------
>>> from fsdvs_hw.costs.asic import asic_cost
>>> from fsdvs_hw.costs.assumptions import CostAssumptions
>>> figs, flags = asic_cost({"adders": 64, "accumulator_bits": 17, "nonzero_taps": 45}, CostAssumptions(),
...                         kernel_size=7, input_bits=8)
>>> f"{figs['energy_per_pixel_j'].value:.4e}"
'1.2350e-11'
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from .assumptions import CostAssumptions
from .process import HOROWITZ_SOURCE, adder_area_m2, adder_energy_j, sram_energy_per_bit_j
from .record import CostFigure

__all__ = ["asic_cost", "asic_process_cost"]


def asic_cost(
    items: Mapping[str, float],
    a: CostAssumptions,
    *,
    kernel_size: int,
    input_bits: int = 8,
    sources: Mapping[str, str] | None = None,
) -> tuple[dict[str, CostFigure], list[str]]:
    """Power, area and latency figures of a fitted ASIC datapath (module docstring).

    Parameters
    ----------
    items : mapping
        The ASIC's stored cost items by name: ``adders``, ``accumulator_bits`` and
        ``nonzero_taps`` (counts, bits); ``area_m2`` (a yosys synthesis's cell area) is passed on
        as ``yosys_area_m2`` when present.
    a : CostAssumptions
        The ``[costs]`` section.
    kernel_size : int
        Window side k (px).
    input_bits : int
        Bits of an intensity sample.
    sources : mapping, optional
        The items' descriptions (where each came from), for the process-built figures.

    Returns
    -------
    figures, flags
        ``power_w`` (array), ``power_per_pixel_w``, ``energy_per_pixel_j``, ``area_m2`` (per
        pixel), ``array_area_m2``, ``fill_factor``, ``latency_s``, ``lanes``; no flags.
    """
    node, vdd = a.process_node_m, a.digital_supply_v
    h, w = a.array_resolution
    n_add, b_acc = float(items["adders"]), float(items["accumulator_bits"])
    rows = kernel_size - 1
    e_add = n_add * adder_energy_j(b_acc, node_m=node, supply_v=vdd)
    e_mem = (rows + 1) * input_bits * sram_energy_per_bit_j(node_m=node, supply_v=vdd)
    energy = e_add + e_mem
    pixel_rate = h * w * a.sample_rate_hz
    scaled = (
        f"{HOROWITZ_SOURCE}, scaled as F·V² to costs.process_node_m = {node:g} m, costs.digital_supply_v = {vdd:g} V"
    )
    src_e = f"{int(n_add)} adders at {int(b_acc)} bits + {rows + 1} line-buffer accesses of {input_bits} bits; {scaled}"
    src_p = f"energy per pixel x {h}x{w} pixels x costs.sample_rate_hz = {a.sample_rate_hz:g} Hz"
    lanes = math.ceil(pixel_rate / a.clock_hz)
    sram_bits = rows * w * input_bits
    array_area = lanes * n_add * adder_area_m2(b_acc, node_m=node) + sram_bits * a.sram_cell_area_f2 * node**2
    src_a = (
        f"{lanes} lane(s) x {int(n_add)} adders ({HOROWITZ_SOURCE}, scaled as F²) + {sram_bits} line-buffer "
        f"SRAM cells x costs.sram_cell_area_f2 = {a.sram_cell_area_f2:g} F², at costs.process_node_m = {node:g} m"
    )
    stages = math.ceil(math.log2(max(2.0, float(items.get("nonzero_taps", n_add + 1)))))
    cycles = (rows // 2) * math.ceil(w / lanes) + rows // 2 + stages
    latency = cycles / a.clock_hz + 0.5 / a.sample_rate_hz
    figs = {
        "power_w": CostFigure(energy * pixel_rate, "W", src_p),
        "power_per_pixel_w": CostFigure(energy * a.sample_rate_hz, "W", "energy per pixel x costs.sample_rate_hz"),
        "energy_per_pixel_j": CostFigure(energy, "J", src_e),
        "area_m2": CostFigure(array_area / (h * w), "m^2", "array datapath area / pixel count (periphery)"),
        "array_area_m2": CostFigure(array_area, "m^2", src_a),
        "fill_factor": CostFigure(1.0, "1", "datapath in the periphery: the pixel is unchanged"),
        "latency_s": CostFigure(
            latency,
            "s",
            f"{cycles} cycles (window fill + {stages} adder stages) at "
            f"costs.clock_hz = {a.clock_hz:g} Hz + half a sample period "
            f"(costs.sample_rate_hz = {a.sample_rate_hz:g} Hz)",
        ),
    }
    if "max_clock_hz" in items and "energy_per_pixel_j" in items:
        return asic_process_cost(items, a, kernel_size=kernel_size, input_bits=input_bits, sources=sources)
    if "area_m2" in items:
        figs["yosys_area_m2"] = CostFigure(
            float(items["area_m2"]), "m^2", "yosys cell area with the fit's liberty file"
        )
    figs["lanes"] = CostFigure(float(lanes), "1", f"ceil(pixel rate {pixel_rate:g} pixels/s / costs.clock_hz)")
    return figs, []


def asic_process_cost(
    items: Mapping[str, float],
    a: CostAssumptions,
    *,
    kernel_size: int,
    input_bits: int = 8,
    sources: Mapping[str, str] | None = None,
) -> tuple[dict[str, CostFigure], list[str]]:
    """Power, area and latency of taps built in a process (module docstring, "Built in a process").

    ``items`` holds ``max_clock_hz`` (OpenSTA), ``energy_per_pixel_j`` (gate-level toggles),
    ``datapath_area_m2`` (the mapped arithmetic), ``flip_flop_area_m2`` (one flip-flop) and
    ``accumulator_bits``; ``sources`` their descriptions. Returns the figures of :func:`asic_cost`
    plus ``max_clock_hz`` and ``frame_rate_per_lane_hz``; no flags.
    """
    src = dict(sources or {})
    h, w = a.array_resolution
    k, rows = kernel_size, kernel_size - 1
    f_max, energy = float(items["max_clock_hz"]), float(items["energy_per_pixel_j"])
    pixel_rate = h * w * a.sample_rate_hz
    lanes = math.ceil(pixel_rate / f_max)
    ff = float(items["flip_flop_area_m2"])
    window_bits, line_bits = k * k * input_bits, rows * w * input_bits
    array_area = lanes * (float(items["datapath_area_m2"]) + window_bits * ff) + line_bits * ff
    stages = math.ceil(math.log2(max(2.0, float(items.get("nonzero_taps", 2)))))
    cycles = (rows // 2) * math.ceil(w / lanes) + rows // 2 + stages
    latency = cycles / f_max + 0.5 / a.sample_rate_hz
    e_src = src.get("energy_per_pixel_j", "gate-level toggle energy")
    clock_src = src.get("max_clock_hz", "OpenSTA critical path")
    figs = {
        "power_w": CostFigure(energy * pixel_rate, "W", f"energy per pixel x {h}x{w} pixels x {a.sample_rate_hz:g} Hz"),
        "power_per_pixel_w": CostFigure(energy * a.sample_rate_hz, "W", "energy per pixel x costs.sample_rate_hz"),
        "energy_per_pixel_j": CostFigure(energy, "J", e_src),
        "area_m2": CostFigure(array_area / (h * w), "m^2", "array datapath area / pixel count (periphery)"),
        "array_area_m2": CostFigure(
            array_area,
            "m^2",
            f"{lanes} lane(s) x (mapped arithmetic, {src.get('datapath_area_m2', 'yosys stat -liberty')}; + {window_bits} "
            f"window flip-flops) + {line_bits} line-buffer bits, each a flip-flop of {ff * 1e12:.4g} µm² "
            f"({src.get('flip_flop_area_m2', 'dfxtp_1')})",
        ),
        "fill_factor": CostFigure(1.0, "1", "datapath in the periphery: the pixel is unchanged"),
        "latency_s": CostFigure(
            latency,
            "s",
            f"{cycles} cycles (window fill + {stages} adder stages) at the STA clock {f_max / 1e6:.4g} MHz + half a "
            f"sample period (costs.sample_rate_hz = {a.sample_rate_hz:g} Hz)",
        ),
        "max_clock_hz": CostFigure(f_max, "Hz", clock_src),
        "frame_rate_per_lane_hz": CostFigure(
            f_max / (h * w), "Hz", f"STA clock / {h}x{w} pixels: frames per second one lane sustains"
        ),
        "lanes": CostFigure(float(lanes), "1", f"ceil(pixel rate {pixel_rate:g} pixels/s / the STA clock)"),
    }
    return figs, []
