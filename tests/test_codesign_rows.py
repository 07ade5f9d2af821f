"""The exploration's co-design rows: [codesign] validation, the three rows with CIs,
the recovered fraction's CI, resuming a killed run, and the report section."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.design import load_design, parse_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.report.codesign_section import CODESIGN_HEADERS, codesign_section
from fsdvs_hw.report.report_input import CodesignSummary
from fsdvs_hw.stats import ClipMeans

REPO = Path(__file__).resolve().parents[1]
DESIGNS = REPO / "designs"
NET = "kernels/networks/recognition_with_learned_detection_7x7_s{}.safetensors"


def _raw(**codesign):
    return {
        "design": {"name": "tiny"},
        "kernel": {"source": "file", "path": "kernels/learned_detection_7x7.json"},
        "realisations": {"include": ["learned", "asic"]},
        "tasks": {"checkpoints": {"recognition": [NET.format(0), NET.format(1)]}, "n_test": 8},
        "emulation": {"enabled": False},
        "scoring": {"n_resamples": 200},
        "run": {"workers": 1},
        "codesign": {"enabled": True, "realisations": ["asic"], "seeds": 1, "epochs": 1, "n_train": 32, **codesign},
    }


# --------------------------------------------------------------------------- validation
def test_codesign_is_off_by_default_and_the_shipped_design_turns_it_on():
    assert load_design(DESIGNS / "default.toml").data["codesign"]["enabled"] is False
    d = load_design(DESIGNS / "codesign.toml")
    assert d.data["codesign"]["enabled"] is True
    from fsdvs_hw.explore.codesign import codesign_cells

    assert ("metalens", "recognition") in codesign_cells(d) and ("mesh", "segmentation") in codesign_cells(d)


@pytest.mark.parametrize(
    "codesign, key, words",
    [
        ({"bogus": 1}, "codesign.bogus", "unknown key"),
        ({"epochs": 0}, "codesign.epochs", "[1, 1000]"),
        ({"seeds": 3}, "codesign.seeds", "at most 2"),
        ({"realisations": ["learned"]}, "codesign.realisations[0]", "'mesh', 'asic', 'metalens'"),
        ({"cells": ["asic/detection"]}, "codesign.cells[0]", "realisation/task"),
        ({"cells": ["metalens/recognition"]}, "codesign.cells[0]", "codesign.realisations (asic)"),
        ({"modes": ["zero-shot"]}, "codesign.modes[0]", "'swap', 'finetune', 'codesign'"),
        ({"modes": []}, "codesign.modes", "non-empty"),
        ({"lr_network": 0}, "codesign.lr_network", "(0, 10]"),
        ({"tasks": ["detection"]}, "codesign.tasks[0]", "not a task in tasks.checkpoints"),
        ({"enabled": "yes"}, "codesign.enabled", "boolean"),
    ],
)
def test_bad_codesign_values_name_file_key_value_and_range(codesign, key, words):
    with pytest.raises(InputError) as err:
        parse_design(_raw(**codesign), source="tiny.toml", base_dir=DESIGNS)
    msg = str(err.value)
    assert "tiny.toml" in msg and f"key '{key}'" in msg and words in msg


def test_enabled_codesign_needs_networks_and_the_checkpoint_simulator():
    raw = _raw()
    raw["tasks"] = {"checkpoints": {}}
    raw["codesign"]["realisations"] = ["asic"]
    with pytest.raises(InputError, match="codesign.enabled.*needs trained networks"):
        parse_design(raw, source="t.toml", base_dir=DESIGNS)
    raw = _raw()
    raw["tasks"]["sensor"] = "design"
    with pytest.raises(InputError, match="tasks.sensor.*'checkpoint'"):
        parse_design(raw, source="t.toml", base_dir=DESIGNS)
    raw["codesign"]["enabled"] = False  # a disabled table is only checked for its own values
    assert parse_design(raw, source="t.toml", base_dir=DESIGNS).data["codesign"]["enabled"] is False


# --------------------------------------------------------------------------- recovered fraction
def _arm(values_per_network, n=40):
    """One ClipMeans per network with the given accuracy (first fraction of clips correct)."""
    return [ClipMeans(np.r_[np.ones(round(v * n)), np.zeros(n - round(v * n))]) for v in values_per_network]


def test_recovered_fraction_is_the_share_of_the_swap_loss_won_back_with_a_covering_ci():
    from fsdvs_hw.explore.codesign import recovered_fraction_ci

    ref = _arm([1.0, 0.95, 0.9, 1.0])
    swap = _arm([0.6, 0.55, 0.5, 0.6])  # loss 0.4 in every network
    half = _arm([0.8, 0.75, 0.7, 0.8])  # loss 0.2: half recovered
    r = recovered_fraction_ci(ref, swap, half, n_resamples=500)
    assert r["estimate"] == pytest.approx(0.5, abs=1e-12)
    assert r["low"] <= 0.5 <= r["high"] and r["high"] - r["low"] < 1e-9  # the same share in every network
    full = recovered_fraction_ci(ref, swap, ref, n_resamples=500)
    assert full["estimate"] == pytest.approx(1.0) and full["low"] == pytest.approx(1.0)
    none = recovered_fraction_ci(ref, swap, swap, n_resamples=500)
    assert none["estimate"] == pytest.approx(0.0) and none["high"] == pytest.approx(0.0, abs=1e-12)
    # networks that disagree widen the interval
    mixed = recovered_fraction_ci(ref, swap, _arm([1.0, 0.55, 0.9, 0.6]), n_resamples=500)
    assert mixed["estimate"] == pytest.approx(0.5) and mixed["high"] - mixed["low"] > 0.3
    with pytest.raises(InputError, match="one metric per network"):
        recovered_fraction_ci(ref, swap[:2], half)


def test_one_network_resamples_clips():
    from fsdvs_hw.explore.codesign import recovered_fraction_ci

    r = recovered_fraction_ci(_arm([1.0], 200), _arm([0.5], 200), _arm([0.75], 200), n_resamples=500)
    assert r["resampled"] == "clips" and r["estimate"] == pytest.approx(0.5) and r["low"] < 0.5 < r["high"]


# --------------------------------------------------------------------------- end to end, resumable
def test_three_rows_with_cis_and_a_killed_run_resumes_without_retraining(tmp_path, monkeypatch):
    pytest.importorskip("torch")
    from fsdvs_hw.explore.codesign import run_codesign, write_codesign
    from fsdvs_hw.tasks import learn

    design = parse_design(_raw(), source="tiny.toml", base_dir=DESIGNS)
    trained = []
    real_finetune = learn.finetune_network

    def counting(*a, **kw):
        trained.append("codesign" if kw.get("realisation") is not None else "finetune")
        return real_finetune(*a, **kw)

    monkeypatch.setattr(learn, "finetune_network", counting)
    first = run_codesign(design, tmp_path, progress=False)
    assert sorted(trained) == ["codesign", "finetune"]
    (cell,) = first["cells"]
    assert (cell["realisation"], cell["task"], cell["n_seeds"], cell["n_clips"]) == ("asic", "recognition", 1, 8)
    assert list(cell["rows"]) == ["swap", "finetune", "codesign"]
    for row in cell["rows"].values():
        ci = row["loss"]
        assert ci["low"] <= ci["estimate"] <= ci["high"] and ci["n_clips"] == 8 and row["label"]
    assert "recovered" in cell["rows"]["codesign"] and "gain_over_swap" in cell["rows"]["finetune"]
    for f in ("ms_correlation_initial", "ms_correlation_final"):
        assert len(cell[f]) == 1 and -1 <= cell[f][0] <= 1
    assert cell["kernel_error_fit"] < 0.05  # 8-bit taps of the learned kernel
    units = sorted((tmp_path / "codesign" / "units").glob("*.json"))
    assert len(units) == 4  # reference + three rows
    assert len(list((tmp_path / "codesign" / "networks").glob("*.safetensors"))) == 2

    # a killed run: the co-designed unit never got written; the rerun trains only that one
    cd_unit = next(u for u in units if "_codesign_" in u.name)
    cd_unit.unlink()
    trained.clear()
    second = run_codesign(design, tmp_path, progress=False)
    assert trained == ["codesign"]
    # a complete store: nothing is trained or scored again, and the summary is the same
    trained.clear()
    from fsdvs_hw.explore import paired

    monkeypatch.setattr(paired, "clip_evidence", lambda *a, **k: (_ for _ in ()).throw(AssertionError("rescored")))
    third = run_codesign(design, tmp_path, progress=False)
    assert trained == []
    assert json.dumps(third["cells"]) == json.dumps(second["cells"])  # (NaN-safe: no loss, no recovered share)
    assert json.dumps(second["cells"][0]["rows"]["swap"]) == json.dumps(first["cells"][0]["rows"]["swap"])

    jpath, cpath = write_codesign(third, tmp_path)
    assert json.dumps(json.loads(jpath.read_text())["cells"]) == json.dumps(third["cells"])
    lines = cpath.read_text().splitlines()
    assert len(lines) == 4 and lines[1].startswith("asic,recognition,swap,top1,1,8,")
    html = codesign_section(CodesignSummary.from_dict(third))
    assert all(h in html for h in ("fit then swap", "co-designed", "asic", "recognition"))


def test_a_changed_setting_is_measured_again(tmp_path):
    pytest.importorskip("torch")
    from fsdvs_hw.explore.codesign import run_codesign

    run_codesign(parse_design(_raw(modes=["swap"]), source="t", base_dir=DESIGNS), tmp_path, progress=False)
    run_codesign(
        parse_design(_raw(modes=["swap"]), source="t", base_dir=DESIGNS).with_overrides({"tasks.n_test": 6}),
        tmp_path,
        progress=False,
    )
    names = [u.name for u in (tmp_path / "codesign" / "units").glob("*_swap_*.json")]
    assert len(names) == 2  # n_test is part of a unit's key


# --------------------------------------------------------------------------- the report section
def test_section_lists_every_cell_and_escapes():
    summary = {
        "settings": {"epochs": 2, "n_train": 0},
        "cells": [
            {
                "realisation": "<lens>",
                "task": "recognition",
                "metric_name": "top1",
                "n_seeds": 3,
                "n_clips_per_network": 384,
                "kernel_error_fit_gain_free": 0.2,
                "kernel_error_codesign_gain_free": [0.3],
                "ms_correlation_initial": [0.89],
                "ms_correlation_final": [0.5],
                "verdict": "v",
                "swap_loss_above_zero": True,
                "rows": {
                    m: {
                        "loss": {"estimate": e, "low": e - 0.01, "high": e + 0.01},
                        **({"recovered": {"estimate": 0.5, "low": 0.4, "high": 0.6}} if m != "swap" else {}),
                    }
                    for m, e in (("swap", 0.25), ("finetune", 0.125), ("codesign", 0.125))
                },
            }
        ],
    }
    html = codesign_section(CodesignSummary.from_dict(summary))
    assert "&lt;lens&gt;" in html and "<lens>" not in html
    assert "0.2500 [0.2400, 0.2600]" in html and "50% [40%, 60%]" in html and "3 × 384" in html
    assert "0.890 → 0.500" in html and html.count("<th>") == len(CODESIGN_HEADERS)
    assert "No co-design cell" in codesign_section(CodesignSummary.from_dict({"cells": []}))
    summary["cells"][0]["swap_loss_above_zero"] = False  # no loss: no recovered share is shown
    html = codesign_section(CodesignSummary.from_dict(summary))
    assert "50% [40%, 60%]" not in html and "no loss above 0" in html
