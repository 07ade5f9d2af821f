"""Typed score records: what one scored realisation is, and its one serialisation.

A design point's score (:func:`fsdvs_hw.explore.scoring.score`) is a :class:`Score`: the realised
kernel, its errors against the target, CSF agreement, spectral summary, hardware :class:`Cost`,
task metrics per task and track (:class:`TrackScore`), the emulation comparison and the
:class:`WallTimes` spent. A stored point (:class:`ScoredPoint`) wraps a score with its sweep key,
parameters and status, and what the exploration adds to it: its paired task losses
(:class:`PairedLoss`), its physical cost with its limits (:class:`fsdvs_hw.costs.PhysicalCost`,
per ``costs.*`` sweep setting :class:`CostSetting`, and the :class:`CostFlip` assumptions that
reorder it against other kinds) and its buildable files (:class:`ArtifactLink`).

:meth:`Score.to_dict` is the one serialisation: the results store (SQLite), ``scores.json`` and
the report all read and write it, and :meth:`Score.from_dict` rebuilds the record from it
(``Score.from_dict(s.to_dict()).to_dict() == s.to_dict()``; unknown keys are kept, so records
written by a newer version survive a round trip). Units are in the field names (``_s`` seconds,
``_m`` metres, ``_cpp`` cycles per pixel) or, for costs, in each :class:`CostItem`.

The nested summaries that belong to other modules stay the mappings those modules write:
``spectral`` is :meth:`fsdvs_hw.spectra.SpectralSummary.to_dict`, each ``csf`` entry is
:meth:`fsdvs_hw.csf.CsfAgreement.to_dict`, ``emulation`` is
:func:`fsdvs_hw.explore.emulation.emulation_scores`; they are exposed read-only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from .errors import InputError
from .kernels import Kernel
from .realise.base import CostItem

if TYPE_CHECKING:
    from .costs.record import PhysicalCost

__all__ = [
    "ArtifactLink",
    "Cost",
    "CostFlip",
    "CostItem",
    "CostSetting",
    "PairedLoss",
    "Score",
    "ScoredPoint",
    "TaskScores",
    "TrackScore",
    "WallTimes",
]


def _ro(m: Mapping[str, Any] | None) -> Mapping[str, Any]:
    return MappingProxyType(dict(m or {}))


def _num(x: Any) -> float:
    """A float, or NaN for anything that is not a real number (None, "n/a", a bool)."""
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def _mapping(data: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(data, Mapping):
        raise InputError(f"{where}: expected a JSON object, got {type(data).__name__}")
    return data


def _list(data: Any, where: str) -> list[Any] | tuple[Any, ...]:
    if not isinstance(data, (list, tuple)):
        raise InputError(f"{where}: expected a JSON list, got {type(data).__name__}")
    return data


def _int(data: Mapping[str, Any], key: str, where: str) -> int:
    """``data[key]`` (0 when absent) as an int; an InputError naming the field when it is not a number."""
    v = data.get(key, 0)
    if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
        raise InputError(f"{where}.{key}: expected a number, got {v!r}"[:200])
    return int(v)


@dataclass(frozen=True)
class Cost:
    """A realisation's hardware cost: named items, each with its value and SI unit.

    Parameters
    ----------
    items : mapping of str to CostItem
        ``{name: CostItem(value, unit, description)}`` as the realisation's ``cost()`` returns.
    """

    items: Mapping[str, CostItem] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, item in self.items.items():
            if not isinstance(item, CostItem):
                raise InputError(f"cost item {name!r}: expected a CostItem, got {type(item).__name__}")
        object.__setattr__(self, "items", _ro(self.items))

    def value(self, name: str) -> float:
        """The item's value in its unit; NaN when the item is absent."""
        item = self.items.get(name)
        return _num(item.value) if item is not None else math.nan

    def unit(self, name: str) -> str:
        """The item's unit ("" when absent)."""
        item = self.items.get(name)
        return item.unit if item is not None else ""

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {k: v.to_dict() for k, v in self.items.items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "cost") -> Cost:
        items = {}
        for name, item in _mapping(data, where).items():
            item = _mapping(item, f"{where}.{name}")
            if "value" not in item or "unit" not in item:
                raise InputError(f"{where}.{name}: a cost item needs 'value' and 'unit', got {sorted(item)}")
            items[name] = CostItem(
                value=item["value"], unit=str(item["unit"]), description=str(item.get("description", ""))
            )
        return cls(items)


