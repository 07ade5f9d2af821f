"""Report figures: kernels side by side, spectra, radial responses vs CSF, Pareto and speed plots.

Each function takes the scored design points (:class:`fsdvs_hw.records.ScoredPoint`) or the flat rows of
:func:`fsdvs_hw.report.tables.score_rows`, and returns a matplotlib ``Figure``; nothing is shown.

Every realisation keeps one colour and one marker across all figures
(:func:`fsdvs_hw.report.present.style`, from its registry entry); markers are drawn hollow so
points that coincide (the learned kernel and 8-bit ASIC taps often do) stay visible. Kernel
panels use a diverging map centred at zero with their own scale and colour bar; spectra share
one scale and one colour bar.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..kernels import Kernel
from ..records import ScoredPoint
from .present import number, params_text, point_title, si, style
from .tables import accuracy_axis, is_reference, loss_interval

__all__ = [
    "Panel",
    "fig_cost_fronts",
    "fig_kernels",
    "fig_matched_rate",
    "fig_pareto",
    "fig_radial",
    "fig_spectra",
    "fig_speed",
    "kernel_colour_limit",
    "realised_kernels",
]

_MAX_PANELS = 12
#: Kernel panels: the colour scale is set by the largest tap outside the centre when the centre
#: tap exceeds it by more than this factor (else the surround would be near-white).
_CENTRE_DOMINANCE = 2.0


@dataclass(frozen=True)
class Panel:
    """One realised kernel to draw: its people's label, realisation name (for its style) and taps."""

    label: str
    realisation: str
    kernel: Kernel


def realised_kernels(points: Sequence[ScoredPoint], *, limit: int = _MAX_PANELS) -> list[Panel]:
    """One :class:`Panel` per distinct successful point's realised kernel, at most ``limit`` (evenly picked)."""
    ok: list[ScoredPoint] = []
    seen = set()
    for p in points:  # one panel per distinct kernel (axes such as the optics do not change it)
        if p.ok and p.score is not None:
            taps = np.round(np.asarray(p.score.kernel.taps, dtype=float), 12)
            sig = (p.realisation, taps.shape, taps.tobytes())
            if sig not in seen:
                seen.add(sig)
                ok.append(p)
    if len(ok) > limit:
        idx = np.unique(np.linspace(0, len(ok) - 1, limit).round().astype(int))
        ok = [ok[i] for i in idx]
    return [Panel(point_title(p.realisation, p.params), p.realisation, p.score.kernel) for p in ok if p.score]


