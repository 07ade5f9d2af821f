"""Verilog for quantised ASIC taps: generate, simulate (Icarus Verilog) and synthesise (yosys).

The generated module is a streaming k×k filter for a raster-scanned image, one pixel per clock
when ``in_valid`` is high (``in_valid`` may drop at any time; the pipeline simply waits):

* ``k - 1`` line buffers (``W``-entry memories of ``input_bits`` words) and a k×k window of
  registers;
* symmetric pre-adds: the pixels of one symmetry class are summed first;
* constant coefficients as shift-add: each class sum is shifted by the positions of the non-zero
  canonical-signed-digit (CSD) digits of its tap and added or subtracted — no multipliers;
* a two's-complement accumulator of :func:`~fsdvs_hw.realise.asic.arith.accumulator_bits` bits
  (intermediate terms wrap modulo ``2**acc_bits``; the final sum is exact because it fits);
* an optional rounding right shift (add ``2**(out_shift-1)``, arithmetic shift), registered.

Outputs appear two clocks after the pixel that completes a window, in raster order, only for the
valid-mode positions ``(row, col)`` with ``row, col ≥ k - 1`` of the last pixel, i.e. exactly
:func:`~fsdvs_hw.realise.asic.arith.integer_correlate`. Rows wrap after ``image_height``, so
frames can be streamed back to back.

Tools are run as subprocesses: ``iverilog``/``vvp`` (Icarus Verilog ≥ 10) and ``yosys`` (≥ 0.9).
Synthesis maps to the small liberty file shipped in ``asic/data/fsdvs_demo45.lib`` (areas in µm²,
about the X1 cells of the NanGate FreePDK45 Open Cell Library) with ``dfflibmap`` and
``abc -liberty``, and reports ``stat -liberty``.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import FsdvsError, InputError, ToolMissingError
from .arith import (
    SymmetryClasses,
    accumulator_bits,
    csd_digits,
    integer_correlate,
    output_bits,
    symmetry_classes,
)

__all__ = [
    "LIBERTY_AREA_UNIT_M2",
    "LIBERTY_PATH",
    "RtlError",
    "SynthesisReport",
    "generate_datapath_verilog",
    "generate_testbench",
    "generate_verilog",
    "simulate_rtl",
    "synthesise_verilog",
    "testbench_ports",
]

#: The shipped liberty file (areas in µm²).
LIBERTY_PATH: Path = Path(__file__).with_name("data") / "fsdvs_demo45.lib"

#: One liberty area unit of :data:`LIBERTY_PATH` in m² (the file's areas are µm²).
LIBERTY_AREA_UNIT_M2: float = 1e-12

_MAX_IMAGE_SIDE = 4096


class RtlError(FsdvsError, RuntimeError):
    """An external RTL tool failed, or its output could not be read; the message has its log."""


def find_tool(name: str) -> str:
    """Path of the external tool ``name`` on PATH, or ToolMissingError saying how to install it."""
    path = shutil.which(name)
    if path is None:
        raise ToolMissingError(
            f"{name} not found on PATH; install it (Debian/Ubuntu: apt-get install "
            f"{'iverilog' if name in ('iverilog', 'vvp') else name})"
        )
    return path


def _run(cmd: list[str], cwd: Path, timeout_s: float) -> subprocess.CompletedProcess:
    try:
        res = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise RtlError(f"{Path(cmd[0]).name} timed out after {timeout_s:g} s: {' '.join(cmd)}") from None
    if res.returncode != 0:
        log = (res.stdout + res.stderr)[-4000:]
        raise RtlError(f"{Path(cmd[0]).name} failed (exit {res.returncode}): {' '.join(cmd)}\n{log}")
    return res


def _check_side(name: str, value: int, k: int) -> int:
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or not k <= value <= _MAX_IMAGE_SIDE:
        raise InputError(
            f"{name}: must be an integer in {k}..{_MAX_IMAGE_SIDE} (at least the kernel size), got {value!r}"
        )
    return int(value)


def _ubits(n: int) -> int:
    """Unsigned bits to count 0..n (at least 1)."""
    return max(1, int(n).bit_length())


def _datapath_lines(cls: SymmetryClasses, reps: list[int], IN: int, acc: int, out_shift: int, ob: int) -> list[str]:
    """Verilog lines of the arithmetic: pre-adds ``p<c>``, the shift-add ``acc`` and (if shifting) ``acc_r``.

    Expects the window pixels as ``w<row>_<col>`` (``IN`` bits each) in scope.
    """
    L: list[str] = []
    a = L.append
    a("  // symmetric pre-adds: one unsigned sum per coefficient class")
    names: list[str | None] = []
    widths: dict[int, int] = {}
    for c, val in enumerate(reps):
        members = [f"w{r}_{cc}" for r, cc in zip(*np.nonzero(cls.labels == c))]
        if val == 0:
            names.append(None)
            continue
        pb = IN + math.ceil(math.log2(len(members))) if len(members) > 1 else IN
        # every operand zero-extended to the sum's width: widths explicit (verilator -Wall clean)
        a(
            f"  wire [{pb - 1}:0] p{c} = {' + '.join(_zext(m, IN, pb) for m in members)};  // tap {val}, "
            f"{len(members)} pixel(s)"
        )
        names.append(f"p{c}")
        widths[c] = pb
    terms: list[str] = []
    for c, val in enumerate(reps):
        if val == 0:
            continue
        for shift, sign in csd_digits(val):
            name = names[c]
            assert name is not None  # None only for a zero tap, skipped above
            x = _zext(name, widths[c], acc)
            t = x if shift == 0 else f"({x} << {shift})"
            terms.append(("- " if sign < 0 else "+ ") + t)
    expr = " ".join(terms) or f"+ {acc}'d0"
    expr = expr[2:] if expr.startswith("+ ") else expr
    a(f"  // constant coefficients as CSD shift-add ({len(terms)} terms), modulo 2^{acc} (the exact sum fits)")
    a(f"  wire [{acc - 1}:0] acc_u = {expr};")
    a(f"  wire signed [{acc - 1}:0] acc = acc_u;")
    if out_shift:
        a(
            f"  wire signed [{acc}:0] acc_r = {{acc[{acc - 1}], acc}} + {acc + 1}'d{1 << (out_shift - 1)};  // round half up"
        )
        if ob + out_shift > acc + 1:  # cannot happen (the shifted range fits); kept exact anyway
            a(f"  wire signed [{acc}:0] acc_s = acc_r >>> {out_shift};")
        else:
            # (acc + 2^(s-1)) >>> s keeps bits [ob+s-1 : s]: the rest are the rounded-off fraction and
            # sign copies; they feed a wire named 'unused_*' (verilator's --unused-regexp idiom)
            a(f"  wire signed [{ob - 1}:0] acc_s = acc_r[{ob + out_shift - 1}:{out_shift}];")
            dropped = [f"acc_r[{out_shift - 1}:0]"] + (
                [f"acc_r[{acc}:{ob + out_shift}]"] if ob + out_shift <= acc else []
            )
            a(f"  wire unused_rounding_bits = &{{1'b0, {', '.join(dropped)}, 1'b0}};")
    return L


def _result(acc: int, ob: int, out_shift: int) -> str:
    """The registered output: the (shifted) accumulator's low ``ob`` bits, where the value fits exactly."""
    if out_shift:
        return "acc_s" if ob + out_shift <= acc + 1 else f"acc_s[{ob - 1}:0]"
    return "acc" if ob == acc else f"acc[{ob - 1}:0]"


