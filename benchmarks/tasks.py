"""``fsdvs-hw bench tasks``: training and evaluation cost, and the evaluation's accuracy-for-speed trade.

Two tables:

1. **Time per epoch and per evaluation** for each task at the shipped settings (32×32 clips,
   5 frames, 7×7 kernel): a frozen-filter epoch (events computed once and cached), a joint epoch
   (simulator forward + backward every batch) and one :func:`~fsdvs_hw.tasks.learn.evaluate_kernel`.
2. **Metric confidence interval versus test-set size** (the knob of evaluation fidelity): the
   shipped 7×7 checkpoint scored on the first ``n`` test clips, with a 95 % bootstrap interval
   (resampling clips, 100 replicates), the error against the largest test set (the
   highest-fidelity reference) and the wall time.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from fsdvs_hw.resources import shipped_path

from .harness import BenchRun, BenchSection, Column, Measured, kept_global_state, timed

__all__ = ["SHIPPED_DIR", "bench_tasks", "bootstrap_interval"]

#: The shipped kernels and checkpoints (:func:`fsdvs_hw.resources.shipped_path`).
SHIPPED_DIR = shipped_path("kernels")


def bootstrap_interval(evaluator, prediction, target, *, n_boot: int = 200, seed: int = 0) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of the evaluator's primary metric, resampling clips."""
    import torch

    rng = np.random.default_rng(seed)
    n = next(iter(target.values())).shape[0]
    vals = []
    for _ in range(n_boot):
        idx = torch.from_numpy(rng.integers(0, n, n))
        try:
            vals.append(
                evaluator.score({k: v[idx] for k, v in prediction.items()}, {k: v[idx] for k, v in target.items()})[
                    evaluator.primary_metric
                ]
            )
        except ValueError:  # a resample without ground truth (tiny n): skip it
            continue
    lo, hi = np.percentile(vals, [2.5, 97.5])
    return float(lo), float(hi)


def _predictions(task: str, checkpoint: Path, n_test: int):
    import torch

    from fsdvs_hw.scenes.synthetic import SceneConfig
    from fsdvs_hw.sensor import SensorConfig
    from fsdvs_hw.tasks.checkpoints import load_checkpoint
    from fsdvs_hw.tasks.evaluators import concat_predictions, get_evaluator
    from fsdvs_hw.tasks.event_inputs import network_input
    from fsdvs_hw.tasks.learn import TrainingSettings
    from fsdvs_hw.tasks.synthetic_data import synthetic_dataset

    ev = get_evaluator(task)
    prov, state, kernel = load_checkpoint(checkpoint)
    net = ev.build_network(int(prov["in_channels"]), TrainingSettings(**{"dtype": "float64", **prov["settings"]}).width)
    net.load_state_dict(state)
    net.eval()
    scene = SceneConfig.from_dict(prov["scene"])
    sensor = SensorConfig(**prov["sensor"])
    video, targets = synthetic_dataset(
        scene, n_test, int(prov["test_seed"]), task, TrainingSettings(**{"dtype": "float64", **prov["settings"]}).dtype
    )
    k = torch.as_tensor(np.array(kernel.taps))
    with torch.no_grad():
        preds = [
            ev.predict(net(network_input(video[s : s + 64], k, sensor, scene.timestamps_s)))
            for s in range(0, n_test, 64)
        ]
    return ev, concat_predictions(preds), targets, kernel


def bench_tasks(*, quick: bool = False) -> BenchRun:
    """Tables: time per epoch / evaluation, and metric CI versus test-set size, as records and Markdown.

    Timed with one torch thread; torch's thread count and random state (training seeds it) and the
    rest of the process-wide state are restored afterwards (:func:`~benchmarks.harness.kept_global_state`).
    """
    import torch

    with kept_global_state():
        torch.set_num_threads(1)
        return _bench_tasks(quick)


