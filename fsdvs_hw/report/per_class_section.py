"""The report's "Per class" section: each user-data task's dataset, per-class metrics and confusion matrix.

For every ``[tasks.datasets.<task>]`` task scored on the simulator track, the section (template
``per_class.html.j2``) shows

* the **dataset summary** (clips, videos, classes, resolution, frames per clip, frame rate, split
  sizes; ``dataset_summary`` of the track record);
* a **per-class table**: each class's metric (top-1 for recognition, AP@[.50:.95] for detection,
  IoU for segmentation) with its 95 % bootstrap CI for every scored design point, and for
  detection each class's AP50 and AP75 in the reference point (``per_class`` of the track record,
  :func:`fsdvs_hw.tasks.per_class.per_class_metrics`);
* for detection, **mAP, AP50 and AP75** of every point with their CIs;
* for recognition, the **confusion matrix** of the reference point (the learned kernel where it
  was scored) as a figure, counts in every cell.

Nothing here is computed again: the numbers are the records the exploration stored.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from markupsafe import Markup

from ..records import ScoredPoint
from .present import number, point_title
from .templating import render

__all__ = ["confusion_figure", "per_class_section", "per_class_tracks"]

_METRIC_LABEL = {"top1": "top-1", "ap": "AP@[.50:.95]", "iou": "IoU"}


def per_class_tracks(points: Sequence[ScoredPoint]) -> dict[str, list[tuple[str, str, Mapping[str, Any]]]]:
    """Task → ``[(point title, realisation, simulator-track extra record)]`` of points with ``per_class``.

    Examples
    --------
    >>> per_class_tracks([])
    {}
    """
    out: dict[str, list[tuple[str, str, Mapping[str, Any]]]] = {}
    for p in points:
        if not p.ok or p.score is None:
            continue
        for task, tracks in p.score.tasks.tracks.items():
            rec = tracks.get("simulator")
            if rec is not None and rec.ok and rec.extra.get("per_class"):
                out.setdefault(task, []).append((point_title(p.realisation, p.params), p.realisation, rec.extra))
    return out


def _ci_text(value: Any, ci: Any) -> str:
    if value is None:
        return "–"
    if not ci:
        return number(float(value), 3)
    return f"{number(float(value), 3)} [{number(float(ci[0]), 3)}, {number(float(ci[1]), 3)}]"


def confusion_figure(confusion: Sequence[Sequence[int]], names: Sequence[str], title: str) -> Any:
    """A Matplotlib figure of a confusion matrix (rows true, columns predicted), counts written in each cell.

    Examples
    --------
    >>> fig = confusion_figure([[3, 1], [0, 4]], ["run", "jump"], "learned")
    >>> fig.axes[0].get_xlabel()
    'predicted class'
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    m = np.asarray(confusion, dtype=np.int64)
    c = m.shape[0]
    side = min(9.0, 2.2 + 0.45 * c)
    fig, ax = plt.subplots(figsize=(side + 1.2, side))
    im = ax.imshow(m, cmap="Blues", vmin=0)
    fig.colorbar(im, ax=ax, label="clips")
    ticks = range(c)
    labels = [str(n)[:18] for n in names] if c <= 40 else [str(k) for k in ticks]
    ax.set_xticks(list(ticks), labels, rotation=90 if c > 6 else 0, fontsize=8)
    ax.set_yticks(list(ticks), labels, fontsize=8)
    ax.set_xlabel("predicted class")
    ax.set_ylabel("true class")
    ax.set_title(title, fontsize=10)
    if c <= 30:
        top = max(1, int(m.max()))
        for i in range(c):
            for j in range(c):
                ax.text(
                    j,
                    i,
                    str(m[i, j]),
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="white" if m[i, j] > top / 2 else "black",
                )
    fig.tight_layout()
    return fig


def _reference(entries: Sequence[tuple[str, str, Mapping[str, Any]]]) -> tuple[str, str, Mapping[str, Any]]:
    """The learned kernel's entry where it was scored, else the first."""
    return next((e for e in entries if e[1] == "learned"), entries[0])


