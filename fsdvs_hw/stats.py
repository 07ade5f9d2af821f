"""Paired bootstrap confidence intervals for task-metric differences (clips × training seeds).

The toolkit's verdict on a realisation is an accuracy *loss*: the task metric of the reference
kernel minus that of the candidate, measured in the same networks on the same test clips. This
module turns per-clip evidence into that loss with a 95 % confidence interval.

Design of the resampling
------------------------
Every training seed's network is scored on the *same* test clips, so clips and seeds are
**crossed** factors, not nested. The CI comes from :func:`scipy.stats.bootstrap` with one sample
of clip indices and one sample of seed indices, resampled independently (``paired=False`` between
the two *samples*; scipy then draws clips and seeds independently, the two-way "crossed"
bootstrap). Within a sample the reference and the candidate are **paired**: one resample of clip
indices weights both kernels' clips alike, one resample of seeds picks the same networks for both.
The statistic is the dataset-level metric recomputed from clip *multiplicities* (how often each
clip was drawn), so metrics that are not per-clip means (COCO mAP, mIoU) are resampled correctly:

* top-1 (or any per-clip mean): :class:`ClipMeans`, ``Σ wᵢ xᵢ / Σ wᵢ``;
* mIoU: :class:`ConfusionMIoU`, per-clip confusion matrices summed with the multiplicities;
* COCO mAP@[.5:.95] / AP50 / AP75: :class:`CocoDetections`, the detection↔ground-truth matches of
  every clip at every IoU threshold computed once by ``pycocotools`` (``COCOeval.evaluate``), then
  ``COCOeval.accumulate`` re-done from weighted cumulative sums. On the unresampled set it equals
  pycocotools to floating-point summation order (tested ≤ 1e-12); for integer weights it equals
  pycocotools run on the dataset with each clip duplicated that many times, up to the order of
  exactly tied scores (copies of one detection are placed next to each other).

**Nested** design (``nested_clips=True``): each network is scored on its *own* test clips (the
exploration's default, :mod:`fsdvs_hw.explore.paired`), so clips are nested in seeds. Then the
bootstrap resamples whole (network, clip set) clusters: the spread of the cluster means already
holds each cluster's clip-sampling variance, and resampling clips again inside each drawn cluster
would count it twice (Davison & Hinkley 1997, §3.8, "strategy 1" with the within-cluster stage
dropped; Field & Welsh 2007). Kernels stay paired: one cluster resample picks the same networks and
clips for the reference and the candidate. With many networks per task this design measures more
of the seed-to-seed spread for the same simulation cost (each clip is simulated once, in one
network), which is what limits a loss's CI once the clips are many.

The two-way bootstrap of a crossed design is slightly conservative (McCullagh 2000: the
interaction variance is counted by both factors), and with few seeds it under-represents the
seed-to-seed spread by the factor ``(S-1)/S`` (3 seeds: 2/3 of the seed variance). With one seed
(``n_seeds = 1``) seed variance cannot enter: the CI covers clip sampling only and
:attr:`DifferenceCI.seed_variance_included` is False.

Interval method: **percentile** by default. The statistic is a difference of two near-linear
dataset metrics over thousands of clips, where bootstrap bias and skewness are negligible (the
BCa correction is checked against percentile in the tests); BCa's jackknife would cost
``n_clips + n_seeds`` extra evaluations of the full mAP per interval and, with three seeds, its
acceleration constant rests on a three-point jackknife. ``method="BCa"`` is available.

References
----------
B. Efron and R. Tibshirani, *An Introduction to the Bootstrap*, Chapman & Hall, 1993.
P. McCullagh, "Resampling and exchangeable arrays", Bernoulli 6(2), 285–301, 2000.
A. C. Davison and D. V. Hinkley, *Bootstrap Methods and their Application*, Cambridge, 1997, §3.8.
C. A. Field and A. H. Welsh, "Bootstrapping clustered data", J. R. Stat. Soc. B 69(3), 369–390, 2007.
T.-Y. Lin et al., "Microsoft COCO: Common Objects in Context", ECCV 2014 (the AP definition).
"""

from __future__ import annotations

import contextlib
import functools
import io
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from .errors import InputError

__all__ = [
    "DEFAULT_RESAMPLES",
    "ClipMeans",
    "ClipMetric",
    "CocoDetections",
    "ConfusionMIoU",
    "DifferenceCI",
    "chance_metric",
    "clips_for_half_width",
    "coco_records",
    "difference_ci",
    "difference_cis",
    "metric_from_state",
    "multiplicities",
    "task_difference_cis",
]

#: Bootstrap resamples per interval (percentile CI; Monte-Carlo error of a 95 % bound ≈ 2 % of h).
DEFAULT_RESAMPLES: int = 2000


@runtime_checkable
class ClipMetric(Protocol):
    """A dataset-level metric that can be recomputed for any clip multiplicities.

    Attributes
    ----------
    n_clips : int
        Number of test clips the metric was measured on.
    """

    n_clips: int

    def weighted(self, weights: np.ndarray) -> np.ndarray:
        """Metric for each row of ``weights`` (shape (B, n_clips), non-negative clip multiplicities).

        Returns an array of shape (B,); NaN where the metric is undefined for that resample.
        """


def _as_weights(weights: Any, n: int) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim == 1:
        w = w[None, :]
    if w.ndim != 2 or w.shape[1] != n:
        raise InputError(f"weights: expected shape (B, {n}), got {np.shape(weights)}")
    return w


# --------------------------------------------------------------------------- per-clip means
class ClipMeans:
    """A metric that is the mean of a per-clip value (top-1 accuracy: 1 if correct, else 0).

    Parameters
    ----------
    values : array, shape (n_clips,)
        Per-clip value (finite).
    labels : array of int, shape (n_clips,), optional
        Each clip's true class (class index ≥ 0), kept by :meth:`top1` for :func:`chance_metric`.
    num_classes : int, optional
        The classifier's class count, kept with ``labels``.
    """

    def __init__(self, values: Any, *, labels: Any = None, num_classes: int | None = None) -> None:
        v = np.asarray(values, dtype=np.float64)
        if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)):
            raise InputError(f"ClipMeans: values must be a finite non-empty 1-D array, got shape {v.shape}")
        self.values = v
        self.n_clips = int(v.size)
        #: True class of each clip and the class count, where a classifier's top-1 was measured
        #: (:meth:`top1`): what :func:`chance_metric` needs.
        self.labels = None if labels is None else np.asarray(labels, dtype=np.int64).reshape(-1)
        self.num_classes = None if num_classes is None else int(num_classes)
        if self.labels is not None and (self.labels.size != v.size or np.any(self.labels < 0)):
            raise InputError(
                f"ClipMeans: labels must be one class index >= 0 per clip ({v.size}), got shape {np.shape(labels)}"
            )

    @classmethod
    def top1(cls, logits: Any, target: Any) -> ClipMeans:
        """Per-clip correctness of the arg-max class (top-1 accuracy, as torchmetrics' micro average)."""
        lg = np.asarray(logits)
        t = np.asarray(target).astype(np.int64)
        if lg.ndim != 2 or t.shape != (lg.shape[0],):
            raise InputError(f"ClipMeans.top1: logits (N, C) and target (N,) expected, got {lg.shape}, {t.shape}")
        return cls((lg.argmax(axis=1) == t).astype(np.float64), labels=t, num_classes=int(lg.shape[1]))

    def state(self) -> dict[str, np.ndarray]:
        """Arrays that rebuild this metric (:func:`metric_from_state`)."""
        out = {"kind": np.array("clip_means"), "values": self.values}
        if self.labels is not None and self.num_classes is not None:
            out["labels"], out["num_classes"] = self.labels.astype(np.int32), np.array(self.num_classes)
        return out

    def weighted(self, weights: Any) -> np.ndarray:
        w = _as_weights(weights, self.n_clips)
        tot = w.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(tot > 0, (w @ self.values) / tot, np.nan)


