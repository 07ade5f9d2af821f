"""Tests of fsdvs_hw.stats: the bootstrap CIs cover known differences, pairing and seeds behave,
and the resampled metrics equal the libraries' (pycocotools, torchmetrics) on the unresampled set."""

from __future__ import annotations

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.stats import (
    ClipMeans,
    CocoDetections,
    ConfusionMIoU,
    DifferenceCI,
    clips_for_half_width,
    difference_cis,
    difference_ci,
)
from fsdvs_hw.tasks.metrics import detection_map, segmentation_scores, top1_accuracy


# --------------------------------------------------------------------------- synthetic data
def _detections(n: int, rng: np.random.Generator, *, quality: float = 1.0, n_classes: int = 3, k: int = 6):
    """Random scenes (1-2 boxes) and a noisy detector: ``quality`` scales its box jitter inversely."""
    gt = np.full((n, 2, 4), np.nan)
    gl = np.full((n, 2), -1)
    for i in range(n):
        for j in range(rng.integers(1, 3)):
            x, y = rng.uniform(0, 40, 2)
            w, h = rng.uniform(6, 16, 2)
            gt[i, j] = (x, y, x + w, y + h)
            gl[i, j] = rng.integers(0, n_classes)
    pb = np.zeros((n, k, 4))
    ps = rng.uniform(0.0, 0.5, (n, k))
    pl = rng.integers(0, n_classes, (n, k))
    for i in range(n):
        for j in range(2):
            if gl[i, j] >= 0 and rng.uniform() < 0.9:
                jitter = rng.normal(0, 2.0 / quality, 4)
                pb[i, j] = gt[i, j] + jitter
                ps[i, j] = rng.uniform(0.3, 1.0)
                pl[i, j] = gl[i, j] if rng.uniform() < 0.9 else rng.integers(0, n_classes)
        for j in range(2, k):
            x, y = rng.uniform(0, 40, 2)
            pb[i, j] = (x, y, x + rng.uniform(4, 14), y + rng.uniform(4, 14))
    return pb, ps, pl, gt, gl


# --------------------------------------------------------------------------- metrics equal the libraries
def test_coco_weighted_equals_pycocotools_on_the_full_set():
    rng = np.random.default_rng(1)
    pb, ps, pl, gt, gl = _detections(120, rng)
    ref = detection_map(pb, ps, pl, gt, gl, num_classes=3)
    det = CocoDetections.from_predictions(pb, ps, pl, gt, gl, num_classes=3)
    got = det.weighted_all(np.ones((1, 120)))
    for key in ("map", "map_50", "map_75"):
        assert abs(got[key][0] - ref[key]) <= 1e-12, key
    assert 0.1 < ref["map"] < 0.9  # a non-trivial detector, so the comparison means something


def test_coco_weighted_equals_pycocotools_on_the_duplicated_set():
    """Integer weights = pycocotools on the dataset with clip i repeated w_i times (zeros dropped)."""
    rng = np.random.default_rng(2)
    pb, ps, pl, gt, gl = _detections(60, rng)
    det = CocoDetections.from_predictions(pb, ps, pl, gt, gl, num_classes=3)
    for draw in range(3):
        w = rng.multinomial(60, np.full(60, 1 / 60))  # a bootstrap resample's multiplicities
        rep = np.repeat(np.arange(60), w)
        ref = detection_map(pb[rep], ps[rep], pl[rep], gt[rep], gl[rep], num_classes=3)
        got = det.weighted_all(w[None, :])
        for key in ("map", "map_50", "map_75"):
            assert abs(got[key][0] - ref[key]) <= 1e-12, (draw, key)


def test_coco_weighted_batches_agree_with_single_rows_and_chunking():
    rng = np.random.default_rng(3)
    pb, ps, pl, gt, gl = _detections(50, rng)
    det = CocoDetections.from_predictions(pb, ps, pl, gt, gl, num_classes=3)
    w = rng.multinomial(50, np.full(50, 1 / 50), size=7).astype(float)
    batch = det.weighted(w)
    small = det.weighted_all(w, chunk_elements=1)["map"]
    single = np.array([det.weighted(row[None])[0] for row in w])
    np.testing.assert_allclose(batch, single, rtol=0, atol=1e-15)
    np.testing.assert_allclose(batch, small, rtol=0, atol=1e-15)


