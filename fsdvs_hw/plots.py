"""Figures for kernels, their spectra and their agreement with CSF models.

Every function returns ``(fig, ax)`` and accepts an existing ``ax`` so figures compose; nothing
is shown or saved here. matplotlib is imported on first use.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from .csf import Geometry, contrast_sensitivity, csf_agreement, csf_peak
from .errors import InputError
from .kernels import Kernel, as_kernel
from .spectra import magnitude_spectrum, radial_response

__all__ = ["plot_kernel", "plot_radial_vs_csf", "plot_spectrum"]


def _axes(ax: Any = None, figsize: tuple[float, float] = (4.2, 3.6)) -> tuple[Any, Any]:
    if ax is not None:
        return ax.figure, ax
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    return fig, ax


def _one_kernel(kernels: Any) -> bool:
    """True if ``kernels`` is one kernel (a Kernel, a path, a 2-D array or nested list of numbers)."""
    if isinstance(kernels, (Kernel, str, Path)) or getattr(kernels, "ndim", None) == 2:
        return True
    return (
        isinstance(kernels, (list, tuple))
        and len(kernels) > 0
        and isinstance(kernels[0], (list, tuple))
        and len(kernels[0]) > 0
        and np.isscalar(kernels[0][0])
    )


def plot_kernel(
    kernel: Kernel | Any, ax: Any = None, *, annotate: bool | None = None, title: str | None = None
) -> tuple[Any, Any]:
    """Heat map of the taps on a diverging colour map centred at 0 (red > 0, blue < 0).

    Parameters
    ----------
    kernel : Kernel, path or array_like
        What :func:`~fsdvs_hw.kernels.as_kernel` accepts.
    ax : matplotlib Axes, optional
    annotate : bool, optional
        Write each tap's value in its cell (default: for kernels up to 9×9).
    title : str, optional
        Defaults to the kernel's name.
    """
    kernel = as_kernel(kernel)
    fig, ax = _axes(ax)
    t = kernel.taps
    vmax = float(np.abs(t).max())
    r = kernel.radius
    im = ax.imshow(t, cmap="RdBu_r", vmin=-vmax, vmax=vmax, extent=(-r - 0.5, r + 0.5, r + 0.5, -r - 0.5))
    fig.colorbar(im, ax=ax, shrink=0.85, label="tap weight")
    if annotate is None:
        annotate = kernel.size <= 9
    if annotate:
        for (y, x), v in np.ndenumerate(t):
            ax.text(
                x - r,
                y - r,
                f"{v:.2f}",
                ha="center",
                va="center",
                fontsize=7,
                color="white" if abs(v) > 0.6 * vmax else "black",
            )
    ax.set_xlabel("x (pixels)")
    ax.set_ylabel("y (pixels)")
    ax.set_title(title if title is not None else kernel.name, fontsize=9)
    return fig, ax


def plot_spectrum(
    kernel: Kernel | Any, ax: Any = None, *, n_fft: int = 128, title: str | None = None
) -> tuple[Any, Any]:
    """2-D magnitude spectrum |H(f_x, f_y)| over the Nyquist square (cycles/pixel); ``kernel`` as
    :func:`~fsdvs_hw.kernels.as_kernel` accepts it."""
    kernel = as_kernel(kernel)
    fig, ax = _axes(ax)
    f, mag = magnitude_spectrum(kernel, n_fft)
    step = f[1] - f[0]
    im = ax.imshow(
        mag, cmap="magma", origin="lower", extent=(f[0] - step / 2, f[-1] + step / 2, f[0] - step / 2, f[-1] + step / 2)
    )
    fig.colorbar(im, ax=ax, shrink=0.85, label="|H|")
    ax.set_xlabel("$f_x$ (cycles/pixel)")
    ax.set_ylabel("$f_y$ (cycles/pixel)")
    ax.set_title(title if title is not None else f"|H| of {kernel.name}", fontsize=9)
    return fig, ax


def plot_radial_vs_csf(
    kernels: Kernel | Sequence[Kernel] | Any,
    *,
    methods: Sequence[str] = ("mannos_sakrison_1974",),
    geometry: Geometry | None = None,
    ax: Any = None,
    labels: Sequence[str] | None = None,
) -> tuple[Any, Any]:
    """Radial responses and CSF curves, each normalised to its own maximum (as in the FS-DVS paper).

    The bottom axis is the kernels' frequency in cycles/pixel; the top axis is cycles/degree,
    tied to the bottom by the geometry's pixels-per-degree, or — without a geometry — by the
    scale that best aligns the first kernel with the first CSF (:func:`~fsdvs_hw.csf.csf_agreement`),
    stated in the legend. ``kernels`` is one kernel or a sequence of them, each as
    :func:`~fsdvs_hw.kernels.as_kernel` accepts it (a single k×k array is one kernel).
    """
    if _one_kernel(kernels):
        kernels = [kernels]
    # a sequence of kernels here: one kernel was wrapped above
    kernels = [as_kernel(k, name=f"kernel {i}") for i, k in enumerate(cast(Sequence[Any], kernels))]
    if not kernels:
        raise InputError("plot_radial_vs_csf: need at least one kernel")
    fig, ax = _axes(ax, figsize=(5.6, 3.8))
    if geometry is not None:
        ppd, how = geometry.pixels_per_degree, f"geometry: {geometry.pixels_per_degree:.1f} px/deg"
    else:
        agr = csf_agreement(kernels[0], method=methods[0])
        ppd, how = agr.pixels_per_degree, f"fitted scale: {agr.pixels_per_degree:.1f} px/deg"
    for i, k in enumerate(kernels):
        rr = radial_response(k, n_freq=257)
        ax.plot(rr.f_cpp, rr.normalised(), lw=2, label=(labels[i] if labels else k.name))
    f_cpp = np.linspace(1e-3, 0.5, 400)
    for m in methods:
        _, peak = csf_peak(m)
        ax.plot(f_cpp, contrast_sensitivity(f_cpp * ppd, m) / peak, ls="--", lw=1.5, label=f"CSF {m}")
    ax.set_xlim(0, 0.5)
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("spatial frequency (cycles/pixel)")
    ax.set_ylabel("response / own maximum")
    top = ax.secondary_xaxis("top", functions=(lambda x: x * ppd, lambda x: x / ppd))
    top.set_xlabel(f"cycles/degree ({how})", fontsize=8)
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)
    return fig, ax
