"""One-call analysis of a kernel: band summary, CSF agreement for every model, figures, JSON.

This is what ``fsdvs-hw analyse`` runs. The speed/accuracy trade of the radial-response methods
and of the CSF-agreement fit is measured by ``benchmarks/csf.py`` (``fsdvs-hw bench csf``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .csf import CSF_METHODS, CsfAgreement, Geometry, csf_agreement
from .kernels import Kernel, as_kernel
from .paths import figure_png, write_output
from .spectra import SpectralSummary, spectral_summary

__all__ = ["KernelAnalysis", "analyse_kernel", "format_analysis", "write_analysis"]


@dataclass(frozen=True)
class KernelAnalysis:
    """Result of :func:`analyse_kernel`.

    Attributes
    ----------
    kernel : Kernel
    geometry : Geometry or None
    summary : SpectralSummary
        Band summary in cycles/pixel.
    agreements : dict[str, CsfAgreement]
        One entry per CSF model.
    asymmetry : float
        Departure from 8-fold symmetry (0 = perfectly symmetric); see :meth:`Kernel.asymmetry`.
    """

    kernel: Kernel
    geometry: Geometry | None
    summary: SpectralSummary
    agreements: dict[str, CsfAgreement]
    asymmetry: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "kernel": self.kernel.to_dict(),
            "geometry": None
            if self.geometry is None
            else {
                "pitch_m": self.geometry.pitch_m,
                "focal_length_m": self.geometry.focal_length_m,
                "pixels_per_degree": self.geometry.pixels_per_degree,
            },
            "spectral_summary": self.summary.to_dict(),
            "asymmetry": self.asymmetry,
            "csf_agreement": {m: a.to_dict() for m, a in self.agreements.items()},
        }


def analyse_kernel(
    kernel: Kernel | Any,
    *,
    pitch_m: float | None = None,
    geometry: Geometry | None = None,
    methods: Sequence[str] = tuple(CSF_METHODS),
) -> KernelAnalysis:
    """Spectral summary and CSF agreement of ``kernel`` against each model in ``methods``.

    Parameters
    ----------
    kernel : Kernel, path or array_like
        What :func:`~fsdvs_hw.kernels.as_kernel` accepts (a Kernel, a kernel file, odd k×k taps).
    pitch_m : float, optional
        Pixel pitch in metres of an array (default :data:`~fsdvs_hw.kernels.DEFAULT_PITCH_M`);
        a Kernel keeps its own (a different value is an error).
    geometry : Geometry, optional
        Pitch and focal length giving pixels per degree; None fits the scale (shape-only agreement).
    methods : sequence of str
        CSF models (:data:`~fsdvs_hw.csf.CSF_METHODS`).

    Returns
    -------
    KernelAnalysis

    Examples
    --------
    >>> from fsdvs_hw import analyse_kernel, reference_kernel
    >>> a = analyse_kernel(reference_kernel("dog", 7), methods=("mannos_sakrison_1974",))
    >>> a.summary.kind, round(a.summary.peak_frequency_cpp, 2), round(a.summary.dc_gain, 3)
    ('band-pass', 0.19, 0.2)
    >>> r = a.agreements["mannos_sakrison_1974"]
    >>> r.scale_fitted, r.correlation > 0.9
    (True, True)
    """
    kernel = as_kernel(kernel, pitch_m=pitch_m)
    agreements = {}
    for m in methods:
        a = csf_agreement(kernel, method=m, geometry=geometry)
        agreements[a.method] = a
    return KernelAnalysis(kernel, geometry, spectral_summary(kernel), agreements, kernel.asymmetry())


def format_analysis(analysis: KernelAnalysis) -> str:
    """A short plain-text table of the analysis."""
    k, s = analysis.kernel, analysis.summary
    lines = [
        f"kernel      {k.name}  ({k.size}x{k.size}, pitch {k.pitch_m * 1e6:.3g} um)",
        f"DC gain     {s.dc_gain:+.4f}    centre tap {k.centre:+.4f}    asymmetry {analysis.asymmetry:.3g}",
        f"response    {s.kind}, peak {s.peak_frequency_cpp:.4f} cyc/px (gain {s.peak_gain:.4g}), "
        f"half-max band {s.band_low_cpp:.4f}-{s.band_high_cpp:.4f} cyc/px, Q {s.q:.3f}",
    ]
    if analysis.geometry is not None:
        g = analysis.geometry
        lines.append(f"geometry    focal {g.focal_length_m * 1e3:.4g} mm -> {g.pixels_per_degree:.2f} px/deg")
    lines.append("")
    header = f"{'CSF model':<22}{'px/deg':>9}{'fitted':>8}{'peak ratio':>12}{'corr':>8}{'RMS':>8}{'logRMS dec':>12}"
    lines += [header, "-" * len(header)]
    for m, a in analysis.agreements.items():
        lines.append(
            f"{m:<22}{a.pixels_per_degree:>9.2f}{('yes' if a.scale_fitted else 'no'):>8}{a.peak_ratio:>12.3f}"
            f"{a.correlation:>8.3f}{a.rms_error:>8.3f}{a.log_rms_error_dec:>12.3f}"
        )
    return "\n".join(lines)


def write_analysis(analysis: KernelAnalysis, out_dir: str | Path) -> dict[str, Path]:
    """Write ``metrics.json``, ``kernel.png``, ``spectrum.png`` and ``radial_csf.png`` to ``out_dir``."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from .plots import plot_kernel, plot_radial_vs_csf, plot_spectrum

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"metrics": out / "metrics.json"}
    write_output(paths["metrics"], json.dumps(analysis.to_dict(), indent=1) + "\n")
    for key, make in (
        ("kernel", lambda: plot_kernel(analysis.kernel)),
        ("spectrum", lambda: plot_spectrum(analysis.kernel)),
        (
            "radial_csf",
            lambda: plot_radial_vs_csf(analysis.kernel, methods=list(analysis.agreements), geometry=analysis.geometry),
        ),
    ):
        fig, _ = make()
        paths[key] = out / f"{key}.png"
        write_output(paths[key], figure_png(fig, dpi=120))
        plt.close(fig)
    return paths