def test_coco_without_detections_scores_zero_and_rejects_fractional_weights():
    gt = np.array([[[0, 0, 10, 10.0]]])
    det = CocoDetections.from_predictions(
        np.zeros((1, 1, 4)), np.zeros((1, 1)), -np.ones((1, 1), int), gt, np.array([[0]]), num_classes=2
    )
    assert det.weighted(np.ones((1, 1)))[0] == 0.0
    with pytest.raises(InputError, match="integers"):
        det.weighted(np.full((1, 1), 0.5))


def test_miou_and_top1_equal_torchmetrics_on_the_full_set():
    rng = np.random.default_rng(4)
    target = rng.integers(0, 4, (30, 8, 8))
    pred = np.where(rng.uniform(size=target.shape) < 0.7, target, rng.integers(0, 4, target.shape))
    pred[pred == 3] = 0  # class 3 never predicted: still present through the target
    ref = segmentation_scores(pred, target, num_classes=5)["miou"]  # class 4 absent from both
    got = ConfusionMIoU.from_masks(pred, target, 5).weighted(np.ones((1, 30)))[0]
    assert abs(got - ref) < 1e-6  # torchmetrics computes in float32
    logits = rng.normal(size=(40, 6))
    lab = rng.integers(0, 6, 40)
    assert (
        abs(ClipMeans.top1(logits, lab).weighted(np.ones(40))[0] - top1_accuracy(logits, lab, num_classes=6)["top1"])
        < 1e-7
    )


@pytest.mark.parametrize("labels", [[0, 1], [0, -1, 2]])
def test_clip_means_refuses_labels_that_are_not_one_class_per_clip(labels):
    with pytest.raises(InputError, match="labels must be one class index >= 0 per clip"):
        ClipMeans([1.0, 0.0, 1.0], labels=labels, num_classes=3)


# --------------------------------------------------------------------------- the intervals
def _crossed(rng, n, s, delta, *, sd_clip=0.3, sd_seed=0.0, sd_noise=0.2, corr=True):
    """Per-seed reference and candidate per-clip values with a known population difference ``delta``."""
    base = rng.normal(0.6, 0.3, n)  # clip difficulty, shared by both kernels when corr
    b = rng.normal(0, sd_clip, n)  # clip-level difference effect
    a = rng.normal(0, sd_seed, s)
    ref, cand = [], []
    for k in range(s):
        r = (base if corr else rng.normal(0.6, 0.3, n)) + rng.normal(0, sd_noise, n)
        ref.append(ClipMeans(r))
        cand.append(ClipMeans(r - delta - a[k] - b - rng.normal(0, sd_noise, n)))
    return ref, cand


@pytest.mark.parametrize("n_seeds, sd_seed", [(1, 0.0), (3, 0.02)])
def test_ci_covers_the_known_difference_in_at_least_90_percent_of_200_draws(n_seeds, sd_seed):
    rng = np.random.default_rng(10 + n_seeds)
    delta, hits = 0.05, 0
    for draw in range(200):
        ref, cand = _crossed(rng, 150, n_seeds, delta, sd_seed=sd_seed)
        ci = difference_ci(ref, cand, n_resamples=400, rng=draw)
        hits += ci.low <= delta <= ci.high
    assert hits >= 180, hits


def test_coverage_with_binary_top1_data_and_mean_true_difference():
    """Bernoulli correctness (top-1): 95 % percentile CIs cover p_ref − p_cand ≥ 90 % of the time."""
    rng = np.random.default_rng(20)
    hits = 0
    for draw in range(200):
        ref_ok = rng.uniform(size=300) < 0.8
        cand_ok = np.where(rng.uniform(size=300) < 0.85, ref_ok, rng.uniform(size=300) < 0.5)
        # P(cand correct) = 0.85*0.8 + 0.15*0.5 = 0.755 → true difference 0.045
        ci = difference_ci(ClipMeans(ref_ok), ClipMeans(cand_ok), n_resamples=400, rng=draw)
        hits += ci.low <= 0.045 <= ci.high
    assert hits >= 180, hits


