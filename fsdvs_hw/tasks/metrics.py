"""Task metrics, computed by maintained libraries (pycocotools, torchmetrics), never by hand.

* Detection: COCO mAP@[.50:.95], AP50 and AP75 from ``pycocotools.cocoeval.COCOeval`` (Lin et al.
  2014), the reference implementation used by the FS-DVS paper's Table I. (``torchmetrics``'
  ``MeanAveragePrecision`` wraps the same code but needs torchvision, which this CPU install does
  not carry.)
* Recognition: top-1 accuracy, ``torchmetrics.classification.MulticlassAccuracy(average="micro")``.
* Segmentation: mIoU (``MulticlassJaccardIndex(average="macro")``), mean class accuracy
  (``MulticlassAccuracy(average="macro")``) and pixel accuracy (``average="micro"``), as in the
  paper's Table III.

All functions return plain Python floats in [0, 1] (not percent).

References
----------
T.-Y. Lin et al., "Microsoft COCO: Common Objects in Context", ECCV 2014.
"""

from __future__ import annotations

import contextlib
import io
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = [
    "DETECTION_METRICS",
    "RECOGNITION_METRICS",
    "SEGMENTATION_METRICS",
    "detection_map",
    "segmentation_scores",
    "top1_accuracy",
]

DETECTION_METRICS = ("map", "map_50", "map_75")
RECOGNITION_METRICS = ("top1",)
SEGMENTATION_METRICS = ("miou", "macc", "pixel_accuracy")


def _as_numpy(x: Any, name: str, ndim: int | None = None) -> np.ndarray:
    try:
        arr = x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: expected an array ({exc})") from None
    if ndim is not None and arr.ndim != ndim:
        raise InputError(f"{name}: expected {ndim}-D, got shape {arr.shape}")
    return arr


