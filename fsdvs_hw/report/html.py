"""The self-contained HTML report of an exploration (figures embedded as base64 PNG).

One file, no external assets and no script: it opens from a mail attachment or a CI artefact,
offline. Alongside it ``scores.csv`` and ``scores.json`` hold the same numbers for further
analysis. The page opens with the verdict (:mod:`fsdvs_hw.report.verdict`); figures follow, each
in a ``<figure>`` with a caption and a descriptive alt text, drawn at twice their displayed size
for sharp screens; the wide tables are split by topic and sit behind ``<details>`` toggles in
containers that scroll on their own, so the page fits a 1280 px window.

:func:`write_report` writes a report from the scored points and the design's
:class:`~fsdvs_hw.report.report_input.ReportInput`; :func:`fsdvs_hw.report.redraw.write_report_from_scores`
rebuilds one from the ``scores.json`` an earlier run left, without rerunning anything.
"""

from __future__ import annotations

import base64
import datetime as _dt
import io
import json
import math
import platform
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from markupsafe import Markup

from .. import __version__
from ..paths import write_output
from ..records import Cost, ScoredPoint
from . import figures
from .artifact_links import artifacts_html
from .codesign_section import codesign_section
from .costs import cost_section, with_cost_columns
from .failures import failures_section, task_failures
from .metalens_layout_section import metalens_layout_section
from .per_class_section import per_class_section
from .present import cost_label, number, plain, point_title, si, style, title
from .process_section import process_section
from .report_input import ReportInput
from .tables import accuracy_axis, networks_note, score_rows, verdict_rows, write_scores
from .templating import render
from .verdict import VERDICT_COLUMNS, advice, loss_header, measurability_table, verdict_table

__all__ = ["CSS_DPI", "FIGURE_DPI", "render_html", "write_report"]

#: CSS pixels per inch: a figure of w inches is shown w × CSS_DPI px wide.
CSS_DPI = 96
#: Pixels per inch of the embedded PNGs: twice :data:`CSS_DPI`, sharp on 2× (HiDPI) screens.
FIGURE_DPI = 2 * CSS_DPI

_CSS = """
*{box-sizing:border-box}
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;margin:1.5em auto;max-width:1200px;color:#222;
padding:0 1em;line-height:1.4;overflow-wrap:break-word}
h1{font-size:1.6em;margin-bottom:.3em}h2{font-size:1.25em;border-bottom:1px solid #ccc;padding-bottom:.2em;
margin-top:1.6em}h3{font-size:1.05em}
.lead{font-size:1.02em}
table{border-collapse:collapse;font-size:.85em;margin:.6em 0}td,th{border:1px solid #ddd;padding:3px 7px;
text-align:right;vertical-align:top}
th{background:#f3f3f3}td.l,th.l{text-align:left}tr.front td{background:#eef7ee}
.scroll{max-width:100%;overflow-x:auto}
table.verdict{font-size:.95em}table.verdict td{padding:5px 9px}table.verdict small{color:#555;display:block}
.swatch{display:inline-block;width:.8em;height:.8em;border-radius:50%;margin-right:.4em;vertical-align:baseline}
ul.advice li{margin:.3em 0}
figure{margin:1em 0;max-width:100%}figure img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:.88em;color:#444;max-width:60em}
details{margin:.5em 0;border:1px solid #e3e3e3;border-radius:4px;padding:.3em .8em}
summary{cursor:pointer;font-weight:600}
pre{background:#f7f7f7;padding:.6em;font-size:.8em;overflow:auto;white-space:pre-wrap;max-width:100%}
.note{color:#555;font-size:.9em}.bad{color:#a00}
"""


def _png(fig: Any) -> dict[str, Any]:
    """The figure as a base64 PNG at :data:`FIGURE_DPI` with its displayed size in CSS pixels (closes it)."""
    import matplotlib.pyplot as plt

    w_in, h_in = fig.get_size_inches()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=FIGURE_DPI)
    plt.close(fig)
    return {
        "b64": base64.b64encode(buf.getvalue()).decode("ascii"),
        "width": round(w_in * CSS_DPI),
        "height": round(h_in * CSS_DPI),
    }


