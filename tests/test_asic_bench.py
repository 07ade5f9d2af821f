"""The `fsdvs-hw bench asic` benchmark runs end to end and its RTL checks report zero mismatches."""

from __future__ import annotations

import re

import pytest

from conftest import require_tool


@pytest.mark.slow
@pytest.mark.tools
def test_bench_asic_quick_runs_and_rtl_is_bit_exact():
    require_tool("iverilog")
    require_tool("yosys")
    from benchmarks import BENCHMARKS, run_benchmark

    assert BENCHMARKS["asic"] == "benchmarks.asic:bench_asic"
    text = run_benchmark("asic", quick=True)
    assert "Bit sweep on DoG 7×7" in text and "objective='csf'" in text
    # every RTL row ends with its mismatch count; all must be zero
    sweep_rows = [
        line
        for line in text.splitlines()
        if re.match(r"\| (2|4|8|12|16) \| [0-9.e+-]+ \| [0-9.e+-]+ \| [0-9.e+-]+ \|", line)
    ]
    assert len(sweep_rows) >= 10
    mism = [int(line.rstrip(" |").rsplit("|", 1)[1]) for line in sweep_rows if line.count("|") == 15]
    assert mism and all(m == 0 for m in mism)