def _zext(name: str, width: int, to: int) -> str:
    """``name`` (``width`` bits, unsigned) zero-extended (or truncated) to ``to`` bits, explicitly."""
    if width == to:
        return name
    if width > to:
        return f"{name}[{to - 1}:0]"
    return f"{{{to - width}'d0, {name}}}"


def _checked_taps(
    taps: np.ndarray, input_bits: int, out_shift: int, symmetry: str
) -> tuple[np.ndarray, int, int, SymmetryClasses, list[int]]:
    q = np.asarray(taps, dtype=np.int64)
    acc = accumulator_bits(q, input_bits)
    if not (isinstance(out_shift, (int, np.integer)) and 0 <= out_shift < acc):
        raise InputError(f"out_shift: must be an integer in 0..{acc - 1}, got {out_shift!r}")
    cls = symmetry_classes(q.shape[0], symmetry)
    reps = [int(q[r, c]) for r, c in cls.representatives]
    if not np.array_equal(cls.expand(np.array(reps)), q):
        raise InputError(f"taps are not {symmetry}-symmetric; generate with symmetry='none'")
    return q, acc, output_bits(q, input_bits, out_shift), cls, reps


def generate_datapath_verilog(
    taps: np.ndarray,
    *,
    input_bits: int,
    out_shift: int = 0,
    symmetry: str = "none",
    module_name: str = "fsdvs_datapath",
) -> str:
    """The arithmetic alone (pre-adds, shift-add, rounding shift, output register), for costing.

    Ports: ``clk``, ``window[input_bits*k*k-1:0]`` (pixel (i, j) at bits ``(i*k + j)*input_bits``),
    ``out_value`` (signed, registered). No line buffers: the cells that the taps decide.
    """
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", module_name):
        raise InputError(f"module_name: {module_name!r} is not a Verilog identifier")
    q, acc, ob, cls, reps = _checked_taps(taps, input_bits, out_shift, symmetry)
    k, IN = q.shape[0], int(input_bits)
    L = [
        f"// Generated by fsdvs_hw.realise.asic.rtl: datapath of a {k}x{k} shift-add filter ({symmetry} symmetry).",
        f"module {module_name} (",
        "  input  wire clk,",
        f"  input  wire [{IN * k * k - 1}:0] window,",
        f"  output reg  signed [{ob - 1}:0] out_value",
        ");",
    ]
    zero = [f"window[{(i * k + j) * IN} +: {IN}]" for i in range(k) for j in range(k) if reps[cls.labels[i, j]] == 0]
    for i in range(k):
        for j in range(k):
            if reps[cls.labels[i, j]] != 0:
                L.append(f"  wire [{IN - 1}:0] w{i}_{j} = window[{(i * k + j) * IN} +: {IN}];")
    if zero:  # pixels under zero taps: no logic ('unused_*': verilator's --unused-regexp idiom)
        L.append(f"  wire unused_zero_tap_pixels = &{{1'b0, {', '.join(zero)}, 1'b0}};")
    L += _datapath_lines(cls, reps, IN, acc, out_shift, ob)
    L += ["  always @(posedge clk)", f"    out_value <= {_result(acc, ob, out_shift)};", "endmodule"]
    return "\n".join(L) + "\n"