def _figure(fig: Any, alt: str, caption: str, *, fig_id: str) -> Markup:
    """``<figure>`` with the PNG, alt text (plain text, escaped) and caption (HTML, as given)."""
    return render("macros.html.j2", macro="figure", fig_id=fig_id, png=_png(fig), alt=alt, caption=Markup(caption))


def _cell(v: Any) -> str:
    """A table cell's text (the template escapes it)."""
    if isinstance(v, bool):
        return "yes" if v else ""
    if isinstance(v, (int, float)):
        return number(v, 4) if isinstance(v, float) else number(v)
    return plain(str(v))


def _table_rows(rows: Sequence[Mapping[str, Any]], columns: Sequence[tuple[str, str]]) -> list[dict[str, Any]]:
    """Rows for the ``table`` macro: the formatted cells, and whether the row is on a Pareto front."""
    return [
        {"front": bool(r.get("pareto") or r.get("pareto_all")), "cells": {c: _cell(r.get(c, "")) for c, _ in columns}}
        for r in rows
    ]


def _names(items: Sequence[str]) -> str:
    items = list(dict.fromkeys(items))
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _verdict_section(rows: Sequence[Mapping[str, Any]], failed_tasks: Sequence[str] = ()) -> Markup:
    """The verdict; ``failed_tasks`` names the requested tasks that failed (``"task (track)"``), so
    the template can say that no loss was measured because they failed, not because none was asked."""
    vt = verdict_table(rows)
    if not vt:
        return render("verdict.html.j2", rows=[], failed_tasks=list(failed_tasks))
    acc, acc_label = accuracy_axis(rows)
    return render(
        "verdict.html.j2",
        rows=[{**v, "colour": style(v["realisation_name"]).colour} for v in vt],
        advice=advice(rows),
        headers=[loss_header(rows) if c == "loss" else t for c, t in VERDICT_COLUMNS],
        acc_is_loss=acc.endswith("_loss"),
        acc_label=acc_label,
        failed_tasks=list(failed_tasks),
        measure=measurability_table(rows),
    )


def _per_task_table(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any] | None:
    """Every task's loss per point (the rows, columns and left-aligned keys of the report's toggle)."""
    vr = verdict_rows(rows)
    if not vr:
        return None
    titled = []
    ok = [r for r in rows if r["status"] == "ok"]
    for verdict, r in zip(vr, ok):  # verdict_rows keeps the order of the ok rows
        v: dict[str, Any] = dict(verdict)
        v["realisation"] = point_title(r["realisation"], r.get("params"))
        v.pop("MS agreement, fitted scale", None)  # in the verdict table already
        v.pop("cost (own unit)", None)  # the verdict's headline cost and the realisation details hold the costs
        v["pareto"], v["pareto_all"] = r.get("pareto"), r.get("pareto_all")
        titled.append(v)
    cols = [(c, c) for c in dict.fromkeys(k for v in titled for k in v) if c not in ("pareto", "pareto_all")]
    cols = [(c, "Mannos–Sakrison r, design geometry" if c == "MS agreement, design geometry" else t) for c, t in cols]
    return {"rows": _table_rows(titled, cols), "columns": cols, "left": [c for c, _ in cols]}


def _ci_cell(rec: Mapping[str, Any] | None, digits: int = 3) -> str:
    if not isinstance(rec, Mapping):
        return "–"
    if rec.get("status") != "ok":
        return "refused" if str(rec.get("status", "")).startswith("refused") else "–"
    return f"{rec['estimate']:+.{digits}f} [{rec['low']:+.{digits}f}, {rec['high']:+.{digits}f}]"


#: Columns of the equal-event-rate table.
_MATCHED_COLUMNS = [
    ("name", "point"),
    ("task", "task"),
    ("rate", "event rate (events/pixel/s)"),
    ("raw", "loss, same threshold"),
    ("matched", "loss at equal rate"),
    ("gain", "gain over a plain DVS at equal rate"),
]