# --------------------------------------------------------------------------- segmentation
class ConfusionMIoU:
    """Mean IoU from per-clip confusion matrices (macro average over classes present).

    A class counts when it appears in the prediction or the target of the (resampled) set, as in
    :func:`fsdvs_hw.tasks.metrics.segmentation_scores` (torchmetrics ``MulticlassJaccardIndex``).

    Parameters
    ----------
    confusions : array, shape (n_clips, C, C)
        ``confusions[i, t, p]`` = pixels of clip ``i`` with true class ``t`` predicted as ``p``.
    """

    def __init__(self, confusions: Any) -> None:
        c = np.asarray(confusions, dtype=np.float64)
        if c.ndim != 3 or c.shape[1] != c.shape[2] or c.shape[0] == 0 or np.any(c < 0):
            raise InputError(f"ConfusionMIoU: confusions must be non-negative (N, C, C), got shape {c.shape}")
        self.confusions = c
        self.n_clips = int(c.shape[0])
        self.num_classes = int(c.shape[1])

    @classmethod
    def from_masks(cls, pred: Any, target: Any, num_classes: int, ignore_index: int | None = None) -> ConfusionMIoU:
        """Per-clip confusion matrices of predicted and true masks, shape (N, H, W) each.

        Pixels whose target is ``ignore_index`` are left out (prediction and target), as
        torchmetrics' ``MulticlassJaccardIndex(ignore_index=...)`` does.
        """
        p = np.asarray(pred).astype(np.int64)
        t = np.asarray(target).astype(np.int64)
        if p.shape != t.shape or p.ndim != 3:
            raise InputError(f"ConfusionMIoU.from_masks: pred and target must be (N, H, W), got {p.shape}, {t.shape}")
        n = p.shape[0]
        keep = np.ones(t.shape, bool) if ignore_index is None else t != ignore_index
        for name, x in (("pred", p), ("target", t)):
            if x[keep].size and (x[keep].min() < 0 or x[keep].max() >= num_classes):
                raise InputError(f"ConfusionMIoU.from_masks: {name} classes must lie in [0, {num_classes})")
        flat = (np.arange(n)[:, None, None] * num_classes * num_classes + t * num_classes + p)[keep]
        conf = np.bincount(flat, minlength=n * num_classes * num_classes)
        return cls(conf.reshape(n, num_classes, num_classes))

    def state(self) -> dict[str, np.ndarray]:
        """Arrays that rebuild this metric (:func:`metric_from_state`)."""
        small = self.confusions.max(initial=0) < 2**31
        return {
            "kind": np.array("confusion_miou"),
            "confusions": self.confusions.astype(np.int32 if small else np.float64),
        }

    def weighted(self, weights: Any) -> np.ndarray:
        w = _as_weights(weights, self.n_clips)
        c = self.num_classes
        tot = (w @ self.confusions.reshape(self.n_clips, c * c)).reshape(-1, c, c)
        tp = np.diagonal(tot, axis1=1, axis2=2)
        union = tot.sum(axis=1) + tot.sum(axis=2) - tp
        present = union > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            iou = np.where(present, tp / np.where(present, union, 1.0), 0.0)
            return np.where(present.any(axis=1), iou.sum(axis=1) / present.sum(axis=1), np.nan)


# --------------------------------------------------------------------------- detection
_COCO_METRICS = ("map", "map_50", "map_75")


@dataclass(frozen=True)
class _Category:
    img: np.ndarray  # (D,) clip index of each detection, in pycocotools' accumulate order
    tps: np.ndarray  # (T, D) bool
    fps: np.ndarray  # (T, D) bool
    ngt: np.ndarray  # (n_clips,) non-ignored ground truths of this category per clip
    has_eval: np.ndarray  # (n_clips,) bool: pycocotools has an evalImg (gt or dt) for this clip

    @functools.cached_property
    def any_ignored(self) -> bool:
        """Some detection is neither a true nor a false positive (pycocotools' dtIgnore)."""
        return bool(np.any(~(self.tps | self.fps)))

    @functools.cached_property
    def tp_positions(self) -> list[np.ndarray]:
        """Indices of the true positives at each IoU threshold."""
        return [np.flatnonzero(row) for row in self.tps]


def coco_records(
    pred_boxes: np.ndarray,
    pred_scores: np.ndarray,
    pred_labels: np.ndarray,
    gt_boxes: np.ndarray,
    gt_labels: np.ndarray,
    *,
    num_classes: int,
    who: str = "coco_records",
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[dict[str, Any]]]:
    """COCO ``images``, ``annotations`` and detection records of padded per-clip boxes.

    Boxes are ``(x0, y0, x1, y1)`` in pixels, shape (N, K, 4) predicted with (N, K) scores and
    labels, (N, M, 4) true with (N, M) labels; a label < 0 or a non-finite box (or score) is
    padding and skipped. Clip ``i`` is COCO image ``i``. Shared by
    :func:`fsdvs_hw.tasks.metrics.detection_map` and :class:`CocoDetections` so both score the
    same records.

    Raises
    ------
    InputError
        A label outside ``[0, num_classes)`` (message prefixed with ``who``).
    """
    images: list[dict[str, Any]] = []
    anns: list[dict[str, Any]] = []
    dets: list[dict[str, Any]] = []
    for i in range(int(gt_boxes.shape[0])):
        images.append({"id": i, "width": 1, "height": 1})
        for b, c in zip(gt_boxes[i], gt_labels[i]):
            if c < 0 or not np.all(np.isfinite(b)):
                continue
            if not 0 <= c < num_classes:
                raise InputError(f"{who}: gt label {int(c)} outside [0, {num_classes})")
            w, h = float(b[2] - b[0]), float(b[3] - b[1])
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i,
                    "category_id": int(c),
                    "iscrowd": 0,
                    "bbox": [float(b[0]), float(b[1]), w, h],
                    "area": w * h,
                }
            )
        for b, sc, c in zip(pred_boxes[i], pred_scores[i], pred_labels[i]):
            if c < 0 or not np.all(np.isfinite(b)) or not np.isfinite(sc):
                continue
            if not 0 <= c < num_classes:
                raise InputError(f"{who}: predicted label {int(c)} outside [0, {num_classes})")
            dets.append(
                {
                    "image_id": i,
                    "category_id": int(c),
                    "score": float(sc),
                    "bbox": [float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])],
                }
            )
    return images, anns, dets


