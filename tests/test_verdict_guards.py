"""A verdict that knows when it cannot answer: hard limits veto 'build' and say what
would fit; a task at chance or with degenerate intervals is 'not measurable'; the verdict opens
with the kernel against a plain DVS at equal event rate; a cross-kind 'cheapest' sentence names
the assumption key that flips it and the value at which it does."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.costs import CostAssumptions, physical_cost
from fsdvs_hw.costs.limits import assumption_at, cost_flips, costed, shared_node_error
from fsdvs_hw.design import parse_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.records import Score, ScoredPoint
from fsdvs_hw.stats import ClipMeans, CocoDetections, ConfusionMIoU, chance_metric

sys.path.insert(0, str(Path(__file__).parent))
from test_costs import _asic_point  # noqa: E402  (a scored DoG realisation with a measured event rate)


def _rows(raw, design):
    from fsdvs_hw.explore.costing import with_physical_costs
    from fsdvs_hw.report.costs import with_cost_columns
    from fsdvs_hw.report.tables import score_rows

    points = with_physical_costs([ScoredPoint.from_dict(p) for p in raw], design)
    return with_cost_columns(score_rows(points), points), points


# --------------------------------------------------------------------------- hard limits
@pytest.fixture(scope="module")
def mesh_point():
    return _asic_point(100.0, key="m", realisation="mesh")


def test_a_mesh_larger_than_the_pixel_is_never_build_and_the_verdict_says_what_would_fit(mesh_point):
    from fsdvs_hw.report.verdict import advice, verdict_table

    design = parse_design({"realisations": {"include": ["learned", "mesh", "asic"]}, "costs": {"loss_budget": 1.0}})
    rows, _ = _rows([mesh_point, _asic_point(100.0, key="a")], design)
    mesh = next(r for r in rows if r["realisation"] == "mesh")
    pitch = 4.86e-6
    assert mesh["area_m2"] > pitch**2 and mesh["fits"] is False  # the default MIM capacitors: ~108 µm²
    said = " ".join(advice(rows))
    assert "Build resistive mesh" not in said
    words = {v["realisation"]: v["verdict"] for v in verdict_table(rows)}
    assert words["resistive mesh"].startswith("does not fit: area") and "(sensor.pitch_m)" in words["resistive mesh"]
    # the pitch at which it fits is sqrt(area), from the cost model's own area
    assert f"a pixel pitch of at least {math.sqrt(mesh['area_m2']) * 1e6:.3g} µm (now 4.86 µm)" in said
    assert "one mesh node shared by" in said and "costs.capacitor_density_f_m2 above" in said


def test_every_remedy_meets_its_limit_in_the_cost_model(mesh_point):
    score = Score.from_dict(mesh_point["result"])
    a = CostAssumptions()
    pc = costed(score, a)
    (lim,) = pc.limits
    assert lim["figure"] == "area_m2" and lim["limit"] == pytest.approx(4.86e-6**2)
    keyed = [r for r in lim["remedies"] if r["key"].startswith("costs.")]
    assert keyed, lim["remedies"]
    for r in keyed:
        fixed = physical_cost(score, a.model_copy(update={r["key"].split(".", 1)[1]: r["value"]}))
        assert fixed.value("area_m2") == pytest.approx(4.86e-6**2, rel=1e-6)  # exactly at the pixel's area
    shared = next(r for r in lim["remedies"] if r["key"] == "placement.shared_node")
    k = int(shared["value"])
    assert pc.value("area_m2") / k**2 <= 4.86e-6**2 < pc.value("area_m2") / (k - 1) ** 2  # the smallest k that fits
    assert 0.0 < shared["kernel_error"] <= 1.0


def test_a_latency_budget_vetoes_the_asic_and_the_sample_rate_that_meets_it_is_exact():
    from fsdvs_hw.report.verdict import verdict_table

    design = parse_design(
        {"realisations": {"include": ["learned", "asic"]}, "costs": {"loss_budget": 1.0, "latency_budget_s": 1e-4}}
    )
    raw = _asic_point(100.0, key="a")
    rows, points = _rows([raw], design)
    assert rows[0]["fits"] is False and "latency" in rows[0]["cost_flags"]
    assert verdict_table(rows)[0]["verdict"].startswith("does not fit: latency")
    (lim,) = points[0].physical_cost.limits
    fs = next(r for r in lim["remedies"] if r["key"] == "costs.sample_rate_hz")
    score = Score.from_dict(raw["result"])
    a = design.spec.costs.model_copy(update={"sample_rate_hz": fs["value"]})
    assert physical_cost(score, a).value("latency_s") == pytest.approx(1e-4, rel=1e-7) and fs["value"] > 1e3


def test_assumption_at_inverts_a_linear_cost_exactly():
    score = Score.from_dict(_asic_point(100.0)["result"])
    a = CostAssumptions()
    p0 = physical_cost(score, a).value("power_w")
    (fs,) = assumption_at(score, a, "costs.sample_rate_hz", "power_w", 3.7 * p0)
    assert fs == pytest.approx(3700.0, rel=1e-8)  # P = E·HW·f_s
    assert assumption_at(score, a, "costs.sample_rate_hz", "power_w", 1e6) == []  # beyond the key's range
    for key in ("costs.no_such_key", "costs.array_resolution", "sample_rate_hz"):  # unknown, not a number, no section
        with pytest.raises(InputError, match=rf"key '{key}': not a number of the \[costs\] section; allowed: "):
            assumption_at(score, a, key, "power_w", 2 * p0)


def test_the_mesh_conductance_is_scanned_over_the_range_a_design_allows(mesh_point):
    from _schema_view import view

    from fsdvs_hw.costs.limits import MESH_CONDUCTANCE
    from fsdvs_hw.realise.mesh import MeshOptions

    score, a = Score.from_dict(mesh_point["result"]), CostAssumptions()
    g0, tau0 = score.cost.value("g_lateral_narrow"), physical_cost(score, a).value("latency_s")  # tau ∝ 1/g
    opt = view(MeshOptions, "g_lateral_s")
    for g, reached in ((2 * opt.lo, True), (0.5 * opt.hi, True), (0.5 * opt.lo, False), (2 * opt.hi, False)):
        roots = assumption_at(score, a, MESH_CONDUCTANCE, "latency_s", tau0 * g0 / g)
        assert roots == ([pytest.approx(g, rel=1e-8)] if reached else []), (g, roots)


def test_shared_node_error_bounds():
    delta = np.zeros((7, 7))
    delta[3, 3] = 1.0
    y, x = np.mgrid[-3:4, -3:4]
    broad = np.exp(-(x**2 + y**2) / (2 * 3.0**2))
    assert shared_node_error(delta, 1) == 0.0
    for k in (2, 3, 4):
        e_delta, e_broad = shared_node_error(delta, k), shared_node_error(broad, k)
        assert 0.0 < e_broad < e_delta <= 1.0  # a smooth kernel survives a coarse node lattice better
    # a kernel that is already the phase average of a shared node (box * box / k²) is reproduced exactly
    from scipy.signal import convolve2d

    box = np.ones((3, 3))
    placed = convolve2d(convolve2d([[1.0]], box), box) / 9  # one node, 3 × 3 pixels: a 5 × 5 pyramid
    assert shared_node_error(placed, 3) < 1e-10


# --------------------------------------------------------------------------- assumption flips
@pytest.fixture(scope="module")
def fitting_pair():
    """A mesh that fits (dense node capacitors) and 8-bit taps, both within the loss budget."""
    return _asic_point(100.0, key="m", realisation="mesh"), _asic_point(100.0, key="a")


def test_one_cost_key_flips_the_cheapest_sentence_which_names_the_key_and_the_flip_value(fitting_pair):
    from fsdvs_hw.report.costs import cost_advice

    costs = {"loss_budget": 1.0, "capacitor_density_f_m2": 0.05}
    design = parse_design({"realisations": {"include": ["learned", "mesh", "asic"]}, "costs": costs})
    mesh, asic = (Score.from_dict(p["result"]) for p in fitting_pair)
    flip = next(f for f in cost_flips(asic, mesh, design.spec.costs, "power_w") if f["key"] == "costs.sample_rate_hz")
    # the flip value is where the two cost models give equal power
    at = design.spec.costs.model_copy(update={"sample_rate_hz": flip["value"]})
    assert physical_cost(asic, at).value("power_w") == pytest.approx(physical_cost(mesh, at).value("power_w"), rel=1e-8)
    khz = f"{flip['value'] / 1e3:.3g} kHz"

    said = " ".join(cost_advice(_rows(list(fitting_pair), design)[0]))
    assert "least power: ASIC taps (" in said
    assert f"cheaper than resistive mesh only while costs.sample_rate_hz stays below {khz} (now 1 kHz)" in said

    # one key changed past the flip value: the sentence flips and names the same key and value
    design2 = parse_design(
        {
            "realisations": {"include": ["learned", "mesh", "asic"]},
            "costs": {**costs, "sample_rate_hz": 2 * flip["value"]},
        }
    )
    said2 = " ".join(cost_advice(_rows(list(fitting_pair), design2)[0]))
    assert "least power: resistive mesh (" in said2
    assert f"cheaper than ASIC taps only while costs.sample_rate_hz stays above {khz}" in said2


# --------------------------------------------------------------------------- chance and measurability
def test_chance_levels_by_hand():
    # top-1: always the most frequent class (class 2: 3 of 5 clips)
    m = ClipMeans.top1(np.eye(3)[[0, 1, 2, 2, 2]], np.array([2, 1, 2, 2, 0]))
    c, how = chance_metric(m)
    assert float(c.weighted(np.ones((1, 5)))[0]) == pytest.approx(0.6) and "class 2" in how
    # mIoU: every pixel the majority class (class 0: 6 of 8 pixels): IoU_0 = 6/8, IoU_1 = 0 → 0.375
    conf = np.array([[[3, 1], [0, 0]], [[2, 0], [1, 1]]], float)  # clip, true, predicted
    c, _ = chance_metric(ConfusionMIoU(conf))
    assert float(c.weighted(np.ones((1, 2)))[0]) == pytest.approx(0.375)
    # mAP: a detector that returns no boxes scores 0
    boxes = np.array([[[0, 0, 10, 10]], [[5, 5, 20, 20]]], float)
    det = CocoDetections.from_predictions(
        boxes, np.ones((2, 1)), np.zeros((2, 1)), boxes, np.zeros((2, 1)), num_classes=1
    )
    assert float(det.weighted(np.ones((1, 2)))[0]) == pytest.approx(1.0)
    c, _ = chance_metric(det)
    assert float(c.weighted(np.ones((1, 2)))[0]) == pytest.approx(0.0)
    # a top-1 metric stored without its labels: the chance level is unknown, never invented
    assert chance_metric(ClipMeans([1.0, 0.0])) is None


def _task_point(key, realisation, values, labels, classes=4, *, n_networks=2):
    """A scored reference/asic point whose recognition track holds per-clip top-1 evidence."""
    from fsdvs_hw.explore.paired import encode_evidence

    raw = _asic_point(100.0, key=key, realisation=realisation)
    res = raw["result"]
    ev = [encode_evidence(ClipMeans(v, labels=labels, num_classes=classes)) for v in values]
    res["tasks"] = {
        "status": "ok",
        "recognition": {
            "simulator": {
                "status": "ok",
                "metric": float(np.mean(values)),
                "metric_name": "top1",
                "per_seed": [float(np.mean(v)) for v in values],
                "n_seeds": n_networks,
                "n_clips": sum(len(v) for v in values),
                "n_clips_per_network": len(values[0]),
                "test_clips": "per_network",
                "test_seeds": list(range(n_networks)),
                "evidence": ev,
            }
        },
    }
    return raw


def _points(rows):
    return [ScoredPoint.from_dict(r) for r in rows]


def _chance_world(correct_ref, correct_cand, n=40, seed=0):
    rng = np.random.default_rng(seed)
    labels = np.arange(n) % 4  # balanced: chance = 1/4
    ref = [(rng.random(n) < correct_ref).astype(float) for _ in range(2)]
    cand = [(rng.random(n) < correct_cand).astype(float) for _ in range(2)]
    return [
        _task_point("L", "learned", ref, labels),
        _task_point("A", "asic", cand, labels),
    ]


def test_a_network_at_chance_is_not_measurable_and_no_verdict_rests_on_it():
    from fsdvs_hw.explore.measurability import measured_losses
    from fsdvs_hw.report.tables import accuracy_axis, score_rows
    from fsdvs_hw.report.verdict import advice, measurability_table

    points = measured_losses(_points(_chance_world(0.25, 0.25)), n_resamples=400)
    rec = points[0].extra["measurability"]["simulator"]["recognition"]
    assert rec["chance"] == pytest.approx(0.25) and rec["measurable"] is False
    assert "not above chance" in rec["reason"] and rec["above_chance"]["low"] <= 0.0
    rows = score_rows(points)
    assert rows[1]["recognition_loss_text"] == "not measurable"
    assert accuracy_axis(rows)[0] == "kernel_error"  # nothing measurable: no loss is claimed
    said = " ".join(advice(rows))
    assert "Not measurable: recognition — the learned kernel's top1" in said
    assert "no accuracy loss is claimed" in said and "no measurable accuracy loss" not in said
    table = measurability_table(rows)
    assert table[0]["chance"].startswith("0.250 (always class 0, the most frequent of 4") and table[0][
        "verdict"
    ].startswith("no:")


def test_a_trained_network_is_measurable_and_its_chance_level_is_shown():
    from fsdvs_hw.explore.measurability import measured_losses
    from fsdvs_hw.report.tables import accuracy_axis, score_rows
    from fsdvs_hw.report.verdict import measurability_table

    points = measured_losses(_points(_chance_world(0.9, 0.8)), n_resamples=400)
    rec = points[0].extra["measurability"]["simulator"]["recognition"]
    assert rec["measurable"] is True and rec["above_chance"]["low"] > 0.4
    rows = score_rows(points)
    assert accuracy_axis(rows)[0] != "kernel_error" and rows[1]["measurable_tasks"] == "recognition"
    assert "(network, clips) clusters of 2 networks" in measurability_table(rows)[0]["interval"]


def test_a_realisation_identical_on_every_clip_gets_the_rule_of_three_not_a_zero_width_interval():
    from fsdvs_hw.explore.measurability import measured_losses

    world = _chance_world(0.9, 0.9)
    # the candidate gives the reference's result on every clip; a third kernel (delta) does not
    world[1]["result"]["tasks"]["recognition"] = world[0]["result"]["tasks"]["recognition"]
    rng = np.random.default_rng(5)
    world.append(_task_point("D", "delta", [(rng.random(40) < 0.6).astype(float) for _ in range(2)], np.arange(40) % 4))
    points = measured_losses(_points(world), n_resamples=400)
    ci = points[1].paired_loss.tracks["simulator"]["recognition"]
    b = 1 - 0.05 ** (1 / 80)
    assert ci["degenerate"] is True and ci["high"] == pytest.approx(b) and ci["low"] == pytest.approx(-b)
    assert ci["text"] == f"no clip changed (n = 80): |loss| ≤ {b:.3f} (rule of three)"
    own = points[0].paired_loss.tracks["simulator"]["recognition"]  # the reference against itself: 0, not widened
    assert own["high"] == own["low"] == 0.0 and "degenerate" not in own
    assert (
        points[0].extra["measurability"]["simulator"]["recognition"]["measurable"] is True
    )  # one kernel alike is no reason
    # every kernel alike: the task cannot rank kernels
    world[2]["result"]["tasks"]["recognition"] = world[0]["result"]["tasks"]["recognition"]
    rec = measured_losses(_points(world), n_resamples=400)[0].extra["measurability"]["simulator"]["recognition"]
    assert rec["measurable"] is False and "every kernel's per-clip result is identical (3 kernels)" in rec["reason"]


def test_a_metric_undefined_on_its_clips_is_not_measurable_with_its_reason_not_nan():
    """A mean IoU over clips without a labelled pixel is NaN: the task reads "not measurable" with
    why, and no NaN interval is drawn around it."""
    from fsdvs_hw.explore.measurability import task_measurability
    from fsdvs_hw.explore.paired import encode_evidence

    world = _chance_world(0.9, 0.8)
    for p in world:
        track = p["result"]["tasks"]["recognition"]["simulator"]
        track["metric_name"] = "mIoU"
        track["evidence"] = [encode_evidence(ConfusionMIoU(np.zeros((40, 3, 3)))) for _ in range(2)]
    (per_setting,) = task_measurability(world, n_resamples=200).values()
    rec = per_setting["simulator"]["recognition"]
    assert rec["measurable"] is False and "above_chance" not in rec
    assert rec["reason"].startswith(
        "the learned kernel's mIoU is undefined on its 80 test clips (nothing to score: no labelled pixels or boxes)"
    )
    assert "nan" not in rec["reason"]


# --------------------------------------------------------------------------- the first question
def _first_question_rows(low, high, status="ok"):
    ref = {
        "status": "ok",
        "realisation": "learned",
        "key": "L",
        "loss_reference": "L",
        "detection_loss": 0.0,
        "detection_n_clips": 2048,
        "matched_rate_status": status,
        "detection_gain_over_plain_dvs_at_matched_rate": (low + high) / 2,
        "detection_gain_over_plain_dvs_at_matched_rate_ci95_low": low,
        "detection_gain_over_plain_dvs_at_matched_rate_ci95_high": high,
        "detection_gain_over_plain_dvs_at_matched_rate_threshold": 0.111,
    }
    return [ref]


@pytest.mark.parametrize(
    ("low", "high", "words"),
    [
        (-0.002, 0.014, "None of these gains is resolved above 0: building the filter gains nothing shown"),
        (0.004, 0.02, "The filter's gain holds at equal event rate on every measurable task"),
        (-0.03, -0.01, "None of these gains is resolved above 0"),
    ],
)
def test_the_verdict_opens_with_the_kernel_against_a_plain_dvs_at_equal_rate(low, high, words):
    from fsdvs_hw.report.verdict import first_question

    (line,) = first_question(_first_question_rows(low, high))
    assert line.startswith("First question — does the kernel beat a plain DVS at equal event rate?")
    assert f"detection {(low + high) / 2:+.3f} [{low:+.3f}, {high:+.3f}] (plain DVS at threshold 0.111; n = 2" in line
    assert words in line


def test_without_the_matched_rate_control_the_first_question_is_said_unanswered():
    from fsdvs_hw.report.verdict import first_question

    (line,) = first_question(_first_question_rows(0.0, 0.0, status="not requested ([rate] enabled = false)"))
    assert line.startswith("First question, not answered") and "[rate] enabled = false" in line


def test_a_refused_matched_rate_comparison_is_said_in_the_first_question_not_dropped():
    from fsdvs_hw.report.verdict import first_question

    [ref] = _first_question_rows(0.004, 0.02)
    ref["recognition_loss"] = 0.0
    ref["recognition_gain_over_plain_dvs_at_matched_rate_status"] = "refused: outside the plain DVS's curve"
    (line,) = first_question([ref])
    assert "detection +0.012 [+0.004, +0.020]" in line
    assert "recognition: refused: outside the plain DVS's curve" in line
    only = {k: v for k, v in ref.items() if not k.startswith("detection_gain")}
    (line,) = first_question([only])
    assert "recognition: refused" in line and line.endswith(
        "No task's comparison could be made, so the question stays open."
    )


def test_the_first_question_tells_held_open_and_worse_gains_apart():
    """An interval above 0 holds, one containing 0 is "not resolved" (never "not measurable": that
    word is kept for tasks at chance), one below 0 says the lowered-threshold DVS does better."""
    from fsdvs_hw.report.verdict import _gain_tail

    tail = _gain_tail([("recognition", 1), ("detection", 0), ("segmentation", -1)])
    assert tail.startswith("The filter's gain holds at equal event rate for recognition;")
    assert "for detection it is not resolved: the interval contains 0" in tail
    assert "for segmentation a plain DVS with a lowered threshold does better" in tail
    assert "not measurable" not in tail
    assert _gain_tail([("detection", 1)]) == "The filter's gain holds at equal event rate on every measurable task."
    assert _gain_tail([("detection", 0), ("recognition", -1)]).startswith("None of these gains is resolved above 0")
    assert _gain_tail([]).startswith("No task's comparison could be made")
