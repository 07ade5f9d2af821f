"""The shipped `make demo` record (designs/results/demo/scores.json, issue 38): its verdict, recomputed
from its rows by today's code, opens with the kernel against a plain DVS at equal event rate, never
recommends a realisation that breaks a hard limit and says what would make the mesh fit; every
point carries its matched-rate columns; every task shows its chance level."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from fsdvs_hw.report.verdict import advice, first_question, measurability_table, verdict_table

RECORD = Path(__file__).resolve().parents[1] / "designs" / "results" / "demo" / "scores.json"
TASKS = ("detection", "recognition", "segmentation")


@pytest.fixture(scope="module")
def shipped():
    data = json.loads(RECORD.read_text())
    rows = data["rows"]
    # the report's own column (not in the files): the measurability record of each point
    meas = {p["key"]: p.get("measurability") for p in data["points"]}
    return [{**r, "_measurability": meas.get(r["key"])} for r in rows], data


def test_the_demo_ran_the_default_design_with_the_rate_control(shipped):
    rows, data = shipped
    assert data["design"]["name"] == "default" and data["design"]["data"]["rate"]["enabled"] is True
    assert [r["realisation"] for r in rows] == ["learned", "delta", "mesh", "asic", "metalens", "metalens_layout"]
    assert all(r["status"] == "ok" for r in rows)


def test_every_point_carries_its_matched_rate_columns(shipped):
    rows, _ = shipped
    for r in rows:
        assert r["matched_rate_status"] == "ok", r["realisation"]
        for task in TASKS:
            col = f"{task}_gain_over_plain_dvs_at_matched_rate"  # the first question, for every point
            assert r[f"{col}_status"] == "ok" and math.isfinite(r[col]), (r["realisation"], col)
            assert r[f"{col}_ci95_low"] <= r[col] <= r[f"{col}_ci95_high"]
            col = f"{task}_loss_at_matched_rate"  # against the learned kernel: refused, never extrapolated,
            status = r[f"{col}_status"]  # where the point's rate lies outside the learned kernel's curve
            assert status == "ok" or status.startswith("refused: the reference rate"), (r["realisation"], status)
    refused = [r["realisation"] for r in rows if r["detection_loss_at_matched_rate_status"] != "ok"]
    assert refused == [
        "metalens",
        "metalens_layout",
    ]  # 5.6 and 5.3 events/pixel/s: below the learned kernel's rate at 0.45


def test_the_verdict_opens_with_the_kernel_against_a_plain_dvs_at_equal_rate(shipped):
    rows, _ = shipped
    lines = advice(rows)
    assert lines[0] == first_question(rows)[0]
    assert lines[0].startswith("First question — does the kernel beat a plain DVS at equal event rate?")
    ref = rows[0]
    held, lost = [], []
    for task in TASKS:
        col = f"{task}_gain_over_plain_dvs_at_matched_rate"
        lo, hi = ref[f"{col}_ci95_low"], ref[f"{col}_ci95_high"]
        assert f"{task} {ref[col]:+.3f} [{lo:+.3f}, {hi:+.3f}]" in lines[0]
        assert f"same threshold {ref[f'{col}_raw']:+.3f}" in lines[0]
        assert lo <= hi
        (held if lo > 0 else lost).append(task)
    assert "not measurable" not in lines[0]  # every task is measurable here: an open interval is "not resolved"
    if held and lost:  # the sentence says where the gain holds and where the interval cannot decide
        assert f"holds at equal event rate for {', '.join(held)}; for {', '.join(lost)} it is not resolved" in lines[0]
    elif not held:
        assert "None of these gains is resolved above 0" in lines[0]


def test_the_mesh_beyond_the_pixel_is_not_built_and_the_verdict_says_what_would_fit(shipped):
    rows, _ = shipped
    mesh = next(r for r in rows if r["realisation"] == "mesh")
    assert mesh["fits"] is False and mesh["area_m2"] > (4.86e-6) ** 2
    said = " ".join(advice(rows))
    assert "Build resistive mesh" not in said and "Build ASIC taps" in said
    assert f"a pixel pitch of at least {math.sqrt(mesh['area_m2']) * 1e6:.3g} µm" in said
    assert "one mesh node shared by 3 × 3 pixels" in said
    words = {v["realisation"]: v["verdict"] for v in verdict_table(rows)}
    assert words["resistive mesh"].startswith("does not fit: area 108 µm² > 23.6 µm²")
    assert words["ASIC taps"] == "build"


def test_every_task_shows_its_chance_level_and_can_measure(shipped):
    rows, _ = shipped
    table = measurability_table(rows)
    assert [t["task"] for t in table[:3]] == list(TASKS)
    assert table[0]["chance"].startswith("0.000 (a detector that returns no boxes")
    assert "the most frequent of 6 (top-1)" in table[1]["chance"]
    assert all(t["verdict"].startswith("yes") for t in table)
    assert rows[0]["measurable_tasks"] == "detection recognition segmentation"