class CocoDetections:
    """COCO box AP recomputable for any clip multiplicities (pycocotools matches, weighted accumulate).

    Build it with :meth:`from_predictions` (the same inputs as
    :func:`fsdvs_hw.tasks.metrics.detection_map`). The per-image greedy matching of
    ``COCOeval.evaluate`` runs once; :meth:`weighted` then re-does ``COCOeval.accumulate`` for a
    batch of weight vectors with cumulative sums of the weights, which is exactly pycocotools on the
    dataset in which clip ``i`` appears ``wᵢ`` times (see the module docstring for tied scores).

    Parameters
    ----------
    categories : list of _Category
        Built by :meth:`from_predictions`.
    iou_thresholds, recall_thresholds : array
        pycocotools' ``params.iouThrs`` (10) and ``params.recThrs`` (101).
    n_clips : int
    metric : {"map", "map_50", "map_75"}
        What :meth:`weighted` returns (:meth:`weighted_all` returns all three).
    """

    def __init__(
        self,
        categories: list[_Category],
        iou_thresholds: np.ndarray,
        recall_thresholds: np.ndarray,
        n_clips: int,
        metric: str = "map",
    ) -> None:
        if metric not in _COCO_METRICS:
            raise InputError(f"CocoDetections: metric {metric!r} unknown; allowed {', '.join(_COCO_METRICS)}")
        self.categories = categories
        self.iou_thresholds = np.asarray(iou_thresholds, dtype=np.float64)
        self.recall_thresholds = np.asarray(recall_thresholds, dtype=np.float64)
        self.n_clips = int(n_clips)
        self.metric = metric

    @classmethod
    def from_predictions(
        cls,
        pred_boxes: Any,
        pred_scores: Any,
        pred_labels: Any,
        gt_boxes: Any,
        gt_labels: Any,
        *,
        num_classes: int,
        metric: str = "map",
    ) -> CocoDetections:
        """Run ``COCOeval.evaluate`` once and keep every clip's matches per IoU threshold.

        Parameters are those of :func:`fsdvs_hw.tasks.metrics.detection_map` (boxes ``(x0, y0, x1,
        y1)`` in pixels, shape (N, K, 4) predicted and (N, M, 4) true; label −1 or NaN box = padding).
        """
        from pycocotools.coco import COCO
        from pycocotools.cocoeval import COCOeval

        pb, ps, pl = (np.asarray(x) for x in (pred_boxes, pred_scores, pred_labels))
        gb, gl = np.asarray(gt_boxes), np.asarray(gt_labels)
        if (
            pb.ndim != 3
            or gb.ndim != 3
            or not (pb.shape[0] == ps.shape[0] == pl.shape[0] == gb.shape[0] == gl.shape[0])
        ):
            raise InputError(
                f"CocoDetections: inconsistent shapes pred {pb.shape}, {ps.shape}, {pl.shape}; "
                f"gt {gb.shape}, {gl.shape}"
            )
        n = int(gb.shape[0])
        images, anns, dets = coco_records(pb, ps, pl, gb, gl, num_classes=num_classes, who="CocoDetections")
        if not anns:
            raise InputError("CocoDetections: no ground-truth boxes; mAP is undefined")
        with contextlib.redirect_stdout(io.StringIO()):
            gt = COCO()
            gt.dataset = {"images": images, "annotations": anns, "categories": [{"id": c} for c in range(num_classes)]}
            gt.createIndex()
            ev = COCOeval(gt, gt.loadRes(dets) if dets else COCO(), iouType="bbox")
            if not dets:
                return cls._without_detections(gt, ev.params, n, num_classes, metric)
            ev.evaluate()
        p = ev.params
        n_img, n_area = len(p.imgIds), len(p.areaRng)
        max_det = p.maxDets[-1]
        n_thr = len(p.iouThrs)
        cats = []
        for k in range(len(p.catIds)):
            clip, scores, tm, ti = [], [], [], []
            ngt = np.zeros(n, np.int64)
            has = np.zeros(n, bool)
            for i in range(n_img):
                e = ev.evalImgs[k * n_area * n_img + i]  # area range 0 = "all"
                if e is None:
                    continue
                img = int(e["image_id"])
                has[img] = True
                ngt[img] = int(np.count_nonzero(np.asarray(e["gtIgnore"]) == 0))
                d = len(e["dtScores"][:max_det])
                clip.append(np.full(d, img, np.int64))
                scores.append(np.asarray(e["dtScores"][:max_det], dtype=np.float64))
                tm.append(np.asarray(e["dtMatches"])[:, :max_det].reshape(n_thr, d))
                ti.append(np.asarray(e["dtIgnore"])[:, :max_det].reshape(n_thr, d))
            if clip:
                sc = np.concatenate(scores)
                order = np.argsort(-sc, kind="mergesort")  # pycocotools' order
                dtm = np.concatenate(tm, axis=1)[:, order].astype(bool)
                dti = np.concatenate(ti, axis=1)[:, order].astype(bool)
                img_of = np.concatenate(clip)[order]
            else:
                dtm = dti = np.zeros((n_thr, 0), bool)
                img_of = np.zeros(0, np.int64)
            tps, fps = dtm & ~dti, ~dtm & ~dti
            # detections ranked below the last true positive (at every IoU threshold) never change
            # AP for any weights: recall thresholds land on true positives, and the envelope there
            # is a maximum over later true positives only; drop them (the tail of low-score boxes)
            hit = np.flatnonzero(tps.any(axis=0))
            keep = hit[-1] + 1 if hit.size else 0
            cats.append(_Category(img=img_of[:keep], tps=tps[:, :keep], fps=fps[:, :keep], ngt=ngt, has_eval=has))
        return cls(cats, p.iouThrs, p.recThrs, n, metric)

    @classmethod
    def _without_detections(cls, gt: Any, params: Any, n: int, num_classes: int, metric: str) -> CocoDetections:
        n_thr = len(params.iouThrs)
        cats = []
        for k in range(num_classes):
            ngt = np.zeros(n, np.int64)
            for a in gt.dataset["annotations"]:
                if a["category_id"] == k:
                    ngt[a["image_id"]] += 1
            cats.append(
                _Category(
                    img=np.zeros(0, np.int64),
                    tps=np.zeros((n_thr, 0), bool),
                    fps=np.zeros((n_thr, 0), bool),
                    ngt=ngt,
                    has_eval=ngt > 0,
                )
            )
        return cls(cats, params.iouThrs, params.recThrs, n, metric)

    def state(self) -> dict[str, np.ndarray]:
        """Arrays that rebuild this metric (:func:`metric_from_state`); matches bit-packed."""
        out: dict[str, np.ndarray] = {
            "kind": np.array("coco_detections"),
            "metric": np.array(self.metric),
            "iou_thresholds": self.iou_thresholds,
            "recall_thresholds": self.recall_thresholds,
            "n_clips": np.array(self.n_clips),
            "n_categories": np.array(len(self.categories)),
        }
        for k, c in enumerate(self.categories):
            out[f"c{k}_img"] = c.img.astype(np.int32)
            out[f"c{k}_d"] = np.array(c.img.size)
            out[f"c{k}_tps"] = np.packbits(c.tps, axis=1)
            out[f"c{k}_fps"] = np.packbits(c.fps, axis=1)
            out[f"c{k}_ngt"] = c.ngt.astype(np.int32)
            out[f"c{k}_has"] = np.packbits(c.has_eval)
        return out

    @classmethod
    def _from_state(cls, st: Mapping[str, np.ndarray]) -> CocoDetections:
        n = int(st["n_clips"])
        cats = []
        for k in range(int(st["n_categories"])):
            d = int(st[f"c{k}_d"])
            cats.append(
                _Category(
                    img=np.asarray(st[f"c{k}_img"], np.int64),
                    tps=np.unpackbits(st[f"c{k}_tps"], axis=1, count=d).astype(bool),
                    fps=np.unpackbits(st[f"c{k}_fps"], axis=1, count=d).astype(bool),
                    ngt=np.asarray(st[f"c{k}_ngt"], np.int64),
                    has_eval=np.unpackbits(st[f"c{k}_has"], count=n).astype(bool),
                )
            )
        return cls(cats, st["iou_thresholds"], st["recall_thresholds"], n, str(st["metric"]))

    def with_metric(self, metric: str) -> CocoDetections:
        """The same matches, reporting another of ``map``, ``map_50``, ``map_75``."""
        return CocoDetections(self.categories, self.iou_thresholds, self.recall_thresholds, self.n_clips, metric)

    def weighted(self, weights: Any) -> np.ndarray:
        return self.weighted_all(weights)[self.metric]

    def weighted_all(self, weights: Any, *, chunk_elements: int = 4_000_000) -> dict[str, np.ndarray]:
        """``{"map", "map_50", "map_75"}``, each shape (B,), for clip multiplicities (B, n_clips).

        ``chunk_elements`` bounds the (resamples × detections) work arrays.
        """
        w = _as_weights(weights, self.n_clips)
        if np.any(w < 0) or np.any(w != np.round(w)):
            raise InputError("CocoDetections.weighted: weights must be non-negative integers (clip multiplicities)")
        b_all = w.shape[0]
        n_thr = len(self.iou_thresholds)
        # precision[b, t, k] averaged over recall thresholds; NaN = category excluded (no gt)
        ap = np.full((b_all, n_thr, len(self.categories)), np.nan)
        for k, cat in enumerate(self.categories):
            npig = w @ cat.ngt.astype(np.float64)  # (B,)
            d = cat.img.size
            step = max(1, chunk_elements // max(1, 2 * d))
            for s in range(0, b_all, step):
                sl = slice(s, min(b_all, s + step))
                ap[sl, :, k] = self._category_ap(cat, w[sl], npig[sl])
        t50 = np.where(self.iou_thresholds == 0.5)[0]
        t75 = np.where(self.iou_thresholds == 0.75)[0]
        with np.errstate(invalid="ignore"), _quiet_nanmean():  # an all-NaN row (no gt drawn) stays NaN
            return {
                "map": np.nanmean(ap.reshape(b_all, -1), axis=1),
                "map_50": np.nanmean(ap[:, t50[0], :], axis=1),
                "map_75": np.nanmean(ap[:, t75[0], :], axis=1),
            }

    def _category_ap(self, cat: _Category, w: np.ndarray, npig: np.ndarray) -> np.ndarray:
        """Mean interpolated precision over recall thresholds, shape (B, T); NaN where npig = 0.

        Only true-positive positions are kept: searching the first detection with recall >= r
        always lands on one (or on the first detection, whose envelope is the overall maximum, which
        a true positive attains), and a false positive's precision never exceeds the precision at
        the detection before it, so the precision envelope at true positives is unchanged.
        """
        b, n_thr = w.shape[0], len(self.iou_thresholds)
        r = self.recall_thresholds
        out = np.zeros((b, n_thr))
        if cat.img.size:
            wd = w[:, cat.img]  # (B, D)
            counted = None if cat.any_ignored else np.cumsum(wd, axis=1)  # tp + fp up to each detection
            npig_safe = np.where(npig > 0, npig, 1.0)[:, None]
            # least integer m_k with float(m_k / npig) >= r_k (pycocotools divides tp by npig)
            m = np.ceil(r[None, :] * npig_safe)
            m = np.where((m - 1) / npig_safe >= r[None, :], m - 1, m)
            m = np.where(m / npig_safe < r[None, :], m + 1, m).astype(np.int64)  # (B, R)
            rows = np.arange(b, dtype=np.int64)[:, None]
            for t in range(n_thr):
                pos = cat.tp_positions[t]
                p = pos.size
                if p == 0:
                    continue  # no true positive: precision 0 at every recall threshold
                tp = np.cumsum(wd[:, pos], axis=1)
                if counted is None:
                    fp = np.cumsum(wd * cat.fps[t], axis=1)[:, pos]
                else:
                    fp = counted[:, pos] - tp
                pr = tp / (fp + tp + np.spacing(1))
                env = np.maximum.accumulate(pr[:, ::-1], axis=1)[:, ::-1]
                tpi = tp.astype(np.int64)
                off = int(tpi[:, -1].max()) + int(m.max()) + 2
                keys = (tpi + rows * off).ravel()
                idx = np.searchsorted(keys, (m + rows * off).ravel(), side="left").reshape(b, -1) - rows * p
                found = idx < p
                q = np.where(found, np.take_along_axis(env, np.minimum(idx, p - 1), axis=1), 0.0)
                out[:, t] = q.mean(axis=1)
        out[npig == 0] = np.nan
        return out


@contextlib.contextmanager
def _quiet_nanmean() -> Any:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def metric_from_state(state: Mapping[str, Any]) -> ClipMetric:
    """Rebuild a :class:`ClipMeans`, :class:`ConfusionMIoU` or :class:`CocoDetections` from ``state()``.

    Raises
    ------
    InputError
        ``state`` is not one of these (missing or unknown ``kind``).
    """
    kind = str(np.asarray(state.get("kind", ""))) if isinstance(state, Mapping) else ""
    if kind == "clip_means":
        if "labels" in state and "num_classes" in state:
            return ClipMeans(state["values"], labels=state["labels"], num_classes=int(state["num_classes"]))
        return ClipMeans(state["values"])
    if kind == "confusion_miou":
        return ConfusionMIoU(state["confusions"])
    if kind == "coco_detections":
        return CocoDetections._from_state(state)
    raise InputError(
        f"metric_from_state: unknown metric kind {kind!r}; allowed clip_means, confusion_miou, coco_detections"
    )


# --------------------------------------------------------------------------- chance
def chance_metric(metric: ClipMetric) -> tuple[ClipMetric, str] | None:
    """The same metric, on the same clips, for a predictor that has learned nothing from its input.

    * **Top-1** (:class:`ClipMeans` from :meth:`ClipMeans.top1`): always the test set's most
      frequent class (= 1/classes on a balanced set).
    * **Mean IoU** (:class:`ConfusionMIoU`): every pixel the most frequent class of the test set.
    * **COCO mAP** (:class:`CocoDetections`): a detector that returns no boxes (its mAP is 0: a
      detector whose interval does not lie above 0 has not been shown to detect anything).

    Parameters
    ----------
    metric : ClipMetric
        A measured metric (its ground truth is what the chance predictor is scored on).

    Returns
    -------
    (ClipMetric, str) or None
        The chance predictor's metric (recomputable for any clip weights, so a bootstrap can pair
        it with ``metric``) and how it was made; None when ``metric`` does not keep its ground truth
        (a top-1 metric stored before labels were kept).

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw.stats import ClipMeans, chance_metric
    >>> m = ClipMeans.top1(np.eye(4)[[0, 1, 2, 3, 0, 0]], np.array([0, 1, 2, 3, 0, 0]))
    >>> c, how = chance_metric(m)
    >>> float(c.weighted(np.ones((1, 6)))[0]), how
    (0.5, 'always class 0, the most frequent of 4 (top-1)')
    """
    if isinstance(metric, ClipMeans):
        if metric.labels is None or metric.num_classes is None:
            return None
        counts = np.bincount(metric.labels, minlength=metric.num_classes)
        top = int(np.argmax(counts))
        return (
            ClipMeans((metric.labels == top).astype(np.float64), labels=metric.labels, num_classes=metric.num_classes),
            f"always class {top}, the most frequent of {metric.num_classes} (top-1)",
        )
    if isinstance(metric, ConfusionMIoU):
        truth = metric.confusions.sum(axis=2)  # (n_clips, C): pixels of each true class
        top = int(np.argmax(truth.sum(axis=0)))
        conf = np.zeros_like(metric.confusions)
        conf[:, :, top] = truth
        return ConfusionMIoU(conf), f"every pixel class {top}, the most frequent of {metric.num_classes} (mIoU)"
    if isinstance(metric, CocoDetections):
        empty = [
            _Category(
                img=np.zeros(0, np.int64),
                tps=np.zeros((len(metric.iou_thresholds), 0), bool),
                fps=np.zeros((len(metric.iou_thresholds), 0), bool),
                ngt=c.ngt,
                has_eval=c.ngt > 0,
            )
            for c in metric.categories
        ]
        return (
            CocoDetections(empty, metric.iou_thresholds, metric.recall_thresholds, metric.n_clips, metric.metric),
            f"a detector that returns no boxes ({metric.metric})",
        )
    return None


# --------------------------------------------------------------------------- the interval
@dataclass(frozen=True)
class DifferenceCI:
    """A metric difference ``reference − candidate`` with its bootstrap CI (fractions, not %).

    Attributes
    ----------
    estimate : float
        The difference on the full test set, averaged over the seeds (each arm over its own seeds).
    low, high : float
        The CI bounds at :attr:`confidence`.
    confidence : float
    n_clips : int
    n_seeds_reference, n_seeds_candidate : int
    paired_clips, paired_seeds : bool
        Whether one resample weights both arms' clips / seeds alike.
    resampled : tuple of str
        Which factors were resampled (``"clips"``, ``"seeds"``).
    method : str
        ``"percentile"`` or ``"BCa"`` (scipy.stats.bootstrap).
    n_resamples : int
    bootstrap_se : float
        Standard deviation of the bootstrap distribution.
    clip_design : str
        ``"crossed"`` (every network on the same clips) or ``"nested"`` (each network on its own
        clips; ``n_clips`` is then the total over the networks, and a seed resample draws whole
        network-and-clips clusters, which carries the clip variance).
    """

    estimate: float
    low: float
    high: float
    confidence: float
    n_clips: int
    n_seeds_reference: int
    n_seeds_candidate: int
    paired_clips: bool
    paired_seeds: bool
    resampled: tuple[str, ...]
    method: str
    n_resamples: int
    bootstrap_se: float
    clip_design: str = "crossed"

    @property
    def half_width(self) -> float:
        """Half the CI width."""
        return 0.5 * (self.high - self.low)

    @property
    def seed_variance_included(self) -> bool:
        """True when training seeds were resampled (needs ≥ 2 seeds in an arm)."""
        return "seeds" in self.resampled

    @property
    def contains_zero(self) -> bool:
        """The CI does not exclude 0: no measurable difference."""
        return self.low <= 0.0 <= self.high

    def describe(self, *, digits: int = 3) -> str:
        """``"0.021 [0.012, 0.030]"`` or ``"no measurable loss (± 0.008)"`` when the CI contains 0."""
        if self.contains_zero:
            return f"no measurable loss (± {self.half_width:.{digits}f})"
        return f"{self.estimate:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.__dict__,
            "resampled": list(self.resampled),
            "half_width": self.half_width,
            "seed_variance_included": self.seed_variance_included,
            "contains_zero": self.contains_zero,
        }


