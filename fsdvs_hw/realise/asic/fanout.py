"""Buffer trees on the high-fanout nets of a mapped netlist: what a designer's flow does before timing it.

yosys and abc map the filter's logic but leave nets that fan out to thousands of pins: the
line buffers' read-address register drives every read multiplexer's select (some 2.7 pF at a
48 × 64 frame). With load-dependent cell tables OpenSTA then sees a drive of one ``dfxtp_1`` or
``inv_1`` charging that load through tens of nanoseconds — a netlist nobody would tape out. A
place-and-route flow repairs it (OpenROAD's ``repair_design``, not packaged for these machines);
:func:`buffer_high_fanout` does the part of that repair timing needs, by a stated rule:

* every net with more than ``max_fanout`` cell input pins (the clock excepted: STA takes an ideal
  clock) gets a balanced tree of ``buf_1`` cells: the sinks in groups of at most ``max_fanout``,
  each group driven by one buffer, the buffers themselves grouped the same way until the root
  drives at most ``max_fanout`` buffers;
* the original driver, module ports and every other connection stay as they were.

The result is simulated at gate level against the integer model like any other mapped netlist
(a wrong rewiring fails there), and yosys's ``stat -liberty`` counts the buffers' area.

Examples
--------
>>> from fsdvs_hw.realise.asic.fanout import buffer_high_fanout
>>> v = "module m (a, y0, y1, y2);\\n  input a;\\n  output y0, y1, y2;\\n" + "".join(
...     f"  sky130_fd_sc_hd__inv_1 u{i} (\\n    .A(a),\\n    .Y(y{i})\\n  );\\n" for i in range(3)) + "endmodule\\n"
>>> out, added = buffer_high_fanout(v, {"sky130_fd_sc_hd__inv_1": {"A"}}, max_fanout=2)
>>> added  # three sinks in groups of two: two buffers
2
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from ...errors import InputError
from ...process.sky130 import CELL_LIBRARY

__all__ = ["BUFFER_CELL", "DEFAULT_MAX_FANOUT", "INSTANCE_PATTERN", "PIN_PATTERN", "buffer_high_fanout", "fanouts"]

#: The cell the trees are built from (the only buffer in the synthesis subset).
BUFFER_CELL: str = f"{CELL_LIBRARY}__buf_1"
#: Largest number of cell inputs a net drives after buffering (about 20 fF of ``_1`` inputs).
DEFAULT_MAX_FANOUT: int = 8

#: One cell instance of yosys's ``write_verilog -noattr``: (indent, cell type, instance, pin list).
INSTANCE_PATTERN = re.compile(r"^(\s*)(\w+)\s+(\\\S+|\w+)\s*\(((?:\s*\.\w+\([^()]*\),?)+)\s*\);", flags=re.M)
#: One ``.PIN(net)`` connection of an instance's pin list: (pin, net as written).
PIN_PATTERN = re.compile(r"\.(\w+)\(([^()]*)\)")


def _sinks(verilog: str, inputs: Mapping[str, set[str]]) -> dict[str, list[tuple[str, str]]]:
    """Net (spaces removed) → ``[(instance, pin)]`` of the cell inputs it drives."""
    out: dict[str, list[tuple[str, str]]] = {}
    for m in INSTANCE_PATTERN.finditer(verilog):
        pins_in = inputs.get(m.group(2), set())
        for p in PIN_PATTERN.finditer(m.group(4)):
            if p.group(1) in pins_in:
                out.setdefault(p.group(2).replace(" ", ""), []).append((m.group(3), p.group(1)))
    return out


def fanouts(verilog: str, inputs: Mapping[str, set[str]]) -> dict[str, int]:
    """Net → number of cell input pins it drives (``inputs``: cell type → its input pin names)."""
    return {net: len(s) for net, s in _sinks(verilog, inputs).items()}


def _tree(
    root: str, sinks: list[tuple[str, str]], k: int, first: int
) -> tuple[list[tuple[str, str, str]], dict[tuple[str, str], str]]:
    """One net's tree: buffers ``(instance, input net, output net)`` and the sinks' new nets.

    Buffers are numbered from ``first``; each level groups at most ``k`` items (sinks, then buffers).
    """
    out_net: dict[str, str] = {}
    in_net: dict[str, str] = {}
    remap: dict[tuple[str, str], str] = {}
    level: list[tuple[str, str] | str] = list(sinks)  # sinks (instance, pin), then buffer instances
    n = first
    while len(level) > k:
        parents: list[tuple[str, str] | str] = []
        for i in range(0, len(level), k):
            inst, net = f"_fobuf{n}_", f"_fo{n}_"
            n += 1
            out_net[inst] = net
            for item in level[i : i + k]:
                if isinstance(item, tuple):
                    remap[item] = net
                else:
                    in_net[item] = net
            parents.append(inst)
        level = parents
    for item in level:  # what is left hangs on the root
        if isinstance(item, str):
            in_net[item] = root + " " if root.startswith("\\") else root  # an escaped name ends at a space
    return [(b, in_net[b], out_net[b]) for b in out_net], remap


def buffer_high_fanout(
    verilog: str,
    inputs: Mapping[str, set[str]],
    *,
    max_fanout: int = DEFAULT_MAX_FANOUT,
    exclude: tuple[str, ...] = ("clk",),
) -> tuple[str, int]:
    """Insert balanced ``buf_1`` trees on every net driving more than ``max_fanout`` cell inputs.

    Parameters
    ----------
    verilog : str
        A flat netlist from yosys ``write_verilog -noattr -noexpr -simple-lhs`` (one module).
    inputs : mapping
        Cell type → names of its input pins (e.g. from the timing liberty's pin capacitances).
    max_fanout : int
        Most cell inputs one net may drive (2 … 64).
    exclude : tuple of str
        Nets left alone (the clock: STA assumes an ideal clock tree).

    Returns
    -------
    (str, int)
        The netlist with the trees, and the number of buffers added.
    """
    if not (isinstance(max_fanout, int) and 2 <= max_fanout <= 64):
        raise InputError(f"max_fanout: allowed an integer in 2 … 64, got {max_fanout!r}")
    if verilog.count("endmodule") != 1:
        raise InputError("buffer_high_fanout: expected one flat module")
    buffers: list[tuple[str, str, str]] = []
    remap: dict[tuple[str, str], str] = {}
    for net, sinks in _sinks(verilog, inputs).items():
        if len(sinks) > max_fanout and net not in exclude:
            b, r = _tree(net, sinks, max_fanout, len(buffers))
            buffers += b
            remap.update(r)
    if not buffers:
        return verilog, 0

    def rewire(m: re.Match[str]) -> str:
        inst = m.group(3)
        pins = PIN_PATTERN.sub(lambda p: f".{p.group(1)}({remap.get((inst, p.group(1)), p.group(2))})", m.group(4))
        return f"{m.group(1)}{m.group(2)} {inst} ({pins});"

    body = INSTANCE_PATTERN.sub(rewire, verilog)
    first = INSTANCE_PATTERN.search(body)
    at = first.start() if first is not None else body.rindex("endmodule")
    wires = "".join(f"  wire {o};\n" for _, _, o in buffers)  # declared before the first instance uses them
    head, _, _ = (body[:at] + wires + body[at:]).rpartition("endmodule")
    cells = "".join(f"  {BUFFER_CELL} {b} (\n    .A({i}),\n    .X({o})\n  );\n" for b, i, o in buffers)
    return head + cells + "endmodule\n", len(buffers)