def test_paired_ci_is_narrower_than_unpaired_on_correlated_data():
    rng = np.random.default_rng(5)
    ref, cand = _crossed(rng, 400, 1, 0.02, sd_clip=0.05, sd_noise=0.02)
    paired = difference_ci(ref, cand, n_resamples=1000)
    unpaired = difference_ci(ref, cand, paired_clips=False, n_resamples=1000)
    assert paired.half_width < 0.5 * unpaired.half_width
    assert paired.low > 0 and unpaired.low < 0  # only pairing resolves the 0.02 difference


def test_seed_spread_widens_the_ci_and_one_seed_is_flagged():
    rng = np.random.default_rng(6)
    quiet = _crossed(np.random.default_rng(6), 300, 3, 0.03, sd_seed=0.0)
    spread = _crossed(np.random.default_rng(6), 300, 3, 0.03, sd_seed=0.05)
    h_quiet = difference_ci(*quiet, n_resamples=1000).half_width
    h_spread = difference_ci(*spread, n_resamples=1000).half_width
    assert h_spread > 1.5 * h_quiet
    clips_only = difference_ci(*spread, resample=("clips",), n_resamples=1000)
    assert clips_only.half_width < 0.7 * h_spread and not clips_only.seed_variance_included
    one = difference_ci(*_crossed(rng, 300, 1, 0.03), n_resamples=200)
    assert one.n_seeds_reference == 1 and not one.seed_variance_included and one.resampled == ("clips",)


def test_unpaired_seeds_resample_each_arm_and_reject_misaligned_paired_seeds():
    rng = np.random.default_rng(7)
    ref, _ = _crossed(rng, 200, 3, 0.0)
    _, cand = _crossed(rng, 200, 4, 0.0)
    with pytest.raises(InputError, match="paired seeds"):
        difference_ci(ref, cand)
    ci = difference_ci(ref, cand, paired_seeds=False, n_resamples=300)
    assert ci.n_seeds_reference == 3 and ci.n_seeds_candidate == 4 and ci.seed_variance_included


def test_bca_and_percentile_agree_on_a_near_linear_statistic():
    rng = np.random.default_rng(8)
    ref, cand = _crossed(rng, 300, 1, 0.04)
    p = difference_ci(ref, cand, n_resamples=2000, method="percentile")
    b = difference_ci(ref, cand, n_resamples=2000, method="BCa")
    assert abs(p.low - b.low) < 0.2 * p.half_width and abs(p.high - b.high) < 0.2 * p.half_width


def test_mAP_difference_ci_through_the_detection_metric():
    rng = np.random.default_rng(9)
    data = _detections(200, rng)
    pb, ps, pl, gt, gl = data
    good = CocoDetections.from_predictions(pb, ps, pl, gt, gl, num_classes=3)
    worse_boxes = pb + rng.normal(0, 1.5, pb.shape)  # the same detector with extra box jitter
    worse = CocoDetections.from_predictions(worse_boxes, ps, pl, gt, gl, num_classes=3)
    ci = difference_ci(good, worse, n_resamples=300)
    full = (
        detection_map(pb, ps, pl, gt, gl, num_classes=3)["map"]
        - detection_map(worse_boxes, ps, pl, gt, gl, num_classes=3)["map"]
    )
    assert abs(ci.estimate - full) < 1e-12
    assert ci.low > 0 and ci.low < ci.estimate < ci.high


def test_describe_and_sizing():
    ci = DifferenceCI(0.004, -0.003, 0.011, 0.95, 500, 1, 1, True, True, ("clips",), "percentile", 1000, 0.0036)
    assert ci.contains_zero and ci.describe() == "no measurable loss (± 0.007)"
    # h ∝ 1/√n: halving h needs 4× the clips; the seed part is subtracted in variance
    assert clips_for_half_width(ci, 0.0035) == 2000
    assert clips_for_half_width(ci, 0.007, seed_half_width=0.0) == 500
    n = clips_for_half_width(ci, 0.0125, seed_half_width=0.0075)
    assert n == int(np.ceil(500 * 0.007**2 / (0.0125**2 - 0.0075**2)))
    with pytest.raises(InputError, match="more seeds"):
        clips_for_half_width(ci, 0.005, seed_half_width=0.006)