def _stream_lines(k: int, W: int, H: int, cb: int, rb: int) -> list[str]:
    """Verilog of the streaming front end: the raster counters (``cb``/``rb`` bits wide) that tell a
    complete k×k window, the k−1 line buffers of ``W`` pixels and the window registers."""
    L: list[str] = []
    a = L.append
    a("  // control: raster position of the incoming pixel; a window is complete when row, col >= k-1")
    a("  always @(posedge clk) begin")
    a("    if (rst) begin")
    a(f"      col <= {cb}'d0; row <= {rb}'d0; win_valid <= 1'b0;")
    a("    end else begin")
    a(
        f"      win_valid <= in_valid && (row >= {rb}'d{k - 1}) && (col >= {cb}'d{k - 1});"
        if k > 1
        else "      win_valid <= in_valid;"
    )
    a("      if (in_valid) begin")
    a(f"        if (col == {cb}'d{W - 1}) begin")
    a(f"          col <= {cb}'d0;")
    a(f"          row <= (row == {rb}'d{H - 1}) ? {rb}'d0 : row + {rb}'d1;")
    a("        end else begin")
    a(f"          col <= col + {cb}'d1;")
    a("        end")
    a("      end")
    a("    end")
    a("  end")
    a("")
    a("  // line buffers and the k x k window (w<row>_<col>; row 0 = oldest line, col k-1 = newest pixel)")
    a("  always @(posedge clk) begin")
    a("    if (in_valid) begin")
    if k > 1:
        a("      lb0[col] <= in_pixel;")
    for j in range(1, k - 1):
        a(f"      lb{j}[col] <= lb{j - 1}[col];")
    for i in range(k):
        for j in range(k - 1):
            a(f"      w{i}_{j} <= w{i}_{j + 1};")
        src = "in_pixel" if i == k - 1 else f"lb{k - 2 - i}[col]"
        a(f"      w{i}_{k - 1} <= {src};")
    a("    end")
    a("  end")
    a("")
    return L


