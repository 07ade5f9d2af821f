"""Kernel-size ablation (the FS-DVS paper's Tables I-II) and the zero-shot transfer table (Table III).

One *run* trains one network with :func:`~fsdvs_hw.tasks.learn.learn_kernel` and keeps its per-clip
predictions on the fixed test clips (:data:`~fsdvs_hw.tasks.learn.TEST_SEED`), so that every
comparison is paired over clips. Three kinds of run (:func:`ablation_jobs`, :func:`transfer_jobs`,
:func:`frozen_kernel_jobs`):

``size``
    a task trained with a k×k kernel learned end to end ("w/o" = the 1×1 delta, i.e. a conventional
    DVS, with the same schedule);
``frozen``
    a task network trained with a given kernel frozen (``learn_filter=False``): the paper's
    segmentation transfer (the detection kernel, not retrained) and the networks the exploration
    scores realised kernels in;
``zero_shot``
    a given kernel swapped into a trained w/o network with no retraining at all.

:func:`run_job` executes one run (the sweep executor in :mod:`fsdvs_hw.studies.kernel_size_ablation` shards
them over processes or a Dask cluster and stores each as it finishes); :func:`ablation_markdown`
and :func:`transfer_markdown` build the tables, with the gain over w/o and its 95 % confidence
interval from :func:`fsdvs_hw.stats.difference_cis` (bootstrap over test clips, paired, and
training seeds). For each learned kernel the table records its shape (:func:`kernel_shape`): the
sign of the centre tap against the summed surround, where its radial response peaks and its
agreement with the Mannos-Sakrison CSF.
"""

from __future__ import annotations

import io
import math
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..fingerprints import fingerprint
from ..kernels import Kernel, delta_taps
from ..paths import write_output

__all__ = [
    "PAPER_GAINS",
    "ablation_jobs",
    "ablation_markdown",
    "clip_metric",
    "frozen_kernel_jobs",
    "job_key",
    "kernel_shape",
    "run_job",
    "transfer_jobs",
    "transfer_markdown",
]

#: The FS-DVS paper's gains of the 7×7 kernel over w/o (metric points ×100): detection mAP
#: (Table I), recognition top-1 (Table II), zero-shot segmentation mIoU (Table III).
PAPER_GAINS: dict[str, float] = {"detection": 12.3, "recognition": 8.9, "segmentation": 4.77}


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
        out.update(
            ms_correlation=float(agr.correlation),
            ms_peak_ratio=float(agr.peak_ratio),
            ms_rms_error=float(agr.rms_error),
        )
    return out


def _check_common(tasks: Sequence[str], seeds: Sequence[int]) -> None:
    from .evaluators import get_evaluator

    for t in tasks:
        get_evaluator(t)
    if not seeds:
        raise InputError("ablation: give at least one seed")
    for sd in seeds:
        if isinstance(sd, bool) or not isinstance(sd, (int, np.integer)) or sd < 0:
            raise InputError(f"ablation: seeds must be non-negative integers, got {sd!r}")


def _job(
    kind: str,
    task: str,
    size: int,
    seed: int,
    n_train: int | None,
    n_test: int | None,
    settings: dict[str, Any] | None,
    **extra: Any,
) -> dict[str, Any]:
    return {
        "kind": kind,
        "task": task,
        "size": int(size),
        "seed": int(seed),
        "n_train": n_train,
        "n_test": n_test,
        "settings": dict(settings or {}),
        **extra,
    }


