"""Buffer trees on high-fanout nets (fsdvs_hw.realise.asic.fanout): fanout bound, tree size, function kept."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsdvs_hw.errors import InputError
from fsdvs_hw.realise.asic.fanout import BUFFER_CELL, buffer_high_fanout, fanouts

INV = "sky130_fd_sc_hd__inv_1"
INPUTS = {INV: {"A"}, BUFFER_CELL: {"A"}}


def _fanout_netlist(n: int, net: str = "a") -> str:
    """One input (``net``, possibly an escaped name) driving ``n`` inverters, each output a port."""
    ref = net + " " if net.startswith("\\") else net
    ports = ", ".join(f"y{i}" for i in range(n))
    lines = [f"module fan (a, {ports});", "  input a;", f"  output {ports};"]
    if net != "a":
        lines += [f"  wire {ref};", f"  {BUFFER_CELL} src (\n    .A(a),\n    .X({ref})\n  );"]
    lines += [f"  {INV} u{i} (\n    .A({ref}),\n    .Y(y{i})\n  );" for i in range(n)]
    return "\n".join(lines) + "\nendmodule\n"


def _tree_size(n: int, k: int) -> int:
    """Buffers of a balanced tree: ⌈n/k⌉ at the first level, then the same on those, until ≤ k remain."""
    total = 0
    while n > k:
        n = math.ceil(n / k)
        total += n
    return total


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 300), k=st.integers(2, 16))
def test_every_net_drives_at_most_max_fanout_and_the_tree_is_balanced(n: int, k: int) -> None:
    out, added = buffer_high_fanout(_fanout_netlist(n), INPUTS, max_fanout=k)
    assert max(fanouts(out, INPUTS).values()) <= k
    assert added == _tree_size(n, k)
    assert out.count(f"{INV} u") == n  # every sink kept
    # each sink still hangs (through buffers) on the original net: walk back to the root
    drivers = {}
    for m in re.finditer(rf"{BUFFER_CELL} \S+ \(\s*\.A\(([^()]*)\),\s*\.X\(([^()]*)\)", out):
        drivers[m.group(2).strip()] = m.group(1).strip()
    for m in re.finditer(rf"{INV} u\d+ \(\s*\.A\(([^()]*)\)", out):
        net, depth = m.group(1).strip(), 0
        while net in drivers:
            net, depth = drivers[net], depth + 1
        assert net == "a" and depth <= math.ceil(math.log(max(n, 2), k)) + 1


def test_small_fanout_and_the_clock_are_left_alone() -> None:
    v = _fanout_netlist(8)
    assert buffer_high_fanout(v, INPUTS, max_fanout=8) == (v, 0)
    clocked = _fanout_netlist(20).replace("(a,", "(clk,").replace("input a;", "input clk;").replace(".A(a)", ".A(clk)")
    assert buffer_high_fanout(clocked, INPUTS, max_fanout=4)[1] == 0  # an ideal clock in STA
    with pytest.raises(InputError, match="max_fanout"):
        buffer_high_fanout(v, INPUTS, max_fanout=1)


needs_tools = pytest.mark.skipif(
    not all(shutil.which(t) for t in ("yosys", "iverilog", "vvp")), reason="yosys and iverilog needed"
)


@needs_tools
def test_a_buffered_escaped_net_is_read_by_yosys_and_keeps_the_logic_in_iverilog(tmp_path: Path) -> None:
    pytest.importorskip("fsdvs_hw.process.sky130")
    from fsdvs_hw.realise.asic.gate_level import cell_model_files

    out, added = buffer_high_fanout(_fanout_netlist(40, net="\\row[3]"), INPUTS, max_fanout=4)
    assert added == _tree_size(40, 4)
    (tmp_path / "fan.v").write_text(out)
    r = subprocess.run(["yosys", "-q", "-p", "read_verilog fan.v; hierarchy -top fan; stat"], cwd=tmp_path)
    assert r.returncode == 0
    tb = (
        "module tb; reg a; wire [39:0] y; fan dut (a, "
        + ", ".join(f"y[{i}]" for i in range(40))
        + '); initial begin a = 0; #10 $display("%b", y); a = 1; #10 $display("%b", y); end endmodule\n'
    )
    (tmp_path / "tb.v").write_text(tb)
    models = [str(p) for p in cell_model_files([INV, BUFFER_CELL])]
    subprocess.run(
        ["iverilog", "-g2012", "-grelative-include", "-DFUNCTIONAL", "-o", "sim", "tb.v", "fan.v", *models],
        cwd=tmp_path,
        check=True,
    )
    lines = subprocess.run(
        ["vvp", "-n", "sim"], cwd=tmp_path, capture_output=True, text=True, check=True
    ).stdout.split()
    assert lines[:2] == ["1" * 40, "0" * 40]  # every inverter still sees a, through its tree
    assert np.array_equal(sorted(fanouts(out, INPUTS).values())[-1:], [4])