def _matched_rate_section(points: Sequence[ScoredPoint]) -> Markup | str:
    """Equal event rate: the metric-vs-rate figure, one sentence per task, the per-point table."""
    recs = [(p, p.extra.get("matched_rate") or {}) for p in points if p.ok]
    if not any(m.get("status") == "ok" for _, m in recs):
        return ""
    tasks = list(dict.fromkeys(t for _, m in recs for t, e in m.items() if isinstance(e, Mapping)))
    learned = next((m for p, m in recs if p.realisation == "learned" and not p.params), None) or next(
        (m for p, m in recs if p.realisation == "learned"), {}
    )
    said = [
        (
            t,
            (learned.get(t) or {}).get("gain_over_plain_dvs_at_matched_rate")
            or {"status": "no learned point with a plain-DVS curve"},
        )
        for t in tasks
    ]
    table = []
    for p, m in recs:
        for t in tasks:
            e = m.get(t)
            if not isinstance(e, Mapping):
                continue
            q = e.get("point") or {}
            loss = e.get("loss_at_matched_rate") or {}
            raw = (
                {"status": "ok", "estimate": loss["raw_estimate"], "low": loss["raw_low"], "high": loss["raw_high"]}
                if loss.get("status") == "ok"
                else None
            )
            table.append(
                {
                    "name": point_title(p.realisation, p.params),
                    "task": t,
                    "rate": (f"{q['rate']:.3g} [{q['rate_low']:.3g}, {q['rate_high']:.3g}]" if q else "–"),
                    "raw": _ci_cell(raw),
                    "matched": _ci_cell(loss),
                    "gain": _ci_cell(e.get("gain_over_plain_dvs_at_matched_rate")),
                }
            )
    png = _png(figures.fig_matched_rate(points))
    alt = (
        f"Log-x line and scatter plots, one per task ({_names(tasks)}), of the task metric against the event rate: "
        "the plain DVS and the learned kernel as their contrast threshold is swept, and every scored point at its "
        "own threshold, with confidence bars on both axes."
    )
    return render(
        "matched_rate.html.j2",
        sentences=said,
        png=png,
        alt=alt,
        table=_table_rows(table, _MATCHED_COLUMNS),
        columns=_MATCHED_COLUMNS,
    )


def _score_tables(ok: Sequence[Mapping[str, Any]], methods: Sequence[str]) -> Markup:
    """The scores split by topic, each a few columns, behind toggles."""
    named = [{**r, "name": point_title(r["realisation"], r.get("params"))} for r in ok]

    def table(columns: list[tuple[str, str]]) -> dict[str, Any]:
        return {"rows": _table_rows(named, columns), "columns": columns}

    fit = table(
        [
            ("name", "realisation"),
            ("kernel_error", "kernel error"),
            ("kernel_error_gain_free", "gain-free error"),
            ("peak_frequency_cpp", "peak (cycles/pixel)"),
            ("response_kind", "response"),
        ]
    )
    csf_cols = [("name", "realisation")] + [(f"csf_{m}_correlation", _csf_name(m)) for m in methods]
    csf_cols += [("csf_fitted_correlation", "Mannos–Sakrison, fitted scale"), ("csf_fitted_ppd", "fitted px/degree")]
    metrics = list(dict.fromkeys(c for r in ok for c in r if c.startswith("metric_")))
    emulation = any("emu_event_ratio" in r for r in ok)
    return render(
        "scores.html.j2",
        fit=fit,
        csf=table(csf_cols),
        metrics=table([("name", "realisation")] + [(c, _metric_name(c)) for c in metrics]) if metrics else None,
        emulation=table(
            [
                ("name", "realisation"),
                ("emu_event_ratio", "events, emulated / in-sensor"),
                ("emu_signed_correlation", "ON−OFF frame correlation"),
            ]
        )
        if emulation
        else None,
    )