def ablation_jobs(
    tasks: Sequence[str] = ("detection", "recognition"),
    sizes: Sequence[int] = (1, 3, 5, 7, 9),
    seeds: Sequence[int] = (0, 1, 2),
    *,
    n_train: int | None = None,
    n_test: int | None = None,
    settings: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """One ``size`` run per (task, kernel size, seed), longest first.

    Parameters
    ----------
    tasks : sequence of str
        Registered task names.
    sizes : sequence of int
        Odd kernel sizes; 1 is the "w/o" baseline (conventional DVS).
    seeds : sequence of int
        Training seeds (clips, initial noise, network, batch order); test clips are fixed.
    n_train, n_test : int, optional
        Data sizes (default: :func:`~fsdvs_hw.tasks.learn.learn_kernel`'s).
    settings : dict, optional
        :class:`~fsdvs_hw.tasks.learn.TrainingSettings` fields.
    """
    _check_common(tasks, seeds)
    for s in sizes:
        if isinstance(s, bool) or not isinstance(s, int) or s < 1 or s % 2 == 0:
            raise InputError(f"ablation: sizes must be odd integers >= 1, got {s!r}")
    jobs = [_job("size", t, s, sd, n_train, n_test, settings) for t in tasks for s in sizes for sd in seeds]
    jobs.sort(key=lambda j: (-j["size"], j["task"]))  # long runs first, so parallel workers finish together
    return jobs


def frozen_kernel_jobs(
    kernel_path: str | Path,
    tasks: Sequence[str] = ("detection", "recognition", "segmentation"),
    seeds: Sequence[int] = (0, 1, 2),
    *,
    n_train: int | None = None,
    n_test: int | None = None,
    settings: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """One ``frozen`` run per (task, seed): a network trained with the kernel in ``kernel_path`` frozen."""
    from ..kernels import load_kernel

    _check_common(tasks, seeds)
    k = load_kernel(kernel_path)
    taps = np.asarray(k.taps).tolist()
    return [
        _job("frozen", t, k.size, sd, n_train, n_test, settings, kernel=taps, kernel_name=k.name)
        for t in tasks
        for sd in seeds
    ]


def transfer_jobs(
    kernel_path: str | Path,
    seeds: Sequence[int] = (0, 1, 2),
    *,
    n_train: int | None = None,
    n_test: int | None = None,
    settings: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Table III: segmentation w/o (plus the kernel swapped in zero-shot) and with the kernel frozen."""
    from ..kernels import load_kernel

    k = load_kernel(kernel_path)
    jobs = ablation_jobs(["segmentation"], [1], seeds, n_train=n_train, n_test=n_test, settings=settings)
    for j in jobs:
        j.update(kind="zero_shot", kernel=np.asarray(k.taps).tolist(), kernel_name=k.name)
    return jobs + frozen_kernel_jobs(
        kernel_path, ["segmentation"], seeds, n_train=n_train, n_test=n_test, settings=settings
    )


def job_key(job: dict[str, Any]) -> str:
    """SHA-1 (20 hex chars) of everything that decides a run's result (not where it writes)."""
    decisive = {k: v for k, v in job.items() if k not in ("out", "pred_dir", "kernel_name")}
    return fingerprint(decisive, length=20)


def _save_predictions(path: Path, predictions: dict[str, np.ndarray]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    small: dict[str, Any] = {}  # Any: numpy's stub reads **dict[str, ndarray] as its bool keyword
    for k, v in predictions.items():
        a = np.asarray(v)
        if k == "mask":
            a = a.astype(np.uint8)
        elif a.dtype.kind == "f":
            a = a.astype(np.float32)
        small[k] = a
    buf = io.BytesIO()
    np.savez_compressed(buf, **small)
    write_output(path, buf.getvalue(), flag="predictions")


def run_job(job: dict[str, Any]) -> dict[str, Any]:
    """Train (and score) one run; return its record.

    ``job`` comes from :func:`ablation_jobs`, :func:`transfer_jobs` or :func:`frozen_kernel_jobs`;
    optional keys ``pred_dir`` (save the per-clip test predictions as ``pred_dir/KEY.npz``) and
    ``out`` (file stem: save kernel + checkpoint + provenance there, see
    :func:`~fsdvs_hw.tasks.learn.learn_kernel`).

    Returns
    -------
    dict
        ``key, kind, task, size, seed, metrics, primary, seconds, event_rate, taps`` (+ ``shape``
        for learned kernels, ``zero_shot_metrics`` for zero-shot runs, ``predictions`` and
        ``zero_shot_predictions`` file names, ``n_test``, ``scene``, ``files``).
    """
    from .learn import TrainingSettings, evaluate_kernel, learn_kernel

    t0 = time.perf_counter()
    key = job_key(job)
    kind = job["kind"]
    settings = TrainingSettings(**job["settings"]) if job.get("settings") else None
    kw = {k: job[k] for k in ("n_train", "n_test") if job.get(k)}
    init = np.asarray(job["kernel"]) if kind == "frozen" else None
    learn = kind == "size" and job["size"] > 1
    size = job["size"] if kind != "zero_shot" else 1
    with tempfile.TemporaryDirectory() as tmp:
        out = job.get("out") or (Path(tmp) / "run" if kind == "zero_shot" else None)
        res = learn_kernel(
            job["task"], size, seed=job["seed"], settings=settings, learn_filter=learn, init_kernel=init, out=out, **kw
        )
        rec: dict[str, Any] = {
            "key": key,
            "kind": kind,
            "task": job["task"],
            "size": job["size"],
            "seed": job["seed"],
            "metrics": res.metrics,
            "primary": res.primary_metric,
            "n_test": res.provenance["n_test"],
            "n_train": res.provenance["n_train"],
            "scene": res.provenance["scene"],
            "event_rate": res.provenance["test_event_rate_per_pixel_frame"],
            "taps": res.kernel.taps.tolist(),
            "final_loss": res.history[-1]["loss"] if res.history else None,
            "train_seconds": res.provenance["train_seconds"],
            "kernel_name": job.get("kernel_name"),
        }
        if job.get("pred_dir"):
            _save_predictions(Path(job["pred_dir"]) / f"{key}.npz", res.predictions)
            rec["predictions"] = f"{key}.npz"
        if kind == "zero_shot":  # the given kernel swapped into the network trained on conventional events
            ev = evaluate_kernel(np.asarray(job["kernel"]), job["task"], res.paths["checkpoint"], keep_predictions=True)
            rec["zero_shot_metrics"] = ev.metrics
            rec["zero_shot_event_rate"] = ev.event_rate
            if job.get("pred_dir"):
                _save_predictions(Path(job["pred_dir"]) / f"{key}_zero_shot.npz", ev.predictions)
                rec["zero_shot_predictions"] = f"{key}_zero_shot.npz"
        if job.get("out"):
            rec["files"] = {k: str(v) for k, v in res.paths.items()}
    if learn:
        rec["shape"] = kernel_shape(res.kernel)
        rec["kernel_change_l1"] = float(np.abs(np.asarray(res.kernel.taps) - delta_taps(job["size"])).sum())
    rec["seconds"] = time.perf_counter() - t0
    print(
        f"[ablation] {kind} {job['task']} {job['size']}x{job['size']} seed {job['seed']}: "
        f"{res.primary_metric} {res.value:.4f} ({rec['seconds']:.0f} s)",
        file=sys.stderr,
        flush=True,
    )
    return rec


# --------------------------------------------------------------------------- tables
def clip_metric(task: str, predictions: dict[str, np.ndarray], targets: dict[str, np.ndarray]) -> Any:
    """The task's primary metric as a resamplable :mod:`fsdvs_hw.stats` object (per-clip evidence)."""
    from ..stats import ClipMeans, CocoDetections, ConfusionMIoU
    from .evaluators import get_evaluator

    ev: Any = get_evaluator(task)  # the map and miou evaluators (built-in) carry num_classes
    if ev.primary_metric == "map":
        return CocoDetections.from_predictions(
            predictions["boxes"],
            predictions["scores"],
            predictions["labels"],
            targets["boxes"],
            targets["labels"],
            num_classes=ev.num_classes,
            metric="map",
        )
    if ev.primary_metric == "top1":
        return ClipMeans.top1(predictions["logits"], targets["motion"])
    if ev.primary_metric == "miou":
        return ConfusionMIoU.from_masks(predictions["mask"].astype(np.int64), targets["mask"], ev.num_classes)
    raise InputError(f"ablation: no per-clip metric for task {task!r} (primary metric {ev.primary_metric!r})")


def _gains(
    records: list[dict[str, Any]],
    pred_dir: Path | None,
    task: str,
    baseline: list[dict[str, Any]],
    arms: dict[str, tuple[list[dict[str, Any]], str]],
    n_resamples: int,
) -> dict[str, Any]:
    """Gain of every arm over the baseline with its 95 % CI (None where predictions are missing)."""
    from ..stats import difference_cis
    from .learn import heldout_targets

    if pred_dir is None or not baseline or not arms:
        return {}
    ok = all("predictions" in r and (pred_dir / r["predictions"]).is_file() for r in baseline)
    for recs, field in arms.values():
        ok = ok and all(field in r and (pred_dir / r[field]).is_file() for r in recs)
    if not ok:
        return {}
    n = {int(r["n_test"]) for r in baseline}
    if len(n) != 1:
        return {}
    targets = heldout_targets(task, baseline[0]["scene"], n.pop())

    def metrics(recs: list[dict[str, Any]], field: str) -> list[Any]:
        out = []
        for r in sorted(recs, key=lambda r: r["seed"]):
            with np.load(pred_dir / r[field]) as z:
                out.append(clip_metric(task, {k: z[k] for k in z.files}, targets))
        return out

    base = metrics(baseline, "predictions")
    cands = {name: metrics(recs, field) for name, (recs, field) in arms.items()}
    by_seeds: dict[int, dict[str, list[Any]]] = {}
    for name, m in cands.items():
        by_seeds.setdefault(len(m), {})[name] = m
    out: dict[str, Any] = {}
    for group in by_seeds.values():
        cis = difference_cis(base, group, paired_seeds=False, n_resamples=n_resamples)
        for name, ci in cis.items():  # reference − candidate = w/o − arm: the gain is its negative
            out[name] = {
                "gain": -ci.estimate,
                "low": -ci.high,
                "high": -ci.low,
                "n_clips": ci.n_clips,
                "n_seeds": min(ci.n_seeds_reference, ci.n_seeds_candidate),
            }
    return out


def _mean_std(values: list[float]) -> tuple[float, float]:
    a = np.asarray(values, dtype=np.float64)
    return float(a.mean()), (float(a.std(ddof=1)) if a.size > 1 else float("nan"))


def _fmt(m: float, s: float, scale: float = 100.0) -> str:
    return f"{m * scale:.1f} ± {s * scale:.1f}" if math.isfinite(s) else f"{m * scale:.1f}"


def _fmt_gain(g: dict[str, Any] | None, fallback: float | None) -> str:
    if g:
        return f"{g['gain'] * 100:+.1f} [{g['low'] * 100:+.1f}, {g['high'] * 100:+.1f}]"
    return f"{fallback * 100:+.1f}" if fallback is not None else "—"


def _group(records: list[dict[str, Any]], task: str, kind: str = "size") -> dict[int, list[dict[str, Any]]]:
    out: dict[int, list[dict[str, Any]]] = {}
    for r in records:
        if r["task"] == task and r.get("kind", "size") == kind:
            out.setdefault(r["size"], []).append(r)
    return dict(sorted(out.items()))


def ablation_markdown(
    records: list[dict[str, Any]], pred_dir: str | Path | None = None, *, n_resamples: int = 1000
) -> str:
    """Paper-style tables (metrics ×100, mean ± std over seeds; gain over w/o with its 95 % CI).

    Parameters
    ----------
    records : list of dict
        :func:`run_job` records of kind ``size``.
    pred_dir : path, optional
        Folder of the runs' prediction files; without it (or with files missing) the gain is the
        difference of the seed means, without a CI.
    n_resamples : int
        Bootstrap resamples per interval.
    """
    from .evaluators import get_evaluator

    pdir = Path(pred_dir) if pred_dir is not None else None
    lines: list[str] = []
    recs_all = [r for r in records if r.get("kind", "size") == "size"]
    for task in dict.fromkeys(r["task"] for r in recs_all):
        ev = get_evaluator(task)
        groups = _group(recs_all, task)
        n_seeds = max(len(v) for v in groups.values())
        n_clips = max(int(r.get("n_test", 0)) for v in groups.values() for r in v)
        names = list(ev.metric_names)
        base = _mean_std([r["metrics"][ev.primary_metric] for r in groups.get(1, [])]) if 1 in groups else None
        gains = _gains(
            recs_all,
            pdir,
            task,
            groups.get(1, []),
            {str(s): (v, "predictions") for s, v in groups.items() if s != 1},
            n_resamples,
        )
        lines.append(
            f"**{task}** ({n_seeds} seeds × {n_clips} test clips; metrics ×100, mean ± std over seeds; "
            f"Δ = gain over w/o with its 95 % CI, bootstrap over test clips (paired) and seeds)\n"
        )
        lines.append("| Filter | " + " | ".join(names) + f" | Δ {ev.primary_metric} [95 % CI] | events / px / frame |")
        lines.append("|---" * (len(names) + 3) + "|")
        for size, recs in groups.items():
            cells = [_fmt(*_mean_std([r["metrics"][k] for r in recs])) for k in names]
            prim = _mean_std([r["metrics"][ev.primary_metric] for r in recs])[0]
            delta = "—" if size == 1 else _fmt_gain(gains.get(str(size)), prim - base[0] if base else None)
            rate = np.mean([r["event_rate"] for r in recs])
            label = "w/o" if size == 1 else f"{size}×{size}"
            lines.append(f"| {label} | " + " | ".join(cells) + f" | {delta} | {rate:.4f} |")
        lines.append("")
    shaped = [r for r in recs_all if "shape" in r]
    if shaped:
        lines.append(
            "**Learned kernels** (per task and size: how many seeds gave a centre-surround kernel; "
            "means over seeds; L1 change = Σ|taps − delta|)\n"
        )
        lines.append(
            "| Task | Filter | centre-surround | centre | surround sum | DC gain | L1 change from delta "
            "| radial peak (cyc/px) | MS correlation | MS peak ratio |"
        )
        lines.append("|---|---|---|---|---|---|---|---|---|---|")
        for task in dict.fromkeys(r["task"] for r in shaped):
            for size, recs in _group(shaped, task).items():
                sh = [r["shape"] for r in recs]
                n_cs = sum(s["centre_surround"] for s in sh)
                m = {
                    k: float(np.mean([s[k] for s in sh]))
                    for k in (
                        "centre",
                        "surround_sum",
                        "dc_gain",
                        "peak_frequency_cpp",
                        "ms_correlation",
                        "ms_peak_ratio",
                    )
                }
                l1 = float(np.mean([r.get("kernel_change_l1", float("nan")) for r in recs]))
                lines.append(
                    f"| {task} | {size}×{size} | {n_cs}/{len(sh)} | {m['centre']:.3f} | "
                    f"{m['surround_sum']:+.3f} | {m['dc_gain']:.3f} | {l1:.2f} | {m['peak_frequency_cpp']:.3f} | "
                    f"{m['ms_correlation']:.2f} | {m['ms_peak_ratio']:.2f} |"
                )
        lines.append("")
    return "\n".join(lines)


def transfer_markdown(
    records: list[dict[str, Any]], kernel_name: str, pred_dir: str | Path | None = None, *, n_resamples: int = 1000
) -> str:
    """Table III: segmentation with the delta vs the (frozen) detection kernel, gains with 95 % CIs."""
    from .evaluators import get_evaluator

    ev = get_evaluator("segmentation")
    pdir = Path(pred_dir) if pred_dir is not None else None
    wo = [r for r in records if r["task"] == "segmentation" and r.get("kind") == "zero_shot"]
    frozen = [r for r in records if r["task"] == "segmentation" and r.get("kind") == "frozen"]
    if not wo:
        return ""
    base = _mean_std([r["metrics"]["miou"] for r in wo])[0]
    arms = {}
    if frozen:
        arms["frozen"] = (frozen, "predictions")
    arms["zero_shot"] = (wo, "zero_shot_predictions")
    gains = _gains(records, pdir, "segmentation", wo, arms, n_resamples)
    n_clips = max(int(r.get("n_test", 0)) for r in wo)
    lines = [
        f"**segmentation, kernel transfer** ({len(wo)} seeds × {n_clips} test clips; kernel = {kernel_name}, "
        "frozen, never trained on segmentation; metrics ×100, mean ± std; Δ = gain over w/o with its 95 % CI)\n",
        "| Filter | " + " | ".join(ev.metric_names) + " | Δ miou [95 % CI] |",
        "|---" * (len(ev.metric_names) + 2) + "|",
    ]
    cells = [_fmt(*_mean_std([r["metrics"][k] for r in wo])) for k in ev.metric_names]
    lines.append("| w/o | " + " | ".join(cells) + " | — |")
    if frozen:
        cells = [_fmt(*_mean_std([r["metrics"][k] for r in frozen])) for k in ev.metric_names]
        prim = _mean_std([r["metrics"]["miou"] for r in frozen])[0]
        lines.append(
            "| detection kernel, segmentation network trained on its events | "
            + " | ".join(cells)
            + f" | {_fmt_gain(gains.get('frozen'), prim - base)} |"
        )
    zs = [r for r in wo if "zero_shot_metrics" in r]
    if zs:
        cells = [_fmt(*_mean_std([r["zero_shot_metrics"][k] for r in zs])) for k in ev.metric_names]
        prim = _mean_std([r["zero_shot_metrics"]["miou"] for r in zs])[0]
        lines.append(
            "| detection kernel swapped into the w/o network (zero-shot, no retraining at all) | "
            + " | ".join(cells)
            + f" | {_fmt_gain(gains.get('zero_shot'), prim - base)} |"
        )
    return "\n".join(lines) + "\n"