def generate_verilog(
    taps: np.ndarray,
    *,
    input_bits: int,
    image_width: int,
    image_height: int,
    out_shift: int = 0,
    symmetry: str = "none",
    module_name: str = "fsdvs_conv",
) -> str:
    """Synthesisable Verilog-2005 for a streaming k×k shift-add filter (see the module docstring).

    Parameters
    ----------
    taps : ndarray of int, shape (k, k)
        Signed integer taps (constant on the classes of ``symmetry``).
    input_bits : int
        Unsigned pixel width.
    image_width, image_height : int
        Image size in pixels (line-buffer length and row wrap).
    out_shift : int
        Rounding right shift of the accumulator (0: full precision).
    symmetry : {"none", "quadrant", "8-fold"}
        Pixels of one class are pre-added before the constant multiplication.
    module_name : str
        Verilog module name.

    Returns
    -------
    str
        The module source. Ports: ``clk``, ``rst`` (synchronous, active high), ``in_valid``,
        ``in_pixel[input_bits-1:0]``, ``out_valid``, ``out_value`` (signed, :func:`output_bits`).
    """
    q = np.asarray(taps, dtype=np.int64)
    k = q.shape[0]
    W = _check_side("image_width", image_width, k)
    H = _check_side("image_height", image_height, k)
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", module_name):
        raise InputError(f"module_name: {module_name!r} is not a Verilog identifier")
    q, acc, ob, cls, reps = _checked_taps(q, input_bits, out_shift, symmetry)
    IN, cb, rb = int(input_bits), _ubits(W - 1), _ubits(H - 1)

    L: list[str] = []
    a = L.append
    a(
        f"// Generated by fsdvs_hw.realise.asic.rtl: {k}x{k} shift-add filter, {symmetry} symmetry, "
        f"{IN}-bit unsigned pixels, {acc}-bit accumulator, out_shift {out_shift}."
    )
    a("// Integer taps (row = y, col = x), applied as a valid-mode correlation:")
    for row in q:
        a("//   " + " ".join(f"{int(v):6d}" for v in row))
    a(f"module {module_name} (")
    a("  input  wire clk,")
    a("  input  wire rst,")
    a("  input  wire in_valid,")
    a(f"  input  wire [{IN - 1}:0] in_pixel,")
    a("  output reg  out_valid,")
    a(f"  output reg  signed [{ob - 1}:0] out_value")
    a(");")
    a(f"  reg [{cb - 1}:0] col;")
    a(f"  reg [{rb - 1}:0] row;")
    a("  reg win_valid;")
    for j in range(k - 1):
        a(f"  reg [{IN - 1}:0] lb{j} [0:{W - 1}];  // line buffer: row - {j + 1}")
    for i in range(k):
        a("  reg [{}:0] {};".format(IN - 1, ", ".join(f"w{i}_{j}" for j in range(k))))
    a("")
    L += _stream_lines(k, W, H, cb, rb)
    L += _datapath_lines(cls, reps, IN, acc, out_shift, ob)
    result = _result(acc, ob, out_shift)
    a("")
    a("  always @(posedge clk) begin")
    a("    if (rst) begin")
    a("      out_valid <= 1'b0;")
    a(f"      out_value <= {ob}'sd0;")
    a("    end else begin")
    a("      out_valid <= win_valid;")
    a(f"      out_value <= {result};")
    a("    end")
    a("  end")
    a("endmodule")
    return "\n".join(L) + "\n"


def testbench_ports(*, input_bits: int, out_bits: int, n_pixels: int) -> str:
    """The signals every testbench of the streaming filter declares: clock, reset, the input pixel
    stream, the signed output and the stimulus memory (Verilog-2005 lines, two-space indented)."""
    return (
        f"  reg clk = 1'b0;\n  reg rst = 1'b1;\n  reg in_valid = 1'b0;\n"
        f"  reg [{input_bits - 1}:0] in_pixel = {input_bits}'d0;\n  wire out_valid;\n"
        f"  wire signed [{out_bits - 1}:0] out_value;\n  reg [{input_bits - 1}:0] img [0:{n_pixels - 1}];\n"
    )


