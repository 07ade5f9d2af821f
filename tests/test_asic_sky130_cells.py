"""The taps as sky130 standard cells: the generated liberty against the wheel's own files, and the
mapped netlist against yosys and the bit-exact integer model (fast: a 3×3 kernel, 4-bit pixels)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.errors import InputError

pytest.importorskip("fsdvs_hw.process.sky130")
from fsdvs_hw.process.sky130 import cell_files  # noqa: E402
from fsdvs_hw.realise.asic.arith import integer_correlate  # noqa: E402
from fsdvs_hw.realise.asic.rtl import generate_verilog  # noqa: E402
from fsdvs_hw.realise.asic.standard_cells import (  # noqa: E402
    GENERATED_LIBERTY_PATH,
    SYNTHESIS_CELLS,
    SYNTHESIS_LIBERTY_PATH,
    generate_liberty,
    read_liberty_areas,
)

needs_tools = pytest.mark.skipif(
    not all(shutil.which(t) for t in ("yosys", "iverilog", "vvp")), reason="yosys and iverilog needed"
)

SAMPLE = ("inv_1", "nand2_1", "a21oi_1", "o21ai_1", "xor2_1", "mux2_1", "mux2i_1", "mux4_1", "fa_1", "ha_1", "maj3_1")
TAPS = np.array([[1, -2, 1], [-2, 5, -2], [1, -2, 1]])


def _lef_area_um2(cell: str) -> float:
    fam, drive = cell.rsplit("_", 1)
    text = cell_files(fam, int(drive))["lef"].read_text()
    w, h = re.search(r"SIZE\s+(\S+)\s+BY\s+(\S+)", text).groups()  # type: ignore[union-attr]
    return float(w) * float(h)


def test_generated_areas_are_the_lef_sizes_of_the_wheel() -> None:
    areas = read_liberty_areas(GENERATED_LIBERTY_PATH)
    assert len(areas) > 250
    for cell in (*SAMPLE, "dfxtp_1", "inv_16", "fa_4"):
        assert areas[f"sky130_fd_sc_hd__{cell}"] == pytest.approx(_lef_area_um2(cell), abs=1e-6)
    # published sky130_fd_sc_hd areas (the skywater-pdk liberty): inv_1 3.7536, fa_1 20.0192 µm²
    assert areas["sky130_fd_sc_hd__inv_1"] == pytest.approx(3.7536)
    assert areas["sky130_fd_sc_hd__fa_1"] == pytest.approx(20.0192)


def test_synthesis_liberty_holds_the_stated_cells() -> None:
    assert set(read_liberty_areas(SYNTHESIS_LIBERTY_PATH)) == set(SYNTHESIS_CELLS)


@needs_tools
def test_committed_liberties_are_what_the_generator_writes(tmp_path: Path) -> None:
    generate_liberty(tmp_path / "f.lib", synthesis_path=tmp_path / "s.lib")
    assert (tmp_path / "f.lib").read_text() == GENERATED_LIBERTY_PATH.read_text()
    assert (tmp_path / "s.lib").read_text() == SYNTHESIS_LIBERTY_PATH.read_text()


@needs_tools
def test_liberty_functions_agree_with_the_cells_own_verilog(tmp_path: Path) -> None:
    """yosys builds each cell from the liberty's ``function``; Icarus compares it with the wheel's
    functional model over every input combination (an independent reader of both)."""
    names = [f"sky130_fd_sc_hd__{c}" for c in SAMPLE]
    subprocess.run(
        [
            "yosys",
            "-q",
            "-p",
            f"read_liberty {GENERATED_LIBERTY_PATH}; select {' '.join(names)}; write_verilog -selected lib.v",
        ],
        cwd=tmp_path,
        check=True,
    )
    lib_v = (tmp_path / "lib.v").read_text()
    for n in names:  # the liberty's modules renamed, so both models live in one simulation
        lib_v = re.sub(rf"\bmodule\s+\\?{n}\b", f"module L_{n}", lib_v)
    (tmp_path / "lib.v").write_text(lib_v)
    tb, total = ["module tb; integer v;"], 0
    init = []
    for i, n in enumerate(names):
        fam, drive = n.split("__")[1].rsplit("_", 1)
        ports = re.findall(
            r'\[\s*"signal",\s*"(\w+)",\s*"(input|output)"',
            cell_files(fam, int(drive))["lef"].with_name("definition.json").read_text(),
        )
        ins = [p for p, d in ports if d == "input"]
        outs = [p for p, d in ports if d == "output"]
        conn_in = ", ".join(f".{p}(x{i}[{k}])" for k, p in enumerate(ins))
        tb += [f"reg [{len(ins) - 1}:0] x{i};", f"wire [{len(outs) - 1}:0] a{i}, b{i};"]
        tb += [f"{n} u{i} ({conn_in}, {', '.join(f'.{p}(a{i}[{k}])' for k, p in enumerate(outs))});"]
        tb += [f"L_{n} l{i} ({conn_in}, {', '.join(f'.{p}(b{i}[{k}])' for k, p in enumerate(outs))});"]
        init.append(
            f'for (v = 0; v < {1 << len(ins)}; v = v + 1) begin x{i} = v; #1; $display("%0d %b %b", {i}, a{i}, b{i}); end'
        )
        total += 1 << len(ins)
    (tmp_path / "tb.v").write_text("\n".join([*tb, "initial begin", *init, "end", "endmodule"]) + "\n")
    models = [
        str(cell_files(*n.split("__")[1].rsplit("_", 1)[:1], int(n.rsplit("_", 1)[1]))["functional"]) for n in names
    ]
    subprocess.run(
        ["iverilog", "-g2012", "-grelative-include", "-o", "s.vvp", "tb.v", "lib.v", *models], cwd=tmp_path, check=True
    )
    lines = subprocess.run(
        ["vvp", "-n", "s.vvp"], cwd=tmp_path, capture_output=True, text=True, check=True
    ).stdout.split("\n")
    rows = [ln.split() for ln in lines if ln.strip()]
    assert len(rows) == total
    assert all(set(a) <= {"0", "1"} and a == b for _, a, b in rows)


@needs_tools
def test_mapped_netlist_is_bit_exact_uses_full_adders_and_has_yosys_area(tmp_path: Path) -> None:
    from fsdvs_hw.realise.asic.gate_level import read_stat, simulate_gate_level, synthesise_to_cells
    from fsdvs_hw.realise.asic.toggle_power import video_frames

    frames = video_frames(4, (8, 10), n_frames=2)  # a real clip, 4-bit pixels
    assert frames.shape == (2, 8, 10) and frames.max() > frames.min()
    net = synthesise_to_cells(generate_verilog(TAPS, input_bits=4, image_width=10, image_height=8, symmetry="8-fold"))
    assert net.full_adders > 0 and net.flip_flops > 0
    assert set(net.cell_types) <= set(SYNTHESIS_CELLS)
    run = simulate_gate_level(net, frames, TAPS, input_bits=4)
    np.testing.assert_array_equal(run.outputs, integer_correlate(frames, TAPS, input_bits=4))
    # the area: yosys stat -liberty on the written netlist, and the liberty's areas summed by hand
    (tmp_path / "m.v").write_text(net.verilog)
    subprocess.run(
        ["yosys", "-q", "-p", f"read_verilog m.v; tee -o stat.txt stat -liberty {SYNTHESIS_LIBERTY_PATH}"],
        cwd=tmp_path,
        check=True,
    )
    _, area_um2, _ = read_stat((tmp_path / "stat.txt").read_text())
    assert net.area_m2 == pytest.approx(area_um2 * 1e-12, rel=1e-9)
    areas = read_liberty_areas(SYNTHESIS_LIBERTY_PATH)
    assert net.area_m2 == pytest.approx(sum(n * areas[c] for c, n in net.cell_types.items()) * 1e-12, rel=1e-9)


@needs_tools
def test_gate_level_simulation_catches_a_wrong_cell() -> None:
    """One NAND swapped for a NOR in the netlist: the comparison with the integer model must fail."""
    from dataclasses import replace

    from fsdvs_hw.realise.asic.gate_level import simulate_gate_level, synthesise_to_cells

    rng = np.random.default_rng(1)
    frames = rng.integers(0, 16, (2, 8, 10))
    net = synthesise_to_cells(generate_verilog(TAPS, input_bits=4, image_width=10, image_height=8, symmetry="8-fold"))
    from fsdvs_hw.realise.asic.rtl import RtlError

    broken = replace(net, verilog=net.verilog.replace("sky130_fd_sc_hd__nand2_1", "sky130_fd_sc_hd__nor2_1", 3))
    try:  # a broken control path gives the wrong number of outputs (RtlError), a broken datapath wrong values
        out = simulate_gate_level(broken, frames, TAPS, input_bits=4).outputs
    except RtlError as exc:
        assert "outputs" in str(exc)
    else:
        assert not np.array_equal(out, integer_correlate(frames, TAPS, input_bits=4))


def test_bad_inputs_are_refused_clearly(tmp_path: Path) -> None:
    from fsdvs_hw.realise.asic.gate_level import synthesise_to_cells

    with pytest.raises(InputError, match="top"):
        synthesise_to_cells("module m; endmodule", top="m; shell")
    with pytest.raises(InputError, match="liberty"):
        synthesise_to_cells("module m; endmodule", top="m", liberty=tmp_path / "missing.lib")
    with pytest.raises(InputError, match="cell family"):
        from fsdvs_hw.realise.asic.standard_cells import synthesis_cells

        synthesis_cells(("no_such_cell",))
