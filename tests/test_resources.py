"""The shipped-data resolver (fsdvs_hw.resources) and how commands find designs.

The wheel itself (data inside the installed package, the main job run from it) is tested in
tests/test_wheel.py; these are the checkout-side checks, fast.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fsdvs_hw.cli.explore import parse_overrides
from fsdvs_hw.design import load_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.resources import DEFAULT_DESIGN, designs_dir, resolve_design, shipped_designs, shipped_path

REPO = Path(__file__).resolve().parents[1]


def test_in_a_checkout_the_designs_folder_is_the_top_level_one():
    assert designs_dir() == (REPO / "designs").resolve()
    assert shipped_path("kernels", "learned_detection_7x7.json").is_file()
    assert DEFAULT_DESIGN in shipped_designs() and "sweep_asic_bits.toml" in shipped_designs()


def test_no_module_finds_data_relative_to_its_own_file():
    """Every reader of shipped data goes through fsdvs_hw.resources (a wheel has no ../designs)."""
    offenders = []
    for path in (REPO / "fsdvs_hw").rglob("*.py"):
        if path.name == "resources.py":  # the resolver (its docstring names the old pattern)
            continue
        text = path.read_text(encoding="utf-8")
        if re.search(r"__file__\)?(\.resolve\(\))?\.parents?\b", text) and "designs" in text:
            offenders.append(str(path.relative_to(REPO)))
    assert offenders == []


def test_resolve_design_prefers_a_users_file_then_shipped_names(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no designs/ here: names fall back to the shipped ones
    assert resolve_design(None) == shipped_path(DEFAULT_DESIGN)
    assert resolve_design("sweep_asic_bits") == shipped_path("sweep_asic_bits.toml")
    assert resolve_design("designs/default.toml") == shipped_path("default.toml")
    own = tmp_path / "default.toml"
    own.write_text('[design]\nname = "mine"\n')
    assert resolve_design("default.toml") == Path("default.toml")  # the user's file wins
    with pytest.raises(InputError, match=r"'nope'.*shipped: .*default\.toml"):
        resolve_design("nope")
    with pytest.raises(InputError, match="not a shipped design"):
        resolve_design("elsewhere/sweep_asic_bits.toml")  # a folder that is not designs/: no fallback


def test_a_user_design_resolves_its_paths_against_its_own_folder(tmp_path, monkeypatch):
    """A design in its own folder, loaded from another working directory, finds its kernel and
    checkpoints next to itself."""
    folder = tmp_path / "project"
    (folder / "k").mkdir(parents=True)
    shutil.copy(shipped_path("kernels", "learned_detection_7x7.json"), folder / "k" / "mine.json")
    net = shipped_path("kernels", "networks", "detection_with_learned_detection_7x7_s0.safetensors")
    shutil.copy(net, folder / "k" / "det.safetensors")
    (folder / "d.toml").write_text(
        '[kernel]\nsource = "file"\npath = "k/mine.json"\n[tasks]\ncheckpoints = { detection = "k/det.safetensors" }\n'
    )
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    design = load_design(Path("..") / "project" / "d.toml")
    assert design.target.taps.shape == (7, 7)
    assert design.checkpoints() == {"detection": [(folder / "k" / "det.safetensors").resolve()]}
    (folder / "d.toml").write_text('[kernel]\nsource = "file"\npath = "../outside.json"\n')
    with pytest.raises(InputError, match="outside the design's folder"):
        load_design(folder / "d.toml")


def test_set_overrides_parse_toml_values():
    got = parse_overrides(
        [
            "asic.bits=6",
            "tasks.n_test={detection=16}",
            'tasks.tracks=["simulator"]',
            "emulation.enabled=false",
            "design.name=quick",
        ]
    )
    assert got == {
        "asic.bits": 6,
        "tasks.n_test": {"detection": 16},
        "tasks.tracks": ["simulator"],
        "emulation.enabled": False,
        "design.name": "quick",
    }
    with pytest.raises(InputError, match="KEY=VALUE"):
        parse_overrides(["asic.bits"])


def test_explore_with_a_bad_override_is_a_one_line_error_before_any_work(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "fsdvs_hw.cli", "explore", "--set", "asic.bits=1", "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**__import__("os").environ, "PYTHONPATH": str(REPO)},
    )
    assert proc.returncode == 2, proc.stderr
    assert "asic.bits" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "o" / "report.html").exists()


def test_shipped_design_files_name_only_shipped_files():
    """Every path in every shipped design exists in the shipped folder (so a wheel is complete)."""
    for name in shipped_designs():
        design = load_design(shipped_path(name))
        for paths in design.checkpoints().values():
            assert paths and all(p.is_file() and designs_dir() in p.parents for p in paths), name
    prov = json.loads(shipped_path("kernels", "learned_detection_7x7.json").read_text())
    assert prov  # a readable kernel file
