"""Rate curves with networks retrained at every threshold, and the zero-shot swap at matched rate.

The fixed-network protocol (:func:`fsdvs_hw.explore.rate.rate_curve`) scores every kernel and
threshold in networks trained with the learned kernel at one threshold, a bias in favour of that
operating point. The **retrained protocol** removes it: for each kernel and threshold, networks
are trained (:func:`fsdvs_hw.tasks.learn.learn_kernel`, the kernel frozen, the paper's two-stage
schedule) at that threshold, one per seed, and each is scored with the kernel it was trained with
at its own threshold. Network ``i`` (seed ``seeds[i]``) scores clip set ``i`` with sensor seed
offset ``i`` at every threshold, so the curves stay paired across thresholds and kernels and
:func:`fsdvs_hw.explore.rate.matched_rate_difference` applies unchanged; its bootstrap then
resamples seed slots (a network per threshold each), which carries the training-seed variance.

The **zero-shot swap at matched rate** repeats the paper's transfer experiment (its Table III:
networks trained on a plain DVS, the learned kernel swapped in without retraining) with the
swapped kernel's threshold moved until it fires at the rate the networks were trained on.

Every trained network is saved under ``OUT/networks/`` and every scored point under
``OUT/points/`` as it finishes; a rerun reuses both (resume).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..explore.paired import clip_evidence
from ..explore.rate import RateCurve, RatePoint, check_thresholds
from ..kernels import Kernel
from ..paths import write_output
from ..progress import progress_bar

__all__ = ["network_stem", "networks_dir", "retrained_networks", "retrained_rate_curve"]


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def _sensor(task: str, threshold: float) -> Any:
    from ..tasks import get_evaluator
    from ..tasks.learn import default_sensor

    base = default_sensor(get_evaluator(task).default_scene())
    return dataclasses.replace(base, threshold_on=float(threshold), threshold_off=float(threshold))


def networks_dir(out_dir: str | Path, n_train: int) -> Path:
    """Folder of the retrained networks of a study (one per training-set size)."""
    return Path(out_dir) / "networks" / f"n_train{int(n_train)}"


def network_stem(label: str, threshold: float, seed: int) -> str:
    """File stem of a retrained network: ``w_o_t0p2_s0`` (no dot, which a suffix would eat)."""
    return f"{_slug(label)}_t{threshold:g}_s{int(seed)}".replace(".", "p")


def retrained_networks(
    kernel: Kernel | None,
    task: str,
    threshold: float,
    seeds: Sequence[int],
    folder: str | Path,
    *,
    label: str,
    n_train: int = 2048,
    n_test: int = 256,
    settings: Any = None,
    progress: bool | None = None,
) -> list[Path]:
    """Train (or reuse) one network per seed with ``kernel`` frozen at ``threshold``.

    Parameters
    ----------
    kernel : Kernel or None
        The frozen kernel (None: w/o, a plain DVS).
    task : str
    threshold : float
        ON = OFF contrast threshold of the simulator while training (log units).
    seeds : sequence of int
        Training seeds (clips, initialisation, batch order).
    folder : path
        Where the checkpoints go (:func:`network_stem` ``.safetensors``); existing ones are reused.
    label : str
        Kernel name in the file names.
    n_train, n_test : int
        Training clips; held-out clips scored at the end of training (the checkpoint's own metric).
    settings : fsdvs_hw.tasks.learn.TrainingSettings, optional
        Epochs, learning rates, width (default: the shipped networks').
    progress : bool, optional

    Returns
    -------
    list of Path
        The checkpoints, in seed order.
    """
    from ..tasks.learn import learn_kernel

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    with progress_bar(
        total=len(seeds), desc=f"train {label} @ {threshold:g}", unit="network", progress=progress
    ) as bar:
        for s in seeds:
            stem = out / network_stem(label, threshold, s)
            ckpt = out / f"{stem.name}.safetensors"
            if not ckpt.is_file():
                learn_kernel(
                    task,
                    1 if kernel is None else kernel.size,
                    seed=int(s),
                    n_train=n_train,
                    n_test=n_test,
                    settings=settings,
                    sensor=_sensor(task, threshold),
                    learn_filter=False,
                    init_kernel=kernel,
                    out=stem,
                    name=label,
                )
            paths.append(ckpt)
            bar.update(1)
    return paths


def _scored_point(
    kernel: Kernel | None, task: str, threshold: float, checkpoints: Sequence[Path], n_test: int
) -> tuple[RatePoint, str]:
    """Score each network with the kernel it was trained with at its own threshold.

    Parameters
    ----------
    kernel : Kernel or None
        None: w/o (a plain DVS).
    task : str
    threshold : float
        ON = OFF contrast threshold (log units), the networks' own.
    checkpoints : sequence of path
        Network ``i`` scores clip set ``i`` with sensor seed offset ``i``.
    n_test : int
        Test clips per network.

    Returns
    -------
    point : RatePoint
    metric_name : str
    """
    sensor = _sensor(task, threshold)
    evid = [
        clip_evidence(kernel, task, c, n_test=n_test, sensor=sensor, seed_offset=i, clip_set=i)
        for i, c in enumerate(checkpoints)
    ]
    return RatePoint.from_evidence(threshold, evid), evid[0].metric_name


def _save_point(
    file: Path, key: dict[str, Any], metric_name: str, point: RatePoint, checkpoints: Sequence[Path]
) -> None:
    """Save a scored point with the key that a rerun must match to reuse it, and its networks' files."""
    write_output(
        file,
        json.dumps(
            {
                "key": key,
                "metric_name": metric_name,
                "point": point.to_dict(),
                "checkpoints": [c.name for c in checkpoints],
            }
        ),
    )


def retrained_rate_curve(
    kernel: Kernel | None,
    task: str,
    thresholds: Sequence[float],
    seeds: Sequence[int],
    out_dir: str | Path,
    *,
    label: str,
    n_train: int = 2048,
    n_test: int = 256,
    settings: Any = None,
    progress: bool | None = None,
) -> RateCurve:
    """A kernel's rate curve where every threshold has its own networks, trained at that threshold.

    Parameters
    ----------
    kernel : Kernel or None
        None: w/o (a plain DVS).
    task : str
    thresholds : sequence of float
        ON = OFF thresholds (log units), at least 2.
    seeds : sequence of int
        Training seeds: one network per seed and threshold (≥ 3 for a seed-variance estimate).
    out_dir : path
        ``networks/n_train{N}/`` (:func:`networks_dir`) and ``points/`` are kept here (resume).
    label : str
    n_train, n_test : int
        Training clips per network; test clips each network scores (its clip set ``i``).
    settings : TrainingSettings, optional
    progress : bool, optional

    Returns
    -------
    RateCurve
        Paired across thresholds by seed slot (test seeds and sensor seeds equal at every threshold).

    Raises
    ------
    InputError
        Fewer than 2 thresholds, no seeds, bad counts.

    Examples
    --------
    >>> from fsdvs_hw.studies.rate_retrained import retrained_rate_curve
    >>> curve = retrained_rate_curve(None, "detection", [0.1, 0.2], [0, 1, 2], "out/rt",
    ...                              label="w/o")  # doctest: +SKIP
    """
    ts = check_thresholds(thresholds)
    seeds = [int(s) for s in seeds]
    if not seeds or len(set(seeds)) != len(seeds):
        raise InputError(f"retrained_rate_curve: seeds={seeds}; allowed: one or more distinct integers")
    out = Path(out_dir)
    (out / "points").mkdir(parents=True, exist_ok=True)
    points: list[RatePoint] = []
    metric_name = ""
    all_ckpts: list[str] = []
    for t in ts:
        file = out / "points" / f"{_slug(label)}_t{t:g}.json"
        key = {
            "task": task,
            "seeds": seeds,
            "n_train": n_train,
            "n_test": n_test,
            "taps": [[1.0]] if kernel is None else np.asarray(kernel.taps).round(15).tolist(),
        }
        if file.is_file():
            stored = json.loads(file.read_text())
            if stored.get("key") == key:
                points.append(RatePoint.from_dict(stored["point"]))
                metric_name = stored["metric_name"]
                all_ckpts.extend(stored.get("checkpoints", []))
                continue
        ckpts = retrained_networks(
            kernel,
            task,
            t,
            seeds,
            networks_dir(out, n_train),
            label=label,
            n_train=n_train,
            n_test=n_test,
            settings=settings,
            progress=progress,
        )
        point, metric_name = _scored_point(kernel, task, t, ckpts, n_test)
        _save_point(file, key, metric_name, point, ckpts)
        points.append(point)
        all_ckpts.extend(c.name for c in ckpts)
    return RateCurve(
        kernel_name=label,
        task=task,
        metric_name=metric_name,
        test_clips="per_network",
        points=tuple(points),
        checkpoints=tuple(all_ckpts),
    )
