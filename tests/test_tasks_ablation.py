"""Ablation driver and kernel-shape descriptors (tiny settings)."""

from __future__ import annotations

import json

import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.tasks.ablation import ablation_jobs, ablation_markdown, job_key, kernel_shape


def test_kernel_shape_of_reference_kernels():
    dog = kernel_shape(reference_kernel("dog", 7, w_surround=1.0))
    assert dog["centre_surround"] and dog["centre"] > 0 and dog["surround_sum"] < 0
    assert dog["peak_frequency_cpp"] > 0.05 and abs(dog["dc_gain"]) < 1e-9
    assert -1.0 <= dog["ms_correlation"] <= 1.0
    gauss = kernel_shape(reference_kernel("gaussian", 7, sigma_px=1.0))
    assert not gauss["centre_surround"] and gauss["peak_frequency_cpp"] == 0.0
    delta = kernel_shape(reference_kernel("delta", 7))
    assert not delta["centre_surround"] and delta["surround_sum"] == 0.0


TINY = {"epochs_frozen": 1, "epochs_joint": 1, "width": 8}


def test_tiny_ablation_table_resumes_through_the_sweep_store(tmp_path):
    from fsdvs_hw.explore.store import ResultsStore
    from fsdvs_hw.studies.kernel_size_ablation import ablation_points, run_ablation

    jobs = ablation_jobs(["recognition"], sizes=[1, 3], seeds=[0, 1], n_train=16, n_test=24, settings=TINY)
    points = ablation_points(jobs, tmp_path / "pred")
    store = tmp_path / "runs.sqlite"
    # a run killed after two trainings: the store holds those two
    first = run_ablation(points[:2], store, progress=False)
    assert len(first) == 2
    with ResultsStore(store) as st:
        assert st.done() == {p.key for p in points[:2]}
    # the rerun trains only the other two and returns all four records
    recs = run_ablation(points, store, progress=False)
    assert sorted((r["size"], r["seed"]) for r in recs) == [(1, 0), (1, 1), (3, 0), (3, 1)]
    assert [r["key"] for r in recs[:2]] == [r["key"] for r in first]
    assert all((tmp_path / "pred" / r["predictions"]).is_file() for r in recs)
    assert all("shape" in r and r["kernel_change_l1"] > 0 for r in recs if r["size"] == 3)
    table = ablation_markdown(recs, tmp_path / "pred", n_resamples=200)
    assert "| w/o |" in table and "| 3×3 |" in table and "2 seeds × 24 test clips" in table
    row = next(line for line in table.splitlines() if line.startswith("| 3×3 |"))
    lo, hi = (float(x) for x in row.split("[")[1].split("]")[0].split(","))
    assert lo <= hi  # the gain's 95 % CI
    # without prediction files the gain has no CI
    assert "[" not in next(line for line in ablation_markdown(recs).splitlines() if line.startswith("| 3×3 |"))


def test_cli_rebuilds_the_tables_from_the_store(tmp_path, capsys):
    out = tmp_path / "abl"
    args = [
        "ablation",
        "--tasks",
        "recognition",
        "--sizes",
        "1",
        "3",
        "--seeds",
        "0",
        "--n-train",
        "16",
        "--n-test",
        "16",
        "--epochs-frozen",
        "1",
        "--epochs-joint",
        "1",
        "--out",
        str(out),
        "--no-progress",
    ]
    assert main(args) == 0
    first = (out / "ablation.md").read_text()
    assert main(args + ["--from-store"]) == 0
    assert (out / "ablation.md").read_text().split("Measured")[0] == first.split("Measured")[0]
    assert json.loads((out / "ablation.json").read_text())["records"][0]["task"] == "recognition"


def test_job_keys_ignore_where_results_go():
    a = ablation_jobs(["recognition"], [3], [0])[0]
    assert job_key(a) == job_key({**a, "out": "x", "pred_dir": "y"}) != job_key({**a, "seed": 1})


