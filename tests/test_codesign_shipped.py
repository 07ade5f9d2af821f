"""The shipped co-design results (``make codesign``, designs/results/codesign/) are what the code makes
of their own measurements: the summary is recomputed from the shipped per-unit evidence, and the
report section is rebuilt from it, cell by cell."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from fsdvs_hw.design import load_design
from fsdvs_hw.explore.codesign import CODESIGN_FORMAT, summarise_codesign
from fsdvs_hw.report.codesign_section import codesign_section
from fsdvs_hw.report.report_input import CodesignSummary

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "designs" / "results" / "codesign"

pytestmark = pytest.mark.skipif(not (SHIPPED / "codesign.json").is_file(), reason="no shipped co-design results")


@pytest.fixture(scope="module")
def shipped():
    return json.loads((SHIPPED / "codesign.json").read_text())


@pytest.fixture(scope="module")
def units():
    return [json.loads(p.read_text()) for p in sorted((SHIPPED / "units").glob("*.json"))]


def _close(a, b, path=""):
    if isinstance(a, dict):
        assert set(a) == set(b), path
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-9, abs=1e-12), path
    else:
        assert a == b, path


def test_shipped_results_come_from_the_shipped_design(shipped):
    design = load_design(REPO / "designs" / "codesign.toml")
    assert shipped["format"] == CODESIGN_FORMAT and shipped["design"] == design.name
    cd = design.data["codesign"]
    for k in ("epochs", "n_train", "lr_network", "lr_filter", "seeds", "cells"):
        assert shipped["settings"][k] == cd[k], k
    assert {(c["realisation"], c["task"]) for c in shipped["cells"]} == {tuple(c.split("/")) for c in cd["cells"]}
    assert all(c["n_seeds"] == cd["seeds"] for c in shipped["cells"])


def test_the_summary_is_recomputed_from_the_shipped_evidence(shipped, units):
    st = shipped["settings"]
    design = load_design(REPO / "designs" / "codesign.toml")
    sc = design.data["scoring"]
    again = summarise_codesign(
        units, n_resamples=sc["n_resamples"], confidence=sc["confidence"], rng=design.data["run"]["seed"]
    )
    key = lambda c: (c["realisation"], c["task"])
    _close(sorted(again["cells"], key=key), sorted(shipped["cells"], key=key))
    assert st["test_clips"] == "per_network" and all(c["clips"] == "nested in networks" for c in shipped["cells"])


def test_the_report_section_shows_every_cell_with_its_cis(shipped):
    html = codesign_section(CodesignSummary.from_dict(shipped))
    for c in shipped["cells"]:
        for m in ("swap", "finetune", "codesign"):
            loss = c["rows"][m]["loss"]
            assert f"{loss['estimate']:.4f} [{loss['low']:.4f}, {loss['high']:.4f}]" in html
        rec = c["rows"]["codesign"]["recovered"]
        if c["swap_loss_above_zero"]:
            assert f"{rec['estimate']:.0%} [{rec['low']:.0%}, {rec['high']:.0%}]" in html
        assert c["verdict"].replace("'", "&#x27;") in html


def test_every_verdict_follows_from_its_numbers(shipped):
    """A loss whose CI lies above 0 is either recovered by half or said not to be, with the numbers."""
    for c in shipped["cells"]:
        swap, rec = c["rows"]["swap"]["loss"], c["rows"]["codesign"]["recovered"]
        if swap["low"] <= 0:
            assert c["verdict"].startswith("no loss to recover")
        elif not rec["high"] - rec["low"] <= 1.0:
            assert c["verdict"].startswith("unresolved")
        elif rec["low"] >= 0.5:
            assert c["verdict"].startswith("co-design recovers at least half")
        else:
            assert "recovers" in c["verdict"] and f"{rec['estimate']:.0%}" in c["verdict"]


def test_the_explore_report_carries_the_section_before_the_run_conditions(shipped, tmp_path):
    """write_report shows the co-design summary it is handed for a design with [codesign] enabled
    (and only then); the redraw reads OUT/codesign.json for it."""
    import shutil

    from fsdvs_hw.explore.reporting import report_input
    from fsdvs_hw.report.html import write_report
    from fsdvs_hw.report.redraw import write_report_from_scores

    section = codesign_section(CodesignSummary.from_dict(shipped))
    pages = {}
    for name in ("codesign", "default"):
        design = load_design(REPO / "designs" / f"{name}.toml")
        pages[name] = write_report([], report_input(design, codesign=shipped), tmp_path / name).read_text()
    assert section in pages["codesign"]
    assert pages["codesign"].index(section) < pages["codesign"].index("id='conditions'")
    assert section not in pages["default"]  # [codesign] off: a stray codesign.json is not reported
    for name in ("codesign", "default"):
        shutil.copy(SHIPPED / "codesign.json", tmp_path / name / "codesign.json")
        design = load_design(REPO / "designs" / f"{name}.toml")
        redrawn = write_report_from_scores(tmp_path / name, report_input(design), to=tmp_path / f"{name}_redrawn")
        assert (section in redrawn.read_text()) == (name == "codesign")


def test_write_report_shows_the_summary_it_is_handed_and_reads_no_file(tmp_path):
    """The exploration hands its co-design summary to the report in memory: a codesign.json lying in
    the output folder is not read by write_report (only the redraw of a finished run reads it)."""
    from fsdvs_hw.explore.reporting import report_input
    from fsdvs_hw.report.html import write_report

    design = load_design(REPO / "designs" / "codesign.toml")
    (tmp_path / "codesign.json").write_text(json.dumps({"cells": [], "settings": {"epochs": 7}}))
    assert "7 epochs" not in write_report([], report_input(design), tmp_path).read_text()
    handed = report_input(design, codesign={"cells": [], "settings": {"epochs": 7}})
    assert "7 epochs" in write_report([], handed, tmp_path).read_text()
