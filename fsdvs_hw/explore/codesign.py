"""Scoring both ways: fit then swap, fit then fine-tune the network, co-designed.

With ``[codesign] enabled = true`` the exploration measures, per hardware realisation with a
differentiable form and per task (a *cell*), three rows against the design's kernel (the
``learned`` row), each in the first ``seeds`` networks of the task (shipped networks trained with
that kernel):

* ``swap`` — **fit then swap**: the realisation fitted to the kernel and swapped zero-shot into the
  network (the exploration's own loss, on the same clips);
* ``finetune`` — **fit then fine-tune the network**: the same network trained further with the
  fitted kernel frozen (:func:`fsdvs_hw.tasks.learn.finetune_network`);
* ``codesign`` — **co-designed**: the same network and the realisation's own physical parameters
  trained together, starting from the fitted design
  (:meth:`fsdvs_hw.realise.registry.RealisationSpec.differentiable_kernel`), so the kernel stays
  buildable at every step.

Every row is scored per clip like the exploration's zero-shot rows
(:func:`fsdvs_hw.explore.paired.clip_evidence`): network ``s`` scores its own held-out clips
(clip set ``s``) with its own mismatch pattern (sensor seed + ``s``), the learned kernel in the
original network on the same clips and noise draws. Each loss ``metric(learned) − metric(row)``
carries the 95 % CI of :func:`fsdvs_hw.stats.difference_cis` (clips nested in networks, whole
(network, clips) clusters resampled, as in :func:`fsdvs_hw.explore.scoring.paired_losses`). The
fraction of the fit-then-swap loss a row recovers, ``1 − loss(row) / loss(swap)``, gets a
percentile bootstrap CI from the same cluster resampling (:func:`recovered_fraction_ci`), and the
gain over the swap, ``metric(row) − metric(swap)``, its paired difference CI. The co-designed
kernel's drift from the Mannos–Sakrison CSF shape is
:func:`csf_drift` (also the co-design pilot's, :mod:`fsdvs_hw.studies.codesign_pilot`).

On a ``[tasks.datasets.<task>]`` task (the user's clips and network) the rows are measured in its
one network (``weights``, or the ``train`` table's checkpoint): fine-tune and co-design run
:func:`fsdvs_hw.explore.user_data.finetune_user_network` (the loop of
:func:`fsdvs_hw.tasks.dataset_training.train_on_dataset`, on the table's training clips, never a
scored one), every row is scored by :func:`fsdvs_hw.explore.user_data.dataset_evidence` on the
table's scored clips, and with one network the CIs resample clips only (the cell's ``ci_note``).

Resumable: every (cell, network, row) is saved as soon as it is measured, as one JSON file under
``OUT/codesign/units/`` keyed by everything that determines it (written atomically); a killed run
started again reuses every finished unit without retraining it. The trained networks are kept
under ``OUT/codesign/networks/``. :func:`write_codesign` writes ``OUT/codesign.json`` and
``OUT/codesign.csv``; :func:`fsdvs_hw.report.codesign_section.codesign_section` renders the report section.
"""

from __future__ import annotations

import csv
import io
import json
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..design import Design
from ..design.sections import CODESIGN_MODES
from ..environment import env
from ..errors import InputError
from ..fingerprints import fingerprint
from ..paths import write_output
from ..stats import multiplicities
from .paired import encode_evidence
from .user_data import ONE_NETWORK_NOTE

__all__ = [
    "CODESIGN_FORMAT",
    "codesign_cells",
    "csf_drift",
    "recovered_fraction_ci",
    "run_codesign",
    "summarise_codesign",
    "write_codesign",
]

#: ``format`` of ``codesign.json``.
CODESIGN_FORMAT = "fsdvs_hw.codesign/1"

_LABELS = {"swap": "fit then swap", "finetune": "fit then fine-tune the network", "codesign": "co-designed"}


def codesign_cells(design: Design) -> list[tuple[str, str]]:
    """The (realisation, task) cells of a design's ``[codesign]`` table, in run order (``tasks = []``:
    every task of ``tasks.checkpoints``, then of ``tasks.datasets``)."""
    cd = design.spec.codesign
    tasks = cd.tasks or [*design.spec.tasks.checkpoints, *design.spec.tasks.datasets]
    if cd.cells:
        return [tuple(c.split("/", 1)) for c in cd.cells]
    return [(r, t) for r in cd.realisations for t in tasks]


