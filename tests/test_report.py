"""Report: score tables, Pareto marking, and the self-contained HTML with embedded figures."""

from __future__ import annotations

import base64
import csv
import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.explore.design import parse_design
from fsdvs_hw.kernels import Kernel
from fsdvs_hw.realise.base import kernel_error
from fsdvs_hw.report.tables import headline_cost, pareto_front, score_rows


def test_pareto_front_by_hand():
    # minimise both: (1,3) (2,2) (3,1) are a front; (3,3) is dominated by (2,2); NaN never optimal
    pts = [(1, 3), (2, 2), (3, 1), (3, 3), (math.nan, 0), (2, 2)]
    assert pareto_front(pts) == [True, True, True, False, False, True]  # equal points do not dominate each other
    assert pareto_front([(0, 0, 0), (0, 0, 1)]) == [True, False]


def test_headline_cost_prefers_area_then_adders_then_the_first_item():
    c = {"adders": {"value": 57, "unit": "count"}, "area_m2": {"value": 2e-9, "unit": "m^2"}}
    assert headline_cost(c) == ("area_m2", 2e-9, "m^2")
    assert headline_cost({"g": {"value": 1e-6, "unit": "S"}, "adders": {"value": 3, "unit": "count"}})[0] == "adders"
    assert headline_cost({"g": {"value": 1e-6, "unit": "S"}}) == ("g", 1e-6, "S")
    assert headline_cost({}) is None


def _point(key, realisation, kernel_err, corr, cost=None, metric=None):
    res = {"kernel_error": kernel_err, "csf": {"mannos_sakrison_1974": {"correlation": corr}},
           "cost": cost or {}, "wall_s": {"fit": 0.1, "analysis": 0.2, "tasks": 0.0}}
    if metric is not None:
        res["tasks"] = {"status": "ok", "detection": {"simulator": {"metric": metric}}}
    return {"key": key, "realisation": realisation, "params": {}, "status": "ok", "result": res, "wall_s": 0.3}


def test_score_rows_flatten_losses_and_mark_pareto_within_a_kind():
    pts = [
        _point("L", "learned", 0.0, 0.9, metric=0.50),
        _point("a4", "asic", 0.2, 0.8, {"adders": {"value": 20, "unit": "count"}}, metric=0.40),
        _point("a8", "asic", 0.01, 0.9, {"adders": {"value": 60, "unit": "count"}}, metric=0.49),
        _point("a8bad", "asic", 0.3, 0.7, {"adders": {"value": 80, "unit": "count"}}, metric=0.30),
    ]
    rows = {r["key"]: r for r in score_rows(pts)}
    assert rows["a4"]["loss_detection/simulator"] == pytest.approx(0.10)
    assert rows["a8"]["loss_detection/simulator"] == pytest.approx(0.01)
    assert rows["a4"]["headline_cost_value"] == 20
    assert rows["a4"]["pareto"] and rows["a8"]["pareto"] and not rows["a8bad"]["pareto"]


def _pngs(html: str) -> dict[str, bytes]:
    found = re.findall(r'<img alt="([^"]+)" src="data:image/png;base64,([^"]+)"', html)
    return {alt: base64.b64decode(b) for alt, b in found}


def test_explore_end_to_end_writes_a_self_contained_report(tmp_path, monkeypatch, capsys):
    pytest.importorskip("fsdvs_hw.realise.asic")
    from fsdvs_hw.explore import design as design_mod

    # one realisation whose module is missing: reported as skipped, with the reason
    monkeypatch.setitem(design_mod.REALISATION_FITTERS, "metalens", "fsdvs_hw.realise.not_here:fit_metalens")
    p = tmp_path / "tiny.toml"
    p.write_text('[realisations]\ninclude = ["learned", "delta", "asic", "metalens"]\n'
                 '[realisations.asic]\nbits = 4\n[analysis]\ncsf_methods = ["mannos_sakrison_1974", "barten_1999"]\n'
                 '[sensor]\nresolution = [24, 32]\n[emulation]\nn_clips = 1\nn_frames = 4\n[run]\nworkers = 1\n')
    out = tmp_path / "out"
    assert main(["explore", str(p), "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert re.search(r"^\| asic \| ok \| 0\.\d+ \|", printed, re.M)  # the Markdown summary
    assert re.search(r"^\| metalens \| skipped \|", printed, re.M)
    html = (out / "report.html").read_text()
    assert "src=\"http" not in html and "<script" not in html  # nothing fetched from elsewhere
    imgs = _pngs(html)
    assert set(imgs) == {"kernels", "spectra", "radial", "pareto", "speed"}
    import matplotlib.image as mpimg

    for name, png in imgs.items():
        assert png[:8] == b"\x89PNG\r\n\x1a\n", name
        img = mpimg.imread(io.BytesIO(png), format="png")
        assert img.shape[0] > 200 and img.shape[1] > 300
        assert float(np.std(img[..., :3])) > 0.02, f"{name} figure is blank"
    assert "not_here" in html and "skipped" in html
    with (out / "scores.csv").open() as fh:
        rows = {r["point"]: r for r in csv.DictReader(fh)}
    assert set(rows) == {"learned", "delta", "asic", "metalens"}
    assert rows["metalens"]["status"] == "skipped" and rows["metalens"]["kernel_error"] == ""
    data = json.loads((out / "scores.json").read_text())
    asic = next(pt for pt in data["points"] if pt["realisation"] == "asic")
    realised = Kernel.from_dict(asic["result"]["kernel"])
    target = parse_design({}).target
    assert float(rows["asic"]["kernel_error"]) == pytest.approx(kernel_error(realised, target), rel=1e-12)
    assert 0 < float(rows["asic"]["kernel_error"]) < 0.5  # 4-bit taps: close, not exact
    assert float(rows["learned"]["kernel_error"]) == 0.0
    # emulation track scored for every realisation: events recaptured, frames correlated
    for name in ("learned", "delta", "asic"):
        assert float(rows[name]["emu_event_ratio"]) > 0 and -1 <= float(rows[name]["emu_signed_correlation"]) <= 1
    assert float(rows["delta"]["emu_signed_correlation"]) > 0.5
    assert int(float(rows["asic"]["cost_adders"])) == asic["result"]["cost"]["adders"]["value"]
    # rerun: nothing recomputed
    assert main(["explore", str(p), "--out", str(out), "--no-progress"]) == 0
    from fsdvs_hw.explore.store import ResultsStore

    with ResultsStore(out / "results.sqlite") as s:
        assert sorted(r["realisation"] for r in s.rows()) == ["asic", "delta", "learned", "metalens"]
