"""Typed score records (fsdvs_hw.records): one serialisation, exact round trips, clear errors."""

from __future__ import annotations

import json
import math

import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.explore.scoring import fit_realisation, score
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.records import Cost, CostItem, Score, ScoredPoint, TaskScores, TrackScore, WallTimes
from fsdvs_hw.report.tables import score_rows


def _track(metric: float, **extra) -> dict:
    return {
        "status": "ok",
        "metric": metric,
        "metric_name": "top1",
        "per_seed": [metric - 0.01, metric + 0.01],
        "n_seeds": 2,
        "test_clips": "per_network",
        "n_clips": 200,
        "n_clips_per_network": 100,
        "test_seeds": [1000, 1001],
        "event_rate": 0.12,
        "wall_s": 3.5,
        **extra,
    }


@pytest.fixture(scope="module")
def asic_score() -> Score:
    k = reference_kernel("dog", 7)
    real, fit_s = fit_realisation("asic", k, {"bits": 6})
    return score(real, target=k, csf_methods=("mannos_sakrison_1974", "barten_1999"), fit_wall_s=fit_s)


def test_a_score_round_trips_through_json_exactly(asic_score):
    d = asic_score.to_dict()
    again = Score.from_dict(json.loads(json.dumps(d)))
    assert again.to_dict() == d
    assert again.kernel.allclose(asic_score.kernel, rtol=0, atol=0)
    assert again.cost.value("adders") == asic_score.cost.value("adders") > 0
    assert again.cost.unit("adders") == "count"
    assert math.isnan(again.cost.value("no such item")) and again.cost.unit("no such item") == ""


def test_unknown_keys_survive_a_round_trip_and_known_ones_are_typed():
    k = reference_kernel("dog", 5)
    d = {
        "kind": "box",
        "label": "box",
        "describe": "a box",
        "kernel": k.to_dict(),
        "kernel_error": 0.25,
        "kernel_error_gain_free": 0.2,
        "dc_gain": 0.0,
        "asymmetry": 0.0,
        "spectral": {"status": "ok"},
        "csf": {"status": "ok", "mannos_sakrison_1974": {"correlation": 0.8}},
        "cost": {"taps": {"value": 9, "unit": "count", "description": "taps"}},
        "tasks": {
            "status": "partial",
            "recognition": {
                "simulator": _track(0.9, networks=[{"seed": 0}]),
                "emulation": {"status": "unavailable: no display"},
            },
        },
        "emulation": {"status": "not requested"},
        "wall_s": {"fit": 1.0, "analysis": 2.0, "tasks": 3.0, "emulation": 4.0},
        "from_the_future": {"x": 1},
    }
    s = Score.from_dict(d)
    assert s.to_dict() == d
    assert s.extra == {"from_the_future": {"x": 1}}
    assert s.csf_correlation("mannos_sakrison_1974") == 0.8 and math.isnan(s.csf_correlation("daly_1993"))
    assert s.tasks.metrics() == {"recognition/simulator": 0.9}
    sim = s.tasks.tracks["recognition"]["simulator"]
    assert sim.n_clips == 200 and sim.per_seed == (0.89, 0.91) and sim.extra["networks"] == [{"seed": 0}]
    assert not s.tasks.tracks["recognition"]["emulation"].ok
    assert s.wall == WallTimes(1.0, 2.0, 3.0, 4.0)


def test_the_tables_read_the_typed_fields(asic_score):
    """A swapped field (kernel error ↔ gain-free error, fit ↔ analysis time) would show here."""
    p = ScoredPoint(key="k", realisation="asic", params={}, status="ok", score=asic_score)
    [row] = score_rows([p])
    [row_from_dict] = score_rows([ScoredPoint.from_dict(p.to_dict())])
    assert set(row) == set(row_from_dict)
    same = lambda a, b: a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))  # noqa: E731
    assert all(same(row[c], row_from_dict[c]) for c in row), [c for c in row if not same(row[c], row_from_dict[c])]
    assert row["kernel_error"] == asic_score.kernel_error != row["kernel_error_gain_free"]
    assert row["kernel_error_gain_free"] == asic_score.kernel_error_gain_free
    assert row["fit_s"] == asic_score.wall.fit_s and row["analysis_s"] == asic_score.wall.analysis_s
    assert row["cost_adders"] == asic_score.cost.value("adders")
    assert row["csf_agreement"] == asic_score.csf_correlation("mannos_sakrison_1974")


