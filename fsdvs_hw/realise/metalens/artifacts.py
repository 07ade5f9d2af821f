"""Buildable artifacts of a metalens: its phase profile (CSV, NPZ), a plot, and the PSF it implies.

:func:`write_metalens_artifacts` writes, for a fitted :class:`~fsdvs_hw.realise.metalens.MetalensDesign`:

``phase_profile.csv``
    Per lens and radius: ``lens``, ``radius_m`` (m, 0 … aperture radius, :data:`N_RADII` uniform
    samples), ``phase_rad`` (rad at the design wavelength, unwrapped: hyperbolic focusing term plus
    the fitted polynomial) and ``phase_wrapped_rad`` (the same modulo 2π, what a metasurface
    imposes), preceded by ``#`` comment lines with the scalars (design wavelength, focal length,
    NA, aperture, lens-to-sensor distances, pixel pitch, dispersion model).
``phase_profile.npz``
    The same profile (``radius_m``, ``phase_rad`` of shape (lenses, radii)) with everything the
    propagation needs: ``wavelengths_m`` and ``wavelength_weights`` (the spectral samples),
    ``design_wavelength_m``, ``focal_length_m``, ``aperture_m``, ``numerical_aperture`` (geometric,
    of the focusing term), ``local_na_max`` (largest local NA of the fitted phase),
    ``na_budget``, ``unit_cell_max_m`` (λ_min / (2 NA), the largest metasurface period that
    samples the phase), ``sensor_distance_m``, ``pixel_pitch_m``, ``n_pixels``, ``dispersion``,
    ``coefficients`` (rad at λ0 of (r/a)^2, (r/a)^4, …).
``psf.npz``
    ``psf`` (lenses, n, n): the pixel- and spectrum-integrated PSF of each lens as fractions of the
    power entering the aperture (the design's own), ``kernel`` (the applied kernel g·P or
    g₊P₊ − g₋P₋), ``gains``, ``pedestal``, ``guard_px``, ``pixel_pitch_m``.
``phase_psf.png``
    The phase profile against radius and each lens's PSF.

:func:`psf_from_phase_profile` reloads a profile and propagates it with the fit's forward model
(radial angular spectrum, spectral weights, pixel integration;
:class:`~fsdvs_hw.realise.metalens.fit.RadialKernelModel`); :func:`check_metalens_artifacts`
compares the result with ``psf.npz``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ...paths import csv_text, figure_png, npz_bytes, write_output
from ..artifacts import Artifact
from ..spectral import SpectralSamples
from .fit import MetalensDesign, RadialKernelModel
from .lens import LensGeometry, design_phase, local_numerical_aperture

__all__ = [
    "N_RADII",
    "PSF_RTOL",
    "check_metalens_artifacts",
    "psf_from_phase_profile",
    "read_phase_profile_csv",
    "write_metalens_artifacts",
]

#: Radii per lens in the written profile (uniform over the aperture radius; 50 µm → 12 nm steps).
N_RADII: int = 4097

#: Largest relative L2 difference allowed between the PSF propagated from the reloaded profile and
#: the written PSF. The reload interpolates the tabulated phase (cubic spline) onto the propagator's
#: pupil nodes; a phase error δφ changes the pupil field by at most |δφ| relative and the intensity
#: by about 2|δφ|. On the default lens (100 µm aperture, f = 200 µm, 4097 radii) the spline is off by
#: 2e-12 rad and the two PSFs agree to 7e-15; 1e-6 leaves room for larger, faster-varying phases
#: and still fails for a wrong radius, phase, wavelength or distance (a 1 mrad phase error moves
#: the PSF by ~1e-3).
PSF_RTOL: float = 1e-6

_WINDOW_PAD = 3.0  # the window padding fit_metalens evaluates its returned PSFs with


def _profile(design: MetalensDesign) -> tuple[np.ndarray, np.ndarray]:
    r = np.linspace(0.0, design.geometry.radius_m, N_RADII)
    phase = np.stack([design_phase(r, design.geometry, np.asarray(c, dtype=float)) for c in design.coefficients])
    return r, phase


def _write_phase_csv(
    path: Path,
    r: np.ndarray,
    phase: np.ndarray,
    scalars: dict[str, Any],
    sensor_distance_m: Any,
    wavelengths_m: np.ndarray,
) -> None:
    """The phase profile as CSV: ``#`` header lines with the scalars, then one row per lens and radius
    (radius in m, phase in rad unwrapped and mod 2π)."""
    head = [
        "# fsdvs_hw metalens phase profile: phase_rad at the design wavelength (unwrapped), radius_m from "
        "the optical axis"
    ]
    head += [f"# {key} = {val!r}" for key, val in scalars.items()]
    head += [
        f"# sensor_distance_m = {[float(z) for z in sensor_distance_m]!r}",
        f"# wavelengths_m = {[float(v) for v in wavelengths_m]!r}",
    ]
    rows: list[list[Any]] = [["lens", "radius_m", "phase_rad", "phase_wrapped_rad"]]
    rows += [
        [i, repr(float(rr)), repr(float(ph)), repr(float(np.mod(ph, 2 * math.pi)))]
        for i in range(phase.shape[0])
        for rr, ph in zip(r, phase[i])
    ]
    write_output(path, "\n".join(head) + "\n" + csv_text(rows), flag="artifacts")


def write_metalens_artifacts(
    design: MetalensDesign, out_dir: str | Path, *, resolution: tuple[int, int] | None = None
) -> tuple[Artifact, ...]:
    """Write the phase profile (CSV, NPZ), the PSF (NPZ) and a plot into ``out_dir`` (module docstring).

    ``resolution`` is accepted for the writer protocol and not used.
    """
    if not isinstance(design, MetalensDesign):
        raise InputError(f"write_metalens_artifacts: expected a MetalensDesign, got {type(design).__name__}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    g, spec = design.geometry, design.spectral
    r, phase = _profile(design)
    lam = np.asarray(spec.wavelengths_m, dtype=float)
    local_na = max(local_numerical_aperture(g, c, lam) for c in design.coefficients)
    budget = float(design.fit_info.get("na_budget", max(local_na, g.numerical_aperture)))
    n_pix = int(design.psfs[0].shape[0])
    scalars: dict[str, Any] = {
        "design_wavelength_m": g.design_wavelength_m,
        "focal_length_m": g.focal_length_m,
        "aperture_m": g.aperture_m,
        "numerical_aperture": g.numerical_aperture,
        "local_na_max": local_na,
        "na_budget": budget,
        "unit_cell_max_m": float(lam.min() / (2 * local_na)),
        "pixel_pitch_m": design.target.pitch_m,
        "n_pixels": n_pix,
        "dispersion": g.dispersion,
    }
    write_output(
        out / "phase_profile.npz",
        npz_bytes(
            radius_m=r,
            phase_rad=phase,
            wavelengths_m=lam,
            wavelength_weights=np.asarray(spec.weights, dtype=float),
            sensor_distance_m=np.asarray(design.sensor_distance_m, dtype=float),
            coefficients=np.array([list(c) for c in design.coefficients], dtype=float),
            **scalars,
        ),
        flag="artifacts",
    )
    _write_phase_csv(out / "phase_profile.csv", r, phase, scalars, design.sensor_distance_m, lam)
    psf = np.stack([np.asarray(p, dtype=float) for p in design.psfs])
    write_output(
        out / "psf.npz",
        npz_bytes(
            psf=psf,
            kernel=np.asarray(design.kernel().taps, dtype=float),
            gains=np.asarray(design.gains, dtype=float),
            pedestal=float(design.pedestal),
            guard_px=int(design.guard_px),
            pixel_pitch_m=design.target.pitch_m,
            strategy=design.strategy,
        ),
        flag="artifacts",
    )
    _plot(out / "phase_psf.png", r, phase, psf, design)
    n_lens = phase.shape[0]
    check = (
        "reload phase_profile.npz (or .csv), interpolate onto the propagator's pupil radii, propagate "
        f"(fsdvs_hw.realise.metalens.artifacts.check_metalens_artifacts): equals psf.npz within 1 part in "
        f"{1 / PSF_RTOL:,.0f} (relative L2)"
    )
    return (
        Artifact(
            "phase_profile_csv",
            out / "phase_profile.csv",
            f"{n_lens} lens phase profile(s): radius_m, phase_rad at {g.design_wavelength_m * 1e9:.0f} nm "
            f"(unwrapped and mod 2π), f = {g.focal_length_m * 1e3:.3g} mm, NA {g.numerical_aperture:.3f}",
            check,
        ),
        Artifact(
            "phase_profile_npz",
            out / "phase_profile.npz",
            "the profile with wavelengths (m) and weights, focal length, aperture, NA, unit cell, sensor "
            "distance, pixel pitch (SI)",
            check,
        ),
        Artifact(
            "psf",
            out / "psf.npz",
            f"pixel-integrated PSF per lens ({n_pix}x{n_pix}, fractions of aperture power) and the applied kernel",
            "",
        ),
        Artifact("plot", out / "phase_psf.png", "phase vs radius and the PSF it implies (PNG)", ""),
    )


def _plot(path: Path, r: np.ndarray, phase: np.ndarray, psf: np.ndarray, design: MetalensDesign) -> None:
    from matplotlib.figure import Figure

    n_lens = phase.shape[0]
    fig = Figure(figsize=(4.2 * (1 + n_lens), 3.4), layout="constrained")
    axes = fig.subplots(1, 1 + n_lens)
    ax = axes[0]
    for i in range(n_lens):
        ax.plot(r * 1e6, phase[i], label=f"lens {i + 1} (unwrapped)")
        ax.plot(r * 1e6, np.mod(phase[i], 2 * math.pi), lw=0.5, alpha=0.6, label=f"lens {i + 1} mod 2π")
    ax.set_xlabel("radius (µm)")
    ax.set_ylabel(f"phase at {design.geometry.design_wavelength_m * 1e9:.0f} nm (rad)")
    ax.legend(fontsize=7)
    half = psf.shape[1] // 2
    ext = np.array([-half - 0.5, half + 0.5]) * design.target.pitch_m * 1e6
    for i in range(n_lens):
        im = axes[1 + i].imshow(psf[i], extent=(*ext, *ext[::-1]), cmap="magma")
        axes[1 + i].set_title(f"PSF lens {i + 1} (fraction of aperture power)", fontsize=8)
        axes[1 + i].set_xlabel("x (µm)")
        axes[1 + i].set_ylabel("y (µm)")
        fig.colorbar(im, ax=axes[1 + i], shrink=0.8)
    write_output(path, figure_png(fig, dpi=110), flag="artifacts")


def read_phase_profile_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``(radius_m, phase_rad)`` of a ``phase_profile.csv`` (phase shape (lenses, radii))."""
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
        lens = np.array([int(row["lens"]) for row in rows])
        r = np.array([float(row["radius_m"]) for row in rows])
        ph = np.array([float(row["phase_rad"]) for row in rows])
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(f"{path}: not a phase_profile.csv of write_metalens_artifacts ({exc})") from None
    n_lens = int(lens.max()) + 1
    radius = r[lens == 0]
    return radius, np.stack([ph[lens == i] for i in range(n_lens)])