def multiplicities(idx: np.ndarray, n: int) -> np.ndarray:
    """(B, n) counts of each index in each row of ``idx`` (B, m): bootstrap draws as weights.

    Example
    -------
    >>> multiplicities(np.array([[0, 0, 2], [1, 2, 2]]), 3)
    array([[2., 0., 1.],
           [0., 1., 2.]])
    """
    idx = np.asarray(idx, dtype=np.int64)
    if idx.ndim == 1:
        idx = idx[None, :]
    b = idx.shape[0]
    flat = (idx + n * np.arange(b, dtype=np.int64)[:, None]).ravel()
    return np.bincount(flat, minlength=b * n).reshape(b, n).astype(np.float64)


def _arm(metrics: Sequence[ClipMetric] | ClipMetric, name: str) -> list[ClipMetric]:
    arm = [metrics] if isinstance(metrics, ClipMetric) else list(metrics)
    if not arm or not all(isinstance(m, ClipMetric) for m in arm):
        raise InputError(f"difference_ci: {name} must be a ClipMetric or a non-empty sequence of them (one per seed)")
    return arm


def difference_ci(
    reference: Sequence[ClipMetric] | ClipMetric,
    candidate: Sequence[ClipMetric] | ClipMetric,
    *,
    paired_seeds: bool = True,
    paired_clips: bool = True,
    nested_clips: bool = False,
    resample: Sequence[str] = ("clips", "seeds"),
    confidence: float = 0.95,
    n_resamples: int = DEFAULT_RESAMPLES,
    method: str = "percentile",
    rng: Any = 0,
    batch: int | None = 200,
) -> DifferenceCI:
    """Bootstrap CI of ``metric(reference) − metric(candidate)`` over test clips and training seeds.

    Parameters
    ----------
    reference, candidate : ClipMetric or sequence of ClipMetric
        One per training seed (network), all on the same ``n_clips`` test clips in the same order.
        With ``paired_seeds`` the two lists must be aligned: entry ``s`` of both is network ``s``.
    paired_seeds : bool
        True (default): the same networks score both kernels (zero-shot swap, the explore loss);
        one seed resample picks the same networks for both arms. False: the arms are different
        networks (the ablation's w/o vs 7×7), and each arm's seeds are resampled on their own.
    paired_clips : bool
        True (default): the same clip resample weights both arms (they were scored on the same
        clips). False resamples each arm's clips independently, which is only right for arms scored
        on different clips (and shows how much pairing buys).
    nested_clips : bool
        False (default): every network scored the same clips (crossed). True: network ``s`` scored
        its own clips (``reference[s]`` and ``candidate[s]`` on the same ones; the count may differ
        between networks); with ``"seeds"`` in ``resample`` and ≥ 2 networks, whole
        (network, clips) clusters are resampled (module docstring), otherwise clips are resampled
        within each network. Needs ``paired_seeds`` and ``paired_clips``.
    resample : sequence of {"clips", "seeds"}
        The factors to resample; ``("clips",)`` or ``("seeds",)`` isolate one variance component
        (used to size the test set, :func:`clips_for_half_width`). Seeds are resampled only in an
        arm with at least 2 seeds.
    confidence : float
        Two-sided confidence level in (0, 1).
    n_resamples : int
        Bootstrap resamples (≥ 100).
    method : {"percentile", "BCa", "basic"}
        ``scipy.stats.bootstrap`` interval method (percentile by default: see the module docstring).
    rng : int or numpy Generator
        Seed of the resampling (same seed → same resamples, so intervals of different candidates
        against one reference use the same clip draws).
    batch : int or None
        Resamples per vectorised statistic call (memory bound).

    Returns
    -------
    DifferenceCI

    Raises
    ------
    InputError
        Arms of different clip counts, unaligned paired seeds, bad options.

    Examples
    --------
    >>> ref = ClipMeans(np.r_[np.ones(80), np.zeros(20)])        # 80 % correct
    >>> cand = ClipMeans(np.r_[np.ones(60), np.zeros(40)])       # 60 %, the same clips
    >>> ci = difference_ci(ref, cand, n_resamples=500)
    >>> round(ci.estimate, 3), ci.low > 0
    (0.2, True)
    """
    cand = _arm(candidate, "candidate")
    return difference_cis(
        reference,
        {"candidate": cand},
        paired_seeds=paired_seeds,
        paired_clips=paired_clips,
        nested_clips=nested_clips,
        resample=resample,
        confidence=confidence,
        n_resamples=n_resamples,
        method=method,
        rng=rng,
        batch=batch,
    )["candidate"]