def kernel_colour_limit(taps: np.ndarray) -> tuple[float, bool]:
    """``(vmax, centre_clipped)``: the half-range of a kernel panel's zero-centred colour scale.

    The largest |tap| outside the centre when the centre tap exceeds it by more than
    :data:`_CENTRE_DOMINANCE` (the centre then saturates and is labelled with its value, and the
    surround's sign and shape stay readable), else the largest |tap|. 1 for an all-zero kernel.
    """
    t = np.abs(np.asarray(taps, dtype=float))
    full = float(t.max()) if t.size else 0.0
    if full == 0.0:
        return 1.0, False
    c = tuple(s // 2 for s in t.shape)
    rest = t.copy()
    rest[c] = 0.0
    off = float(rest.max())
    if off > 0.0 and t[c] > _CENTRE_DOMINANCE * off:
        return off, True
    return full, False


def _grid(n: int, *, w: float = 3.0, h: float = 2.7, cols: int = 4) -> tuple[Any, np.ndarray]:
    import matplotlib.pyplot as plt

    cols = max(1, min(n, cols))
    rows = max(1, math.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(w * cols, h * rows), constrained_layout=True, squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes


def _frame(ax: Any, colour: str) -> None:
    for s in ax.spines.values():
        s.set_edgecolor(colour)
        s.set_linewidth(2.0)


def fig_kernels(panels: Sequence[Panel]) -> Any:
    """Taps of every kernel side by side: diverging map centred at 0, each panel its own scale and colour bar.

    Red is positive, blue negative. Where the centre tap dominates (:func:`kernel_colour_limit`)
    the scale follows the surround, the colour bar's ends are arrows, and the centre cell is
    written with its value; kernels up to 7×7 have every tap written.
    """
    fig, axes = _grid(len(panels))
    for ax, pan in zip(axes.ravel(), panels):
        t = pan.kernel.taps
        r = pan.kernel.radius
        vmax, clipped = kernel_colour_limit(t)
        im = ax.imshow(t, cmap="RdBu_r", vmin=-vmax, vmax=vmax, extent=(-r - 0.5, r + 0.5, r + 0.5, -r - 0.5))
        fig.colorbar(im, ax=ax, shrink=0.9, extend="both" if clipped else "neither", label="tap weight")
        for (y, x), v in np.ndenumerate(t):
            if pan.kernel.size <= 7 or (clipped and (y, x) == (r, r)):
                ax.text(
                    x - r,
                    y - r,
                    f"{v:.2f}",
                    ha="center",
                    va="center",
                    fontsize=5.5,
                    color="white" if abs(v) > 0.6 * vmax else "black",
                )
        _label_panel(ax, pan, "x (pixels)", "y (pixels)")
    return fig


def _label_panel(ax: Any, pan: Panel, xlabel: str, ylabel: str) -> None:
    """Axis labels, and the panel's title and frame in its realisation's colour."""
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel(ylabel, fontsize=8)
    ax.tick_params(labelsize=7)
    colour = style(pan.realisation).colour
    ax.set_title(pan.label, fontsize=9, color=colour)
    _frame(ax, colour)


def fig_spectra(panels: Sequence[Panel], *, n_fft: int = 64) -> Any:
    """Magnitude spectra |H(f_x, f_y)| side by side on ONE shared scale and colour bar."""
    from ..spectra import magnitude_spectrum

    fig, axes = _grid(len(panels), w=2.8)
    spectra = [magnitude_spectrum(p.kernel, n_fft) for p in panels]
    vmax = max((float(np.max(m)) for _, m in spectra), default=1.0) or 1.0
    im = None
    for ax, pan, (f, mag) in zip(axes.ravel(), panels, spectra):
        step = f[1] - f[0]
        im = ax.imshow(
            mag,
            cmap="magma",
            origin="lower",
            vmin=0.0,
            vmax=vmax,
            extent=(f[0] - step / 2, f[-1] + step / 2, f[0] - step / 2, f[-1] + step / 2),
        )
        _label_panel(ax, pan, "$f_x$ (cycles/pixel)", "$f_y$ (cycles/pixel)")
    if im is not None:
        fig.colorbar(im, ax=list(axes.ravel()[: len(panels)]), shrink=0.9, label="|H| (shared scale)")
    return fig


def fig_radial(panels: Sequence[Panel], *, methods: Sequence[str], pitch_m: float, focal_length_m: float) -> Any:
    """Peak-normalised radial responses vs the CSF models: at the design geometry and at the fitted scale."""
    import matplotlib.pyplot as plt

    from ..csf import Geometry
    from ..plots import plot_radial_vs_csf
    from .present import si

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), constrained_layout=True)
    ks = [p.kernel for p in panels]
    labels = [p.label for p in panels]
    plot_radial_vs_csf(ks, methods=list(methods), geometry=Geometry(pitch_m, focal_length_m), ax=axes[0], labels=labels)
    axes[0].set_title(f"design geometry (pitch {si(pitch_m, 'm')}, focal length {si(focal_length_m, 'm')})", fontsize=9)
    plot_radial_vs_csf(ks, methods=list(methods[:1]), geometry=None, ax=axes[1], labels=labels)
    axes[1].set_title("viewing scale fitted to the first kernel (shape comparison, as in the FS-DVS paper)", fontsize=9)
    dashes = ["--", ":", "-.", (0, (5, 1, 1, 1, 1, 1))]
    for ax in axes:  # restyle: one colour and marker per realisation, CSF curves in greys
        lines = ax.get_lines()
        for line, pan in zip(lines, panels):
            st = style(pan.realisation)
            line.set_color(st.colour)
            line.set_marker(st.marker)
            line.set_markevery(0.1)
            line.set_markersize(5)
            line.set_markerfacecolor("none")
        for i, line in enumerate(lines[len(panels) :]):
            line.set_color(str(0.15 + 0.15 * i))
            line.set_linestyle(dashes[i % len(dashes)])
            line.set_label(csf_title(line.get_label()))
        ax.legend(fontsize=7, loc="best")
    return fig


