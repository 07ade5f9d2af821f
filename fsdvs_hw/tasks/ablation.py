"""Kernel-size ablation (the FS-DVS paper's Tables I-II) and the zero-shot transfer table (Table III).

``fsdvs-hw ablation`` trains, for every task, kernel size and seed, one network with
:func:`~fsdvs_hw.tasks.learn.learn_kernel` ("w/o" = the 1×1 delta, i.e. a conventional DVS, with the
same total number of epochs), and reports mean ± sample standard deviation over seeds of every
metric on the fixed test clips, with the gain over "w/o". For each learned kernel it also records
its shape: the sign of the centre tap against the summed surround (centre-surround or not), where
its radial response peaks (:func:`fsdvs_hw.spectra.spectral_summary`) and its agreement with the
Mannos-Sakrison CSF (:func:`fsdvs_hw.csf.csf_agreement`, pixels-per-degree fitted).

The transfer table follows Table III: a segmentation network is trained with the filter frozen
at (a) the delta ("w/o") and (b) the learned detection kernel, without retraining the kernel.

Runs are independent, so ``workers > 1`` spreads them over processes (each single-threaded).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import as_completed
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..kernels import Kernel
from ..workers import process_pool

__all__ = ["run_ablation", "kernel_shape", "ablation_markdown", "transfer_markdown", "run_transfer",
           "HELP", "add_arguments", "run"]

HELP = "kernel-size ablation (w/o, 3, 5, 7, 9) on detection and recognition, mean ± std over seeds"
DESCRIPTION = (
    "Train one network per (task, kernel size, seed) with the FS-DVS protocol and print the\n"
    "paper-style tables (mean ± std over seeds, gain over the w/o baseline), the learned kernels'\n"
    "shape (centre-surround, radial peak, Mannos-Sakrison agreement), and the zero-shot transfer\n"
    "of the 7x7 detection kernel to segmentation.\n\n"
    "Example (the README table): fsdvs-hw ablation --seeds 0 1 2 --workers 2 --out out/ablation"
)


def kernel_shape(kernel: Kernel) -> dict[str, Any]:
    """Shape descriptors of a learned kernel.

    Returns
    -------
    dict
        ``centre`` (centre tap), ``surround_sum`` (sum of all other taps), ``ring1_mean`` (mean of
        the 8 taps around the centre), ``centre_surround`` (True when the centre and the summed
        surround have opposite signs and the surround is at least 5 % of the centre: an
        excitatory centre with an inhibitory surround or vice versa), ``dc_gain``,
        ``peak_frequency_cpp``, ``kind`` (spectral band type), and Mannos-Sakrison agreement
        ``ms_correlation``, ``ms_peak_ratio``, ``ms_rms_error`` (pixels per degree fitted).
    """
    from ..csf import csf_agreement
    from ..spectra import spectral_summary

    taps = np.asarray(kernel.taps)
    r = kernel.radius
    centre = float(taps[r, r])
    surround = float(taps.sum() - centre)
    if r >= 1:
        ring = taps[r - 1 : r + 2, r - 1 : r + 2].copy()
        ring1 = float((ring.sum() - centre) / 8.0)
    else:
        ring1 = 0.0
    cs = bool(r >= 1 and centre * surround < 0 and abs(surround) >= 0.05 * abs(centre))
    out: dict[str, Any] = {"centre": centre, "surround_sum": surround, "ring1_mean": ring1, "centre_surround": cs}
    summ = spectral_summary(kernel)
    out.update(dc_gain=float(summ.dc_gain), peak_frequency_cpp=float(summ.peak_frequency_cpp), kind=summ.kind)
    if r >= 1:
        agr = csf_agreement(kernel)
        out.update(ms_correlation=float(agr.correlation), ms_peak_ratio=float(agr.peak_ratio),
                   ms_rms_error=float(agr.rms_error))
    return out


def _one_run(job: dict[str, Any]) -> dict[str, Any]:
    import torch

    from .learn import TrainingSettings, learn_kernel

    torch.set_num_threads(1)
    settings = TrainingSettings(**job["settings"]) if job.get("settings") else None
    t0 = time.perf_counter()
    kw = {k: job[k] for k in ("n_train", "n_test") if job.get(k)}
    res = learn_kernel(job["task"], job["size"], seed=job["seed"], settings=settings, learn_filter=job["size"] > 1,
                       init_kernel=job.get("init_kernel"), out=job.get("out"), **kw)
    rec = {"task": job["task"], "size": job["size"], "seed": job["seed"], "metrics": res.metrics,
           "primary": res.primary_metric, "seconds": time.perf_counter() - t0,
           "event_rate": res.provenance["test_event_rate_per_pixel_frame"], "taps": res.kernel.taps.tolist(),
           "final_loss": res.history[-1]["loss"] if res.history else None}
    if job["size"] > 1:
        rec["shape"] = kernel_shape(res.kernel)
    print(f"[ablation] {job['task']} {job['size']}x{job['size']} seed {job['seed']}: "
          f"{res.primary_metric} {res.value:.4f} ({rec['seconds']:.0f} s)", file=sys.stderr, flush=True)
    return rec


def _map(jobs: list[dict[str, Any]], workers: int, fn: Any = None, log_path: Path | None = None) -> list[dict[str, Any]]:
    """Run ``fn`` over ``jobs`` (in ``workers`` processes); append each record to ``log_path`` (JSON lines)."""
    fn = fn or _one_run
    out: list[dict[str, Any]] = []

    def _keep(rec: dict[str, Any]) -> None:
        out.append(rec)
        if log_path is not None:
            with open(log_path, "a") as fh:
                fh.write(json.dumps(rec) + "\n")

    if workers <= 1:
        for j in jobs:
            _keep(fn(j))
        return out
    with process_pool(workers) as pool:  # spawned workers that die with this process
        futures = [pool.submit(fn, j) for j in jobs]
        for fut in as_completed(futures):
            _keep(fut.result())
    return out


def run_ablation(tasks: Sequence[str] = ("detection", "recognition"), sizes: Sequence[int] = (1, 3, 5, 7, 9),
                 seeds: Sequence[int] = (0, 1, 2), *, n_train: int | None = None, n_test: int | None = None,
                 settings: dict[str, Any] | None = None, workers: int = 1,
                 log_path: Path | None = None, ship_dir: Path | None = None) -> list[dict[str, Any]]:
    """Train every (task, size, seed) and return one record per run.

    Parameters
    ----------
    tasks : sequence of str
        Registered task names.
    sizes : sequence of int
        Odd kernel sizes; 1 is the "w/o" baseline (conventional DVS).
    seeds : sequence of int
        Training seeds (clips, initial noise, network, batch order); test clips are fixed.
    n_train, n_test : int, optional
        Data sizes (default: :func:`learn_kernel`'s).
    settings : dict, optional
        :class:`~fsdvs_hw.tasks.learn.TrainingSettings` fields.
    workers : int
        Processes to run in parallel.
    log_path : path, optional
        Append every finished run to this JSON-lines file (partial results survive an interrupt).
    ship_dir : path, optional
        Save the 7×7 runs of the first seed as ``ship_dir/learned_{task}_7x7.{json,safetensors,
        provenance.json}`` (how the shipped kernels in ``designs/kernels`` are made).

    Returns
    -------
    list of dict
        ``task, size, seed, metrics, primary, seconds, event_rate, taps`` (+ ``shape`` for k > 1).
    """
    from .evaluators import get_evaluator

    for t in tasks:
        get_evaluator(t)
    for s in sizes:
        if isinstance(s, bool) or not isinstance(s, int) or s < 1 or s % 2 == 0:
            raise InputError(f"ablation: sizes must be odd integers >= 1, got {s!r}")
    if not seeds:
        raise InputError("ablation: give at least one seed")
    jobs = [{"task": t, "size": s, "seed": int(sd), "n_train": n_train, "n_test": n_test, "settings": settings}
            for t in tasks for s in sizes for sd in seeds]
    if ship_dir is not None:
        for j in jobs:
            if j["size"] == 7 and j["seed"] == seeds[0]:
                j["out"] = str(Path(ship_dir) / f"learned_{j['task']}_7x7")
    # longest first (large kernels, detection) so parallel workers finish together
    jobs.sort(key=lambda j: (-j["size"], j["task"]))
    return _map(jobs, workers, _one_run, log_path)


def run_transfer(det_kernel: Kernel, seeds: Sequence[int] = (0, 1, 2), *, n_train: int | None = None,
                 n_test: int | None = None, settings: dict[str, Any] | None = None,
                 workers: int = 1, log_path: Path | None = None) -> list[dict[str, Any]]:
    """Segmentation with the filter frozen at the delta ("w/o") and at ``det_kernel`` (not retrained)."""
    jobs = []
    for sd in seeds:
        jobs.append({"task": "segmentation", "size": 1, "seed": int(sd), "n_train": n_train, "n_test": n_test,
                     "settings": settings, "zero_shot_kernel": det_kernel})
        jobs.append({"task": "segmentation", "size": det_kernel.size, "seed": int(sd), "n_train": n_train,
                     "n_test": n_test, "settings": settings, "init_kernel": det_kernel})
    return _map(jobs, workers, _one_transfer, log_path)


def _one_transfer(job: dict[str, Any]) -> dict[str, Any]:
    import torch

    from .learn import TrainingSettings, learn_kernel

    torch.set_num_threads(1)
    settings = TrainingSettings(**job["settings"]) if job.get("settings") else None
    kw = {k: job[k] for k in ("n_train", "n_test") if job.get(k)}
    t0 = time.perf_counter()
    zk = job.get("zero_shot_kernel")
    with tempfile.TemporaryDirectory() as tmp:
        res = learn_kernel("segmentation", job["size"], seed=job["seed"], settings=settings, learn_filter=False,
                           init_kernel=job.get("init_kernel"), out=Path(tmp) / "seg" if zk is not None else None,
                           **kw)
        rec = {"task": "segmentation", "size": job["size"], "seed": job["seed"], "metrics": res.metrics,
               "primary": res.primary_metric, "seconds": time.perf_counter() - t0,
               "event_rate": res.provenance["test_event_rate_per_pixel_frame"]}
        if zk is not None:  # swap the detection kernel into the network trained on conventional DVS events
            from .learn import evaluate_kernel

            rec["zero_shot_metrics"] = evaluate_kernel(zk, "segmentation", res.paths["checkpoint"]).metrics
    print(f"[transfer] segmentation {job['size']}x{job['size']} seed {job['seed']}: miou {res.value:.4f}",
          file=sys.stderr, flush=True)
    return rec


def _mean_std(values: list[float]) -> tuple[float, float]:
    a = np.asarray(values, dtype=np.float64)
    return float(a.mean()), (float(a.std(ddof=1)) if a.size > 1 else float("nan"))


def _fmt(m: float, s: float, scale: float = 100.0) -> str:
    return f"{m * scale:.1f} ± {s * scale:.1f}" if math.isfinite(s) else f"{m * scale:.1f}"


def _group(records: list[dict[str, Any]], task: str) -> dict[int, list[dict[str, Any]]]:
    out: dict[int, list[dict[str, Any]]] = {}
    for r in records:
        if r["task"] == task:
            out.setdefault(r["size"], []).append(r)
    return dict(sorted(out.items()))


def ablation_markdown(records: list[dict[str, Any]]) -> str:
    """Paper-style tables (metrics ×100, mean ± std over seeds) plus the learned kernels' shape."""
    from .evaluators import get_evaluator

    lines: list[str] = []
    for task in dict.fromkeys(r["task"] for r in records):
        ev = get_evaluator(task)
        groups = _group(records, task)
        n_seeds = max(len(v) for v in groups.values())
        names = list(ev.metric_names)
        base = _mean_std([r["metrics"][ev.primary_metric] for r in groups.get(1, [])]) if 1 in groups else None
        lines.append(f"**{task}** ({n_seeds} seeds; metrics ×100, mean ± std; Δ = gain of the mean over w/o)\n")
        lines.append("| Filter | " + " | ".join(names) + f" | Δ {ev.primary_metric} | events / px / frame |")
        lines.append("|---" * (len(names) + 3) + "|")
        for size, recs in groups.items():
            cells = [_fmt(*_mean_std([r["metrics"][k] for r in recs])) for k in names]
            prim = _mean_std([r["metrics"][ev.primary_metric] for r in recs])[0]
            delta = f"{(prim - base[0]) * 100:+.1f}" if base else "—"
            rate = np.mean([r["event_rate"] for r in recs])
            label = "w/o" if size == 1 else f"{size}×{size}"
            lines.append(f"| {label} | " + " | ".join(cells) + f" | {delta} | {rate:.4f} |")
        lines.append("")
    shaped = [r for r in records if "shape" in r]
    if shaped:
        lines.append("**Learned kernels** (per task and size: how many seeds gave a centre-surround kernel; "
                     "means over seeds)\n")
        lines.append("| Task | Filter | centre-surround | centre | surround sum | DC gain | radial peak (cyc/px) "
                     "| MS correlation | MS peak ratio |")
        lines.append("|---|---|---|---|---|---|---|---|---|")
        for task in dict.fromkeys(r["task"] for r in shaped):
            for size, recs in _group(shaped, task).items():
                sh = [r["shape"] for r in recs]
                n_cs = sum(s["centre_surround"] for s in sh)
                m = {k: float(np.mean([s[k] for s in sh])) for k in
                     ("centre", "surround_sum", "dc_gain", "peak_frequency_cpp", "ms_correlation", "ms_peak_ratio")}
                lines.append(f"| {task} | {size}×{size} | {n_cs}/{len(sh)} | {m['centre']:.3f} | "
                             f"{m['surround_sum']:+.3f} | {m['dc_gain']:.3f} | {m['peak_frequency_cpp']:.3f} | "
                             f"{m['ms_correlation']:.2f} | {m['ms_peak_ratio']:.2f} |")
        lines.append("")
    return "\n".join(lines)


def transfer_markdown(records: list[dict[str, Any]], kernel_name: str) -> str:
    """Table III: segmentation with the delta vs the (frozen) detection kernel."""
    from .evaluators import get_evaluator

    ev = get_evaluator("segmentation")
    groups = _group(records, "segmentation")
    base = _mean_std([r["metrics"]["miou"] for r in groups.get(1, [])])[0] if 1 in groups else None
    n_seeds = max(len(v) for v in groups.values())
    lines = [f"**segmentation, zero-shot kernel transfer** ({n_seeds} seeds; kernel = {kernel_name}, frozen; "
             "metrics ×100, mean ± std)\n",
             "| Filter | " + " | ".join(ev.metric_names) + " | Δ miou |", "|---" * (len(ev.metric_names) + 2) + "|"]
    for size, recs in groups.items():
        cells = [_fmt(*_mean_std([r["metrics"][k] for r in recs])) for k in ev.metric_names]
        prim = _mean_std([r["metrics"]["miou"] for r in recs])[0]
        delta = f"{(prim - base) * 100:+.1f}" if base is not None else "—"
        label = "w/o" if size == 1 else f"{size}×{size} (detection), network trained on its events"
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {delta} |")
    zs = [r for r in groups.get(1, []) if "zero_shot_metrics" in r]
    if zs:
        cells = [_fmt(*_mean_std([r["zero_shot_metrics"][k] for r in zs])) for k in ev.metric_names]
        prim = _mean_std([r["zero_shot_metrics"]["miou"] for r in zs])[0]
        delta = f"{(prim - base) * 100:+.1f}" if base is not None else "—"
        lines.append("| detection kernel swapped into the w/o network (zero-shot, no retraining at all) | "
                     + " | ".join(cells) + f" | {delta} |")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tasks", nargs="+", default=["detection", "recognition"], help="tasks (default: both)")
    parser.add_argument("--sizes", nargs="+", type=int, default=[1, 3, 5, 7, 9],
                        help="odd kernel sizes; 1 = w/o (default 1 3 5 7 9)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2], help="training seeds (default 0 1 2)")
    parser.add_argument("--n-train", type=int, default=None, help="training clips (default 512)")
    parser.add_argument("--n-test", type=int, default=None, help="test clips (default 256)")
    parser.add_argument("--epochs-frozen", type=int, default=None, help="frozen-filter epochs (staged tasks)")
    parser.add_argument("--epochs-joint", type=int, default=None, help="joint epochs")
    parser.add_argument("--workers", type=int, default=1, help="parallel processes (default 1)")
    parser.add_argument("--transfer", default=None, metavar="KERNEL",
                        help="also run the segmentation transfer table with this (detection) kernel file")
    parser.add_argument("--out", type=Path, default=None,
                        help="write runs.jsonl (each run as it finishes), ablation.json and ablation.md here")
    parser.add_argument("--transfer-only", action="store_true",
                        help="skip the size ablation; run only the --transfer table")
    parser.add_argument("--ship-dir", type=Path, default=None,
                        help="save the 7x7 runs of the first seed here as learned_{task}_7x7.* (designs/kernels)")
    parser.add_argument("--from-runs", type=Path, default=None, metavar="RUNS_JSONL",
                        help="do not train: rebuild the tables from a runs.jsonl written earlier")


def _read_runs(path: Path) -> list[dict[str, Any]]:
    """Records of a ``runs.jsonl`` log; :class:`InputError` naming the file and line otherwise."""
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"--from-runs {path}: not UTF-8 text (invalid byte at offset {exc.start})") from None
    recs = []
    for n, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except (json.JSONDecodeError, RecursionError):
            raise InputError(f"--from-runs {path}: line {n} is not a JSON record") from None
        if not isinstance(rec, dict) or not isinstance(rec.get("task"), str):
            raise InputError(f"--from-runs {path}: line {n} is not a run record (needs a 'task' field)")
        recs.append(rec)
    return recs


def run(args: argparse.Namespace) -> int:
    from ..kernels import load_kernel
    from ..paths import output_dir

    if not 1 <= args.workers <= 256:
        raise InputError(f"--workers {args.workers}: must be an integer in 1..256")

    if args.from_runs is not None:
        if not args.from_runs.is_file():
            raise InputError(f"--from-runs: {str(args.from_runs)!r} not found")
        recs = _read_runs(args.from_runs)
        main = [r for r in recs if r["task"] != "segmentation"]
        seg = [r for r in recs if r["task"] == "segmentation"]
        text = ablation_markdown(main) if main else ""
        if seg:
            text += "\n" + transfer_markdown(seg, "the 7×7 detection kernel")
        print(text)
        return 0
    settings = {}
    if args.epochs_frozen is not None:
        settings["epochs_frozen"] = args.epochs_frozen
    if args.epochs_joint is not None:
        settings["epochs_joint"] = args.epochs_joint
    t0 = time.perf_counter()
    log_path = None
    if args.out is not None:
        output_dir(args.out, flag="--out")  # checked before hours of training
        log_path = args.out / "runs.jsonl"
    if args.ship_dir is not None:
        output_dir(args.ship_dir, flag="--ship-dir")
    if args.transfer_only and not args.transfer:
        raise InputError("--transfer-only needs --transfer KERNEL")
    records = [] if args.transfer_only else run_ablation(
        args.tasks, args.sizes, args.seeds, n_train=args.n_train, n_test=args.n_test, settings=settings or None,
        workers=args.workers, log_path=log_path, ship_dir=args.ship_dir)
    text = ablation_markdown(records) if records else ""
    transfer = []
    if args.transfer:
        k = load_kernel(args.transfer)
        transfer = run_transfer(k, args.seeds, n_train=args.n_train, n_test=args.n_test,
                                settings=settings or None, workers=args.workers, log_path=log_path)
        text += "\n" + transfer_markdown(transfer, k.name)
    cmd = "fsdvs-hw ablation " + " ".join(sys.argv[2:]) if len(sys.argv) > 2 else "fsdvs-hw ablation"
    text += f"\nMeasured with `{cmd}` in {time.perf_counter() - t0:.0f} s.\n"
    print(text)
    if args.out is not None:
        (args.out / "ablation.json").write_text(json.dumps({"records": records, "transfer": transfer}, indent=1))
        (args.out / "ablation.md").write_text(text)
    return 0
