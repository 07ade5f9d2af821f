"""A report per class: per-class metrics with CIs (checked against torchmetrics and pycocotools), AP50/AP75,
the confusion matrix and the dataset summary, in the records and on the report page.
"""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest
from PIL import Image

torch = pytest.importorskip("torch")

from conftest import cheap_design

from fsdvs_hw.errors import InputError
from fsdvs_hw.stats import ClipMeans, CocoDetections, ConfusionMIoU
from fsdvs_hw.tasks.metrics import detection_map
from fsdvs_hw.tasks.per_class import confusion_matrix, per_class_metrics

SIDE = 16


# --------------------------------------------------------------------------- the numbers
def test_recognition_per_class_top1_is_torchmetrics_recall_and_its_ci_holds_it(rng):
    from torchmetrics.classification import MulticlassRecall

    labels = rng.integers(0, 4, 200)
    labels[labels == 3] = 2  # class 3 has no clip
    logits = rng.normal(size=(200, 4)) + 2.0 * np.eye(4)[labels] * (rng.random(200) < 0.6)[:, None]
    out = per_class_metrics(
        ClipMeans.top1(logits, labels), ["a", "b", "c", "d"], predicted=logits.argmax(1), n_resamples=500
    )
    recall = MulticlassRecall(num_classes=4, average="none")(torch.as_tensor(logits), torch.as_tensor(labels))
    for c, row in enumerate(out["classes"][:3]):
        assert row["n"] == int((labels == c).sum())
        assert row["value"] == pytest.approx(float(recall[c]), abs=1e-6)
        assert row["ci"][0] <= row["value"] <= row["ci"][1] and row["ci"][1] - row["ci"][0] > 0.05
    assert out["classes"][3] == {"name": "d", "n": 0}  # no clip: no value, no interval
    conf = np.array(out["confusion"])
    assert conf.sum() == 200 and (conf.sum(axis=1) == np.bincount(labels, minlength=4)).all()
    assert np.diag(conf)[:3] / conf.sum(axis=1)[:3] == pytest.approx([r["value"] for r in out["classes"][:3]])


def test_a_perfect_classifier_has_zero_width_intervals():
    labels = np.array([0, 1, 1, 2, 2, 2])
    out = per_class_metrics(ClipMeans.top1(np.eye(3)[labels], labels), predicted=labels, n_resamples=100)
    assert [r["value"] for r in out["classes"]] == [1.0, 1.0, 1.0]
    assert [r["ci"] for r in out["classes"]] == [[1.0, 1.0]] * 3
    assert out["confusion"] == np.diag([1, 2, 3]).tolist() and out["classes"][0]["name"] == "0"


def test_detection_per_class_ap50_ap75_are_pycocotools_on_each_category(rng):
    n = 14
    gb, gl = np.zeros((n, 2, 4)), np.zeros((n, 2), int)
    pb, ps, pl = np.zeros((n, 3, 4)), rng.random((n, 3)), np.zeros((n, 3), int)
    for i in range(n):
        gb[i] = [[2, 2, 10, 10], [20, 20, 30, 34]]
        gl[i] = [0, 1]
        pb[i, :2] = gb[i] + rng.normal(0, [[1.5], [3.0]], (2, 4))
        pl[i] = [0, 1, rng.integers(0, 2)]
        pb[i, 2] = [0, 0, 5, 5]
    out = per_class_metrics(CocoDetections.from_predictions(pb, ps, pl, gb, gl, num_classes=2), ["car", "bus"])
    whole = detection_map(pb, ps, pl, gb, gl, num_classes=2)
    for k in ("map", "map_50", "map_75"):
        assert out["overall"][k]["value"] == pytest.approx(whole[k], abs=1e-12)
        lo, hi = out["overall"][k]["ci"]
        assert lo <= whole[k] <= hi
    for c, row in enumerate(out["classes"]):
        one = detection_map(
            pb,
            ps,
            np.where(pl == c, 0, -1),
            np.where((gl == c)[..., None], gb, np.nan),
            np.where(gl == c, 0, -1),
            num_classes=1,
        )  # pycocotools on this category alone
        assert row["n"] == n
        assert (row["value"], row["ap50"], row["ap75"]) == pytest.approx(
            (one["map"], one["map_50"], one["map_75"]), abs=1e-12
        )
        assert row["ci"][0] <= row["value"] <= row["ci"][1] and row["ap50_ci"][0] <= row["ap50"] <= row["ap50_ci"][1]


def test_segmentation_per_class_iou_is_torchmetrics_jaccard(rng):
    from torchmetrics.classification import MulticlassJaccardIndex

    target = rng.integers(0, 3, (6, 8, 8))
    pred = np.where(rng.random((6, 8, 8)) < 0.7, target, rng.integers(0, 3, (6, 8, 8)))
    out = per_class_metrics(ConfusionMIoU.from_masks(pred, target, 3), n_resamples=300)
    jac = MulticlassJaccardIndex(num_classes=3, average="none")(torch.as_tensor(pred), torch.as_tensor(target))
    assert [r["value"] for r in out["classes"]] == pytest.approx(jac.tolist(), abs=1e-6)
    assert [r["n"] for r in out["classes"]] == np.bincount(target.ravel(), minlength=3).tolist()


def test_bad_settings_and_objects_are_refused():
    m = ClipMeans.top1(np.eye(2), np.array([0, 1]))
    with pytest.raises(InputError, match="n_resamples = 10"):
        per_class_metrics(m, n_resamples=10)
    with pytest.raises(InputError, match="allowed: ClipMeans"):
        per_class_metrics(object())
    with pytest.raises(InputError, match="without its labels"):
        per_class_metrics(ClipMeans([1.0, 0.0]))
    with pytest.raises(InputError, match=r"must be \(N,\)"):
        confusion_matrix([0, 1], [0], 2)


