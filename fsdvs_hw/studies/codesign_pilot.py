"""Co-design pilot: how much of a realisation's loss do retraining and co-design recover?

For one task and one realisation, against the learned kernel in its own networks (the shipped
``designs/kernels/networks/{task}_with_learned_detection_7x7_sSEED``), on the checkpoint's fixed
test clips:

* ``retrain``: fit the realisation to the learned kernel, then train a fresh network with that
  realised kernel frozen (:func:`fsdvs_hw.tasks.learn_kernel` with ``learn_filter=False``);
* ``codesign``: train a fresh network and the realisation's own parameters together
  (``learn_kernel(..., realisation=NAME)``).

Each loss is ``metric(learned) − metric(arm)`` with the 95 % CI of the clips × seeds bootstrap for
different networks (:func:`fsdvs_hw.stats.difference_ci` with ``paired_seeds=False``).

Command: ``fsdvs-hw codesign-pilot --task recognition --realisation metalens --seeds 0 1 2 --out out/codesign``
(:mod:`fsdvs_hw.cli.codesign_pilot`).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..paths import write_output
from ..resources import shipped_path

__all__ = ["run_pilot"]


def run_pilot(task: str, realisation: str, seeds: list[int], out: Path, *, n_test: int = 2048) -> dict[str, Any]:
    """Train the ``retrain`` and ``codesign`` arms for each seed and return their losses with CIs."""
    import torch

    from ..errors import InputError
    from ..explore.codesign import csf_drift
    from ..explore.paired import PER_CLIP_METRICS, clip_evidence
    from ..kernels import load_kernel
    from ..realise.registry import fit_realisation, get_realisation
    from ..stats import difference_ci
    from ..tasks import get_evaluator
    from ..tasks.checkpoints import load_checkpoint
    from ..tasks.learn import heldout_targets, learn_kernel

    # every input checked before the first (minutes-long) training
    ev = get_evaluator(task)
    spec = get_realisation(realisation)
    if not spec.differentiable:
        raise InputError(f"codesign pilot: realisation {realisation!r} has no differentiable form")
    if not seeds or len(set(seeds)) != len(seeds) or any(s < 0 for s in seeds):
        raise InputError(f"codesign pilot: seeds must be distinct non-negative integers, got {seeds}")
    nets = [
        shipped_path("kernels", "networks", f"{ev.name}_with_learned_detection_7x7_s{s}.safetensors") for s in seeds
    ]
    missing = [n.name for n in nets if not n.is_file()]
    if missing:
        raise InputError(
            f"codesign pilot: no shipped reference network {', '.join(missing)} (the shipped seeds are "
            "listed in designs/kernels/networks/)"
        )
    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    target = load_kernel(shipped_path("kernels", "learned_detection_7x7.json"))
    ref = [clip_evidence(target, task, n, n_test=n_test).metric for n in nets]
    scene = load_checkpoint(nets[0])[0]["scene"]
    targets = heldout_targets(ev, scene, n_test)
    arms: dict[str, list[Any]] = {"retrain": [], "codesign": []}
    wall: dict[str, list[float]] = {"retrain": [], "codesign": []}
    drift: list[dict[str, float]] = []
    for s in seeds:
        for mode in arms:
            t0 = time.perf_counter()
            if mode == "retrain":
                k = fit_realisation(realisation, target).kernel()
                res = learn_kernel(
                    task,
                    k.size,
                    seed=s,
                    n_test=n_test,
                    init_kernel=k,
                    learn_filter=False,
                    out=out / f"{realisation}_{task}_retrain_s{s}",
                )
            else:
                res = learn_kernel(
                    task,
                    target.size,
                    seed=s,
                    n_test=n_test,
                    init_kernel=target,
                    realisation=realisation,
                    out=out / f"{realisation}_{task}_codesign_s{s}",
                )
            wall[mode].append(time.perf_counter() - t0)
            if mode == "codesign":
                drift.append(csf_drift(res.kernel.provenance))
            preds = {k: np.asarray(v) for k, v in res.predictions.items()}
            arms[mode].append(PER_CLIP_METRICS[ev.name](preds, targets, ev))
            print(
                f"[codesign-pilot] {mode} seed {s}: {ev.primary_metric} {res.metrics[ev.primary_metric]:.4f} "
                f"({wall[mode][-1]:.0f} s)",
                file=sys.stderr,
                flush=True,
            )
    ones = np.ones((1, n_test))
    result: dict[str, Any] = {
        "task": task,
        "realisation": realisation,
        "seeds": seeds,
        "n_test": n_test,
        "reference_per_seed": [float(m.weighted(ones)[0]) for m in ref],
    }
    for mode, arm in arms.items():
        ci = difference_ci(ref, arm, paired_seeds=False, n_resamples=2000)
        result[mode] = {
            **{k: v for k, v in ci.to_dict().items() if k in ("estimate", "low", "high")},
            "text": ci.describe(),
            "per_seed": [float(m.weighted(ones)[0]) for m in arm],
            "wall_s": wall[mode],
        }
    result["codesign"]["csf_drift"] = drift
    write_output(out / f"pilot_{realisation}_{task}.json", json.dumps(result, indent=1))
    return result
