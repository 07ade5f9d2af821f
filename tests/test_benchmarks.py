"""Benchmarks as records: the table builder, the records it prints, JSON, and no global state changed.

Fast tests exercise :class:`benchmarks.harness.BenchSection` directly and run the ``csf`` bench
(quick); the slow test runs every other registered bench in quick mode and checks, for each, that
it returns a :class:`BenchRun` whose every record is the number its Markdown prints, with a unit
(and repeats and spread on every timing), that the records survive a JSON round trip, and that
the bench itself — called without the registry's safety net — leaves torch's threads, inter-op
threads, default dtype and random state, numpy's error state, the warnings filters and the
environment as it found them.
"""

from __future__ import annotations

import importlib
import math
import os
import re
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.harness import (
    BenchRecord,
    BenchRun,
    BenchSection,
    Column,
    Measured,
    Timing,
    kept_global_state,
    read_json,
    timed,
    write_json,
)
from fsdvs_hw.errors import InputError

#: A printed number: optional sign, digits, optional decimals and exponent.
_TOKEN = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
#: Metrics (or units) that are times: their records must carry repeats and a spread.
_TIME_UNITS = {"s", "ms", "µs", "us", "min"}


def _close(value: float, token: str) -> bool:
    """``value`` printed as ``token`` (to the token's precision, half a unit of its last digit)."""
    mantissa, _, exp = token.partition("e")
    decimals = len(mantissa.partition(".")[2])
    tol = 0.5 * 10.0 ** (int(exp or 0) - decimals)
    return abs(value - float(token)) <= tol * (1 + 1e-9) + 1e-15 * abs(value) + 1e-12


def _rows_of(markdown: str, case: str) -> list[str]:
    """The table rows of ``markdown`` that hold every text value of ``case`` (``h=v; h=v``)."""
    values = [part.split("=", 1)[1] for part in case.split("; ") if "=" in part]
    return [
        line
        for line in markdown.splitlines()
        if line.startswith("|") and values and all(v in line.replace("**", "").replace("`", "") for v in values)
    ]


def assert_records_are_what_is_printed(run: BenchRun) -> None:
    """Every record's value is printed in its row (or, for values quoted in text, in the section),
    every record has a unit field, every timing has repeats and a spread around its value, and
    every table of the Markdown has records."""
    assert isinstance(run, BenchRun) and run.records, run.name
    for r in run.records:
        assert isinstance(r.unit, str) and r.metric and r.table and math.isfinite(r.value), r
        where = _rows_of(run.markdown, r.case) or [run.markdown]
        tokens = [t for line in where for t in _TOKEN.findall(line)]
        assert any(_close(r.value, t) for t in tokens), f"{r.table} / {r.case} / {r.metric} = {r.value} not printed"
        if r.unit in _TIME_UNITS:
            assert r.repeats is not None and r.repeats >= 1, r
            assert r.spread_min is not None and r.spread_max is not None, r
            assert r.spread_min <= r.value * (1 + 1e-9) and r.value <= r.spread_max * (1 + 1e-9), r
    n_tables = sum(1 for line in run.markdown.splitlines() if re.match(r"^\|(---\|)+$", line))
    assert len({r.table for r in run.records}) >= 1 and n_tables >= 1


def _global_state() -> dict[str, object]:
    import torch

    return {
        "threads": torch.get_num_threads(),
        "interop": torch.get_num_interop_threads(),
        "dtype": torch.get_default_dtype(),
        "rng": torch.get_rng_state().numpy().tobytes(),
        "np_err": np.geterr(),
        "np_rng": np.random.get_state()[1].tobytes(),
        "warnings": list(warnings.filters),
        "environ": dict(os.environ),
    }


# --------------------------------------------------------------------------------------- builder
def _demo() -> BenchRun:
    sec = BenchSection("demo", settings={"quick": True})
    sec.text("### 2. Fits", "")
    t = sec.table(
        Column.text("case"),
        Column.text("solver"),
        Column.number("error", ".2e"),
        Column.number("wall (ms)", ".1f", spread=True),
        Column.number("yield", ".0f", suffix=" %", unit="%"),
        Column.numbers("95 % CI", "[{0}, {1}]", ("CI low", "%", ".1f"), ("CI high", "%", ".1f")),
        threads=2,
    )
    t.row("dog 7", "ipopt", 1.5e-3, Timing((0.010, 0.0125, 0.020), None), 95.0, (1.04, 2.96))
    t.row("dog 9", "—", "n/a", None, float("nan"), "no data")
    sec.text(
        "",
        f"Fit of the demo: {sec.value('demo fit', 'time per call', Measured(3.25, 4, 3.0, 3.5), unit='s', spec='.2f')} s.",
    )
    return sec.run()


