"""Ablation driver and kernel-shape descriptors (tiny settings)."""

from __future__ import annotations

import json

import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.tasks.ablation import ablation_markdown, kernel_shape, run_ablation


def test_kernel_shape_of_reference_kernels():
    dog = kernel_shape(reference_kernel("dog", 7, w_surround=1.0))
    assert dog["centre_surround"] and dog["centre"] > 0 and dog["surround_sum"] < 0
    assert dog["peak_frequency_cpp"] > 0.05 and abs(dog["dc_gain"]) < 1e-9
    assert -1.0 <= dog["ms_correlation"] <= 1.0
    gauss = kernel_shape(reference_kernel("gaussian", 7, sigma_px=1.0))
    assert not gauss["centre_surround"] and gauss["peak_frequency_cpp"] == 0.0
    delta = kernel_shape(reference_kernel("delta", 7))
    assert not delta["centre_surround"] and delta["surround_sum"] == 0.0


def test_tiny_ablation_table(tmp_path):
    settings = {"epochs_frozen": 1, "epochs_joint": 1, "width": 8}
    recs = run_ablation(["recognition"], sizes=[1, 3], seeds=[0, 1], n_train=16, n_test=16, settings=settings,
                        log_path=tmp_path / "runs.jsonl")
    assert sorted((r["size"], r["seed"]) for r in recs) == [(1, 0), (1, 1), (3, 0), (3, 1)]
    assert len((tmp_path / "runs.jsonl").read_text().splitlines()) == 4
    assert all("shape" in r for r in recs if r["size"] == 3)
    table = ablation_markdown(recs)
    assert "| w/o |" in table and "| 3×3 |" in table and "±" in table and "2 seeds" in table
    # the CLI rebuilds the same table from the run log without training
    assert main(["ablation", "--from-runs", str(tmp_path / "runs.jsonl")]) == 0
    assert json.loads((tmp_path / "runs.jsonl").read_text().splitlines()[0])["task"] == "recognition"


def test_ablation_bad_input():
    with pytest.raises(InputError, match="odd"):
        run_ablation(["recognition"], sizes=[2], seeds=[0])
    with pytest.raises(InputError, match="unknown"):
        run_ablation(["tracking"], sizes=[3], seeds=[0])
    with pytest.raises(InputError, match="seed"):
        run_ablation(["recognition"], sizes=[3], seeds=[])


def test_bootstrap_interval_matches_binomial_theory():
    import torch

    from fsdvs_hw.tasks.bench import bootstrap_interval
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
