"""``fsdvs-hw bench mesh_sky130``: the time of one mesh design point built in SkyWater 130 nm transistors.

One point = the shipped design's learned 7×7 kernel realised by
:func:`~fsdvs_hw.realise.mesh.process_mesh.fit_process_mesh` (the ``mesh_process`` realisation,
``[process] pdk = "sky130"``): the ideal dual-mesh fit, the gate-bias fit against the sky130 device
models at tt 27 °C (two ngspice runs), the four conductances at each of 3 corners × 2 temperatures
(six ngspice runs) and 30 Monte Carlo mismatch samples (one ``tt_mm`` ngspice run drawing the
device population, then 30 lattice solves). Target (issue 39): within 3 minutes on 2 cores.

Reported: wall time of the whole point (``repeats`` runs, median [min–max]) and what it produces
(kernel error per condition, the mismatch interval, area, pitch answer).
"""

from __future__ import annotations

import sys
import time

from fsdvs_hw.kernels import load_kernel
from fsdvs_hw.resources import shipped_path

from .harness import BenchRun, BenchSection, Column, Timing

__all__ = ["bench_mesh_sky130"]


def _log(msg: str) -> None:
    print(f"[bench mesh_sky130] {msg}", file=sys.stderr, flush=True)


def bench_mesh_sky130(*, quick: bool = False) -> BenchRun:
    """Time the sky130 mesh point (module docstring); ``quick``: tt only, 27 °C, 4 samples, 1 run."""
    from fsdvs_hw.realise.mesh.process_mesh import fit_process_mesh

    kernel = load_kernel(shipped_path("kernels") / "learned_detection_7x7.json")
    corners, temps, samples = (["tt"], [27.0], 4) if quick else (["tt", "ff", "ss"], [27.0, 85.0], 30)
    reps = 1 if quick else 3
    sec = BenchSection(
        "mesh_sky130", settings={"quick": quick, "repeats": reps, "corners": corners, "samples": samples}
    )
    sec.text("### Mesh in sky130 transistors (`fsdvs-hw bench mesh_sky130`)", "")
    sec.text(
        f"The learned 7×7 detection kernel as a dual mesh of sky130 nfet_01v8 pass transistors (W/L 1/2 µm): "
        f"bias fit at tt 27 °C, {len(corners)} corner(s) × {len(temps)} temperature(s), {samples} mismatch samples "
        f"(ngspice 39, one thread per run). {reps} run(s); target 3 minutes on 2 cores.",
        "",
    )
    times: list[float] = []
    built = None
    for i in range(reps):
        _log(f"run {i + 1}/{reps}")
        t0 = time.perf_counter()
        built = fit_process_mesh(kernel, corners=corners, temperatures_c=temps, mismatch_samples=samples)
        times.append(time.perf_counter() - t0)
    assert built is not None
    table = sec.table(
        Column.text("step"), Column.number("wall (s)", ".1f", metric="wall time"), title="Time per mesh point in sky130"
    )
    table.row("whole point (fit, bias fit, corners, mismatch)", Timing(tuple(times), None))
    sec.text("")
    figs = sec.table(
        Column.text("figure"), Column.number("value", ".4g"), Column.text("unit"), title="What the point produces"
    )
    for cond in built.conditions:
        figs.row(f"kernel error, {cond['corner']} {cond['temperature_c']:g} °C", cond["kernel_error"], "1")
    if built.mismatch:
        mean, lo, hi = built.mismatch["ci"]["error_vs_nominal"]
        figs.row(f"mismatch kernel error vs nominal, mean of {samples}", mean, "1")
        figs.row("  95 % CI low", lo, "1")
        figs.row("  95 % CI high", hi, "1")
    figs.row("mesh area per pixel", built.area["total_m2"] * 1e12, "µm²")
    figs.row("smallest pitch that fits", built.area["min_pitch_m"] * 1e6, "µm")
    figs.row("sharing k (node per k×k pixels) at 4.86 µm", built.area["sharing_k"], "count")
    sec.text("")
    return sec.run()