def _key(blob: Mapping[str, Any]) -> str:
    return fingerprint(blob, length=16)


def _runnable_cells(design: Design) -> list[tuple[str, str]]:
    """The design's (realisation, task) cells, once ``[codesign]`` is enabled and each realisation differentiable."""
    from ..realise.registry import get_realisation

    if not design.spec.codesign.enabled:
        raise InputError(f"{design.source}: [codesign] enabled = false; nothing to run")
    cells = codesign_cells(design)
    for real, _ in cells:
        if not get_realisation(real).differentiable:  # the schema allows only these; a plug-in may not
            raise InputError(f"{design.source}: codesign realisation {real!r} has no differentiable form")
    return cells


def _progress_log(progress: bool | None) -> Callable[[str], None]:
    """A function printing one ``[codesign]`` line on stderr, or doing nothing without progress."""

    def log(msg: str) -> None:
        if progress:
            print(f"[codesign] {msg}", file=sys.stderr, flush=True)

    return log


def _stored_unit(path: Path, key: str) -> dict[str, Any] | None:
    """A unit measured before under the same key (``None``: absent, torn or of another key: measure again)."""
    if not path.is_file():
        return None
    try:
        rec = json.loads(path.read_text())
    except (OSError, ValueError):
        return None  # a torn file: measure again
    return rec if isinstance(rec, dict) and rec.get("key") == key else None


def csf_drift(provenance: Mapping[str, Any]) -> dict[str, float]:
    """Mannos–Sakrison correlation of the realisation's kernel before and after co-design.

    The kernel compared is the realisation's *shape*: its ``signal_kernel()`` where it has one (a
    metalens with the pedestal subtracted), else ``kernel()``. ``provenance``: a co-designed
    checkpoint's (``realisation``, ``realisation_initial``, ``realisation_design``).
    """
    from ..csf import csf_agreement
    from ..realise.registry import realisation_from_dict

    out = {}
    for key, label in (("realisation_initial", "initial"), ("realisation_design", "final")):
        rec = realisation_from_dict(provenance[key])
        shape = getattr(rec, "signal_kernel", rec.kernel)()
        out[f"ms_correlation_{label}"] = float(csf_agreement(shape, method="mannos_sakrison_1974").correlation)
    return out


def _codesign_outcome(provenance: Mapping[str, Any], target: Any) -> dict[str, Any]:
    """A co-designed row's realisation after training: its kernel errors, CSF drift and design."""
    from ..realise.base import realised_kernel_error
    from ..realise.registry import realisation_from_dict

    final = realisation_from_dict(provenance["realisation_design"])
    return {
        **csf_drift(provenance),
        "kernel_error_codesign": realised_kernel_error(final, target),
        "kernel_error_codesign_gain_free": realised_kernel_error(final, target, fit_scale=True),
        "realisation_design": provenance["realisation_design"],
    }


@dataclass(frozen=True)
class _Network:
    """One network a cell's rows are measured in: a trained checkpoint, or a user-data table's network."""

    task: str
    index: int  # the network's place in its task (0 for user data: one network)
    tag: str  # in the trained networks' file names
    name: str
    ident: dict[str, Any]  # what determines its units besides the kernel and the row
    n_test: int | None
    evidence: Callable[[Any, Any], Any]  # (kernel, trained network or None = this one) -> ClipEvidence
    #: (fit, mode, stem, [codesign], key) -> (training result, trained network, training seconds)
    train: Callable[[Any, str, Path, Any, str], tuple[Any, Any, float]]