def psf_from_phase_profile(
    profile: str | Path | dict[str, Any], *, radius_m: np.ndarray | None = None, phase_rad: np.ndarray | None = None
) -> dict[str, Any]:
    """Propagate a written phase profile to the pixel PSF with the fit's forward model.

    Parameters
    ----------
    profile : path or mapping
        ``phase_profile.npz`` (or its arrays): the settings (wavelengths and weights, geometry,
        sensor distances, pixel pitch, window size, NA budget) and, unless given, the profile.
    radius_m, phase_rad : ndarray, optional
        A profile from elsewhere (e.g. :func:`read_phase_profile_csv`) to propagate instead.

    Returns
    -------
    dict
        ``psf`` (lenses, n, n), fractions of the aperture's power; ``phase_error_rad``: the largest
        difference between the interpolated phase and the stored polynomial on the pupil nodes.
    """
    import torch
    from scipy.interpolate import CubicSpline

    data = dict(np.load(profile)) if isinstance(profile, (str, Path)) else dict(profile)
    r = np.asarray(data["radius_m"] if radius_m is None else radius_m, dtype=float)
    phase = np.atleast_2d(np.asarray(data["phase_rad"] if phase_rad is None else phase_rad, dtype=float))
    geometry = LensGeometry(
        float(data["aperture_m"]),
        float(data["focal_length_m"]),
        float(data["design_wavelength_m"]),
        str(data["dispersion"]),
    )
    spectral = SpectralSamples(
        np.asarray(data["wavelengths_m"], dtype=float),
        np.asarray(data["wavelength_weights"], dtype=float),
        "artifact",
        "artifact",
    )
    model = RadialKernelModel(
        geometry,
        pitch_m=float(data["pixel_pitch_m"]),
        n_pixels=int(data["n_pixels"]),
        spectral=spectral,
        n_sub=None,
        window_pad=_WINDOW_PAD,
        na_budget=float(data["na_budget"]),
    )
    nodes = model.prop.r_pupil
    if nodes.max() > r.max() * (1 + 1e-12) or nodes.min() < r.min() - 1e-18:
        raise InputError(f"phase profile covers {r.min():.3g}..{r.max():.3g} m; the pupil needs 0..{nodes.max():.3g} m")
    psfs, err = [], 0.0
    coeffs = np.atleast_2d(np.asarray(data.get("coefficients", np.zeros((phase.shape[0], 0))), dtype=float))
    for i, z in enumerate(np.asarray(data["sensor_distance_m"], dtype=float)):
        phi = CubicSpline(r, phase[i])(nodes)
        err = max(err, float(np.abs(phi - design_phase(nodes, geometry, coeffs[i])).max()))
        with torch.no_grad():
            psfs.append(model.psf_of_phase(torch.from_numpy(phi), float(z)).numpy())
    return {"psf": np.stack(psfs), "phase_error_rad": err}


