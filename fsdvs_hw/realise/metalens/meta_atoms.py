r"""Meta-atom library: the complex transmission of dielectric nano-pillars against their radius, by RCWA.

A metalens is a lattice of pillars (material, height, lattice and period fixed; the radius varies
from site to site). Each pillar, simulated in a periodic array of identical pillars at normal
incidence (the local-periodicity approximation), transmits the zero diffraction order with a
complex coefficient :math:`t(r, \lambda)`: its phase spans 2π over the radius range, its amplitude
dips near guided-mode resonances. :func:`compute_library` computes :math:`t` by rigorous
coupled-wave analysis with ``meent`` (MIT, numpy backend; Kim et al., "Meent: differentiable
electromagnetic simulator for machine learning", arXiv:2406.12904, 2024) at two truncation orders,
so that every entry carries its own convergence check; :func:`load_library` reads the committed
cache (``data/meta_atoms_<fingerprint>.json``) or a user cache (``$FSDVS_HW_CACHE/meta_atoms``)
when the inputs' fingerprint matches, and computes it (with a progress bar) otherwise.

Conventions
-----------
* Light enters from the substrate and leaves into air; the pillar sits on the substrate.
* Phase grows with optical path (fields :math:`\propto e^{+ikz}`, the project's lens convention;
  meent solves on :math:`e^{-ikz}` and its transmission is conjugated). ``t`` is normalised so
  that :math:`|t|^2` is the zero-order power transmission (meent's ``de_ti``).
* A radius is **usable** when at the design wavelength :math:`|t|^2 \ge` ``transmission_min``
  and its phase moves by at most ``phase_tolerance_rad`` between the two truncation orders
  (resonances, which move with the order, fail it).
* **Period rule**: the period must not exceed :math:`\lambda_{min}/n_{substrate}(\lambda_{min})`,
  else the lattice diffracts into the substrate and the zero order loses power (the SiN 1 µm
  pillar at 400 nm period loses transmission above r ≈ 110 nm for that reason; issue 40).

Materials are the cited refractive-index tables meent ships (refractiveindex.info database):
``TiO2_siefke`` (ALD TiO₂; Siefke et al., Adv. Opt. Mater. 4, 1780, 2016), ``Si3N4_luke`` (Luke et
al., Opt. Lett. 40, 4823, 2015), ``SiO2_malitson`` (fused silica; Malitson, JOSA 55, 1205, 1965),
or a number (a constant, lossless index).

Example
-------
A tiny library (3 radii, 1 wavelength, low orders; the committed default uses 225 harmonics):

>>> from fsdvs_hw.realise.metalens.meta_atoms import MetaAtomSpec, compute_library
>>> spec = MetaAtomSpec(radii_m=(50e-9, 80e-9, 110e-9), wavelengths_m=(555e-9,), fourier_orders=2,
...                     check_orders=1, raster=32)
>>> lib = compute_library(spec, progress=False)
>>> lib.transmission.shape, bool(abs(lib.transmission).max() <= 1.0 + 1e-9)
((1, 3), True)
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from dataclasses import asdict, dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ...fingerprints import fingerprint

__all__ = [
    "DATA_DIR",
    "LATTICES",
    "MetaAtomLibrary",
    "MetaAtomSpec",
    "compute_library",
    "library_path",
    "load_library",
    "refractive_index",
    "save_library",
]

#: Lattices of pillar sites.
LATTICES = ("square", "hexagonal")

#: The committed libraries (package data).
DATA_DIR = Path(__file__).resolve().parent / "data"

_SCHEMA = "fsdvs_hw.meta_atoms/1"


@cache
def _material_table() -> dict[str, Any]:
    from meent.on_numpy.modeler.modeling import read_material_table  # type: ignore[import-untyped]

    return read_material_table()


def refractive_index(material: str | float, wavelength_m: float) -> complex:
    """Complex refractive index n + ik of ``material`` at ``wavelength_m`` (m).

    ``material`` is a name of meent's cited tables (``"TiO2_siefke"``, ``"SiO2_malitson"``,
    ``"Si3N4_luke"``, …) or a number (constant, lossless).

    Example
    -------
    >>> round(refractive_index("SiO2_malitson", 555e-9).real, 4)
    1.4597
    """
    if isinstance(material, (int, float)) and not isinstance(material, bool):
        return complex(float(material))
    from meent.on_numpy.modeler.modeling import find_nk_index

    table = _material_table()
    if str(material).upper() not in table:
        names = sorted(k for k in table if not k.startswith("["))
        raise InputError(f"material {material!r} unknown; allowed: a number or one of {', '.join(names)}")
    nk = complex(find_nk_index(str(material), table, float(wavelength_m)))
    return complex(nk.real, abs(nk.imag))  # meent returns n - ik; report n + ik


@dataclass(frozen=True)
class MetaAtomSpec:
    """Everything a meta-atom library depends on (its fingerprint is the cache key).

    Attributes
    ----------
    material, substrate : str or float
        Pillar and substrate materials (module docstring); default ALD TiO₂ on fused silica.
    height_m : float
        Pillar height (m); default 600 nm.
    period_m : float
        Lattice period (m); default 300 nm (≤ λ_min / n_substrate at 460 nm).
    lattice : {"square", "hexagonal"}
        Lattice of the sites (hexagonal: the RCWA cell is P × P√3 with two pillars).
    radii_m : tuple of float
        Pillar radii (m), ascending; default 40 … 125 nm in 44 steps (min width 80 nm, min gap 50 nm).
    wavelengths_m : tuple of float
        Wavelengths (m), ascending; the PSF interpolates between them (amplitude and unwrapped phase).
    fourier_orders : int
        Truncation order per axis (harmonics (2N+1)²); default 7 → 225.
    check_orders : int
        The second, lower truncation order of the convergence check; default 5 → 121.
    raster : int
        Permittivity raster per period side (area-weighted cells, so t varies smoothly with r).
    """

    material: str | float = "TiO2_siefke"
    substrate: str | float = "SiO2_malitson"
    height_m: float = 600e-9
    period_m: float = 300e-9
    lattice: str = "square"
    radii_m: tuple[float, ...] = tuple(float(v) for v in np.round(np.linspace(40e-9, 125e-9, 44), 12))
    wavelengths_m: tuple[float, ...] = (460e-9, 510e-9, 555e-9, 600e-9, 650e-9)
    fourier_orders: int = 7
    check_orders: int = 5
    raster: int = 64

    def __post_init__(self) -> None:
        if self.lattice not in LATTICES:
            raise InputError(f"meta-atom lattice {self.lattice!r} unknown; allowed: {', '.join(LATTICES)}")
        radii, lam = np.asarray(self.radii_m, float), np.asarray(self.wavelengths_m, float)
        if radii.size < 2 or np.any(np.diff(radii) <= 0) or radii[0] <= 0:
            raise InputError(f"meta-atom radii_m must be ≥ 2 positive ascending radii (m), got {self.radii_m!r}")
        if lam.size < 1 or np.any(np.diff(lam) <= 0) or not (lam[0] >= 100e-9 and lam[-1] <= 20e-6):
            raise InputError(
                f"meta-atom wavelengths_m must be ascending in [100 nm, 20 µm], got {self.wavelengths_m!r}"
            )
        if 2 * radii[-1] >= self.period_m:
            raise InputError(
                f"meta-atom radius {radii[-1]:.4g} m: pillars of diameter {2 * radii[-1]:.4g} m touch at period "
                f"{self.period_m:.4g} m"
            )
        if not (0 < self.height_m <= 20e-6 and 0 < self.period_m <= 20e-6):
            raise InputError(
                f"meta-atom height_m and period_m must be in (0, 20 µm], got {self.height_m}, {self.period_m}"
            )
        if not (1 <= self.check_orders < self.fourier_orders <= 20):
            raise InputError(
                f"meta-atom orders: need 1 ≤ check_orders ({self.check_orders}) < fourier_orders ({self.fourier_orders}) ≤ 20"
            )
        if not 8 <= self.raster <= 512:
            raise InputError(f"meta-atom raster must be in 8..512 cells per period, got {self.raster}")
        n_sub = refractive_index(self.substrate, lam[0]).real
        if self.period_m > lam[0] / n_sub * (1 + 1e-9):
            raise InputError(
                f"meta-atom period_m={self.period_m:.4g} m exceeds λ_min/n_substrate = {lam[0]:.4g}/{n_sub:.4f} = "
                f"{lam[0] / n_sub:.4g} m: the lattice diffracts into the substrate (zero order loses power); "
                "use a smaller period or a longer shortest wavelength"
            )

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["radii_m"], d["wavelengths_m"] = list(self.radii_m), list(self.wavelengths_m)
        return d

    @property
    def fingerprint(self) -> str:
        """The cache key: the spec, the solver and its version (12 hex characters)."""
        return fingerprint({"spec": self.to_dict(), "solver": _solver_name()}, length=12)


def _solver_name() -> str:
    from importlib.metadata import version

    return f"meent {version('meent')} (numpy backend, TMM, discrete Fourier series)"


@dataclass(frozen=True, eq=False)
class MetaAtomLibrary:
    """Complex zero-order transmission of the pillars of :attr:`spec`, at two truncation orders.

    Attributes
    ----------
    spec : MetaAtomSpec
        What was computed.
    transmission : numpy.ndarray, complex, shape (wavelengths, radii)
        t at ``spec.fourier_orders`` (module conventions).
    check_transmission : numpy.ndarray, complex, shape (wavelengths, radii)
        t at ``spec.check_orders`` (the convergence check).
    provenance : dict
        Solver and version, harmonics, compute time (s), date, fingerprint.
    """

    spec: MetaAtomSpec
    transmission: np.ndarray
    check_transmission: np.ndarray
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def radii_m(self) -> np.ndarray:
        return np.asarray(self.spec.radii_m, dtype=float)

    @property
    def wavelengths_m(self) -> np.ndarray:
        return np.asarray(self.spec.wavelengths_m, dtype=float)

    def index_of_wavelength(self, wavelength_m: float) -> int:
        """Index of a library wavelength within 0.1 nm of ``wavelength_m``."""
        i = int(np.argmin(np.abs(self.wavelengths_m - wavelength_m)))
        if abs(self.wavelengths_m[i] - wavelength_m) > 1e-10:
            raise InputError(
                f"wavelength {wavelength_m:.4g} m is not one of the meta-atom library's "
                f"{[round(v * 1e9, 1) for v in self.wavelengths_m]} nm; add it to the library's wavelengths"
            )
        return i

    def phase_change(self, wavelength_m: float) -> np.ndarray:
        """|Δφ| (rad) per radius between the two truncation orders at a library wavelength."""
        i = self.index_of_wavelength(wavelength_m)
        return np.abs(np.angle(self.transmission[i] * np.conj(self.check_transmission[i])))

    def usable(
        self, wavelength_m: float, *, transmission_min: float = 0.5, phase_tolerance_rad: float = 0.1
    ) -> np.ndarray:
        """Mask of usable radii at ``wavelength_m`` (module docstring): transmitting and converged."""
        i = self.index_of_wavelength(wavelength_m)
        power = np.abs(self.transmission[i]) ** 2
        return (power >= transmission_min) & (self.phase_change(wavelength_m) <= phase_tolerance_rad)

    def at_wavelengths(self, wavelengths_m: np.ndarray) -> np.ndarray:
        """t (len(wavelengths_m), radii) interpolated linearly in amplitude and unwrapped phase.

        Raises
        ------
        InputError
            A wavelength outside the library's range (by more than 0.5 nm).
        """
        lam = np.asarray(wavelengths_m, dtype=float)
        lo, hi = self.wavelengths_m[0], self.wavelengths_m[-1]
        if lam.min() < lo - 5e-10 or lam.max() > hi + 5e-10:
            raise InputError(
                f"the spectrum's wavelengths {lam.min() * 1e9:.1f}–{lam.max() * 1e9:.1f} nm leave the meta-atom "
                f"library's {lo * 1e9:.1f}–{hi * 1e9:.1f} nm; widen its wavelengths"
            )
        t = self.transmission
        if t.shape[0] == 1:
            return np.repeat(t, lam.size, axis=0)
        amp, phase = np.abs(t), np.unwrap(np.angle(t), axis=0)
        out = np.empty((lam.size, t.shape[1]), dtype=complex)
        for j in range(t.shape[1]):
            out[:, j] = np.interp(lam, self.wavelengths_m, amp[:, j]) * np.exp(
                1j * np.interp(lam, self.wavelengths_m, phase[:, j])
            )
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": _SCHEMA,
            "spec": self.spec.to_dict(),
            "fingerprint": self.spec.fingerprint,
            "provenance": dict(self.provenance),
            "transmission_re": self.transmission.real.tolist(),
            "transmission_im": self.transmission.imag.tolist(),
            "check_transmission_re": self.check_transmission.real.tolist(),
            "check_transmission_im": self.check_transmission.imag.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MetaAtomLibrary:
        try:
            spec_d = dict(data["spec"])
            spec_d["radii_m"] = tuple(spec_d["radii_m"])
            spec_d["wavelengths_m"] = tuple(spec_d["wavelengths_m"])
            t = np.asarray(data["transmission_re"], float) + 1j * np.asarray(data["transmission_im"], float)
            c = np.asarray(data["check_transmission_re"], float) + 1j * np.asarray(data["check_transmission_im"], float)
            return cls(MetaAtomSpec(**spec_d), t, c, dict(data.get("provenance", {})))
        except (KeyError, TypeError) as exc:
            raise InputError(f"meta-atom library: malformed record ({type(exc).__name__}: {exc})") from None


def _area_fractions(spec: MetaAtomSpec, radius_m: float) -> np.ndarray:
    """Pillar area fraction of each raster cell of the RCWA unit cell (8×8 sub-samples per cell)."""
    p, n, s = spec.period_m, spec.raster, 8
    if spec.lattice == "square":
        width, height, centres = p, p, [(0.0, 0.0)]
    else:  # rectangular cell P × P√3 holding a pillar at the centre and one at the corners
        width, height = p, p * math.sqrt(3)
        centres = [(0.0, 0.0)] + [(sx * p / 2, sy * height / 2) for sx in (-1, 1) for sy in (-1, 1)]
    ny = int(round(n * height / width))
    x = ((np.arange(n * s) + 0.5) / (n * s) - 0.5) * width
    y = ((np.arange(ny * s) + 0.5) / (ny * s) - 0.5) * height
    xx, yy = np.meshgrid(x, y)
    inside = np.zeros_like(xx, dtype=bool)
    for cx, cy in centres:
        inside |= (xx - cx) ** 2 + (yy - cy) ** 2 <= radius_m**2
    return inside.reshape(ny, s, n, s).mean(axis=(1, 3))


def _rcwa_transmission(spec: MetaAtomSpec, radius_m: float, wavelength_m: float, orders: int) -> complex:
    """Zero-order complex transmission of one pillar array (meent, numpy backend)."""
    import meent  # type: ignore[import-untyped]

    n_pillar = refractive_index(spec.material, wavelength_m)
    n_sub = refractive_index(spec.substrate, wavelength_m).real
    frac = _area_fractions(spec, radius_m)
    eps = frac * n_pillar**2 + (1 - frac) * 1.0
    ucell = np.conj(np.sqrt(eps))[None]  # meent's n - ik
    nm = 1e9
    cell = (spec.period_m * nm, spec.period_m * nm * (1 if spec.lattice == "square" else math.sqrt(3)))
    mee = meent.call_mee(
        backend=0,
        pol=1,
        n_top=n_sub,
        n_bot=1.0,
        theta=0.0,
        phi=0.0,
        psi=0.0,
        fto=[orders, orders],
        wavelength=wavelength_m * nm,
        thickness=[spec.height_m * nm],
        period=list(cell),
        ucell=ucell if np.iscomplexobj(ucell) and np.any(ucell.imag) else ucell.real,
        type_complex=np.complex128,
    )
    res = mee.conv_solve().res
    amplitude = math.sqrt(max(float(np.real(res.de_ti[orders, orders])), 0.0))
    return amplitude * np.exp(-1j * np.angle(res.T_p[orders, orders]))


def compute_library(spec: MetaAtomSpec, *, progress: bool | None = None) -> MetaAtomLibrary:
    """Compute the library of ``spec`` by RCWA at both truncation orders (module docstring).

    Cost: one RCWA solve per (wavelength, radius, order); about 1 s at 225 harmonics on one core.
    """
    from ...progress import progress_bar

    t0, c0 = time.perf_counter(), time.process_time()
    lam, radii = spec.wavelengths_m, spec.radii_m
    t = np.empty((len(lam), len(radii)), dtype=complex)
    check = np.empty_like(t)
    with progress_bar(total=t.size, desc="meta-atom library (RCWA)", unit="pillar", progress=progress) as bar:
        for i, wl in enumerate(lam):
            for j, r in enumerate(radii):
                t[i, j] = _rcwa_transmission(spec, r, wl, spec.fourier_orders)
                check[i, j] = _rcwa_transmission(spec, r, wl, spec.check_orders)
                bar.update(1)
    provenance = {
        "solver": _solver_name(),
        "harmonics": (2 * spec.fourier_orders + 1) ** 2,
        "check_harmonics": (2 * spec.check_orders + 1) ** 2,
        "polarisation": "p (circular pillars at normal incidence: polarisation-independent)",
        "fingerprint": spec.fingerprint,
        "wall_time_s": time.perf_counter() - t0,
        "cpu_time_s": time.process_time() - c0,
        "computed": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "materials": {
            "pillar": str(spec.material),
            "substrate": str(spec.substrate),
            "source": "meent nk_data (refractiveindex.info database; see the module docstring)",
        },
    }
    return MetaAtomLibrary(spec, t, check, provenance)


def _user_cache_dir() -> Path:
    from ...environment import env

    root = env("FSDVS_HW_CACHE") or os.path.join(os.environ.get("XDG_CACHE_HOME") or "~/.cache", "fsdvs_hw")
    return Path(root).expanduser() / "meta_atoms"


def library_path(spec: MetaAtomSpec, folder: str | Path | None = None) -> Path:
    """Where the library of ``spec`` is cached: ``<folder>/meta_atoms_<fingerprint>.json``."""
    return Path(folder if folder is not None else DATA_DIR) / f"meta_atoms_{spec.fingerprint}.json"


def save_library(library: MetaAtomLibrary, path: str | Path) -> Path:
    """Write ``library`` as JSON, whole or not at all (temporary file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(library.to_dict(), fh, indent=1)
        fh.write("\n")
    os.chmod(tmp, 0o644)  # mkstemp's 0600 would keep a shared cache from other users
    os.replace(tmp, path)
    return path


def load_library(spec: MetaAtomSpec, *, compute: bool = True, progress: bool | None = None) -> MetaAtomLibrary:
    """The library of ``spec``: the committed one, else the user cache, else computed (and cached).

    A cached file is used only when its fingerprint (spec, solver and version) matches.

    Raises
    ------
    InputError
        Not cached and ``compute`` is false.
    """
    for folder in (DATA_DIR, _user_cache_dir()):
        path = library_path(spec, folder)
        if path.is_file():
            data = json.loads(path.read_text())
            if data.get("fingerprint") == spec.fingerprint:
                return MetaAtomLibrary.from_dict(data)
    if not compute:
        raise InputError(f"no cached meta-atom library for fingerprint {spec.fingerprint} (looked in {DATA_DIR})")
    library = compute_library(spec, progress=progress)
    try:
        save_library(library, library_path(spec, _user_cache_dir()))
    except OSError:  # a read-only home: the library still serves this run
        pass
    return library


if __name__ == "__main__":  # python -m fsdvs_hw.realise.metalens.meta_atoms: (re)compute the committed default
    _default = MetaAtomSpec()
    print(save_library(compute_library(_default, progress=True), library_path(_default)))
