"""OpenSTA on the lctime liberty and the whole sky130 flow: needs every synthesis cell characterised
(the full adder and the flip-flop included)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fsdvs_hw.process.sky130")
from fsdvs_hw.realise.asic.cell_timing import TIMING_LIBERTY_PATH, read_pin_capacitance_f  # noqa: E402
from fsdvs_hw.realise.asic.standard_cells import SYNTHESIS_CELLS  # noqa: E402

needs_tools = pytest.mark.skipif(
    not all(shutil.which(t) for t in ("yosys", "iverilog", "vvp", "sta")), reason="yosys, iverilog and OpenSTA needed"
)
TAPS = np.array([[1, -2, 1], [-2, 5, -2], [1, -2, 1]])
INV = "sky130_fd_sc_hd__inv_1"
DFF = "sky130_fd_sc_hd__dfxtp_1"


def test_timing_liberty_covers_every_synthesis_cell_on_full_tables() -> None:
    import re

    from fsdvs_hw.realise.asic.cell_timing import split_cells
    from fsdvs_hw.realise.asic.sky130_data import read_provenance

    from fsdvs_hw.realise.asic.cell_timing import characterised_corners, timing_liberty_path

    assert characterised_corners() == ("tt", "ff", "ss")
    for corner in characterised_corners():
        lib = timing_liberty_path(corner)
        assert set(read_pin_capacitance_f(lib)) == set(SYNTHESIS_CELLS)
        _, cells, _ = split_cells(lib.read_text())
        for name, text in cells.items():  # delays and the flip-flop's constraints follow load and slew: 3 x 3
            templates = set(re.findall(r"(?:cell_rise|cell_fall|rise_constraint|fall_constraint) \((\w+)\)", text))
            assert templates and all(t.endswith("3x3") for t in templates), (corner, name, templates)
    assert read_provenance()["timing_liberty"]["single_point_cells"] == []


def _chain(n: int) -> str:
    """Two flip-flops with ``n`` inverters between them (n even: Q reaches D unchanged)."""
    lines = ["module chain (clk, d, q);", "  input clk, d;", "  output q;", f"  wire [{n}:0] w;"]
    lines += [f"  {DFF} f0 (.CLK(clk), .D(d), .Q(w[0]));"]
    lines += [f"  {INV} i{k} (.A(w[{k}]), .Y(w[{k + 1}]));" for k in range(n)]
    lines += [f"  {DFF} f1 (.CLK(clk), .D(w[{n}]), .Q(q));", "endmodule"]
    return "\n".join(lines) + "\n"


@needs_tools
def test_sta_critical_path_grows_by_one_inverter_delay_per_inverter() -> None:
    from fsdvs_hw.realise.asic.static_timing import run_sta

    t4 = run_sta(_chain(4), TIMING_LIBERTY_PATH, top="chain")
    t12 = run_sta(_chain(12), TIMING_LIBERTY_PATH, top="chain")
    assert t4.endpoint.startswith("f1") and t4.startpoint.startswith("f0")
    per_inverter = (t12.critical_path_s - t4.critical_path_s) / 8
    # an inv_1 driving one inv_1 (2.3 fF) in sky130 hd at tt: some 15-60 ps (published tables ~25-35 ps)
    assert 10e-12 < per_inverter < 80e-12
    assert t4.max_clock_hz == pytest.approx(1 / t4.critical_path_s)
    assert 1e-10 < t4.critical_path_s < 3e-9  # clock-to-Q + 4 inverters + setup


@needs_tools
def test_an_inverter_is_slowest_at_ss_and_fastest_at_ff() -> None:
    from fsdvs_hw.realise.asic.cell_timing import characterised_corners, timing_liberty_path
    from fsdvs_hw.realise.asic.static_timing import run_sta

    assert {"tt", "ss", "ff"} <= set(characterised_corners())
    per = {}
    for c in ("ff", "tt", "ss"):
        t4, t12 = (run_sta(_chain(n), timing_liberty_path(c), top="chain") for n in (4, 12))
        per[c] = (t12.critical_path_s - t4.critical_path_s) / 8
    # same 1.8 V and 25 °C, slow or fast devices: the delay moves by tens of per cent, not by factors
    assert per["ff"] < per["tt"] < per["ss"]
    assert 1.05 < per["ss"] / per["tt"] < 2.0 and 0.5 < per["ff"] / per["tt"] < 0.95


def test_a_corner_without_a_liberty_is_refused_with_the_command() -> None:
    from fsdvs_hw import fit_asic_taps
    from fsdvs_hw.errors import InputError

    with pytest.raises(InputError, match="process-cells --corners sf"):
        fit_asic_taps(TAPS / 5.0, bits=4, pdk="sky130", corners=["sf"])


@needs_tools
def test_the_flow_builds_checks_and_writes_artifacts_the_tools_accept(tmp_path: Path) -> None:
    from fsdvs_hw import fit_asic_taps
    from fsdvs_hw.realise.asic.artifacts import write_asic_artifacts
    from fsdvs_hw.realise.asic.sky130_artifacts import check_sky130_artifacts

    d = fit_asic_taps(TAPS / 5.0, bits=4, input_bits=4, pdk="sky130", pdk_frame=(8, 10), corners=("tt", "ss", "ff"))
    p = d.process
    clocks = {c: t["max_clock_hz"] for c, t in p["corner_timing"].items()}
    assert clocks["ss"] < clocks["tt"] < clocks["ff"] and p["clock_corner"] == "ss"  # the slowest corner sets the clock
    assert p["max_clock_hz"] == clocks["ss"] and "slowest of tt, ss, ff" in p["sources"]["max_clock_hz"]
    assert p is not None and p["gate_level_bit_exact"] and p["outputs_checked"] == 6 * 8  # one frame
    lo, hi = p["energy_per_pixel_interval_j"]
    assert lo < p["energy_per_pixel_j"] < hi and p["energy_spans"] == 12
    assert p["full_adders"] > 0
    assert p["fanout_buffers"] > 0 and p["max_fanout"] == 8  # reset and valid nets fan out: buffered, still bit-exact
    assert 50e6 < p["max_clock_hz"] < 3e9  # a few ns of logic in 130 nm
    assert p["energy_per_pixel_j"] > 0
    cost = d.cost()
    assert cost["max_clock_hz"].value == p["max_clock_hz"] and "OpenSTA" in cost["max_clock_hz"].description
    assert cost["area_m2"].value == p["area_m2"]
    arts = {a.name: a for a in write_asic_artifacts(d, tmp_path, resolution=(8, 10))}
    assert {"gate_level_verilog", "liberty", "timing_liberty", "sta_report", "verilog"} <= set(arts)
    checked = check_sky130_artifacts(tmp_path)
    assert checked["pass_line"].startswith("PASS")
    assert checked["area_um2"] * 1e-12 == pytest.approx(p["area_m2"], rel=1e-9)
    # the record round-trips without the netlist text
    from fsdvs_hw.realise.asic import AsicDesign

    again = AsicDesign.from_dict(d.to_dict())
    assert again.process == d.process and again.built is None


_SKY130_DESIGN = """
[realisations]
include = ["learned", "delta", "asic"]
[process]
pdk = "sky130"                # [process] alone builds the taps in sky130 cells
[realisations.asic]
bits = 6
pdk_frame = [16, 24]
[analysis]
csf_methods = ["mannos_sakrison_1974"]
[sensor]
resolution = [16, 24]
[emulation]
enabled = false
[run]
workers = 1
"""


@pytest.mark.slow
@needs_tools
def test_explore_with_sky130_taps_records_the_sta_clock_and_writes_the_netlist(tmp_path: Path) -> None:
    import json

    from fsdvs_hw.explore.explore import run_exploration
    from fsdvs_hw.realise.artifacts import read_index

    p = tmp_path / "sky130.toml"
    p.write_text(_SKY130_DESIGN)
    res = run_exploration(p, tmp_path / "out", progress=False)
    text = (tmp_path / "out" / "scores.json").read_text()
    assert "max_clock_hz" in text and "OpenSTA" in text and "sky130 tt 25" in text
    scores = json.loads(text)
    assert "asic" in json.dumps(scores)
    names = {e["name"] for e in read_index(res.artifacts_index) if e["realisation"] == "asic"}
    assert {"gate_level_verilog", "liberty", "timing_liberty", "sta_report"} <= names
    folder = next(res.artifacts_index.parent.glob("asic*"))
    from fsdvs_hw.realise.asic.sky130_artifacts import check_sky130_artifacts

    assert check_sky130_artifacts(folder)["pass_line"].startswith("PASS")
    html = "".join(f.read_text() for f in (tmp_path / "out").rglob("*.html"))
    assert "taps in sky130 standard cells" in html and "MHz" in html and "bit-exact" in html
