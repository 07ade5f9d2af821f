"""Static timing of a mapped netlist with OpenSTA: the critical path, the highest clock, the sample rate.

OpenSTA (Parallax Software, GPL-3.0; Debian's ``sta``, run as a program) reads the characterised
liberty (:mod:`~fsdvs_hw.realise.asic.cell_timing`) and the gate-level netlist
(:mod:`~fsdvs_hw.realise.asic.gate_level`) and reports the worst setup path under one clock::

    read_liberty cells.lib
    read_verilog mapped.v
    link_design <top>
    create_clock -name clk -period <T> [get_ports clk]
    set_input_delay 0 -clock clk <inputs but clk>
    set_output_delay 0 -clock clk [all_outputs]
    report_checks -path_delay max -digits 4 -fields {slew cap input_pins fanout}

The worst slack ``S`` at period ``T`` gives the critical path ``T − S`` (clock-to-Q, the logic and the
capturing flip-flop's setup time, or an input port's path) and the highest clock
``f_max = 1 / (T − S)``. Stated conditions: the liberty's corner (tt, 25 °C, 1.8 V), an ideal
clock (no skew, no clock tree), inputs arriving at the clock edge, and **no wire load**: the
loads are the fanout cells' pin capacitances only (a pre-layout figure; routing adds to it).

A streaming filter takes one pixel per clock per lane, so one lane sustains ``f_max / (H·W)``
frames per second on an ``H × W`` array (:attr:`TimingReport.frame_rate_hz`).

References
----------
Parallax Software, *OpenSTA*, https://github.com/The-OpenROAD-Project/OpenSTA .

Examples
--------
>>> from fsdvs_hw.realise.asic.static_timing import read_worst_path
>>> read_worst_path("Startpoint: a (input port)\\nEndpoint: b (rising edge-triggered flip-flop)\\n"
...                 "   9.1000   slack (MET)")
('a', 'b', 9.1)
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from ...errors import InputError
from .rtl import RtlError, find_tool

__all__ = ["TimingReport", "read_worst_path", "run_sta", "sta_script", "sta_version"]


@dataclass(frozen=True)
class TimingReport:
    """OpenSTA's worst setup path of a design.

    Attributes
    ----------
    period_s : float
        Clock period constrained, s.
    slack_s : float
        Worst setup slack at that period, s.
    startpoint, endpoint : str
        The critical path's ends.
    report : str
        OpenSTA's ``report_checks`` text (the artifact a designer reads).
    liberty : str
        The liberty (name) timed against.
    sta_version : str
    wall_s : float
        OpenSTA wall time, s.
    """

    period_s: float
    slack_s: float
    startpoint: str
    endpoint: str
    report: str = ""
    liberty: str = ""
    sta_version: str = ""
    wall_s: float = 0.0

    @property
    def critical_path_s(self) -> float:
        """The critical path, ``period − slack``, s."""
        return self.period_s - self.slack_s

    @property
    def max_clock_hz(self) -> float:
        """The highest clock, ``1 / critical path``, Hz."""
        return 1.0 / self.critical_path_s

    def frame_rate_hz(self, height: int, width: int, lanes: int = 1) -> float:
        """Frames per second ``lanes`` lanes sustain at :attr:`max_clock_hz` on an ``height × width`` array."""
        return self.max_clock_hz * lanes / (height * width)

    def summary(self) -> dict[str, Any]:
        """The figures without the report text."""
        d = asdict(self)
        d.pop("report")
        d.update(critical_path_s=self.critical_path_s, max_clock_hz=self.max_clock_hz)
        return d


def sta_version() -> str:
    """OpenSTA's version (``sta -version``)."""
    res = subprocess.run([find_tool("sta"), "-version"], capture_output=True, text=True, timeout=60)
    return res.stdout.strip() or res.stderr.strip()


def sta_script(top: str, period_ns: float, clock: str = "clk") -> str:
    """The OpenSTA Tcl script of the module docstring (files ``cells.lib`` and ``mapped.v``)."""
    return "\n".join(
        [
            "read_liberty cells.lib",
            "read_verilog mapped.v",
            f"link_design {top}",
            f"create_clock -name clk -period {period_ns:g} [get_ports {clock}]",
            f"set_input_delay 0 -clock clk [delete_from_list [all_inputs] [get_ports {clock}]]",
            "set_output_delay 0 -clock clk [all_outputs]",
            "report_checks -path_delay max -digits 4 -fields {slew cap input_pins fanout}",
            "",
        ]
    )


def read_worst_path(report: str) -> tuple[str, str, float]:
    """Startpoint, endpoint and slack (report units) of OpenSTA's ``report_checks`` text."""
    start = re.search(r"Startpoint:\s+(\S+)", report)
    end = re.search(r"Endpoint:\s+(\S+)", report)
    slack = re.search(r"(-?[0-9.]+)\s+slack \((?:MET|VIOLATED)\)", report)
    if not (start and end and slack):
        raise RtlError(f"could not read the worst path from OpenSTA's report:\n{report[-3000:]}")
    return start.group(1), end.group(1), float(slack.group(1))


def run_sta(
    netlist_verilog: str,
    liberty: str | Path,
    *,
    top: str = "fsdvs_conv",
    clock: str = "clk",
    period_ns: float = 20.0,
    timeout_s: float = 600.0,
) -> TimingReport:
    """Time a gate-level netlist with OpenSTA (module docstring).

    Parameters
    ----------
    netlist_verilog : str
        Mapped Verilog (:attr:`~fsdvs_hw.realise.asic.gate_level.MappedNetlist.verilog`).
    liberty : path
        Liberty with timing tables for every cell of the netlist (time unit ns).
    top, clock : str
        Top module and its clock port.
    period_ns : float
        The clock period constrained (any value: the critical path does not depend on it).

    Raises
    ------
    RtlError
        OpenSTA failed (e.g. a cell without timing), or its report could not be read.
    """
    for name, value in (("top", top), ("clock", clock)):
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,127}", str(value)):
            raise InputError(f"{name}: {str(value)[:80]!r} is not a Verilog identifier")
    if not (isinstance(period_ns, (int, float)) and 0 < period_ns < 1e6):
        raise InputError(f"period_ns: must be in (0, 1e6) ns, got {period_ns!r}")
    lib = Path(liberty)
    if not lib.is_file():
        raise InputError(f"liberty: file {lib} not found")
    sta = find_tool("sta")
    with tempfile.TemporaryDirectory(prefix="fsdvs_sta_") as tmp:
        d = Path(tmp)
        shutil.copyfile(lib, d / "cells.lib")
        (d / "mapped.v").write_text(netlist_verilog)
        (d / "sta.tcl").write_text(sta_script(top, period_ns, clock))
        t0 = time.perf_counter()
        res = subprocess.run(
            [sta, "-no_init", "-no_splash", "-exit", "sta.tcl"],
            cwd=d,
            capture_output=True,
            text=True,
            timeout=timeout_s,
        )
        wall = time.perf_counter() - t0
    text = res.stdout + res.stderr
    if res.returncode != 0 or "Error" in text:
        raise RtlError(f"OpenSTA failed (exit {res.returncode}):\n{text[-4000:]}")
    start, end, slack_ns = read_worst_path(text)
    return TimingReport(period_ns * 1e-9, slack_ns * 1e-9, start, end, text, lib.name, sta_version(), wall)
