"""``[rate]`` (matched event rate, fsdvs_hw.explore.matched) on a ``[tasks.datasets.<task>]`` task.

Frames + label PNGs (8 frames, 6 clips of 3) with the toy voxel network beside the design; explore
with learned + delta and ``[rate]`` on: the reference curves are measured in the user's network on
the user's clips (the plain DVS and the learned kernel at 0.1 and 0.4 besides the operating 0.2).
A point compared with its own curve at its own rate must give exactly 0 (the curve passes through
it), the event rate must fall with the threshold, and a rerun must reuse the saved curve points.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

pytest.importorskip("torch")
from conftest import cheap_design
from test_user_datasets import PLUGINS, _masks, _write_masks

SOURCE = (
    'format = "mask_frames", root = "seg", frames = "img", masks = "lbl", num_classes = 3, n_frames = 3, '
    "clip_stride = 1, fps = 25.0"
)
TABLE = f"""
[rate]
enabled = true
thresholds = [0.1, 0.4]

[tasks.datasets.segmentation]
network = "toy_network:make_voxel"
network_options = {{ task = "segmentation" }}
dataset = {{ {SOURCE} }}
"""


def _folder(tmp_path: Path) -> Path:
    _write_masks(tmp_path / "seg", *_masks(8))
    shutil.copy(PLUGINS / "toy_network.py", tmp_path / "toy_network.py")
    return tmp_path


def test_dataset_rate_curve_pairs_with_the_explored_score(tmp_path, monkeypatch):
    from fsdvs_hw.design import load_design
    from fsdvs_hw.explore.rate import dataset_rate_curve
    from fsdvs_hw.explore.user_data import dataset_evidence

    folder = _folder(tmp_path)
    (folder / "d.toml").write_text(cheap_design("d") + TABLE)
    monkeypatch.syspath_prepend(str(folder))
    entry = load_design(folder / "d.toml").data["tasks"]["datasets"]["segmentation"]
    curve = dataset_rate_curve(None, "segmentation", entry, folder, [0.1, 0.2, 0.4], cache_dir=tmp_path / "c")
    assert curve.thresholds == (0.1, 0.2, 0.4) and curve.n_networks == 1 and curve.n_clips == 6
    rates = [p.rate for p in curve.points]
    assert rates[0] > rates[1] > rates[2] > 0
    own, _ = dataset_evidence(None, "segmentation", entry, folder)  # the exploration's score (threshold 0.2)
    mid = curve.points[1]
    assert mid.metric == pytest.approx(own.value, abs=1e-12)
    assert mid.clip_rates[0] == pytest.approx(own.clip_event_rates, rel=1e-12)
    assert (mid.test_seeds, mid.sensor_seeds) == ((own.test_seed,), (own.sensor_seed,))
    again = dataset_rate_curve(
        None,
        "segmentation",
        {**entry, "dataset": {**entry["dataset"], "cache": {"dir": "cc", "max_mb": 8.0}}},
        folder,
        [0.1, 0.2, 0.4],
        cache_dir=tmp_path / "c",
    )  # saved points reused
    assert [p.seconds for p in again.points] == [p.seconds for p in curve.points]


@pytest.mark.slow
def test_rate_section_measures_curves_in_the_user_network_and_clips(tmp_path, monkeypatch):
    from fsdvs_hw.cli import main
    from fsdvs_hw.explore import user_data

    _folder(tmp_path)
    design = tmp_path / "rate.toml"
    design.write_text(cheap_design("rate") + "[scoring]\nn_resamples = 200\n" + TABLE)
    out = tmp_path / "out"
    assert main(["explore", str(design), "--out", str(out), "--no-progress"]) == 0
    points = {p["realisation"]: p for p in json.loads((out / "scores.json").read_text())["points"]}
    for ref, name in (("delta", "gain_over_plain_dvs_at_matched_rate"), ("learned", "loss_at_matched_rate")):
        rec = points[ref]["matched_rate"]["segmentation"]
        own = rec[name]  # the reference's own point against its own curve
        assert own["status"] == "ok", own["status"]
        assert own["estimate"] == pytest.approx(0.0, abs=1e-12) and own["matched_threshold"] == pytest.approx(0.2)
        curve = rec["curve"]
        assert [round(p["threshold"], 6) for p in curve] == [0.1, 0.2, 0.4] and all(p["n_clips"] == 6 for p in curve)
        rates = [p["rate"] for p in curve]
        assert rates[0] > rates[1] > rates[2] > 0
    assert len(list((out / "rate_curves").rglob("*.json"))) == 4  # 2 references x 2 extra thresholds
    calls = []
    monkeypatch.setattr(user_data, "dataset_evidence", lambda *a, **k: calls.append(1))
    out2 = tmp_path / "out2"
    shutil.copytree(out, out2)
    assert main(["explore", str(design), "--out", str(out2), "--no-progress"]) == 0  # points and curves reused
    assert calls == []
