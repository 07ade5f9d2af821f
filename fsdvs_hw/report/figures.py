"""Report figures: kernels side by side, spectra, radial responses vs CSF, Pareto and speed plots.

Each function takes stored design points (dicts with ``realisation``, ``params``, ``status`` and
a :func:`~fsdvs_hw.explore.scoring.score` record in ``result``) or the flat rows of
:func:`fsdvs_hw.report.tables.score_rows`, and returns a matplotlib ``Figure``; nothing is shown.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..kernels import Kernel
from ..realise.registry import REALISATIONS
from .tables import accuracy_axis, is_reference, loss_interval

__all__ = ["realised_kernels", "fig_kernels", "fig_spectra", "fig_radial", "fig_pareto", "fig_speed"]

_MAX_PANELS = 12


def _colour(name: str) -> str | None:
    """The realisation's registered colour (None: matplotlib's cycle)."""
    spec = REALISATIONS.get(name)
    return spec.colour if spec is not None else None


def _label(p: Mapping[str, Any]) -> str:
    params = p.get("params") or {}
    return p["realisation"] + ("" if not params else " " + ", ".join(f"{k.split('.')[-1]}={v}" for k, v in params.items()))


def realised_kernels(points: Sequence[Mapping[str, Any]], *, limit: int = _MAX_PANELS) -> list[tuple[str, Kernel]]:
    """``(label, realised kernel)`` of the distinct successful points, at most ``limit`` (evenly picked)."""
    ok, seen = [], set()
    for p in points:  # one panel per distinct kernel (axes such as the optics do not change it)
        if p["status"] == "ok" and "kernel" in (p.get("result") or {}):
            taps = np.round(np.asarray(p["result"]["kernel"]["taps"], dtype=float), 12)
            sig = (p["realisation"], taps.shape, taps.tobytes())
            if sig not in seen:
                seen.add(sig)
                ok.append(p)
    if len(ok) > limit:
        idx = np.unique(np.linspace(0, len(ok) - 1, limit).round().astype(int))
        ok = [ok[i] for i in idx]
    return [(_label(p), Kernel.from_dict(p["result"]["kernel"], source=_label(p))) for p in ok]


def _grid(n: int, *, w: float = 3.0, h: float = 2.7) -> tuple[Any, np.ndarray]:
    import matplotlib.pyplot as plt

    cols = min(n, 4)
    rows = max(1, math.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(w * cols, h * rows), constrained_layout=True, squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()


def fig_kernels(kernels: Sequence[tuple[str, Kernel]]) -> Any:
    """Taps of every kernel side by side (diverging colour map, own scale each)."""
    from ..plots import plot_kernel

    fig, axes = _grid(len(kernels))
    for ax, (label, k) in zip(axes, kernels):
        plot_kernel(k, ax=ax, annotate=k.size <= 7 and len(kernels) <= 4, title=label)
    return fig


def fig_spectra(kernels: Sequence[tuple[str, Kernel]]) -> Any:
    """2-D magnitude spectra |H(f_x, f_y)| side by side."""
    from ..plots import plot_spectrum

    fig, axes = _grid(len(kernels))
    for ax, (label, k) in zip(axes, kernels):
        plot_spectrum(k, ax=ax, n_fft=64, title=label)
    return fig


def fig_radial(kernels: Sequence[tuple[str, Kernel]], *, methods: Sequence[str], pitch_m: float,
               focal_length_m: float) -> Any:
    """Peak-normalised radial responses vs the CSF models: at the design geometry and at the fitted scale."""
    import matplotlib.pyplot as plt

    from ..csf import Geometry
    from ..plots import plot_radial_vs_csf

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), constrained_layout=True)
    ks = [k for _, k in kernels]
    labels = [lab for lab, _ in kernels]
    plot_radial_vs_csf(ks, methods=list(methods), geometry=Geometry(pitch_m, focal_length_m), ax=axes[0], labels=labels)
    axes[0].set_title(f"design geometry (pitch {pitch_m * 1e6:.2f} µm, f = {focal_length_m * 1e3:.2f} mm)", fontsize=9)
    plot_radial_vs_csf(ks, methods=list(methods[:1]), geometry=None, ax=axes[1], labels=labels)
    axes[1].set_title("scale fitted to the first kernel (shape comparison, as in the FS-DVS paper)", fontsize=9)
    return fig


def fig_pareto(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Accuracy loss (95 % CI bars) vs CSF agreement across kinds, then one panel per hardware kind
    with the loss against that kind's own cost in its own unit (never one shared cost axis).

    Rings mark the uncertainty-aware fronts (:func:`fsdvs_hw.report.tables.uncertain_pareto_front`):
    across kinds in the first panel, within the kind in the others.
    """
    import matplotlib.pyplot as plt

    acc, acc_label = accuracy_axis(rows)
    ok = [r for r in rows if r["status"] == "ok"]
    kinds = [k for k in dict.fromkeys(r["realisation"] for r in ok)
             if any(not math.isnan(_val(r, "kind_cost_value")) for r in ok if r["realisation"] == k)]
    n = 1 + max(1, len(kinds))
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 4.2), constrained_layout=True)
    ax = axes[0]
    for kind in dict.fromkeys(r["realisation"] for r in ok):
        g = [r for r in ok if r["realisation"] == kind]
        x = [_val(r, "csf_fitted_correlation") for r in g]
        y, lo, hi = zip(*(loss_interval(r, acc) for r in g))
        ax.errorbar(x, y, yerr=[np.subtract(y, lo), np.subtract(hi, y)], fmt="o", ms=5, capsize=3,
                    color=_colour(kind), label=kind, zorder=3)
        for xi, yi, r in zip(x, y, g):
            if r.get("pareto_all"):
                ax.scatter([xi], [yi], s=150, facecolors="none", edgecolors=_colour(kind), lw=1.5, zorder=2)
            if len(ok) <= 10:
                ax.annotate(r["point"], (xi, yi), fontsize=6, xytext=(3, 3), textcoords="offset points")
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("CSF agreement (Mannos–Sakrison, fitted viewing scale)")
    ax.set_ylabel(acc_label, fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("across kinds (rings: not dominated beyond the CIs)", fontsize=9)
    if not kinds:
        axes[1].text(0.5, 0.5, "no hardware realisation with costs was scored", ha="center", va="center",
                     transform=axes[1].transAxes)
        axes[1].set_axis_off()
    for ax, kind in zip(axes[1:], kinds):
        g = sorted((r for r in ok if r["realisation"] == kind and not math.isnan(_val(r, "kind_cost_value"))),
                   key=lambda r: r["kind_cost_value"])
        x = [r["kind_cost_value"] for r in g]
        y, lo, hi = zip(*(loss_interval(r, acc) for r in g))
        ax.errorbar(x, y, yerr=[np.subtract(y, lo), np.subtract(hi, y)], fmt="o-", ms=5, capsize=3,
                    color=_colour(kind))
        for xi, yi, r in zip(x, y, g):
            if r.get("pareto"):
                ax.scatter([xi], [yi], s=150, facecolors="none", edgecolors=_colour(kind), lw=1.5)
            if len(g) <= 8:
                ax.annotate(r["point"], (xi, yi), fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_xlabel(f"{g[0]['kind_cost']} [{g[0]['kind_cost_unit']}]")
        ax.set_ylabel(acc_label, fontsize=8)
        ax.grid(alpha=0.3, which="both")
        ax.set_title(f"{kind}: loss vs its own cost", fontsize=9)
    return fig


def _val(r: Mapping[str, Any], key: str) -> float:
    v = r.get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def fig_speed(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Speed for accuracy: kernel error against fit time for every realisation point."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    ok = [r for r in rows if r["status"] == "ok" and not is_reference(r["realisation"])]
    for kind in dict.fromkeys(r["realisation"] for r in ok):
        g = [r for r in ok if r["realisation"] == kind]
        ax.scatter([max(r["fit_s"], 1e-6) for r in g], [max(r["kernel_error"], 1e-12) for r in g],
                   color=_colour(kind), label=kind)
    if ok:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no hardware realisation was fitted", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("fit wall time (s)")
    ax.set_ylabel("kernel error vs target (relative L2)")
    ax.grid(alpha=0.3, which="both")
    ax.set_title("speed for accuracy of the realisation fits", fontsize=9)
    return fig