def _csf_name(method: str) -> str:
    return figures.csf_title("CSF " + method)[4:]


def _metric_name(column: str) -> str:
    task, _, track = column[len("metric_") :].partition("/")
    primary = {"detection": "mAP", "recognition": "top-1", "segmentation": "mIoU"}.get(task, "metric")
    return f"{task} {primary} ({track})"


#: Wall-time columns of the score rows (seconds).
_WALL = ("fit_s", "analysis_s", "tasks_s", "emulation_s", "point_s")

#: Stored cost items also shown as score columns (listed once, there).
_SHOWN_AS_SCORES = {"kernel_error": "kernel error (Scores by topic)", "fit_time": "fit time (Speed for accuracy)"}

#: Columns of a point's quantity table.
_QUANTITY_COLUMNS = [("item", "quantity"), ("value", "value"), ("definition", "definition")]


def _realisation_details(points: Sequence[ScoredPoint]) -> Markup:
    """Per scored point: every stored cost and design quantity with its unit (SI prefixes) and definition."""
    shown = [
        {
            "title": point_title(p.realisation, p.params),
            "quantities": _table_rows(_quantities(p.realisation, p.score.cost), _QUANTITY_COLUMNS),
            "warnings": [plain(w) for w in p.score.warnings],
        }
        for p in points
        if p.ok and p.score is not None
    ]
    return render(
        "realisations.html.j2", points=shown, columns=_QUANTITY_COLUMNS, shown_as_scores=list(_SHOWN_AS_SCORES.values())
    )


def _quantities(realisation: str, cost: Cost) -> list[dict[str, str]]:
    """Rows (quantity, value, definition) of a point's stored cost items, each quantity once.

    Items shown as score columns (:data:`_SHOWN_AS_SCORES`) are left out; a length stored both in
    metres (``X_m``) and in pixels (``X_px``) is one row, "5.35 µm (1.1 px)".
    """
    items = cost.items
    rows = []
    for k, v in items.items():
        if k in _SHOWN_AS_SCORES or (k.endswith("_px") and k[:-3] + "_m" in items):
            continue
        value = si(cost.value(k), v.unit or "1")
        label = cost_label(realisation, k)
        if k.endswith("_m") and k[:-2] + "_px" in items:
            value += f" ({si(cost.value(k[:-2] + '_px'), cost.unit(k[:-2] + '_px') or 'px')})"
            label = cost_label(realisation, k[:-2])
        rows.append({"item": label, "value": value, "definition": plain(str(v.description))})
    return rows


def _float(v: Any) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def render_html(
    points: Sequence[ScoredPoint],
    report: ReportInput,
    *,
    title_text: str | None = None,
    stamp: str | None = None,
    sections: Sequence[str] = (),
) -> str:
    """The report as one HTML string (figures embedded), from the templates in ``report/templates``.

    Parameters
    ----------
    points : sequence of ScoredPoint
        The scored design points, with their paired losses where task losses were computed.
    report : ReportInput
        The design they came from (:func:`fsdvs_hw.explore.reporting.report_input`): its name,
        target, sensor, optics and CSF settings.
    title_text : str, optional
        Page title (default: "FS-DVS design exploration: <design name>").
    stamp : str, optional
        Time stamp in the provenance (default: now, UTC).
    sections : sequence of str
        Further HTML fragments (each starting with its own ``<h2>``, inserted as given), placed after
        the buildable artifacts and before the run conditions, e.g.
        :func:`fsdvs_hw.report.codesign_section.codesign_section`.
    """
    rows = with_cost_columns(score_rows(points), points)  # power_w, area_m2, ...
    ok = [r for r in rows if r["status"] == "ok"]
    acc, acc_label = accuracy_axis(rows)
    methods = list(report.csf_methods)
    t = report.target
    focal = report.focal_length_m
    n_ok, n_skip, n_err = (sum(r["status"] == s for r in rows) for s in ("ok", "skipped", "error"))
    page: dict[str, Any] = {
        "page_title": title_text or f"FS-DVS design exploration: {report.name}",
        "css": Markup(_CSS),
        "target": t,
        "focal": focal,
        "n_rows": len(rows),
        "n_ok": n_ok,
        "n_skip": n_skip,
        "n_err": n_err,
        "failures": failures_section(points),  # tasks that failed, clips skipped: first (report/failures.py)
        "verdict": _verdict_section(rows, [f"{f.task} ({f.track})" for f in task_failures(points)]),
        "figures": None,
        "acc_label": acc_label,
        "not_scored": _table_rows(
            [{**r, "name": point_title(r["realisation"], r.get("params"))} for r in rows if r["status"] != "ok"],
            [("name", ""), ("status", ""), ("reason", "")],
        ),
    }
    if ok:
        page.update(_figures_and_tables(points, rows, ok, acc, methods, t.pitch_m, focal))
    page.update(
        artifacts=artifacts_html(points),  # buildable files per hardware point (report/artifact_links.py)
        sections=[Markup(s) for s in sections if s],
        conditions=_conditions(points, rows, report),
        version=__version__,
        python=platform.python_version(),
        node=platform.node(),
        stamp=stamp or _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        source=report.source,
        versions=_versions(points),
        design_json=json.dumps(dict(report.design_data), indent=1),
    )
    return str(render("report.html.j2", **page))


