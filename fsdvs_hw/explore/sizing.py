"""Size the test sets from a pilot run so that every loss CI reaches a wanted half-width.

Procedure (what ``designs/default.toml``'s ``n_test`` came from; the README records the numbers):

1. Run the design once with a pilot number of test clips ``n_p`` per task
   (``fsdvs-hw sizing designs/default.toml --pilot 512``), or take a finished
   run as the pilot (``--from out/demo``).
2. For every track, task and realisation, bootstrap the paired loss over clips only (half-width
   ``h_c`` at ``n_p`` clips), over training seeds only (``h_seeds``; none with one seed), and over
   clips for each seed's network alone (``h_c,s``). The seed-only interval also sees each seed's
   clip noise, ``h_n² = (S−1)/S · mean_s(h_c,s²) / S``; the rest is the true seed-to-seed spread,
   ``h_s² = max(0, h_seeds² − h_n²)``.
3. The clip parts fall as ``1/n`` in variance and the parts add, so the realisation needs
   ``n = ⌈n_p (h_c² + h_n²) / (h²/margin − h_s²)⌉`` clips
   (:func:`fsdvs_hw.stats.clips_for_half_width`, ``margin`` for the pilot's own sampling error),
   rounded up to a multiple of the evaluation batch; a task's test set is the largest over the
   realisations that can reach the target.

If the seed part alone exceeds the target, no number of clips reaches it: the budget lists that
realisation as seed-limited with its ``h_s`` (train more seeds to go below it).

Nested design (``[tasks] test_clips = "per_network"``, the default: each of the ``S`` networks
scores its own ``m`` clips). The whole-cluster interval ``h_t`` holds both parts,
``h_t² ∝ (σ_seed² + σ_clip²/m) / S``; the interval that resamples clips within each network holds
the clip part alone, ``h_c``. So ``h_s² = max(0, h_t² − h_c²)`` and each network needs
``m = ⌈m_p h_c² / (h²/margin − h_s²)⌉`` clips (rounded up to a multiple of 16). Here more
networks shrink ``h_s`` as ``1/√S``: the fix for a seed-limited loss.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import InputError

__all__ = ["ClipBudget", "budget_table", "size_test_sets"]


@dataclass(frozen=True)
class ClipBudget:
    """The clips one task needs on one track.

    Attributes
    ----------
    track, task : str
    n_clips : int or None
        Recommended test clips per network (None: unreachable by clips; see ``reason``).
    n_pilot : int
        Pilot clips per network.
    nested : bool
        Each network scored its own clips (``test_clips = "per_network"``).
    limiting : str
        The realisation that needs the most clips.
    h_clip, h_seed : float
        Its clip-only pilot half-width and its true seed-to-seed half-width (clip noise removed).
    per_realisation : dict
        Realisation label → clips it alone would need (None if seed-limited).
    seed_limited : dict
        Realisation label → its seed-to-seed half-width ``h_s`` where that alone exceeds the target.
    reason : str
        Empty, or why ``n_clips`` is None (every realisation seed-limited).
    """

    track: str
    task: str
    n_clips: int | None
    n_pilot: int
    limiting: str
    h_clip: float
    h_seed: float
    per_realisation: dict[str, int | None]
    seed_limited: dict[str, float]
    reason: str = ""
    nested: bool = False


def size_test_sets(
    points: Iterable[Mapping[str, Any]],
    *,
    target_half_width: float = 0.01,
    margin: float = 1.15,
    batch: int = 64,
    n_resamples: int = 1000,
    confidence: float = 0.95,
    reference: str = "learned",
) -> list[ClipBudget]:
    """Clips per task and track for loss CIs of half-width ``target_half_width``, from pilot points.

    Parameters
    ----------
    points : iterable of mappings
        Stored pilot points with per-clip evidence (``results.sqlite`` rows of an exploration).
    target_half_width : float
        Wanted CI half-width (metric fraction; 0.01 = one point).
    margin : float
        Safety factor on the clip count (≥ 1) for the pilot's own sampling error.
    batch : int
        Round the clip count up to a multiple of this (the evaluation batch).
    n_resamples, confidence, reference
        Bootstrap settings and the reference realisation.

    Returns
    -------
    list of ClipBudget
    """
    from ..stats import DifferenceCI, task_difference_cis
    from .paired import decode_evidence
    from .scoring import TRACK_PREFIX

    if not margin >= 1.0:
        raise InputError(f"size_test_sets: margin must be >= 1, got {margin!r}")
    points = [p for p in points if p.get("status") == "ok"]
    ref = next((p for p in points if p["realisation"] == reference), None)
    if ref is None:
        raise InputError(f"size_test_sets: no {reference!r} point among the pilot points")

    def arm(p: Mapping[str, Any], task: str, track: str) -> list[Any] | None:
        rec = ((p.get("result") or {}).get("tasks") or {}).get(task, {}).get(track)
        if not isinstance(rec, Mapping) or not rec.get("evidence"):
            return None
        return [decode_evidence(e) for e in rec["evidence"]]

    def label(p: Mapping[str, Any]) -> str:
        params = p.get("params") or {}
        return p["realisation"] + ("" if not params else " " + ", ".join(f"{k}={v}" for k, v in params.items()))

    out: list[ClipBudget] = []
    for track in TRACK_PREFIX:
        for task, tracks in ((ref.get("result") or {}).get("tasks") or {}).items():
            if not isinstance(tracks, Mapping):
                continue
            r_arm = arm(ref, task, track)
            if r_arm is None:
                continue
            cands = {p["key"]: a for p in points if p is not ref and (a := arm(p, task, track)) is not None}
            if not cands:
                continue
            labels = {p["key"]: label(p) for p in points}
            kw: dict[str, Any] = {"n_resamples": n_resamples, "confidence": confidence}
            if tracks.get(track, {}).get("test_clips") == "per_network":
                out.append(_nested_budget(track, task, r_arm, cands, labels, target_half_width, margin, kw))
                continue
            clips = task_difference_cis({task: (r_arm, cands)}, resample=("clips",), **kw)
            n_seeds = len(r_arm)
            seeds = task_difference_cis({task: (r_arm, cands)}, resample=("seeds",), **kw) if n_seeds > 1 else {}
            per_seed = (
                [
                    task_difference_cis(
                        {task: ([r_arm[s]], {k: [a[s]] for k, a in cands.items()})}, resample=("clips",), **kw
                    )
                    for s in range(n_seeds)
                ]
                if n_seeds > 1
                else []
            )
            rows = []
            for key in cands:
                c: DifferenceCI = clips[key][task]
                h_n2 = 0.0
                h_s = 0.0
                if seeds:
                    h_n2 = (n_seeds - 1) / n_seeds * sum(ps[key][task].half_width ** 2 for ps in per_seed) / n_seeds**2
                    h_s = math.sqrt(max(0.0, seeds[key][task].half_width ** 2 - h_n2))
                rows.append(
                    (
                        labels[key],
                        c,
                        h_s,
                        _clips_needed(c, target_half_width / margin**0.5, h_s, math.sqrt(h_n2), 1, batch),
                    )
                )
            out.append(
                _budget(track, task, r_arm[0].n_clips, rows, "every realisation is seed-limited: train more seeds")
            )
    return out


def _nested_budget(
    track: str,
    task: str,
    r_arm: list[Any],
    cands: dict[str, list[Any]],
    labels: dict[str, str],
    target: float,
    margin: float,
    kw: dict[str, Any],
    step: int = 16,
) -> ClipBudget:
    """Clips per network for one task of a nested design (module docstring)."""
    from ..stats import task_difference_cis

    n_seeds = len(r_arm)
    clips = task_difference_cis({task: (r_arm, cands)}, nested_clips=True, resample=("clips",), **kw)
    both = task_difference_cis({task: (r_arm, cands)}, nested_clips=True, **kw) if n_seeds > 1 else clips
    rows = []
    for key in cands:
        c, t = clips[key][task], both[key][task]
        h_s = math.sqrt(max(0.0, t.half_width**2 - c.half_width**2))
        rows.append((labels[key], c, h_s, _clips_needed(c, target / margin**0.5, h_s, 0.0, n_seeds, step)))
    return _budget(
        track,
        task,
        r_arm[0].n_clips,
        rows,
        f"every realisation is seed-limited with {n_seeds} networks: train more",
        nested=True,
    )


def _clips_needed(pilot: Any, target: float, h_s: float, h_n: float, n_networks: int, step: int) -> int | None:
    """Clips (per network) for ``target``, rounded up to ``step``; None when the seed part alone exceeds it."""
    from ..stats import clips_for_half_width

    try:
        total = clips_for_half_width(pilot, target, seed_half_width=h_s, seed_noise_half_width=h_n)
    except InputError:
        return None
    return int(math.ceil(total / n_networks / step) * step)


def _budget(
    track: str,
    task: str,
    n_pilot: int,
    rows: list[tuple[str, Any, float, int | None]],
    reason: str,
    *,
    nested: bool = False,
) -> ClipBudget:
    """One task's budget from (label, pilot clip CI, seed half-width, clips needed or None) per realisation."""
    need: dict[str, int | None] = {}
    limited: dict[str, float] = {}
    worst: tuple[float, str, float, float] = (-1.0, "", math.nan, math.nan)
    for label, c, h_s, n in rows:
        need[label] = n
        if n is None:
            limited[label] = h_s
        elif n > worst[0]:
            worst = (float(n), label, c.half_width, h_s)
    n_max = None if worst[0] < 0 else int(worst[0])
    return ClipBudget(
        track,
        task,
        n_max,
        n_pilot,
        worst[1],
        worst[2],
        worst[3],
        need,
        limited,
        "" if n_max is not None else reason,
        nested=nested,
    )


def budget_table(budgets: Iterable[ClipBudget]) -> str:
    """The clip budgets of :func:`size_test_sets` as a Markdown table (one row per track and task)."""
    lines = [
        "| track | task | clips needed | limiting realisation | its pilot h (clips) | its h (seeds) | "
        "clips per realisation | seed-limited (± h_s, more clips cannot help) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for b in budgets:
        per = ", ".join(f"{k}: {v}" for k, v in b.per_realisation.items() if v is not None)
        lim = ", ".join(f"{k}: ± {v:.3f}" for k, v in b.seed_limited.items()) or "none"
        lines.append(
            f"| {b.track} | {b.task} | {b.n_clips if b.n_clips is not None else b.reason} | {b.limiting} | "
            f"{b.h_clip:.4f} | {b.h_seed:.4f} | {per} | {lim} |"
        )
    return "\n".join(lines)