def difference_cis(
    reference: Sequence[ClipMetric] | ClipMetric,
    candidates: Mapping[str, Sequence[ClipMetric] | ClipMetric],
    *,
    paired_seeds: bool = True,
    paired_clips: bool = True,
    nested_clips: bool = False,
    resample: Sequence[str] = ("clips", "seeds"),
    confidence: float = 0.95,
    n_resamples: int = DEFAULT_RESAMPLES,
    method: str = "percentile",
    rng: Any = 0,
    batch: int | None = 200,
) -> dict[str, DifferenceCI]:
    """:func:`difference_ci` of several candidates against one reference, from the same resamples.

    One ``scipy.stats.bootstrap`` call with a vector-valued statistic: every resample of clips and
    seeds is applied to the reference once and to every candidate, so the reference metric (the
    expensive part for mAP) is computed once per resample, and all intervals share their draws.
    With ``paired_seeds=False`` all candidates must have the same number of seeds (one seed
    resample serves them all). Parameters otherwise as :func:`difference_ci`.

    Returns
    -------
    dict
        Candidate name → :class:`DifferenceCI`, in the order given.
    """
    out = task_difference_cis(
        {"_": (reference, candidates)},
        paired_seeds=paired_seeds,
        paired_clips=paired_clips,
        nested_clips=nested_clips,
        resample=resample,
        confidence=confidence,
        n_resamples=n_resamples,
        method=method,
        rng=rng,
        batch=batch,
    )
    return {k: v["_"] for k, v in out.items()}


