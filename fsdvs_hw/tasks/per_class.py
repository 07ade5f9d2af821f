"""Per-class metrics with bootstrap CIs, AP50 / AP75, a confusion matrix, and a dataset's summary.

What a user reads about *their* classes, from the same per-clip metric objects the paired losses
use (:mod:`fsdvs_hw.stats`), so every figure is recomputed, never estimated twice:

* **recognition** (:class:`~fsdvs_hw.stats.ClipMeans` of top-1 with its labels): each class's
  top-1 accuracy (= its recall: the fraction of the class's clips predicted as it) and the
  confusion matrix of true × predicted classes (torchmetrics ``MulticlassConfusionMatrix``);
* **detection** (:class:`~fsdvs_hw.stats.CocoDetections`, pycocotools' matches): each category's
  AP@[.50:.95], AP50 and AP75, and the overall mAP, AP50 and AP75;
* **segmentation** (:class:`~fsdvs_hw.stats.ConfusionMIoU`): each class's IoU.

Each value carries a percentile bootstrap CI over clips (the statistic recomputed from clip
multiplicities, :func:`fsdvs_hw.stats.multiplicities`): a class's top-1 resamples that class's
clips (stratified: the class keeps its clip count), AP and IoU resample every scored clip (a
category's AP depends on the other clips' false positives). With one network the CI covers clip
sampling only. A class with no scored clip (no box, no pixel) has ``n = 0`` and no value.

:func:`dataset_summary` says what was scored: clips, videos, classes, resolution, frames per clip,
frame rate and split sizes.

References
----------
B. Efron and R. Tibshirani, *An Introduction to the Bootstrap*, Chapman & Hall, 1993 (percentile CI).
T.-Y. Lin et al., "Microsoft COCO: Common Objects in Context", ECCV 2014 (AP, AP50, AP75).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import InputError
from ..stats import ClipMeans, CocoDetections, ConfusionMIoU, multiplicities

__all__ = ["PER_CLASS_RESAMPLES", "confusion_matrix", "dataset_summary", "per_class_metrics"]

#: Bootstrap resamples of a per-class CI (Monte-Carlo error of a 95 % bound ≈ 3 % of its half-width).
PER_CLASS_RESAMPLES = 1000

#: Clip multiplicities held at once (resamples × clips): bounds the memory of the resampling (8 bytes each).
_MAX_WEIGHTS = 2_000_000


def _resampled(n: int, n_resamples: int, rng: Any, statistic: Any) -> Any:
    """``statistic(weights)`` over ``n_resamples`` bootstrap draws of ``n`` clips, in chunks of at most
    :data:`_MAX_WEIGHTS` multiplicities; the chunks' results stacked along the first axis (arrays) or per key (dicts)."""
    step = max(1, _MAX_WEIGHTS // max(1, n))
    parts = [
        statistic(multiplicities(rng.integers(0, n, size=(min(step, n_resamples - s), n)), n))
        for s in range(0, n_resamples, step)
    ]
    if isinstance(parts[0], dict):
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return np.concatenate(parts)


def _interval(values: np.ndarray, confidence: float) -> list[float] | None:
    """Percentile interval of the finite resampled values; None when there are none."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return None
    a = (1.0 - confidence) / 2.0
    return [float(np.quantile(v, a)), float(np.quantile(v, 1.0 - a))]


def confusion_matrix(predicted: Any, labels: Any, num_classes: int) -> np.ndarray:
    """Counts ``[true, predicted]`` (torchmetrics ``MulticlassConfusionMatrix``), shape (C, C), int64.

    Examples
    --------
    >>> confusion_matrix([0, 1, 1], [0, 1, 0], 2).tolist()
    [[1, 1], [0, 1]]
    """
    import torch
    from torchmetrics.classification import MulticlassConfusionMatrix

    p = torch.as_tensor(np.asarray(predicted, dtype=np.int64))
    t = torch.as_tensor(np.asarray(labels, dtype=np.int64))
    if p.shape != t.shape or p.ndim != 1:
        raise InputError(f"confusion_matrix: predicted and labels must be (N,), got {tuple(p.shape)}, {tuple(t.shape)}")
    return MulticlassConfusionMatrix(num_classes=num_classes)(p, t).numpy().astype(np.int64)


def _recognition(
    metric: ClipMeans, names: Sequence[str], predicted: Any, n_resamples: int, confidence: float, rng: Any
) -> dict[str, Any]:
    if metric.labels is None or metric.num_classes is None:
        raise InputError("per_class_metrics: a top-1 metric without its labels (stored before labels were kept)")
    rows = []
    for c in range(metric.num_classes):
        values = metric.values[metric.labels == c]
        row: dict[str, Any] = {"name": _name(names, c), "n": int(values.size)}
        if values.size:
            idx = rng.integers(0, values.size, size=(n_resamples, values.size))
            boot = multiplicities(idx, values.size) @ values / values.size
            row |= {"value": float(values.mean()), "ci": _interval(boot, confidence)}
        rows.append(row)
    out: dict[str, Any] = {"metric": "top1", "classes": rows}
    if predicted is not None:
        out["confusion"] = confusion_matrix(predicted, metric.labels, metric.num_classes).tolist()
    return out


def _detection(
    metric: CocoDetections, names: Sequence[str], n_resamples: int, confidence: float, rng: Any
) -> dict[str, Any]:
    n = metric.n_clips
    ones = np.ones((1, n))
    state = rng.bit_generator.state  # every category and the overall metric see the same resamples

    def with_ci(m: CocoDetections) -> dict[str, Any]:
        rng.bit_generator.state = state
        point, boot = m.weighted_all(ones), _resampled(n, n_resamples, rng, m.weighted_all)
        return {
            k: {
                "value": None if not np.isfinite(point[k][0]) else float(point[k][0]),
                "ci": _interval(boot[k], confidence),
            }
            for k in ("map", "map_50", "map_75")
        }

    rows = []
    for k, cat in enumerate(metric.categories):
        row: dict[str, Any] = {"name": _name(names, k), "n": int(cat.ngt.sum())}  # boxes of the category
        if row["n"]:
            one = with_ci(CocoDetections([cat], metric.iou_thresholds, metric.recall_thresholds, n))
            row |= {
                "value": one["map"]["value"],
                "ci": one["map"]["ci"],
                "ap50": one["map_50"]["value"],
                "ap50_ci": one["map_50"]["ci"],
                "ap75": one["map_75"]["value"],
                "ap75_ci": one["map_75"]["ci"],
            }
        rows.append(row)
    return {"metric": "ap", "classes": rows, "overall": with_ci(metric)}


def _segmentation(
    metric: ConfusionMIoU, names: Sequence[str], n_resamples: int, confidence: float, rng: Any
) -> dict[str, Any]:
    n, c = metric.n_clips, metric.num_classes
    flat = metric.confusions.reshape(n, c * c)

    def iou(weights: np.ndarray) -> np.ndarray:
        tot = (weights @ flat).reshape(-1, c, c)
        tp = np.diagonal(tot, axis1=1, axis2=2)
        union = tot.sum(axis=1) + tot.sum(axis=2) - tp
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(union > 0, tp / np.where(union > 0, union, 1.0), np.nan)

    point, boot = iou(np.ones((1, n)))[0], _resampled(n, n_resamples, rng, iou)
    truth = metric.confusions.sum(axis=(0, 2))  # pixels of each true class
    rows = []
    for k in range(c):
        row: dict[str, Any] = {"name": _name(names, k), "n": int(truth[k])}  # labelled pixels of the class
        if np.isfinite(point[k]):
            row |= {"value": float(point[k]), "ci": _interval(boot[:, k], confidence)}
        rows.append(row)
    return {"metric": "iou", "classes": rows}


def _name(names: Sequence[str], k: int) -> str:
    return str(names[k]) if k < len(names) else str(k)


def per_class_metrics(
    metric: Any,
    class_names: Sequence[str] = (),
    *,
    predicted: Any = None,
    n_resamples: int = PER_CLASS_RESAMPLES,
    confidence: float = 0.95,
    seed: int = 0,
) -> dict[str, Any]:
    """Each class's metric with its bootstrap CI, from a task's per-clip metric object.

    Parameters
    ----------
    metric : ClipMeans, CocoDetections or ConfusionMIoU
        The per-clip metric of the scored clips (:data:`fsdvs_hw.explore.paired.PER_CLIP_METRICS`).
    class_names : sequence of str
        Names of the class indices (missing ones are named by their index).
    predicted : array of int, shape (n_clips,), optional
        Recognition: each clip's predicted class (arg-max), for the confusion matrix.
    n_resamples : int
        Bootstrap resamples (≥ 100).
    confidence : float
        Of the percentile interval, in (0, 1).
    seed : int
        Seeds the resampling (the same seed for every kernel: paired draws).

    Returns
    -------
    dict
        ``metric`` (``"top1"``, ``"ap"`` or ``"iou"``), ``classes`` (one row per class: ``name``,
        ``n`` — clips, boxes or labelled pixels — and, where ``n`` > 0, ``value`` and ``ci``;
        detection adds ``ap50``, ``ap75`` and their ``_ci``), ``confusion`` (recognition with
        ``predicted``: counts ``[true][predicted]``), ``overall`` (detection: ``map``, ``map_50``,
        ``map_75``, each ``{value, ci}``), ``n_clips``, ``n_resamples``, ``confidence``,
        ``resampled`` (``"clips"``).

    Raises
    ------
    InputError
        An unknown metric object, bad settings, or a top-1 metric without labels.

    Examples
    --------
    >>> from fsdvs_hw.stats import ClipMeans
    >>> m = ClipMeans.top1(np.eye(2)[[0, 1, 1, 1]], np.array([0, 1, 0, 1]))
    >>> out = per_class_metrics(m, ["run", "jump"], predicted=[0, 1, 1, 1], n_resamples=200)
    >>> [(r["name"], r["n"], r["value"]) for r in out["classes"]], out["confusion"]
    ([('run', 2, 0.5), ('jump', 2, 1.0)], [[1, 1], [0, 2]])
    """
    if not 100 <= int(n_resamples) <= 100_000 or not 0.0 < float(confidence) < 1.0:
        raise InputError(
            f"per_class_metrics: n_resamples = {n_resamples}, confidence = {confidence}; allowed: "
            "100 to 100000 resamples, a confidence in (0, 1)"
        )
    rng = np.random.default_rng(seed)
    if isinstance(metric, ClipMeans):
        out = _recognition(metric, class_names, predicted, int(n_resamples), float(confidence), rng)
    elif isinstance(metric, CocoDetections):
        out = _detection(metric, class_names, int(n_resamples), float(confidence), rng)
    elif isinstance(metric, ConfusionMIoU):
        out = _segmentation(metric, class_names, int(n_resamples), float(confidence), rng)
    else:
        raise InputError(
            f"per_class_metrics: {type(metric).__name__}; allowed: ClipMeans, CocoDetections, ConfusionMIoU"
        )
    return {
        **out,
        "n_clips": int(metric.n_clips),
        "n_resamples": int(n_resamples),
        "confidence": float(confidence),
        "resampled": "clips",
    }


def dataset_summary(
    dataset: Any, scored: Any, *, train_size: int | None = None, fps: float | None = None
) -> dict[str, Any]:
    """What was scored: clips, videos, classes, resolution, frames, frame rate and split sizes.

    Parameters
    ----------
    dataset : ClipDataset
        The scored split (:mod:`fsdvs_hw.scenes.datasets`).
    scored : sequence of int
        The clips (or videos, with several clips per video) scored.
    train_size : int, optional
        Clips of the training split or draw, when the table trains.
    fps : float, optional
        Frame rate in Hz (the first readable clip's); the reader's stated rate where not given.

    Returns
    -------
    dict
        ``format`` (the reader), ``n_clips`` (of the split), ``n_scored``, ``n_videos`` (distinct
        videos or sequences the clips come from, where the reader says), ``n_classes``,
        ``class_names``, ``resolution`` ([H, W] px, the stated size; None: the files' own),
        ``n_frames`` (frames per clip), ``fps`` (Hz, where the reader states one) and ``split_sizes``
        (``{"scored": …, "train": …}``).

    Examples
    --------
    >>> dataset_summary(ds, range(10), train_size=40)["split_sizes"]   # doctest: +SKIP
    {'scored': 10, 'train': 40}
    """
    videos = getattr(dataset, "video_of", None)
    if videos is None and hasattr(dataset, "clips") and hasattr(dataset, "images"):  # COCO: video_id of each clip
        first = [dataset.images[ids[0]] for ids in dataset.clips]
        # COCO images are dicts with a video_id; other readers with these attributes (DSEC) do not say
        videos = [im.get("video_id", 0) for im in first] if all(isinstance(im, dict) for im in first) else None
    elif videos is None and hasattr(dataset, "items"):  # one clip per video
        videos = list(range(len(dataset.items)))
    n_scored = len(list(scored))
    fps = getattr(dataset, "fps", None) if fps is None else fps
    return {
        "format": type(dataset).__name__,
        "n_clips": len(dataset),
        "n_scored": n_scored,
        "n_videos": None if videos is None else len(set(np.asarray(videos).tolist())),
        "n_classes": int(dataset.num_classes),
        "class_names": [str(c) for c in dataset.class_names],
        "resolution": None if dataset.size is None else [int(s) for s in dataset.size],
        "n_frames": int(dataset.n_frames),
        "fps": None if fps is None else float(fps),
        "split_sizes": {"scored": n_scored, **({} if train_size is None else {"train": int(train_size)})},
    }