def _task_networks(design: Design, task: str) -> list[_Network]:
    """The networks of ``task`` the cells use: the first ``codesign.seeds`` checkpoints, or the one
    network of a ``[tasks.datasets.<task>]`` table (its ``weights`` or its ``train`` checkpoint)."""
    from ..tasks.learn import finetune_network
    from .paired import clip_evidence
    from .user_data import dataset_evidence, finetune_user_network, user_network_identity

    entry = design.data["tasks"]["datasets"].get(task)
    if entry is not None:
        base, confine = design.base_dir, design.confine_paths
        ident = {"task": task, **user_network_identity(entry, base, confine=confine)}

        def user_evidence(kernel: Any, trained: Any) -> Any:
            return dataset_evidence(kernel, task, entry, base, network=trained, confine=confine)[0]

        def user_train(rec: Any, mode: str, stem: Path, cd: Any, key: str) -> tuple[Any, Any, float]:
            res = finetune_user_network(
                task,
                entry,
                base,
                kernel=rec.kernel() if mode == "finetune" else None,
                realisation=rec if mode == "codesign" else None,
                epochs=cd.epochs,
                n_train=cd.n_train,
                lr_network=cd.lr_network,
                lr_filter=cd.lr_filter,
                out=stem,
                fingerprint={"codesign_unit": key},
                confine=confine,
            )
            return res, res.network, float(res.provenance["train_seconds"])

        return [
            _Network(
                task,
                0,
                "0",
                entry["network"] or f"built-in {task} network",
                ident,
                entry["n_clips"] or None,
                user_evidence,
                user_train,
            )
        ]
    per_net = design.spec.tasks.test_clips == "per_network"
    nets = []
    for s, ck in enumerate(design.checkpoints()[task][: design.spec.codesign.seeds]):
        ident = {
            "task": task,
            "network": ck.name,
            "network_size": ck.stat().st_size,
            "n_test": design.n_test(task),
            "clip_set": s if per_net else 0,
            "seed_offset": s,
        }

        def ck_evidence(kernel: Any, trained: Any, ck: Path = ck, s: int = s) -> Any:
            return clip_evidence(
                kernel, task, trained or ck, n_test=design.n_test(task), seed_offset=s, clip_set=s if per_net else 0
            )

        def ck_train(rec: Any, mode: str, stem: Path, cd: Any, key: str, ck: Path = ck) -> tuple[Any, Any, float]:
            res = finetune_network(
                ck,
                task,
                kernel=rec.kernel() if mode == "finetune" else None,
                realisation=rec if mode == "codesign" else None,
                epochs=cd.epochs,
                n_train=cd.n_train or None,
                lr_network=cd.lr_network,
                lr_filter=cd.lr_filter,
                out=stem,
            )
            return res, res.paths["checkpoint"], float(res.provenance["finetune"]["seconds"])

        nets.append(
            _Network(task, s, ck.stem.rsplit("_s", 1)[-1], ck.name, ident, design.n_test(task), ck_evidence, ck_train)
        )
    return nets


@dataclass
class _Units:
    """The measured units of one co-design run: each measured once, saved under ``root/units`` and
    reused by a rerun with the same identity (target, network, mode, realisation and its options,
    and the training settings for the trained modes)."""

    design: Design
    root: Path
    train: Mapping[str, Any]
    log: Callable[[str], None]
    done: list[dict[str, Any]] = field(default_factory=list)

    def measure(self, kind: str, net: _Network, real: str | None, mode: str, work: Any) -> dict[str, Any]:
        """The unit's record, stored or measured now (``work(key)`` gives its extra fields, kernel and network)."""
        target = self.design.target
        ident = {
            "target": target.to_dict()["taps"],
            "pitch_m": target.pitch_m,
            **net.ident,
            "mode": mode,
            "realisation": real,
            "format": CODESIGN_FORMAT,
        }
        if real is not None:
            ident.update(options=self.design.realisation_options(real), run_seed=self.design.spec.run.seed)
        if mode in ("finetune", "codesign"):
            ident.update(self.train)
        key = _key(ident)
        path = self.root / "units" / f"{real or 'learned'}_{net.task}_s{net.index}_{mode}_{key}.json"
        stored = _stored_unit(path, key)
        if stored is not None:
            self.done.append(stored)
            return stored
        t0 = time.perf_counter()
        extra, kernel, trained = work(key)
        ev = net.evidence(kernel, trained)
        rec = {
            "key": key,
            "kind": kind,
            "realisation": real or "learned",
            "task": net.task,
            "seed_index": net.index,
            "mode": mode,
            "network": net.name,
            "metric_name": ev.metric_name,
            "metric": ev.value,
            "n_clips": ev.n_clips,
            "test_seed": ev.test_seed,
            "sensor_seed": ev.sensor_seed,
            "evidence": encode_evidence(ev.metric),
            "wall_s": time.perf_counter() - t0,
            **extra,
        }
        write_output(path, json.dumps(rec, default=float))
        self.done.append(rec)
        self.log(
            f"{real or 'learned'} / {net.task} / network {net.index} / {mode}: {ev.metric_name} {ev.value:.4f} "
            f"({rec['wall_s']:.0f} s)"
        )
        return rec