def test_section_prints_its_records_and_nothing_else():
    run = _demo()
    assert run.markdown == (
        "### 2. Fits\n\n| case | solver | error | wall (ms) | yield | 95 % CI |\n|---|---|---|---|---|---|\n"
        "| dog 7 | ipopt | 1.50e-03 | 12.5 [10.0–20.0] | 95 % | [1.0, 3.0] |\n"
        "| dog 9 | — | n/a | — | n/a | no data |\n\nFit of the demo: 3.25 s."
    )
    by = {(r.case, r.metric): r for r in run.records}
    assert set(by) == {("case=dog 7; solver=ipopt", m) for m in ("error", "wall", "yield", "CI low", "CI high")} | {
        ("demo fit", "time per call")
    }
    wall = by[("case=dog 7; solver=ipopt", "wall")]
    # a Timing cell: the median of its runs in the column's unit, repeats and min–max kept
    assert (wall.unit, wall.value, wall.repeats) == ("ms", pytest.approx(12.5), 3)
    assert (wall.spread_min, wall.spread_max) == (pytest.approx(10.0), pytest.approx(20.0))
    assert (
        by[("case=dog 7; solver=ipopt", "error")].unit == "" and by[("case=dog 7; solver=ipopt", "yield")].unit == "%"
    )
    assert (
        by[("case=dog 7; solver=ipopt", "CI low")].value == 1.04
        and by[("case=dog 7; solver=ipopt", "CI high")].value == 2.96
    )
    assert all(r.table == "2. Fits" and r.bench == "demo" and r.settings == {"quick": True} for r in run.records)
    assert all(r.threads == 2 for r in run.records if r.case != "demo fit")
    quoted = by[("demo fit", "time per call")]
    assert (quoted.value, quoted.repeats, quoted.spread_min, quoted.spread_max) == (3.25, 4, 3.0, 3.5)
    assert all(r.machine["cpu_count"] >= 1 and r.versions["python"] and r.timestamp for r in run.records)
    assert_records_are_what_is_printed(run)


def test_columns_refuse_what_they_cannot_record():
    with pytest.raises(InputError, match="not a unit"):
        Column.number("adders (pre-add)")  # a parenthesised word is not a unit: say which
    assert Column.number("adders (pre-add)", "d", unit="count", metric="adders").parts[0].unit == "count"
    with pytest.raises(InputError, match="summary"):
        Column.number("t (s)", summary="average")
    sec = BenchSection("x")
    t = sec.table(
        Column.text("a"), Column.number("b"), Column.numbers("c", "{0}/{1}", ("c0", "", ".1f"), ("c1", "", ".1f"))
    )
    with pytest.raises(InputError, match="3 cells"):
        t.row("only", 1.0)
    with pytest.raises(InputError, match="tuple of 2"):
        t.row("x", 1.0, 2.0)
    t2 = sec.table(Column.text("a"), Column.number("speed (m/s)", unit="m/s"))
    with pytest.raises(InputError, match="time units"):
        t2.row("x", timed(lambda: None))  # a timing shown in m/s
    with pytest.raises(InputError, match="empty"):
        Measured.of([])
    t3 = sec.table(Column.text("a"), Column.number("wall (s)"))
    with pytest.raises(InputError, match="is a time"):
        t3.row("x", 0.5)  # a bare number as a timing: its repeats and spread would be lost
    t3.row("x", Measured.of([0.5]))


def test_measured_summaries_and_timing_units():
    m = Measured.of([3.0, 1.0, 2.0, 10.0], "median")
    assert (m.value, m.repeats, m.low, m.high) == (2.5, 4, 1.0, 10.0)
    assert Measured.of([3.0, 1.0], "best").value == 1.0 and Measured.of([3.0, 1.0], "mean").value == 2.0
    t = Timing((0.002, 0.001, 0.004), "r")
    us = t.measured("µs", "best")
    assert (us.value, us.repeats, us.low, us.high) == (
        pytest.approx(1000.0),
        3,
        pytest.approx(1000.0),
        pytest.approx(4000.0),
    )
    assert t.measured("ms").value == pytest.approx(2.0)


def test_case_override_and_row_threads():
    sec = BenchSection("x")
    t = sec.table(Column.text("a"), Column.number("b", ".1f"))
    t.row("p", 1.0, case="my case", threads=7)
    t.row("q", 2.0, threads=None)
    (r1, r2) = sec.records()
    assert (r1.case, r1.threads) == ("my case", 7) and (r2.case, r2.threads) == ("a=q", None)


