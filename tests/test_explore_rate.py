"""Bandwidth-matched comparison (fsdvs_hw.explore.rate): interpolation, refusal, CI coverage, a
rate-only gain that vanishes at matched rate, per-clip event rates, and the CLI's resume."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.explore.paired import ClipEvidence, bootstrap_weights, event_rate_ci
from fsdvs_hw.explore.rate import (
    INTERPOLATIONS,
    RateCurve,
    RatePoint,
    interpolate_log_rate,
    matched_rate_difference,
    rate_curve,
)
from fsdvs_hw.kernels import Kernel
from fsdvs_hw.stats import ClipMeans

ROOT = Path(__file__).parents[1]


def _curve(name: str, thresholds, rates, metric_values, *, seeds=(1000, 1001)) -> RateCurve:
    """A curve from given per-point (networks, clips) rate and metric arrays."""
    pts = [
        RatePoint(
            threshold=t,
            metrics=tuple(ClipMeans(m) for m in np.atleast_2d(mv)),
            clip_rates=np.atleast_2d(np.asarray(r, dtype=float)),
            test_seeds=tuple(seeds[: len(np.atleast_2d(mv))]),
            sensor_seeds=tuple(range(len(np.atleast_2d(mv)))),
        )
        for t, r, mv in zip(thresholds, rates, metric_values)
    ]
    return RateCurve(
        kernel_name=name, task="recognition", metric_name="top1", test_clips="per_network", points=tuple(pts)
    )


def test_interpolation_is_exact_on_a_curve_linear_in_log_rate():
    a, b = 0.3, 0.05
    rates = [80.0, 40.0, 20.0, 10.0]  # falling with threshold
    ths = [0.1, 0.2, 0.3, 0.4]
    ones = np.ones((2, 5))
    curve = _curve("w/o", ths, [r * ones for r in rates], [(a + b * math.log(r)) * ones for r in rates])
    ref = _curve("learned", [0.2], [27.0 * ones], [0.9 * ones])
    d = matched_rate_difference(curve, ref, 0.2, n_resamples=200)
    assert d.ok and d.inside_range
    assert d.estimate == pytest.approx(0.9 - (a + b * math.log(27.0)), abs=1e-12)
    # no noise: every resample gives the same number
    assert d.low == pytest.approx(d.estimate, abs=1e-12) and d.high == pytest.approx(d.estimate, abs=1e-12)
    # the same-threshold difference reads the curve's own point at 0.2
    assert d.raw_estimate == pytest.approx(0.9 - (a + b * math.log(40.0)), abs=1e-12)
    # threshold at the matched rate: between 0.2 (40/s) and 0.3 (20/s), linear in log rate
    assert d.matched_threshold == pytest.approx(0.2 + 0.1 * math.log(40 / 27) / math.log(2), abs=1e-12)
    assert interpolate_log_rate(rates, [a + b * math.log(r) for r in rates], 15.0) == pytest.approx(
        a + b * math.log(15.0), abs=1e-12
    )


def test_reference_rate_outside_the_curve_is_refused_not_extrapolated():
    ones = np.ones((2, 5))
    curve = _curve("w/o", [0.2, 0.3], [10 * ones, 5 * ones], [0.5 * ones, 0.4 * ones])
    ref = _curve("learned", [0.2], [30 * ones], [0.8 * ones])
    d = matched_rate_difference(curve, ref, 0.2, n_resamples=200)
    assert not d.ok and not d.inside_range and d.status.startswith("refused")
    assert "outside" in d.status and "30" in d.status
    assert math.isnan(d.estimate) and math.isnan(d.low)
    assert d.raw_estimate == pytest.approx(0.3)  # the same-threshold difference is still measured
    assert math.isnan(interpolate_log_rate([10, 5], [0.5, 0.4], 30.0))
    with pytest.raises(InputError, match="monotone"):
        interpolate_log_rate([10, 12, 5], [0.5, 0.4, 0.3], 8.0)


def test_unpaired_curves_are_an_error():
    ones = np.ones((2, 5))
    curve = _curve("w/o", [0.2, 0.3], [10 * ones, 5 * ones], [0.5 * ones, 0.4 * ones])
    other = _curve("learned", [0.2], [7 * ones], [0.8 * ones], seeds=(7, 8))
    with pytest.raises(InputError, match="not paired"):
        matched_rate_difference(curve, other, 0.2)


def _noisy_study(rng: np.random.Generator, n_net: int = 16, n_clip: int = 24):
    """w/o curve and a reference point with known truth: metric = 0.2 + 0.1·ln(rate/10) per clip + noise."""
    ths = [0.1, 0.15, 0.2, 0.3]
    true_rates = [40.0, 20.0, 10.0, 4.0]
    ref_rate, ref_metric = 15.0, 0.5
    activity = 1 + 0.2 * rng.standard_normal((n_net, n_clip))  # a busy clip is busy at every threshold
    net_bias = 0.03 * rng.standard_normal((n_net, 1))  # networks differ

    def metric(r):
        return 0.2 + 0.1 * math.log(r / 10) + net_bias + 0.1 * rng.standard_normal((n_net, n_clip))

    curve = _curve(
        "w/o", ths, [r * activity for r in true_rates], [metric(r) for r in true_rates], seeds=tuple(range(n_net))
    )
    ref = _curve(
        "learned",
        [0.2],
        [ref_rate * activity],
        [ref_metric + net_bias + 0.1 * rng.standard_normal((n_net, n_clip))],
        seeds=tuple(range(n_net)),
    )
    truth = ref_metric - (0.2 + 0.1 * math.log(ref_rate / 10))
    return curve, ref, truth


def test_matched_rate_ci_covers_the_truth_at_about_its_level():
    rng = np.random.default_rng(12)
    hits, widths = [], []
    for _ in range(40):
        curve, ref, truth = _noisy_study(rng)
        d = matched_rate_difference(curve, ref, 0.2, n_resamples=300, rng=int(rng.integers(1 << 30)))
        assert d.ok
        hits.append(d.low <= truth <= d.high)
        widths.append(d.high - d.low)
    assert np.mean(hits) >= 0.85  # nominal 0.95, 40 replications
    assert 0.005 < np.median(widths) < 0.2  # an interval, not a point, not everything


class _Counter:
    """A stand-in for clip_evidence: a kernel's tap sum acts as a gain that divides the threshold.

    Per clip: event rate = activity · 40·exp(−t_eff/0.1) events/pixel/s, correct ⇔ uniform < p(t_eff),
    with p falling with t_eff; t_eff = threshold / gain. Deterministic in (clip set, clip).
    """

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, kernel, task, checkpoint, *, n_test=None, sensor=None, seed_offset=0, clip_set=0, **kw):
        self.calls += 1
        gain = 1.0 if kernel is None else float(np.sum(kernel.taps))
        t_eff = float(sensor.threshold_on) / gain
        r = np.random.default_rng(1000 + clip_set)
        n = n_test or 32
        activity, u = 1 + 0.3 * r.random(n), r.random(n)
        p = 0.9 - 1.5 * t_eff
        rates = activity * 40 * np.exp(-t_eff / 0.1)
        return ClipEvidence(
            task=task,
            metric_name="top1",
            value=float(np.mean(u < p)),
            n_clips=n,
            metric=ClipMeans((u < p).astype(float)),
            checkpoint=str(checkpoint),
            sensor_seed=seed_offset,
            seconds=0.0,
            test_seed=1000 + clip_set,
            event_rate=float(rates.mean()) / 100,
            clip_event_rates=rates,
        )


def test_a_gain_that_only_lowers_the_threshold_vanishes_at_matched_rate(monkeypatch):
    from fsdvs_hw.explore import rate as rate_mod

    monkeypatch.setattr(rate_mod, "clip_evidence", _Counter())
    ckpts = sorted((ROOT / "designs/kernels/networks").glob("recognition_with_learned_detection_7x7_s*.safetensors"))[
        :8
    ]
    double = Kernel(np.array([[2.0]]), name="delta x2")  # doubles the contrast: the effective threshold halves
    ths = (0.1, 0.15, 0.2, 0.3, 0.4)
    wo = rate_curve(None, "recognition", ckpts, ths, n_test=64)
    dbl = rate_curve(double, "recognition", ckpts, ths, n_test=64)
    assert dbl.point(0.2).rate > 2 * wo.point(0.2).rate  # it fires more events at the same threshold
    d = matched_rate_difference(wo, dbl, 0.2, n_resamples=500)
    assert d.ok and d.n_networks == 8 and d.n_clips == 8 * 64
    assert d.raw_low > 0  # raw: a clear "gain"
    assert abs(d.estimate) < 1e-12 < d.raw_estimate  # at equal rate it is w/o at 0.1: nothing left
    assert d.low <= 0 <= d.high
    assert d.matched_threshold == pytest.approx(0.1, abs=1e-12)


def test_clip_event_rates_are_the_mean_rate_in_events_per_pixel_second():
    pytest.importorskip("torch")
    from fsdvs_hw.explore.paired import clip_evidence
    from fsdvs_hw.kernels import load_kernel

    ckpt = ROOT / "designs/kernels/learned_detection_7x7.safetensors"
    ev = clip_evidence(load_kernel(ROOT / "designs/kernels/learned_detection_7x7.json"), "detection", ckpt, n_test=8)
    assert ev.clip_event_rates.shape == (8,) and np.all(ev.clip_event_rates > 0)
    # per pixel-frame interval × 100 frames/s (the scene's frame rate) = per pixel-second
    assert ev.clip_event_rates.mean() == pytest.approx(ev.event_rate * 100.0, rel=1e-9)
    ci = event_rate_ci([ev], n_resamples=500)
    assert ci["low"] < ci["mean"] < ci["high"] and ci["unit"] == "events/pixel/s" and ci["n_clips"] == 8


def test_event_rate_ci_resamples_networks_when_clips_are_nested():
    ev = [
        ClipEvidence(
            "recognition",
            "top1",
            0.5,
            4,
            ClipMeans(np.ones(4)),
            "x",
            s,
            0.0,
            clip_event_rates=np.full(4, 10.0 * (s + 1)),
        )
        for s in range(5)
    ]
    ci = event_rate_ci(ev, n_resamples=2000)
    assert ci["mean"] == pytest.approx(30.0) and ci["n_networks"] == 5 and ci["n_clips"] == 20
    assert ci["low"] < 25 and ci["high"] > 35  # the spread between networks enters (clips alone: zero width)
    ws, wc = bootstrap_weights(5, 4, n_resamples=100)
    assert wc is None and ws.shape == (100, 5) and np.all(ws.sum(axis=1) == 5)
    assert event_rate_ci([ClipEvidence("r", "top1", 0.5, 4, ClipMeans(np.ones(4)), "x", 0, 0.0)])["status"].startswith(
        "unavailable"
    )


def test_rate_curve_rejects_bad_thresholds():
    with pytest.raises(InputError, match="thresholds"):
        rate_curve(None, "detection", ["x.safetensors"], (0.2,))
    with pytest.raises(InputError, match="thresholds"):
        rate_curve(None, "detection", ["x.safetensors"], (0.2, -1.0))


def _rate_argv(out: Path) -> list[str]:
    """``fsdvs-hw rate`` on the default design: recognition, 3 networks × 16 clips, thresholds 0.1 and 0.3."""
    return [
        "rate",
        str(ROOT / "designs/default.toml"),
        "--task",
        "recognition",
        "--networks",
        "3",
        "--n-test",
        "16",
        "--thresholds",
        "0.1",
        "0.3",
        "--n-resamples",
        "200",
        "--out",
        str(out),
        "--no-progress",
    ]


def test_cli_rate_resumes_without_recomputing_a_point(monkeypatch, tmp_path):
    from fsdvs_hw.cli import main
    from fsdvs_hw.explore import rate as rate_mod

    counter = _Counter()
    monkeypatch.setattr(rate_mod, "clip_evidence", counter)
    argv = _rate_argv(tmp_path / "r")
    assert main(argv) == 0
    assert counter.calls == 2 * 3 * 3  # (w/o, learned) × thresholds (0.1, 0.2 of the design, 0.3) × networks
    first = json.loads((tmp_path / "r/matched_rate.json").read_text())
    assert main(argv) == 0
    assert counter.calls == 18  # the rerun loaded every point
    second = json.loads((tmp_path / "r/matched_rate.json").read_text())
    assert second["comparisons"] == first["comparisons"]
    csv_rows = (tmp_path / "r/rate_curves.csv").read_text().splitlines()
    assert len(csv_rows) == 1 + 2 * 3 and "events/pixel/s" in csv_rows[1]
    # a changed setting (clips per network) is a new point, not a stale one
    argv[argv.index("16")] = "12"
    assert main(argv) == 0 and counter.calls == 36


# --------------------------------------------------------------------------- interpolation options (issue 38)
def test_linear_interpolation_is_np_interp_in_log_rate():
    rng = np.random.default_rng(3)
    rates = np.sort(rng.uniform(0.5, 300.0, 7))[::-1]  # falling with threshold
    metrics = rng.uniform(0.0, 1.0, 7)
    for target in rng.uniform(rates.min(), rates.max(), 20):
        expected = np.interp(math.log(target), np.log(rates[::-1]), metrics[::-1])
        assert interpolate_log_rate(rates, metrics, target) == expected
        assert interpolate_log_rate(rates, metrics, target, interpolation="linear") == expected


def test_quadratic_interpolation_reproduces_a_parabola_in_log_rate():
    def truth(r):  # a peak at 20 events/pixel/s, like a plain DVS's metric vs rate
        return 0.2 - 0.03 * (math.log(r) - math.log(20.0)) ** 2

    rates = [250.0, 90.0, 40.0, 12.0, 3.0, 0.5]
    metrics = [truth(r) for r in rates]
    for target in (0.7, 5.0, 15.0, 20.0, 33.0, 100.0, 240.0):
        assert interpolate_log_rate(rates, metrics, target, interpolation="quadratic") == pytest.approx(
            truth(target), abs=1e-12
        )
    # the chord of a concave curve lies below it: linear underestimates the peak
    assert interpolate_log_rate(rates, metrics, 20.0) < truth(20.0) - 1e-3
    # every interpolation passes through the measured points and refuses to extrapolate
    for how in ("linear", "pchip", "quadratic"):
        assert interpolate_log_rate(rates, metrics, 40.0, interpolation=how) == pytest.approx(truth(40.0), abs=1e-12)
        assert math.isnan(interpolate_log_rate(rates, metrics, 300.0, interpolation=how))


def test_pchip_interpolation_preserves_monotonicity_and_never_overshoots():
    rates = [100.0, 50.0, 20.0, 10.0, 5.0]
    metrics = [0.1, 0.5, 0.52, 0.9, 0.95]  # monotone in rate, with a near-flat step a cubic spline overshoots
    grid = np.geomspace(5.0, 100.0, 400)
    for how in ("pchip", "linear"):
        values = np.array([interpolate_log_rate(rates, metrics, g, interpolation=how) for g in grid])
        assert np.all(np.diff(values) <= 1e-15)  # metrics fall with rate here, and so does the curve
        assert values.min() >= 0.1 - 1e-15 and values.max() <= 0.95 + 1e-15
    # at a peak pchip stays at or below the peak value (a quadratic through it may rise above)
    peak = [0.1, 0.5, 0.9, 0.5, 0.2]
    values = [interpolate_log_rate(rates, peak, g, interpolation="pchip") for g in grid]
    assert max(values) <= 0.9 + 1e-15


def test_interpolation_option_is_checked():
    with pytest.raises(InputError, match="allowed: linear, pchip, quadratic"):
        interpolate_log_rate([10, 5, 2], [0.5, 0.4, 0.3], 8.0, interpolation="cubic")
    with pytest.raises(InputError, match=r"quadratic.*3 points"):
        interpolate_log_rate([10, 5], [0.5, 0.4], 8.0, interpolation="quadratic")
    ones = np.ones((2, 5))
    curve = _curve("w/o", [0.2, 0.3], [10 * ones, 5 * ones], [0.5 * ones, 0.4 * ones])
    ref = _curve("learned", [0.2], [7 * ones], [0.8 * ones])
    with pytest.raises(InputError, match="at least 3 thresholds"):
        matched_rate_difference(curve, ref, 0.2, interpolation="quadratic")


def test_matched_rate_difference_applies_the_interpolation_in_every_resample():
    """A noise-free curve quadratic in log rate: each option's CI collapses onto its own estimate."""

    def truth(r):
        return 0.3 - 0.02 * (math.log(r) - math.log(25.0)) ** 2

    rates = [160.0, 80.0, 40.0, 20.0, 10.0]
    ths = [0.1, 0.15, 0.2, 0.3, 0.4]
    ones = np.ones((3, 6))
    curve = _curve("w/o", ths, [r * ones for r in rates], [truth(r) * ones for r in rates], seeds=(0, 1, 2))
    ref = _curve("learned", [0.2], [27.0 * ones], [0.5 * ones], seeds=(0, 1, 2))
    d = {how: matched_rate_difference(curve, ref, 0.2, n_resamples=200, interpolation=how) for how in INTERPOLATIONS}
    assert d["quadratic"].estimate == pytest.approx(0.5 - truth(27.0), abs=1e-12)
    assert d["linear"].estimate > d["quadratic"].estimate + 1e-4  # the chord under a concave curve
    for how, res in d.items():
        assert res.ok and res.interpolation == how and res.to_dict()["interpolation"] == how
        assert res.low == pytest.approx(res.estimate, abs=1e-12) and res.high == pytest.approx(res.estimate, abs=1e-12)
    assert "quadratic interpolation" in d["quadratic"].describe() and "interpolation" not in d["linear"].describe()