def run_codesign(design: Design, out_dir: str | Path, *, progress: bool | None = True) -> dict[str, Any]:
    """Measure every cell's rows (resuming finished units) and return :func:`summarise_codesign`.

    Parameters
    ----------
    design : Design
        A validated design with ``[codesign] enabled = true``.
    out_dir : path
        The exploration's output folder; units and networks go to ``out_dir/codesign/``.
    progress : bool
        One line per unit on stderr.

    Raises
    ------
    InputError
        ``[codesign]`` not enabled, or a realisation without a differentiable form.
    """
    import torch

    from ..realise.base import realised_kernel_error
    from ..realise.registry import fit_realisation

    cd = design.spec.codesign
    cells = _runnable_cells(design)
    root = Path(out_dir) / "codesign"
    (root / "units").mkdir(parents=True, exist_ok=True)
    (root / "networks").mkdir(parents=True, exist_ok=True)
    if env("FSDVS_HW_WORKER_THREADS"):
        torch.set_num_threads(int(env("FSDVS_HW_WORKER_THREADS") or 1))
    target = design.target
    seed = design.spec.run.seed
    train = {k: getattr(cd, k) for k in ("epochs", "n_train", "lr_network", "lr_filter")}
    fits: dict[str, Any] = {}
    t_run = time.perf_counter()
    units = _Units(design, root, train, _progress_log(progress))
    networks = {task: _task_networks(design, task) for task in dict.fromkeys(t for _, t in cells)}

    def fitted(real: str) -> Any:
        if real not in fits:
            fits[real] = fit_realisation(real, target, design.realisation_options(real), seed=seed)
        return fits[real]

    for real, task in cells:
        for net in networks[task]:
            units.measure("reference", net, None, "reference", lambda key: ({}, target, None))
            for mode in [m for m in CODESIGN_MODES if m in cd.modes]:

                def work(key: str, real: str = real, mode: str = mode, net: _Network = net) -> Any:
                    rec = fitted(real)
                    info: dict[str, Any] = {
                        "kernel_error_fit": realised_kernel_error(rec, target),
                        "kernel_error_fit_gain_free": realised_kernel_error(rec, target, fit_scale=True),
                    }
                    if mode == "swap":
                        return info, rec.kernel(), None
                    stem = root / "networks" / f"{real}_{net.task}_s{net.tag}_{mode}_{key}"
                    res, trained, info["train_s"] = net.train(rec, mode, stem, cd, key)
                    info["train_loss_last"] = res.history[-1]["loss"] if res.history else None
                    if mode == "codesign":
                        info.update(_codesign_outcome(res.provenance, target))
                    return info, res.kernel, trained

                units.measure("row", net, real, mode, work)
    return _run_summary(design, units.done, {t: networks[t][0].n_test for _, t in cells}, t_run)


def _run_summary(
    design: Design, units: Sequence[dict[str, Any]], n_test: Mapping[str, Any], t_run: float
) -> dict[str, Any]:
    """:func:`summarise_codesign` of the run's units with its settings, design name and wall times (s)."""
    sc = design.spec.scoring
    summary = summarise_codesign(units, n_resamples=sc.n_resamples, confidence=sc.confidence, rng=design.spec.run.seed)
    _note_user_cells(summary, design)
    summary["settings"] = {
        **design.section("codesign"),
        "test_clips": design.spec.tasks.test_clips,
        "n_test": dict(n_test),
    }
    summary["design"] = design.name
    summary["wall_s"] = time.perf_counter() - t_run  # this call (a resumed run reuses finished units)
    summary["units_wall_s"] = float(sum(u["wall_s"] for u in units))  # when each unit was measured
    return summary