def _figures_and_tables(
    points: Sequence[ScoredPoint],
    rows: Sequence[Mapping[str, Any]],
    ok: Sequence[Mapping[str, Any]],
    acc: str,
    methods: Sequence[str],
    pitch_m: float,
    focal: float,
) -> dict[str, Any]:
    """The report's figures (PNG and alt text, drawn in page order) and the sections between them."""
    kinds = [title(k) for k in dict.fromkeys(r["realisation"] for r in ok)]
    hw = [title(k) for k in dict.fromkeys(r["realisation"] for r in ok if r.get("kind_cost"))]
    what = "accuracy loss" if acc.endswith("_loss") else "kernel error"
    bars = "with 95 % confidence bars " if acc.endswith("_loss") else ""
    figs = {
        "pareto": {
            "png": _png(figures.fig_pareto(rows)),
            "alt": f"Scatter plots of {what} {bars}against CSF agreement for {_names(kinds)}, and against "
            f"each hardware kind's own cost{(' for ' + _names(hw)) if hw else ''}.",
        }
    }
    costs = cost_section(rows, points, _figure)  # physical costs across kinds
    panels = figures.realised_kernels(points)
    pnames = _names([p.label for p in panels])
    figs["kernels"] = {
        "png": _png(figures.fig_kernels(panels)),
        "alt": f"Heat maps of the realised kernel taps of {pnames}, red positive and blue negative, "
        "each on its own colour scale centred at zero.",
    }
    figs["spectra"] = {
        "png": _png(figures.fig_spectra(panels)),
        "alt": f"Heat maps of the two-dimensional magnitude spectra of {pnames} on one shared colour scale.",
    }
    figs["radial"] = {
        "png": _png(figures.fig_radial(panels, methods=methods, pitch_m=pitch_m, focal_length_m=focal)),
        "alt": f"Line plots of the peak-normalised radial frequency responses of {pnames} against "
        "contrast sensitivity curves, at the design geometry and at a fitted viewing scale.",
    }
    per_task = _per_task_table(rows)
    matched_rate = _matched_rate_section(points)
    scores = _score_tables(ok, methods)
    hw_kinds = [title(k) for k in dict.fromkeys(r["realisation"] for r in ok if r.get("kind_cost"))]
    figs["speed"] = {
        "png": _png(figures.fig_speed(rows)),
        "alt": "Log-log scatter plot of kernel error against fit wall time for "
        f"{_names(hw_kinds) if hw_kinds else 'no hardware realisation'}.",
    }
    named = [{**r, "name": point_title(r["realisation"], r.get("params"))} for r in ok]
    wall = [{**r, **{c: si(_float(r.get(c)), "s") for c in _WALL}} for r in named]
    return {
        "figures": figs,
        "what": what,
        "bars": bool(bars),
        "costs": costs,
        "per_task": per_task,
        "matched_rate": matched_rate,
        "scores": scores,
        "realisations": _realisation_details(points),
        "wall_times": _table_rows(wall, [("name", ""), *((c, "") for c in _WALL)]),
    }