@dataclass
class _Task:
    ref: list[ClipMetric]
    cands: list[list[ClipMetric]]
    slots: list[str]
    n: int
    nested: bool = False


def _nested_task(
    tname: str,
    ref: list[ClipMetric],
    cands: list[list[ClipMetric]],
    resample: Sequence[str],
    paired_seeds: bool,
    paired_clips: bool,
) -> _Task:
    """Validate one task of a nested design (network ``s`` on its own clips) and pick its slots."""
    if not (paired_seeds and paired_clips):
        raise InputError(
            f"difference_ci: task {tname!r}: nested clips need paired_seeds and paired_clips "
            "(each network scores every kernel on its own clips)"
        )
    for c in cands:
        if len(c) != len(ref):
            raise InputError(
                f"difference_ci: task {tname!r}: paired seeds need one candidate per reference "
                f"network; got {len(ref)} and {len(c)}"
            )
        bad = [s for s, (a, m) in enumerate(zip(ref, c)) if a.n_clips != m.n_clips]
        if bad:
            raise InputError(
                f"difference_ci: task {tname!r}: network {bad[0]} scored {ref[bad[0]].n_clips} "
                f"clips with the reference and {c[bad[0]].n_clips} with a candidate (nested clips: "
                "each network scores every kernel on the same clips)"
            )
    if any(m.n_clips < 2 for m in ref):
        raise InputError(
            f"difference_ci: task {tname!r}: need at least 2 test clips per network, got {[m.n_clips for m in ref]}"
        )
    if "seeds" in resample and len(ref) >= 2:
        slots = ["seeds"]  # whole (network, clips) clusters: carries the clip variance (module docstring)
    elif "clips" in resample:
        slots = [f"clips@{s}" for s in range(len(ref))]
    else:
        slots = []
    return _Task(ref, cands, slots, sum(m.n_clips for m in ref), nested=True)


def _resampled(task: _Task) -> tuple[str, ...]:
    """The variance components an interval holds (nested clusters hold both clips and seeds)."""
    if task.nested and task.slots == ["seeds"]:
        return ("clips", "seeds")
    return tuple(dict.fromkeys("clips" if sl.startswith("clips") else "seeds" for sl in task.slots))