def generate_testbench(
    *,
    input_bits: int,
    out_bits: int,
    n_pixels: int,
    input_file: str,
    output_file: str,
    module_name: str = "fsdvs_conv",
    bubble_every: int = 0,
) -> str:
    """Icarus Verilog testbench: streams ``input_file`` (hex, one pixel per line) and writes every
    valid output as a signed decimal line to ``output_file``. With ``bubble_every = n > 0`` the
    input is stalled (``in_valid = 0``) for one clock after every ``n``-th pixel."""
    stall = (
        (
            f"      if ({bubble_every} > 0 && (i % {bubble_every}) == {bubble_every} - 1) begin\n"
            "        in_valid = 1'b0; @(negedge clk);\n      end\n"
        )
        if bubble_every > 0
        else ""
    )
    return f"""`timescale 1ns/1ps
module tb;
{testbench_ports(input_bits=input_bits, out_bits=out_bits, n_pixels=n_pixels)}  integer i, f;
  {module_name} dut (.clk(clk), .rst(rst), .in_valid(in_valid), .in_pixel(in_pixel), .out_valid(out_valid), .out_value(out_value));
  always #5 clk = ~clk;
  always @(posedge clk) if (!rst && out_valid) $fwrite(f, "%0d\\n", out_value);
  initial begin
    $readmemh("{input_file}", img);
    f = $fopen("{output_file}", "w");
    @(negedge clk); @(negedge clk);
    rst = 1'b0;
    for (i = 0; i < {n_pixels}; i = i + 1) begin
      in_valid = 1'b1; in_pixel = img[i]; @(negedge clk);
{stall}    end
    in_valid = 1'b0;
    repeat (4) @(negedge clk);
    $fclose(f);
    $finish;
  end
endmodule
"""


def simulate_rtl(
    taps: np.ndarray,
    images: np.ndarray,
    *,
    input_bits: int,
    out_shift: int = 0,
    symmetry: str = "none",
    bubble_every: int = 7,
    workdir: str | Path | None = None,
    timeout_s: float = 300.0,
) -> np.ndarray:
    """Generate the RTL and a testbench, run them in Icarus Verilog, and return the outputs.

    Parameters
    ----------
    taps : ndarray of int, shape (k, k)
        Integer taps.
    images : ndarray of int, shape (N, H, W) or (H, W)
        Unsigned pixels in ``[0, 2**input_bits - 1]``, streamed back to back in raster order.
    input_bits, out_shift, symmetry
        As in :func:`generate_verilog`.
    bubble_every : int
        Stall the input for one clock after every ``bubble_every``-th pixel (0: never), to exercise
        the ``in_valid`` handshake.
    workdir : path, optional
        Keep the generated files here (default: a temporary directory, removed afterwards).

    Returns
    -------
    ndarray of int64, shape (N, H - k + 1, W - k + 1) (or without N)
        What the RTL computed; compare with :func:`~fsdvs_hw.realise.asic.arith.integer_correlate`.
    """
    q = np.asarray(taps, dtype=np.int64)
    x = np.asarray(images)
    squeeze = x.ndim == 2
    if squeeze:
        x = x[None]
    # validates shapes and pixel range, and is the expected output size
    expected_shape = integer_correlate(x, q, input_bits=input_bits, out_shift=out_shift).shape
    n, H, W = x.shape
    iverilog, vvp = find_tool("iverilog"), find_tool("vvp")
    ob = output_bits(q, input_bits, out_shift)
    with tempfile.TemporaryDirectory(prefix="fsdvs_rtl_") as tmp:
        d = Path(workdir) if workdir is not None else Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        (d / "dut.v").write_text(
            generate_verilog(
                q, input_bits=input_bits, image_width=W, image_height=H, out_shift=out_shift, symmetry=symmetry
            )
        )
        (d / "tb.v").write_text(
            generate_testbench(
                input_bits=input_bits,
                out_bits=ob,
                n_pixels=x.size,
                input_file="input.hex",
                output_file="output.txt",
                bubble_every=bubble_every,
            )
        )
        digits = max(1, math.ceil(input_bits / 4))
        (d / "input.hex").write_text("\n".join(f"{int(v):0{digits}x}" for v in x.ravel()) + "\n")
        _run([iverilog, "-g2005", "-o", "sim.vvp", "tb.v", "dut.v"], d, timeout_s)
        _run([vvp, "-n", "sim.vvp"], d, timeout_s)
        text = (d / "output.txt").read_text().split()
    try:
        out = np.array([int(v) for v in text], dtype=np.int64)
    except ValueError:
        raise RtlError(f"simulation wrote non-integer output: {text[:5]} ...") from None
    if out.size != int(np.prod(expected_shape)):
        raise RtlError(
            f"simulation produced {out.size} outputs, expected {int(np.prod(expected_shape))} "
            f"for {n} image(s) of {H}x{W} and a {q.shape[0]}x{q.shape[0]} kernel"
        )
    out = out.reshape(expected_shape)
    return out[0] if squeeze else out


