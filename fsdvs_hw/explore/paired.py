"""Paired per-clip evidence: every kernel scored on the same test clips, noise draws and networks.

:func:`clip_evidence` swaps a kernel zero-shot into one trained network (a task checkpoint, one per
training seed) and keeps what each test clip contributes to the task metric — a
:mod:`fsdvs_hw.stats` metric object that recomputes the dataset metric for any clip resample
(COCO mAP from pycocotools matches, top-1 per clip, mIoU from per-clip confusion matrices).
:func:`encode_evidence` / :func:`decode_evidence` store it compactly (base64 ``.npz``) inside a
design point's result, so the paired losses can be computed after every point has run
(:func:`fsdvs_hw.explore.scoring.paired_losses`).

Pairing
-------
* **Clips**: the checkpoint's test clips, regenerated from its ``test_seed`` plus ``clip_set``;
  clip ``i`` is the same for every kernel and every ``n_test`` (first ``n_test`` clips). The
  exploration gives network ``s`` of a task clip set ``s`` (``test_clips = "per_network"``, the
  default): clips are then nested in networks, every clip is simulated once per kernel, and the
  same simulation budget samples many more (network, mismatch pattern) pairs — the part of a
  loss's CI that more clips cannot shrink (:mod:`fsdvs_hw.stats`, nested design). With
  ``"shared"`` every network scores the same clips (crossed).
* **Noise draws**: the simulator seeds every random effect from ``SensorConfig.seed`` at each call
  (:func:`fsdvs_hw.sensor.simulation.pixel.effect_generator`), and every kernel is run on the same batches of
  ``batch_size`` clips, so every kernel sees the same threshold-mismatch pattern and the same shot
  noise.
* **Mismatch patterns**: network ``s`` (the ``s``-th checkpoint of a task) is scored with sensor
  seed ``checkpoint seed + s``: each training seed meets its own fixed-pattern chip, so resampling
  training seeds resamples (network, chip) pairs and the mismatch-pattern variance enters the CI
  with the seed variance. With one checkpoint neither enters (the CI says ``n_seeds = 1``).
"""

from __future__ import annotations

import base64
import dataclasses
import functools
import io
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, cast

import numpy as np

from ..errors import InputError
from ..kernels import Kernel
from ..stats import ClipMeans, ClipMetric, CocoDetections, ConfusionMIoU, metric_from_state, multiplicities

__all__ = [
    "EVAL_BATCH",
    "EVENT_RATE_UNIT",
    "PER_CLIP_METRICS",
    "ClipEvidence",
    "bootstrap_weights",
    "clip_evidence",
    "decode_evidence",
    "encode_evidence",
    "event_rate_ci",
    "network_info",
    "weighted_rate",
]

#: Unit of :attr:`ClipEvidence.clip_event_rates` and of every event rate with a CI.
EVENT_RATE_UNIT = "events/pixel/s"

#: Clips per simulator call. Noise streams restart at every call, so every kernel must be run on
#: the same batches for its noise draws to be paired; 64 is also :func:`evaluate_kernel`'s batch,
#: so the learned kernel reproduces its stored metric.
EVAL_BATCH = 64


def _detection(pred: dict[str, Any], targets: dict[str, Any], evaluator: Any) -> ClipMetric:
    return CocoDetections.from_predictions(
        pred["boxes"],
        pred["scores"],
        pred["labels"],
        targets["boxes"],
        targets["labels"],
        num_classes=evaluator.num_classes,
        metric="map",
    )


def _recognition(pred: dict[str, Any], targets: dict[str, Any], evaluator: Any) -> ClipMetric:
    return ClipMeans.top1(pred["logits"], targets["motion"])


def _segmentation(pred: dict[str, Any], targets: dict[str, Any], evaluator: Any) -> ClipMetric:
    return ConfusionMIoU.from_masks(
        pred["mask"], targets["mask"], evaluator.num_classes, ignore_index=getattr(evaluator, "ignore_index", None)
    )


#: task name → builder of its per-clip metric (the evaluator's primary metric) from predictions and targets
PER_CLIP_METRICS: dict[str, Callable[[dict[str, Any], dict[str, Any], Any], ClipMetric]] = {
    "detection": _detection,
    "recognition": _recognition,
    "segmentation": _segmentation,
}


