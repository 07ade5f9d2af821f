"""The report's "Built in a real process" section: the mesh in a PDK's transistors, corner by corner.

For every scored ``mesh_process`` point (:mod:`fsdvs_hw.realise.mesh.process_mesh`): a table of the
conditions it was simulated at (corner × temperature: kernel error against the target, distance
from the ideal mesh's kernel, space constants, settling time), the Monte Carlo mismatch (kernel
error against the nominal kernel and against the target: mean and 95 % interval, n), the accuracy
loss of the scored condition (the worst corner by default) beside the ideal ``mesh`` point's, and
the designer's question: does it fit the pixel, and if not the smallest pitch and the sharing that
fits, with the kernel error sharing costs. For every ``asic`` point built in the process
(:mod:`fsdvs_hw.realise.asic.sky130_flow`): the mapped cells, area, OpenSTA's critical path and
highest clock, the toggle energy per pixel with its interval and the gate-level check. Every figure
names its source (PDK, condition, tool version, samples).

Examples
--------
>>> process_section([], [])
''
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from markupsafe import Markup, escape

from ..records import ScoredPoint

__all__ = ["process_section"]


def _f(v: Any, digits: int = 3) -> str:
    return "–" if not isinstance(v, (int, float)) else f"{v:.{digits}g}"


def _loss(row: Mapping[str, Any] | None) -> str:
    if not row:
        return "not scored"
    for key in ("weighted_loss", "detection_loss", "recognition_loss", "segmentation_loss"):
        if isinstance(row.get(key), (int, float)):
            lo, hi = row.get(f"{key}_ci95_low"), row.get(f"{key}_ci95_high")
            return f"{key.replace('_', ' ')} {_f(row[key])} [95 % CI {_f(lo)}, {_f(hi)}]"
    return "no task loss measured"


def _conditions_table(rec: Mapping[str, Any]) -> str:
    head = (
        "<tr><th>condition</th><th>kernel error vs target</th><th>vs ideal mesh kernel</th>"
        "<th>λ narrow / wide (px)</th><th>τ wide</th></tr>"
    )
    body = []
    for c in rec.get("conditions", []):
        scored = f"{c['corner']} {c['temperature_c']:g} °C" == rec.get("scored_label")
        body.append(
            f"<tr><td>{escape(rec.get('pdk', ''))} {escape(c['corner'])} {c['temperature_c']:g} °C{' (scored)' if scored else ''}</td>"
            f"<td>{_f(c['kernel_error'])}</td><td>{_f(c['error_vs_ideal'])}</td>"
            f"<td>{_f(c['lambda_narrow_px'])} / {_f(c['lambda_wide_px'])}</td><td>{_f(c['tau_wide_s'] * 1e6)} µs</td></tr>"
        )
    return f"<table>{head}{''.join(body)}</table>"


def _point_html(
    p: ScoredPoint, rec: Mapping[str, Any], own: Mapping[str, Any] | None, ideal: Mapping[str, Any] | None
) -> str:
    tool, pdk = escape(rec.get("tool", "ngspice")), escape(rec.get("pdk", ""))
    parts = [
        f"<h3>mesh, {pdk} {escape(rec.get('scored_label', ''))} (scored) — {escape(tool)}</h3>",
        _conditions_table(rec),
    ]
    parts.append(
        f"<p>Accuracy loss of <b>mesh, {pdk} {escape(rec.get('scored_label', ''))}</b>: {escape(_loss(own))}; "
        f"of the ideal mesh: {escape(_loss(ideal))}.</p>"
    )
    mm = rec.get("mismatch")
    if mm:
        n, (m0, l0, h0), (m1, l1, h1) = mm["samples"], mm["ci"]["error_vs_nominal"], mm["ci"]["error_vs_target"]
        parts.append(
            f"<p>Mismatch ({pdk} {escape(mm['corner'])}_mm {mm['temperature_c']:g} °C, {n} samples, ngspice seed {mm['seed']}): "
            f"kernel error against the nominal kernel {_f(m0)} [95 % CI {_f(l0)}, {_f(h0)}], against the target "
            f"{_f(m1)} [{_f(l1)}, {_f(h1)}]; device spread σ(ln g) {', '.join(f'{k} {_f(v, 2)}' for k, v in mm['sigma_ln_g'].items())}.</p>"
        )
    a = rec.get("area") or {}
    if a:
        fits = "fits" if a.get("fits_pixel") else "does <b>not</b> fit"
        parts.append(
            f"<p>Area per pixel {_f(a['total_m2'] * 1e12)} µm² (six transistors {_f(a['devices_m2'] * 1e12)} µm², two MIM "
            f"capacitors {_f(a['capacitor_m2'] * 1e12)} µm², above the devices): the mesh {fits} the {_f(a['pitch_m'] * 1e6)} µm "
            f"pixel. Smallest pitch that fits: {_f(a['min_pitch_m'] * 1e6)} µm. One mesh node per {a['sharing_k']}×{a['sharing_k']} "
            f"pixels fits this pitch; its kernel error against the target (window, gain fitted) is "
            f"{_f(a.get('sharing_kernel_error'))}, against {_f(a.get('unshared_kernel_error'))} unshared.</p>"
        )
    return "".join(parts)


def _taps_html(p: ScoredPoint, proc: Mapping[str, Any]) -> str:
    """The ASIC taps point built in the process: cells, area, clock, energy, each with its source."""
    src = proc.get("sources", {})
    lo, hi = proc.get("energy_per_pixel_interval_j") or (None, None)
    rows = [
        (
            "cells (flip-flops, full adders, fanout buffers)",
            f"{proc['cells']} ({proc['flip_flops']}, {proc['full_adders']}, {proc.get('fanout_buffers', 0)})",
            src.get("area_m2", ""),
        ),
        ("cell area", f"{_f(proc['area_m2'] * 1e12, 4)} µm²", src.get("area_m2", "")),
        (
            "critical path / highest clock",
            f"{_f(proc['critical_path_s'] * 1e9)} ns / {_f(proc['max_clock_hz'] / 1e6)} MHz",
            src.get("max_clock_hz", ""),
        ),
        (
            "highest clock per corner",
            ", ".join(f"{c} {_f(t['max_clock_hz'] / 1e6)} MHz" for c, t in (proc.get("corner_timing") or {}).items()),
            "OpenSTA at each corner's lctime liberty (25 °C, 1.8 V)",
        ),
        (
            "energy per pixel",
            f"{_f(proc['energy_per_pixel_j'] * 1e12)} pJ [95 % interval {_f(lo and lo * 1e12)}, {_f(hi and hi * 1e12)}]",
            src.get("energy_per_pixel_j", ""),
        ),
        ("gate-level check", f"{proc['outputs_checked']} outputs bit-exact", src.get("gate_level_bit_exact", "")),
    ]
    body = "".join(
        f"<tr><td>{escape(a)}</td><td>{escape(b)}</td><td class='note'>{escape(c)}</td></tr>" for a, b, c in rows
    )
    h, w = proc.get("frame", ["?", "?"])
    label = p.score.label if p.score is not None else p.realisation
    return (
        f"<h3>{escape(label)}: taps in {escape(proc.get('pdk', ''))} standard cells ({h}×{w} frame, "
        f"{escape(proc.get('corner', ''))} {_f(proc.get('temperature_c'))} °C)</h3>"
        f"<table><tr><th>figure</th><th>value</th><th>source</th></tr>{body}</table>"
    )


def process_section(points: Sequence[ScoredPoint], rows: Sequence[Mapping[str, Any]]) -> Markup | str:
    """HTML of the section (module docstring); ``""`` when no point was built in a process."""
    procs = [p for p in points if p.ok and p.score is not None and p.realisation == "mesh_process"]
    taps = [
        (p, p.score.realisation["process"])
        for p in points
        if p.ok and p.score is not None and p.realisation == "asic" and (p.score.realisation or {}).get("process")
    ]
    if not procs and not taps:
        return ""
    by_key = {r.get("key"): r for r in rows}
    ideal = next((r for r in rows if r.get("realisation") == "mesh" and r.get("status") == "ok"), None)
    html = [
        "<h2 id='process'>Built in a real process</h2><p class='note'>The dual mesh as the PDK's subthreshold "
        "transistors (fsdvs_hw.process): gate biases fitted at the nominal condition and held, the kernel at every "
        "corner × temperature and under Monte Carlo mismatch; the scored condition's kernel went through the simulator "
        "and the task networks like any realisation. The ASIC taps as the PDK's standard cells: synthesised, "
        "checked bit-exactly at gate level, timed and costed from their toggles (their kernel is the "
        "idealised taps' own: only the costs change).</p>"
    ]
    for p in procs:
        rec = p.score.realisation if p.score is not None else {}
        html.append(_point_html(p, rec or {}, by_key.get(p.key), ideal))
    html += [_taps_html(p, proc) for p, proc in taps]
    return Markup("".join(html))