def detection_map(
    pred_boxes: Any, pred_scores: Any, pred_labels: Any, gt_boxes: Any, gt_labels: Any, *, num_classes: int
) -> dict[str, float]:
    """COCO box mAP@[.50:.95], AP50 and AP75 (pycocotools, 101-point interpolation, maxDets 100).

    Parameters
    ----------
    pred_boxes : array, shape (N, K, 4)
        Predicted boxes ``(x0, y0, x1, y1)`` in pixels per image; rows with label < 0 or a NaN box
        are padding.
    pred_scores : array, shape (N, K)
        Confidence of each predicted box.
    pred_labels : array, int, shape (N, K)
        Class index in ``[0, num_classes)``, or -1 for padding.
    gt_boxes : array, shape (N, M, 4)
        Ground-truth boxes ``(x0, y0, x1, y1)``; NaN or label -1 marks unused slots.
    gt_labels : array, int, shape (N, M)
        Ground-truth class, -1 for unused slots.
    num_classes : int
        Number of classes (categories ``0 … num_classes-1``).

    Returns
    -------
    dict
        ``{"map", "map_50", "map_75"}`` in [0, 1]. COCO averages over categories that have ground
        truth; a category with ground truth but no detection counts 0. With no ground truth at all
        the metrics are undefined and :class:`InputError` is raised.

    Examples
    --------
    A perfect predictor scores 1; one of two objects found (score-ordered) scores 51/101 (COCO's
    101 recall points 0, 0.01, …, 0.5 have precision 1):

    >>> gt = np.array([[[0, 0, 10, 10], [20, 20, 30, 30]]], float); lab = np.array([[0, 0]])
    >>> round(detection_map(gt, np.ones((1, 2)), lab, gt, lab, num_classes=1)["map"], 6)
    1.0
    >>> round(detection_map(gt[:, :1], np.ones((1, 1)), lab[:, :1], gt, lab, num_classes=1)["map"], 6)
    0.50495
    """
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    from ..stats import coco_records

    pb = _as_numpy(pred_boxes, "pred_boxes", 3)
    ps = _as_numpy(pred_scores, "pred_scores", 2)
    pl = _as_numpy(pred_labels, "pred_labels", 2)
    gb = _as_numpy(gt_boxes, "gt_boxes", 3)
    gl = _as_numpy(gt_labels, "gt_labels", 2)
    if not (pb.shape[0] == ps.shape[0] == pl.shape[0] == gb.shape[0] == gl.shape[0]):
        raise InputError(
            f"detection_map: batch sizes differ: pred {pb.shape[0]}, {ps.shape[0]}, {pl.shape[0]}; "
            f"gt {gb.shape[0]}, {gl.shape[0]}"
        )
    if pb.shape[-1] != 4 or gb.shape[-1] != 4 or pb.shape[:2] != ps.shape or gb.shape[:2] != gl.shape:
        raise InputError(
            f"detection_map: shapes do not match: pred boxes {pb.shape}, scores {ps.shape}, "
            f"gt boxes {gb.shape}, labels {gl.shape} (boxes need a last axis of 4)"
        )
    images, anns, dets = coco_records(pb, ps, pl, gb, gl, num_classes=num_classes, who="detection_map")
    if not anns:
        raise InputError("detection_map: no ground-truth boxes; mAP is undefined")
    if not dets:
        return {k: 0.0 for k in DETECTION_METRICS}
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO()
        gt.dataset = {"images": images, "annotations": anns, "categories": [{"id": c} for c in range(num_classes)]}
        gt.createIndex()
        dt = gt.loadRes(dets)
        ev = COCOeval(gt, dt, iouType="bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    stats = [max(0.0, float(v)) for v in ev.stats[:3]]  # -1 means "no such gt"; none here
    return dict(zip(DETECTION_METRICS, stats))


def top1_accuracy(logits: Any, target: Any, *, num_classes: int) -> dict[str, float]:
    """Top-1 accuracy (torchmetrics ``MulticlassAccuracy``, micro average).

    Parameters
    ----------
    logits : tensor, shape (N, C) scores, or (N,) predicted class indices
    target : tensor, int, shape (N,)
    num_classes : int

    Returns
    -------
    dict
        ``{"top1": fraction correct}``. A constant predictor scores the frequency of its class.
    """
    import torch
    from torchmetrics.classification import MulticlassAccuracy

    p = torch.as_tensor(logits)
    t = torch.as_tensor(target).long()
    if t.ndim != 1 or p.shape[0] != t.shape[0] or p.ndim not in (1, 2) or (p.ndim == 2 and p.shape[1] != num_classes):
        raise InputError(
            f"top1_accuracy: logits must be (N, {num_classes}) or (N,) and target (N,); "
            f"got {tuple(p.shape)} and {tuple(t.shape)}"
        )
    if t.numel() == 0:
        raise InputError("top1_accuracy: empty target; accuracy is undefined")
    if p.ndim == 1:
        p = p.long()
    metric = MulticlassAccuracy(num_classes=num_classes, average="micro", top_k=1)
    return {"top1": float(metric(p, t))}


def segmentation_scores(
    pred: Any, target: Any, *, num_classes: int, ignore_index: int | None = None
) -> dict[str, float]:
    """mIoU, mean class accuracy and pixel accuracy (torchmetrics).

    Parameters
    ----------
    pred : tensor, int, shape (N, H, W)
        Predicted class per pixel.
    target : tensor, int, shape (N, H, W)
        True class per pixel.
    num_classes : int
        Number of classes including background.
    ignore_index : int, optional
        Target label of unlabelled pixels (e.g. 255 in Cityscapes): those pixels are left out of
        every score, whatever the prediction there.

    Returns
    -------
    dict
        ``miou`` (``MulticlassJaccardIndex``, macro average over classes present in target or
        prediction), ``macc`` (``MulticlassAccuracy``, macro average of per-class recall) and
        ``pixel_accuracy`` (micro average). Predicting background everywhere gives
        ``pixel_accuracy`` = background fraction, ``miou`` = background fraction / number of
        classes present, ``macc`` = 1 / number of classes present.
    """
    import torch
    from torchmetrics.classification import MulticlassAccuracy, MulticlassJaccardIndex

    p = torch.as_tensor(pred).long()
    t = torch.as_tensor(target).long()
    if p.shape != t.shape or p.ndim != 3:
        raise InputError(
            f"segmentation_scores: pred and target must both be (N, H, W); got {tuple(p.shape)} and {tuple(t.shape)}"
        )
    if ignore_index is not None:
        keep = t != int(ignore_index)
        if not bool(keep.any()):
            raise InputError(
                f"segmentation_scores: every target pixel is ignore_index={ignore_index}; the scores are undefined"
            )
        p, t = p[keep].reshape(1, 1, -1), t[keep].reshape(1, 1, -1)
    for name, x in (("pred", p), ("target", t)):
        if x.numel() and (int(x.min()) < 0 or int(x.max()) >= num_classes):
            raise InputError(
                f"segmentation_scores: {name} classes must lie in [0, {num_classes}), "
                f"got range [{int(x.min())}, {int(x.max())}]"
            )
    # classes absent from both prediction and target are left out of the macro averages
    present = torch.zeros(num_classes, dtype=torch.bool)
    present[torch.unique(torch.cat([p.flatten(), t.flatten()]))] = True
    jac = MulticlassJaccardIndex(num_classes=num_classes, average="none")(p, t)
    acc_c = MulticlassAccuracy(num_classes=num_classes, average="none")(p, t)
    in_target = torch.zeros(num_classes, dtype=torch.bool)
    in_target[torch.unique(t)] = True
    pa = MulticlassAccuracy(num_classes=num_classes, average="micro")(p, t)
    return {"miou": float(jac[present].mean()), "macc": float(acc_c[in_target].mean()), "pixel_accuracy": float(pa)}
