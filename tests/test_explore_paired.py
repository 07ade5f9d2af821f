"""Paired per-clip evidence from the shipped networks: it reproduces evaluate_kernel, is paired (same
clips, same noise), gives each training seed its own mismatch pattern, and survives storage."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import load_kernel, reference_kernel

KERNELS = Path(__file__).parents[1] / "designs" / "kernels"
DET = KERNELS / "learned_detection_7x7.safetensors"
REC = KERNELS / "learned_recognition_7x7.safetensors"

pytest.importorskip("torch")


@pytest.mark.parametrize("task, ckpt", [("detection", DET), ("recognition", REC)])
def test_learned_kernel_reproduces_evaluate_kernel(task, ckpt):
    from fsdvs_hw.explore.paired import clip_evidence
    from fsdvs_hw.tasks import evaluate_kernel

    k = load_kernel(KERNELS / f"learned_{task}_7x7.json")
    ref = evaluate_kernel(k, task, ckpt, n_test=128)
    ev = clip_evidence(k, task, ckpt, n_test=128)
    assert ev.value == pytest.approx(ref.value, abs=1e-12)  # the same clips, noise and metric
    assert ev.n_clips == 128 and ev.event_rate == pytest.approx(ref.event_rate, rel=1e-9)


def test_same_kernel_same_evidence_and_each_seed_its_own_mismatch_pattern():
    from fsdvs_hw.explore.paired import clip_evidence

    k = load_kernel(KERNELS / "learned_recognition_7x7.json")
    a = clip_evidence(k, "recognition", REC, n_test=128)
    b = clip_evidence(k, "recognition", REC, n_test=128)
    np.testing.assert_array_equal(a.metric.values, b.metric.values)  # paired: the same noise draws
    c = clip_evidence(k, "recognition", REC, n_test=128, seed_offset=1)
    assert c.sensor_seed == a.sensor_seed + 1
    # another chip: the events differ (fixed-pattern mismatch), the metric stays close
    assert c.event_rate != a.event_rate and abs(c.value - a.value) < 0.1
    # the first n clips do not depend on n (clip i is the same clip for every n_test)
    d = clip_evidence(k, "recognition", REC, n_test=64)
    np.testing.assert_array_equal(d.metric.values, a.metric.values[:64])


def test_evidence_round_trip_and_paired_delta_loss():
    from fsdvs_hw.explore.paired import clip_evidence, decode_evidence, encode_evidence
    from fsdvs_hw.stats import difference_ci

    k = load_kernel(KERNELS / "learned_detection_7x7.json")
    learned = clip_evidence(k, "detection", DET, n_test=128)
    delta = clip_evidence(reference_kernel("delta", 7), "detection", DET, n_test=128)
    back = decode_evidence(encode_evidence(delta.metric))
    w = np.random.default_rng(0).multinomial(128, np.full(128, 1 / 128), size=4)
    np.testing.assert_array_equal(back.weighted(w), delta.metric.weighted(w))
    ci = difference_ci(learned.metric, delta.metric, n_resamples=300)
    assert ci.estimate == pytest.approx(learned.value - delta.value, abs=1e-12)
    assert ci.low <= ci.estimate <= ci.high and ci.n_clips == 128


def test_task_without_per_clip_metric_and_bad_evidence_are_clear_errors():
    from fsdvs_hw.explore.paired import clip_evidence, decode_evidence

    with pytest.raises(InputError, match="unknown"):
        clip_evidence(None, "no_such_task", DET)
    with pytest.raises(InputError, match="n_test"):
        clip_evidence(None, "detection", DET, n_test=1)
    with pytest.raises(InputError, match="not an encoded"):
        decode_evidence("not base64 npz")


def test_explore_writes_loss_cis_for_every_task_and_track(tmp_path, capsys):
    """`explore` on the shipped networks (64 clips, two tasks, both tracks): scores.json and scores.csv
    carry T_loss, its CI, n_clips and n_seeds per task, emu_ on the emulation track; the learned row's
    loss is exactly 0 and the verdict table is printed."""
    import csv
    import json

    from fsdvs_hw.cli import main

    import shutil

    # the kernel and networks beside the design (paths in a design file must stay inside its folder)
    for src in (KERNELS / "learned_detection_7x7.json", DET, REC):
        shutil.copy(src, tmp_path / src.name)
    p = tmp_path / "d.toml"
    p.write_text(
        '[kernel]\nsource = "file"\npath = "learned_detection_7x7.json"\n'
        '[realisations]\ninclude = ["learned", "delta"]\n[analysis]\ncsf_methods = ["mannos_sakrison_1974"]\n'
        "[emulation]\nenabled = false\n"
        f'[tasks]\ncheckpoints = {{ detection = ["{DET.name}"], recognition = "{REC.name}" }}\n'
        "n_test = { detection = 64, recognition = 96 }\nn_test_emulation = 32\n"
        'tracks = ["simulator", "emulation"]\n[scoring]\nn_resamples = 300\n'
        "task_weights = { detection = 3, recognition = 1 }\n[run]\nworkers = 1\n"
    )
    out = tmp_path / "out"
    assert main(["explore", str(p), "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "| realisation | detection loss | recognition loss | weighted loss |" in printed
    assert (
        "losses measured in: detection: 1 network (training seeds 0) trained with the kernel being realised" in printed
    )
    assert "recognition: 1 network (training seeds 0) NOT trained with the kernel being realised" in printed
    rows = {r["realisation"]: r for r in json.loads((out / "scores.json").read_text())["rows"]}
    for prefix, n_det, n_rec in (("", 64, 96), ("emu_", 32, 32)):
        for task, n in (("detection", n_det), ("recognition", n_rec)):
            d = rows["delta"]
            for f in ("loss", "loss_ci95_low", "loss_ci95_high", "n_clips", "n_seeds"):
                assert f"{prefix}{task}_{f}" in d, f"{prefix}{task}_{f}"
            assert d[f"{prefix}{task}_n_clips"] == n and d[f"{prefix}{task}_n_seeds"] == 1
            assert (
                d[f"{prefix}{task}_loss_ci95_low"] <= d[f"{prefix}{task}_loss"] <= d[f"{prefix}{task}_loss_ci95_high"]
            )
            assert rows["learned"][f"{prefix}{task}_loss"] == 0.0
            m = d[f"metric_{task}/{'emulation' if prefix else 'simulator'}"]
            m_ref = rows["learned"][f"metric_{task}/{'emulation' if prefix else 'simulator'}"]
            assert d[f"{prefix}{task}_loss"] == pytest.approx(m_ref - m, abs=1e-12)
    d = rows["delta"]
    assert d["weighted_loss"] == pytest.approx(0.75 * d["detection_loss"] + 0.25 * d["recognition_loss"], abs=1e-12)
    with (out / "scores.csv").open() as fh:
        header = next(csv.reader(fh))
    assert {"detection_loss_ci95_low", "emu_recognition_n_seeds", "weighted_loss_ci95_high"} <= set(header)
    assert "evidence" not in (out / "scores.json").read_text()  # per-clip evidence stays in results.sqlite


def test_stats_benchmark_quick_reports_equality_with_pycocotools():
    import re

    from benchmarks import BENCHMARKS, run_benchmark

    assert BENCHMARKS["stats"] == "benchmarks.stats:bench_stats"
    text = run_benchmark("stats", quick=True)
    row = next(line for line in text.splitlines() if line.startswith("| 256 |"))
    diff = float(re.split(r"\s*\|\s*", row)[3])
    assert diff <= 1e-9  # the weighted accumulate equals pycocotools on resampled sets


def test_each_network_scores_its_own_clips_and_the_losses_are_nested(tmp_path):
    """test_clips = "per_network": network s scores clip set s (another held-out draw of the scene
    family, test seed + s), the record totals the clips, and the paired loss is a nested-design
    interval; "shared" keeps the crossed design."""
    from fsdvs_hw.explore.paired import clip_evidence
    from fsdvs_hw.explore.scoring import paired_losses, task_scores

    nets = sorted((KERNELS / "networks").glob("recognition_with_learned_detection_7x7_s[01].safetensors"))
    assert len(nets) == 2
    k = load_kernel(KERNELS / "learned_detection_7x7.json")
    a = clip_evidence(k, "recognition", nets[0], n_test=64)
    b = clip_evidence(k, "recognition", nets[0], n_test=64, clip_set=1)
    assert b.test_seed == a.test_seed + 1
    assert not np.array_equal(a.metric.values, b.metric.values)  # other clips
    with pytest.raises(InputError, match="clip_set"):
        clip_evidence(k, "recognition", nets[0], n_test=64, clip_set=-1)
    points = []
    for name, kern in (("learned", k), ("delta", reference_kernel("delta", 7))):
        for mode in ("per_network", "shared"):
            rec = task_scores(kern, {"recognition": nets}, n_test=48, test_clips=mode)
            r = rec["recognition"]["simulator"]
            if mode == "per_network":
                assert r["n_clips"] == 96 and r["n_clips_per_network"] == 48 and len(set(r["test_seeds"])) == 2
            else:
                assert r["n_clips"] == 48 and len(set(r["test_seeds"])) == 1
            points.append(
                {
                    "key": f"{name}-{mode}",
                    "realisation": name,
                    "status": "ok",
                    "params": {"mode": mode},
                    "result": {"tasks": rec},
                }
            )
    losses = paired_losses(points, n_resamples=300)
    nested = losses["delta-per_network"]["simulator"]["recognition"]
    crossed = losses["delta-shared"]["simulator"]["recognition"]
    assert nested["clip_design"] == "nested" and nested["n_clips"] == 96 and nested["n_seeds_reference"] == 2
    assert crossed["clip_design"] == "crossed" and crossed["n_clips"] == 48
    # the nested estimate is the mean of the two networks' own-clip differences
    pn = [p for p in points if p["params"]["mode"] == "per_network"]
    per = np.subtract(
        pn[0]["result"]["tasks"]["recognition"]["simulator"]["per_seed"],
        pn[1]["result"]["tasks"]["recognition"]["simulator"]["per_seed"],
    )
    assert nested["estimate"] == pytest.approx(per.mean(), abs=1e-12)
