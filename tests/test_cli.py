"""The command line in one place (fsdvs_hw/cli/), defaults in every --help, clear --out errors, bench records."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

import fsdvs_hw
from fsdvs_hw.cli import COMMANDS, main

PACKAGE = Path(fsdvs_hw.__file__).resolve().parent


def test_only_the_cli_package_parses_arguments():
    """No library module imports argparse or defines a verb's add_arguments/run pair."""
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] == "cli":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import) and any(a.name == "argparse" for a in node.names):
                offenders.append(f"{rel}: import argparse")
            elif isinstance(node, ast.ImportFrom) and node.module == "argparse":
                offenders.append(f"{rel}: from argparse")
        names = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
        if {"add_arguments", "run"} <= names:
            offenders.append(f"{rel}: defines a command (add_arguments + run)")
    assert offenders == []
    assert all(m.startswith("fsdvs_hw.cli.") for m in COMMANDS.values())


@pytest.mark.parametrize("verb", sorted(COMMANDS))
def test_every_help_shows_the_defaults(verb, capsys):
    with pytest.raises(SystemExit) as exc:
        main([verb, "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "default" in text
    import argparse

    from fsdvs_hw.cli import _parser

    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction)).choices[verb]
    # every option with a real default (not None/False) names it in its help line
    for action in sub._actions:
        if action.option_strings and action.default not in (None, False, argparse.SUPPRESS) and action.help:
            shown = sub._get_formatter()._get_help_string(action)
            assert "default" in shown, (verb, action.option_strings)


