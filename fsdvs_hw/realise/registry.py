"""The one registry of realisations: every hardware form and every ideal reference, by name.

Each realisation declares a :class:`RealisationSpec` — its name, options schema
(a pydantic model, :mod:`fsdvs_hw.schema`: type, unit, range, default, help), fit function, declared
cost items (:class:`CostSpec`: name, unit, and which of them the report uses as the kind's Pareto
axis and headline), the record class that rebuilds it from JSON, and the artifacts it can write
with the ``"module:function"`` that writes them (:mod:`fsdvs_hw.realise.artifacts`) — and
registers it with :func:`register_realisation`. Everything downstream reads only this
registry: the design loader (allowed names, option tables, sweep axes), the scorer (which fit to
call), the sweep (which sweep keys belong to a realisation), the report (cost axes, headline costs,
colours, which rows are references) and :func:`realisation_from_dict`.

The built-in entries are registered when :mod:`fsdvs_hw.realise` is imported: the ideal
references ``learned`` and ``delta`` (kind ``"reference"``, here), and the hardware forms
``mesh``, ``asic`` and ``metalens`` (kind ``"hardware"``, each in its own folder's ``__init__``).

Adding a realisation outside the package is one module::

    from fsdvs_hw.realise.registry import CostSpec, RealisationSpec, register_realisation
    register_realisation(RealisationSpec(name="box", fit=fit_box, options=BoxOptions, record_type=BoxDesign,
                                         costs=(CostSpec("taps", "count", pareto=True, headline=True),)))

An installed package registers its realisations through the entry-point group
:data:`ENTRY_POINT_GROUP` (``fsdvs_hw.realisations``), which every process loads, spawned and
remote Dask workers included. A module registered at run time without being installed is recorded
in the environment variable :data:`PLUGIN_ENV`, so spawned workers (``[run] workers > 1``) import
it too; remote Dask workers must import it themselves.

References
----------
The ``method=`` registries of colour-science (``colour.utilities.CanonicalMapping``) and
:func:`fsdvs_hw.tasks.evaluators.register_evaluator` follow the same pattern.
"""

from __future__ import annotations

import importlib
import math
import os
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ..environment import env, set_env
from ..errors import InputError
from ..kernels import Kernel, as_kernel, reference_kernel
from ..schema import StrictModel, validate
from .artifacts import Artifact
from .base import Realisation, ReferenceRealisation

__all__ = [
    "ENTRY_POINT_GROUP",
    "KINDS",
    "PLUGIN_ENV",
    "REALISATIONS",
    "CostSpec",
    "NoOptions",
    "RealisationSpec",
    "check_realisation_options",
    "fit_realisation",
    "get_realisation",
    "realisation_from_dict",
    "realisation_names",
    "register_realisation",
    "unregister_realisation",
]

#: What a realisation is: a hardware form (has a cost; on the per-kind Pareto fronts) or an ideal
#: reference scored the same way (no cost; never on a front).
KINDS: tuple[str, ...] = ("hardware", "reference")

#: Environment variable listing the modules outside fsdvs_hw that registered realisations at run
#: time (``os.pathsep``-separated); spawned workers import them (:mod:`fsdvs_hw.environment`).
PLUGIN_ENV = "FSDVS_HW_REALISATION_PLUGINS"

#: Entry-point group of installed realisation plugins: each entry point names a module (imported:
#: its module-level :func:`register_realisation` calls register) or a callable (called once). Every
#: process, spawned workers and remote Dask workers included, loads them when it imports
#: :mod:`fsdvs_hw.realise`. In a plugin's ``pyproject.toml``::
#:
#:     [project.entry-points."fsdvs_hw.realisations"]
#:     box = "box_filter.realisation"
ENTRY_POINT_GROUP = "fsdvs_hw.realisations"

#: Units a cost item may carry: SI units, "count", "bit", "px" and "1" (dimensionless).
COST_UNITS: frozenset[str] = frozenset({"S", "F", "s", "m", "m^2", "W", "J", "A", "V", "Hz", "count", "bit", "px", "1"})


