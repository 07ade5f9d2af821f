"""The kernel-size ablation (``fsdvs-hw ablation``, :mod:`fsdvs_hw.cli.ablation`) sharded over the sweep executor, resumable.

Every training run (:mod:`fsdvs_hw.tasks.ablation`: one task, kernel size and seed; or a network
trained with a given kernel frozen; or the zero-shot swap) is one point of the project's sweep
executor (:func:`fsdvs_hw.explore.sweep.run_points`): a local process pool (one torch thread per
process) or a Dask cluster, each result committed to a SQLite :class:`~fsdvs_hw.explore.store.ResultsStore`
as it finishes, finished runs skipped on a rerun (kill it and run the same command again to
resume). Per-clip test predictions go to ``OUT/predictions/KEY.npz``; the tables with the gain
over w/o and its 95 % CI (paired over the fixed test clips, bootstrap over clips and seeds,
:func:`fsdvs_hw.stats.difference_cis`) are written to ``OUT/ablation.md``.

Phases: (1) the size ablation; (2) when ``--transfer`` is given: the segmentation transfer of
that kernel (Table III) and, with ``--frozen-tasks``, networks for other tasks trained with the
kernel frozen (what :mod:`fsdvs_hw.explore.scoring` scores realised kernels in). ``--transfer
from-run`` uses the 7×7 detection kernel of the first seed learned in phase 1.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..environment import env
from ..errors import InputError
from ..paths import write_output

__all__ = [
    "AblationOptions",
    "AblationPoint",
    "AblationStudy",
    "ablation_points",
    "annotate_shipped",
    "evaluate_ablation_point",
    "run_ablation",
    "run_ablation_study",
]

_DESIGN = "ablation"


@dataclass(frozen=True)
class AblationPoint:
    """One training run as a sweep point (the fields :func:`~fsdvs_hw.explore.sweep.run_points` reads)."""

    key: str
    job: dict[str, Any] = field(repr=False)
    design: str = _DESIGN

    @property
    def realisation(self) -> str:
        return f"{self.job['kind']} {self.job['task']}"

    @property
    def params(self) -> dict[str, Any]:
        return {"kind": self.job["kind"], "task": self.job["task"], "size": self.job["size"], "seed": self.job["seed"]}

    @property
    def label(self) -> str:
        j = self.job
        return f"{j['kind']} {j['task']} {j['size']}x{j['size']} s{j['seed']}"


def ablation_points(
    jobs: list[dict[str, Any]], pred_dir: Path, ship: dict[str, Path] | None = None
) -> list[AblationPoint]:
    """Wrap :mod:`fsdvs_hw.tasks.ablation` jobs as sweep points (``ship``: job key → file stem)."""
    from ..tasks.ablation import job_key

    points = []
    for j in jobs:
        key = job_key(j)
        job = {**j, "pred_dir": str(pred_dir)}
        if ship and key in ship:
            job["out"] = str(ship[key])
        points.append(AblationPoint(key=key, job=job))
    return points


def evaluate_ablation_point(point: AblationPoint) -> dict[str, Any]:
    """Run one training (in a worker); never raises: a failure becomes an ``"error"`` status."""
    if env("FSDVS_HW_WORKER_THREADS"):
        import torch

        torch.set_num_threads(int(env("FSDVS_HW_WORKER_THREADS") or 1))
    from ..tasks.ablation import run_job

    t0 = time.perf_counter()
    try:
        status, rec = "ok", run_job(point.job)
    except Exception as exc:  # noqa: BLE001 - one failed run must not stop the ablation; it is recorded
        status, rec = "error", {"reason": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc(limit=8)}
    return {
        "key": point.key,
        "status": status,
        "result": rec,
        "wall_s": time.perf_counter() - t0,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }


def run_ablation(
    points: list[AblationPoint],
    store_path: str | Path,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool | None = None,
) -> list[dict[str, Any]]:
    """Run every point not yet stored; return the records of all ``points`` (status ``ok``) in order."""
    from ..explore.store import ResultsStore
    from ..explore.sweep import run_points

    if workers < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    with ResultsStore(store_path) as store:
        summary = run_points(
            points,
            store,
            workers=workers,
            scheduler=scheduler,
            progress=progress,
            evaluate=evaluate_ablation_point,
            desc="training runs",
        )
        print(f"[ablation] {summary}", file=sys.stderr, flush=True)
        rows = {r["key"]: r for r in store.rows(design=_DESIGN)}
    out = []
    for p in points:
        r = rows.get(p.key)
        if r is None or r["status"] != "ok":
            reason = r.get("result", {}).get("reason", "not run") if r else "not run"
            print(f"[ablation] {p.label}: {r['status'] if r else 'missing'} ({reason})", file=sys.stderr, flush=True)
            continue
        out.append(dict(r["result"]))
    return out


@dataclass(frozen=True)
class AblationOptions:
    """What one ablation study runs (the ``fsdvs-hw ablation`` flags, typed).

    Attributes
    ----------
    tasks, sizes, seeds : tuple
        Tasks, odd kernel sizes in pixels (1 = w/o) and training seeds of the size ablation.
    n_train, n_test : int, optional
        Training / test clips per run (default: the task's, 2048).
    epochs_frozen, epochs_joint : int, optional
        Epochs of the frozen-filter and joint stages (default: the protocol's, 16 each).
    workers : int
        Local worker processes, 1..256.
    scheduler : str, optional
        Dask scheduler address (``tcp://HOST:PORT``) instead of local processes.
    progress : bool, optional
        Progress bar on stderr (None, the default: when stderr is a terminal; see :mod:`fsdvs_hw.progress`).
    transfer : str, optional
        Kernel file for the segmentation transfer, or ``"from-run"`` (the first seed's 7×7
        detection kernel learned here).
    frozen_tasks : tuple of str
        With ``transfer``: tasks whose networks are also trained with that kernel frozen.
    transfer_only, frozen_only : bool
        Skip the size ablation / train only the frozen-kernel networks, seed by seed.
    out : Path
        Folder: ``runs.sqlite``, ``predictions/``, ``ablation.md``, ``ablation.json``.
    ship_dir : Path, optional
        Where the 7×7 learned kernels and the frozen-kernel networks are saved.
    from_store : bool
        Do not train: rebuild the tables from the store.
    command : str
        The command line quoted under the tables.
    """

    tasks: tuple[str, ...] = ("detection", "recognition")
    sizes: tuple[int, ...] = (1, 3, 5, 7, 9)
    seeds: tuple[int, ...] = (0, 1, 2)
    n_train: int | None = None
    n_test: int | None = None
    epochs_frozen: int | None = None
    epochs_joint: int | None = None
    workers: int = 1
    scheduler: str | None = None
    progress: bool | None = None
    transfer: str | None = None
    frozen_tasks: tuple[str, ...] = ()
    transfer_only: bool = False
    frozen_only: bool = False
    out: Path = Path("out") / "ablation"
    ship_dir: Path | None = None
    from_store: bool = False
    command: str = "fsdvs-hw ablation"


@dataclass(frozen=True)
class AblationStudy:
    """What :func:`run_ablation_study` produced: the Markdown tables and the run records."""

    markdown: str
    records: list[dict[str, Any]]
    transfer: list[dict[str, Any]]
    markdown_path: Path
    json_path: Path


def _settings(args: AblationOptions) -> dict[str, Any]:
    return {
        k: v for k, v in (("epochs_frozen", args.epochs_frozen), ("epochs_joint", args.epochs_joint)) if v is not None
    }


def _ship_stem(ship_dir: Path, job: dict[str, Any], first_seed: int, kernel_stem: str) -> Path | None:
    if job["kind"] == "size" and job["size"] == 7:
        tail = "" if job["seed"] == first_seed else f"_s{job['seed']}"
        return ship_dir / f"learned_{job['task']}_7x7{tail}"
    if job["kind"] == "frozen":
        return ship_dir / "networks" / f"{job['task']}_with_{kernel_stem}_s{job['seed']}"
    return None


def run_ablation_study(args: AblationOptions) -> AblationStudy:
    """Run (or resume, or rebuild from the store) one ablation study and write its tables.

    Writes ``OUT/ablation.md`` and ``OUT/ablation.json``; see the module docstring for the phases.

    Raises
    ------
    InputError
        Inconsistent options (``workers`` outside 1..256, ``transfer_only`` without a kernel file,
        ...); the message names the command-line flag.
    """
    from ..paths import output_dir
    from ..tasks.ablation import ablation_jobs, ablation_markdown, frozen_kernel_jobs, transfer_jobs, transfer_markdown

    if not 1 <= args.workers <= 256:
        raise InputError(f"--workers {args.workers}: must be an integer in 1..256")
    t0 = time.perf_counter()
    out: Path = output_dir(args.out, flag="--out")  # checked before hours of training
    if args.ship_dir is not None:
        output_dir(args.ship_dir, flag="--ship-dir")
    pred_dir = out / "predictions"
    store = out / "runs.sqlite"
    settings = _settings(args) or None
    kw: dict[str, Any] = {"n_train": args.n_train, "n_test": args.n_test, "settings": settings}
    exe = {"workers": args.workers, "scheduler": args.scheduler, "progress": args.progress}
    if args.transfer_only and (not args.transfer or args.transfer == "from-run"):
        raise InputError("--transfer-only needs --transfer KERNEL_FILE")
    if args.frozen_only and (not args.transfer or args.transfer == "from-run" or not args.frozen_tasks):
        raise InputError("--frozen-only needs --transfer KERNEL_FILE and --frozen-tasks TASK ...")
    records: list[dict[str, Any]] = []
    if not (args.transfer_only or args.frozen_only):
        jobs = ablation_jobs(list(args.tasks), list(args.sizes), list(args.seeds), **kw)
        ship = None
        if args.ship_dir is not None:
            from ..tasks.ablation import job_key

            ship = {job_key(j): s for j in jobs if (s := _ship_stem(args.ship_dir, j, args.seeds[0], "")) is not None}
        points = ablation_points(jobs, pred_dir, ship)
        records = _collect(points, store, exe, args.from_store)
    text = ablation_markdown(records, pred_dir) if records else ""
    transfer: list[dict[str, Any]] = []
    if args.transfer:
        kpath = _transfer_kernel(args, records, out)
        stem = kpath.name.removesuffix(".json")
        if args.frozen_only:
            jobs = sorted(
                frozen_kernel_jobs(kpath, list(args.frozen_tasks), list(args.seeds), **kw),
                key=lambda j: (args.seeds.index(j["seed"]), args.frozen_tasks.index(j["task"])),
            )
        else:
            jobs = transfer_jobs(kpath, list(args.seeds), **kw)
        if args.frozen_tasks and not args.frozen_only:
            jobs += frozen_kernel_jobs(
                kpath, [t for t in args.frozen_tasks if t != "segmentation"], list(args.seeds), **kw
            )
        ship = None
        if args.ship_dir is not None:
            from ..tasks.ablation import job_key

            ship = {job_key(j): s for j in jobs if (s := _ship_stem(args.ship_dir, j, args.seeds[0], stem)) is not None}
        transfer = _collect(ablation_points(jobs, pred_dir, ship), store, exe, args.from_store)
        text += "\n" + transfer_markdown(transfer, stem, pred_dir)
        others = [r for r in transfer if r["kind"] == "frozen" and (args.frozen_only or r["task"] != "segmentation")]
        if others:
            text += "\n" + _frozen_markdown(others, stem)
    shipped = annotate_shipped(records + transfer, pred_dir)
    if shipped:
        print(f"[ablation] held-out metric CIs written to {len(shipped)} shipped provenance files", file=sys.stderr)
    text += f"\nMeasured with `{args.command}` (this invocation: {time.perf_counter() - t0:.0f} s wall).\n"
    write_output(out / "ablation.json", json.dumps({"records": records, "transfer": transfer}, indent=1))
    write_output(out / "ablation.md", text)
    return AblationStudy(text, records, transfer, out / "ablation.md", out / "ablation.json")


def annotate_shipped(records: list[dict[str, Any]], pred_dir: Path, *, n_resamples: int = 1000) -> list[Path]:
    """Add the held-out metric's 95 % CI (bootstrap over test clips) to every shipped run's provenance file.

    For each record that saved files (``--ship-dir``), ``STEM.provenance.json`` gains
    ``heldout_metric`` (primary metric on the test clips), ``heldout_ci95_low``/``heldout_ci95_high``
    (percentile bootstrap over the clips with :func:`scipy.stats.bootstrap`, one network: training-seed
    variance is not in it; the ablation table's CIs carry it), ``heldout_n_clips`` and
    ``ablation_key`` (the run's key in the ablation store).

    Returns
    -------
    list of Path
        The provenance files updated.
    """
    from scipy import stats

    from ..tasks.ablation import clip_metric
    from ..tasks.learn import heldout_targets

    done = []
    for r in records:
        files = r.get("files") or {}
        prov_path = Path(files["provenance"]) if "provenance" in files else None
        pred = pred_dir / r["predictions"] if r.get("predictions") else None
        if prov_path is None or not prov_path.is_file() or pred is None or not pred.is_file():
            continue
        targets = heldout_targets(r["task"], r["scene"], int(r["n_test"]))
        with np.load(pred) as z:
            metric = clip_metric(r["task"], {k: z[k] for k in z.files}, targets)
        n = metric.n_clips

        def statistic(idx: np.ndarray, axis: int = -1) -> np.ndarray:
            flat = idx.reshape(-1, idx.shape[-1])
            w = np.stack([np.bincount(row, minlength=n) for row in flat]).astype(np.float64)  # noqa: B023 - bootstrap runs in this iteration
            return metric.weighted(w).reshape(idx.shape[:-1])  # noqa: B023

        res = stats.bootstrap(
            (np.arange(n),),
            statistic,
            vectorized=True,
            n_resamples=n_resamples,
            method="percentile",
            random_state=np.random.default_rng(0),
            batch=200,
        )
        prov = json.loads(prov_path.read_text())
        prov.update(
            heldout_metric=float(metric.weighted(np.ones((1, n)))[0]),
            heldout_ci95_low=float(res.confidence_interval.low),
            heldout_ci95_high=float(res.confidence_interval.high),
            heldout_n_clips=n,
            heldout_ci_method="percentile bootstrap over test clips (scipy.stats.bootstrap), one network",
            ablation_key=r["key"],
        )
        write_output(prov_path, json.dumps(prov, indent=1) + "\n", flag="provenance")
        done.append(prov_path)
    return done


def _collect(points: list[AblationPoint], store: Path, exe: dict[str, Any], from_store: bool) -> list[dict[str, Any]]:
    if from_store:
        from ..explore.store import ResultsStore

        if not store.is_file():
            raise InputError(f"--from-store: {str(store)!r} not found")
        with ResultsStore(store) as st:
            rows = {r["key"]: r for r in st.rows(design=_DESIGN) if r["status"] == "ok"}
        return [dict(rows[p.key]["result"]) for p in points if p.key in rows]
    return run_ablation(points, store, **exe)


def _transfer_kernel(args: AblationOptions, records: list[dict[str, Any]], out: Path) -> Path:
    assert args.transfer is not None  # called only with --transfer
    if args.transfer != "from-run":
        p = Path(args.transfer)
        if not p.is_file():
            raise InputError(f"--transfer: kernel file {str(p)!r} not found")
        return p
    from ..kernels import Kernel

    first = [r for r in records if r["task"] == "detection" and r["size"] == 7 and r["seed"] == args.seeds[0]]
    if not first:
        raise InputError(
            "--transfer from-run needs the 7x7 detection run of the first seed (--tasks detection, --sizes including 7)"
        )
    shipped = args.ship_dir / "learned_detection_7x7.json" if args.ship_dir is not None else None
    if shipped is not None and shipped.is_file():
        from ..kernels import load_kernel

        if not np.allclose(np.asarray(load_kernel(shipped).taps), np.asarray(first[0]["taps"]), atol=1e-6):
            raise InputError(
                f"--transfer from-run: {str(shipped)!r} is not the kernel of the stored 7x7 detection "
                "run (written by another run?); pass that file as --transfer or re-ship it"
            )
        return shipped
    k = Kernel(np.asarray(first[0]["taps"]), name=f"learned detection 7x7 (seed {args.seeds[0]})")
    path = out / "learned_detection_7x7.json"
    k.save(path)
    return path


def _frozen_markdown(records: list[dict[str, Any]], stem: str) -> str:
    from ..tasks.evaluators import get_evaluator

    lines = [
        f"**networks trained with {stem} frozen** (for the exploration's scoring; metric ×100 on the test clips)\n",
        "| Task | seed | metric | value |",
        "|---|---|---|---|",
    ]
    for r in sorted(records, key=lambda r: (r["task"], r["seed"])):
        ev = get_evaluator(r["task"])
        lines.append(
            f"| {r['task']} | {r['seed']} | {ev.primary_metric} | {r['metrics'][ev.primary_metric] * 100:.1f} |"
        )
    return "\n".join(lines) + "\n"
