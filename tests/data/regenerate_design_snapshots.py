"""Rewrite tests/data/design_snapshots.json from the shipped designs (run after a deliberate change
to the design schema, e.g. a new section, and say so in the commit):

    python tests/data/regenerate_design_snapshots.py
"""

import json
from pathlib import Path

from fsdvs_hw.design import load_design

REPO = Path(__file__).resolve().parents[2]
snap = {
    p.name: {"data": load_design(p).to_dict(), "fingerprint": load_design(p).fingerprint()}
    for p in sorted((REPO / "designs").glob("*.toml"))
}
(REPO / "tests" / "data" / "design_snapshots.json").write_text(json.dumps(snap, indent=1) + "\n")
print(f"{len(snap)} designs")
