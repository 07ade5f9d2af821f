"""The self-contained HTML report of an exploration (figures embedded as base64 PNG).

One file, no external assets: it opens from a mail attachment or a CI artefact. Alongside it
``scores.csv`` and ``scores.json`` hold the same numbers for further analysis.
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
from . import figures
from .tables import accuracy_axis, networks_note, score_rows, verdict_rows, write_scores

__all__ = ["write_report", "render_html"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;margin:2em auto;max-width:1250px;color:#222;padding:0 1em}
h1{font-size:1.6em}h2{font-size:1.25em;border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;font-size:.82em;margin:.6em 0}td,th{border:1px solid #ddd;padding:3px 7px;text-align:right}
th{background:#f3f3f3}td.l,th.l{text-align:left}tr.pareto td{background:#eef7ee}
img{max-width:100%;border:1px solid #eee;margin:.4em 0}pre{background:#f7f7f7;padding:.6em;font-size:.8em;overflow:auto}
.note{color:#555;font-size:.9em}.bad{color:#a00}
"""


def _png(fig: Any) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else ""
    if isinstance(v, float):
        if math.isnan(v):
            return "–"
        return f"{v:.4g}"
    return html.escape(str(v))


def _table(rows: Sequence[Mapping[str, Any]], columns: Sequence[tuple[str, str]], *, left: Sequence[str] = ("point",)) -> str:
    head = "".join(f'<th class="{"l" if c in left else ""}">{html.escape(t)}</th>' for c, t in columns)
    body = []
    for r in rows:
        cls = ' class="pareto"' if r.get("pareto") else ""
        cells = "".join(f'<td class="{"l" if c in left else ""}">{_fmt(r.get(c, ""))}</td>' for c, _ in columns)
        body.append(f"<tr{cls}>{cells}</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def _img(b64: str, alt: str) -> str:
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'


def render_html(points: Sequence[Mapping[str, Any]], design: Any, *, title: str | None = None) -> str:
    """The report as one HTML string (figures embedded).

    Parameters
    ----------
    points : sequence of mappings
        Stored design points (:meth:`fsdvs_hw.explore.store.ResultsStore.rows`).
    design : fsdvs_hw.explore.design.Design
        The design they came from (sensor, optics and CSF settings are read from it).
    """
    data = design.to_dict()
    rows = score_rows(points)
    ok = [r for r in rows if r["status"] == "ok"]
    acc, acc_label = accuracy_axis(rows)
    methods = data["analysis"]["csf_methods"]
    title = title or f"FS-DVS design exploration: {design.name}"
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
             f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>"]
    t = design.target
    parts.append(
        f"<p>Target kernel <b>{html.escape(t.name)}</b> ({t.size}×{t.size}, pitch {t.pitch_m * 1e6:.3g} µm, "
        f"DC gain {t.dc_gain:.4g}); optics focal length {data['optics']['focal_length_m'] * 1e3:.3g} mm; "
        f"filter placement <b>{data['sensor']['placement']}</b>, positivity <b>{data['sensor']['positivity']}</b>. "
        f"{len(rows)} design points: {sum(r['status'] == 'ok' for r in rows)} scored, "
        f"{sum(r['status'] == 'skipped' for r in rows)} skipped, {sum(r['status'] == 'error' for r in rows)} failed.</p>")
    missing = [r for r in rows if r["status"] != "ok"]
    if missing:
        parts.append("<h2>Not scored</h2><p class='note'>Points whose realisation is not installed, or whose fit "
                     "failed; nothing is filled in for them.</p>")
        parts.append(_table(missing, [("point", "point"), ("status", "status"), ("reason", "reason")],
                            left=("point", "status", "reason")))
    sensors = set()
    for p in points:
        for task, tracks in ((p.get("result") or {}).get("tasks") or {}).items():
            for res in (tracks.values() if isinstance(tracks, Mapping) else []):
                if isinstance(res, Mapping) and isinstance(res.get("sensor"), Mapping):
                    sensors.add(f"{task}: " + ", ".join(f"{k}={v}" for k, v in res["sensor"].items()))
    if sensors:
        parts.append("<p class='note'>Task-track simulator: " + html.escape("; ".join(sorted(sensors))) + ".</p>")
    nets = networks_note(points)
    if nets:
        parts.append("<p class='note'>Networks each task's loss is measured in (every realisation is swapped "
                     "zero-shot into these; the loss compares it with the learned kernel in the same networks): "
                     + html.escape(nets) + ".</p>")
    task_status = sorted({r.get("tasks_status", "") for r in ok} - {""})
    if task_status:
        parts.append(f"<p class='note'>Task evaluation: {html.escape('; '.join(task_status))}. "
                     f"Accuracy axis: {html.escape(acc_label)}.</p>")

    verdict = verdict_rows(rows)
    if verdict:
        vcols = list(dict.fromkeys(k for v in verdict for k in v))
        flags = {v["realisation"]: r for v, r in zip(verdict, ok)}  # verdict_rows keeps the order of ok rows
        parts.append(
            "<h2>Verdict</h2><p class='note'>Loss = task metric of the learned kernel (the kernel being realised) "
            "minus that of the realisation, in the same networks on the same test clips and noise draws (mAP, "
            "top-1, mIoU as fractions; positive = accuracy lost), with its 95% bootstrap CI over test clips and "
            "training seeds (each seed with its own mismatch pattern); a CI that contains 0 reads "
            "'no measurable loss (± half-width)' and is never ranked by its point estimate. Weighted loss: "
            "<code>[scoring] task_weights</code>. Each task's loss is measured in the networks listed in "
            "<code>[tasks] checkpoints</code>. CSF agreement: Mannos–Sakrison correlation at the fitted viewing "
            "scale (headline) and at the design's optics geometry. Cost: each kind on its own axis and unit. "
            "Pareto: not dominated beyond the loss CIs, within the kind (loss, agreement, cost) and across kinds "
            "(loss, agreement); green rows are on their kind's front.</p>")
        head = "".join(f'<th class="l">{html.escape(c)}</th>' for c in vcols)
        trs = []
        for v in verdict:
            cls = ' class="pareto"' if flags[v["realisation"]].get("pareto") else ""
            cells = "".join(f'<td class="l">{html.escape(v.get(c, "–"))}</td>' for c in vcols)
            trs.append(f"<tr{cls}>{cells}</tr>")
        parts.append(f"<table><tr>{head}</tr>{''.join(trs)}</table>")

    parts.append("<h2>Scores</h2><p class='note'>Kernel error: relative L2 against the target (gain-free: with "
                 "the least-squares gain, which a comparator threshold absorbs). CSF: correlation of the "
                 "peak-normalised radial response with each CSF at the design geometry; 'fitted' uses the best "
                 "pixels-per-degree scale. Metrics: each task's primary metric on each track (mean over networks). "
                 "Emulation: the realised kernel applied to the video, shown on "
                 "an emulated display and recaptured by the noisy simulator (the paper's sensor-in-the-loop track), "
                 "against the same kernel inside the pixel: event-count ratio and correlation of ON−OFF frames.</p>")
    cols = [("point", "point"), ("kernel_error", "kernel error"), ("kernel_error_gain_free", "gain-free error"),
            ("peak_frequency_cpp", "peak (cyc/px)"), ("response_kind", "response")]
    cols += [(f"csf_{m}_correlation", f"r {m.split('_')[0]}") for m in methods]
    cols += [("csf_fitted_correlation", "r MS fitted")]
    cols += [(k, k.replace("_", " ", 1)) for k in dict.fromkeys(c for r in ok for c in r if c.startswith("metric_"))]
    cols += [("emu_event_ratio", "emul. events / in-sensor"), ("emu_signed_correlation", "emul. r")]
    cols += [("headline_cost", "cost item"), ("headline_cost_value", "value"), ("headline_cost_unit", "unit")]
    parts.append(_table(ok, cols, left=("point", "response_kind", "headline_cost", "headline_cost_unit")))

    if ok:
        kernels = figures.realised_kernels(points)
        parts.append("<h2>Kernels side by side</h2>" + _img(_png(figures.fig_kernels(kernels)), "kernels"))
        parts.append("<h2>Magnitude spectra</h2>" + _img(_png(figures.fig_spectra(kernels)), "spectra"))
        parts.append("<h2>Radial responses vs Mannos–Sakrison</h2>"
                     + _img(_png(figures.fig_radial(kernels, methods=methods, pitch_m=t.pitch_m,
                                                    focal_length_m=data["optics"]["focal_length_m"])), "radial"))
        parts.append("<h2>Pareto: accuracy loss (95% CI) vs CSF agreement, and vs each kind's own cost</h2>" + _img(_png(figures.fig_pareto(rows)), "pareto"))
        parts.append("<h2>Speed for accuracy</h2><p class='note'>Wall times on the machine that ran each point "
                     "(fit: the realisation's optimiser; analysis: spectra and CSF; tasks: evaluators; emulation: "
                     "display and recapture track).</p>")
        parts.append(_table(ok, [("point", "point"), ("kernel_error", "kernel error"), ("csf_agreement", "r MS"),
                                 (acc, acc_label.split(" (")[0]), ("fit_s", "fit (s)"), ("analysis_s", "analysis (s)"),
                                 ("tasks_s", "tasks (s)"), ("emulation_s", "emulation (s)"),
                                 ("point_s", "point total (s)")]))
        parts.append(_img(_png(figures.fig_speed(rows)), "speed"))
        parts.append("<h2>Realisations</h2>")
        for p in points:
            if p["status"] == "ok":
                text = p["result"].get("describe", "")
                for w in p["result"].get("warnings", []):
                    text += f"\n  warning: {w}"
                parts.append(f"<pre>{html.escape(text)}</pre>")
                cost = p["result"].get("cost") or {}
                if cost:
                    parts.append(_table([{"point": k, "value": v["value"], "unit": v["unit"], "description": v["description"]}
                                         for k, v in cost.items()],
                                        [("point", "cost"), ("value", "value"), ("unit", "unit"), ("description", "description")],
                                        left=("point", "unit", "description")))
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    parts.append(f"<h2>Provenance</h2><p class='note'>fsdvs_hw {__version__}, Python {platform.python_version()}, "
                 f"{html.escape(platform.node())}, {stamp}; design source {html.escape(design.source)}.</p>")
    parts.append(f"<pre>{html.escape(json.dumps(data, indent=1))}</pre></body></html>")
    return "\n".join(parts)


def write_report(points: Sequence[Mapping[str, Any]], design: Any, out_dir: str | Path) -> Path:
    """Write ``report.html``, ``scores.csv`` and ``scores.json`` into ``out_dir``; return the HTML path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    points = list(points)
    write_scores(score_rows(points), out, full=points)
    path = out / "report.html"
    text = render_html(points, design)
    if (out / "codesign.json").is_file() and design.data.get("codesign", {}).get("enabled"):  # issue 16 rows
        from .codesign import codesign_section
        text = text.replace("<h2>Provenance</h2>", codesign_section(json.loads((out / "codesign.json").read_text()))
                            + "\n<h2>Provenance</h2>", 1)
    path.write_text(text)
    return path