@pytest.mark.parametrize("argv", [
    ["analyse", "dog", "--out", "{f}"],
    ["explore", "designs/default.toml", "--out", "{f}"],
    ["ablation", "--out", "{f}"],
    ["sizing", "designs/default.toml", "--out", "{f}"],
    ["learn", "detection", "--out", "{f}/stem"],
    ["bench", "csf", "--out", "{f}/bench.md"],
    ["bench", "csf", "--json", "{f}/bench.json"],
    ["sweep", "designs/sweep_asic_bits.toml", "--store", "{f}/x.sqlite"],
])
def test_out_naming_an_existing_file_is_a_one_line_error(argv, tmp_path, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    root = Path(__file__).resolve().parents[1]
    args = [a.format(f=f) if "{f}" in a else (str(root / a) if a.endswith(".toml") else a) for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(f) in err and "Traceback" not in err


def test_python_m_fsdvs_hw_cli_is_the_command():
    res = subprocess.run([sys.executable, "-m", "fsdvs_hw.cli", "--version"], capture_output=True, text=True,
                         cwd=PACKAGE.parent, check=False)
    assert res.returncode == 0 and res.stdout.startswith("fsdvs-hw ")


def test_bench_json_writes_records_with_machine_versions_and_units(tmp_path, capsys):
    from fsdvs_hw.benchmarks import RECORD_SCHEMA, read_json

    out = tmp_path / "bench.json"
    assert main(["bench", "csf", "--quick", "--json", str(out), "--out", str(tmp_path / "bench.md")]) == 0
    data = json.loads(out.read_text())
    assert data["schema"] == RECORD_SCHEMA
    records = read_json(out)
    assert records and all(r.bench == "csf" and r.settings == {"quick": True} for r in records)
    r = records[0]
    assert r.machine["cpu_count"] >= 1 and r.versions["python"] and r.versions["numpy"] and r.timestamp
    # the csf table's error column is a number per method row, its wall column in a unit
    errors = [x for x in records if x.metric.startswith("rel") or "error" in x.metric.lower()]
    assert errors and all(x.value >= 0 for x in errors)
    assert any(x.unit in ("s", "ms", "µs") for x in records)
    assert (tmp_path / "bench.md").read_text().startswith("#")
    assert {r.table for r in records} == {"Radial response and CSF agreement (`fsdvs-hw bench csf`)"}


def test_records_from_markdown_reads_units_and_context():
    from fsdvs_hw.benchmarks import BenchRecord, records_from_markdown, timed

    md = ("### 2. Fits\n\n| case | solver | error | wall (ms) | yield |\n|---|---|---|---|---|\n"
          "| dog 7 | ipopt | 1.5e-3 | 12.5 | 95 % |\n| dog 9 | — | n/a | 20 | 90 % |\n\n"
          "| case | median (s) [min–max] |\n|---|---|\n| fit | 0.31 [0.29–0.35] |\n")
    t = timed(lambda: 3, repeats=3)
    recs = records_from_markdown("mesh", md, settings={"quick": True}, threads=2, timings={("dog 7", "wall"): t})
    by = {(r.case, r.metric): r for r in recs}
    assert by[("dog 7; solver=ipopt", "error")].value == pytest.approx(1.5e-3)
    wall = by[("dog 7; solver=ipopt", "wall")]
    assert wall.unit == "ms" and wall.value == 12.5 and wall.repeats == 3
    assert wall.spread_min == pytest.approx(t.best_s * 1e3) and wall.spread_max == pytest.approx(t.worst_s * 1e3)
    assert by[("dog 7; solver=ipopt", "yield")].unit == "%" and by[("dog 9", "wall")].repeats is None
    assert ("dog 9", "error") not in by  # "n/a" is not a number
    assert all(r.table == "2. Fits" and r.threads == 2 for r in recs)
    spread = by[("fit", "median")]
    assert (spread.unit, spread.value, spread.spread_min, spread.spread_max) == ("s", 0.31, 0.29, 0.35)
    assert BenchRecord.from_dict(wall.to_dict()) == wall


def test_timed_keeps_every_run_and_the_last_result():
    from fsdvs_hw.benchmarks import timed

    calls = []
    t = timed(lambda: calls.append(1) or len(calls), repeats=4)
    assert t.repeats == 4 and t.result == 4 and len(calls) == 4
    assert 0 <= t.best_s <= t.median_s <= t.worst_s
    with pytest.raises(ValueError):
        timed(lambda: None, repeats=0)


def test_a_bench_that_changes_torch_threads_leaves_them_as_they_were(monkeypatch):
    torch = pytest.importorskip("torch")
    from fsdvs_hw import bench

    def greedy(*, quick: bool = False) -> str:
        torch.set_num_threads(1 if torch.get_num_threads() != 1 else 2)
        return "## toy\n\n| case | wall (s) |\n|---|---|\n| a | 0.5 |\n"

    module = type(sys)("fsdvs_toy_bench")
    module.greedy = greedy
    monkeypatch.setitem(sys.modules, "fsdvs_toy_bench", module)
    monkeypatch.setitem(bench.BENCHMARKS, "toy", "fsdvs_toy_bench:greedy")
    before = torch.get_num_threads()
    run = bench.benchmark_run("toy", quick=True)
    assert torch.get_num_threads() == before
    assert [(r.metric, r.unit, r.value) for r in run.records] == [("wall", "s", 0.5)]
    assert bench.run_benchmark("toy") == run.markdown


def test_metalens_bench_figure_goes_to_the_figures_folder_or_a_temp_dir(monkeypatch, tmp_path):
    """The full metalens bench draws a figure: never into the package or source tree."""
    import tempfile

    from fsdvs_hw.realise.metalens import bench as mb

    drawn = []
    monkeypatch.setattr(mb, "_grid_table", lambda quick: [])
    monkeypatch.setattr(mb, "_spectral_table", lambda quick: [])
    monkeypatch.setattr(mb, "_fit_table", lambda quick: ([], []))
    monkeypatch.setattr(mb, "plot_fits", lambda fits, path: drawn.append(Path(path)) or Path(path))
    text = mb.bench_metalens(quick=False, figures=tmp_path)
    assert drawn == [tmp_path / "metalens_fits.png"] and str(drawn[0]) in text
    mb.bench_metalens(quick=False)
    assert Path(tempfile.gettempdir()) in drawn[1].parents
    assert PACKAGE.parent not in drawn[1].parents


# one bad value each verb checks itself (after parsing), and one argparse error each
_BAD_VALUES = {
    "analyse": ["analyse", "dog", "--pitch-um", "-3"],
    "bench": ["bench", "no_such_bench"],
    "learn": ["learn", "no_such_task"],
    "codesign-pilot": ["codesign-pilot", "--seeds", "-1"],
    "ablation": ["ablation", "--sizes", "4"],
    "explore": ["explore", "no/such/design.toml"],
    "sweep": ["sweep", "no/such/design.toml"],
    "simulate": ["simulate", "example:bikes", "--out", "events.txt"],
    "sizing": ["sizing", "designs/default.toml", "--target", "-1"],
}


def _one_line_exit_2(argv, capsys) -> str:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2, (argv, code, err)
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_every_verb_has_a_bad_value_case():
    assert set(_BAD_VALUES) == set(COMMANDS)


@pytest.mark.parametrize("verb", sorted(COMMANDS))
def test_a_bad_value_is_one_line_on_stderr_and_exit_2(verb, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    argv = [str(tmp_path / a) if a == "events.txt" else a for a in _BAD_VALUES[verb]]
    err = _one_line_exit_2(argv, capsys)
    assert err.startswith(f"fsdvs-hw {verb}: error:")


@pytest.mark.parametrize("verb", sorted(COMMANDS))
def test_an_unknown_option_is_one_line_on_stderr_and_exit_2(verb, capsys):
    err = _one_line_exit_2([verb, "--no-such-option", "1"], capsys)
    assert err.startswith(f"fsdvs-hw {verb}: error:") and f"fsdvs-hw {verb} --help" in err


def test_every_verb_takes_no_progress_and_it_switches_bars_off(monkeypatch):
    import argparse

    from fsdvs_hw import progress
    from fsdvs_hw.cli import _parser

    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert all("--no-progress" in p._option_string_actions for p in sub.choices.values())
    monkeypatch.setattr(progress, "_ENABLED", True)
    main(["analyse", "dog", "--no-progress"])
    assert progress._ENABLED is False


def test_the_installed_command_exits_2_without_a_traceback():
    res = subprocess.run([sys.executable, "-m", "fsdvs_hw.cli", "sweep", "--workers", "many", "x.toml"],
                         capture_output=True, text=True, cwd=PACKAGE.parent, check=False)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
    assert "--workers" in res.stderr
