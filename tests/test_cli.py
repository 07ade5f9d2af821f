"""The command line in one place (fsdvs_hw/cli/), defaults in every --help, clear --out errors, bench records."""

from __future__ import annotations

import ast
import json
import re
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


@pytest.mark.parametrize(
    "argv",
    [
        ["analyse", "dog", "--out", "{f}"],
        ["explore", "designs/default.toml", "--out", "{f}"],
        ["ablation", "--out", "{f}"],
        ["sizing", "designs/default.toml", "--out", "{f}"],
        ["learn", "detection", "--out", "{f}/stem"],
        ["bench", "csf", "--out", "{f}/bench.md"],
        ["bench", "csf", "--json", "{f}/bench.json"],
        ["sweep", "designs/sweep_asic_bits.toml", "--store", "{f}/x.sqlite"],
    ],
)
def test_out_naming_an_existing_file_is_a_one_line_error(argv, tmp_path, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    root = Path(__file__).resolve().parents[1]
    args = [a.format(f=f) if "{f}" in a else (str(root / a) if a.endswith(".toml") else a) for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(f) in err and "Traceback" not in err


def test_python_m_fsdvs_hw_cli_is_the_command():
    res = subprocess.run(
        [sys.executable, "-m", "fsdvs_hw.cli", "--version"],
        capture_output=True,
        text=True,
        cwd=PACKAGE.parent,
        check=False,
    )
    assert res.returncode == 0 and res.stdout.startswith("fsdvs-hw ")


def _toy_bench(monkeypatch, fn):
    """Register ``fn`` as the bench ``toy`` (module ``fsdvs_toy_bench``) for one test."""
    import benchmarks as bench

    module = type(sys)("fsdvs_toy_bench")
    module.toy = fn
    monkeypatch.setitem(sys.modules, "fsdvs_toy_bench", module)
    monkeypatch.setitem(bench.BENCHMARKS, "toy", "fsdvs_toy_bench:toy")
    return bench


def _toy_run(*, quick: bool = False):
    from benchmarks.harness import BenchSection, Column, timed

    sec = BenchSection("toy", settings={"quick": quick})
    sec.text("### Toy table", "")
    t = sec.table(Column.text("case"), Column.number("max error", ".2e"), Column.number("wall (ms)", ".3f"))
    t.row("a", 1.5e-3, timed(lambda: sum(range(100)), 3))
    return sec.run()


def test_bench_json_writes_records_with_machine_versions_and_units(tmp_path, capsys, monkeypatch):
    from benchmarks.harness import RECORD_SCHEMA, read_json

    _toy_bench(monkeypatch, _toy_run)
    out = tmp_path / "bench.json"
    assert main(["bench", "toy", "--quick", "--json", str(out), "--out", str(tmp_path / "bench.md")]) == 0
    data = json.loads(out.read_text())
    assert data["schema"] == RECORD_SCHEMA
    records = read_json(out)
    assert [(r.bench, r.table, r.case, r.metric, r.unit) for r in records] == [
        ("toy", "Toy table", "case=a", "max error", ""),
        ("toy", "Toy table", "case=a", "wall", "ms"),
    ]
    assert all(r.settings == {"quick": True} for r in records)
    r = records[0]
    assert r.machine["cpu_count"] >= 1 and r.versions["python"] and r.versions["numpy"] and r.timestamp
    assert records[0].value == 1.5e-3 and records[1].repeats == 3 and records[1].spread_min <= records[1].value
    md = (tmp_path / "bench.md").read_text()
    assert md.startswith("### Toy table") and f"| a | 1.50e-03 | {records[1].value:.3f} |" in md


def test_timed_keeps_every_run_and_the_last_result():
    from benchmarks.harness import timed

    calls = []
    t = timed(lambda: calls.append(1) or len(calls), repeats=4)
    assert t.repeats == 4 and t.result == 4 and len(calls) == 4
    assert 0 <= t.best_s <= t.median_s <= t.worst_s
    with pytest.raises(ValueError):
        timed(lambda: None, repeats=0)


def test_a_bench_that_changes_global_state_leaves_it_as_it_was(monkeypatch):
    """The registry's safety net: threads, default dtype, numpy error state restored after a bench."""
    torch = pytest.importorskip("torch")
    import numpy as np

    def greedy(*, quick: bool = False):
        torch.set_num_threads(1 if torch.get_num_threads() != 1 else 2)
        torch.set_default_dtype(torch.float64)
        np.seterr(all="ignore")
        return _toy_run(quick=quick)

    bench = _toy_bench(monkeypatch, greedy)
    before = (torch.get_num_threads(), torch.get_default_dtype(), np.geterr())
    run = bench.benchmark_run("toy", quick=True)
    assert (torch.get_num_threads(), torch.get_default_dtype(), np.geterr()) == before
    assert [(r.metric, r.unit) for r in run.records] == [("max error", ""), ("wall", "ms")]

    # the Markdown of a second run equals the first but for its wall time (the table's last column)
    def untimed(md: str) -> list[str]:
        return [re.sub(r"\| [0-9.]+ \|$", "| <t> |", line) for line in md.splitlines()]

    again = bench.run_benchmark("toy")
    assert untimed(again) == untimed(run.markdown) and "| a | 1.50e-03 | <t> |" in untimed(again)


def test_metalens_bench_figure_goes_to_the_figures_folder_or_a_temp_dir(monkeypatch, tmp_path):
    """The full metalens bench draws a figure: never into the package or source tree."""
    import tempfile

    from benchmarks import metalens as mb

    drawn = []
    monkeypatch.setattr(mb, "_grid_table", lambda sec, quick: None)
    monkeypatch.setattr(mb, "_spectral_table", lambda sec, quick: None)
    monkeypatch.setattr(mb, "_fit_table", lambda sec, quick: [])
    monkeypatch.setattr(mb, "plot_fits", lambda fits, path: drawn.append(Path(path)) or Path(path))
    text = mb.bench_metalens(quick=False, figures=tmp_path).markdown
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
    "report": ["report", "designs/default.toml", "--out", "no/such/run_dir"],
    "schema": ["schema", "--out", "designs"],
    "sweep": ["sweep", "no/such/design.toml"],
    "simulate": ["simulate", "example:bikes", "--out", "events.txt"],
    "sizing": ["sizing", "designs/default.toml", "--target", "-1"],
    "rate": ["rate", "designs/default.toml", "--task", "no_such_task"],
    "process-cells": ["process-cells", "--cells", "no_such_cell"],
    "recording": ["recording", "info", "no/such/recording.raw"],
    "information": ["information", "designs/default.toml", "--realisations", "no_such_realisation"],
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
    res = subprocess.run(
        [sys.executable, "-m", "fsdvs_hw.cli", "sweep", "--workers", "many", "x.toml"],
        capture_output=True,
        text=True,
        cwd=PACKAGE.parent,
        check=False,
    )
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
    assert "--workers" in res.stderr