def test_several_candidates_share_the_draws_of_single_intervals():
    rng = np.random.default_rng(11)
    ref, c1 = _crossed(rng, 200, 3, 0.02)
    c2 = [ClipMeans(r.values + 0.01 + rng.normal(0, 0.01, 200)) for r in ref]  # a better candidate
    both = difference_cis(ref, {"a": c1, "b": c2}, n_resamples=500, rng=4)
    one = difference_ci(ref, c2, n_resamples=500, rng=4)
    assert both["b"] == one
    assert both["a"].estimate > 0 > both["b"].estimate


def test_metric_state_round_trip_is_exact():
    from fsdvs_hw.stats import metric_from_state

    rng = np.random.default_rng(12)
    pb, ps, pl, gt, gl = _detections(40, rng)
    w = rng.multinomial(40, np.full(40, 1 / 40), size=5)
    target = rng.integers(0, 3, (40, 4, 4))
    for m in (
        CocoDetections.from_predictions(pb, ps, pl, gt, gl, num_classes=3, metric="map_50"),
        ConfusionMIoU.from_masks(rng.integers(0, 3, (40, 4, 4)), target, 3),
        ClipMeans(rng.uniform(size=40)),
    ):
        back = metric_from_state(dict(m.state()))
        np.testing.assert_array_equal(back.weighted(w), m.weighted(w))
    with pytest.raises(InputError, match="unknown metric kind"):
        metric_from_state({"kind": np.array("nope")})


def test_weighted_task_loss_combines_independent_tasks():
    """Two tasks with independent clips: the weighted interval is centred on the weighted estimate and,
    with equal weights, its half-width is about √(h₁² + h₂²)/2 (independent parts add in variance)."""
    from fsdvs_hw.stats import task_difference_cis

    rng = np.random.default_rng(13)
    r1, c1 = _crossed(rng, 400, 1, 0.04)
    r2, c2 = _crossed(rng, 300, 1, 0.00)
    out = task_difference_cis({"a": (r1, {"x": c1}), "b": (r2, {"x": c2})}, weights={"a": 1, "b": 1}, n_resamples=3000)[
        "x"
    ]
    assert out["weighted"].estimate == pytest.approx(0.5 * (out["a"].estimate + out["b"].estimate), abs=1e-12)
    expected = 0.5 * np.hypot(out["a"].half_width, out["b"].half_width)
    assert out["weighted"].half_width == pytest.approx(expected, rel=0.1)
    assert out["weighted"].n_clips == 700
    only_a = task_difference_cis({"a": (r1, {"x": c1}), "b": (r2, {"x": c2})}, weights={"a": 1}, n_resamples=3000)["x"][
        "weighted"
    ]
    assert only_a.estimate == pytest.approx(out["a"].estimate, abs=1e-12)
    assert only_a.n_clips == 400


def test_test_set_sized_from_a_pilot_reaches_the_target_half_width():
    """size_test_sets on a 200-clip pilot; a fresh test set of the recommended size resolves ± 0.01."""
    from fsdvs_hw.explore.paired import encode_evidence
    from fsdvs_hw.explore.sizing import size_test_sets
    from fsdvs_hw.stats import difference_ci

    def draw(n, seed):
        g = np.random.default_rng(seed)
        ok = g.uniform(size=n) < 0.85
        flip = g.uniform(size=n) < 0.12  # the candidate disagrees on 12 % of the clips
        return ok.astype(float), np.where(flip, ~ok, ok).astype(float)

    def points(ref, cand):
        def pt(key, v):
            rec = {"status": "ok", "evidence": [encode_evidence(ClipMeans(v))]}
            return {
                "key": key,
                "realisation": key,
                "params": {},
                "status": "ok",
                "result": {"tasks": {"recognition": {"simulator": rec}}},
            }

        return [pt("learned", ref), pt("delta", cand)]

    budget = size_test_sets(points(*draw(200, 1)), target_half_width=0.01, margin=1.15, batch=64)
    (b,) = budget
    assert b.task == "recognition" and b.n_pilot == 200 and b.limiting == "delta" and b.h_seed == 0.0
    # 12 % discordant clips: var ≈ 0.12, so n ≈ 1.15 · 1.96² · 0.12 / 0.01² ≈ 5300 (pilot noise aside)
    assert 3000 < b.n_clips < 8000 and b.n_clips % 64 == 0
    ci = difference_ci(*(ClipMeans(v) for v in draw(b.n_clips, 2)), n_resamples=1000)
    assert ci.half_width <= 0.01


