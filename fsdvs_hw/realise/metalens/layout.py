r"""From a phase profile to a layout: lattice sites, one pillar radius per site, and the GDSII file.

:func:`lattice_sites` places the sites of a square or hexagonal lattice inside the lens aperture;
:func:`assign_levels` gives each site the library radius whose complex transmission at the design
wavelength is nearest the wanted :math:`e^{i(\phi(r)+\theta)}` — amplitude and phase together,
so a resonant, dim pillar loses to a bright one of slightly worse phase — with the free global
phase :math:`\theta` chosen to minimise the total error; :func:`write_gds` writes the layout with
gdstk: one cell per radius level holding one circle, referenced once per site from the top cell,
on the design's layer and datatype (gdstk, BSL-1.0; Heitzmann Gabrielli, https://github.com/heitzmann/gdstk).

Example
-------
>>> import numpy as np
>>> from fsdvs_hw.realise.metalens.layout import assign_levels, lattice_sites
>>> sites = lattice_sites(1e-6, 300e-9, "square")
>>> len(sites)  # (i, j) with (0.3 i)² + (0.3 j)² ≤ 1 µm²
37
>>> t = np.exp(1j * np.linspace(0, 2 * np.pi, 16, endpoint=False))  # a lossless 16-level library
>>> levels, theta = assign_levels(np.array([0.0, np.pi]), t)
>>> int((levels[1] - levels[0]) % 16)
8
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError

__all__ = ["GdsSummary", "assign_levels", "lattice_sites", "read_gds_pillars", "write_gds"]

_N_OFFSETS = 90  # global phase offsets tried (4° steps)
_N_BINS = 720  # wanted-phase histogram bins (0.5°)


def lattice_sites(aperture_radius_m: float, period_m: float, lattice: str = "square") -> np.ndarray:
    """Centres (N, 2) in m of the lattice sites within ``aperture_radius_m`` of the optical axis.

    The lattice has a site on the axis; square: (iP, jP); hexagonal: rows jP√3/2 apart, odd
    rows shifted by P/2.
    """
    if not (0 < period_m <= aperture_radius_m):
        raise InputError(f"lattice period {period_m:.4g} m must be in (0, aperture radius {aperture_radius_m:.4g} m]")
    if lattice == "square":
        n = int(math.ceil(aperture_radius_m / period_m))
        i = np.arange(-n, n + 1)
        x, y = np.meshgrid(i * period_m, i * period_m)
    elif lattice == "hexagonal":
        dy = period_m * math.sqrt(3) / 2
        nx, ny = int(math.ceil(aperture_radius_m / period_m)) + 1, int(math.ceil(aperture_radius_m / dy))
        jj, ii = np.meshgrid(np.arange(-ny, ny + 1), np.arange(-nx, nx + 1), indexing="ij")
        x, y = (ii + 0.5 * (jj % 2)) * period_m, jj * dy
    else:
        raise InputError(f"lattice {lattice!r} unknown; allowed: square, hexagonal")
    pts = np.stack([x.ravel(), y.ravel()], axis=-1)
    return pts[np.hypot(pts[:, 0], pts[:, 1]) <= aperture_radius_m * (1 + 1e-12)]


def assign_levels(
    phase_rad: np.ndarray, transmission: np.ndarray, *, theta: float | None = None
) -> tuple[np.ndarray, float]:
    r"""Per site, the index of the library entry nearest :math:`e^{i(\phi+\theta)}` in the complex plane.

    Parameters
    ----------
    phase_rad : numpy.ndarray
        Wanted phase per site (rad, at the design wavelength).
    transmission : numpy.ndarray, complex, shape (levels,)
        The usable library entries' transmission at the design wavelength.
    theta : float, optional
        A given global phase offset (rad); default: the best one (below).

    Returns
    -------
    levels : numpy.ndarray of int
        Index into ``transmission`` per site.
    theta : float
        The global phase offset (rad) that minimises :math:`\sum_s |t_{l(s)} - e^{i(\phi_s+\theta)}|^2`
        (searched on a 4° grid over a 0.5° histogram of the wanted phases).
    """
    t = np.asarray(transmission, dtype=complex).ravel()
    if t.size == 0:
        raise InputError("the meta-atom library has no usable radius (all excluded as resonant or dim)")
    phi = np.mod(np.asarray(phase_rad, dtype=float), 2 * math.pi)
    if theta is not None:
        levels = np.argmin(np.abs(np.exp(1j * (phi + theta))[:, None] - t[None, :]), axis=1)
        return levels.astype(np.int32), float(theta)
    counts = np.bincount(np.minimum((phi / (2 * math.pi) * _N_BINS).astype(int), _N_BINS - 1), minlength=_N_BINS)
    centres = (np.arange(_N_BINS) + 0.5) * 2 * math.pi / _N_BINS
    offsets = np.arange(_N_OFFSETS) * 2 * math.pi / _N_OFFSETS
    wanted = np.exp(1j * (centres[None, :] + offsets[:, None]))  # (offsets, bins)
    err = np.min(np.abs(wanted[..., None] - t[None, None, :]) ** 2, axis=-1)  # (offsets, bins)
    theta = float(offsets[int(np.argmin(err @ counts))])
    levels = np.argmin(np.abs(np.exp(1j * (phi + theta))[:, None] - t[None, :]), axis=1)
    return levels.astype(np.int32), theta


@dataclass(frozen=True)
class GdsSummary:
    """What :func:`write_gds` wrote (or :func:`read_gds_pillars` read back).

    Attributes
    ----------
    path : pathlib.Path
        The GDSII file.
    pillars : int
        Pillar references (one per lattice site).
    levels : int
        Radius levels (cells) used.
    per_level : dict
        Cell name → references.
    """

    path: Path
    pillars: int
    levels: int
    per_level: dict[str, int]


def _level_name(index: int, radius_m: float) -> str:
    return f"PILLAR_{index:03d}_R{radius_m * 1e9:.1f}NM".replace(".", "P")


def write_gds(
    path: str | Path,
    lenses: list[tuple[np.ndarray, np.ndarray]],
    radii_m: np.ndarray,
    *,
    layer: int = 1,
    datatype: int = 0,
    tolerance_m: float = 1e-9,
    spacing_m: float = 0.0,
    name: str = "METALENS",
) -> GdsSummary:
    """Write the layout as GDSII (µm units, 1 nm precision), whole or not at all.

    Parameters
    ----------
    path : str or Path
        Output file.
    lenses : list of (sites (N, 2) in m, level index (N,))
        One entry per lens (a differential pair has two, placed ``spacing_m`` apart along x).
    radii_m : numpy.ndarray
        Radius (m) of each level index.
    layer, datatype : int
        GDSII layer and datatype of the pillars.
    tolerance_m : float
        Largest distance between a circle and its polygon (m).
    """
    import gdstk

    um = 1e6
    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    top = lib.new_cell(name)
    used = sorted({int(v) for _, lv in lenses for v in np.unique(lv)})
    cells = {}
    for i in used:
        cell = lib.new_cell(_level_name(i, float(radii_m[i])))
        cell.add(
            gdstk.ellipse((0, 0), float(radii_m[i]) * um, tolerance=tolerance_m * um, layer=layer, datatype=datatype)
        )
        cells[i] = cell
    per_level = dict.fromkeys((cells[i].name for i in used), 0)
    for k, (sites, levels) in enumerate(lenses):
        shift = np.array([k * spacing_m, 0.0])
        for i in used:
            pts = (sites[levels == i] + shift) * um
            if len(pts) == 0:
                continue
            ref = gdstk.Reference(cells[i], origin=(float(pts[0, 0]), float(pts[0, 1])))
            if len(pts) > 1:  # gdstk adds the origin itself to explicit offsets (one SREF each in the file)
                ref.repetition = gdstk.Repetition(offsets=[(float(x), float(y)) for x, y in pts[1:] - pts[0]])
            top.add(ref)
            per_level[cells[i].name] += len(pts)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    os.close(fd)
    try:
        lib.write_gds(tmp)
        os.chmod(tmp, 0o644)  # a file for the user (mkstemp makes it private)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return GdsSummary(path, sum(per_level.values()), len(used), per_level)


def read_gds_pillars(path: str | Path, *, name: str = "METALENS") -> GdsSummary:
    """Read a layout back with gdstk: pillar references per radius cell under the top cell ``name``."""
    import gdstk

    lib = gdstk.read_gds(str(path))
    tops = [c for c in lib.top_level() if isinstance(c, gdstk.Cell) and c.name == name]
    if not tops:
        raise InputError(f"{path}: no top cell {name!r}; top cells: {[c.name for c in lib.top_level()]}")
    per_level: dict[str, int] = {}
    for ref in tops[0].references:
        n = 1 if ref.repetition.size == 0 else ref.repetition.size
        per_level[ref.cell.name] = per_level.get(ref.cell.name, 0) + n
    return GdsSummary(Path(path), sum(per_level.values()), len(per_level), per_level)