def _note_user_cells(summary: Mapping[str, Any], design: Design) -> None:
    """Mark the cells of user-data tasks: one network, so their CIs resample the clips only."""
    for cell in summary["cells"]:
        if cell["task"] in design.spec.tasks.datasets:
            cell["data"], cell["ci_note"] = "user", ONE_NETWORK_NOTE


def recovered_fraction_ci(
    reference: Sequence[Any],
    swap: Sequence[Any],
    candidate: Sequence[Any],
    *,
    nested_clips: bool = True,
    confidence: float = 0.95,
    n_resamples: int = 2000,
    rng: Any = 0,
) -> dict[str, Any]:
    """Fraction of the fit-then-swap loss a row recovers, ``1 − loss(candidate) / loss(swap)``, with a CI.

    ``loss(x) = metric(reference) − metric(x)``, every arm a list of per-network
    :class:`~fsdvs_hw.stats.ClipMetric` on the same clips as the reference's entry (paired). The
    percentile interval of :func:`scipy.stats.bootstrap` resamples what
    :func:`fsdvs_hw.stats.difference_ci` resamples: whole (network, clips) clusters with clips
    nested in ≥ 2 networks (a network's metric is recomputed on its own clips), else the clips of
    the (crossed, or single) networks; all three arms share every resample. 1 = the whole loss
    recovered, 0 = none, < 0 = worse than the swap.

    Returns
    -------
    dict
        ``estimate``, ``low``, ``high``, ``confidence``, ``n_resamples``, ``resampled``.
    """
    from scipy import stats

    arms = [list(reference), list(swap), list(candidate)]
    n_s = len(arms[0])
    if any(len(a) != n_s for a in arms) or n_s == 0:
        raise InputError(f"recovered_fraction_ci: one metric per network in every arm, got {[len(a) for a in arms]}")
    ones = [[m.weighted(np.ones((1, m.n_clips)))[0] for m in a] for a in arms]
    cluster = nested_clips and n_s >= 2
    if cluster:
        vals = np.array(ones)  # (3, S)

        def statistic(idx: np.ndarray, axis: int = -1) -> np.ndarray:
            w = multiplicities(idx, n_s)  # (B, S)
            r, sw, c = ((w * v).sum(axis=1) / w.sum(axis=1) for v in vals)
            return (1.0 - (r - c) / (r - sw)).reshape(idx.shape[:-1])

        data: tuple[np.ndarray, ...] = (np.arange(n_s),)
    else:
        n = arms[0][0].n_clips
        if any(m.n_clips != n for a in arms for m in a):
            raise InputError("recovered_fraction_ci: crossed networks must all score the same clips")

        def statistic(idx: np.ndarray, axis: int = -1) -> np.ndarray:
            w = multiplicities(idx, n)
            r, sw, c = (np.mean([m.weighted(w) for m in a], axis=0) for a in arms)
            return (1.0 - (r - c) / (r - sw)).reshape(idx.shape[:-1])

        data = (np.arange(n),)
    r0, s0, c0 = (float(np.mean(v)) for v in ones)
    est = 1.0 - (r0 - c0) / (r0 - s0) if r0 != s0 else float("nan")
    with np.errstate(divide="ignore", invalid="ignore"):
        res = stats.bootstrap(
            data,
            statistic,
            vectorized=True,
            confidence_level=confidence,
            n_resamples=n_resamples,
            method="percentile",
            random_state=np.random.default_rng(rng),
            batch=200,
        )
    lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return {
        "estimate": est,
        "low": lo,
        "high": hi,
        "confidence": confidence,
        "n_resamples": n_resamples,
        "resampled": "networks (clips nested)" if cluster else "clips",
    }


