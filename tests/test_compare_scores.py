"""benchmarks/compare_scores.py: the field-by-field check that a refactor left make demo's scores alone."""

from __future__ import annotations

import copy
import json
from pathlib import Path

from benchmarks.compare_scores import compare, main

RECORD = Path(__file__).resolve().parents[1] / "designs" / "results" / "demo" / "scores.json"


def test_the_shipped_demo_record_equals_itself_and_one_changed_loss_is_found(tmp_path):
    a = json.loads(RECORD.read_text())
    assert compare(a, a) == []
    b = copy.deepcopy(a)
    b["rows"][3]["weighted_loss"] += 1e-12  # the smallest change is a difference
    b["points"][0]["wall_s"] += 5.0  # a timing is not
    b["points"][2]["result"]["describe"] = b["points"][2]["result"]["describe"].replace(" s\n", "1 s\n", 1)
    assert compare(a, b) == [
        f".rows[3].weighted_loss: {a['rows'][3]['weighted_loss']} vs {b['rows'][3]['weighted_loss']}"
    ]
    first, second = tmp_path / "a.json", tmp_path / "b.json"
    first.write_text(json.dumps(a))
    second.write_text(json.dumps(b))
    assert main([str(first), str(first)]) == 0 and main([str(first), str(second)]) == 1


def test_a_checkout_prefix_is_stripped_and_missing_fields_are_named():
    a = {"rows": [{"checkpoint": "designs/k.safetensors", "latency_s": 1.0}]}
    b = {"rows": [{"checkpoint": "/tmp/x/designs/k.safetensors", "latency_s": 2.0, "extra": 1}]}
    assert compare(a, b, strip="/tmp/x/") == [".rows[0].extra: only in the second", ".rows[0].latency_s: 1.0 vs 2.0"]


def test_a_result_in_si_units_ending_in_s_is_compared_and_a_row_timing_is_not():
    """``g_lateral_narrow_s`` (siemens) and ``event_rate_per_s`` are results; ``tasks_s`` is time spent."""
    a = {"rows": [{"tasks_s": 1.0, "g_lateral_narrow_s": 1e-8, "event_rate_per_s": {"mean": 32.5}}]}
    b = {"rows": [{"tasks_s": 9.0, "g_lateral_narrow_s": 2e-8, "event_rate_per_s": {"mean": 30.0}}]}
    assert compare(a, b) == [
        ".rows[0].event_rate_per_s.mean: 32.5 vs 30.0",
        ".rows[0].g_lateral_narrow_s: 1e-08 vs 2e-08",
    ]