@dataclass(frozen=True)
class ClipEvidence:
    """One kernel on one trained network: its per-clip metric and the full-set value.

    Attributes
    ----------
    task, metric_name : str
    value : float
        The metric on all ``n_clips`` test clips (fraction).
    n_clips : int
    metric : ClipMetric
        Recomputes the metric for any clip multiplicities (:mod:`fsdvs_hw.stats`).
    checkpoint : str
    sensor_seed : int
        The simulator seed used (mismatch pattern and noise streams).
    seconds : float
        Wall time of the evaluation.
    test_seed : int
        Seed of the held-out clips scored (the checkpoint's ``test_seed`` + ``clip_set``).
    event_rate : float
        Mean events per pixel and frame interval the network saw.
    clip_event_rates : ndarray or None
        Events per pixel per second of each clip (ON + OFF, over the clip's duration; None where
        not recorded): what :mod:`fsdvs_hw.explore.rate` resamples for an event rate's CI.
    failures : tuple of ClipFailure
        User data (:func:`fsdvs_hw.explore.user_data.dataset_evidence`): the drawn clips skipped
        because they failed to read (:class:`fsdvs_hw.tasks.dataset_eval.ClipFailure`); ``n_clips``
        counts the others.
    n_drawn : int
        User data: the clips drawn (scored + failed); 0 where not recorded.
    details : dict
        User data: record keys of the track besides the metric (``per_class``: each class's metric
        with its CI, :func:`fsdvs_hw.tasks.per_class.per_class_metrics`; ``dataset_summary``).
    """

    task: str
    metric_name: str
    value: float
    n_clips: int
    metric: ClipMetric
    checkpoint: str
    sensor_seed: int
    seconds: float
    test_seed: int = -1
    event_rate: float = float("nan")
    clip_event_rates: np.ndarray | None = dataclasses.field(default=None, repr=False)
    failures: tuple[Any, ...] = ()
    n_drawn: int = 0
    details: dict[str, Any] = dataclasses.field(default_factory=dict, repr=False)


def clip_evidence(
    kernel: Kernel | None,
    task: str,
    checkpoint: str | Path,
    *,
    n_test: int | None = None,
    sensor: Any = None,
    seed_offset: int = 0,
    clip_set: int = 0,
    events_fn: Any = None,
) -> ClipEvidence:
    """Score ``kernel`` zero-shot in one trained network and keep every clip's contribution.

    Parameters
    ----------
    kernel : Kernel or None
        The realised kernel (None: the conventional DVS, a 1×1 delta).
    task : str
        A task with a per-clip metric in :data:`PER_CLIP_METRICS`.
    checkpoint : path
        ``STEM.safetensors`` written by :func:`fsdvs_hw.tasks.learn_kernel`.
    n_test : int, optional
        The first ``n_test`` test clips (default: the checkpoint's ``n_test``).
    sensor : SensorConfig, optional
        Simulator settings (default: the checkpoint's); its seed is offset by ``seed_offset``.
    seed_offset : int
        Added to the sensor seed: the index of this checkpoint among the task's training seeds, so
        each network meets its own mismatch pattern (module docstring).
    clip_set : int
        Which held-out clip set: test seed = the checkpoint's ``test_seed`` + ``clip_set`` (0: the
        checkpoint's own test set). The exploration passes the network's index (module docstring).
    events_fn : callable, optional
        ``events_fn(video, kernel_taps, sensor, timestamps_s) -> (B, T-1, 2, H, W)`` event frames
        (the emulation track); default the in-pixel simulator.

    Returns
    -------
    ClipEvidence

    Raises
    ------
    InputError
        Unknown task, missing checkpoint, a task without a per-clip metric, bad ``n_test``.
    """
    from ..sensor import SensorConfig
    from ..tasks import get_evaluator
    from ..tasks.learn import evaluate_kernel, heldout_targets

    t0 = time.perf_counter()
    evaluator = get_evaluator(task)
    if evaluator.name not in PER_CLIP_METRICS:
        raise InputError(
            f"task {evaluator.name!r} has no per-clip metric; allowed: {', '.join(PER_CLIP_METRICS)} "
            f"(add a builder to fsdvs_hw.explore.paired.PER_CLIP_METRICS)"
        )
    prov, _ = _training_kernel(str(checkpoint))
    n = int(prov["n_test"]) if n_test is None else n_test
    if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= 100_000:
        raise InputError(f"clip_evidence: n_test must be an integer in [2, 100000], got {n_test!r}")
    cfg = sensor if sensor is not None else SensorConfig(**prov["sensor"])
    cfg = dataclasses.replace(cfg, seed=int(cfg.seed) + int(seed_offset))
    if isinstance(clip_set, bool) or not isinstance(clip_set, int) or clip_set < 0:
        raise InputError(f"clip_evidence: clip_set must be a non-negative integer, got {clip_set!r}")
    test_seed = int(prov["test_seed"]) + clip_set
    # the same code path (test clips, batches of EVAL_BATCH, noise streams) as evaluate_kernel, which
    # caches the test set, so every kernel scored in one process meets the same clips and noise draws
    ev = evaluate_kernel(
        kernel,
        evaluator,
        checkpoint,
        n_test=n,
        sensor=cfg,
        events_fn=events_fn,
        keep_predictions=True,
        test_seed=test_seed,
    )
    targets = heldout_targets(evaluator, prov["scene"], n, test_seed=test_seed)
    metric = PER_CLIP_METRICS[evaluator.name](ev.predictions, targets, evaluator)
    value = float(metric.weighted(np.ones((1, n)))[0])
    return ClipEvidence(
        task=evaluator.name,
        metric_name=evaluator.primary_metric,
        value=value,
        n_clips=n,
        metric=metric,
        checkpoint=str(checkpoint),
        sensor_seed=int(cfg.seed),
        seconds=time.perf_counter() - t0,
        test_seed=test_seed,
        event_rate=ev.event_rate,
        clip_event_rates=np.asarray(ev.clip_event_rates, dtype=np.float64),
    )