def summarise_codesign(
    units: Sequence[Mapping[str, Any]], *, n_resamples: int = 2000, confidence: float = 0.95, rng: Any = 0
) -> dict[str, Any]:
    """Per-cell rows with paired loss CIs, recovered fractions and CSF drift, from measured units.

    Parameters
    ----------
    units : sequence of mappings
        What :func:`run_codesign` stores per (cell, network, row): ``realisation``, ``task``,
        ``seed_index``, ``mode`` (``reference`` for the learned kernel), ``evidence`` (base64,
        :func:`fsdvs_hw.explore.paired.encode_evidence`), ``test_seed`` and the row's extras.

    Returns
    -------
    dict
        ``{"format", "cells": [{"realisation", "task", "metric_name", "n_seeds", "n_clips",
        "n_clips_per_network", "rows": {mode: {"label", "loss" (DifferenceCI dict + text),
        "metric_per_seed", "gain_over_swap", "recovered"}}, "kernel_error_fit",
        "kernel_error_codesign", "ms_correlation_initial", "ms_correlation_final",
        "swap_loss_above_zero", "verdict"}]}``.
    """
    from ..stats import difference_cis
    from .paired import decode_evidence

    refs: dict[tuple[str, int], Mapping[str, Any]] = {}
    rows: dict[tuple[str, str], dict[str, dict[int, Mapping[str, Any]]]] = {}
    for u in units:
        if u["mode"] == "reference":
            refs[(u["task"], int(u["seed_index"]))] = u
        else:
            rows.setdefault((u["realisation"], u["task"]), {}).setdefault(u["mode"], {})[int(u["seed_index"])] = u
    cells = []
    for (real, task), modes in rows.items():
        seeds = sorted(set.intersection(*(set(m) for m in modes.values())) & {s for t, s in refs if t == task})
        if not seeds:
            continue
        names = [m for m in CODESIGN_MODES if m in modes]
        ref = [decode_evidence(refs[(task, s)]["evidence"]) for s in seeds]
        arms = {m: [decode_evidence(modes[m][s]["evidence"]) for s in seeds] for m in names}
        nested = len({refs[(task, s)]["test_seed"] for s in seeds}) == len(seeds) and len(seeds) > 1
        kw = {"nested_clips": nested, "n_resamples": n_resamples, "confidence": confidence, "rng": rng}
        losses = difference_cis(ref, arms, **kw)
        cell: dict[str, Any] = {
            "realisation": real,
            "task": task,
            "metric_name": refs[(task, seeds[0])]["metric_name"],
            "n_seeds": len(seeds),
            "seeds": seeds,
            "n_clips_per_network": int(ref[0].n_clips),
            "n_clips": int(sum(m.n_clips for m in ref)) if nested else int(ref[0].n_clips),
            "clips": "nested in networks" if nested else "shared",
            "reference_metric_per_seed": [refs[(task, s)]["metric"] for s in seeds],
            "rows": {},
        }
        for m in names:
            ci = losses[m]
            row = {
                "label": _LABELS[m],
                "loss": {**ci.to_dict(), "text": ci.describe()},
                "metric_per_seed": [modes[m][s]["metric"] for s in seeds],
                "wall_s": [modes[m][s]["wall_s"] for s in seeds],
            }
            if m != "swap" and "swap" in arms:
                gain = difference_cis(arms[m], {"swap": arms["swap"]}, **kw)["swap"]
                row["gain_over_swap"] = {**gain.to_dict(), "text": gain.describe()}
                row["recovered"] = recovered_fraction_ci(
                    ref,
                    arms["swap"],
                    arms[m],
                    nested_clips=nested,
                    n_resamples=n_resamples,
                    confidence=confidence,
                    rng=rng,
                )
            cell["rows"][m] = row
        any_unit = next(iter(modes.values()))[seeds[0]]
        cell["kernel_error_fit"] = any_unit.get("kernel_error_fit")
        cell["kernel_error_fit_gain_free"] = any_unit.get("kernel_error_fit_gain_free")
        if "codesign" in modes:
            cdu = [modes["codesign"][s] for s in seeds]
            for f in (
                "kernel_error_codesign",
                "kernel_error_codesign_gain_free",
                "ms_correlation_initial",
                "ms_correlation_final",
            ):
                cell[f] = [u.get(f) for u in cdu]
        cell["swap_loss_above_zero"] = bool("swap" in cell["rows"] and cell["rows"]["swap"]["loss"]["low"] > 0)
        cell["verdict"] = _verdict(cell)
        cells.append(cell)
    return {"format": CODESIGN_FORMAT, "cells": cells}