def test_interpolation_sensitivity_rows_and_cli_flag(monkeypatch, tmp_path):
    from fsdvs_hw.cli import main
    from fsdvs_hw.explore import rate as rate_mod

    monkeypatch.setattr(rate_mod, "clip_evidence", _Counter())
    out = tmp_path / "r"
    argv = _rate_argv(out)
    assert main(argv) == 0 and not (out / "interpolation_sensitivity.json").exists()
    assert main([*argv, "--interpolation-sensitivity"]) == 0
    stored = json.loads((out / "interpolation_sensitivity.json").read_text())
    matched = json.loads((out / "matched_rate.json").read_text())["comparisons"]
    rows = {(r["comparison"], r["interpolation"]): r for r in stored["rows"]}
    assert set(rows) == {(c, how) for c in matched for how in INTERPOLATIONS}
    assert stored["settings"]["interpolations"] == list(INTERPOLATIONS) and "command" in stored["provenance"]
    for c, m in matched.items():  # the linear rows are matched_rate.json's numbers, to the bit
        lin = rows[(c, "linear")]
        assert (lin["estimate"], lin["low"], lin["high"]) == (m["estimate"], m["low"], m["high"])
        assert lin["shift_vs_linear"] == 0.0
        for how in ("pchip", "quadratic"):
            assert rows[(c, how)]["shift_vs_linear"] == pytest.approx(rows[(c, how)]["estimate"] - m["estimate"])
    assert len((out / "interpolation_sensitivity.csv").read_text().splitlines()) == 1 + len(rows)
