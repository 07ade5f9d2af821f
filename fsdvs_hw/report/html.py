"""The self-contained HTML report of an exploration (figures embedded as base64 PNG).

One file, no external assets and no script: it opens from a mail attachment or a CI artefact,
offline. Alongside it ``scores.csv`` and ``scores.json`` hold the same numbers for further
analysis. The page opens with the verdict (:mod:`fsdvs_hw.report.verdict`); figures follow, each
in a ``<figure>`` with a caption and a descriptive alt text, drawn at twice their displayed size
for sharp screens; the wide tables are split by topic and sit behind ``<details>`` toggles in
containers that scroll on their own, so the page fits a 1280 px window.

:func:`write_report` writes a report from stored points; :func:`write_report_from_scores` rebuilds
one from the ``scores.json`` an earlier run left, without rerunning anything.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import json
import math
import platform
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .. import __version__
from ..paths import write_output
from ..records import Cost, ScoredPoint
from . import figures
from .artifacts import artifacts_html
from .costs import cost_section, with_cost_columns
from .present import cost_label, number, plain, point_title, si, style, title
from .tables import accuracy_axis, networks_note, score_rows, verdict_rows, write_scores
from .verdict import VERDICT_COLUMNS, advice, loss_header, verdict_table

__all__ = [
    "CSS_DPI",
    "FIGURE_DPI",
    "check_same_design",
    "design_stamp",
    "render_html",
    "write_report",
    "write_report_from_scores",
]

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



def _figure(fig: Any, alt: str, caption: str, *, fig_id: str) -> str:
    """``<figure>`` with the PNG at :data:`FIGURE_DPI`, shown at its size in CSS pixels, alt text and caption."""
    import matplotlib.pyplot as plt

    w_in, h_in = fig.get_size_inches()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=FIGURE_DPI)
    plt.close(fig)
    b64 = base64.b64encode(buf.getvalue()).decode("ascii")
    return (f'<figure id="{fig_id}"><img alt="{html.escape(alt)}" width="{round(w_in * CSS_DPI)}" '
            f'height="{round(h_in * CSS_DPI)}" src="data:image/png;base64,{b64}">'
            f"<figcaption>{caption}</figcaption></figure>")


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else ""
    if isinstance(v, (int, float)):
        return number(v, 4) if isinstance(v, float) else number(v)
    return html.escape(plain(str(v)))


def _table(rows: Sequence[Mapping[str, Any]], columns: Sequence[tuple[str, str]], *, left: Sequence[str] = ("point",),
           cls: str = "") -> str:
    """A table in a container that scrolls on its own (the page never does)."""
    head = "".join(f'<th class="{"l" if c in left else ""}" scope="col">{html.escape(t)}</th>' for c, t in columns)
    body = []
    for r in rows:
        tr = ' class="front"' if r.get("pareto") or r.get("pareto_all") else ""
        cells = "".join(f'<td class="{"l" if c in left else ""}">{_fmt(r.get(c, ""))}</td>' for c, _ in columns)
        body.append(f"<tr{tr}>{cells}</tr>")
    return f"<div class='scroll'><table class='{cls}'><tr>{head}</tr>{''.join(body)}</table></div>"


def _details(summary: str, body: str, *, open_: bool = False) -> str:
    return f"<details{' open' if open_ else ''}><summary>{html.escape(summary)}</summary>{body}</details>"


def _names(items: Sequence[str]) -> str:
    items = list(dict.fromkeys(items))
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _verdict_section(rows: Sequence[Mapping[str, Any]]) -> str:
    vt = verdict_table(rows)
    if not vt:
        return "<h2 id='verdict'>Verdict</h2><p>No design point was scored.</p>"
    lines = "".join(f"<li>{html.escape(s)}</li>" for s in advice(rows))
    head = "".join(f"<th class='l' scope='col'>{html.escape(loss_header(rows) if c == 'loss' else t)}</th>"
                   for c, t in VERDICT_COLUMNS)
    trs = []
    for v in vt:
        colour = style(v["realisation_name"]).colour
        n = f"<small>{html.escape(v['n'])}</small>" if v["n"] else ""
        cells = [f"<td class='l'><span class='swatch' style='background:{colour}'></span>"
                 f"{html.escape(v['realisation'])}</td>", f"<td class='l'>{html.escape(v['loss'])}{n}</td>"]
        cells += [f"<td class='l'>{html.escape(v[c])}</td>" for c in ("agreement", "cost", "verdict")]
        tr = " class='front'" if v["front"] else ""
        trs.append(f"<tr{tr}>{''.join(cells)}</tr>")
    acc, acc_label = accuracy_axis(rows)
    if acc.endswith("_loss"):
        first = (f"Accuracy loss: {html.escape(acc_label)}, as a fraction (positive = accuracy lost), with its 95 % "
                 "bootstrap CI over test clips and training seeds; n counts the paired test clips and seeds. ")
    else:
        first = ("No task evaluator ran (the design lists no <code>[tasks] checkpoints</code>), so there is no "
                 "accuracy loss: the column is the kernel error, ‖K − T‖/‖T‖ against the target. ")
    legend = (first + "CSF agreement: correlation of the kernel's radial response with the Mannos–Sakrison CSF at the "
              "fitted viewing scale. Green rows are on a Pareto front. Every number below is defined where it "
              "appears; the full set is in scores.csv and scores.json.")
    how = ("<p class='note'>Loss = task metric of the learned kernel (the kernel being realised) minus that of the "
           "realisation, in the same networks on the same test clips and noise draws (mAP, top-1, mIoU as "
           "fractions), with its 95 % bootstrap CI over test clips and training seeds (each seed with its own "
           "mismatch pattern); a CI that contains 0 reads 'no measurable loss (± half-width)' and is never ranked "
           "by its point estimate. Weighted loss: <code>[scoring] task_weights</code>. Costs: each kind on its own "
           "axis and unit (never one shared cost axis). Pareto: not dominated beyond the loss CIs, within the kind "
           "(loss, agreement, cost) and across kinds (loss, agreement). 'build' marks the hardware on the "
           "front across kinds with no measurable loss (the cheapest of each kind), or else the smallest loss; 'a "
           "cheaper option of its kind' is on its kind's front below a kind that is on the front across kinds; "
           "'not recommended' is everything else.</p>")
    return (f"<h2 id='verdict'>Verdict: what to build</h2><ul class='advice'>{lines}</ul>"
            f"<div class='scroll'><table class='verdict'><tr>{head}</tr>{''.join(trs)}</table></div>"
            f"<p class='note'>{legend}</p>" + _details("How the verdict is decided", how))


def _per_task_section(rows: Sequence[Mapping[str, Any]]) -> str:
    vr = verdict_rows(rows)
    if not vr:
        return ""
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
    return _details("Loss of every task, on the simulator and the emulation track",
                    "<p class='note'>Each task's loss with its 95 % CI and n (test clips, training seeds); the "
                    "emulation track shows the realised kernel on a display recaptured by the noisy simulator. "
                    "Mannos–Sakrison r at the design's optics geometry (the verdict's r uses the fitted scale).</p>"
                    + _table(titled, cols, left=[c for c, _ in cols]))


def _ci_cell(rec: Mapping[str, Any] | None, digits: int = 3) -> str:
    if not isinstance(rec, Mapping):
        return "–"
    if rec.get("status") != "ok":
        return "refused" if str(rec.get("status", "")).startswith("refused") else "–"
    return f"{rec['estimate']:+.{digits}f} [{rec['low']:+.{digits}f}, {rec['high']:+.{digits}f}]"


def _matched_sentence(task: str, rec: Mapping[str, Any]) -> str:
    """One sentence: does the learned kernel beat a plain DVS whose threshold gives the same event rate?"""
    if rec.get("status") != "ok":
        return f"<b>{html.escape(task)}</b>: no matched-rate comparison ({html.escape(str(rec.get('status')))})."
    est, lo, hi, m = rec["estimate"], rec["low"], rec["high"], html.escape(str(rec["metric_name"]))
    if lo > 0:
        words = "the filter's gain holds at equal event rate"
    elif hi < 0:
        words = "a plain DVS at that rate does better: the same-threshold gain came from firing more events"
    else:
        words = ("no measurable gain at equal event rate: the same-threshold gain is what lowering the threshold "
                 "gives")
    return (f"<b>{html.escape(task)}</b>: at equal event rate ({rec['reference_rate']:.3g} events/pixel/s) the learned "
            f"kernel scores {est:+.3f} [{lo:+.3f}, {hi:+.3f}] {m} against a plain DVS whose threshold is lowered "
            f"from {rec['reference_threshold']:g} to {rec['matched_threshold']:.3g} (same threshold: "
            f"{rec['raw_estimate']:+.3f} [{rec['raw_low']:+.3f}, {rec['raw_high']:+.3f}]); {words} "
            f"({rec['confidence']:.0%} CI, n = {rec['n_clips']} clips in {rec['n_networks']} networks).")


def _matched_rate_section(points: Sequence[ScoredPoint]) -> str:
    """Equal event rate: the metric-vs-rate figure, one sentence per task, the per-point table."""
    recs = [(p, p.extra.get("matched_rate") or {}) for p in points if p.ok]
    if not any(m.get("status") == "ok" for _, m in recs):
        return ""
    tasks = list(dict.fromkeys(t for _, m in recs for t, e in m.items() if isinstance(e, Mapping)))
    learned = next((m for p, m in recs if p.realisation == "learned" and not p.params), None) or \
        next((m for p, m in recs if p.realisation == "learned"), {})
    said = [_matched_sentence(t, (learned.get(t) or {}).get("gain_over_plain_dvs_at_matched_rate") or
                              {"status": "no learned point with a plain-DVS curve"}) for t in tasks]
    table = []
    for p, m in recs:
        for t in tasks:
            e = m.get(t)
            if not isinstance(e, Mapping):
                continue
            q = e.get("point") or {}
            loss = e.get("loss_at_matched_rate") or {}
            raw = ({"status": "ok", "estimate": loss["raw_estimate"], "low": loss["raw_low"], "high": loss["raw_high"]}
                   if loss.get("status") == "ok" else None)
            table.append({"name": point_title(p.realisation, p.params), "task": t,
                          "rate": (f"{q['rate']:.3g} [{q['rate_low']:.3g}, {q['rate_high']:.3g}]" if q else "–"),
                          "raw": _ci_cell(raw), "matched": _ci_cell(loss),
                          "gain": _ci_cell(e.get("gain_over_plain_dvs_at_matched_rate"))})
    fig = _figure(
        figures.fig_matched_rate(points),
        f"Log-x line and scatter plots, one per task ({_names(tasks)}), of the task metric against the event rate: "
        "the plain DVS and the learned kernel as their contrast threshold is swept, and every scored point at its "
        "own threshold, with confidence bars on both axes.",
        "<b>Task metric vs event rate.</b> Lines: the reference kernels with their ON = OFF threshold swept (labels: "
        "threshold, log units), in the same networks, clips and noise draws as the points; markers: each point at "
        "the design's threshold. Bars: 95 % bootstrap CIs over (network, clips) clusters on both axes. A point above "
        "the plain-DVS line at its own rate beats a plain DVS with a lowered threshold.", fig_id="fig-matched-rate")
    return ("<h2 id='matched-rate'>Equal event rate</h2><p class='note'>A filter that fires more events can gain "
            "accuracy the way a lowered threshold does. Here every point is also compared at its own event rate: "
            "against the learned kernel and against a plain DVS, each with its threshold moved (interpolated in log "
            "rate, never extrapolated) until it fires as many events.</p><ul class='advice'>"
            + "".join(f"<li>{x}</li>" for x in said) + "</ul>" + fig
            + _details("Every point at equal event rate", "<p class='note'>Loss = learned − point (positive: accuracy "
                       "lost); gain = point − plain DVS; 95 % CIs. 'refused': the point's rate lies outside a "
                       "reference curve (add thresholds to [rate] thresholds).</p>" + _table(
                           table, [("name", "point"), ("task", "task"), ("rate", "event rate (events/pixel/s)"),
                                   ("raw", "loss, same threshold"), ("matched", "loss at equal rate"),
                                   ("gain", "gain over a plain DVS at equal rate")], left=("name", "task"))))


def _score_tables(ok: Sequence[Mapping[str, Any]], methods: Sequence[str]) -> str:
    """The scores split by topic, each a few columns, behind toggles."""
    named = [{**r, "name": point_title(r["realisation"], r.get("params"))} for r in ok]
    out = []
    out.append(_details("Kernel fit and spectrum", "<p class='note'>Kernel error: relative L2 distance of the "
                        "realised kernel from the target, ‖K − T‖/‖T‖ (each realisation's one error; the metalens "
                        "pedestal included). Gain-free error: the same after the least-squares gain, which a "
                        "comparator threshold absorbs. Peak: frequency of the largest radial response.</p>"
                        + _table(named, [("name", "realisation"), ("kernel_error", "kernel error"),
                                         ("kernel_error_gain_free", "gain-free error"),
                                         ("peak_frequency_cpp", "peak (cycles/pixel)"), ("response_kind", "response")],
                                 left=("name", "response_kind"))))
    csf_cols = [("name", "realisation")] + [(f"csf_{m}_correlation", _csf_name(m)) for m in methods]
    csf_cols += [("csf_fitted_correlation", "Mannos–Sakrison, fitted scale"), ("csf_fitted_ppd", "fitted px/degree")]
    out.append(_details("CSF agreement", "<p class='note'>Correlation of the peak-normalised radial response with "
                        "each CSF model at the design's optics geometry, and with Mannos–Sakrison at the best "
                        "pixels-per-degree scale (the verdict's r).</p>" + _table(named, csf_cols, left=("name",))))
    metrics = list(dict.fromkeys(c for r in ok for c in r if c.startswith("metric_")))
    if metrics:
        cols = [("name", "realisation")] + [(c, _metric_name(c)) for c in metrics]
        out.append(_details("Task metrics", "<p class='note'>Each task's primary metric (detection mAP, recognition "
                            "top-1, segmentation mIoU; fractions), mean over its networks, on each track.</p>"
                            + _table(named, cols, left=("name",))))
    if any("emu_event_ratio" in r for r in ok):
        out.append(_details("Emulation track", "<p class='note'>The realised kernel applied to the video, shown on an "
                            "emulated display and recaptured by the noisy simulator (the paper's sensor-in-the-loop "
                            "track), against the same kernel inside the pixel.</p>"
                            + _table(named, [("name", "realisation"),
                                             ("emu_event_ratio", "events, emulated / in-sensor"),
                                             ("emu_signed_correlation", "ON−OFF frame correlation")],
                                     left=("name",))))
    return "<h2 id='scores'>Scores by topic</h2>" + "".join(out)


def _csf_name(method: str) -> str:
    return figures._csf_title("CSF " + method)[4:]


def _metric_name(column: str) -> str:
    task, _, track = column[len("metric_"):].partition("/")
    primary = {"detection": "mAP", "recognition": "top-1", "segmentation": "mIoU"}.get(task, "metric")
    return f"{task} {primary} ({track})"


#: Wall-time columns of the score rows (seconds).
_WALL = ("fit_s", "analysis_s", "tasks_s", "emulation_s", "point_s")

#: Stored cost items also shown as score columns (listed once, there).
_SHOWN_AS_SCORES = {"kernel_error": "kernel error (Scores by topic)", "fit_time": "fit time (Speed for accuracy)"}


def _realisation_details(points: Sequence[ScoredPoint]) -> str:
    """Per scored point: every stored cost and design quantity with its unit (SI prefixes) and definition."""
    parts = []
    for p in points:
        if not p.ok or p.score is None:
            continue
        items = _quantities(p.realisation, p.score.cost)
        body = ""
        if items:
            body += _table(items, [("item", "quantity"), ("value", "value"), ("definition", "definition")],
                           left=("item", "value", "definition"))
        for w in p.score.warnings:
            body += f"<p class='bad'>warning: {html.escape(plain(w))}</p>"
        if not body:
            body = "<p class='note'>An ideal reference: no hardware quantities.</p>"
        parts.append(_details(point_title(p.realisation, p.params), body))
    if not parts:
        return ""
    return ("<h2 id='realisations'>Realisations</h2><p class='note'>Every quantity each fit stored, once, with its "
            f"definition ({'; '.join(_SHOWN_AS_SCORES.values())} are in the score tables). The fit's own text "
            "summary is kept in scores.json (<code>describe</code>).</p>" + "".join(parts))


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


def _typed(points: Sequence[Mapping[str, Any] | ScoredPoint]) -> list[ScoredPoint]:
    return [p if isinstance(p, ScoredPoint) else ScoredPoint.from_dict(p) for p in points]


def _float(v: Any) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def render_html(points: Sequence[Mapping[str, Any] | ScoredPoint], design: Any, *, title_text: str | None = None,
                stamp: str | None = None, sections: Sequence[str] = ()) -> str:
    """The report as one HTML string (figures embedded).

    Parameters
    ----------
    points : sequence of ScoredPoint or mappings
        Stored design points (:class:`fsdvs_hw.records.ScoredPoint`, or the dicts of
        :meth:`fsdvs_hw.explore.store.ResultsStore.rows`), with ``paired_loss`` where task losses
        were computed.
    design : fsdvs_hw.explore.design.Design
        The design they came from (sensor, optics and CSF settings are read from it).
    title_text : str, optional
        Page title (default: "FS-DVS design exploration: <design name>").
    stamp : str, optional
        Time stamp in the provenance (default: now, UTC).
    sections : sequence of str
        Further HTML fragments (each starting with its own ``<h2>``), placed after the buildable
        artifacts and before the run conditions, e.g. :func:`fsdvs_hw.report.codesign.codesign_section`.
    """
    points = _typed(points)
    data = design.to_dict()
    rows = with_cost_columns(score_rows(points), points)  # power_w, area_m2, ... (issue 25)
    ok = [r for r in rows if r["status"] == "ok"]
    acc, acc_label = accuracy_axis(rows)
    methods = data["analysis"]["csf_methods"]
    page_title = title_text or f"FS-DVS design exploration: {design.name}"
    t = design.target
    focal = data["optics"]["focal_length_m"]
    n_ok, n_skip, n_err = (sum(r["status"] == s for r in rows) for s in ("ok", "skipped", "error"))
    parts = [
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<meta name='viewport' content='width=device-width, initial-scale=1'><title>{html.escape(page_title)}</title>",
        f"<style>{_CSS}</style></head><body><h1>{html.escape(page_title)}</h1>",
    ]
    parts.append(
        f"<p class='lead'>Which hardware realises the learned kernel <b>{html.escape(t.name)}</b> "
        f"({t.size}×{t.size} taps at {si(t.pitch_m, 'm')} pixel pitch) best, for which cost: "
        f"{len(rows)} design points, {n_ok} scored, {n_skip} skipped, {n_err} failed.</p>")
    parts.append(_verdict_section(rows))
    missing = [r for r in rows if r["status"] != "ok"]
    if missing:
        parts.append("<h2 id='not-scored'>Not scored</h2><p class='note'>Points whose realisation is not installed, "
                     "or whose fit failed; nothing is filled in for them.</p>")
        named = [{**r, "name": point_title(r["realisation"], r.get("params"))} for r in missing]
        parts.append(_table(named, [("name", "realisation"), ("status", "status"), ("reason", "reason")],
                            left=("name", "status", "reason")))
    if ok:
        kinds = [title(k) for k in dict.fromkeys(r["realisation"] for r in ok)]
        hw = [title(k) for k in dict.fromkeys(r["realisation"] for r in ok if r.get("kind_cost"))]
        what = "accuracy loss" if acc.endswith("_loss") else "kernel error"
        bars = "with 95 % confidence bars " if acc.endswith("_loss") else ""
        parts.append("<h2 id='trade-off'>Trade-off</h2>" + _figure(
            figures.fig_pareto(rows),
            f"Scatter plots of {what} {bars}against CSF agreement for {_names(kinds)}, "
            f"and against each hardware kind's own cost{(' for ' + _names(hw)) if hw else ''}.",
            f"<b>{what.capitalize()} vs CSF agreement, and vs each kind's own cost.</b> "
            + (f"Bars: the stored 95 % bootstrap CIs of the {html.escape(acc_label)}. " if bars else
               "No task evaluator ran, so there are no losses and no CIs. ")
            + "Rings: on the Pareto front beyond the CIs (across kinds in the first panel, within the kind in the "
            "others). Hollow markers of different shapes, so coinciding "
            "points stay visible; one colour per realisation in every figure.", fig_id="fig-pareto"))
        parts.append(cost_section(rows, points, _figure))  # physical costs across kinds (issue 25)
        panels = figures.realised_kernels(points)
        pnames = _names([p.label for p in panels])
        parts.append("<h2 id='kernels'>Kernels</h2>" + _figure(
            figures.fig_kernels(panels),
            f"Heat maps of the realised kernel taps of {pnames}, red positive and blue negative, each on its own "
            "colour scale centred at zero.",
            "<b>Realised kernels, tap by tap.</b> Diverging colours centred at zero, each panel on its own scale "
            "with its own colour bar. Where the centre tap is more than twice the largest surround tap, the scale "
            "follows the surround (colour-bar arrows; the saturated centre is labelled with its value), so the "
            "surround's sign and shape are visible. Frame and title in the realisation's colour.",
            fig_id="fig-kernels"))
        parts.append(_figure(
            figures.fig_spectra(panels),
            f"Heat maps of the two-dimensional magnitude spectra of {pnames} on one shared colour scale.",
            "<b>Magnitude spectra |H(f<sub>x</sub>, f<sub>y</sub>)|</b> over the Nyquist square (cycles/pixel), all "
            "panels on one shared scale and colour bar, so brightness compares across realisations.",
            fig_id="fig-spectra"))
        parts.append(_figure(
            figures.fig_radial(panels, methods=methods, pitch_m=t.pitch_m, focal_length_m=focal),
            f"Line plots of the peak-normalised radial frequency responses of {pnames} against contrast "
            "sensitivity curves, at the design geometry and at a fitted viewing scale.",
            "<b>Radial responses vs contrast sensitivity.</b> Each curve normalised to its own maximum. Left: at the "
            f"design's geometry (pixel pitch {si(t.pitch_m, 'm')}, focal length {si(focal, 'm')}), against every "
            "CSF model of <code>[analysis] csf_methods</code>. Right: Mannos–Sakrison at the viewing scale fitted to "
            "the first kernel (a shape comparison, as in the FS-DVS paper). CSF curves in greys.",
            fig_id="fig-radial"))
        parts.append(_per_task_section(rows))
        parts.append(_matched_rate_section(points))
        parts.append(_score_tables(ok, methods))
        named = [{**r, "name": point_title(r["realisation"], r.get("params"))} for r in ok]
        hw_kinds = [title(k) for k in dict.fromkeys(r["realisation"] for r in ok if r.get("kind_cost"))]
        parts.append("<h2 id='speed'>Speed for accuracy</h2>" + _figure(
            figures.fig_speed(rows),
            "Log-log scatter plot of kernel error against fit wall time for "
            f"{_names(hw_kinds) if hw_kinds else 'no hardware realisation'}.",
            "<b>Kernel error vs fit wall time</b> of each hardware realisation on the machine that ran the point "
            "(log axes).", fig_id="fig-speed"))
        parts.append(_details("Wall times of every point", "<p class='note'>Seconds on the machine that ran each point "
                              "(fit: the realisation's optimiser; analysis: spectra and CSF; tasks: evaluators; "
                              "emulation: display and recapture track).</p>"
                              + _table([{**r, **{c: si(_float(r.get(c)), "s") for c in _WALL}} for r in named],
                                       [("name", "realisation"), ("fit_s", "fit"), ("analysis_s", "analysis"),
                                        ("tasks_s", "tasks"), ("emulation_s", "emulation"),
                                        ("point_s", "point total")], left=("name",))))
        parts.append(_realisation_details(points))
    parts.append(artifacts_html(points))  # buildable files per hardware point (report/artifacts.py)
    parts.extend(sections)
    parts.append(_conditions(points, rows, data, design))
    stamp = stamp or _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    parts.append(f"<h2 id='provenance'>Provenance</h2><p class='note'>fsdvs_hw {__version__}, Python "
                 f"{platform.python_version()}, {html.escape(platform.node())}, {stamp}; design source "
                 f"{html.escape(design.source)}.</p>" + _versions_note(points))
    parts.append(_details("The design, as run (JSON)", f"<pre>{html.escape(json.dumps(data, indent=1))}</pre>"))
    parts.append("</body></html>")
    return "\n".join(p for p in parts if p)


def _versions_note(points: Sequence[ScoredPoint]) -> str:
    """The numerical library versions the points were computed with (one line per distinct set)."""
    sets = {tuple(sorted((k, str(v)) for k, v in p.score.versions.items()))
            for p in points if p.score is not None and p.score.versions}
    if not sets:
        return "<p class='note'>Library versions: not recorded with these points (made before they were kept).</p>"
    lines = [", ".join(f"{k} {v}" for k, v in s) for s in sorted(sets)]
    head = "Computed with" if len(lines) == 1 else f"Computed with {len(lines)} different environments:"
    return "".join(f"<p class='note'>{head if i == 0 else ''} {html.escape(line)}.</p>" for i, line in enumerate(lines))


def _conditions(points: Sequence[ScoredPoint], rows: Sequence[Mapping[str, Any]], data: Mapping[str, Any],
                design: Any) -> str:
    """Run conditions: sensor, simulator of the task tracks, networks, task status."""
    t = design.target
    items = [f"Target kernel {html.escape(t.name)}: {t.size}×{t.size} taps, pixel pitch {si(t.pitch_m, 'm')}, "
             f"DC gain {number(t.dc_gain)}; optics focal length {si(data['optics']['focal_length_m'], 'm')}; filter "
             f"placement {html.escape(str(data['sensor']['placement']))}, positivity "
             f"{html.escape(str(data['sensor']['positivity']))}."]
    sensors = set()
    for p in points:
        for task, tracks in (p.score.tasks.tracks.items() if p.score is not None else ()):
            for track in tracks.values():
                sensor = track.extra.get("sensor")
                if isinstance(sensor, Mapping):
                    sensors.add(f"{task}: " + ", ".join(f"{k} = {v}" for k, v in sensor.items()))
    if sensors:
        items.append("Task-track simulator: " + html.escape("; ".join(sorted(sensors))) + ".")
    nets = networks_note(points)
    if nets:
        items.append("Networks each task's loss is measured in (every realisation is swapped zero-shot into these; "
                     "the loss compares it with the learned kernel in the same networks): " + html.escape(nets) + ".")
    ok = [r for r in rows if r["status"] == "ok"]
    task_status = sorted({r.get("tasks_status", "") for r in ok} - {""})
    if task_status:
        items.append(f"Task evaluation: {html.escape('; '.join(task_status))}.")
    return "<h2 id='conditions'>Run conditions</h2>" + _details(
        "Sensor, simulator and networks", "".join(f"<p class='note'>{i}</p>" for i in items))


def write_report(points: Sequence[Mapping[str, Any] | ScoredPoint], design: Any, out_dir: str | Path) -> Path:
    """Write ``report.html``, ``scores.csv`` and ``scores.json`` into ``out_dir``; return the HTML path."""
    from ..errors import InputError

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name in ("report.html", "scores.csv", "scores.json"):  # refused before any file is replaced
        if (out / name).is_symlink():
            raise InputError(f"--out: {out / name} is a symbolic link; refusing to write through it (remove the link)")
    points = _typed(points)
    write_scores(with_cost_columns(score_rows(points), points), out, full=[p.to_dict() for p in points], design=design_stamp(design))
    path = out / "report.html"
    sections = []
    if (out / "codesign.json").is_file() and design.spec.codesign.enabled:  # issue 16 rows
        from .codesign import codesign_section

        sections.append(codesign_section(json.loads((out / "codesign.json").read_text())))
    # atomically, never through a symbolic link planted in the folder
    return write_output(path, render_html(points, design, sections=sections))


def design_stamp(design: Any) -> dict[str, Any]:
    """What ``scores.json`` records of the design its points came from: name, fingerprint
    (:meth:`fsdvs_hw.explore.design.Design.fingerprint`: SHA-1 of the validated content and target
    taps) and the validated data, so that :func:`write_report_from_scores` can refuse another design."""
    return {"name": design.name, "fingerprint": design.fingerprint(), "data": design.to_dict()}


def _flat(data: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(data, Mapping) and data:
        out: dict[str, Any] = {}
        for k, v in data.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: data}


def check_same_design(src: Path, stored: Any, points: Sequence[ScoredPoint], design: Any) -> None:
    """Refuse to redraw the points of ``src`` (a ``scores.json``) with a design other than theirs.

    Compares the stored fingerprint (:func:`design_stamp`) with ``design``'s; a ``scores.json``
    written before fingerprints were kept is checked by the design name its points carry.

    Raises
    ------
    InputError
        Naming both designs (source, name, fingerprint) and the first keys that differ.
    """
    from ..errors import InputError

    given = f"{design.source} (design {design.name!r}"
    if isinstance(stored, Mapping) and isinstance(stored.get("fingerprint"), str):
        if stored["fingerprint"] == design.fingerprint():
            return
        run_flat = _flat(stored.get("data") or {})
        now_flat = _flat(design.to_dict())
        diff = [
            k for k in dict.fromkeys([*run_flat, *now_flat]) if run_flat.get(k, "<unset>") != now_flat.get(k, "<unset>")
        ]
        shown = "; ".join(f"{k}: run {json.dumps(run_flat.get(k, '<unset>'), default=str)[:40]}, given "
                          f"{json.dumps(now_flat.get(k, '<unset>'), default=str)[:40]}" for k in diff[:3])
        more = f" and {len(diff) - 3} more" if len(diff) > 3 else ""
        raise InputError(f"{given}, fingerprint {design.fingerprint()[:12]}) does not match the design of the run "
                         f"in {src} (design {str(stored.get('name'))[:60]!r}, fingerprint "
                         f"{stored['fingerprint'][:12]}); differs in {shown or 'the target kernel'}{more}; pass "
                         "the design file (and --set options) the run used")
    names = {str(p.extra.get("design")) for p in points if p.extra.get("design") is not None}
    if names and names != {design.name}:
        raise InputError(f"{given}) does not match the design of the run in {src} (its points are of design "
                         f"{', '.join(repr(n[:60]) for n in sorted(names)[:3])}); pass the design file the run used")


def write_report_from_scores(out_dir: str | Path, design: Any, *, to: str | Path | None = None) -> Path:
    """Rebuild ``report.html`` from the ``scores.json`` an earlier run wrote, without rerunning anything.

    ``scores.json`` keeps every stored point with its paired task losses (``"points"``), so the
    report of ``fsdvs-hw explore`` (or ``sweep --report``) can be redrawn after a change to the
    report code, or into another folder.

    Parameters
    ----------
    out_dir : path
        Folder of the earlier run (holds ``scores.json``).
    design : Design
        The design the run used (:func:`fsdvs_hw.explore.design.load_design` of its TOML file;
        the report layer sits below explore and does not load designs itself).
    to : path, optional
        Folder to write ``report.html``, ``scores.csv`` and ``scores.json`` into (default:
        ``out_dir`` itself, replacing the report there).

    Returns
    -------
    Path
        The written ``report.html``.

    Raises
    ------
    InputError
        ``out_dir`` is not a folder; ``out_dir/scores.json`` is missing, is not JSON, or holds no
        ``"points"`` list of stored points; ``design`` is not a loaded design, or not the design
        the run used (:func:`check_same_design`); a file to write is a symbolic link.

    Examples
    --------
    >>> from fsdvs_hw.explore.design import load_design
    >>> write_report_from_scores("out/demo", load_design("designs/default.toml"))  # doctest: +SKIP
    PosixPath('out/demo/report.html')
    """
    from ..errors import InputError

    if not Path(out_dir).is_dir():
        raise InputError(f"{out_dir}: not a folder (the --out folder of an earlier explore or sweep run)")
    src = Path(out_dir) / "scores.json"
    if src.is_symlink():  # it would be read from, and the report rewrites it, elsewhere
        raise InputError(f"--out: {src} is a symbolic link; refusing to read or write through it (remove the link)")
    try:
        data = json.loads(src.read_text())
    except FileNotFoundError:
        raise InputError(
            f"{src}: no scores.json here (write one with `fsdvs-hw explore DESIGN --out {out_dir}`)"
        ) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{src}: not a scores file (not JSON: {exc})") from None
    points = data.get("points") if isinstance(data, Mapping) else None
    if not isinstance(points, list):
        raise InputError(f"{src}: field 'points' must be the list of stored points that write_report saves")
    points = [ScoredPoint.from_dict(p, where=f"{src}: points[{i}]") for i, p in enumerate(points)]
    if isinstance(design, (str, Path)) or not callable(getattr(design, "to_dict", None)):
        raise InputError(f"write_report_from_scores: design must be a loaded design "
                         f"(fsdvs_hw.explore.design.load_design(path)), got {type(design).__name__}")
    check_same_design(src, data.get("design"), points, design)
    dest = Path(to) if to is not None else Path(out_dir)
    extra = Path(out_dir) / "codesign.json"  # the co-design rows write_report reads beside the report
    if extra.is_file() and dest.resolve() != Path(out_dir).resolve():
        dest.mkdir(parents=True, exist_ok=True)
        write_output(dest / extra.name, extra.read_bytes(), flag="--to")
    return write_report(points, design, dest)