def test_sizing_separates_clip_noise_from_a_true_seed_spread():
    """16 networks (a variance from 16 values is stable across random draws): without a network effect
    the seed-only interval is attributed to clip noise (nothing seed-limited, h_s small); with a
    network-to-network spread of the loss (sd ≈ 0.05) the realisation is flagged as seed-limited."""
    from fsdvs_hw.explore.paired import encode_evidence
    from fsdvs_hw.explore.sizing import size_test_sets

    def pts(spread, seed, n_seeds=16):
        g = np.random.default_rng(seed)
        ref, cand = [], []
        mid = (n_seeds - 1) / 2
        for s in range(n_seeds):
            ok = g.uniform(size=600) < 0.85
            p_flip = 0.10 + spread * (s - mid) / mid  # this network's share of clips the candidate loses
            cand.append(np.where(g.uniform(size=600) < p_flip, 0.0, ok))
            ref.append(ok.astype(float))

        def pt(key, arm):
            rec = {"status": "ok", "evidence": [encode_evidence(ClipMeans(v)) for v in arm]}
            return {
                "key": key,
                "realisation": key,
                "params": {},
                "status": "ok",
                "result": {"tasks": {"recognition": {"simulator": rec}}},
            }

        return [pt("learned", ref), pt("delta", cand)]

    for draw in (3, 11):
        (quiet,) = size_test_sets(pts(0.0, draw), target_half_width=0.01, n_resamples=1000)
        assert quiet.seed_limited == {} and quiet.h_seed < 0.008 and quiet.n_clips is not None
        (spread,) = size_test_sets(pts(0.08, draw), target_half_width=0.01, n_resamples=1000)
        assert spread.seed_limited["delta"] > 0.012 and spread.n_clips is None


# --------------------------------------------------------------------------- nested design (each network its own clips)
def _nested(rng, s, m, delta, *, sd_seed=0.03, sd_clip=0.3, sd_noise=0.2):
    """Network k scores its own ``m`` clips; the population difference is ``delta``."""
    ref, cand = [], []
    for k in range(s):
        base = rng.normal(0.6, 0.3, m)
        a = rng.normal(0, sd_seed)
        r = base + rng.normal(0, sd_noise, m)
        ref.append(ClipMeans(r))
        cand.append(ClipMeans(r - delta - a - rng.normal(0, sd_clip, m)))
    return ref, cand


@pytest.mark.parametrize("sd_seed", [0.0, 0.04])
def test_nested_cluster_ci_covers_the_known_difference_in_at_least_90_percent_of_200_draws(sd_seed):
    rng = np.random.default_rng(30)
    delta, hits, widths = 0.05, 0, []
    for draw in range(200):
        ref, cand = _nested(rng, 24, 40, delta, sd_seed=sd_seed)
        ci = difference_ci(ref, cand, nested_clips=True, n_resamples=400, rng=draw)
        hits += ci.low <= delta <= ci.high
        widths.append(ci.half_width)
    assert hits >= 180, hits
    # and it is not trivially wide: the half-width is within 25 % of the normal-theory value
    se = np.sqrt((sd_seed**2 + 0.3**2 / 40) / 24)
    assert abs(np.mean(widths) / (1.96 * se) - 1) < 0.25, np.mean(widths) / (1.96 * se)