@dataclass(frozen=True)
class TrackScore:
    """One task's metric on one track (simulator or emulation), over every network scored.

    Parameters
    ----------
    status : str
        ``"ok"``, or why there is no number (``"unavailable: …"``).
    metric : float
        Mean over the networks of the task's primary metric (NaN unless ``status == "ok"``).
    metric_name : str
        Its name (``"mAP"``, ``"top1"``, ``"mIoU"``).
    per_seed : tuple of float
        The metric of each network (training seed).
    n_clips : int
        Test clips in total (over the networks when clips are nested in networks).
    n_clips_per_network, n_seeds : int
        Clips each network scored; networks scored.
    test_clips : str
        ``"per_network"`` (clips nested in networks) or ``"shared"``.
    event_rate : float
        Mean events per pixel per frame interval (the extra ``event_rate_per_s`` holds it in
        events/pixel/s with its 95 % CI over networks × clips, ``event_rate_unit`` names the unit).
    wall_s : float
        Seconds spent scoring this track.
    extra : mapping
        Everything else the scorer recorded (checkpoints, test and sensor seeds, the sensor
        settings, per-clip evidence, network provenance), kept as written.
    """

    status: str
    metric: float = math.nan
    metric_name: str = ""
    per_seed: tuple[float, ...] = ()
    n_clips: int = 0
    n_clips_per_network: int = 0
    n_seeds: int = 0
    test_clips: str = ""
    event_rate: float = math.nan
    wall_s: float = math.nan
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "per_seed", tuple(float(v) for v in self.per_seed))
        object.__setattr__(self, "extra", _ro(self.extra))

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    _TYPED = (
        "status",
        "metric",
        "metric_name",
        "per_seed",
        "n_seeds",
        "test_clips",
        "n_clips",
        "n_clips_per_network",
        "event_rate",
        "wall_s",
    )

    def to_dict(self) -> dict[str, Any]:
        if not self.ok:
            return {"status": self.status, **self.extra}
        typed = {
            "status": self.status,
            "metric": float(self.metric),
            "metric_name": self.metric_name,
            "per_seed": list(self.per_seed),
            "n_seeds": int(self.n_seeds),
            "test_clips": self.test_clips,
            "n_clips": int(self.n_clips),
            "n_clips_per_network": int(self.n_clips_per_network),
            "event_rate": float(self.event_rate),
            "wall_s": float(self.wall_s),
        }
        return {**typed, **self.extra}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "track") -> TrackScore:
        data = _mapping(data, where)
        status = str(data.get("status", ""))
        if status != "ok":
            return cls(status=status or "unknown", extra={k: v for k, v in data.items() if k != "status"})
        if not isinstance(data.get("metric"), (int, float)):
            raise InputError(f"{where}: status 'ok' but no numeric 'metric' ({data.get('metric')!r})")
        seeds = _list(data.get("per_seed", ()), f"{where}.per_seed")
        if any(not isinstance(v, (int, float)) or isinstance(v, bool) for v in seeds):
            raise InputError(f"{where}.per_seed: expected a list of numbers, got {seeds!r}"[:200])
        return cls(
            status=status,
            metric=float(data["metric"]),
            metric_name=str(data.get("metric_name", "")),
            per_seed=tuple(seeds),
            n_clips=_int(data, "n_clips", where),
            n_clips_per_network=_int(data, "n_clips_per_network", where),
            n_seeds=_int(data, "n_seeds", where),
            test_clips=str(data.get("test_clips", "")),
            event_rate=_num(data.get("event_rate")),
            wall_s=_num(data.get("wall_s")),
            extra={k: v for k, v in data.items() if k not in cls._TYPED},
        )


@dataclass(frozen=True)
class TaskScores:
    """Task metrics of one kernel: ``tracks[task][track]`` → :class:`TrackScore`.

    Parameters
    ----------
    status : str
        ``"ok"``, ``"partial"`` (some task or track could not be scored), ``"not requested"``.
    tracks : mapping
        Task name → track name → :class:`TrackScore`.
    """

    status: str = "not requested"
    tracks: Mapping[str, Mapping[str, TrackScore]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "tracks", _ro({t: _ro(v) for t, v in self.tracks.items()}))

    def metrics(self) -> dict[str, float]:
        """``{"task/track": metric}`` of every track scored ``ok``."""
        return {f"{t}/{k}": r.metric for t, tr in self.tracks.items() for k, r in tr.items() if r.ok}

    def to_dict(self) -> dict[str, Any]:
        return {"status": self.status, **{t: {k: r.to_dict() for k, r in tr.items()} for t, tr in self.tracks.items()}}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "tasks") -> TaskScores:
        data = _mapping(data, where)
        tracks = {
            t: {k: TrackScore.from_dict(r, where=f"{where}.{t}.{k}") for k, r in _mapping(tr, f"{where}.{t}").items()}
            for t, tr in data.items()
            if t != "status"
        }
        return cls(status=str(data.get("status", "ok" if tracks else "not requested")), tracks=tracks)