@settings(max_examples=60, deadline=None)
@given(
    value=st.floats(min_value=-1e12, max_value=1e12, allow_nan=False) | st.floats(min_value=-1e-12, max_value=1e-12),
    spec=st.sampled_from([".2e", ".3f", ".1f", ".0f", ".3g", ".2g", "d", "+.1f", ".1e"]),
)
def test_every_printed_number_is_its_record_to_the_printed_precision(value, spec):
    """Extremes included (tiny, huge, negative): the cell prints the record's value."""
    sec = BenchSection("p")
    sec.table(Column.text("k"), Column.number("v", spec)).row("row", value)
    run = sec.run()
    (rec,) = run.records
    assert rec.value == value
    cell = run.markdown.splitlines()[-1].split("|")[2].strip()
    if spec.endswith("g"):  # %g may print "1e+12" or an integer: compare the parsed cell
        assert float(cell) == pytest.approx(value, rel=0.5 * 10 ** (1 - int(spec[1:-1])), abs=1e-300)
    else:
        assert _close(value, cell.lstrip("+")) or _close(value, cell)


def test_records_json_round_trip(tmp_path):
    run = _demo()
    path = write_json(run.records, tmp_path / "r.json")
    back = read_json(path)
    assert back == list(run.records)
    assert BenchRecord.from_dict(back[0].to_dict()) == back[0]
    (tmp_path / "bad.json").write_text('{"schema": "other/9", "records": []}')
    with pytest.raises(InputError, match="schema"):
        read_json(tmp_path / "bad.json")


def test_kept_global_state_restores_what_a_bench_may_change(monkeypatch):
    torch = pytest.importorskip("torch")
    before = _global_state()
    monkeypatch.delenv("FSDVS_BENCH_PROBE", raising=False)
    with kept_global_state():
        torch.set_num_threads(1 if torch.get_num_threads() != 1 else 2)
        torch.set_default_dtype(torch.float64)
        torch.manual_seed(123)
        torch.rand(3)
        np.seterr(all="ignore")
        np.random.seed(5)
        warnings.simplefilter("ignore")
        os.environ["FSDVS_BENCH_PROBE"] = "1"
        os.environ["PATH"] = "/nowhere"
        assert _global_state() != before
    assert _global_state() == before


# ------------------------------------------------------------------------------------- benches
def test_benchmark_run_refuses_a_bench_that_returns_markdown(monkeypatch):
    import sys

    import benchmarks as bench

    module = type(sys)("fsdvs_str_bench")
    module.old = lambda *, quick=False: "## old\n\n| a | b |\n|---|---|\n| x | 1 |\n"
    monkeypatch.setitem(sys.modules, "fsdvs_str_bench", module)
    monkeypatch.setitem(bench.BENCHMARKS, "old", "fsdvs_str_bench:old")
    with pytest.raises(TypeError, match="not a BenchRun"):
        bench.benchmark_run("old", quick=True)


def _run_registered(name: str) -> BenchRun:
    """Call the registered function itself (no registry safety net) and check the state it leaves."""
    pytest.importorskip("torch")
    from benchmarks import BENCHMARKS

    module, func = BENCHMARKS[name].split(":")
    fn = getattr(importlib.import_module(module), func)
    before = _global_state()
    run = fn(quick=True)
    after = _global_state()
    changed = {k for k in before if before[k] != after[k]}
    assert not changed, f"bench {name} changed global state: {sorted(changed)}"
    return run


def test_csf_bench_records_are_its_markdown_and_it_leaves_state_alone(tmp_path):
    run = _run_registered("csf")
    assert run.name == "csf"
    assert_records_are_what_is_printed(run)
    errors = [r.value for r in run.records if r.metric == "max error"]
    times = [r for r in run.records if r.metric == "time per call"]
    assert len(errors) == 7 and len(times) == 9  # 7 settings + 2 csf_agreement timings
    # the finest angular setting is closest to the reference; coarse FFT binning is worst
    assert errors[3] < 1e-3 and max(errors) == max(errors[4:])
    assert all(r.unit == "ms" and r.repeats >= 2 for r in times)
    assert read_json(write_json(run.records, tmp_path / "csf.json")) == list(run.records)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",
    ["stats", "explore", "mesh", "metalens", "asic", "tasks", "sim", "sensors", "user_data", "upsampling", "demo"],
)
def test_every_bench_measures_into_records_first(name, tmp_path):
    """Quick mode: a BenchRun whose records are what its Markdown prints; JSON round trip; no global
    state changed. (asic needs iverilog and yosys, mesh's spice table ngspice.)"""
    if name == "asic":
        from conftest import require_tool

        require_tool("iverilog")
        require_tool("yosys")
    run = _run_registered(name)
    assert run.name == name
    assert_records_are_what_is_printed(run)
    assert read_json(write_json(run.records, tmp_path / f"{name}.json")) == list(run.records)


def test_the_bench_help_names_every_registered_bench() -> None:
    import benchmarks
    from fsdvs_hw.cli.bench import _NAMES

    assert [n.strip() for n in _NAMES.split(",")] == list(benchmarks.BENCHMARKS)
