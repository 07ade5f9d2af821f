"""What a run could not measure: the requested tasks that failed and the clips that were skipped.

A task a design requests (``[tasks] checkpoints`` or ``[tasks.datasets.<task>]``) that ends without
a number on some point (``status`` other than ``"ok"``: a checkpoint that does not load, a user
network whose output the evaluator cannot read, more clips failing to read than
``max_failed_clip_fraction``) is a *failed task*; a user-data task that scored but skipped clips
that failed to read lists them as *skipped clips* (``failed_clips``, ``failed_clip_files`` in its
track record, :func:`fsdvs_hw.explore.scoring.task_scores`).

:func:`task_failures` and :func:`skipped_clips` collect them from the scored points (one entry per
task and track, with the points it concerns), :func:`failure_lines` says them on the console
(``fsdvs-hw explore`` then exits with :data:`EXIT_TASK_FAILED`) and :func:`failures_section` is the
report's first section (template ``failures.html.j2``), above the verdict.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from markupsafe import Markup

from ..records import ScoredPoint
from .present import point_title
from .templating import render

__all__ = [
    "EXIT_TASK_FAILED",
    "SkippedClips",
    "TaskFailure",
    "failure_lines",
    "failures_section",
    "skipped_clips",
    "task_failures",
]

#: Exit status of ``fsdvs-hw explore`` when every point ran but a requested task failed on one or
#: more of them (the report and the scores are written first; 1 = a design point failed, 2 = bad input).
EXIT_TASK_FAILED = 3

#: Reasons and files shown per entry before "and N more" (the count always covers them all).
_SHOWN = 5


@dataclass(frozen=True)
class TaskFailure:
    """A requested task and track that has no number on some points.

    Attributes
    ----------
    task, track : str
        ``"segmentation"``, ``"simulator"``.
    reason : str
        The first point's reason (its ``status`` without ``"unavailable: "``).
    points : tuple of str
        Titles of the points it failed on.
    n_points : int
        Points scored (``status == "ok"``) in the run.
    other_reasons : int
        How many different reasons the other points gave.
    failed_clips : int
        Clips that failed to read (user data; 0 elsewhere).
    n_clips_drawn : int
        Clips drawn (user data; 0 elsewhere).
    files : tuple of dict
        The first failed clips as ``{"index", "file", "reason"}``.
    """

    task: str
    track: str
    reason: str
    points: tuple[str, ...]
    n_points: int
    other_reasons: int = 0
    failed_clips: int = 0
    n_clips_drawn: int = 0
    files: tuple[Mapping[str, Any], ...] = ()


@dataclass(frozen=True)
class SkippedClips:
    """A user-data task and track that was scored without some clips that failed to read.

    Attributes
    ----------
    task, track : str
    failed_clips, n_clips_drawn : int
        Skipped clips and clips drawn (the same on every point: the pairing needs it).
    max_failed_clip_fraction : float or None
        The fraction allowed (None where not recorded).
    files : tuple of dict
        The named failures ``{"index", "file", "reason"}`` (capped, see ``failed_clips`` for all).
    points : tuple of str
        Titles of the points scored so.
    """

    task: str
    track: str
    failed_clips: int
    n_clips_drawn: int
    max_failed_clip_fraction: float | None
    files: tuple[Mapping[str, Any], ...]
    points: tuple[str, ...]


def _tracks(points: Sequence[ScoredPoint]) -> list[tuple[str, str, str, Any]]:
    """``(point title, task, track, TrackScore)`` of every scored point, in order."""
    out = []
    for p in points:
        if not p.ok or p.score is None:
            continue
        name = point_title(p.realisation, p.params)
        for task, tracks in p.score.tasks.tracks.items():
            for track, rec in tracks.items():
                out.append((name, task, track, rec))
    return out


def _reason(status: str) -> str:
    return status.removeprefix("unavailable: ")


def task_failures(points: Sequence[ScoredPoint]) -> list[TaskFailure]:
    """Every requested task and track without a number on at least one scored point.

    Parameters
    ----------
    points : sequence of ScoredPoint
        The scored points.

    Returns
    -------
    list of TaskFailure
        In the order the tasks first appear; empty when every task of every point has its number.

    Examples
    --------
    >>> task_failures([])
    []
    """
    n_ok = sum(1 for p in points if p.ok)
    groups: dict[tuple[str, str], list[tuple[str, Any]]] = {}
    for name, task, track, rec in _tracks(points):
        if not rec.ok:
            groups.setdefault((task, track), []).append((name, rec))
    out = []
    for (task, track), failed in groups.items():
        first = failed[0][1]
        reasons = {_reason(r.status) for _, r in failed}
        out.append(
            TaskFailure(
                task=task,
                track=track,
                reason=_reason(first.status),
                points=tuple(n for n, _ in failed),
                n_points=n_ok,
                other_reasons=len(reasons) - 1,
                failed_clips=int(first.extra.get("failed_clips", 0) or 0),
                n_clips_drawn=int(first.extra.get("n_clips_drawn", 0) or 0),
                files=tuple(first.extra.get("failed_clip_files") or ()),
            )
        )
    return out


def skipped_clips(points: Sequence[ScoredPoint]) -> list[SkippedClips]:
    """Every user-data task and track scored without some clips that failed to read.

    Examples
    --------
    >>> skipped_clips([])
    []
    """
    groups: dict[tuple[str, str], list[tuple[str, Any]]] = {}
    for name, task, track, rec in _tracks(points):
        if rec.ok and int(rec.extra.get("failed_clips", 0) or 0) > 0:
            groups.setdefault((task, track), []).append((name, rec))
    out = []
    for (task, track), recs in groups.items():
        first = recs[0][1].extra
        frac = first.get("max_failed_clip_fraction")
        out.append(
            SkippedClips(
                task=task,
                track=track,
                failed_clips=int(first["failed_clips"]),
                n_clips_drawn=int(first.get("n_clips_drawn", 0) or 0),
                max_failed_clip_fraction=float(frac) if isinstance(frac, (int, float)) else None,
                files=tuple(first.get("failed_clip_files") or ()),
                points=tuple(n for n, _ in recs),
            )
        )
    return out


def _short(text: str, limit: int = 800) -> str:
    flat = " ".join(str(text).split())
    return flat if len(flat) <= limit else flat[: limit - 1] + "…"


def failure_lines(points: Sequence[ScoredPoint], *, prefix: str = "[explore] ") -> list[str]:
    """One console line per failed task (task, track, points, reason), then one per task that skipped clips.

    Examples
    --------
    >>> failure_lines([])
    []
    """
    lines = []
    for f in task_failures(points):
        others = f" (and {f.other_reasons} other reason{'s' * (f.other_reasons > 1)} on other points)"
        lines.append(
            f"{prefix}task FAILED: {f.task} ({f.track} track) on {len(f.points)} of {f.n_points} points: "
            f"{_short(f.reason)}{others if f.other_reasons else ''}"
        )
    for s in skipped_clips(points):
        named = "; ".join(f"{d.get('file')!s}: {_short(str(d.get('reason', '')), 160)}" for d in s.files[:_SHOWN])
        more = f"; and {s.failed_clips - min(len(s.files), _SHOWN)} more" if s.failed_clips > _SHOWN else ""
        lines.append(
            f"{prefix}{s.task} ({s.track} track): {s.failed_clips} of {s.n_clips_drawn} clips skipped "
            f"(failed to read; the loss is on the others, the same for every point): {named}{more}"
        )
    return lines


def _files(files: Sequence[Mapping[str, Any]], total: int) -> list[dict[str, str]]:
    shown = [{"file": str(d.get("file", "")), "reason": _short(str(d.get("reason", "")))} for d in files]
    if total > len(shown):
        shown.append({"file": f"… and {total - len(shown)} more", "reason": "(the count covers them all)"})
    return shown


def failures_section(points: Sequence[ScoredPoint]) -> Markup:
    """The report's "Tasks that failed" and "Clips skipped" sections (empty when there is nothing to say).

    Examples
    --------
    >>> str(failures_section([]))
    ''
    """
    failed = [
        {
            "task": f.task,
            "track": f.track,
            "points": f"{len(f.points)} of {f.n_points}",
            "reason": _short(f.reason, 1200),
            "other_reasons": f.other_reasons,
            "clips": f"{f.failed_clips} of {f.n_clips_drawn}" if f.n_clips_drawn else "",
            "files": _files(f.files, f.failed_clips),
        }
        for f in task_failures(points)
    ]
    skipped = [
        {
            "task": s.task,
            "track": s.track,
            "clips": f"{s.failed_clips} of {s.n_clips_drawn}",
            "fraction": "" if s.max_failed_clip_fraction is None else f"{s.max_failed_clip_fraction:g}",
            "points": len(s.points),
            "files": _files(s.files, s.failed_clips),
        }
        for s in skipped_clips(points)
    ]
    if not failed and not skipped:
        return Markup("")
    return render("failures.html.j2", failed=failed, skipped=skipped, exit_status=EXIT_TASK_FAILED)