@dataclass(frozen=True)
class WallTimes:
    """Seconds spent on one point: fitting, analysis (errors, spectra, CSF), tasks, emulation."""

    fit_s: float = math.nan
    analysis_s: float = math.nan
    tasks_s: float = math.nan
    emulation_s: float = math.nan

    def to_dict(self) -> dict[str, float]:
        return {
            "fit": float(self.fit_s),
            "analysis": float(self.analysis_s),
            "tasks": float(self.tasks_s),
            "emulation": float(self.emulation_s),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "wall_s") -> WallTimes:
        data = _mapping(data, where)
        return cls(*(_num(data.get(k)) for k in ("fit", "analysis", "tasks", "emulation")))


@dataclass(frozen=True)
class Score:
    """The score of one realisation against its target kernel.

    Parameters
    ----------
    kind, label, describe : str
        The realisation's kind (registry name), short label and one-line description.
    kernel : Kernel
        The kernel the realisation applies (pitch in metres).
    kernel_error, kernel_error_gain_free : float
        Relative L2 error against the target, as is and with the least-squares gain
        (:func:`fsdvs_hw.realise.base.realised_kernel_error`).
    dc_gain, asymmetry : float
        Sum of taps; relative antisymmetric part.
    spectral : mapping
        :meth:`fsdvs_hw.spectra.SpectralSummary.to_dict` plus ``status``.
    csf : mapping
        ``status`` and, per CSF model (and ``fitted_scale``), :meth:`fsdvs_hw.csf.CsfAgreement.to_dict`.
    cost : Cost
        Hardware cost items with units.
    tasks : TaskScores
        Task metrics per task and track.
    emulation : mapping
        The sensor-in-the-loop emulation comparison (``status`` first).
    wall : WallTimes
        Seconds spent.
    realisation : mapping
        The fitted realisation's own record (``to_dict()``), enough to rebuild it.
    warnings : tuple of str
        Warnings the fit or scoring raised.
    versions : mapping
        Python and numerical library versions of the process that computed the score
        (:func:`fsdvs_hw.provenance.library_versions`; empty in records made before they were kept).
    extra : mapping
        Keys this version does not know, kept for the round trip.
    """

    kind: str
    label: str
    describe: str
    kernel: Kernel
    kernel_error: float
    kernel_error_gain_free: float
    dc_gain: float
    asymmetry: float
    spectral: Mapping[str, Any] = field(default_factory=dict)
    csf: Mapping[str, Any] = field(default_factory=dict)
    cost: Cost = field(default_factory=Cost)
    tasks: TaskScores = field(default_factory=TaskScores)
    emulation: Mapping[str, Any] = field(default_factory=lambda: {"status": "not requested"})
    wall: WallTimes = field(default_factory=WallTimes)
    realisation: Mapping[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    versions: Mapping[str, str | None] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.kernel, Kernel):
            raise InputError(f"Score.kernel: expected a Kernel, got {type(self.kernel).__name__}")
        for name in ("spectral", "csf", "emulation", "realisation", "versions", "extra"):
            object.__setattr__(self, name, _ro(getattr(self, name)))
        object.__setattr__(self, "warnings", tuple(str(w) for w in self.warnings))

    def csf_correlation(self, method: str) -> float:
        """Correlation of the kernel's radial response with CSF ``method`` (NaN if not scored)."""
        return _num((self.csf.get(method) or {}).get("correlation"))

    def with_(self, **changes: Any) -> Score:
        """A copy with fields replaced (:func:`dataclasses.replace`)."""
        return replace(self, **changes)

    _KEYS = (
        "kind",
        "label",
        "describe",
        "kernel",
        "kernel_error",
        "kernel_error_gain_free",
        "dc_gain",
        "asymmetry",
        "spectral",
        "csf",
        "cost",
        "tasks",
        "emulation",
        "wall_s",
        "realisation",
        "warnings",
        "versions",
    )

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready record (the store's, ``scores.json``'s and the report's one format)."""
        out: dict[str, Any] = {
            "kind": self.kind,
            "label": self.label,
            "describe": self.describe,
            "kernel": self.kernel.to_dict(),
            "kernel_error": float(self.kernel_error),
            "kernel_error_gain_free": float(self.kernel_error_gain_free),
            "dc_gain": float(self.dc_gain),
            "asymmetry": float(self.asymmetry),
            "spectral": dict(self.spectral),
            "csf": dict(self.csf),
            "cost": self.cost.to_dict(),
            "tasks": self.tasks.to_dict(),
            "emulation": dict(self.emulation),
            "wall_s": self.wall.to_dict(),
        }
        if self.realisation:
            out["realisation"] = dict(self.realisation)
        if self.warnings:
            out["warnings"] = list(self.warnings)
        if self.versions:
            out["versions"] = dict(self.versions)
        out.update(self.extra)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "score") -> Score:
        """Rebuild a score from :meth:`to_dict`'s output; errors name the field."""
        data = _mapping(data, where)
        missing = [k for k in ("kind", "kernel", "kernel_error") if k not in data]
        if missing:
            raise InputError(f"{where}: not a score record (missing {', '.join(missing)})")
        return cls(
            kind=str(data["kind"]),
            label=str(data.get("label", data["kind"])),
            describe=str(data.get("describe", "")),
            kernel=Kernel.from_dict(data["kernel"], source=f"{where}.kernel"),
            kernel_error=_num(data["kernel_error"]),
            kernel_error_gain_free=_num(data.get("kernel_error_gain_free")),
            dc_gain=_num(data.get("dc_gain")),
            asymmetry=_num(data.get("asymmetry")),
            spectral=_mapping(data.get("spectral", {}), f"{where}.spectral"),
            csf=_mapping(data.get("csf", {}), f"{where}.csf"),
            cost=Cost.from_dict(data.get("cost", {}), where=f"{where}.cost"),
            tasks=TaskScores.from_dict(data.get("tasks", {}), where=f"{where}.tasks"),
            emulation=_mapping(data.get("emulation", {"status": "not requested"}), f"{where}.emulation"),
            wall=WallTimes.from_dict(data.get("wall_s", {}), where=f"{where}.wall_s"),
            realisation=_mapping(data.get("realisation", {}), f"{where}.realisation"),
            warnings=tuple(data.get("warnings", ())),
            versions=_mapping(data.get("versions", {}), f"{where}.versions"),
            extra={k: v for k, v in data.items() if k not in cls._KEYS},
        )


