"""Report: score tables, Pareto marking, and the self-contained HTML with embedded figures."""

from __future__ import annotations

import base64
import csv
import dataclasses
import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.design import parse_design
from fsdvs_hw.kernels import Kernel, reference_kernel
from fsdvs_hw.realise.base import kernel_error
from fsdvs_hw.records import ScoredPoint
from fsdvs_hw.report.tables import (
    accuracy_axis,
    headline_cost,
    kind_cost,
    pareto_front,
    score_rows,
    uncertain_pareto_front,
    verdict_markdown,
    verdict_rows,
)


def test_pareto_front_by_hand():
    # minimise both: (1,3) (2,2) (3,1) are a front; (3,3) is dominated by (2,2); NaN never optimal
    pts = [(1, 3), (2, 2), (3, 1), (3, 3), (math.nan, 0), (2, 2)]
    assert pareto_front(pts) == [True, True, True, False, False, True]  # equal points do not dominate each other
    assert pareto_front([(0, 0, 0), (0, 0, 1)]) == [True, False]


def test_headline_cost_is_the_kinds_declared_item_then_the_first_item():
    c = {"adders": {"value": 57, "unit": "count"}, "area_m2": {"value": 2e-9, "unit": "m^2"}}
    assert headline_cost(c, "asic") == ("area_m2", 2e-9, "m^2")
    assert (
        headline_cost({"g": {"value": 1e-6, "unit": "S"}, "adders": {"value": 3, "unit": "count"}}, "asic")[0]
        == "adders"
    )
    assert (
        headline_cost({"g": {"value": 1e-6, "unit": "S"}, "tau_wide": {"value": 1e-6, "unit": "s"}}, "mesh")[0]
        == "tau_wide"
    )
    assert headline_cost(
        {"lens_count": {"value": 1, "unit": "count"}, "aperture_diameter": {"value": 1e-4, "unit": "m"}}, "metalens"
    ) == ("aperture_diameter", 1e-4, "m")
    assert headline_cost({"g": {"value": 1e-6, "unit": "S"}}, "asic") == ("g", 1e-6, "S")
    assert headline_cost({"g": {"value": 1e-6, "unit": "S"}}) == ("g", 1e-6, "S")  # no kind: the first item
    assert headline_cost({}, "asic") is None


def test_uncertain_pareto_front_by_hand():
    """Objectives (estimate, low, high) to minimise: dominance only beyond the intervals."""
    exact = lambda v: (v, v, v)  # noqa: E731
    pts = [
        [(0.05, 0.04, 0.06), exact(10)],  # 0: loss clearly > 0, cheap
        [(0.00, -0.01, 0.01), exact(20)],  # 1: no measurable loss, mid cost
        [(0.004, -0.006, 0.014), exact(30)],  # 2: tied with 1 in loss (overlap), dearer: not beyond its CI
        [(0.02, 0.015, 0.025), exact(25)],  # 3: worse than 1 beyond both CIs and dearer -> dominated by 1
        [(0.05, 0.045, 0.055), exact(10)],  # 4: overlaps 0 at the same cost: neither dominates
        [(0.03, -0.04, 0.10), exact(5)],  # 5: huge CI, cheapest: kept, and dominates nothing
        [(math.nan, 0, 0), exact(1)],  # 6: NaN: never optimal, dominates nothing
        [(0.06, 0.058, 0.062), exact(12)],  # 7: worse than 0 beyond CIs, dearer -> dominated by 0
    ]
    assert uncertain_pareto_front(pts) == [True, True, True, False, True, True, False, False]
    # the same set judged by point estimates alone would drop 2 (a tie decided by noise)
    assert not pareto_front([(e, c[0]) for (e, _, _), c in pts if not math.isnan(e)])[2]
    # with exact objectives it is the ordinary front
    plain = [(1, 3), (2, 2), (3, 1), (3, 3)]
    assert uncertain_pareto_front([[exact(a), exact(b)] for a, b in plain]) == pareto_front(plain)
    # a point estimate inside the noise never decides: the lower estimate does not dominate
    assert uncertain_pareto_front([[(0.001, -0.01, 0.012), exact(1)], [(0.002, -0.009, 0.013), exact(1)]]) == [
        True,
        True,
    ]


def test_kind_cost_axes_keep_their_own_units():
    assert kind_cost("asic", {"adders": {"value": 57}, "area_m2": {"value": 2e-9}}) == (
        "cell area",
        pytest.approx(2000.0),
        "µm²",
    )
    assert kind_cost("asic", {"adders": {"value": 57}}) == ("adders", 57.0, "count")
    g = {
        f"g_{d}_{w}": {"value": v}
        for (d, w), v in zip(
            [("lateral", "narrow"), ("vertical", "narrow"), ("lateral", "wide"), ("vertical", "wide")],
            [1e-6, 2e-7, 4e-6, 1e-7],
        )
    }
    assert kind_cost("mesh", g) == ("conductance per pixel", pytest.approx((2e-6 + 2e-7 + 8e-6 + 1e-7) * 1e6), "µS")
    assert kind_cost("metalens", {"aperture_diameter": {"value": 1e-4}}) == ("aperture", pytest.approx(100.0), "µm")
    assert kind_cost("learned", {}) is None