def csf_title(label: str) -> str:
    """``"CSF mannos_sakrison_1974"`` → ``"CSF Mannos–Sakrison 1974"``."""
    names = {"mannos": "Mannos–Sakrison", "barten": "Barten", "daly": "Daly", "watson": "Watson–Ahumada"}
    if not label.startswith("CSF "):
        return label
    method = label[4:]
    head = method.split("_")[0]
    year = method.rsplit("_", 1)[-1]
    return f"CSF {names.get(head, head)} {year if year.isdigit() else ''}".rstrip()


def _errorbar(
    ax: Any,
    kind: str,
    x: Sequence[float],
    y: Sequence[float],
    lo: Sequence[float],
    hi: Sequence[float],
    *,
    fmt: str = "",
    label: str | None = None,
) -> None:
    st = style(kind)
    ref = is_reference(kind)
    ax.errorbar(
        x,
        y,
        yerr=[np.subtract(y, lo), np.subtract(hi, y)],
        fmt=st.marker + fmt,
        ms=10 if ref else 7,
        mfc="none",
        mew=1.6,
        capsize=3,
        color=st.colour,
        label=label,
        zorder=3,
    )


def fig_pareto(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Accuracy loss (95 % CI bars) vs CSF agreement across kinds, then one panel per hardware kind
    with the loss against that kind's own cost in its own unit (never one shared cost axis).

    Rings mark the uncertainty-aware fronts (:func:`fsdvs_hw.report.tables.uncertain_pareto_front`):
    across kinds in the first panel, within the kind in the others.
    """
    acc, acc_label = accuracy_axis(rows)
    ok = [r for r in rows if r["status"] == "ok"]
    kinds = [
        k
        for k in dict.fromkeys(r["realisation"] for r in ok)
        if any(not math.isnan(_val(r, "kind_cost_value")) for r in ok if r["realisation"] == k)
    ]
    n = 1 + max(1, len(kinds))
    fig, axes = _grid(n, w=3.0 if n >= 4 else 4.0, h=3.2, cols=4)
    axes = axes.ravel()
    ax = axes[0]
    for kind in dict.fromkeys(r["realisation"] for r in ok):
        g = [r for r in ok if r["realisation"] == kind]
        x = [_val(r, "csf_fitted_correlation") for r in g]
        y, lo, hi = zip(*(loss_interval(r, acc) for r in g))
        _errorbar(ax, kind, x, y, lo, hi, label=style(kind).title)
        for xi, yi, r in zip(x, y, g):
            if r.get("pareto_all"):
                ax.scatter([xi], [yi], s=260, facecolors="none", edgecolors=style(kind).colour, lw=1.0, zorder=2)
            if len(g) > 1 and len(ok) <= 10:
                ax.annotate(
                    params_text(r.get("params")), (xi, yi), fontsize=6, xytext=(4, 4), textcoords="offset points"
                )
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("CSF agreement (Mannos–Sakrison r, fitted scale)", fontsize=8)
    ax.set_ylabel(_short(acc_label), fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("across kinds (rings: not dominated beyond the CIs)", fontsize=9)
    if not kinds:
        axes[1].text(
            0.5,
            0.5,
            "no hardware realisation with costs was scored",
            ha="center",
            va="center",
            transform=axes[1].transAxes,
        )
        axes[1].set_axis_off()
    for ax, kind in zip(axes[1:], kinds):
        g = sorted(
            (r for r in ok if r["realisation"] == kind and not math.isnan(_val(r, "kind_cost_value"))),
            key=lambda r: r["kind_cost_value"],
        )
        x = [r["kind_cost_value"] for r in g]
        y, lo, hi = zip(*(loss_interval(r, acc) for r in g))
        _errorbar(ax, kind, x, y, lo, hi, fmt="-")
        for xi, yi, r in zip(x, y, g):
            if r.get("pareto"):
                ax.scatter([xi], [yi], s=260, facecolors="none", edgecolors=style(kind).colour, lw=1.0)
            if len(g) <= 8 and len(g) > 1:
                ax.annotate(
                    params_text(r.get("params")), (xi, yi), fontsize=6, xytext=(4, 4), textcoords="offset points"
                )
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_xlabel(f"{g[0]['kind_cost']} ({g[0]['kind_cost_unit']})", fontsize=8)
        ax.set_ylabel(_short(acc_label), fontsize=8)
        ax.grid(alpha=0.3, which="both")
        ax.set_title(
            f"{style(kind).title}: {_short(acc_label).split(' (')[0]} vs its own cost",
            fontsize=9,
            color=style(kind).colour,
        )
    return fig


def _short(label: str) -> str:
    return label.split(" (")[0]


def _val(r: Mapping[str, Any], key: str) -> float:
    v = r.get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def fig_speed(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Speed for accuracy: kernel error against fit time for every hardware realisation point."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4), constrained_layout=True)
    ok = [r for r in rows if r["status"] == "ok" and not is_reference(r["realisation"])]
    for kind in dict.fromkeys(r["realisation"] for r in ok):
        g = [r for r in ok if r["realisation"] == kind]
        st = style(kind)
        ax.scatter(
            [max(r["fit_s"], 1e-6) for r in g],
            [max(r["kernel_error"], 1e-12) for r in g],
            s=60,
            marker=st.marker,
            facecolors="none",
            edgecolors=st.colour,
            linewidths=1.6,
            label=st.title,
        )
    if ok:
        from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):  # ticks at 1, 2, 5 × 10ⁿ as plain numbers, no e-notation
            axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
            axis.set_major_formatter(FuncFormatter(lambda v, _: number(v)))
            axis.set_minor_formatter(NullFormatter())
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no hardware realisation was fitted", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("fit wall time (s)")
    ax.set_ylabel("kernel error vs target (relative L2)")
    ax.grid(alpha=0.3, which="both")
    ax.set_title("speed for accuracy of the realisation fits", fontsize=9)
    return fig


def fig_matched_rate(points: Sequence[ScoredPoint]) -> Any:
    """Task metric against event rate, one panel per task: the reference rate curves and every point.

    The reference curves (``delta``: a plain DVS, ``learned``) are lines through their thresholds;
    each scored point is a marker at its own event rate. Error bars on both axes are the 95 %
    bootstrap CIs over (network, clips) clusters (:mod:`fsdvs_hw.explore.matched`); the event-rate
    axis is logarithmic (events/pixel/s).
    """
    recs = [(p, p.extra.get("matched_rate") or {}) for p in points if p.ok]
    tasks = list(dict.fromkeys(t for _, m in recs for t, e in m.items() if isinstance(e, Mapping)))
    fig, axes = _grid(max(1, len(tasks)), w=3.6, h=3.2, cols=3)
    axes = axes.ravel()
    for ax, task in zip(axes, tasks):
        metric_name = ""
        for p, m in recs:
            e = m.get(task)
            if not isinstance(e, Mapping):
                continue
            st = style(p.realisation)
            for row in [e["curve"]] if "curve" in e else []:
                r = sorted(row, key=lambda q: q["rate"])
                x, y = [q["rate"] for q in r], [q["metric"] for q in r]
                ax.errorbar(
                    x,
                    y,
                    xerr=[np.subtract(x, [q["rate_low"] for q in r]), np.subtract([q["rate_high"] for q in r], x)],
                    yerr=[np.subtract(y, [q["metric_low"] for q in r]), np.subtract([q["metric_high"] for q in r], y)],
                    fmt="-",
                    lw=1.2,
                    alpha=0.8,
                    color=st.colour,
                    capsize=2,
                    label=f"{st.title}: threshold swept",
                )
                for q in r:
                    ax.annotate(
                        f"{q['threshold']:g}",
                        (q["rate"], q["metric"]),
                        fontsize=6,
                        xytext=(3, -8),
                        textcoords="offset points",
                        color=st.colour,
                    )
            q = e.get("point")
            if isinstance(q, Mapping):
                metric_name = q.get("metric_name", metric_name)
                ax.errorbar(
                    [q["rate"]],
                    [q["metric"]],
                    xerr=[[q["rate"] - q["rate_low"]], [q["rate_high"] - q["rate"]]],
                    yerr=[[q["metric"] - q["metric_low"]], [q["metric_high"] - q["metric"]]],
                    fmt=st.marker,
                    ms=8,
                    mfc="none",
                    mew=1.6,
                    capsize=3,
                    color=st.colour,
                    zorder=3,
                    label=point_title(p.realisation, p.params),
                )
        ax.set_xscale("log")
        ax.set_xlabel("event rate (events/pixel/s)", fontsize=8)
        ax.set_ylabel(f"{task} {metric_name}".strip(), fontsize=8)
        ax.grid(alpha=0.3, which="both")
        ax.set_title(task, fontsize=9)
        ax.legend(fontsize=6)
    for ax in axes[len(tasks) :]:
        ax.set_axis_off()
    return fig


def fig_cost_fronts(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Accuracy loss (CI bars) against each cross-kind physical cost (:data:`fsdvs_hw.costs.CROSS_KIND_COSTS`).

    One panel per cost, every kind on the same axes (symmetric-log x, so a zero cost shows);
    rings mark ``front_<cost>`` (:func:`fsdvs_hw.report.costs.mark_cost_fronts`).
    """
    from ..costs import CROSS_KIND_COSTS

    acc, acc_label = accuracy_axis(rows)
    ok = [r for r in rows if r["status"] == "ok" and "power_w" in r]
    fig, axes = _grid(len(CROSS_KIND_COSTS), w=3.0, h=3.0, cols=4)  # whole pixels at 96 and 192 dpi
    for ax, (cost, (unit, words)) in zip(axes.ravel(), CROSS_KIND_COSTS.items()):
        vals = [_val(r, cost) for r in ok]
        positive = [v for v in vals if v > 0]
        for kind in dict.fromkeys(r["realisation"] for r in ok):
            g = [r for r in ok if r["realisation"] == kind and not math.isnan(_val(r, cost))]
            if not g:
                continue
            y, lo, hi = zip(*(loss_interval(r, acc) for r in g))
            _errorbar(ax, kind, [_val(r, cost) for r in g], y, lo, hi, label=style(kind).title)
            moves = len({_val(r, cost) for r in g}) > 1  # the cost changes with the costs.* setting
            for r, yi in zip(g, y):
                if r.get(f"front_{cost}"):
                    ax.scatter([_val(r, cost)], [yi], s=260, facecolors="none", edgecolors=style(kind).colour, lw=1.0)
                swept = [_number(k, v) for k, v in _params(r).items() if k.startswith("costs.")]
                if moves and swept and len(g) <= 8:
                    ax.annotate(
                        ", ".join(swept),
                        (_val(r, cost), yi),
                        fontsize=6,
                        xytext=(0, 12),
                        ha="center",
                        textcoords="offset points",
                        rotation=90,
                        va="bottom",
                    )
        if positive and len(positive) == len([v for v in vals if not math.isnan(v)]):
            ax.set_xscale("log")
        elif positive:
            ax.set_xscale("symlog", linthresh=min(positive) / 2)
        else:
            ax.text(0.5, 0.5, "not measured", ha="center", va="center", transform=ax.transAxes)
        ax.xaxis.set_minor_formatter("")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_xlabel(f"{words} ({unit.replace('^2', '²')})", fontsize=8)
        ax.set_ylabel(_short(acc_label), fontsize=8)
        ax.grid(alpha=0.3, which="both")
        ax.tick_params(labelsize=7)
    axes.ravel()[0].legend(fontsize=7)
    return fig


def _number(key: str, v: Any) -> str:
    """A swept ``costs.*`` value, with an SI prefix where the key names its unit (``45 nm``)."""
    unit = {"_m": "m", "_v": "V", "_hz": "Hz", "_s": "s"}
    suffix = next((u for s, u in unit.items() if key.endswith(s)), None)
    return si(v, suffix) if suffix and isinstance(v, (int, float)) else number(v) if isinstance(v, float) else str(v)


def _params(r: Mapping[str, Any]) -> dict[str, Any]:
    p = r.get("params") or {}
    return json.loads(p) if isinstance(p, str) and p.strip() else dict(p) if isinstance(p, Mapping) else {}