@dataclass(frozen=True)
class PairedLoss:
    """A point's paired task losses against the reference kernel, per track and task.

    Parameters
    ----------
    status : str or None
        ``"ok"``, or why there are no losses (``"not scored"``, ``"no 'learned' row in its sweep
        setting"``); None when the record names none.
    reference : str or None
        Store key of the reference point (None when there is none).
    tracks : mapping
        Track (``"simulator"``, ``"emulation"``) → ``{task: interval record, "weighted": interval
        record, "weights": {task: weight}}`` as :func:`fsdvs_hw.explore.scoring.paired_losses`
        writes it (each interval: ``estimate, low, high`` in metric units, positive = accuracy
        lost, ``text``), or ``{"status": why}`` for a track without paired evidence.
    """

    status: str | None = None
    reference: str | None = None
    tracks: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "tracks", _ro(self.tracks))

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.status is not None:
            out["status"] = self.status
        if self.reference is not None:
            out["reference"] = self.reference
        out.update(self.tracks)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "paired_loss") -> PairedLoss:
        data = _mapping(data, where)
        status, reference = data.get("status"), data.get("reference")
        return cls(
            status=None if status is None else str(status),
            reference=None if reference is None else str(reference),
            tracks={k: v for k, v in data.items() if k not in ("status", "reference")},
        )