@functools.lru_cache(maxsize=32)
def _training_kernel(checkpoint: str) -> tuple[dict[str, Any], Kernel]:
    from ..tasks.checkpoints import load_checkpoint

    provenance, _, kernel = load_checkpoint(checkpoint)
    return provenance, kernel


def network_info(checkpoint: str | Path, target: Kernel | None = None) -> dict[str, Any]:
    """Which network a task's loss is measured in: its training kernel and whether that is ``target``.

    Returns
    -------
    dict
        ``checkpoint``, ``task``, ``seed``, ``learn_filter`` (False: trained with the kernel frozen),
        ``training_kernel`` (name), ``trained_with_target`` (the training kernel's taps equal
        ``target``'s to 1e-9; None without a target) and the checkpoint's stored ``final_metric``.
    """
    provenance, kernel = _training_kernel(str(checkpoint))
    same = None
    if target is not None:
        same = bool(
            kernel.size == target.size and np.allclose(np.array(kernel.taps), np.array(target.taps), rtol=0, atol=1e-9)
        )
    return {
        "checkpoint": Path(checkpoint).name,
        "task": provenance.get("task"),
        "seed": provenance.get("seed"),
        "learn_filter": provenance.get("learn_filter"),
        "training_kernel": provenance.get("init_kernel_name") or kernel.name,
        "trained_with_target": same,
        "final_metric": provenance.get("final_metric"),
    }


class _SavedMetric(Protocol):
    def state(self) -> dict[str, Any]: ...


def encode_evidence(metric: ClipMetric) -> str:
    """A metric object as base64 text of a compressed ``.npz`` (for JSON records)."""
    buf = io.BytesIO()
    # the metrics of fsdvs_hw.stats (those metric_from_state rebuilds) carry their state()
    np.savez_compressed(buf, **cast(_SavedMetric, metric).state())
    return base64.b64encode(buf.getvalue()).decode("ascii")


def decode_evidence(text: str) -> ClipMetric:
    """Inverse of :func:`encode_evidence`."""
    try:
        with np.load(io.BytesIO(base64.b64decode(text.encode("ascii"))), allow_pickle=False) as z:
            state = {k: z[k] for k in z.files}
    except (ValueError, OSError, TypeError) as exc:
        raise InputError(f"decode_evidence: not an encoded per-clip metric ({exc})") from None
    return metric_from_state(state)