# --------------------------------------------------------------------------- the report
def _video(path: Path, gain: float, seed: int) -> None:
    base = 40 + 60 * np.random.default_rng(seed).random((SIDE, SIDE, 1))
    with imageio.get_writer(str(path), fps=25, codec="libx264", quality=9, macro_block_size=1) as w:
        for t in range(4):
            w.append_data(np.clip(base * gain**t, 0, 255).astype(np.uint8).repeat(3, axis=2))


def _coco(root: Path, n: int = 6) -> None:
    (root / "frames").mkdir(parents=True)
    images, anns = [], []
    for t in range(n):
        img = np.full((SIDE, SIDE), 50, np.uint8)
        img[4:10, 2 + t : 8 + t] = 220
        img[11:15, 10 - t // 2 : 14 - t // 2] = 150
        Image.fromarray(img).save(root / "frames" / f"f{t}.png")
        images.append({"id": t, "file_name": f"f{t}.png", "width": SIDE, "height": SIDE})
        anns.append({"id": 2 * t, "image_id": t, "category_id": 1, "bbox": [2 + t, 4, 6, 6]})
        anns.append({"id": 2 * t + 1, "image_id": t, "category_id": 2, "bbox": [10 - t // 2, 11, 4, 4]})
    cats = [{"id": 1, "name": "big"}, {"id": 2, "name": "small"}]
    (root / "instances.json").write_text(json.dumps({"images": images, "annotations": anns, "categories": cats}))


def test_the_report_shows_per_class_tables_ap50_ap75_confusion_matrix_and_dataset_summary(tmp_path):
    from fsdvs_hw.cli import main

    for cls, gain in (("Brighten", 1.4), ("Darken", 0.7)):
        (tmp_path / "ucf" / cls).mkdir(parents=True)
        for v in range(3):
            _video(tmp_path / "ucf" / cls / f"v_{cls}_g0{v}.mp4", gain, 10 * v + int(gain * 10))
    _coco(tmp_path / "coco")
    design = tmp_path / "d.toml"
    design.write_text(
        cheap_design("perclass")
        + "[scoring]\nn_resamples = 200\n"
        + '[tasks.datasets.recognition]\ndataset = { format = "video_folder", root = "ucf", n_frames = 4 }\n'
        + "[tasks.datasets.detection]\n"
        + 'dataset = { format = "coco_frames", root = "coco", n_frames = 2, clip_stride = 1, fps = 25.0 }\n'
    )
    out = tmp_path / "out"
    assert main(["explore", str(design), "--out", str(out), "--no-progress"]) == 0
    blob = json.loads((out / "scores.json").read_text())
    point = next(p for p in blob["points"] if p["realisation"] == "learned")
    rec = point["result"]["tasks"]["recognition"]["simulator"]
    summary = rec["dataset_summary"]
    assert summary["n_clips"] == 6 and summary["n_videos"] == 6 and summary["n_classes"] == 2
    assert summary["class_names"] == ["Brighten", "Darken"] and summary["n_frames"] == 4
    assert summary["resolution"] is None and summary["split_sizes"] == {"scored": 6}
    assert summary["fps"] == pytest.approx(25.0)  # the container's, read from the first clip
    pc = rec["per_class"]
    conf = np.array(pc["confusion"])
    assert conf.sum() == 6 and conf.sum(axis=1).tolist() == [3, 3]
    # the classes' top-1 weighted by their clips is the task's metric
    assert sum(r["value"] * r["n"] for r in pc["classes"]) / 6 == pytest.approx(rec["metric"])
    det = point["result"]["tasks"]["detection"]["simulator"]
    assert det["per_class"]["overall"]["map"]["value"] == pytest.approx(det["metric"], abs=1e-12)
    assert [r["name"] for r in det["per_class"]["classes"]] == ["big", "small"]
    assert det["dataset_summary"]["n_clips"] == 5 and det["dataset_summary"]["fps"] == 25.0

    html = (out / "report.html").read_text()
    section = html[html.index("<h2 id='per-class'>") :]
    assert "recognition: top-1 per class" in section and "detection: AP@[.50:.95] per class" in section
    for name in (
        "Brighten",
        "Darken",
        "big",
        "small",
        "AP50 (learned kernel (ideal))",
        "AP75 (learned kernel (ideal))",
    ):
        assert name in section
    first = pc["classes"][0]
    assert f"{first['value']:.3g}" in section  # the stored value is what the page shows
    assert "videos / sequences" in section and "frames per clip" in section and "25 Hz" in section
    assert "mAP@[.50:.95], AP50 and AP75 of every point" in section
    m = re.search(
        r'<figure id="fig-confusion-recognition"><img alt="([^"]*)"[^>]*src="data:image/png;base64,([^"]+)"', section
    )
    assert m is not None and "6 clips" in m.group(1)
    assert base64.b64decode(m.group(2))[:8] == b"\x89PNG\r\n\x1a\n"


def test_resampling_in_chunks_gives_the_same_intervals(rng, monkeypatch):
    """The bootstrap draws are taken in chunks to bound memory; the chunks are the same draws."""
    from fsdvs_hw.tasks import per_class

    target = rng.integers(0, 3, (9, 6, 6))
    pred = np.where(rng.random((9, 6, 6)) < 0.6, target, rng.integers(0, 3, (9, 6, 6)))
    metric = ConfusionMIoU.from_masks(pred, target, 3)
    whole = per_class_metrics(metric, n_resamples=200, seed=3)
    monkeypatch.setattr(per_class, "_MAX_WEIGHTS", 9 * 7)  # chunks of 7 resamples
    assert per_class_metrics(metric, n_resamples=200, seed=3) == whole