def _versions(points: Sequence[ScoredPoint]) -> list[str]:
    """The numerical library versions the points were computed with (one line per distinct set)."""
    sets = {
        tuple(sorted((k, str(v)) for k, v in p.score.versions.items()))
        for p in points
        if p.score is not None and p.score.versions
    }
    return [", ".join(f"{k} {v}" for k, v in s) for s in sorted(sets)]


def _conditions(points: Sequence[ScoredPoint], rows: Sequence[Mapping[str, Any]], report: ReportInput) -> Markup:
    """Run conditions: sensor, simulator of the task tracks, networks, task status."""
    sensors = set()
    for p in points:
        for task, tracks in p.score.tasks.tracks.items() if p.score is not None else ():
            for track in tracks.values():
                sensor = track.extra.get("sensor")
                if isinstance(sensor, Mapping):
                    sensors.add(f"{task}: " + ", ".join(f"{k} = {v}" for k, v in sensor.items()))
    ok = [r for r in rows if r["status"] == "ok"]
    return render(
        "conditions.html.j2",
        target=report.target,
        focal=report.focal_length_m,
        placement=report.placement,
        positivity=report.positivity,
        sensors=sorted(sensors),
        networks=networks_note(points),
        task_status=sorted({r.get("tasks_status", "") for r in ok} - {""}),
    )


def write_report(points: Sequence[ScoredPoint], report: ReportInput, out_dir: str | Path) -> Path:
    """Write ``report.html``, ``scores.csv`` and ``scores.json`` into ``out_dir``; return the HTML path.

    Parameters
    ----------
    points : sequence of ScoredPoint
        The scored design points.
    report : ReportInput
        The design they came from and, with ``[codesign]`` enabled, the co-design summary this
        run produced (its section goes before the run conditions).
    out_dir : path
        Output folder (created).

    Raises
    ------
    InputError
        A file to write is a symbolic link.

    Examples
    --------
    With no stored point the page says so (an exploration's points make the full report,
    :func:`fsdvs_hw.explore.explore.run_exploration`):

    >>> import json, tempfile
    >>> from pathlib import Path
    >>> from fsdvs_hw import write_report
    >>> from fsdvs_hw.design import parse_design
    >>> from fsdvs_hw.explore.reporting import report_input
    >>> with tempfile.TemporaryDirectory() as out:
    ...     page = write_report([], report_input(parse_design({"design": {"name": "empty"}})), out)
    ...     text = page.read_text()
    ...     stored = json.loads((Path(out) / "scores.json").read_text())
    >>> page.name, "No design point was scored" in text, stored["design"]["name"], stored["points"]
    ('report.html', True, 'empty', [])
    """
    from ..errors import InputError

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name in ("report.html", "scores.csv", "scores.json"):  # refused before any file is replaced
        if (out / name).is_symlink():
            raise InputError(f"--out: {out / name} is a symbolic link; refusing to write through it (remove the link)")
    rows = with_cost_columns(score_rows(points), points)
    write_scores(rows, out, full=[p.to_dict() for p in points], design=report.stamp())
    path = out / "report.html"
    sections = [metalens_layout_section(rows, accuracy_axis(rows)[0])]  # ideal phase → library → layout
    sections.append(per_class_section(points, _figure))  # user-data tasks: per-class metrics, confusion matrix
    sections.append(process_section(points, rows))  # the mesh in a PDK's transistors: corners, mismatch, pitch
    if report.codesign is not None and report.codesign_enabled:
        sections.append(codesign_section(report.codesign))
    # atomically, never through a symbolic link planted in the folder
    return write_output(path, render_html(points, report, sections=sections))