def _ci(est, h, n=1000, seeds=3, conf=0.95):
    lo, hi = est - h, est + h
    text = f"no measurable loss (± {h:.3f})" if lo <= 0 <= hi else f"{est:.3f} [{lo:.3f}, {hi:.3f}]"
    return {
        "estimate": est,
        "low": lo,
        "high": hi,
        "half_width": h,
        "confidence": conf,
        "n_clips": n,
        "n_seeds_reference": seeds,
        "text": text,
    }


def _point(key, realisation, kernel_err, corr, cost=None, losses=None):
    res = {
        "kind": realisation,
        "kernel": reference_kernel("dog", 5).to_dict(),
        "kernel_error": kernel_err,
        "csf": {"mannos_sakrison_1974": {"correlation": corr}, "fitted_scale": {"correlation": corr + 0.05}},
        "cost": cost or {},
        "wall_s": {"fit": 0.1, "analysis": 0.2, "tasks": 0.0},
    }
    params = {f"{realisation}.tag": key} if realisation == "asic" else {}
    p = {"key": key, "realisation": realisation, "params": params, "status": "ok", "result": res, "wall_s": 0.3}
    if losses is not None:
        res["tasks"] = {"status": "ok"}
        p["paired_loss"] = {
            "status": "ok",
            "reference": "L",
            "simulator": {  # L: the learned row
                "detection": _ci(*losses[0]),
                "recognition": _ci(*losses[1]),
                "weighted": _ci(*losses[2]),
                "weights": {"detection": 1.0, "recognition": 1.0},
            },
        }
    return p


def test_score_rows_flatten_losses_with_cis_and_mark_uncertain_fronts():
    add = lambda n: {"adders": {"value": n, "unit": "count"}}  # noqa: E731
    pts = [
        _point("L", "learned", 0.0, 0.9, losses=[(0, 0), (0, 0), (0, 0)]),
        _point("a4", "asic", 0.2, 0.8, add(20), losses=[(0.10, 0.01), (0.2, 0.01), (0.15, 0.008)]),
        _point("a8", "asic", 0.01, 0.9, add(60), losses=[(0.002, 0.006), (0.001, 0.004), (0.0015, 0.004)]),
        _point("a12", "asic", 0.001, 0.9, add(90), losses=[(-0.001, 0.006), (0.0, 0.004), (-0.0005, 0.004)]),
        _point("a3", "asic", 0.3, 0.8, add(120), losses=[(0.03, 0.005), (0.03, 0.005), (0.03, 0.004)]),
        _point(
            "m",
            "mesh",
            0.1,
            0.95,
            {f"g_{d}_{w}": {"value": 1e-6, "unit": "S"} for d in ("lateral", "vertical") for w in ("narrow", "wide")},
            losses=[(0.05, 0.01), (0.05, 0.01), (0.05, 0.007)],
        ),
    ]
    rows = {r["key"]: r for r in score_rows([ScoredPoint.from_dict(p) for p in pts])}
    a8 = rows["a8"]
    for f in (
        "detection_loss",
        "detection_loss_ci95_low",
        "detection_loss_ci95_high",
        "detection_n_clips",
        "detection_n_seeds",
        "recognition_loss",
        "weighted_loss",
        "weighted_loss_ci95_high",
    ):
        assert f in a8, f
    assert a8["detection_loss_ci95_low"] == pytest.approx(-0.004) and a8["detection_n_seeds"] == 3
    assert a8["detection_loss_text"] == "no measurable loss (± 0.006)"
    # within the ASIC kind: a12 ties a8 in loss (overlapping CIs) -> not dominated beyond its CI although
    # dearer; a3 loses more than a8 beyond both CIs and costs more -> dominated; a4 is cheapest
    assert rows["a4"]["pareto"] and rows["a8"]["pareto"] and rows["a12"]["pareto"] and not rows["a3"]["pareto"]
    # across kinds (loss vs fitted agreement; references excluded): the mesh agrees better with the CSF
    assert rows["m"]["pareto_all"] and rows["a8"]["pareto_all"] and not rows["a4"]["pareto_all"]
    assert not rows["L"]["pareto"] and not rows["L"]["pareto_all"]
    verdict = {v["realisation"].replace("asic tag=", ""): v for v in verdict_rows(list(rows.values()))}
    verdict["L"], verdict["m"] = verdict.pop("learned"), verdict.pop("mesh")
    assert verdict["a8"]["detection loss"].startswith("no measurable loss (± 0.006)")
    assert verdict["a4"]["weighted loss"] == "0.150 [0.142, 0.158]"
    assert verdict["a8"]["cost (own unit)"] == "adders 60 count"
    assert verdict["m"]["cost (own unit)"].startswith("conductance per pixel 6 µS")
    assert verdict["L"]["Pareto"] == "reference" and verdict["a3"]["Pareto"] == "dominated"
    assert verdict["L"]["detection loss"] == "0 (the reference)"
    assert (
        verdict["a8"]["MS agreement, fitted scale"] == "0.95"
        and verdict["a8"]["MS agreement, design geometry"] == "0.9"
    )
    md = verdict_markdown(list(rows.values()))
    assert md.splitlines()[0].startswith("| realisation | detection loss | recognition loss | weighted loss |")


