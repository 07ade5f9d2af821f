"""Task metrics against hand-computed cases (pycocotools / torchmetrics underneath)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.tasks.metrics import detection_map, segmentation_scores, top1_accuracy

GT = np.array([[[0, 0, 10, 10], [20, 20, 30, 30]], [[5, 5, 15, 12], [np.nan] * 4]], float)
GL = np.array([[0, 1], [2, -1]])


def _det(boxes, scores, labels, gt=GT, gl=GL, n=3):
    return detection_map(np.asarray(boxes, float), np.asarray(scores, float), np.asarray(labels), gt, gl, num_classes=n)


def test_detection_perfect_predictor_scores_one():
    m = _det(np.nan_to_num(GT), [[0.9, 0.8], [0.7, 0.0]], GL)
    assert m == pytest.approx({"map": 1.0, "map_50": 1.0, "map_75": 1.0})


def test_detection_half_recall_is_51_of_101():
    gt = GT[:1]
    gl = np.array([[0, 0]])
    m = _det(gt[:, :1], [[0.9]], [[0]], gt=gt, gl=gl, n=1)
    # COCO: 101 recall points; recall 0..0.5 (51 points) at precision 1, the rest 0
    assert m["map"] == pytest.approx(51 / 101) and m["map_50"] == pytest.approx(51 / 101)


def test_detection_iou_0625_counts_for_three_of_ten_thresholds():
    gt = np.array([[[0, 0, 10, 10]]], float)
    gl = np.array([[0]])
    m = _det([[[0, 0, 10, 6.25]]], [[0.9]], [[0]], gt=gt, gl=gl, n=1)  # IoU 62.5/100
    assert m["map_50"] == pytest.approx(1.0)
    assert m["map_75"] == pytest.approx(0.0)
    assert m["map"] == pytest.approx(0.3)  # matches at IoU thresholds .50, .55, .60 of ten


def test_detection_constant_and_wrong_class_predictors_score_zero():
    const = np.tile([[[40.0, 40.0, 48.0, 48.0]]], (2, 1, 1))  # same box everywhere, far from all objects
    assert _det(const, [[0.9], [0.9]], [[0], [0]])["map"] == 0.0
    wrong = _det(np.nan_to_num(GT), [[0.9, 0.8], [0.7, 0.0]], [[1, 2], [0, -1]])
    assert wrong["map"] == 0.0
    assert _det(np.zeros((2, 0, 4)), np.zeros((2, 0)), np.zeros((2, 0), int))["map"] == 0.0


def test_detection_ranking_matters():
    # a false positive scored above the true one halves precision at every recall level of class 0
    gt = np.array([[[0, 0, 10, 10]]], float)
    gl = np.array([[0]])
    m = _det([[[0, 0, 10, 10], [30, 30, 40, 40]]], [[0.5, 0.9]], [[0, 0]], gt=gt, gl=gl, n=1)
    assert m["map_50"] == pytest.approx(0.5)


def test_detection_bad_input():
    with pytest.raises(InputError, match="batch sizes"):
        _det(np.zeros((1, 1, 4)), [[1.0]], [[0]])
    with pytest.raises(InputError, match="shapes"):
        _det(np.zeros((2, 1, 3)), [[1.0], [1.0]], [[0], [0]])
    with pytest.raises(InputError, match="no ground-truth"):
        _det(np.zeros((1, 1, 4)), [[1.0]], [[0]], gt=np.full((1, 1, 4), np.nan), gl=np.array([[-1]]))
    with pytest.raises(InputError, match="label 5"):
        _det(np.zeros((2, 1, 4)), [[1.0], [1.0]], [[5], [0]])


def test_top1_hand_cases():
    y = torch.tensor([0, 0, 1, 2])
    assert top1_accuracy(torch.nn.functional.one_hot(y, 3).float(), y, num_classes=3)["top1"] == 1.0
    # a constant predictor scores the frequency of its class
    assert top1_accuracy(torch.zeros(4, dtype=torch.long), y, num_classes=3)["top1"] == pytest.approx(0.5)
    assert top1_accuracy(torch.full((4,), 2), y, num_classes=3)["top1"] == pytest.approx(0.25)
    logits = torch.tensor([[2.0, 1, 0], [0, 3, 1], [0, 1, 0.5], [0, 0, 1]])
    assert top1_accuracy(logits, y, num_classes=3)["top1"] == pytest.approx(0.75)
    with pytest.raises(InputError):
        top1_accuracy(torch.zeros(3, 2), y, num_classes=3)


def test_segmentation_hand_cases():
    t = torch.tensor([[[0, 0, 1], [0, 2, 2]]])  # 3 background, 1 of class 1, 2 of class 2
    perfect = segmentation_scores(t, t, num_classes=4)
    assert perfect == pytest.approx({"miou": 1.0, "macc": 1.0, "pixel_accuracy": 1.0})
    const = segmentation_scores(torch.zeros_like(t), t, num_classes=4)
    # background everywhere: PA = 3/6, IoU_bg = 3/6 and 0 for classes 1, 2 -> mIoU = 0.5/3; mAcc = 1/3
    assert const["pixel_accuracy"] == pytest.approx(0.5)
    assert const["miou"] == pytest.approx(0.5 / 3)
    assert const["macc"] == pytest.approx(1 / 3)
    p = torch.tensor([[[0, 1, 1], [0, 2, 0]]])
    s = segmentation_scores(p, t, num_classes=4)
    # IoU: bg 2/4, c1 1/2, c2 1/2 ; recall: bg 2/3, c1 1, c2 1/2 ; PA 4/6
    assert s["miou"] == pytest.approx((0.5 + 0.5 + 0.5) / 3)
    assert s["macc"] == pytest.approx((2 / 3 + 1 + 0.5) / 3)
    assert s["pixel_accuracy"] == pytest.approx(4 / 6)


def test_segmentation_bad_input():
    with pytest.raises(InputError, match="pred and target"):
        segmentation_scores(torch.zeros(1, 2, 2), torch.zeros(1, 2, 3), num_classes=2)
    with pytest.raises(InputError, match="target classes"):
        segmentation_scores(torch.zeros(1, 2, 2), torch.full((1, 2, 2), 7), num_classes=2)