def check_metalens_artifacts(folder: str | Path) -> dict[str, float]:
    """Reload the NPZ and the CSV profiles in ``folder``, propagate each, compare with ``psf.npz``.

    Returns
    -------
    dict
        ``rel_error_npz``, ``rel_error_csv`` (relative L2 against the written PSF) and
        ``phase_error_rad`` (interpolation error on the pupil nodes).

    Raises
    ------
    InputError
        A reloaded profile's PSF differs by more than :data:`PSF_RTOL`, or the CSV and NPZ profiles differ.
    """
    folder = Path(folder)
    with np.load(folder / "phase_profile.npz") as z:
        data = dict(z)
    with np.load(folder / "psf.npz") as z:
        written = np.asarray(z["psf"])
    r_csv, ph_csv = read_phase_profile_csv(folder / "phase_profile.csv")
    if not (np.array_equal(r_csv, data["radius_m"]) and np.array_equal(ph_csv, data["phase_rad"])):
        raise InputError(f"{folder}: phase_profile.csv and phase_profile.npz hold different profiles")
    out: dict[str, float] = {}
    for tag, kwargs in (("npz", {}), ("csv", {"radius_m": r_csv, "phase_rad": ph_csv})):
        res = psf_from_phase_profile(data, **kwargs)
        rel = float(np.linalg.norm(res["psf"] - written) / np.linalg.norm(written))
        if not rel <= PSF_RTOL:
            raise InputError(
                f"{folder}: the PSF propagated from the {tag} profile differs from psf.npz by {rel:.3g} "
                f"(relative L2; allowed {PSF_RTOL:g})"
            )
        out[f"rel_error_{tag}"] = rel
        out["phase_error_rad"] = res["phase_error_rad"]
    return out
