"""``fsdvs-hw bench stats``: the resampled COCO mAP against pycocotools — equality and speed.

The paired loss CIs recompute COCO mAP for every bootstrap resample
(:class:`fsdvs_hw.stats.CocoDetections`). This benchmark scores the shipped detection network's
output on ``n`` test clips and, for a few resamples, compares the weighted accumulate with
pycocotools run on the explicitly duplicated clips (``fsdvs_hw.tasks.metrics.detection_map``):
the largest absolute difference, and the time per resample of each.
"""

from __future__ import annotations

import numpy as np

from fsdvs_hw.resources import shipped_path

from .harness import BenchRun, BenchSection, Column, Measured, kept_global_state, timed

__all__ = ["bench_stats"]

_CKPT = shipped_path("kernels", "learned_detection_7x7.safetensors")


def _detections(n: int) -> tuple[np.ndarray, ...]:
    from fsdvs_hw.kernels import load_kernel
    from fsdvs_hw.tasks.checkpoints import load_checkpoint
    from fsdvs_hw.tasks.learn import evaluate_kernel, heldout_targets

    prov, _, _ = load_checkpoint(_CKPT)
    ev = evaluate_kernel(load_kernel(_CKPT.with_suffix(".json")), "detection", _CKPT, n_test=n, keep_predictions=True)
    p, t = ev.predictions, heldout_targets("detection", prov["scene"], n)
    return p["boxes"], p["scores"], p["labels"], t["boxes"], t["labels"]


@kept_global_state()
def bench_stats(*, quick: bool = False) -> BenchRun:
    """The table: clips, |mAP(weighted) − mAP(pycocotools)|, seconds per resample of each.

    Returns
    -------
    BenchRun
        Markdown and records: the largest absolute mAP difference, pycocotools' seconds per
        resample (median of the checked resamples, with their range), the weighted accumulate's
        milliseconds per resample (median of 3 batches, with their range) and the speed-up.
    """
    from fsdvs_hw.stats import CocoDetections
    from fsdvs_hw.tasks.metrics import detection_map

    sizes = [256] if quick else [512, 2048]
    n_check = 2 if quick else 3
    n_speed = 100 if quick else 400
    sec = BenchSection("stats", settings={"quick": quick, "resamples_checked": n_check, "resamples_per_batch": n_speed})
    sec.text("### Resampled COCO mAP vs pycocotools (shipped detection network, learned kernel)", "")
    table = sec.table(
        Column.text("clips"),
        Column.text("resamples checked"),
        Column.number("max abs difference", ".1e", metric="max abs mAP difference"),
        Column.number("pycocotools s / resample", ".2f", unit="s", metric="pycocotools time per resample"),
        Column.number(
            f"weighted ms / resample (median, range of 3 × {n_speed})",
            ".2f",
            unit="ms",
            metric="weighted accumulate time per resample",
            spread=" ({}–{})",
        ),
        Column.number("speed-up", ".0f", suffix="×", metric="speed-up (pycocotools / weighted)"),
    )
    rng = np.random.default_rng(0)
    for n in sizes:
        args = _detections(n)
        metric = CocoDetections.from_predictions(*args, num_classes=3)
        diffs, t_coco = [], []
        for _ in range(n_check):
            w = rng.multinomial(n, np.full(n, 1.0 / n))
            rep = np.repeat(np.arange(n), w)
            t = timed(lambda rep=rep: detection_map(*(a[rep] for a in args), num_classes=3)["map"])
            t_coco += t.times_s
            diffs.append(abs(t.result - float(metric.weighted(w[None])[0])))
        diffs.append(abs(detection_map(*args, num_classes=3)["map"] - float(metric.weighted(np.ones((1, n)))[0])))
        weights = rng.multinomial(n, np.full(n, 1.0 / n), size=n_speed)
        fast = Measured.of([t / n_speed * 1e3 for t in timed(lambda: metric.weighted(weights), 3).times_s])
        coco = Measured.of(t_coco)
        table.row(str(n), f"{n_check} + full set", max(diffs), coco, fast, coco.value * 1e3 / fast.value)
    sec.text("")
    return sec.run()