def _summary_rows(summary: Mapping[str, Any]) -> list[tuple[str, str]]:
    res = summary.get("resolution")
    splits = summary.get("split_sizes") or {}
    return [
        ("reader", str(summary.get("format", ""))),
        ("clips in the split", str(summary.get("n_clips", ""))),
        ("clips (or videos) scored", str(summary.get("n_scored", ""))),
        ("videos / sequences", "–" if summary.get("n_videos") is None else str(summary["n_videos"])),
        ("classes", f"{summary.get('n_classes', '')}: {', '.join(summary.get('class_names') or [])}"),
        ("resolution (H × W px)", "the files' own" if not res else f"{res[0]} × {res[1]}"),
        ("frames per clip", str(summary.get("n_frames", ""))),
        ("frame rate", "–" if summary.get("fps") is None else f"{number(float(summary['fps']), 3)} Hz"),
        ("split sizes", ", ".join(f"{k} {v}" for k, v in splits.items())),
    ]


def _task_block(
    task: str, entries: Sequence[tuple[str, str, Mapping[str, Any]]], figure: Callable[..., Any] | None
) -> dict[str, Any]:
    ref_title, _, ref = _reference(entries)
    pc = ref["per_class"]
    columns = [("name", "class"), ("n", {"top1": "clips", "ap": "boxes", "iou": "labelled px"}[pc["metric"]])]
    columns += [(f"p{k}", title) for k, (title, _, _) in enumerate(entries)]
    detection = pc["metric"] == "ap"
    if detection:
        columns += [("ap50", f"AP50 ({ref_title})"), ("ap75", f"AP75 ({ref_title})")]
    rows = []
    for i, cls in enumerate(pc["classes"]):
        cells = {"name": cls["name"], "n": str(cls["n"])}
        for k, (_, _, extra) in enumerate(entries):
            row = extra["per_class"]["classes"][i]
            cells[f"p{k}"] = _ci_text(row.get("value"), row.get("ci"))
        if detection:
            cells["ap50"] = _ci_text(cls.get("ap50"), cls.get("ap50_ci"))
            cells["ap75"] = _ci_text(cls.get("ap75"), cls.get("ap75_ci"))
        rows.append({"front": False, "cells": cells})
    overall = []
    if detection:
        for title, _, extra in entries:
            o = extra["per_class"]["overall"]
            overall.append(
                {
                    "front": False,
                    "cells": {"name": title}
                    | {k: _ci_text(o[k]["value"], o[k]["ci"]) for k in ("map", "map_50", "map_75")},
                }
            )
    fig = None
    if figure is not None and pc.get("confusion"):
        names = [c["name"] for c in pc["classes"]]
        n = sum(map(sum, pc["confusion"]))
        fig = figure(
            confusion_figure(pc["confusion"], names, f"{task}: {ref_title}"),
            f"Confusion matrix of {task} ({ref_title}): true class by row, predicted class by column, {n} clips",
            f"<b>Confusion matrix of {task}</b> in the {ref_title} point: counts of the {n} scored clips (or videos), "
            "true class by row, predicted class by column; the diagonal is what was right.",
            fig_id=f"fig-confusion-{task}",
        )
    return {
        "task": task,
        "metric": _METRIC_LABEL.get(pc["metric"], pc["metric"]),
        "summary": _summary_rows(ref.get("dataset_summary") or {}),
        "columns": columns,
        "left": ("name",),
        "rows": rows,
        "overall": overall,
        "n_resamples": pc.get("n_resamples"),
        "confidence": pc.get("confidence"),
        "reference": ref_title,
        "confusion": fig,
    }


def per_class_section(points: Sequence[ScoredPoint], figure: Callable[..., Any] | None = None) -> Markup | str:
    """The "Per class" section (HTML), or ``""`` when no user-data task recorded per-class metrics.

    Parameters
    ----------
    points : sequence of ScoredPoint
        The scored points.
    figure : callable, optional
        ``figure(fig, alt, caption, fig_id=...)`` embeds a Matplotlib figure (the report's own
        helper); without it there is no confusion-matrix figure.

    Examples
    --------
    >>> per_class_section([])
    ''
    """
    tracks = per_class_tracks(points)
    if not tracks:
        return ""
    return render("per_class.html.j2", tasks=[_task_block(t, e, figure) for t, e in tracks.items()])
