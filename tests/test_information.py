"""Information per event (issue 24): the MI estimator, the reconstruction network, bits per event, the study."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.mutual_information import (
    gaussian_mi,
    histogram_mi,
    joint_histogram,
    mutual_information,
    quantile_edges,
)
from fsdvs_hw.studies.information import (
    TABLE_FIELDS,
    ConditionEvidence,
    InformationOptions,
    bits_per_event,
    information_table,
    run_information_study,
)


def _gaussian_pair(rho: float, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = rng.normal(size=n)
    return x, rho * x + math.sqrt(1 - rho**2) * rng.normal(size=n)


# --------------------------------------------------------------------------- estimator
def test_gaussian_mi_analytic_values():
    assert gaussian_mi(0.0) == 0.0
    assert gaussian_mi(math.sqrt(0.75)) == pytest.approx(1.0)  # 1 - rho^2 = 1/4 -> 1 bit
    assert gaussian_mi(-0.9) == gaussian_mi(0.9) == pytest.approx(1.19796, abs=1e-5)


@pytest.mark.parametrize("rho, bias_low, bias_high", [(0.5, -0.015, 0.005), (0.9, -0.06, -0.015)])
def test_estimator_against_bivariate_gaussian(rho, bias_low, bias_high):
    """At the study's sample size (64 clips x 1024 px) and 32 bins: the documented discretisation bias."""
    est = [mutual_information(*_gaussian_pair(rho, 65536, seed)) for seed in range(3)]
    bias = float(np.mean(est)) - gaussian_mi(rho)
    assert bias_low < bias < bias_high  # binning can only lose information: at rho = 0.9, about -0.037 bits
    assert np.std(est) < 0.01


def test_miller_madow_removes_the_plug_in_bias_of_independent_variables():
    x, y = _gaussian_pair(0.0, 65536, 7)
    plug_in = mutual_information(x, y, correction="none")
    corrected = mutual_information(x, y)
    expected_bias = (32 * 32 - 32 - 32 + 1) / (2 * 65536 * math.log(2))  # (m_xy - m_x - m_y + 1) / (2 N ln 2)
    assert plug_in == pytest.approx(expected_bias, rel=0.2)
    assert corrected < 0.002
    # at one 1024-pixel frame the first-order correction is not enough (why MI is never taken per frame)
    assert mutual_information(*_gaussian_pair(0.0, 1024, 7)) > 0.2


def test_histogram_mi_hand_values():
    assert histogram_mi(np.array([[5, 0], [0, 5]]), correction="none") == pytest.approx(1.0)
    assert histogram_mi(np.array([[5, 0], [0, 5]])) == pytest.approx(1.0 + 1 / (20 * math.log(2)))
    assert histogram_mi(np.full((4, 4), 3), correction="none") == pytest.approx(0.0, abs=1e-12)
    stack = histogram_mi(np.stack([np.eye(4) * 10, np.full((4, 4), 1.0)]), correction="none")
    assert stack == pytest.approx([2.0, 0.0], abs=1e-12)


def test_estimator_is_invariant_under_monotone_maps():
    x, y = _gaussian_pair(0.8, 20000, 3)
    assert mutual_information(np.exp(x), 3 * y**3 - 1) == pytest.approx(mutual_information(x, y), abs=1e-12)


def test_quantile_edges_and_joint_histogram():
    assert quantile_edges(np.arange(8.0), 4).tolist() == [1.75, 3.5, 5.25]
    assert quantile_edges(np.zeros(100), 8).size == 1  # ties merged: one constant value, at most 2 bins
    h = joint_histogram([0, 1, 2, 3], [0, 0, 1, 1], np.array([1.5]), np.array([0.5]))
    assert h.tolist() == [[2, 0], [0, 2]]


@pytest.mark.parametrize(
    "call",
    [
        lambda: histogram_mi(np.array([[1, -1], [0, 2]])),
        lambda: histogram_mi(np.zeros((2, 2))),
        lambda: histogram_mi(np.ones((2, 2)), correction="jackknife"),
        lambda: joint_histogram([1, 2, 3], [1, 2], np.array([1.5]), np.array([1.5])),
        lambda: mutual_information([1.0, np.nan, 2.0], [1.0, 2.0, 3.0]),
        lambda: mutual_information([1.0, 2.0], [1.0, 2.0], n_bins=1),
        lambda: gaussian_mi(1.0),
        lambda: bits_per_event(1.0, -0.5),
        lambda: InformationOptions(design="designs/default.toml", out="x", n_networks=1),
    ],
)
def test_bad_input_raises_input_error(call):
    with pytest.raises(InputError):
        call()


# --------------------------------------------------------------------------- bits per event and the table
def test_bits_per_event_arithmetic():
    assert bits_per_event(1.0, 0.5) == 2.0
    np.testing.assert_allclose(bits_per_event([1.06, 0.98], [2.0, 0.49]), [0.53, 2.0])
    assert math.isnan(bits_per_event(0.3, 0.0))


