"""The shipped information result (designs/results/information) is what its evidence gives."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fsdvs_hw.studies.information import MATCHED, ConditionEvidence, information_table

SHIPPED = Path(__file__).resolve().parents[1] / "designs" / "results" / "information"
POINT_FIELDS = (
    "mi",
    "events_per_pixel",
    "rate",
    "bits_per_event",
    "mi_gain",
    "mi_gain_pct",
    "bits_per_event_gain",
    "r2",
    "mi_shuffled",
    "n_networks",
    "n_clips",
    "threshold",
)


def _shipped() -> tuple[dict, list[ConditionEvidence]]:
    stored = json.loads((SHIPPED / "information.json").read_text())
    by_name = {e.name: e for e in map(ConditionEvidence.from_npz, sorted((SHIPPED / "evidence").glob("*.npz")))}
    return stored, [by_name[name] for name in stored["settings"]["conditions"]]


def test_shipped_table_is_recomputed_from_its_evidence():
    stored, evidence = _shipped()
    rows = information_table(evidence, n_resamples=100)  # point values do not depend on the resamples
    for new, old in zip(rows, stored["rows"], strict=True):
        assert new["condition"] == old["condition"]
        for key in POINT_FIELDS:
            assert new[key] == pytest.approx(old[key], rel=1e-9), (old["condition"], key)
    vs = {r["condition"]: r for r in information_table(evidence, reference=MATCHED, n_resamples=100)}
    for old in stored["vs_matched_rate"]:
        assert vs[old["condition"]]["mi_gain"] == pytest.approx(old["mi_gain"], rel=1e-9)


def test_shipped_networks_carry_provenance():
    stored, _ = _shipped()
    for condition, names in stored["settings"]["networks"].items():
        for name in names:
            prov = json.loads((SHIPPED / "networks" / name.replace(".safetensors", ".provenance.json")).read_text())
            assert prov["task"] == "reconstruction" and prov["learn_filter"] is False, condition
            assert "versions" in prov and prov["n_train"] == stored["settings"]["n_train"]


def test_shipped_record_names_its_interval_method_exactly():
    """settings.bootstrap is the writer's exact text, and the interval is the bias-shifted percentile it names."""
    import numpy as np

    from fsdvs_hw.explore.paired import bootstrap_weights
    from fsdvs_hw.studies.information import BOOTSTRAP_METHOD, _condition_values

    stored, evidence = _shipped()
    assert stored["settings"]["bootstrap"] == BOOTSTRAP_METHOD
    assert "bias" in BOOTSTRAP_METHOD and "not BCa" in BOOTSTRAP_METHOD
    n = 300
    row = {r["condition"]: r for r in information_table(evidence, n_resamples=n, rng=7)}["learned"]
    learned = next(e for e in evidence if e.name == "learned")
    n_net, n_clips = np.shape(learned.events_per_pixel)
    ws, wc = bootstrap_weights(n_net, n_clips, test_clips="shared", n_resamples=n, rng=7)
    boot = _condition_values(learned, ws, wc)["mi"]
    a = (1 - 0.95) / 2
    shifted = np.quantile(boot - (boot.mean() - row["mi"]), [a, 1 - a])
    assert (row["mi_low"], row["mi_high"]) == pytest.approx(tuple(shifted), rel=1e-12)
    plain = np.quantile(boot, [a, 1 - a])  # the plain percentile interval is a different one here
    assert abs(plain[0] - shifted[0]) > 1e-6