@dataclass(frozen=True)
class CostSpec:
    """One declared cost item of a realisation.

    Parameters
    ----------
    name : str
        The item's name in ``realisation.cost()`` (``"area_m2"``), or a derived quantity's name
        when ``derive`` is given (``"conductance_per_pixel"``).
    unit : str
        Unit of the stored value (one of :data:`COST_UNITS`).
    label : str
        A few words for tables and axes (default: ``name``).
    display_unit : str
        Unit shown in the report (default: ``unit``).
    factor : float
        Stored value × ``factor`` = displayed value (``1e12`` for m² → µm²).
    pareto : bool
        A candidate for the kind's own cost axis of its Pareto front; the first declared candidate
        present in a point's cost is used.
    headline : bool
        A candidate for the point's single headline cost (first present wins).
    optional : bool
        Not every fit reports it (e.g. yosys cells only when yosys ran).
    derive : callable, optional
        ``derive(cost) -> value or None`` from the stored cost items (name → ``{"value", "unit"}``),
        for a quantity that is not an item itself.

    Examples
    --------
    >>> from fsdvs_hw import CostSpec
    >>> c = CostSpec("adders", "count", "adders", pareto=True, headline=True)
    >>> c.name, c.unit, c.pareto
    ('adders', 'count', True)
    """

    name: str
    unit: str
    label: str = ""
    display_unit: str = ""
    factor: float = 1.0
    pareto: bool = False
    headline: bool = False
    optional: bool = False
    derive: Callable[[Mapping[str, Mapping[str, Any]]], float | None] | None = None

    def __post_init__(self) -> None:
        if self.unit not in COST_UNITS:
            raise InputError(
                f"cost item {self.name!r}: unit {self.unit!r} unknown; allowed: {', '.join(sorted(COST_UNITS))}"
            )
        if not (math.isfinite(self.factor) and self.factor > 0):
            raise InputError(f"cost item {self.name!r}: factor must be a finite number > 0, got {self.factor!r}")

    def value(self, cost: Mapping[str, Mapping[str, Any]]) -> float | None:
        """The stored (SI) value of this item in ``cost``, or None when it is absent."""
        if self.derive is not None:
            v = self.derive(cost)
        else:
            v = (cost.get(self.name) or {}).get("value")
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None


class NoOptions(StrictModel):
    """The options model of a realisation whose fit takes none (the references)."""

    unknown_key = "the fit function takes no options"