def bootstrap_weights(
    n_networks: int, n_clips: int, *, test_clips: str = "per_network", n_resamples: int = 2000, rng: Any = 0
) -> tuple[np.ndarray, np.ndarray | None]:
    """Multiplicities of one bootstrap over networks × clips, as :mod:`fsdvs_hw.stats` draws them.

    Parameters
    ----------
    n_networks, n_clips : int
        Networks (training seeds) and test clips per network.
    test_clips : {"per_network", "shared"}
        ``"per_network"`` (clips nested in networks): with ≥ 2 networks whole (network, clips)
        clusters are drawn and every clip of a drawn network keeps weight 1 (the cluster spread
        already holds the clip variance, :mod:`fsdvs_hw.stats`); with one network its clips are
        drawn. ``"shared"`` (crossed): networks and clips are drawn independently.
    n_resamples : int
        Bootstrap resamples ``B`` (≥ 100).
    rng : int or numpy Generator
        Seed of the draws.

    Returns
    -------
    network_weights : ndarray (B, n_networks)
    clip_weights : ndarray (B, n_clips) or None
        None: every clip has weight 1 in every resample.

    Raises
    ------
    InputError
        Counts or ``test_clips`` out of range.
    """
    for name, v, lo in (("n_networks", n_networks, 1), ("n_clips", n_clips, 2), ("n_resamples", n_resamples, 100)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= int(v) <= 10_000_000:
            raise InputError(f"bootstrap_weights: {name}={v!r}; allowed: an integer in [{lo}, 10000000]")
    if test_clips not in ("per_network", "shared"):
        raise InputError(f"bootstrap_weights: test_clips={test_clips!r}; allowed: 'per_network', 'shared'")
    gen = np.random.default_rng(rng)

    def draw(n: int) -> np.ndarray:
        return multiplicities(gen.integers(0, n, size=(n_resamples, n)), n)

    ws = draw(n_networks) if n_networks >= 2 else np.ones((n_resamples, 1))
    if test_clips == "per_network" and n_networks >= 2:
        return ws, None
    return ws, draw(n_clips)


def weighted_rate(clip_rates: np.ndarray, network_weights: np.ndarray, clip_weights: np.ndarray | None) -> np.ndarray:
    """Mean event rate of (networks, clips) per-clip rates under bootstrap weights.

    Parameters
    ----------
    clip_rates : ndarray (n_networks, n_clips)
        Events per pixel per second of each clip.
    network_weights : ndarray (B, n_networks)
    clip_weights : ndarray (B, n_clips) or None

    Returns
    -------
    ndarray (B,)
        Σ_s w_s · mean_c(w_c r_sc) / Σ_s w_s, in the unit of ``clip_rates``.
    """
    r = np.asarray(clip_rates, dtype=np.float64)
    per_net = (
        np.broadcast_to(r.mean(axis=1), network_weights.shape)
        if clip_weights is None
        else (clip_weights @ r.T) / clip_weights.sum(axis=1, keepdims=True)
    )  # (B, S)
    return (network_weights * per_net).sum(axis=1) / network_weights.sum(axis=1)


def event_rate_ci(
    evidence: Sequence[ClipEvidence],
    *,
    test_clips: str = "per_network",
    confidence: float = 0.95,
    n_resamples: int = 2000,
    rng: Any = 0,
) -> dict[str, Any]:
    """Mean event rate of one kernel over its networks and clips, with a percentile bootstrap CI.

    Parameters
    ----------
    evidence : sequence of ClipEvidence
        One per network, each with :attr:`ClipEvidence.clip_event_rates`, the same clip count.
    test_clips : {"per_network", "shared"}
        How the networks' clips were drawn (:func:`bootstrap_weights`).
    confidence : float
        Two-sided level in (0, 1).
    n_resamples : int
        Bootstrap resamples.
    rng : int or numpy Generator

    Returns
    -------
    dict
        ``mean``, ``low``, ``high`` (events/pixel/s), ``unit``, ``confidence``, ``n_clips`` (in
        total), ``n_networks``; or ``{"status": "unavailable: ..."}`` without per-clip rates.
    """
    if not 0.0 < confidence < 1.0:
        raise InputError(f"event_rate_ci: confidence={confidence!r}; allowed: (0, 1)")
    if not evidence or any(e.clip_event_rates is None for e in evidence):
        return {"status": "unavailable: no per-clip event rates recorded"}
    counts = {len(e.clip_event_rates) for e in evidence}  # type: ignore[arg-type]
    if len(counts) != 1:
        return {"status": f"unavailable: networks scored different clip counts {sorted(counts)}"}
    rates = np.stack([np.asarray(e.clip_event_rates, dtype=np.float64) for e in evidence])
    ws, wc = bootstrap_weights(rates.shape[0], rates.shape[1], test_clips=test_clips, n_resamples=n_resamples, rng=rng)
    boot = weighted_rate(rates, ws, wc)
    alpha = (1.0 - confidence) / 2.0
    n_total = rates.size if test_clips == "per_network" else rates.shape[1]
    return {
        "mean": float(rates.mean()),
        "low": float(np.quantile(boot, alpha)),
        "high": float(np.quantile(boot, 1.0 - alpha)),
        "unit": EVENT_RATE_UNIT,
        "confidence": confidence,
        "n_clips": int(n_total),
        "n_networks": int(rates.shape[0]),
    }