def _bench_tasks(quick: bool) -> BenchRun:
    from fsdvs_hw.tasks.learn import TrainingSettings, evaluate_kernel, learn_kernel

    n_train = 64 if quick else 512
    n_eval = 64 if quick else 256
    sizes = (16, 32, 64) if quick else (64, 256, 1024, 2048)
    n_boot = 50 if quick else 100
    sec = BenchSection("tasks", settings={"quick": quick, "n_train": n_train, "n_eval": n_eval, "n_boot": n_boot})
    sec.text("## tasks: training / evaluation cost and evaluation accuracy vs test-set size", "")
    sec.text(
        f"Time per epoch ({n_train} training clips of 32×32×5 frames, batch 32, 7×7 kernel, one thread) "
        "and per `evaluate_kernel` (256 test clips, shipped checkpoint, zero-shot).",
        "",
    )
    cost = sec.table(
        Column.text("task"),
        Column.number("frozen-filter epoch (s)", ".2f"),
        Column.number("joint epoch (s)", ".2f"),
        Column.number("evaluate_kernel (s)", ".2f"),
        Column.number("clips / s (joint)", ".0f", unit="clips/s", metric="training clips per second (joint)"),
        title="Time per epoch and per evaluation",
    )
    for task in ("detection", "recognition"):
        print(f"[bench tasks] timing {task}", file=sys.stderr, flush=True)
        res = learn_kernel(
            task, 7, seed=0, n_train=n_train, n_test=32, settings=TrainingSettings(epochs_frozen=1, epochs_joint=1)
        )
        frozen = [h["seconds"] for h in res.history if h["stage"] == "frozen_filter"]
        joint = next(h["seconds"] for h in res.history if h["stage"] == "joint")
        ckpt = SHIPPED_DIR / f"learned_{task}_7x7.safetensors"
        if ckpt.is_file():
            kern = SHIPPED_DIR / f"learned_{task}_7x7.json"
            evaluate_kernel(kern, task, ckpt, n_test=n_eval)  # warm the clip cache (scene rendering)
            t_eval: object = timed(lambda: evaluate_kernel(kern, task, ckpt, n_test=n_eval))
        else:
            t_eval = "no shipped checkpoint"
        cost.row(
            task,
            Measured.of(frozen[:1]) if frozen else "— (joint from start)",
            Measured.of([joint]),
            t_eval,
            n_train / joint,
        )
    sec.text(
        "",
        "Metric (×100) of the shipped 7×7 checkpoint versus test-set size: 95 % bootstrap interval "
        "(100 resamples of clips), error against the largest set, and wall time (events + network + "
        "metric).",
        "",
    )
    ci = sec.table(
        Column.text("task"),
        Column.text("n_test"),
        Column.number("metric", ".1f", unit="%", metric="primary metric"),
        Column.numbers("95 % CI", "[{0}, {1}]", ("95 % CI low", "%", ".1f"), ("95 % CI high", "%", ".1f")),
        Column.number("CI half-width", ".1f", unit="%", metric="95 % CI half-width"),
        Column.number("error vs largest", ".1f", unit="%", metric="error vs largest test set"),
        Column.number("wall time (s)", ".2f", metric="evaluate_kernel wall time"),
        title="Metric CI versus test-set size",
    )
    for task in ("detection", "recognition"):
        ckpt = SHIPPED_DIR / f"learned_{task}_7x7.safetensors"
        if not ckpt.is_file():
            ci.row(task, "—", "no shipped checkpoint", "", "", "", "")
            continue
        print(f"[bench tasks] CI vs n_test for {task}", file=sys.stderr, flush=True)
        ev, pred, target, _ = _predictions(task, ckpt, max(sizes))
        ref = ev.score(pred, target)[ev.primary_metric]
        for n in sizes:
            wall = timed(lambda n=n: evaluate_kernel(SHIPPED_DIR / f"learned_{task}_7x7.json", task, ckpt, n_test=n))
            p = {k: v[:n] for k, v in pred.items()}
            t = {k: v[:n] for k, v in target.items()}
            val = ev.score(p, t)[ev.primary_metric]
            lo, hi = bootstrap_interval(ev, p, t, n_boot=n_boot)
            ci.row(task, str(n), val * 100, (lo * 100, hi * 100), (hi - lo) * 50, abs(val - ref) * 100, wall)
    sec.text(
        "",
        "Timings are on this machine under whatever load it carries; re-run `fsdvs-hw bench tasks` to reproduce.",
        "",
    )
    return sec.run()