@dataclass(frozen=True)
class RealisationSpec:
    """A realisation's registry entry.

    Parameters
    ----------
    name : str
        The name used in design files (``[realisations] include``, ``[realisations.<name>]``),
        sweep keys (``"<name>.<option>"``), stored points and reports. A Python identifier.
    fit : callable
        ``fit(target, **options) -> Realisation``. If ``options`` declares ``pitch_m`` or ``seed``
        and the design does not set them, the target's pitch and the design's ``[run] seed`` are
        passed.
    options : type of fsdvs_hw.schema.StrictModel
        Model of every keyword option of ``fit`` (type, unit, range, default, help; one field per
        option), which design files and the fit function check against (default: none).
    kind : {"hardware", "reference"}
        Hardware forms have costs and Pareto fronts; references are ideal kernels scored alike.
    record_type : type, optional
        The class ``fit`` returns: ``record_type.from_dict(realisation.to_dict())`` rebuilds it.
    record_kind : str
        The ``"kind"`` key its ``to_dict()`` writes (default: ``name``).
    costs : tuple of CostSpec
        Declared cost items: units, the Pareto axis and headline candidates.
    artifacts : mapping of str to str
        Files the realisation can write (name → what, e.g. ``"verilog": "streaming filter RTL"``).
    write_artifacts : str
        ``"module:function"`` of the writer of those files (:mod:`fsdvs_hw.realise.artifacts`):
        ``function(record, out_dir, *, resolution) -> sequence of Artifact`` writes them for a
        fitted record into ``out_dir`` (``resolution``: the sensor's (H, W) in pixels); every
        returned name must be declared in ``artifacts``. ``""``: writes none (the references).
        A string, so registering imports nothing; ``fsdvs-hw explore`` calls it for every scored
        point (:meth:`write_artifacts_of`).
    colour : str
        Colour of its points and lines in every report figure (matplotlib colour).
    title : str
        Its name for people, in report tables and legends (``"resistive mesh"``; default: ``name``).
    marker : str
        Matplotlib marker of its points in report figures (default: one picked by the report so
        that no two registered realisations share one).
    in_default_design : bool
        Listed in ``[realisations] include`` when a design does not say.
    description : str
        One line for help texts.
    differentiable : str
        ``"module:Class"`` of a torch module that wraps a fitted record as a differentiable kernel
        of its physical parameters (``Class(record)()`` → the applied kernel, ``.to_design()`` →
        a record), for co-design; ``""``: none. A string, so registering does not import torch.

    Examples
    --------
    >>> from fsdvs_hw import RealisationSpec
    >>> from fsdvs_hw.realise.registry import fit_delta
    >>> spec = RealisationSpec("impulse", fit_delta, kind="reference", title="impulse")
    >>> spec.name, spec.kind, list(spec.options.model_fields)
    ('impulse', 'reference', [])
    """

    name: str
    fit: Callable[..., Realisation]
    options: type[StrictModel] = NoOptions
    kind: str = "hardware"
    record_type: type | None = None
    record_kind: str = ""
    costs: tuple[CostSpec, ...] = ()
    artifacts: Mapping[str, str] = field(default_factory=dict)
    colour: str | None = None
    title: str = ""
    marker: str = ""
    in_default_design: bool = False
    description: str = ""
    differentiable: str = ""
    write_artifacts: str = ""

    def __post_init__(self) -> None:
        if not (isinstance(self.name, str) and self.name.isidentifier()):
            raise InputError(f"realisation name {self.name!r}: must be a Python identifier (it is a design-file key)")
        if self.kind not in KINDS:
            raise InputError(f"realisation {self.name!r}: kind {self.kind!r} unknown; allowed: {', '.join(KINDS)}")
        if not callable(self.fit):
            raise InputError(f"realisation {self.name!r}: fit must be callable, got {type(self.fit).__name__}")
        if not (isinstance(self.options, type) and issubclass(self.options, StrictModel)):
            raise InputError(
                f"realisation {self.name!r}: options must be a fsdvs_hw.schema.StrictModel subclass, "
                f"got {self.options!r}"
            )
        object.__setattr__(self, "artifacts", MappingProxyType(dict(self.artifacts)))
        for field_name in ("differentiable", "write_artifacts"):
            ref = getattr(self, field_name)
            if not isinstance(ref, str) or (ref and ref.count(":") != 1):
                raise InputError(f"realisation {self.name!r}: {field_name} must be 'module:name' or '', got {ref!r}")
        if not self.record_kind:
            object.__setattr__(self, "record_kind", self.name)

    def differentiable_kernel(self, record: Realisation) -> Any:
        """The torch module of :attr:`differentiable` around ``record`` (a fitted realisation).

        Raises
        ------
        InputError
            The realisation declares no differentiable form.
        """
        if not self.differentiable:
            with_form = [n for n, sp in _REGISTRY.items() if sp.differentiable]
            raise InputError(
                f"realisation {self.name!r} has no differentiable form; realisations with one: "
                f"{', '.join(with_form) or 'none'}"
            )
        module, cls = self.differentiable.split(":")
        return getattr(importlib.import_module(module), cls)(record)

    def write_artifacts_of(
        self, record: Realisation, out_dir: str | Path, *, resolution: tuple[int, int] | None = None
    ) -> tuple[Artifact, ...]:
        """Write the buildable files of ``record`` (a fitted realisation) into ``out_dir``.

        Returns
        -------
        tuple of Artifact
            What was written; empty when the realisation declares no :attr:`write_artifacts`.

        Raises
        ------
        InputError
            The writer returned something other than :class:`Artifact` records of declared names.
        """
        if not self.write_artifacts:
            return ()
        module, name = self.write_artifacts.split(":")
        writer = getattr(importlib.import_module(module), name)
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        kwargs = {} if resolution is None else {"resolution": tuple(int(v) for v in resolution)}
        written = tuple(writer(record, out, **kwargs))
        for a in written:
            if not isinstance(a, Artifact) or a.name not in self.artifacts:
                raise InputError(
                    f"realisation {self.name!r}: its writer {self.write_artifacts} returned "
                    f"{getattr(a, 'name', a)!r}; declared artifacts: {', '.join(self.artifacts) or 'none'}"
                )
        return written

    @property
    def fit_name(self) -> str:
        """The fit function's name (for messages)."""
        return getattr(self.fit, "__name__", repr(self.fit))

    def check_option(self, key: str, value: Any) -> Any:
        """Check one option against :attr:`options`; return it normalised (an int for a number
        option becomes a float)."""
        return self.check_options({key: value})[key]

    def check_options(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Check a table of options; return the given ones normalised, in the given order.

        Raises
        ------
        InputError
            Every unknown option, wrong type or value out of range, each naming the option, the
            value and what is allowed.
        """
        if not isinstance(values, Mapping):
            raise InputError(f"options of {self.fit_name}: must be a table, got {type(values).__name__}")
        given = validate(self.options, values).model_dump(exclude_unset=True)
        return {k: given[k] for k in values}

    def cost_axis(self, cost: Mapping[str, Mapping[str, Any]]) -> tuple[str, float, str] | None:
        """``(label, displayed value, display unit)`` on the kind's own Pareto axis, or None."""
        for c in self.costs:
            if c.pareto:
                v = c.value(cost)
                if v is not None:
                    return c.label or c.name, v * c.factor, c.display_unit or c.unit
        return None

    def headline(self, cost: Mapping[str, Mapping[str, Any]]) -> str | None:
        """Name of the first declared headline cost item present in ``cost``, or None."""
        return next((c.name for c in self.costs if c.headline and c.derive is None and c.name in cost), None)


_REGISTRY: dict[str, RealisationSpec] = {}

#: name → spec of every registered realisation, in registration order (read-only view).
REALISATIONS: Mapping[str, RealisationSpec] = MappingProxyType(_REGISTRY)


def register_realisation(spec: RealisationSpec, *, replace: bool = False) -> RealisationSpec:
    """Add a realisation to the registry; return it (usable as a module-level statement).

    Raises
    ------
    InputError
        ``spec`` is not a :class:`RealisationSpec`, or its name is taken and ``replace`` is false.

    Examples
    --------
    >>> from fsdvs_hw import RealisationSpec, reference_kernel, register_realisation
    >>> from fsdvs_hw.realise.registry import fit_delta, fit_realisation, realisation_names, unregister_realisation
    >>> spec = register_realisation(RealisationSpec("impulse", fit_delta, kind="reference", title="impulse"))
    >>> "impulse" in realisation_names("reference")
    True
    >>> real = fit_realisation("impulse", reference_kernel("dog", 5))
    >>> float(real.kernel().taps.sum()), float(real.kernel().taps[2, 2])
    (1.0, 1.0)
    >>> unregister_realisation("impulse")
    >>> "impulse" in realisation_names()
    False
    """
    if not isinstance(spec, RealisationSpec):
        raise InputError(f"register_realisation: expected a RealisationSpec, got {type(spec).__name__}")
    if spec.name in _REGISTRY and not replace and _REGISTRY[spec.name] is not spec:
        raise InputError(f"realisation {spec.name!r} is already registered (pass replace=True to replace it)")
    _REGISTRY[spec.name] = spec
    module = getattr(spec.fit, "__module__", "") or ""
    if module and module != "__main__" and not module.startswith("fsdvs_hw."):
        known = _plugin_modules()
        if module not in known:
            set_env(PLUGIN_ENV, os.pathsep.join([*known, module]))
    return spec


def unregister_realisation(name: str) -> None:
    """Remove a realisation (tests and interactive sessions); unknown names are ignored."""
    spec = _REGISTRY.pop(name, None)
    module = getattr(getattr(spec, "fit", None), "__module__", "") or ""
    known = _plugin_modules()
    if module in known and not any(getattr(s.fit, "__module__", "") == module for s in _REGISTRY.values()):
        set_env(PLUGIN_ENV, os.pathsep.join(m for m in known if m != module) or None)


def _plugin_modules() -> list[str]:
    return [m for m in (env(PLUGIN_ENV) or "").split(os.pathsep) if m]


def import_plugins() -> None:
    """Load the installed plugins (:data:`ENTRY_POINT_GROUP`) and the modules named in :data:`PLUGIN_ENV`
    (spawned workers inherit the variable). A plugin that fails to load is reported as a warning
    naming it and the error; the built-in realisations stay usable."""
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            loaded = ep.load()
            if callable(loaded):
                loaded()
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break the package
            warnings.warn(
                f"realisation plugin {ep.name!r} ({ep.value}) failed to load: {type(exc).__name__}: {exc}",
                RuntimeWarning,
                stacklevel=2,
            )
    for module in _plugin_modules():
        importlib.import_module(module)


def get_realisation(name: str) -> RealisationSpec:
    """The registered spec called ``name``.

    Raises
    ------
    InputError
        Unknown name; the message lists the registered ones.

    Examples
    --------
    >>> from fsdvs_hw import get_realisation
    >>> spec = get_realisation("asic")
    >>> spec.name, [c.name for c in spec.costs][:2]
    ('asic', ['area_m2', 'yosys_cells'])
    """
    spec = _REGISTRY.get(name) if isinstance(name, str) else None
    if spec is None:
        raise InputError(f"realisation {name!r} unknown; allowed: {', '.join(_REGISTRY)}")
    return spec


def realisation_names(kind: str | None = None) -> tuple[str, ...]:
    """Registered names in registration order, optionally of one ``kind`` (``"hardware"``/``"reference"``).

    Examples
    --------
    >>> from fsdvs_hw import realisation_names
    >>> realisation_names()
    ('learned', 'delta', 'mesh', 'mesh_process', 'asic', 'metalens', 'metalens_layout')
    """
    if kind is not None and kind not in KINDS:
        raise InputError(f"realisation kind {kind!r} unknown; allowed: {', '.join(KINDS)}")
    return tuple(n for n, s in _REGISTRY.items() if kind is None or s.kind == kind)


def realisation_from_dict(data: Mapping[str, Any]) -> Realisation:
    """Rebuild a realisation from :meth:`Realisation.to_dict` output (its ``"kind"`` names the record)."""
    kind = data.get("kind") if isinstance(data, Mapping) else None
    # record classes, each with from_dict(mapping) -> Realisation (RealisationSpec.record_type)
    types: dict[str, Any] = {s.record_kind: s.record_type for s in _REGISTRY.values() if s.record_type is not None}
    if kind not in types:
        raise InputError(f"realisation 'kind' is {kind!r}; allowed: {', '.join(types)}")
    return types[kind].from_dict(data)


def check_realisation_options(name: str, values: Mapping[str, Any]) -> dict[str, Any]:
    """Check a table of fit options of the realisation ``name``; return them normalised."""
    return get_realisation(name).check_options(values)


def fit_realisation(
    name: str, target: Kernel | Any, options: Mapping[str, Any] | None = None, *, seed: int = 0
) -> Realisation:
    """Fit the realisation ``name`` to ``target`` with its options.

    ``target`` is anything :func:`~fsdvs_hw.kernels.as_kernel` accepts (a Kernel, a kernel file,
    odd k×k taps at the default pitch). The target's pitch (m) is passed as ``pitch_m`` and
    ``seed`` as ``seed`` where the realisation declares them as options and ``options`` does not
    set them.
    """
    target = as_kernel(target, name="target")
    spec = get_realisation(name)
    options = dict(options or {})
    if "pitch_m" in spec.options.model_fields and "pitch_m" not in options:
        options["pitch_m"] = target.pitch_m
    if "seed" in spec.options.model_fields and "seed" not in options:
        options["seed"] = seed
    return spec.fit(target, **options)


# --------------------------------------------------------------------------- the ideal references
def fit_learned(target: Kernel) -> ReferenceRealisation:
    """The target kernel applied ideally (the row every loss is measured against)."""
    return ReferenceRealisation(target, label="learned")


def fit_delta(target: Kernel) -> ReferenceRealisation:
    """The delta kernel of the target's size and pitch: the "w/o" baseline (no spatial filter)."""
    return ReferenceRealisation(reference_kernel("delta", target.size, pitch_m=target.pitch_m), label="delta")


register_realisation(
    RealisationSpec(
        name="learned",
        fit=fit_learned,
        kind="reference",
        record_type=ReferenceRealisation,
        record_kind="reference",
        colour="#222222",
        title="learned kernel (ideal)",
        marker="o",
        in_default_design=True,
        description="the target kernel applied ideally (no hardware)",
    )
)
register_realisation(
    RealisationSpec(
        name="delta",
        fit=fit_delta,
        kind="reference",
        record_type=ReferenceRealisation,
        record_kind="reference",
        colour="#999999",
        title="no filter (delta)",
        marker="s",
        in_default_design=True,
        description="no spatial filter: the 'w/o' baseline",
    )
)