@dataclass(frozen=True)
class SynthesisReport:
    """yosys results for one module.

    Attributes
    ----------
    cells : int
        Standard cells after mapping to the liberty file.
    flip_flops : int
        Flip-flop cells among them.
    area_m2 : float
        Total cell area in m² (``stat -liberty``; the liberty's unit is µm²).
    cell_types : dict
        Count per cell type.
    liberty : str
        Liberty file name.
    yosys_version : str
    wall_s : float
        yosys run time in seconds.
    """

    cells: int
    flip_flops: int
    area_m2: float
    cell_types: dict[str, int] = field(default_factory=dict)
    liberty: str = ""
    yosys_version: str = ""
    wall_s: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _synth_script(top: str, liberty: str) -> str:
    lib = liberty
    return "; ".join(
        [
            "read_verilog -sv dut.v",
            f"synth -flatten -top {top}",
            "dfflegalize -cell $_DFF_P_ 01",
            f"dfflibmap -liberty {lib}",
            f"abc -liberty {lib}",
            "opt_clean -purge",
            f"tee -q -o stat.txt stat -liberty {lib}",
        ]
    )


def synthesise_verilog(
    source: str, *, top: str = "fsdvs_conv", liberty: str | Path | None = None, timeout_s: float = 600.0
) -> SynthesisReport:
    """Synthesise Verilog with yosys onto a liberty file and report cells and area.

    Script: ``synth -flatten`` (generic), ``dfflegalize`` to plain rising-edge flip-flops (resets
    become logic), ``dfflibmap -liberty``, ``abc -liberty``, ``stat -liberty``.

    Parameters
    ----------
    source : str
        Verilog source.
    top : str
        Top module.
    liberty : path, optional
        Liberty file (default :data:`LIBERTY_PATH`; its areas must be in µm²).
    """
    # top goes into a yosys script, where ';' separates commands and '!' runs a shell: only a
    # Verilog identifier is accepted; the liberty file is copied under a fixed name for the same reason
    if not isinstance(top, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,127}", top):
        raise InputError(
            f"top: {str(top)[:80]!r} is not a Verilog identifier ([A-Za-z_][A-Za-z0-9_]*, ≤ 128 characters)"
        )
    yosys = find_tool("yosys")
    lib = Path(liberty) if liberty is not None else LIBERTY_PATH
    if not lib.is_file():
        raise InputError(f"liberty: file {lib} not found")
    with tempfile.TemporaryDirectory(prefix="fsdvs_syn_") as tmp:
        d = Path(tmp)
        (d / "dut.v").write_text(source)
        shutil.copyfile(lib, d / "cells.lib")
        t0 = time.perf_counter()
        _run([yosys, "-q", "-p", _synth_script(top, "cells.lib")], d, timeout_s)
        wall = time.perf_counter() - t0
        stat = (d / "stat.txt").read_text()
        ver = subprocess.run([yosys, "-V"], capture_output=True, text=True).stdout.strip()
    m_cells = re.search(r"Number of cells:\s+(\d+)", stat)
    m_area = re.search(r"Chip area for (?:top )?module .*?:\s+([0-9.eE+-]+)", stat)
    if not (m_cells and m_area):
        raise RtlError(f"could not read cells/area from yosys stat output:\n{stat[-2000:]}")
    types = {name: int(cnt) for name, cnt in re.findall(r"^\s+(\S+)\s+(\d+)\s*$", stat, flags=re.M)}
    unmapped = [t for t in types if t.startswith("$")]
    if unmapped:
        raise RtlError(f"yosys left unmapped cells {unmapped}; the liberty file lacks a cell for them")
    ff = sum(c for t, c in types.items() if "DFF" in t.upper())
    return SynthesisReport(
        cells=int(m_cells.group(1)),
        flip_flops=ff,
        area_m2=float(m_area.group(1)) * LIBERTY_AREA_UNIT_M2,
        cell_types=types,
        liberty=lib.name,
        yosys_version=ver,
        wall_s=wall,
    )