@dataclass(frozen=True)
class ArtifactLink:
    """One buildable file of a point, as its report links it (an ``artifacts/index.json`` entry).

    Parameters
    ----------
    point : str
        The point's folder under ``artifacts/`` (:func:`fsdvs_hw.explore.point_artifacts.point_folder_name`).
    realisation : str
        Registry name of the realisation.
    name, what, checked_by : str
        The file's short name, what it is, and the tool command that checks it.
    file : str
        Its path relative to the exploration's output folder (``""`` when the writer failed).
    error : str or None
        Why the writer failed (None when it did not).
    extra : mapping
        Other keys of the entry, kept for the round trip.
    """

    point: str = ""
    realisation: str = ""
    name: str = ""
    file: str = ""
    what: str = ""
    checked_by: str = ""
    error: str | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    _KEYS = ("point", "realisation", "name", "file", "what", "checked_by", "error")

    def __post_init__(self) -> None:
        object.__setattr__(self, "extra", _ro(self.extra))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "point": self.point,
            "realisation": self.realisation,
            "name": self.name,
            "file": self.file,
            "what": self.what,
            "checked_by": self.checked_by,
        }
        if self.error is not None:
            out["error"] = self.error
        out.update(self.extra)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "artifact") -> ArtifactLink:
        data = _mapping(data, where)
        error = data.get("error")
        return cls(
            **{k: str(data.get(k, "")) for k in cls._KEYS[:-1]},
            error=None if error is None else str(error),
            extra={k: v for k, v in data.items() if k not in cls._KEYS},
        )


@dataclass(frozen=True)
class CostSetting:
    """A point's physical cost under one setting of the design's ``costs.*`` sweep axes.

    Parameters
    ----------
    setting : mapping
        The axes' values by dotted key (``{"costs.process_node_m": 4.5e-08}``, SI units).
    physical_cost : PhysicalCost
        The cost record under it.
    """

    setting: Mapping[str, Any]
    physical_cost: PhysicalCost

    def __post_init__(self) -> None:
        object.__setattr__(self, "setting", _ro(self.setting))

    def to_dict(self) -> dict[str, Any]:
        return {"setting": dict(self.setting), "physical_cost": self.physical_cost.to_dict()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "physical_cost_sweep") -> CostSetting:
        from .costs.record import PhysicalCost

        data = _mapping(data, where)
        return cls(
            setting=_mapping(data.get("setting", {}), f"{where}.setting"),
            physical_cost=PhysicalCost.from_dict(
                _mapping(data.get("physical_cost"), f"{where}.physical_cost"), where=f"{where}.physical_cost"
            ),
        )


@dataclass(frozen=True)
class CostFlip:
    """A ``[costs]`` assumption whose change within its range reverses which of two points is cheaper.

    Parameters
    ----------
    cost : str
        The cost compared (``"power_w"``, ``"area_m2"``, ``"latency_s"``).
    key : str
        The assumption (``[costs]`` key, or the mesh's conductance).
    value, now : float
        The value at which the order flips, and the present value (in the key's unit).
    other : str
        Store key of the other point.
    cheaper : str
        Store key of the point that is cheaper at the present value.
    """

    cost: str
    key: str
    value: float
    now: float
    other: str
    cheaper: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "cost_flips") -> CostFlip:
        data = _mapping(data, where)
        names = [f.name for f in fields(cls)]
        missing = [k for k in names if k not in data]
        if missing:
            raise InputError(f"{where}: a cost flip needs {', '.join(missing)}")
        for k in ("value", "now"):
            if not isinstance(data[k], (int, float)) or isinstance(data[k], bool):
                raise InputError(f"{where}.{k}: expected a number, got {data[k]!r}"[:200])
        return cls(**{k: data[k] for k in names})