def _bootstrap_intervals(
    samples: tuple[np.ndarray, ...],
    statistic: Callable[..., np.ndarray],
    estimate: np.ndarray,
    confidence: float,
    n_resamples: int,
    method: str,
    rng: Any,
    batch: int | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """One ``scipy.stats.bootstrap`` call over every slot's index sample, resampled independently.

    Parameters
    ----------
    samples : tuple of ndarray
        Each slot's indices (clips of a network, or seeds); none: nothing to resample (seeds only,
        one seed everywhere), and the interval is the estimate.
    statistic : callable
        Vectorised: the slots' resampled indices → (candidates, tasks [+ weighted], resamples).
    estimate : ndarray (candidates, tasks [+ weighted])
        The statistic on the data as they are.
    confidence, n_resamples, method, rng, batch
        As :func:`difference_ci`.

    Returns
    -------
    low, high, standard_error : ndarray
        The shape of ``estimate`` (metric units).
    n_resamples : int
        0 where nothing was resampled.
    """
    from scipy import stats

    if not samples:
        return estimate, estimate, np.zeros_like(estimate), 0
    res = stats.bootstrap(
        samples,
        statistic,
        paired=False,
        vectorized=True,
        axis=-1,
        confidence_level=confidence,
        n_resamples=n_resamples,
        method=method,
        random_state=np.random.default_rng(rng),
        batch=batch,
    )
    lows, highs = np.asarray(res.confidence_interval.low), np.asarray(res.confidence_interval.high)
    return lows, highs, np.asarray(res.standard_error), n_resamples


def task_difference_cis(
    tasks: Mapping[str, tuple[Sequence[ClipMetric] | ClipMetric, Mapping[str, Sequence[ClipMetric] | ClipMetric]]],
    *,
    weights: Mapping[str, float] | None = None,
    paired_seeds: bool = True,
    paired_clips: bool = True,
    nested_clips: bool | Mapping[str, bool] = False,
    resample: Sequence[str] = ("clips", "seeds"),
    confidence: float = 0.95,
    n_resamples: int = DEFAULT_RESAMPLES,
    method: str = "percentile",
    rng: Any = 0,
    batch: int | None = 200,
) -> dict[str, dict[str, DifferenceCI]]:
    """Per-task loss CIs of several candidates and, with ``weights``, the CI of their weighted mean.

    Every task has its own test clips and networks, so each task contributes its own clip (and
    seed) index samples to one ``scipy.stats.bootstrap`` call, all resampled independently; the
    vector statistic holds every candidate's per-task difference and, with ``weights``, the
    weighted mean ``Σ_T w_T Δ_T / Σ_T w_T``, whose interval therefore accounts for every task's
    clip and seed sampling at once.

    Parameters
    ----------
    tasks : mapping
        Task name → ``(reference arm, {candidate name: candidate arm})``; an arm is one
        :class:`ClipMetric` per training seed. Every task must list the same candidate names.
    weights : mapping, optional
        Task name → weight ≥ 0 (missing tasks weigh 0); adds a ``"weighted"`` entry per candidate.
    nested_clips : bool or mapping
        As in :func:`difference_ci`, for every task or per task name (missing tasks: crossed).
    paired_seeds, paired_clips, resample, confidence, n_resamples, method, rng, batch
        As in :func:`difference_ci`.

    Returns
    -------
    dict
        Candidate → {task (and ``"weighted"``) → :class:`DifferenceCI`}. The weighted interval's
        ``n_clips`` is the total over the weighted tasks and its seed counts the smallest.
    """
    _check_bootstrap_settings(resample, confidence, n_resamples, method)
    names, parsed = _parse_tasks(
        tasks, nested_clips=nested_clips, resample=resample, paired_seeds=paired_seeds, paired_clips=paired_clips
    )
    wts = _task_weights(weights, parsed)
    layout = [(t, sl) for t, task in parsed.items() for sl in task.slots]
    statistic = _difference_statistic(parsed, layout, wts, paired_clips=paired_clips, paired_seeds=paired_seeds)
    estimate = statistic(*[np.arange(_slot_size(parsed[t], sl)) for t, sl in layout])
    samples = tuple(np.arange(_slot_size(parsed[t], sl)) for t, sl in layout)
    lows, highs, ses, n_res = _bootstrap_intervals(
        samples, statistic, estimate, confidence, n_resamples, method, rng, batch
    )
    out: dict[str, dict[str, DifferenceCI]] = {}
    tnames = list(parsed)
    for i, cname in enumerate(names):
        out[cname] = {}
        for j, t in enumerate(tnames):
            task = parsed[t]
            out[cname][t] = DifferenceCI(
                float(estimate[i, j]),
                float(lows[i, j]),
                float(highs[i, j]),
                confidence,
                task.n,
                len(task.ref),
                len(task.cands[i]),
                paired_clips,
                paired_seeds,
                _resampled(task),
                method,
                n_res if task.slots else 0,
                float(ses[i, j]),
                "nested" if task.nested else "crossed",
            )
        if wts is not None:
            used = [t for t, wt in zip(tnames, wts) if wt > 0]
            resampled = tuple(dict.fromkeys(f for t in used for f in _resampled(parsed[t])))
            j = len(tnames)
            out[cname]["weighted"] = DifferenceCI(
                float(estimate[i, j]),
                float(lows[i, j]),
                float(highs[i, j]),
                confidence,
                sum(parsed[t].n for t in used),
                min(len(parsed[t].ref) for t in used),
                min(len(parsed[t].cands[i]) for t in used),
                paired_clips,
                paired_seeds,
                resampled,
                method,
                n_res if resampled else 0,
                float(ses[i, j]),
                "nested" if any(parsed[t].nested for t in used) else "crossed",
            )
    return out


def _check_bootstrap_settings(resample: Sequence[str], confidence: float, n_resamples: int, method: str) -> None:
    """Refuse bootstrap settings outside their ranges (messages name the setting and its range)."""
    bad = set(resample) - {"clips", "seeds"}
    if bad or not resample:
        raise InputError(f"difference_ci: resample must name 'clips' and/or 'seeds', got {list(resample)!r}")
    if not 0.0 < confidence < 1.0:
        raise InputError(f"difference_ci: confidence must lie in (0, 1), got {confidence!r}")
    if isinstance(n_resamples, bool) or not isinstance(n_resamples, int) or n_resamples < 100:
        raise InputError(f"difference_ci: n_resamples must be an integer >= 100, got {n_resamples!r}")
    if method not in ("percentile", "BCa", "basic"):
        raise InputError(f"difference_ci: method must be 'percentile', 'BCa' or 'basic', got {method!r}")


def _parse_tasks(
    tasks: Mapping[str, tuple[Any, Mapping[str, Any]]],
    *,
    nested_clips: bool | Mapping[str, bool],
    resample: Sequence[str],
    paired_seeds: bool,
    paired_clips: bool,
) -> tuple[list[str], dict[str, _Task]]:
    """Candidate names and, per task, its arms and the index slots the bootstrap resamples."""
    if not tasks:
        raise InputError("difference_ci: no tasks")
    names: list[str] | None = None
    parsed: dict[str, _Task] = {}
    for tname, (reference, candidates) in tasks.items():
        if names is None:
            names = list(candidates)
        if list(candidates) != names or not names:
            raise InputError(
                f"difference_ci: task {tname!r} lists candidates {list(candidates)}, expected {names} "
                f"(every task must score the same, non-empty set of candidates)"
            )
        ref = _arm(reference, "reference")
        cands = [_arm(candidates[k], f"candidate {k!r}") for k in names]
        if nested_clips.get(tname, False) if isinstance(nested_clips, Mapping) else nested_clips:
            parsed[tname] = _nested_task(tname, ref, cands, resample, paired_seeds, paired_clips)
            continue
        n = ref[0].n_clips
        if any(m.n_clips != n for m in ref) or any(m.n_clips != n for c in cands for m in c):
            raise InputError(
                f"difference_ci: task {tname!r}: every metric must cover the same clips; got "
                f"{[m.n_clips for m in ref]} (reference) and {[[m.n_clips for m in c] for c in cands]}"
            )
        if n < 2:
            raise InputError(f"difference_ci: task {tname!r}: need at least 2 test clips, got {n}")
        n_cs = {len(c) for c in cands}
        if paired_seeds and n_cs != {len(ref)}:
            raise InputError(
                f"difference_ci: task {tname!r}: paired seeds need one candidate per reference network; "
                f"got {len(ref)} and {sorted(n_cs)} (pass paired_seeds=False for different networks)"
            )
        if not paired_seeds and len(n_cs) != 1:
            raise InputError(
                f"difference_ci: task {tname!r}: unpaired seeds need the same number of seeds in "
                f"every candidate, got {sorted(n_cs)}"
            )
        slots: list[str] = []
        if "clips" in resample:
            slots += ["clips"] if paired_clips else ["clips_ref", "clips_cand"]
        if "seeds" in resample:
            if paired_seeds and len(ref) >= 2:
                slots.append("seeds")
            elif not paired_seeds:
                slots += [sl for sl, k in (("seeds_ref", len(ref)), ("seeds_cand", len(cands[0]))) if k >= 2]
        parsed[tname] = _Task(ref, cands, slots, n)
    assert names is not None
    return names, parsed


def _task_weights(weights: Mapping[str, float] | None, parsed: Mapping[str, _Task]) -> np.ndarray | None:
    """Task weights normalised to sum 1, in the order of ``parsed`` (None: no weighted entry)."""
    if weights is None:
        return None
    wts = np.array([float(weights.get(t, 0.0)) for t in parsed])
    if np.any(~np.isfinite(wts)) or np.any(wts < 0) or wts.sum() <= 0:
        raise InputError(f"difference_ci: weights must be finite, >= 0 and not all 0, got {dict(weights)}")
    return wts / wts.sum()


def _slot_size(task: _Task, slot: str) -> int:
    """How many items a resampled index slot draws from (clips of the task or of one network, or seeds)."""
    if slot.startswith("clips@"):  # nested: clips of one network
        return task.ref[int(slot[6:])].n_clips
    return task.n if slot.startswith("clips") else (len(task.cands[0]) if slot == "seeds_cand" else len(task.ref))


def _difference_statistic(
    parsed: Mapping[str, _Task],
    layout: Sequence[tuple[str, str]],
    wts: np.ndarray | None,
    *,
    paired_clips: bool,
    paired_seeds: bool,
) -> Any:
    """The vectorised bootstrap statistic: every candidate's per-task loss (and weighted mean).

    Takes one index sample per ``layout`` slot (``scipy.stats.bootstrap``'s ``*data``) and returns
    an array (candidates, tasks [+ weighted], *batch).
    """

    def arm_value(arm: list[ClipMetric], wc: np.ndarray, ws: np.ndarray) -> np.ndarray:
        vals = np.stack([m.weighted(wc) for m in arm], axis=1)  # (B, S)
        return (vals * ws).sum(axis=1) / ws.sum(axis=1)

    def nested_value(arm: list[ClipMetric], wcs: list[np.ndarray | None], ws: np.ndarray) -> np.ndarray:
        b = ws.shape[0]
        vals = np.stack(
            [
                np.full(b, m.weighted(np.ones((1, m.n_clips)))[0]) if wc is None else m.weighted(wc)
                for m, wc in zip(arm, wcs)
            ],
            axis=1,
        )  # (B, S)
        return (vals * ws).sum(axis=1) / ws.sum(axis=1)

    def statistic(*idx: np.ndarray, axis: int = -1) -> np.ndarray:
        shape = idx[0].shape[:-1] if idx else ()
        b = int(np.prod(shape, dtype=np.int64))
        got = {key: arr.reshape(b, -1) for key, arr in zip(layout, idx)}
        per_task = []
        for t, task in parsed.items():

            def w(sl: str, n_items: int) -> np.ndarray:
                return multiplicities(got[(t, sl)], n_items) if (t, sl) in got else np.ones((b, n_items))  # noqa: B023 - called in this iteration

            if task.nested:
                ws = w("seeds", len(task.ref))
                wcs = [
                    multiplicities(got[(t, f"clips@{s}")], m.n_clips) if (t, f"clips@{s}") in got else None
                    for s, m in enumerate(task.ref)
                ]
                r = nested_value(task.ref, wcs, ws)
                per_task.append(np.stack([r - nested_value(c, wcs, ws) for c in task.cands]))  # (C, B)
                continue

            wc_ref = w("clips" if paired_clips else "clips_ref", task.n)
            wc_cand = wc_ref if paired_clips else w("clips_cand", task.n)
            ws_ref = w("seeds" if paired_seeds else "seeds_ref", len(task.ref))
            ws_cand = ws_ref if paired_seeds else w("seeds_cand", len(task.cands[0]))
            r = arm_value(task.ref, wc_ref, ws_ref)
            per_task.append(np.stack([r - arm_value(c, wc_cand, ws_cand) for c in task.cands]))  # (C, B)
        vals = np.stack(per_task, axis=1)  # (C, T, B)
        if wts is not None:
            vals = np.concatenate([vals, np.tensordot(wts, vals, axes=([0], [1]))[:, None, :]], axis=1)
        return vals.reshape(vals.shape[0], vals.shape[1], *shape)

    return statistic


def clips_for_half_width(
    pilot: DifferenceCI,
    target_half_width: float = 0.01,
    *,
    seed_half_width: float = 0.0,
    seed_noise_half_width: float = 0.0,
    max_clips: int = 100_000,
) -> int:
    """Test clips needed for a CI half-width ``target_half_width``, from a pilot interval.

    The CI's variance has a part that falls as ``1/n`` — clip sampling, ``h_c`` in the clip-only
    pilot interval, and the clip noise inside each seed's estimate that the seed resampling also
    sees, ``h_n`` — and a part that does not, the true seed-to-seed (network and mismatch-pattern)
    spread ``h_s``. Independent parts add in variance:
    ``h(n)² ≈ (h_c² + h_n²) n_p / n + h_s²``, so ``n = ⌈n_p (h_c² + h_n²) / (h² − h_s²)⌉``.

    Parameters
    ----------
    pilot : DifferenceCI
        An interval over clips (``resample`` including ``"clips"``) on ``pilot.n_clips`` clips.
    target_half_width : float
        Wanted half-width (metric fraction; 0.01 = one point).
    seed_half_width : float
        ``h_s``: the seed-only half-width with the pilot's clip noise taken out (0 with one seed).
    seed_noise_half_width : float
        ``h_n``: the part of the pilot's seed-only half-width that is clip noise (falls with ``n``).
    max_clips : int
        Upper bound returned when the target needs more.

    Returns
    -------
    int
        Clips (≥ ``pilot.n_clips`` is not enforced: a pilot tighter than needed returns fewer).

    Raises
    ------
    InputError
        The seed part alone is at least the target: no number of clips reaches it (train more seeds).
    """
    if not target_half_width > 0:
        raise InputError(f"clips_for_half_width: target_half_width must be > 0, got {target_half_width!r}")
    if "clips" not in pilot.resampled:
        raise InputError("clips_for_half_width: the pilot interval must resample clips")
    room = target_half_width**2 - seed_half_width**2
    if room <= 0:
        raise InputError(
            f"clips_for_half_width: the seed-to-seed part of the CI (± {seed_half_width:.4f}) is at "
            f"least the target ± {target_half_width:.4f}; more clips cannot reach it (train more seeds)"
        )
    n = math.ceil(pilot.n_clips * (pilot.half_width**2 + seed_noise_half_width**2) / room)
    return int(min(max(n, 2), max_clips))