def test_a_cost_item_named_like_a_loss_is_not_a_task():
    """The metalens reports its pedestal's price as the cost item ``contrast_loss``; it must not
    become a task column of the verdict table nor the accuracy axis."""
    pedestal = {"contrast_loss": {"value": 0.7, "unit": "fraction"}}
    pts = [
        _point("L", "learned", 0.0, 0.9, losses=[(0, 0), (0, 0), (0, 0)]),
        _point("ml", "metalens", 0.3, 0.5, pedestal, losses=[(0.1, 0.01), (0.2, 0.01), (0.15, 0.01)]),
    ]
    rows = score_rows([ScoredPoint.from_dict(p) for p in pts])
    assert rows[1]["cost_contrast_loss"] == pytest.approx(0.7)
    header = verdict_markdown(rows).splitlines()[0]
    assert "contrast" not in header and header.startswith("| realisation | detection loss | recognition loss |")
    assert accuracy_axis(rows)[0] == "weighted_loss"
    assert (
        accuracy_axis([{k: v for k, v in r.items() if not k.startswith("weighted")} for r in rows])[0]
        == "detection_loss"
    )


def _pngs(html: str) -> dict[str, bytes]:
    """Embedded figures by their <figure id> (fig-kernels -> kernels)."""
    found = re.findall(
        r'<figure id="fig-([a-z]+)"><img alt="[^"]+" width="\d+" height="\d+" '
        r'src="data:image/png;base64,([^"]+)">',
        html,
    )
    return {name: base64.b64decode(b) for name, b in found}


def test_explore_end_to_end_writes_a_self_contained_report(tmp_path, monkeypatch, capsys):
    import fsdvs_hw.realise.registry as registry

    # one realisation whose fit fails: reported as an error with the reason, the others are scored
    def broken_fit(target, **options):
        raise RuntimeError("no such lens")

    monkeypatch.setitem(
        registry._REGISTRY, "metalens", dataclasses.replace(registry.get_realisation("metalens"), fit=broken_fit)
    )
    p = tmp_path / "tiny.toml"
    p.write_text(
        '[realisations]\ninclude = ["learned", "delta", "asic", "metalens"]\n'
        '[realisations.asic]\nbits = 4\n[analysis]\ncsf_methods = ["mannos_sakrison_1974", "barten_1999"]\n'
        "[sensor]\nresolution = [24, 32]\n[emulation]\nn_clips = 1\nn_frames = 4\n[run]\nworkers = 1\n"
    )
    out = tmp_path / "out"
    assert main(["explore", str(p), "--out", str(out), "--no-progress"]) == 1  # a failed point: exit status 1
    printed = capsys.readouterr().out
    assert re.search(r"^\| asic \| .* \| adders \d+ count \| ", printed, re.M)  # the verdict table
    assert re.search(r"^not scored: metalens \(error: RuntimeError: no such lens", printed, re.M)
    html = (out / "report.html").read_text()
    assert 'src="http' not in html and "<script" not in html  # nothing fetched from elsewhere
    imgs = _pngs(html)
    assert set(imgs) == {"kernels", "spectra", "radial", "pareto", "costs", "speed"}
    import matplotlib.image as mpimg

    for name, png in imgs.items():
        assert png[:8] == b"\x89PNG\r\n\x1a\n", name
        img = mpimg.imread(io.BytesIO(png), format="png")
        assert img.shape[0] > 400 and img.shape[1] > 600  # drawn at 2x (FIGURE_DPI) for sharp screens
        assert float(np.std(img[..., :3])) > 0.02, f"{name} figure is blank"
    assert "no such lens" in html and "1 failed" in html
    with (out / "scores.csv").open() as fh:
        rows = {r["point"]: r for r in csv.DictReader(fh)}
    assert set(rows) == {"learned", "delta", "asic", "metalens"}
    assert rows["metalens"]["status"] == "error" and rows["metalens"]["kernel_error"] == ""
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
    # the report rebuilt from the stored scores alone (fsdvs-hw report), nothing rerun: the same numbers and page
    assert main(["report", str(p), "--out", str(out), "--to", str(tmp_path / "again")]) == 0
    again = tmp_path / "again" / "report.html"
    assert (tmp_path / "again" / "scores.csv").read_text() == (out / "scores.csv").read_text()
    stamp = re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC")
    assert stamp.sub("", again.read_text()) == stamp.sub("", (out / "report.html").read_text())