def _verdict(cell: Mapping[str, Any]) -> str:
    rows = cell["rows"]
    if "swap" not in rows or "codesign" not in rows:
        return "incomplete: the swap and co-designed rows are both needed"
    swap, cd = rows["swap"]["loss"], rows["codesign"]
    if swap["low"] <= 0:
        return (
            f"no loss to recover: the fit-then-swap loss {swap['estimate']:.4f} "
            f"[{swap['low']:.4f}, {swap['high']:.4f}] does not lie above 0"
        )
    rec = cd["recovered"]
    if not rec["high"] - rec["low"] <= 1.0:  # wider than the whole loss (or unbounded): nothing resolved
        return (
            f"unresolved: the co-designed loss {cd['loss']['estimate']:.4f} [{cd['loss']['low']:.4f}, "
            f"{cd['loss']['high']:.4f}] is wider than the fit-then-swap loss {swap['estimate']:.4f} "
            f"[{swap['low']:.4f}, {swap['high']:.4f}] itself (recovered {rec['estimate']:.0%}, CI wider than 100 points)"
        )
    if rec["low"] >= 0.5:
        return f"co-design recovers at least half of the loss ({rec['estimate']:.0%} [{rec['low']:.0%}, {rec['high']:.0%}])"
    if rec["estimate"] >= 0.5:
        return (
            f"co-design recovers {rec['estimate']:.0%} of the loss, but the CI [{rec['low']:.0%}, "
            f"{rec['high']:.0%}] does not exclude less than half"
        )
    return (
        f"co-design recovers only {rec['estimate']:.0%} [{rec['low']:.0%}, {rec['high']:.0%}]; the co-designed "
        f"loss {cd['loss']['estimate']:.4f} [{cd['loss']['low']:.4f}, {cd['loss']['high']:.4f}] remains"
    )


def write_codesign(summary: Mapping[str, Any], out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``codesign.json`` (the summary) and ``codesign.csv`` (one row per cell and row)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    jpath, cpath = out / "codesign.json", out / "codesign.csv"
    write_output(jpath, json.dumps(summary, indent=1, default=float) + "\n")
    fields = [
        "realisation",
        "task",
        "row",
        "metric_name",
        "n_seeds",
        "n_clips",
        "loss",
        "loss_ci95_low",
        "loss_ci95_high",
        "recovered",
        "recovered_ci95_low",
        "recovered_ci95_high",
        "gain_over_swap",
        "gain_ci95_low",
        "gain_ci95_high",
        "kernel_error_fit",
        "ms_correlation_initial_mean",
        "ms_correlation_final_mean",
        "verdict",
    ]
    fh = io.StringIO(newline="")
    w = csv.DictWriter(fh, fieldnames=fields)
    w.writeheader()
    for c in summary.get("cells", []):
        for m, r in c["rows"].items():
            rec, gain = r.get("recovered", {}), r.get("gain_over_swap", {})
            w.writerow(
                {
                    "realisation": c["realisation"],
                    "task": c["task"],
                    "row": m,
                    "metric_name": c["metric_name"],
                    "n_seeds": c["n_seeds"],
                    "n_clips": c["n_clips"],
                    "loss": r["loss"]["estimate"],
                    "loss_ci95_low": r["loss"]["low"],
                    "loss_ci95_high": r["loss"]["high"],
                    "recovered": rec.get("estimate"),
                    "recovered_ci95_low": rec.get("low"),
                    "recovered_ci95_high": rec.get("high"),
                    "gain_over_swap": gain.get("estimate"),
                    "gain_ci95_low": gain.get("low"),
                    "gain_ci95_high": gain.get("high"),
                    "kernel_error_fit": c.get("kernel_error_fit"),
                    "ms_correlation_initial_mean": _mean(c.get("ms_correlation_initial")),
                    "ms_correlation_final_mean": _mean(c.get("ms_correlation_final")),
                    "verdict": c["verdict"] if m == "codesign" else "",
                }
            )
    write_output(cpath, fh.getvalue())
    return jpath, cpath


def _mean(values: Any) -> float | None:
    vals = [v for v in (values or []) if v is not None]
    return float(np.mean(vals)) if vals else None