def _evidence(name: str, diagonal: float, epp: float, n_net: int = 3, n_clips: int = 6) -> ConditionEvidence:
    """Clips whose 4x4 joint histogram puts ``diagonal`` of the mass on the diagonal."""
    h = np.full((4, 4), (1 - diagonal) / 12 * 1200) + np.eye(4) * (diagonal - (1 - diagonal) / 12) * 1200
    hist = np.broadcast_to(np.round(h), (n_net, n_clips, 4, 4)).copy()
    return ConditionEvidence(
        name=name,
        kernel=name,
        kernel_size=1,
        threshold=0.2,
        histograms=hist,
        events_per_pixel=np.full((n_net, n_clips), epp),
        span_s=0.04,
        r2=np.zeros(n_net),
        mi_shuffled=0.0,
    )


def test_information_table_gains_and_bits_per_event():
    wo, learned = _evidence("w/o", 0.6, 0.4), _evidence("learned", 0.9, 1.6)
    rows = {r["condition"]: r for r in information_table([wo, learned], n_resamples=200)}
    assert list(rows["w/o"]) == list(TABLE_FIELDS)
    mi_wo = histogram_mi(wo.histograms.sum(axis=1)[0])
    mi_l = histogram_mi(learned.histograms.sum(axis=1)[0])
    assert rows["w/o"]["mi"] == pytest.approx(mi_wo)
    assert rows["learned"]["mi_gain"] == pytest.approx(mi_l - mi_wo) and rows["learned"]["mi_gain"] > 0
    assert rows["learned"]["bits_per_event"] == pytest.approx(mi_l / 1.6)
    # more information, but 4x the events: fewer bits per event
    assert rows["learned"]["bits_per_event_gain"] < 0
    assert rows["learned"]["rate"] == pytest.approx(1.6 / 0.04)
    assert rows["w/o"]["mi_gain"] == 0.0 and rows["learned"]["mi_gain_pct"] == pytest.approx(100 * (mi_l / mi_wo - 1))
    for r in rows.values():
        assert r["mi_low"] - 1e-9 <= r["mi"] <= r["mi_high"] + 1e-9


def test_information_table_refuses_unpaired_conditions():
    with pytest.raises(InputError, match="paired"):
        information_table([_evidence("w/o", 0.6, 0.4), _evidence("learned", 0.9, 1.6, n_clips=5)])
    with pytest.raises(InputError, match="reference"):
        information_table([_evidence("learned", 0.9, 1.6)])


# --------------------------------------------------------------------------- the network
@pytest.fixture
def one_torch_thread():
    """Training on one thread (a second one spins on a loaded machine and costs ~10x the CPU time)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.mark.usefixtures("one_torch_thread")
def test_reconstruction_network_learns_more_than_a_shuffled_pairing():
    import fsdvs_hw.tasks.reconstruction  # noqa: F401 - registers the task
    from fsdvs_hw.scenes.synthetic import scene_regime
    from fsdvs_hw.tasks.learn import TrainingSettings, heldout_targets, learn_kernel

    scene = scene_regime("clutter", motion="random", height_px=16, width_px=16, radius_px=(3.0, 5.0))
    result = learn_kernel(
        "reconstruction",
        1,
        seed=0,
        n_train=128,
        n_test=16,
        scene=scene,
        learn_filter=False,
        settings=TrainingSettings(epochs_frozen=0, epochs_joint=4, width=8),
    )
    recon = result.predictions["image"]
    truth = heldout_targets("reconstruction", scene, 16)["image"]
    mi = mutual_information(truth, recon, n_bins=8)
    shuffled = mutual_information(np.roll(truth, 1, axis=0), recon, n_bins=8)
    assert mi > shuffled + 0.05
    assert result.metrics["r2"] > 0.05


# --------------------------------------------------------------------------- the command
@pytest.mark.usefixtures("one_torch_thread")
def test_study_resumes_without_retraining(tmp_path, monkeypatch):
    import fsdvs_hw.tasks.learn as learn

    opts = InformationOptions(
        design="designs/default.toml",
        out=tmp_path / "info",
        n_networks=2,
        n_train=8,
        n_test=4,
        epochs=1,
        width=4,
        realisations=(),
        matched_rate=False,
        n_resamples=100,
    )
    first = run_information_study(opts)
    assert [r["condition"] for r in first.rows] == ["w/o", "learned"]
    assert (tmp_path / "info" / "information.csv").is_file()

    def refuse(*args, **kwargs):
        raise AssertionError("retrained on resume")

    monkeypatch.setattr(learn, "learn_kernel", refuse)
    monkeypatch.setattr(learn, "evaluate_kernel", refuse)
    second = run_information_study(opts)
    assert second.rows == first.rows
    import json

    stored = json.loads((tmp_path / "info" / "information.json").read_text())
    assert stored["settings"]["training_seeds"] == [0, 1] and "versions" in stored["provenance"]


def test_cli_refuses_bad_arguments(capsys):
    from fsdvs_hw.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["information", "designs/default.toml", "--networks", "1"])
    assert exc.value.code == 2
    assert main(["information", "designs/default.toml", "--realisations", "bogus", "--out", "/tmp/x"]) == 2
    assert "bogus" in capsys.readouterr().err
