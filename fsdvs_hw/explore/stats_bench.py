"""``fsdvs-hw bench stats``: the resampled COCO mAP against pycocotools — equality and speed.

The paired loss CIs recompute COCO mAP for every bootstrap resample
(:class:`fsdvs_hw.stats.CocoDetections`). This benchmark scores the shipped detection network's
output on ``n`` test clips and, for a few resamples, compares the weighted accumulate with
pycocotools run on the explicitly duplicated clips (``fsdvs_hw.tasks.metrics.detection_map``):
the largest absolute difference, and the time per resample of each.
"""

from __future__ import annotations

import time

import numpy as np

from ..resources import shipped_path

__all__ = ["bench_stats"]

_CKPT = shipped_path("kernels", "learned_detection_7x7.safetensors")


def _detections(n: int) -> tuple[np.ndarray, ...]:
    from ..kernels import load_kernel
    from ..tasks.learn import evaluate_kernel, heldout_targets, load_checkpoint

    prov, _, _ = load_checkpoint(_CKPT)
    ev = evaluate_kernel(load_kernel(_CKPT.with_suffix(".json")), "detection", _CKPT, n_test=n, keep_predictions=True)
    p, t = ev.predictions, heldout_targets("detection", prov["scene"], n)
    return p["boxes"], p["scores"], p["labels"], t["boxes"], t["labels"]


def bench_stats(*, quick: bool = False) -> str:
    """Markdown table: clips, |mAP(weighted) − mAP(pycocotools)|, seconds per resample of each."""
    from ..stats import CocoDetections
    from ..tasks.metrics import detection_map

    sizes = [256] if quick else [512, 2048]
    n_check = 2 if quick else 3
    n_speed = 100 if quick else 400
    lines = ["### Resampled COCO mAP vs pycocotools (shipped detection network, learned kernel)", "",
             "| clips | resamples checked | max abs difference | pycocotools s / resample | weighted ms / resample "
             "(median, range of 3 × " + str(n_speed) + ") | speed-up |", "|---|---|---|---|---|---|"]
    rng = np.random.default_rng(0)
    for n in sizes:
        args = _detections(n)
        metric = CocoDetections.from_predictions(*args, num_classes=3)
        diffs, t_coco = [], []
        for _ in range(n_check):
            w = rng.multinomial(n, np.full(n, 1.0 / n))
            rep = np.repeat(np.arange(n), w)
            t0 = time.perf_counter()
            ref = detection_map(*(a[rep] for a in args), num_classes=3)["map"]
            t_coco.append(time.perf_counter() - t0)
            diffs.append(abs(ref - float(metric.weighted(w[None])[0])))
        diffs.append(abs(detection_map(*args, num_classes=3)["map"] - float(metric.weighted(np.ones((1, n)))[0])))
        weights = rng.multinomial(n, np.full(n, 1.0 / n), size=n_speed)
        t_fast = []
        for _ in range(3):
            t0 = time.perf_counter()
            metric.weighted(weights)
            t_fast.append((time.perf_counter() - t0) / n_speed * 1e3)
        med = float(np.median(t_fast))
        lines.append(f"| {n} | {n_check} + full set | {max(diffs):.1e} | {np.median(t_coco):.2f} | {med:.2f} "
                     f"({min(t_fast):.2f}–{max(t_fast):.2f}) | {np.median(t_coco) * 1e3 / med:.0f}× |")
    return "\n".join(lines) + "\n"