@dataclass(frozen=True)
class ScoredPoint:
    """A stored design point: its key, realisation, sweep parameters, status and score, and what the
    exploration adds to it.

    Parameters
    ----------
    key : str
        The point's content hash in the results store.
    realisation : str
        Registry name of the realisation.
    params : mapping
        The sweep parameters that set this point (``{"mesh.g_max_s": 1e-6}``), empty for the base design.
    status : str
        ``"ok"`` or ``"error"``.
    score : Score or None
        The score (None when the point failed).
    failure : mapping
        Why it failed (``reason``: ``"ValueError: …"``, ``traceback``, ``warnings``); empty when ok.
    wall_s : float
        Seconds the whole point took.
    paired_loss : PairedLoss or None
        Its task losses against the reference kernel (:func:`fsdvs_hw.explore.scoring.paired_losses`);
        None when not computed.
    artifacts : tuple of ArtifactLink or None
        Its buildable files (:mod:`fsdvs_hw.explore.point_artifacts`); None when none were written.
    physical_cost : PhysicalCost or None
        Its physical cost with the hard limits it breaks (:func:`fsdvs_hw.costs.limits.costed`).
    physical_cost_sweep : tuple of CostSetting
        The cost under each setting of the design's ``costs.*`` sweep axes (empty without such axes).
    cost_flips : tuple of CostFlip or None
        The assumptions that reorder its cost against the other kinds of its sweep setting.
    extra : mapping
        The store's other columns (design, worker, host, finished_at, traceback) and the other
        records the exploration attaches (``matched_rate``, ``measurability``), kept as written.
    """

    key: str
    realisation: str
    params: Mapping[str, Any]
    status: str
    score: Score | None = None
    failure: Mapping[str, Any] = field(default_factory=dict)
    wall_s: float = math.nan
    paired_loss: PairedLoss | None = None
    artifacts: tuple[ArtifactLink, ...] | None = None
    physical_cost: PhysicalCost | None = None
    physical_cost_sweep: tuple[CostSetting, ...] = ()
    cost_flips: tuple[CostFlip, ...] | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("params", "failure", "extra"):
            object.__setattr__(self, name, _ro(getattr(self, name)))
        object.__setattr__(self, "physical_cost_sweep", tuple(self.physical_cost_sweep))
        for name in ("artifacts", "cost_flips"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, tuple(getattr(self, name)))

    @property
    def ok(self) -> bool:
        return self.status == "ok" and self.score is not None

    @property
    def reason(self) -> str:
        """Why the point failed ("" when it did not)."""
        return str(self.failure.get("reason", ""))

    def with_(self, **changes: Any) -> ScoredPoint:
        """A copy with fields replaced (:func:`dataclasses.replace`)."""
        return replace(self, **changes)

    _KEYS = (
        "key",
        "realisation",
        "params",
        "status",
        "result",
        "wall_s",
        "paired_loss",
        "artifacts",
        "physical_cost",
        "physical_cost_sweep",
        "cost_flips",
    )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "point") -> ScoredPoint:
        """A stored point (the store's row dict, or an entry of ``scores.json``'s ``points``)."""
        from .costs.record import PhysicalCost

        data = _mapping(data, where)
        for k in ("key", "realisation", "status"):
            if k not in data:
                raise InputError(f"{where}: missing field {k!r}")
        where = f"{where} {data['key']}"
        result = data.get("result") or {}
        ok = data["status"] == "ok"
        paired, links, flips = data.get("paired_loss"), data.get("artifacts"), data.get("cost_flips")
        return cls(
            key=str(data["key"]),
            realisation=str(data["realisation"]),
            params=_mapping(data.get("params") or {}, f"{where}.params"),
            status=str(data["status"]),
            score=Score.from_dict(result, where=f"{where}.result") if ok else None,
            failure={} if ok else _mapping(result, f"{where}.result"),
            wall_s=_num(data.get("wall_s")),
            paired_loss=PairedLoss.from_dict(paired, where=f"{where}.paired_loss") if paired else None,
            artifacts=None
            if links is None
            else tuple(
                ArtifactLink.from_dict(e, where=f"{where}.artifacts")
                for e in _list(links, f"{where}.artifacts")
                if isinstance(e, Mapping)
            ),
            physical_cost=PhysicalCost.from_dict(data["physical_cost"], where=f"{where}.physical_cost")
            if isinstance(data.get("physical_cost"), Mapping)
            else None,
            physical_cost_sweep=tuple(
                CostSetting.from_dict(e, where=f"{where}.physical_cost_sweep")
                for e in _list(data.get("physical_cost_sweep") or (), f"{where}.physical_cost_sweep")
            ),
            cost_flips=None
            if flips is None
            else tuple(
                CostFlip.from_dict(f, where=f"{where}.cost_flips")
                for f in _list(flips, f"{where}.cost_flips")
                if isinstance(f, Mapping)
            ),
            extra={k: v for k, v in data.items() if k not in cls._KEYS},
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready record (``scores.json``'s ``points`` entries): :meth:`from_dict`'s input."""
        result = self.score.to_dict() if self.score is not None else dict(self.failure)
        out = {
            "key": self.key,
            "realisation": self.realisation,
            "params": dict(self.params),
            "status": self.status,
            "result": result,
            "wall_s": self.wall_s,
        }
        if self.paired_loss is not None:
            out["paired_loss"] = self.paired_loss.to_dict()
        out.update(self.extra)
        if self.artifacts is not None:
            out["artifacts"] = [a.to_dict() for a in self.artifacts]
        if self.physical_cost is not None:
            out["physical_cost"] = self.physical_cost.to_dict()
        if self.physical_cost_sweep:
            out["physical_cost_sweep"] = [c.to_dict() for c in self.physical_cost_sweep]
        if self.cost_flips is not None:
            out["cost_flips"] = [f.to_dict() for f in self.cost_flips]
        return out