def test_ablation_bad_input(capsys):
    with pytest.raises(InputError, match="odd"):
        ablation_jobs(["recognition"], sizes=[2], seeds=[0])
    with pytest.raises(InputError, match="unknown"):
        ablation_jobs(["tracking"], sizes=[3], seeds=[0])
    with pytest.raises(InputError, match="seed"):
        ablation_jobs(["recognition"], sizes=[3], seeds=[])
    assert main(["ablation", "--transfer-only"]) != 0  # the CLI reports the InputError and fails
    assert "--transfer-only needs --transfer" in capsys.readouterr().err


def test_bootstrap_interval_matches_binomial_theory():
    import torch

    from benchmarks.tasks import bootstrap_interval
    from fsdvs_hw.tasks.evaluators import get_evaluator

    ev = get_evaluator("recognition")
    n = 400
    target = {"motion": torch.arange(n) % 2}
    perfect = {"logits": torch.nn.functional.one_hot(target["motion"], 6).float()}
    assert bootstrap_interval(ev, perfect, target, n_boot=50) == (1.0, 1.0)
    const = {"logits": torch.nn.functional.one_hot(torch.zeros(n, dtype=torch.long), 6).float()}
    lo, hi = bootstrap_interval(ev, const, target, n_boot=400, seed=1)
    # accuracy 0.5 on 400 clips: binomial 95 % half-width 1.96 * sqrt(0.25 / 400) = 0.049
    assert lo < 0.5 < hi and 0.035 < (hi - lo) / 2 < 0.065


def test_ablation_study_options_reach_the_jobs_and_every_table_is_written(tmp_path, monkeypatch):
    """run_ablation_study (what `fsdvs-hw ablation` calls): the typed options reach the jobs, and the
    transfer and frozen-kernel tables both end up in ablation.md (training replaced by canned records)."""
    from fsdvs_hw.studies import kernel_size_ablation as ab
    from fsdvs_hw.tasks import ablation as tab

    kernel = tmp_path / "k.json"
    reference_kernel("dog", 7).save(kernel)
    seen = []

    def fake_collect(points, store, exe, from_store):
        seen.append((sorted(p.job["kind"] + " " + p.job["task"] for p in points), exe, from_store))
        return [
            {
                "kind": p.job["kind"],
                "task": p.job["task"],
                "seed": p.job["seed"],
                "metrics": {"map": 0.5, "top1": 0.25, "miou": 0.75},
            }
            for p in points
        ]

    monkeypatch.setattr(ab, "_collect", fake_collect)
    monkeypatch.setattr(ab, "annotate_shipped", lambda records, pred_dir: [])
    monkeypatch.setattr(tab, "transfer_markdown", lambda records, stem, pred_dir: f"TRANSFER {stem} {len(records)}\n")
    opts = ab.AblationOptions(
        seeds=(0,),
        transfer=str(kernel),
        frozen_tasks=("recognition",),
        transfer_only=True,
        workers=2,
        progress=False,
        out=tmp_path / "out",
        command="fsdvs-hw ablation --test",
    )
    study = ab.run_ablation_study(opts)
    assert seen == [
        (
            ["frozen recognition", "frozen segmentation", "zero_shot segmentation"],
            {"workers": 2, "scheduler": None, "progress": False},
            False,
        )
    ]
    text = study.markdown
    assert (
        "TRANSFER k 3" in text
        and "networks trained with k frozen" in text
        and "| recognition | 0 | top1 | 25.0 |" in text
    )
    assert "`fsdvs-hw ablation --test`" in text
    assert study.markdown_path.read_text() == text
    assert json.loads(study.json_path.read_text())["transfer"][0]["task"] in ("recognition", "segmentation")
    with pytest.raises(InputError, match="--workers"):
        ab.run_ablation_study(ab.AblationOptions(workers=0, out=tmp_path / "o2"))
