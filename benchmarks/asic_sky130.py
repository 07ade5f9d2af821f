"""``fsdvs-hw bench asic_sky130``: the time of one taps design point built in SkyWater 130 nm.

One point = the shipped design's learned 7×7 kernel at 8-bit taps and 8-bit pixels, built for its
48×64 sensor frame by :meth:`~fsdvs_hw.realise.asic.AsicDesign.build_in_process` (``pdk =
"sky130"``): yosys synthesis onto sky130_fd_sc_hd (the streaming filter and the arithmetic alone),
fanout buffering, gate-level simulation of the mapped netlist on 1 frame of the real ``bikes`` clip checked
bit-exactly against the integer model (with the VCD toggles), OpenSTA on the lctime-characterised
cells, and the toggle energy. Target (issue 39): within 3 minutes on 2 cores. The lctime
characterisation is a one-off cached step (``fsdvs-hw process-cells``) outside the timing.

Reported: the wall time per step and in total (``repeats`` runs, median [min–max]) and the
figures the point produces (cells, full adders, area, max clock, energy per pixel).
"""

from __future__ import annotations

import sys
import time

from fsdvs_hw.kernels import load_kernel
from fsdvs_hw.realise.asic.fit import fit_asic_taps
from fsdvs_hw.resources import shipped_path

from .harness import BenchRun, BenchSection, Column, Timing

__all__ = ["CORNERS", "bench_asic_sky130"]

#: The corners the point is timed at (the shipped sky130 design's).
CORNERS: tuple[str, ...] = ("tt", "ff", "ss")


def _log(msg: str) -> None:
    print(f"[bench asic_sky130] {msg}", file=sys.stderr, flush=True)


def bench_asic_sky130(*, quick: bool = False) -> BenchRun:
    """Time the sky130 build of the shipped taps point (module docstring); ``quick``: a 16×16 frame, 1 run."""
    kernel = load_kernel(shipped_path("kernels") / "learned_detection_7x7.json")
    frame = (16, 16) if quick else (48, 64)
    reps = 1 if quick else 3
    design = fit_asic_taps(kernel, 8)
    sec = BenchSection("asic_sky130", settings={"quick": quick, "repeats": reps, "frame": list(frame)})
    sec.text("### Taps in sky130 (`fsdvs-hw bench asic_sky130`)", "")
    sec.text(
        f"The learned 7×7 detection kernel, 8-bit taps, 8-bit pixels, built for a {frame[0]}×{frame[1]} frame "
        '(`pdk = "sky130"`): yosys → sky130_fd_sc_hd (extract_fa, abc), buf_1 trees on nets of fanout > 8, '
        "Icarus gate-level simulation of 1 frame of the `bikes` clip against the integer model (VCD toggles), "
        "OpenSTA on the lctime cells (tt, ff and ss models, 25 °C, 1.8 V), "
        f"toggle energy. {reps} run(s); target 3 minutes on 2 cores; lctime characterisation excluded (cached).",
        "",
    )
    totals: list[float] = []
    steps: dict[str, list[float]] = {"synthesis_s": [], "gate_level_simulation_s": [], "sta_s": []}
    built = design
    for i in range(reps):
        _log(f"run {i + 1}/{reps}")
        t0 = time.perf_counter()
        built = design.build_in_process("sky130", frame=frame, corners=CORNERS)
        totals.append(time.perf_counter() - t0)
        for k in steps:
            steps[k].append(float(built.process["wall_s"][k]))  # type: ignore[index]
    table = sec.table(
        Column.text("step"),
        Column.number("wall (s)", ".1f", metric="wall time", spread=True),
        title="Time per taps design point in sky130",
    )
    for label, key in [
        ("yosys synthesis (filter + arithmetic)", "synthesis_s"),
        ("gate-level simulation + toggles", "gate_level_simulation_s"),
        ("OpenSTA", "sta_s"),
    ]:
        table.row(label, Timing(tuple(steps[key]), None))
    table.row("whole point (incl. frames, toggle energy)", Timing(tuple(totals), None))
    sec.text("")
    p = built.process or {}
    figs = sec.table(
        Column.text("figure"),
        Column.number("value", ".4g"),
        Column.text("unit"),
        title="What the point produces",
    )
    figs.row("cells", p["cells"], "count")
    figs.row("full adders", p["full_adders"], "count")
    figs.row("fanout buffers (buf_1 trees, <= 8 inputs per net)", p["fanout_buffers"], "count")
    figs.row("flip-flops", p["flip_flops"], "count")
    figs.row("cell area", p["area_m2"] * 1e12, "µm²")
    figs.row("arithmetic area", p["datapath_area_m2"] * 1e12, "µm²")
    figs.row("critical path", p["critical_path_s"] * 1e9, "ns")
    figs.row(f"max clock (OpenSTA, slowest corner: {p['clock_corner']})", p["max_clock_hz"] / 1e6, "MHz")
    for corner, t in p["corner_timing"].items():
        figs.row(f"  max clock at {corner}", t["max_clock_hz"] / 1e6, "MHz")
    figs.row("energy per pixel (toggles)", p["energy_per_pixel_j"] * 1e12, "pJ")
    lo, hi = p["energy_per_pixel_interval_j"]
    figs.row(f"  its 95 % interval over {p['energy_spans']} spans of the frame: low", lo * 1e12, "pJ")
    figs.row("  high", hi * 1e12, "pJ")
    figs.row("outputs checked bit-exact", p["outputs_checked"], "count")
    sec.text("")
    return sec.run()