def test_nested_ci_reports_its_design_and_totals_and_isolates_the_clip_part():
    rng = np.random.default_rng(31)
    ref, cand = _nested(rng, 12, 30, 0.05, sd_seed=0.08)
    ci = difference_ci(ref, cand, nested_clips=True, n_resamples=500)
    assert ci.clip_design == "nested" and ci.n_clips == 12 * 30 and ci.n_seeds_reference == 12
    assert ci.resampled == ("clips", "seeds") and ci.seed_variance_included
    clips_only = difference_ci(ref, cand, nested_clips=True, resample=("clips",), n_resamples=500)
    assert clips_only.resampled == ("clips",) and clips_only.half_width < 0.6 * ci.half_width
    assert abs(clips_only.estimate - ci.estimate) < 1e-12
    # the estimate is the mean of the per-network differences
    per = [r.weighted(np.ones((1, 30)))[0] - c.weighted(np.ones((1, 30)))[0] for r, c in zip(ref, cand)]
    assert abs(ci.estimate - np.mean(per)) < 1e-12


def test_nested_clips_may_differ_per_network_but_must_match_between_kernels():
    rng = np.random.default_rng(32)
    ref = [ClipMeans(rng.normal(size=n)) for n in (10, 20, 30)]
    cand = [ClipMeans(rng.normal(size=n)) for n in (10, 20, 30)]
    assert difference_ci(ref, cand, nested_clips=True, n_resamples=200).n_clips == 60
    with pytest.raises(InputError, match="network 1 scored 20 clips"):
        difference_ci(ref, [cand[0], ClipMeans(np.zeros(21)), cand[2]], nested_clips=True, n_resamples=200)
    with pytest.raises(InputError, match="nested clips need paired_seeds"):
        difference_ci(ref, cand, nested_clips=True, paired_seeds=False, n_resamples=200)


def test_nested_sizing_gives_clips_per_network_that_reach_the_target_on_a_fresh_draw():
    """A nested pilot (24 networks × 60 clips, a modest seed spread): size_test_sets returns clips per
    network; a fresh nested draw at that size resolves ± 0.01 (and a large seed spread is flagged)."""
    from fsdvs_hw.explore.paired import encode_evidence
    from fsdvs_hw.explore.sizing import size_test_sets

    def draw(seed, m, sd_seed, n_seeds=24):
        g = np.random.default_rng(seed)
        ref, cand = [], []
        for _ in range(n_seeds):
            ok = (g.uniform(size=m) < 0.85).astype(float)
            p_flip = float(np.clip(0.10 + g.normal(0, sd_seed), 0, 1))
            ref.append(ok)
            cand.append(np.where(g.uniform(size=m) < p_flip, 0.0, ok))
        return ref, cand

    def pts(ref, cand):
        def pt(key, arm):
            rec = {
                "status": "ok",
                "test_clips": "per_network",
                "evidence": [encode_evidence(ClipMeans(v)) for v in arm],
            }
            return {
                "key": key,
                "realisation": key,
                "params": {},
                "status": "ok",
                "result": {"tasks": {"recognition": {"simulator": rec}}},
            }

        return [pt("learned", ref), pt("delta", cand)]

    (b,) = size_test_sets(pts(*draw(1, 60, 0.01)), target_half_width=0.01, n_resamples=1000)
    assert b.nested and b.n_pilot == 60 and b.n_clips is not None and b.n_clips % 16 == 0
    # var per clip ≈ 0.085·0.915 ≈ 0.078 → m ≈ 1.15 · 1.96² · 0.078 / (24 · 0.01²) ≈ 140 with no seed part
    assert 100 <= b.n_clips <= 400, b.n_clips
    ref, cand = draw(2, b.n_clips, 0.01)
    ci = difference_ci([ClipMeans(v) for v in ref], [ClipMeans(v) for v in cand], nested_clips=True, n_resamples=1000)
    assert ci.half_width <= 0.01, ci.half_width
    (wide,) = size_test_sets(pts(*draw(3, 60, 0.06)), target_half_width=0.01, n_resamples=1000)
    assert wide.n_clips is None and wide.seed_limited["delta"] > 0.01
