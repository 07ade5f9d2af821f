"""The kernel-size ablation on a user-data task: one trained network per (kernel size, seed), paired CIs.

:func:`run_user_ablation` is ``fsdvs-hw ablation --design``: for a ``[tasks.datasets.<task>]``
table with a ``train`` table it trains the network and kernel once per kernel size and seed
(:func:`fsdvs_hw.explore.user_data.train_user_task` with ``kernel_size`` and ``seed``
replaced; size 1 is the "w/o" conventional DVS, whose kernel cannot change any event), scores
each on the table's scored clips (the same clips for every run, disjoint from the training
clips of every seed) and reports each size's metric (mean ± std over seeds) and its gain over w/o
with a bootstrap CI from :func:`fsdvs_hw.stats.difference_ci` — the synthetic ablation's
statistics: the two arms are different networks (``paired_seeds=False``), scored on the same
clips (``paired_clips=True``), resampling clips and, with two or more seeds, seeds.

Every run's checkpoint is written under the output folder and reused by a rerun (resume). The
runs are independent: ``workers`` local processes (:mod:`fsdvs_hw.workers`) train and score
them in parallel.

References
----------
FS-DVS paper, Table (kernel-size ablation: w/o, 3×3, 5×5, 7×7, 9×9).
Efron & Tibshirani, "An Introduction to the Bootstrap", Chapman & Hall (1993).
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..paths import Confinement

__all__ = ["labelled_stderr", "run_user_ablation"]


class _LabelledLines(io.TextIOBase):
    """A text stream that writes every line to ``stream`` with ``label`` in front (whole lines, flushed)."""

    def __init__(self, stream: Any, label: str) -> None:
        self.stream, self.label, self.pending = stream, label, ""

    def write(self, text: str) -> int:
        self.pending += text
        *lines, self.pending = self.pending.split("\n")
        for line in lines:
            self.stream.write(f"{self.label}{line}\n")
        if lines:
            self.stream.flush()
        return len(text)

    def flush(self) -> None:
        if self.pending:
            self.stream.write(f"{self.label}{self.pending}")
            self.pending = ""
        self.stream.flush()


@contextlib.contextmanager
def labelled_stderr(label: str) -> Iterator[None]:
    """Every line written to stderr inside the block starts with ``label`` (the run's kernel size and seed).

    Parallel runs of an ablation interleave their epoch lines on one terminal; the label says
    which run each line is from.

    Examples
    --------
    >>> with labelled_stderr("[recognition k=5 s=1] "):
    ...     print("epoch 1/4", file=sys.stderr)   # doctest: +SKIP
    """
    stream = _LabelledLines(sys.stderr, label)
    try:
        with contextlib.redirect_stderr(stream):
            yield
    finally:
        stream.flush()


def run_user_ablation(
    design: Any,
    task: str,
    out: str | Path,
    *,
    sizes: Sequence[int] = (1, 3, 5, 7),
    seeds: Sequence[int] = (0, 1, 2),
    n_resamples: int = 2000,
    verbose: bool = False,
    workers: int = 1,
) -> dict[str, Any]:
    """Kernel-size ablation of a design's user-data task; writes ``ablation.json`` and ``ablation.md``.

    Parameters
    ----------
    design : Design
        A loaded design (:func:`fsdvs_hw.design.load_design`) whose
        ``[tasks.datasets.<task>]`` has a ``train`` table (epochs, rates, clips).
    task : str
        The table's task.
    out : path
        Output folder: ``runs/<task>_k<size>_s<seed>.*`` checkpoints (reused on a rerun),
        ``ablation.json``, ``ablation.md``.
    sizes : sequence of int
        Odd kernel sides in pixels; must include 1 (the w/o reference).
    seeds : sequence of int
        Training seeds (the training clips, initialisation and batch order).
    n_resamples : int
        Bootstrap resamples per CI.
    verbose : bool
        One line per training epoch on stderr.
    workers : int
        Local worker processes (:func:`fsdvs_hw.workers.process_pool`, each with
        ``FSDVS_HW_WORKER_THREADS`` torch threads, default 1) training and scoring the runs in
        parallel; 1 = in this process, one run after the other. The result does not depend on it
        beyond floating-point summation order (torch's thread count).

    Returns
    -------
    dict
        ``rows`` (per size: ``metric_mean``, ``metric_std``, per-seed values, ``gain``,
        ``gain_ci95_low`` / ``high``), ``task``, ``metric``, ``n_clips``, ``seeds``, ``resampled``.

    Raises
    ------
    InputError
        No such user-data task or no ``train`` table, sizes without 1 or not odd, no seeds or a repeated
        one, too few clips.

    Examples
    --------
    >>> res = run_user_ablation(load_design("mine.toml"), "recognition", "out/abl", sizes=(1, 7))  # doctest: +SKIP
    >>> res["rows"][-1]["gain_ci95_low"] <= res["rows"][-1]["gain"]                               # doctest: +SKIP
    True
    """
    from ..design.user_data_inputs import open_dataset
    from ..limits import MAX_WORKERS, check_count
    from ..paths import output_dir, write_output
    from ..tasks.dataset_eval import evaluator_for_dataset

    entry = _trained_task(design, task)
    sizes = _checked_sizes(sizes, seeds)
    workers = check_count("ablation --workers", workers, 1, MAX_WORKERS)
    folder = output_dir(out, flag="--out")
    key = f"tasks.datasets.{task}.dataset"
    ds = open_dataset(entry["dataset"], design.base_dir, confine=design.confine_paths, key=key)
    evaluator = evaluator_for_dataset(task, ds)
    jobs = [
        (
            task,
            entry,
            str(design.base_dir),
            design.confine_paths,
            k,
            int(seed),
            str(folder / "runs" / f"{task}_k{k}_s{seed}"),
            verbose,
        )
        for k in sizes
        for seed in seeds
    ]
    metrics, values, n_clips = _by_size(jobs, _run_jobs(jobs, workers), sizes)
    resample = ("clips", "seeds") if len(seeds) >= 2 else ("clips",)
    rows = [_size_row(k, metrics, values, len(seeds), resample, n_resamples) for k in sizes]
    result = {
        "task": task,
        "metric": evaluator.primary_metric,
        "n_clips": n_clips,
        "seeds": list(map(int, seeds)),
        "resampled": list(resample),
        "rows": rows,
        "design": str(design.source),
        "ci_note": "gain = metric(size) - metric(w/o); different networks per arm, the same scored clips",
    }
    result["markdown"] = _markdown(task, design.source, evaluator.primary_metric, n_clips, len(seeds), resample, rows)
    write_output(folder / "ablation.json", json.dumps(result, indent=1) + "\n", flag="--out")
    write_output(folder / "ablation.md", result["markdown"], flag="--out")
    return result


def _checked_sizes(sizes: Sequence[int], seeds: Sequence[int]) -> list[int]:
    """The kernel sizes sorted, once each; InputError for sizes without 1 or not odd in [1, 15], and
    for no seeds or a repeated one (one network per seed)."""
    out = sorted({int(k) for k in sizes})
    if 1 not in out or any(k % 2 == 0 or not 1 <= k <= 15 for k in out):
        raise InputError(f"ablation --sizes {out}: allowed: odd sides in [1, 15] including 1 (the w/o reference)")
    if not seeds or len(set(map(int, seeds))) != len(seeds):
        raise InputError(f"ablation --seeds {list(seeds)}: allowed: one or more distinct seeds (one network each)")
    return out


def _trained_task(design: Any, task: str) -> dict[str, Any]:
    """The design's ``[tasks.datasets.<task>]`` table dumped; it must have a ``train`` table."""
    user = design.spec.tasks.datasets
    if task not in user or user[task].train is None:
        raise InputError(
            f"ablation --design {design.source}: [tasks.datasets.{task}] with a train table is needed "
            f"(the ablation trains one network per size and seed); allowed tasks: "
            f"{', '.join(t for t, e in user.items() if e.train is not None) or 'none'}"
        )
    return user[task].model_dump()


def _size_row(
    size: int,
    metrics: dict[int, list[Any]],
    values: dict[int, list[float]],
    n_seeds: int,
    resample: tuple[str, ...],
    n_resamples: int,
) -> dict[str, Any]:
    """One kernel size's row: its metric over seeds and, beside w/o, its gain with a bootstrap CI.

    Parameters
    ----------
    size : int
        Kernel side (pixels); 1 is w/o.
    metrics : dict
        Size → per-seed per-clip metric objects (:mod:`fsdvs_hw.stats`).
    values : dict
        Size → per-seed metric (fraction).
    n_seeds : int
    resample : tuple of str
        What the CI resamples (:func:`fsdvs_hw.stats.difference_ci`).
    n_resamples : int

    Returns
    -------
    dict
        ``size``, ``label``, ``metric_mean``, ``metric_std``, ``per_seed`` and, for a size other than
        1, ``gain``, ``gain_ci95_low``, ``gain_ci95_high`` (metric units).
    """
    from ..stats import difference_ci

    row: dict[str, Any] = {
        "size": size,
        "label": "w/o" if size == 1 else f"{size}x{size}",
        "metric_mean": float(np.mean(values[size])),
        "metric_std": float(np.std(values[size], ddof=1)) if n_seeds > 1 else 0.0,
        "per_seed": values[size],
    }
    if size != 1:
        ci = difference_ci(
            metrics[size],
            metrics[1],
            paired_seeds=False,
            paired_clips=True,
            resample=resample,
            n_resamples=n_resamples,
            rng=0,
        )
        row.update(gain=ci.estimate, gain_ci95_low=ci.low, gain_ci95_high=ci.high)
    return row


def _markdown(
    task: str,
    source: Any,
    metric_name: str,
    n_clips: int,
    n_seeds: int,
    resample: tuple[str, ...],
    rows: Sequence[dict[str, Any]],
) -> str:
    """``ablation.md``: a table of each size's metric (mean ± std over seeds) and gain over w/o."""
    lines = [
        f"# Kernel-size ablation on {task} ({source})",
        "",
        f"{metric_name} on {n_clips} scored clips, {n_seeds} seed(s); gain over w/o with a "
        f"95 % bootstrap CI resampling {' and '.join(resample)}.",
        "",
        f"| kernel | {metric_name} (mean ± std) | gain over w/o [95 % CI] |",
        "|---|---|---|",
    ]
    for r in rows:
        gain = "—" if r["size"] == 1 else f"{r['gain']:+.3f} [{r['gain_ci95_low']:+.3f}, {r['gain_ci95_high']:+.3f}]"
        lines.append(f"| {r['label']} | {r['metric_mean']:.3f} ± {r['metric_std']:.3f} | {gain} |")
    return "\n".join(lines) + "\n"


def _by_size(
    jobs: Sequence[tuple[Any, ...]], done: dict[tuple[int, int], tuple[Any, float, int]], sizes: Sequence[int]
) -> tuple[dict[int, list[Any]], dict[int, list[float]], int]:
    """The runs' results grouped by kernel size, in (size, seed) order whatever order the workers finished in.

    Parameters
    ----------
    jobs : sequence of tuple
        :func:`_train_and_score` arguments (size at 4, seed at 5).
    done : dict
        (size, seed) → its result (:func:`_run_jobs`).
    sizes : sequence of int

    Returns
    -------
    metrics : dict
        Size → per-seed per-clip metric objects.
    values : dict
        Size → per-seed metric (fraction).
    n_clips : int
        Scored clips (of the last run; every run scores the same clips).
    """
    metrics: dict[int, list[Any]] = {k: [] for k in sizes}
    values: dict[int, list[float]] = {k: [] for k in sizes}
    n_clips = 0
    for job in jobs:
        metric, value, n_clips = done[job[4], job[5]]
        metrics[job[4]].append(metric)
        values[job[4]].append(value)
    return metrics, values, n_clips


def _run_jobs(jobs: Sequence[tuple[Any, ...]], workers: int) -> dict[tuple[int, int], tuple[Any, float, int]]:
    """Every job's :func:`_train_and_score` result by (size, seed): here, or on a local process pool."""
    if workers <= 1 or len(jobs) <= 1:
        return {(j[4], j[5]): _train_and_score(*j) for j in jobs}
    from concurrent.futures import as_completed

    from ..environment import set_env
    from ..workers import process_pool

    set_env("FSDVS_HW_WORKER_THREADS", "1", default=True)
    pool = process_pool(min(workers, len(jobs)))  # workers die with this process (no orphans)
    futures = {pool.submit(_train_and_score, *j): (j[4], j[5]) for j in jobs}
    out = {}
    try:
        for fut in as_completed(futures):
            out[futures[fut]] = fut.result()
    except BaseException:  # a failed run or Ctrl-C: the finished checkpoints stay for a rerun
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
    return out


def _train_and_score(
    task: str,
    entry: dict[str, Any],
    base_dir: str,
    confine: Confinement,
    size: int,
    seed: int,
    stem: str,
    verbose: bool,
) -> tuple[Any, float, int]:
    """One run: train (or reuse / resume ``stem``) the network and kernel of one size and seed, score it.

    Returns the per-clip metric object, the metric and the number of scored clips.
    """
    from ..design.user_data_inputs import open_dataset
    from ..environment import env
    from ..explore.paired import PER_CLIP_METRICS
    from ..explore.user_data import train_user_task
    from ..tasks.dataset_eval import evaluate_sampled, evaluator_for_dataset

    threads = env("FSDVS_HW_WORKER_THREADS")
    if threads:
        import torch

        torch.set_num_threads(int(threads))
    ds = open_dataset(entry["dataset"], base_dir, confine=confine, key=f"tasks.datasets.{task}.dataset")
    with labelled_stderr(f"[{task} k={size} s={seed}] "):  # parallel runs' lines say which run they are from
        res = train_user_task(
            task,
            entry,
            base_dir,
            confine=confine,
            verbose=verbose,
            overrides={"kernel_size": size, "seed": seed},
            out=stem,
        )
    ev = evaluate_sampled(  # several clips per video with a sampling table, scored per video
        res.kernel,
        task,
        ds,
        res.network,
        sampling=entry.get("sampling"),
        n_clips=entry["n_clips"] or None,
        seed=entry["seed"],
        device=entry["device"],
    )
    evaluator = evaluator_for_dataset(task, ds)
    metric = PER_CLIP_METRICS[evaluator.name](ev.predictions, ev.targets, evaluator)
    n = len(ev.clip_indices)
    return metric, float(metric.weighted(np.ones((1, n)))[0]), n
