"""``fsdvs-hw bench metalens``: speed-for-accuracy tables of the metalens PSF model and fits.

Tables (Markdown):

1. Grid fidelity at one wavelength (555 nm): the pixel-integrated PSF of a defocused, aberrated
   lens (D = 100 µm, f = 200 µm, z = 240 µm, c = [2, −3] rad) from the radial Hankel path at
   growing window, mode count and pixel-quadrature order, and from the 2-D band-limited angular
   spectrum at growing samples per pixel — relative L2 error against the finest radial model,
   versus wall time.
2. Spectral samples: the same PSF under D65 × CIE 1924 V(λ) with 1 … 32 equal-weight samples
   against 64 samples, versus wall time.
3. Fits at 4.86 µm pitch of a DoG 7×7 and a learned 7×7 kernel (``designs/kernels/
   learned_detection_7x7.json`` when present, else a LoG 7×7), both strategies: kernel error,
   radially symmetric floor, pedestal, efficiency, contrast factor, fit wall time. With
   ``quick=False`` the figure ``metalens_fits.png`` is written into ``figures`` (default: a
   temporary folder; ``fsdvs-hw bench metalens --figures out/figures`` makes the README's).
4. The metalens point as a layout (``metalens_layout``) on the learned 7×7 (pedestal): the time per
   point split into the ideal fit, the layout (library from the committed cache, site assignment,
   library-step and 2-D layout PSFs; repeated) and the artifacts (GDS write and read-back, KLayout
   DRC), with the kernel error of each step and the window efficiency.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from fsdvs_hw.resources import shipped_path

from .harness import BenchRun, BenchSection, Column, Measured, kept_global_state, timed

__all__ = ["bench_metalens", "plot_fits", "radial_symmetric_floor"]

_LEARNED = shipped_path("kernels", "learned_detection_7x7.json")
_FIGURE_NAME = "metalens_fits.png"


def _log(msg: str) -> None:
    print(f"[bench metalens] {msg}", file=sys.stderr, flush=True)


def radial_symmetric_floor(taps: np.ndarray) -> float:
    """Relative L2 distance from a kernel to its ring average (taps at equal radius averaged).

    A radially symmetric PSF integrated over square pixels gives equal taps at equal distance from
    the centre, so this is a lower bound on what any rotationally symmetric lens can reach.
    """
    k = taps.shape[0]
    r = k // 2
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    key = x * x + y * y
    out = np.empty_like(taps)
    for v in np.unique(key):
        sel = key == v
        out[sel] = taps[sel].mean()
    return float(np.linalg.norm(taps - out) / np.linalg.norm(taps))


def _grid_table(sec: BenchSection, quick: bool) -> None:
    from fsdvs_hw.realise.metalens.fit import pixel_psf
    from fsdvs_hw.realise.metalens.lens import LensGeometry

    g = LensGeometry()
    kw = dict(coefficients=[2.0, -3.0], sensor_distance_m=240e-6, n_pixels=9, illuminant=555e-9)
    _log("grid reference (radial, window ×4, 4× modes, 24 nodes/pixel side)")
    ref = pixel_psf(g, **kw, window_pad=4.0, n_modes=1600, n_sub=24)
    table = sec.table(
        Column.text("path"),
        Column.text("setting"),
        Column.number("error vs reference", ".2e", metric="relative L2 error vs reference"),
        Column.number("time (s)", ".3f", summary="best", metric="time"),
    )
    radial = [
        ("window ×1.5", dict(window_pad=1.5)),
        ("window ×2 (default)", {}),
        ("window ×3", dict(window_pad=3.0)),
        ("n_sub 4", dict(n_sub=4)),
        ("n_sub 8", dict(n_sub=8)),
        ("2× modes", dict(n_modes=600)),
    ]
    planar = [(f"{m} samples/pixel", dict(samples_per_pixel=m)) for m in ((9, 15) if quick else (9, 15, 21, 27))]
    for label, opts in radial:
        tm = timed(lambda: pixel_psf(g, **kw, **opts), 1 if quick else 3)
        table.row("radial (Hankel)", label, np.linalg.norm(tm.result - ref) / np.linalg.norm(ref), tm)
    for label, opts in planar:
        _log(f"2-D angular spectrum {label}")
        tm = timed(lambda: pixel_psf(g, **kw, method="angular_2d", **opts))
        table.row("2-D angular spectrum", label, np.linalg.norm(tm.result - ref) / np.linalg.norm(ref), tm)


def _spectral_table(sec: BenchSection, quick: bool) -> None:
    from fsdvs_hw.realise.metalens.fit import pixel_psf
    from fsdvs_hw.realise.metalens.lens import LensGeometry

    kw = dict(coefficients=[2.0, -3.0], sensor_distance_m=240e-6, n_pixels=9, illuminant="D65")
    _log("spectral reference (64 samples)")
    table = sec.table(
        Column.text("dispersion"),
        Column.text("wavelength samples"),
        Column.number("error vs 64 samples", ".2e", metric="relative L2 error vs 64 samples"),
        Column.number("time (s)", ".3f", summary="best", metric="time"),
    )
    for disp in ("diffractive", "achromatic"):
        gd = LensGeometry(dispersion=disp)
        ref = pixel_psf(gd, **kw, n_wavelengths=64)
        for n in (1, 4, 16) if quick else (1, 2, 4, 8, 16, 24, 32):
            tm = timed(lambda: pixel_psf(gd, **kw, n_wavelengths=n))
            table.row(disp, str(n), np.linalg.norm(tm.result - ref) / np.linalg.norm(ref), tm)


def _targets() -> list[tuple[str, Any]]:
    from fsdvs_hw.kernels import load_kernel, reference_kernel

    out = [("DoG 7×7 (0.7/2.0 px, 20 % DC)", reference_kernel("dog", 7))]
    if _LEARNED.is_file():
        out.append((f"learned 7×7 ({_LEARNED.name})", load_kernel(_LEARNED)))
    else:
        out.append(("LoG 7×7 (no learned kernel shipped)", reference_kernel("log", 7)))
    return out


def _fit_table(sec: BenchSection, quick: bool) -> list[tuple[str, Any, Any]]:
    from fsdvs_hw.realise.metalens.fit import fit_metalens

    opts: dict[str, Any] = dict(n_starts=2, max_iter=30, n_wavelengths=4, n_terms=2) if quick else {}
    table = sec.table(
        Column.text("target"),
        Column.text("strategy"),
        Column.number("kernel error (applied, pedestal included)", ".3f", unit="", metric="kernel error"),
        Column.number("signal error (pedestal subtracted)", ".3f", unit="", metric="signal error"),
        Column.number("symmetric floor", ".3f"),
        Column.numbers(
            "pedestal c / fraction", "{0} / {1} %", ("pedestal c", "", ".3g"), ("pedestal fraction", "%", ".0f")
        ),
        Column.number("efficiency", ".3f", metric="optical efficiency (smallest)"),
        Column.number("contrast factor", ".3f"),
        Column.numbers(
            "whole-PSF DC (target)", "{0} ({1})", ("whole-PSF DC gain", "", ".3f"), ("target DC gain", "", ".3f")
        ),
        Column.number("defocus (µm)", metric="defocus"),  # cells: text quoting one recorded value per PSF
        Column.number("nodes/pixel side", "d", unit="count", metric="quadrature nodes per pixel side"),
        Column.numbers(
            "fit wall / CPU time (s)", "{0} / {1}", ("fit wall time", "s", ".1f"), ("fit CPU time", "s", ".1f")
        ),
        Column.number("model error", ".1e", metric="model error vs reference fidelity"),
        settings={"fit_options": opts},
    )
    fits = []
    for label, k in _targets():
        pair = []
        for strategy in ("pedestal", "differential"):
            _log(f"fit {label} ({strategy})")
            d = fit_metalens(k, pitch_m=4.86e-6, strategy=strategy, **opts)
            pair.append(d)
            case = f"target={label}; strategy={strategy}"
            ped = (d.pedestal, 100 * d.pedestal_fraction) if strategy == "pedestal" else "—"
            defocus = ", ".join(
                sec.value(case, f"defocus of PSF {i}", (z - d.geometry.focal_length_m) * 1e6, unit="µm", spec="+.1f")
                for i, z in enumerate(d.sensor_distance_m)
            )
            table.row(
                label,
                strategy,
                d.error,
                d.signal_error,
                radial_symmetric_floor(k.taps),
                ped,
                min(d.optical_efficiency),
                d.contrast_factor,
                (d.whole_dc_gain, k.dc_gain),
                defocus,
                d.fit_info["n_sub"],
                (Measured.of([d.fit_info["wall_time_s"]]), Measured.of([d.fit_info["cpu_time_s"]])),
                d.fit_info["model_error"],
                case=case,
            )
        fits.append((label, k, pair))
    return fits


def plot_fits(fits: list[tuple[str, Any, Any]], path: Path) -> Path:
    """Figure: per target, the target, both applied kernels, the differential PSF pair and the errors."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    n = len(fits)
    fig = Figure(figsize=(15, 3.2 * n))  # no pyplot: no backend switch, no global figure registry
    axes = fig.subplots(n, 5, squeeze=False)
    for row, (label, k, (ped, diff)) in enumerate(fits):
        pad = ped.guard_px
        target = np.pad(k.taps / np.abs(k.taps).max(), pad)
        panels = [
            (target, f"target: {label.split(' (')[0]}", "RdBu_r", True),
            (
                ped.kernel().taps / np.abs(ped.kernel().taps).max(),
                f"pedestal: applied gP ≈ K + c\nerror {ped.error:.3f}",
                "RdBu_r",
                True,
            ),
            (
                diff.kernel().taps / np.abs(diff.kernel().taps).max(),
                f"differential: g₊P₊ − g₋P₋\nerror {diff.error:.3f}",
                "RdBu_r",
                True,
            ),
            (
                diff.psfs[0],
                f"P₊ (fraction of power)\ndefocus {(diff.sensor_distance_m[0] - diff.geometry.focal_length_m) * 1e6:+.0f} µm",
                "magma",
                False,
            ),
            (
                diff.psfs[1],
                f"P₋ (fraction of power)\ndefocus {(diff.sensor_distance_m[1] - diff.geometry.focal_length_m) * 1e6:+.0f} µm",
                "magma",
                False,
            ),
        ]
        for ax, (img, title, cmap, signed) in zip(axes[row], panels):
            lim = np.abs(img).max()
            im = ax.imshow(img, cmap=cmap, vmin=-lim if signed else 0, vmax=lim)
            g, s = pad, k.size
            ax.add_patch(Rectangle((g - 0.5, g - 0.5), s, s, fill=False, ec="k", lw=0.8, ls="--"))
            ax.set_title(title, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
            fig.colorbar(im, ax=ax, fraction=0.046)
    fig.suptitle(
        "Metalens fits at 4.86 µm pitch (D = 100 µm, f = 200 µm, D65 × V(λ); dashed: kernel window)", fontsize=10
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def _layout_table(sec: BenchSection, quick: bool) -> None:
    from fsdvs_hw.realise.metalens.layout_artifacts import write_layout_artifacts
    from fsdvs_hw.realise.metalens.layout_design import build_layout, fit_metalens_layout, step_psfs
    from fsdvs_hw.realise.metalens.meta_atoms import load_library
    from fsdvs_hw.realise.metalens.options import MetalensLayoutOptions

    opts: dict[str, Any] = dict(n_starts=2, max_iter=30, n_wavelengths=4, n_terms=2) if quick else {}
    label, k = _targets()[-1]
    table = sec.table(
        Column.text("target"),
        Column.text("step"),
        Column.number("time (s)", ".2f", summary="median", spread=True),
        Column.number("kernel error", ".3f", unit="", metric="kernel error"),
        Column.number("window efficiency", ".3f", unit="", metric="optical efficiency (smallest)"),
        settings={"fit_options": opts},
    )
    _log(f"layout point {label}")
    d = fit_metalens_layout(k, pitch_m=4.86e-6, progress=False, **opts)
    ideal, info = d.ideal, d.layout_info
    library = load_library(MetalensLayoutOptions().meta_atom_spec(), compute=False)

    def layout_again() -> Any:
        lenses = build_layout(ideal, dict(d.options), library)
        return step_psfs(ideal, lenses, library, dict(d.options))

    tm_layout = timed(layout_again, 1 if quick else 3)
    folder = Path(tempfile.mkdtemp(prefix="fsdvs_bench_layout_"))
    tm_art = timed(lambda: write_layout_artifacts(d, folder), 1)
    lib = d.library_step
    table.row(
        label,
        "ideal phase (fit)",
        Measured.of([ideal.fit_info["wall_time_s"]]),
        ideal.error,
        min(ideal.optical_efficiency),
    )
    table.row(label, "library (radial PSF)", "—", lib.error, min(lib.optical_efficiency))
    table.row(
        label, "layout (sites, library + layout PSFs)", tm_layout, d.layout.error, min(d.layout.optical_efficiency)
    )
    table.row(label, "artifacts (GDS, read-back, DRC)", tm_art, "—", "—")
    sec.text(
        "",
        f"{info['pillars']} pillars, {info['radius_levels']} radius levels of {info['usable_radii']} usable "
        f"({info['library_radii']} computed); library |t|² over the used sites and the spectrum "
        + sec.value(label, "library transmission", info["library_transmission"], spec=".3f")
        + ". Kernel error per step: ideal phase, library (radial), layout (2-D lattice); the layout time "
        "excludes the ideal fit, which the ``metalens`` point of the same run also pays.",
    )


@kept_global_state()
def bench_metalens(*, quick: bool = False, figures: Path | None = None) -> BenchRun:
    """Run the metalens speed/accuracy benchmark: its records and Markdown tables (see module docstring)."""
    import torch

    threads = torch.get_num_threads()
    sec = BenchSection("metalens", settings={"quick": quick})
    sec.text(
        "## metalens: PSF model fidelity and fits",
        "",
        f"torch threads: {threads}. Lens D = 100 µm, f = 200 µm (NA 0.243), diffractive dispersion, pitch 4.86 µm.",
        "",
        "### 1. Grid size, one wavelength (555 nm); reference: radial, window ×4, 1600 modes, 24² nodes/pixel",
        "",
    )
    _grid_table(sec, quick)
    sec.text("", "### 2. Spectral samples (D65 × CIE 1924 V(λ), equal-weight bins); reference: 64 samples", "")
    _spectral_table(sec, quick)
    sec.text(
        "",
        "### 3. Fits (torch L-BFGS, float64; 8-sample search, 24-sample polish; PSFs re-evaluated at reference fidelity)",
        "",
    )
    fits = _fit_table(sec, quick)
    sec.text("", "### 4. The metalens point as a layout (learned 7×7, pedestal; TiO₂ pillars, committed library)", "")
    _layout_table(sec, quick)
    sec.text(
        "",
        "kernel error: relative L2 of the applied kernel, pedestal included (the one definition the scorer uses), "
        "against the target, spill into the 2-pixel guard ring included; signal error: the same with the pedestal "
        "subtracted in the window (the shape). whole-PSF DC: the DC gain over all the light on the sensor. "
        "symmetric floor: distance from the target to its ring average (no "
        "rotationally symmetric lens can do better). contrast factor: log-contrast gain relative to the ideal kernel "
        "(n/a when the target has no positive DC). model error: fitted model vs reference-fidelity model.",
    )
    if not quick:
        folder = Path(figures) if figures is not None else Path(tempfile.mkdtemp(prefix="fsdvs_bench_metalens_"))
        path = plot_fits(fits, folder / _FIGURE_NAME)
        sec.text("", f"Figure written: `{path}`.")
    sec.text("")
    return sec.run()
