"""Valid designs validate to the same dict, key order and fingerprint as before the schema moved
to pydantic (issue 28): ``tests/data/design_snapshots.json`` was written from the old engine."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fsdvs_hw.design import load_design

REPO = Path(__file__).resolve().parents[1]
SNAPSHOTS = json.loads((REPO / "tests" / "data" / "design_snapshots.json").read_text())


def test_every_shipped_design_has_a_snapshot():
    assert sorted(SNAPSHOTS) == sorted(p.name for p in (REPO / "designs").glob("*.toml"))


@pytest.mark.parametrize("name", sorted(SNAPSHOTS))
def test_validated_design_is_unchanged(name):
    d = load_design(REPO / "designs" / name)
    # same content and the same key order (json.dumps without sort_keys sees the order)
    assert json.dumps(d.to_dict()) == json.dumps(SNAPSHOTS[name]["data"])
    assert d.fingerprint() == SNAPSHOTS[name]["fingerprint"]
