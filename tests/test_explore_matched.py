"""Matched-rate losses of explored points (fsdvs_hw.explore.matched, the design's ``[rate]``).

A point whose kernel only fires more events (a gain that divides the threshold, in the stand-in
evaluator of test_explore_rate) shows a raw "gain" over the learned kernel that is exactly zero at
matched rate; on the shipped networks, explore with ``[rate] enabled`` writes the event-rate and
matched-rate columns, the references' own comparisons are exactly zero, the curve reproduces the
stored point at the operating threshold, and a rerun reuses every saved curve point.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_explore_rate import _Counter

from fsdvs_hw.explore import paired as paired_mod
from fsdvs_hw.explore import rate as rate_mod
from fsdvs_hw.explore.matched import matched_rate_records, point_rate_curve
from fsdvs_hw.explore.rate import rate_curve
from fsdvs_hw.explore.scoring import task_scores
from fsdvs_hw.kernels import Kernel

ROOT = Path(__file__).parents[1]
KERNELS = ROOT / "designs" / "kernels"
SENSOR = {
    "threshold_on": 0.2,
    "threshold_off": 0.2,
    "threshold_sigma": 0.03,
    "placement": "pre_log",
    "positivity": "pedestal",
}


def test_a_point_that_doubles_the_rate_loses_its_raw_gain_at_matched_rate(monkeypatch):
    counter = _Counter()
    monkeypatch.setattr(paired_mod, "clip_evidence", counter)
    monkeypatch.setattr(rate_mod, "clip_evidence", counter)
    ckpts = sorted((KERNELS / "networks").glob("recognition_with_learned_detection_7x7_s*.safetensors"))[:4]
    # the stand-in's gain divides the threshold: learned 1.25, the point 2.5 (t_eff 0.08 vs 0.16)
    kernels = {
        "learned": Kernel(np.array([[1.25]]), name="learned"),
        "delta": Kernel(np.array([[1.0]]), name="delta"),
        "double": Kernel(np.array([[2.5]]), name="double"),
    }
    points = [
        {
            "key": n,
            "realisation": n,
            "status": "ok",
            "params": {},
            "result": {"tasks": task_scores(k, {"recognition": ckpts}, n_test=64, design_sensor=SENSOR)},
        }
        for n, k in kernels.items()
    ]
    rate = {p["key"]: p["result"]["tasks"]["recognition"]["simulator"]["event_rate_per_s"]["mean"] for p in points}
    assert rate["double"] >= 2 * rate["learned"]  # the point fires twice the events at the same threshold
    curves = {
        "{}": {
            "recognition": {
                "learned": rate_curve(
                    kernels["learned"],
                    "recognition",
                    ckpts,
                    (0.1, 0.15, 0.2, 0.3),
                    n_test=64,
                    design_sensor=SENSOR,
                    label="learned",
                ),
                "delta": rate_curve(
                    kernels["delta"],
                    "recognition",
                    ckpts,
                    (0.05, 0.08, 0.1, 0.2),
                    n_test=64,
                    design_sensor=SENSOR,
                    label="delta",
                ),
            }
        }
    }
    recs = matched_rate_records(points, curves, n_resamples=400)
    dbl = recs["double"]["recognition"]
    loss = dbl["loss_at_matched_rate"]
    assert loss["status"] == "ok" and loss["n_networks"] == 4 and loss["n_clips"] == 4 * 64
    assert loss["raw_high"] < 0  # raw: it "beats" the learned kernel ...
    assert abs(loss["estimate"]) < 1e-12 < -loss["raw_estimate"]  # ... only by firing more: 0 at equal rate
    assert loss["matched_threshold"] == pytest.approx(0.1, abs=1e-9)  # learned at 0.1 has the point's t_eff
    assert loss["low"] <= 0 <= loss["high"]
    gain = dbl["gain_over_plain_dvs_at_matched_rate"]
    assert gain["status"] == "ok" and abs(gain["estimate"]) < 1e-12 < gain["raw_estimate"]
    assert gain["matched_threshold"] == pytest.approx(0.08, abs=1e-9)
    # each reference against its own curve: exactly nothing, and it carries its curve for the figure
    own = recs["learned"]["recognition"]
    assert own["loss_at_matched_rate"]["estimate"] == 0.0 and own["loss_at_matched_rate"]["raw_estimate"] == 0.0
    assert [r["threshold"] for r in own["curve"]] == [0.1, 0.15, 0.2, 0.3]
    assert recs["delta"]["recognition"]["gain_over_plain_dvs_at_matched_rate"]["estimate"] == 0.0


def test_a_point_without_per_clip_rates_says_so():
    assert "rerun" in point_rate_curve(
        {
            "key": "k",
            "realisation": "mesh",
            "result": {"tasks": {"recognition": {"simulator": {"status": "ok", "metric": 0.5, "evidence": ["x"]}}}},
        },
        "recognition",
    )
    assert "ON ≠ OFF" in point_rate_curve(
        {
            "key": "k",
            "realisation": "mesh",
            "result": {
                "tasks": {
                    "recognition": {
                        "simulator": {
                            "status": "ok",
                            "metric": 0.5,
                            "evidence": ["x"],
                            "clip_event_rates": [[1.0]],
                            "sensor": {"threshold_on": 0.2, "threshold_off": 0.3},
                        }
                    }
                }
            },
        },
        "recognition",
    )


def test_explore_with_rate_writes_matched_columns_and_resumes(tmp_path, monkeypatch):
    """Shipped recognition networks (2, 32 clips each): the learned kernel's curve point at 0.2 is
    the explored learned point itself; columns and statuses in scores.json/csv; a rerun reuses it all."""
    pytest.importorskip("torch")
    from fsdvs_hw.cli import main

    nets = sorted((KERNELS / "networks").glob("recognition_with_learned_detection_7x7_s[01].safetensors"))
    # the design in a sub-folder, named relative to the working folder (as `make demo` runs designs/default.toml)
    (tmp_path / "sub").mkdir()
    for src in (KERNELS / "learned_detection_7x7.json", *nets):
        shutil.copy(src, tmp_path / "sub" / src.name)
    monkeypatch.chdir(tmp_path)
    design = Path("sub") / "d.toml"
    design.write_text(
        '[kernel]\nsource = "file"\npath = "learned_detection_7x7.json"\n'
        '[realisations]\ninclude = ["learned", "delta"]\n[analysis]\ncsf_methods = ["mannos_sakrison_1974"]\n'
        "[emulation]\nenabled = false\n"
        f"[tasks]\ncheckpoints = {{ recognition = {json.dumps([n.name for n in nets])} }}\n"
        "n_test = 32\n[scoring]\nn_resamples = 200\n"
        "[rate]\nenabled = true\nthresholds = [0.1, 0.3, 0.45]\n[run]\nworkers = 1\n"
    )
    out = Path("out")
    assert main(["explore", str(design), "--out", str(out), "--no-progress"]) == 0
    blob = json.loads((out / "scores.json").read_text())
    rows = {r["realisation"]: r for r in blob["rows"]}
    learned, delta = rows["learned"], rows["delta"]
    for r in (learned, delta):
        assert r["matched_rate_status"] == "ok"
        lo, mean, hi = (r[f"recognition_event_rate_eps_per_px{s}"] for s in ("_ci95_low", "", "_ci95_high"))
        assert 0 < lo <= mean <= hi
    assert learned["recognition_loss_at_matched_rate"] == 0.0
    assert delta["recognition_gain_over_plain_dvs_at_matched_rate"] == 0.0
    # delta's loss at its own rate: the learned kernel fires more at 0.2, so it is read at a higher threshold
    assert delta["recognition_loss_at_matched_rate_status"] == "ok"
    assert delta["recognition_loss_at_matched_rate_threshold"] > 0.2
    assert (
        delta["recognition_loss_at_matched_rate_ci95_low"]
        <= delta["recognition_loss_at_matched_rate"]
        <= delta["recognition_loss_at_matched_rate_ci95_high"]
    )
    # the learned curve holds the explored point at 0.2 (same clips, noise draws: same metric and rate)
    pts = {p["realisation"]: p for p in blob["points"]}
    curve = {r["threshold"]: r for r in pts["learned"]["matched_rate"]["recognition"]["curve"]}
    assert sorted(curve) == [0.1, 0.2, 0.3, 0.45]
    assert curve[0.2]["metric"] == pytest.approx(learned["metric_recognition/simulator"], abs=1e-12)
    assert curve[0.2]["rate"] == pytest.approx(learned["recognition_event_rate_eps_per_px"], rel=1e-12)
    rates = [curve[t]["rate"] for t in sorted(curve)]
    assert np.all(np.diff(rates) < 0)  # fewer events at higher thresholds
    header = (out / "scores.csv").read_text().splitlines()[0].split(",")
    assert {
        "recognition_loss_at_matched_rate",
        "recognition_gain_over_plain_dvs_at_matched_rate_ci95_high",
        "recognition_event_rate_eps_per_px",
    } <= set(header)
    assert "clip_event_rates" not in (out / "scores.json").read_text()
    report = (out / "report.html").read_text()
    assert "id='fig-matched-rate'" in report.replace('"', "'") and "alt=" in report
    assert "<b>recognition</b>: at equal event rate" in report  # the one sentence per task
    # a rerun computes nothing again: points from the store, curve points from out/rate_curves
    saved = sorted(p.name for p in (out / "rate_curves").rglob("*.json"))
    assert len(saved) == 2 * 3

    def fail(*a, **k):
        raise AssertionError("recomputed a stored curve point")

    monkeypatch.setattr(rate_mod, "clip_evidence", fail)
    assert main(["explore", str(design), "--out", str(out), "--no-progress"]) == 0
    again = {r["realisation"]: r for r in json.loads((out / "scores.json").read_text())["rows"]}
    assert again["delta"]["recognition_loss_at_matched_rate"] == delta["recognition_loss_at_matched_rate"]


@pytest.mark.slow
def test_retrained_curves_are_paired_across_thresholds_and_resume(tmp_path, monkeypatch):
    """The retrained protocol, tiny (recognition, 2 seeds, 1+1 epochs, 64 training clips): a network per
    threshold and seed, the same clip sets and noise draws at every threshold (so the matched-rate
    comparison pairs them), fewer events at a higher threshold, and a rerun trains nothing."""
    pytest.importorskip("torch")
    from fsdvs_hw.explore.rate import matched_rate_difference
    from fsdvs_hw.kernels import load_kernel
    from fsdvs_hw.studies import rate_retrained
    from fsdvs_hw.tasks.learn import TrainingSettings

    tiny = dict(n_train=64, n_test=16, settings=TrainingSettings(epochs_frozen=1, epochs_joint=1, width=4))
    learned = load_kernel(KERNELS / "learned_detection_7x7.json")
    wo = rate_retrained.retrained_rate_curve(None, "recognition", (0.1, 0.2), (0, 1), tmp_path, label="w/o", **tiny)
    ln = rate_retrained.retrained_rate_curve(
        learned, "recognition", (0.2, 0.45), (0, 1), tmp_path, label="learned", **tiny
    )
    assert sorted(p.name for p in (tmp_path / "networks" / "n_train64").glob("*.safetensors")) == [
        "learned_t0p2_s0.safetensors",
        "learned_t0p2_s1.safetensors",
        "learned_t0p45_s0.safetensors",
        "learned_t0p45_s1.safetensors",
        "w_o_t0p1_s0.safetensors",
        "w_o_t0p1_s1.safetensors",
        "w_o_t0p2_s0.safetensors",
        "w_o_t0p2_s1.safetensors",
    ]
    for c in (wo, ln):
        assert {(p.test_seeds, p.sensor_seeds) for p in c.points} == {(c.points[0].test_seeds, (0, 1))}
        assert c.points[0].rate > c.points[1].rate > 0
    d = matched_rate_difference(wo, ln, 0.2, n_resamples=200)
    assert d.n_networks == 2 and d.n_clips == 32 and d.reference_rate == ln.point(0.2).rate
    assert d.ok == (min(wo.point(0.1).rate, wo.point(0.2).rate) <= d.reference_rate <= wo.point(0.1).rate)

    def no_training(*a, **k):
        raise AssertionError("retrained a stored network")

    monkeypatch.setattr("fsdvs_hw.tasks.learn.learn_kernel", no_training)
    monkeypatch.setattr(rate_retrained, "clip_evidence", no_training)
    again = rate_retrained.retrained_rate_curve(None, "recognition", (0.1, 0.2), (0, 1), tmp_path, label="w/o", **tiny)
    assert [p.metric for p in again.points] == [p.metric for p in wo.points]


@pytest.mark.parametrize(
    "args, named",
    [
        (["--protocol", "retrained", "--illuminance-lux", "1"], "--illuminance-lux"),
        (["--zero-shot"], "--zero-shot"),
    ],
)
def test_rate_options_that_a_protocol_would_ignore_are_refused(args, named, tmp_path, capsys):
    """An option the chosen protocol does not use is an error naming it, before any work (not silently dropped)."""
    from fsdvs_hw.cli import main

    assert main(["rate", str(ROOT / "designs" / "default.toml"), "--out", str(tmp_path / "o"), *args]) == 2
    assert named in capsys.readouterr().err
    assert not any((tmp_path / "o").rglob("*.json"))
