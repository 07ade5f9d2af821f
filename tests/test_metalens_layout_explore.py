"""The metalens layout as a design point: scored like any realisation, its GDS in the explore output.

Fast: a small lens through :func:`fsdvs_hw.explore.scoring.score` and the report rows (kernel error,
CSF agreement, efficiency from the library, the steps' kernel errors, the photon budget). Slow: the
default design's explore (tasks and emulation off; the default lens, the committed library) writes a
GDS that gdstk reads back with the expected pillar count and that passes KLayout DRC at the design's
rules, and scores.json and the report carry the layout point beside the ideal lens.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import pytest

from fsdvs_hw import reference_kernel
from fsdvs_hw.costs import CostAssumptions, physical_cost
from fsdvs_hw.realise.metalens.drc import drc_available
from fsdvs_hw.realise.metalens.layout import read_gds_pillars
from fsdvs_hw.realise.registry import fit_realisation, get_realisation, realisation_from_dict
from fsdvs_hw.records import Score, ScoredPoint

REPO = Path(__file__).resolve().parents[1]

#: A small lens with a one-wavelength library of low orders (a few seconds in all).
SMALL = {
    "aperture_m": 20e-6,
    "focal_length_m": 60e-6,
    "illuminant": 555e-9,
    "n_wavelengths": 1,
    "n_terms": 1,
    "max_iter": 5,
    "n_starts": 1,
    "library_wavelengths_m": [555e-9],
    "n_radii": 12,
    "fourier_orders": 2,
    "check_orders": 1,
    "progress": False,
}


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    cache = tmp_path_factory.mktemp("cache")
    mp = pytest.MonkeyPatch()
    mp.setenv("FSDVS_HW_CACHE", str(cache))
    try:
        yield fit_realisation("metalens_layout", reference_kernel("dog", 3, pitch_m=2e-6), SMALL)
    finally:
        mp.undo()


def test_the_layout_point_scores_with_its_kernel_error_csf_agreement_and_library_efficiency(small):
    from fsdvs_hw.explore.scoring import score
    from fsdvs_hw.report.tables import score_rows

    target = small.target
    typed = score(small, target=target, csf_methods=("mannos_sakrison_1974",), fit_wall_s=1.0)
    rec = json.loads(json.dumps(typed.to_dict()))
    assert rec["kind"] == "metalens_layout"
    [row] = score_rows([ScoredPoint("k", "metalens_layout", {}, "ok", score=Score.from_dict(rec))])
    assert row["kernel_error"] == pytest.approx(small.layout.error)  # the layout's kernel, not the ideal's
    assert math.isfinite(row["csf_agreement"])
    assert row["cost_ideal_kernel_error"] == pytest.approx(small.ideal.error)
    assert row["cost_library_kernel_error"] == pytest.approx(small.library_step.error)
    eff, lib_t = row["cost_optical_efficiency"], row["cost_library_transmission"]
    assert 0 < eff < min(small.ideal.optical_efficiency) + 1e-9 and 0 < lib_t <= 1
    assert row["cost_pillar_count"] == small.layout_info["pillars"] > 0
    # the photon budget follows the layout's efficiency, from the library
    cost = physical_cost(Score.from_dict(rec), CostAssumptions())
    assert cost.value("photon_snr_change_db") < 0 and cost.value("pillars") == row["cost_pillar_count"]
    assert "meta-atom library" in cost.figures["library_transmission"].source
    again = realisation_from_dict(json.loads(json.dumps(small.to_dict())))
    assert again.kernel_error() == pytest.approx(small.kernel_error())
    assert again.library_step.error == pytest.approx(small.library_step.error)


def test_the_artifacts_hold_the_gds_its_drc_report_and_the_steps(small, tmp_path):
    written = {a.name: a for a in get_realisation("metalens_layout").write_artifacts_of(small, tmp_path)}
    assert set(written) == {"gds", "drc", "meta_atoms", "layout_psf"}
    back = read_gds_pillars(written["gds"].path)
    assert back.pillars == small.layout_info["pillars"]
    report = json.loads(written["drc"].path.read_text())
    assert report["pillars_read_back"] == report["expected_pillars"] == back.pillars
    if drc_available():
        assert report["drc"]["passed"], report["drc"]["message"]
    else:
        assert "not installed" in report["drc"]["message"]


@pytest.mark.slow
def test_explore_on_the_default_design_writes_a_gds_that_reads_back_and_passes_drc(tmp_path):
    from fsdvs_hw.design import parse_design
    from fsdvs_hw.explore.explore import run_exploration

    data = tomllib.loads((REPO / "designs" / "default.toml").read_text())
    assert "metalens_layout" in data["realisations"]["include"]
    data["realisations"]["include"] = ["learned", "metalens", "metalens_layout"]
    data["kernel"]["path"] = str(REPO / "designs" / data["kernel"]["path"])
    data.pop("tasks")
    data["emulation"] = {"enabled": False}
    data["rate"] = {"enabled": False}
    data["run"] = {"workers": 1}
    data["analysis"] = {"csf_methods": ["mannos_sakrison_1974"]}
    design = parse_design(data, source="default.toml (tasks off)")
    rules = design.data["realisations"]["metalens_layout"]
    run_exploration(design, tmp_path, progress=False)
    rows = {r["realisation"]: r for r in json.loads((tmp_path / "scores.json").read_text())["rows"]}
    layout = rows["metalens_layout"]
    assert layout["status"] == "ok" and rows["metalens"]["status"] == "ok"
    for key in ("kernel_error", "csf_agreement", "cost_optical_efficiency", "cost_library_transmission"):
        assert math.isfinite(layout[key]), key
    assert layout["cost_ideal_kernel_error"] == pytest.approx(rows["metalens"]["kernel_error"])
    [gds] = list((tmp_path / "artifacts").rglob("metalens.gds"))
    assert read_gds_pillars(gds).pillars == layout["cost_pillar_count"]
    drc = json.loads((gds.parent / "drc.json").read_text())["drc"]
    if not drc_available():
        pytest.skip("the klayout package is not installed")
    assert drc["ran"] and drc["passed"], drc["message"]
    assert drc["min_width_m"] == rules.get("min_width_m", 70e-9)
    assert drc["min_space_m"] == rules.get("min_space_m", 40e-9)
    assert "Metalens layout: ideal phase" in (tmp_path / "report.html").read_text()


def test_a_differential_pair_on_a_hexagonal_lattice_is_two_lenses_in_one_gds(tmp_path, small):
    """(``small`` keeps its cache folder in ``FSDVS_HW_CACHE`` for this module.)"""
    options = {
        **SMALL,
        "aperture_m": 30e-6,
        "focal_length_m": 90e-6,
        "n_terms": 2,
        "max_iter": 10,
        "n_starts": 2,
        "strategy": "differential",
        "lattice": "hexagonal",
        "drc": False,
    }
    d = fit_realisation("metalens_layout", reference_kernel("dog", 5, pitch_m=2e-6), options)
    per_lens = d.layout_info["sites_per_lens"]
    assert len(per_lens) == 2 and per_lens[0] == per_lens[1] and d.layout_info["pillars"] == sum(per_lens)
    assert len(d.layout.gains) == 2 and d.layout.strategy == "differential"
    written = {a.name: a for a in get_realisation("metalens_layout").write_artifacts_of(d, tmp_path)}
    assert read_gds_pillars(written["gds"].path).pillars == sum(per_lens)
    assert json.loads(written["drc"].path.read_text())["drc"] == {"ran": False, "message": "DRC off (drc = false)"}


def test_the_report_section_shows_each_steps_loss_beside_the_ideal_lens():
    from fsdvs_hw.report.metalens_layout_section import LAYOUT_STEP_HEADERS, metalens_layout_section

    rows = [
        {"realisation": "metalens", "status": "ok", "kernel_error": 0.23, "csf_agreement": 0.41,
         "weighted_loss_text": "0.021 [0.012, 0.030]"},
        {"realisation": "metalens_layout", "status": "ok", "kernel_error": 0.25, "csf_agreement": 0.40,
         "weighted_loss_text": "0.034 [0.020, 0.047]", "cost_ideal_kernel_error": 0.23,
         "cost_library_kernel_error": 0.24, "cost_optical_efficiency": 0.6, "cost_library_transmission": 0.92,
         "cost_pillar_count": 87253, "cost_radius_levels": 39},
    ]  # fmt: skip
    html = str(metalens_layout_section(rows, "weighted_loss"))
    cells = [c.split("</td>")[0] for c in html.split("<td>")[1:]]
    width = len(LAYOUT_STEP_HEADERS)
    ideal, library, layout = (cells[i * width : (i + 1) * width] for i in range(3))
    assert ideal[1:5] == ["ideal phase", "0.230", "0.410", "0.021 [0.012, 0.030]"]
    assert library[1:3] == ["library", "0.240"] and library[4] == "—"
    assert layout[1:] == ["layout", "0.250", "0.400", "0.034 [0.020, 0.047]", "0.600", "0.920", "87253", "39"]
    assert metalens_layout_section([r for r in rows if r["realisation"] == "metalens"]) == ""