def test_a_failed_point_keeps_its_reason_and_traceback():
    d = {
        "key": "x",
        "realisation": "mesh",
        "params": {"mesh.g_max_s": 1.0},
        "status": "error",
        "result": {"reason": "ValueError: bad", "traceback": "Traceback ...", "warnings": ["W: w"]},
        "wall_s": 0.5,
        "worker": "h:1",
    }
    p = ScoredPoint.from_dict(d)
    assert not p.ok and p.score is None and p.reason == "ValueError: bad"
    assert p.to_dict() == d
    [row] = score_rows([p])
    assert row["status"] == "error" and row["reason"] == "ValueError: bad" and row["warnings"] == "W: w"


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"kind": "x"}, r"score: not a score record \(missing kernel, kernel_error\)"),
        ("not a dict", "score: expected a JSON object, got str"),
    ],
)
def test_a_malformed_score_names_what_is_missing(bad, match):
    with pytest.raises(InputError, match=match):
        Score.from_dict(bad)


def test_malformed_parts_name_their_field():
    with pytest.raises(InputError, match=r"cost.area: a cost item needs 'value' and 'unit'"):
        Cost.from_dict({"area": {"value": 1.0}})
    with pytest.raises(InputError, match=r"tasks.detection.simulator: status 'ok' but no numeric 'metric'"):
        TaskScores.from_dict({"status": "ok", "detection": {"simulator": {"status": "ok", "metric": None}}})
    with pytest.raises(InputError, match="cost item 'a': expected a CostItem"):
        Cost({"a": 1.0})
    with pytest.raises(InputError, match=r"point: missing field 'status'"):
        ScoredPoint.from_dict({"key": "k", "realisation": "mesh"})
    assert TrackScore.from_dict({"status": "unavailable: x"}).to_dict() == {"status": "unavailable: x"}
    assert Cost({"a": CostItem(1.0, "m^2")}).to_dict() == {"a": {"value": 1.0, "unit": "m^2", "description": ""}}


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("params", [1, 2], r"point k\.params: expected a JSON object, got list"),
        ("artifacts", 3, r"point k\.artifacts: expected a JSON list, got int"),
        ("cost_flips", {"a": 1}, r"point k\.cost_flips: expected a JSON list, got dict"),
        ("physical_cost_sweep", 5, r"point k\.physical_cost_sweep: expected a JSON list, got int"),
    ],
)
def test_a_malformed_stored_point_names_its_field(key, value, match):
    """scores.json is a user file the redraw reads: a wrong type is an InputError naming the field."""
    with pytest.raises(InputError, match=match):
        ScoredPoint.from_dict({"key": "k", "realisation": "mesh", "status": "error", "result": {}, key: value})


def test_a_cost_flip_with_a_non_numeric_value_names_its_field():
    from fsdvs_hw.records import CostFlip

    flip = {"cost": "power_w", "key": "costs.node", "value": "x", "now": 1.0, "other": "a", "cheaper": "b"}
    with pytest.raises(InputError, match=r"cost_flips\.value: expected a number, got 'x'"):
        CostFlip.from_dict(flip)


@pytest.mark.parametrize(
    "change, match",
    [
        ({"n_clips": "x"}, r"track\.n_clips: expected a number, got 'x'"),
        ({"n_seeds": None}, r"track\.n_seeds: expected a number, got None"),
        ({"per_seed": 0.5}, r"track\.per_seed: expected a JSON list, got float"),
        ({"per_seed": ["a"]}, r"track\.per_seed: expected a list of numbers"),
    ],
)
def test_a_malformed_track_score_names_its_field(change, match):
    with pytest.raises(InputError, match=match):
        TrackScore.from_dict({"status": "ok", "metric": 0.5, **change})


def test_the_shipped_scores_round_trip_through_the_typed_points_unchanged():
    """scores.json's points → ScoredPoint (paired losses, artifact links, physical cost, cost flips
    typed) → to_dict is the file's content, key order included."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "designs" / "results" / "demo" / "scores.json").read_text()
    stored = json.loads(text)["points"]
    points = [ScoredPoint.from_dict(p) for p in stored]
    assert all(p.physical_cost is not None and p.paired_loss is not None for p in points if p.ok)
    assert all(p.artifacts is not None and p.cost_flips is not None for p in points)
    back = [p.to_dict() for p in points]
    assert back == stored
    assert json.dumps(back, indent=1) == json.dumps(stored, indent=1)
