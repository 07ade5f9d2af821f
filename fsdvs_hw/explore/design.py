"""Design files: TOML descriptions of one exploration (kernel, sensor, optics, realisations, tasks).

A design file says *what* to explore; :mod:`fsdvs_hw.explore.sweep` turns it into design points
and :mod:`fsdvs_hw.explore.scoring` scores each one. Every key is checked against a schema
before any work starts, and every problem is reported as one :class:`~fsdvs_hw.errors.InputError`
naming the file, the key, the value and what is allowed.

Layout (every section and key is optional; defaults in brackets)::

    [design]        name ["design file stem"], description [""]
    [kernel]        source = "file" | "reference" ["reference"]
                    path  (source = "file": .json/.npy/.csv/.pt, relative to the design file)
                    family, size, params  (source = "reference": fsdvs_hw.kernels.reference_kernel)
    [sensor]        pitch_m [4.86e-6], resolution [[48, 64]] (H, W px), threshold_on/off [0.2],
                    threshold_sigma [0.03], placement = "pre_log" | "post_log",
                    positivity = "floor" | "pedestal" | "differential"
    [optics]        focal_length_m [4e-3]  (turns cycles/pixel into cycles/degree)
    [analysis]      csf_methods
    [realisations]  include = ["learned", "delta", "mesh", "asic", "metalens"]  (the registered
                    realisations marked in_default_design; fsdvs_hw.realise.registry)
    [realisations.<name>]   keyword options of a hardware realisation's fit function
                    (mesh: fit_resistive_mesh, asic: fit_asic_taps, metalens: fit_metalens), checked
                    against the schema it registered
    [tasks]         checkpoints = { detection = "kernels/learned_detection_7x7.safetensors" },
                    or a list or glob pattern per task, one network per training seed;
                    n_test (clips per network: number, or table task → clips), n_test_emulation,
                    test_clips = "per_network" | "shared", finetune_epochs,
                    tracks = ["simulator", "emulation"], sensor = "checkpoint" | "design"
    [tasks.datasets.<task>]  the user's clips and network instead of checkpoints:
                    dataset = {format = "video_folder" | "coco_frames" | "dsec_detection" | "mask_frames", ...},
                    network = "package.module:factory", network_options, weights, n_clips, seed,
                    max_failed_clip_fraction [0.05] (fraction in [0, 1] of the drawn clips that may
                    fail to read and be skipped, counted and named; beyond it the task fails)
                    (fsdvs_hw.explore.user_data)
    [scoring]       task_weights = { detection = 1, ... } [equal], n_resamples [2000],
                    confidence [0.95], target_half_width [0.01]  (the paired loss CIs)
    [emulation]     enabled, n_clips, n_frames, display_bits, display_gamma, display_peak_nits,
                    display_black_nits, upsample_factor, upsample ["linear_light" or "flow"], camera
                    ["design" or a sensor preset such as "imx636"]  (fsdvs_hw.explore.emulation)
    [rate]          enabled [false], thresholds [[0.1, 0.125, 0.15, 0.3, 0.45]], references [["delta", "learned"]]
                    (every point's losses at equal event rate; fsdvs_hw.explore.matched)
    [sweep]         axes = { "asic.bits" = [2, 4, 8], "sensor.threshold_on" = [0.1, 0.2] }
    [run]           workers, seed, max_points [10000]
    [costs]         process_node_m [45e-9], digital_supply_v [0.9], analog_supply_v [1.8], clock_hz,
                    sample_rate_hz, array_resolution [[720, 1280]], readout_limit_eps [1.066e9],
                    sensor_illuminance_lux, loss_budget, ...  (fsdvs_hw.costs.assumptions; the
                    physical cost records: a sweep over these keys re-costs the stored points
                    without refitting them)
    [codesign]      enabled [false], realisations [those with a differentiable form], tasks [all],
                    cells ["realisation/task", ...; all], seeds [3] (networks per task), epochs [4],
                    n_train [0 = the checkpoint's], lr_network [1e-3], lr_filter [1e-2],
                    modes [["swap", "finetune", "codesign"]]  (fsdvs_hw.explore.codesign)

Sweep axes are dotted keys into this layout; ``"mesh.X"`` is short for ``"realisations.mesh.X"``.
Realisation names, their option tables and defaults come from the registry
(:mod:`fsdvs_hw.realise.registry`) when a design is parsed, so a realisation registered by any
module is accepted without a change here.
"""

from __future__ import annotations

import copy
import difflib
import fnmatch
import glob
import json
import math
import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from dataclasses import field as dc_field
from pathlib import Path
from typing import Annotated, Any, Literal, get_args

from pydantic import Field, ValidationError, create_model

from ..costs.assumptions import CostAssumptions
from ..csf import CSF_METHODS
from ..errors import InputError, KernelError
from ..fingerprints import fingerprint
from ..kernels import (
    DEFAULT_PITCH_M,
    MAX_KERNEL_SIZE,
    REFERENCE_KERNELS,
    Kernel,
    check_tap_magnitude,
    load_kernel,
    reference_kernel,
)
from ..limits import MAX_WORKERS
from ..paths import confined_path, safe_name
from ..realise.registry import get_realisation, realisation_names
from ..schema import DESIGN_CONTEXT, StrictModel, field, field_schema, members, problems, short
from .user_data import UserTask

__all__ = [
    "CODESIGN_MODES",
    "CSF_DEFAULT_METHODS",
    "MAX_GLOB_ENTRIES",
    "Design",
    "DesignError",
    "axis_values",
    "check_key",
    "load_design",
    "parse_design",
]


class DesignError(InputError):
    """A design file is invalid; the message names the file, key, value and what is allowed."""


#: CSF models scored when a design names none (Mannos–Sakrison first: the paper's reference).
CSF_DEFAULT_METHODS: tuple[str, ...] = ("mannos_sakrison_1974", "barten_1999", "daly_1993", "watson_ahumada_2005")

#: Largest design file read (bytes).
MAX_DESIGN_FILE_BYTES = 1 * 2**20

_Placement = Literal["pre_log", "post_log"]
_Positivity = Literal["floor", "pedestal", "differential"]
_Track = Literal["simulator", "emulation"]
_PLACEMENTS = get_args(_Placement)
_POSITIVITY = get_args(_Positivity)
_TRACKS = get_args(_Track)
#: The emulation track's recapturing camera: the design's [sensor], or a preset of
#: :data:`fsdvs_hw.sensor.cameras.presets.SENSOR_PRESETS` (listed here so reading a design never imports torch;
#: tests/test_sensor_presets.py checks that the two agree).
EMULATION_CAMERAS = ("design", "dvs128", "davis346", "imx636", "v2e-clean", "v2e-default", "v2e-noisy")
_CodesignMode = Literal["swap", "finetune", "codesign"]
#: The ``[codesign]`` rows: fit then swap (zero-shot), fit then fine-tune the network, co-designed.
CODESIGN_MODES: tuple[str, ...] = get_args(_CodesignMode)

_Clips = Annotated[int, Field(ge=0, le=100000)]


# ------------------------------------------------------------------------- the sections' models
class DesignSection(StrictModel):
    """``[design]``: what the exploration is called."""

    name: str | None = field(None, "", "short name used in reports")
    description: str = field("", "", "free text")


class KernelSection(StrictModel):
    """``[kernel]``: the target kernel every realisation is fitted to."""

    source: Literal["file", "reference"] = field("reference", "", "where the target kernel comes from")
    path: str | None = field(None, "", "kernel file, relative to the design file (.json .npy .csv .pt)")
    family: Literal[tuple(REFERENCE_KERNELS)] = field("dog", "", "reference family")  # type: ignore[valid-type]
    size: int = field(7, "px", "kernel side in pixels", ge=1, le=MAX_KERNEL_SIZE, odd=True)
    params: dict[str, Any] = field({}, "", "reference family parameters, e.g. sigma_centre_px = 0.7")


class SensorSection(StrictModel):
    """``[sensor]``: the simulated event sensor."""

    pitch_m: float = field(DEFAULT_PITCH_M, "m", "pixel pitch in metres", ge=1e-7, le=1e-3)
    resolution: list[Annotated[int, Field(ge=8, le=4096)]] = field(
        [48, 64], "px", "simulated sensor size [H, W] in pixels", min_length=2, max_length=2
    )
    threshold_on: float = field(0.2, "", "ON contrast threshold (log units)", ge=1e-4, le=10.0)
    threshold_off: float = field(0.2, "", "OFF contrast threshold (log units)", ge=1e-4, le=10.0)
    threshold_sigma: float = field(0.03, "", "per-pixel threshold mismatch σ (log units)", ge=0.0, le=1.0)
    placement: _Placement = field("pre_log", "", "where the kernel sits relative to the log stage")
    positivity: _Positivity = field("pedestal", "", "how negative filtered intensities are handled")


class OpticsSection(StrictModel):
    """``[optics]``: the imaging lens (turns cycles/pixel into cycles/degree)."""

    focal_length_m: float = field(4.0e-3, "m", "imaging focal length in metres (sets pixels/degree)", ge=1e-4, le=1.0)


class AnalysisSection(StrictModel):
    """``[analysis]``: the CSF models compared against."""

    csf_methods: list[str] = field(list(CSF_DEFAULT_METHODS), "", "CSF models to compare against")


class TasksSection(StrictModel):
    """``[tasks]``: the trained networks the realisations are scored with."""

    checkpoints: dict[str, Any] = field(
        {},
        "",
        "task name → trained checkpoint, or a list of checkpoints (one "
        "network per training seed), .safetensors relative to the design file; a "
        "glob pattern ('networks/det_s*.safetensors') lists every match in natural "
        "order; {} = no task evaluation",
    )
    n_test: _Clips | dict[str, Any] = field(
        0,
        "",
        "test clips per network and evaluation: one number for every "
        "task or a table task → clips; 0 = the checkpoint's own test-set size",
    )
    test_clips: Literal["per_network", "shared"] = field(
        "per_network",
        "",
        "which clips a task's networks score: each its own held-out set (clips nested in "
        "networks: the CI samples as many networks as there are) or the same set for all (crossed)",
    )
    n_test_emulation: _Clips | dict[str, Any] = field(
        0,
        "",
        "test clips of the emulation track (display + "
        "recapture costs about 8x the simulator per clip): a number or "
        "a table task → clips; 0 = as n_test",
    )
    finetune_epochs: int = field(
        0, "", "optional short fine-tune after the zero-shot swap (0 = zero-shot)", ge=0, le=1000
    )
    tracks: list[_Track] = field(["simulator"], "", "evaluation tracks")
    sensor: Literal["checkpoint", "design"] = field(
        "checkpoint",
        "",
        "simulator settings of the task track: the checkpoint's own (the trained condition) or "
        "the checkpoint's with this design's [sensor] thresholds, mismatch, placement and positivity",
    )
    datasets: dict[str, UserTask] = field(
        {},
        "",
        "task name → the user's clips and network "
        "([tasks.datasets.<task>]: dataset = {format, root, split, ...}, network, "
        "weights, n_clips, max_failed_clip_fraction; fsdvs_hw.explore.user_data); {} = none",
    )


class ScoringSection(StrictModel):
    """``[scoring]``: the weighted task loss and its confidence intervals."""

    task_weights: dict[str, Any] = field(
        {}, "", "task → weight of its loss in the weighted task loss; {} = equal weights"
    )
    n_resamples: int = field(2000, "", "bootstrap resamples per confidence interval", ge=100, le=100000)
    confidence: float = field(0.95, "", "two-sided confidence level of the loss intervals", ge=0.5, le=0.999)
    target_half_width: float = field(
        0.01,
        "",
        "loss CI half-width (metric fraction) the test set is sized for; wider intervals are flagged",
        ge=1e-4,
        le=1.0,
    )


class EmulationSection(StrictModel):
    """``[emulation]``: the sensor-in-the-loop track (fsdvs_hw.explore.emulation)."""

    enabled: bool = field(True, "", "score the sensor-in-the-loop emulation track (event level)")
    n_clips: int = field(4, "", "synthetic clips for the emulation track", ge=1, le=10000)
    n_frames: int = field(9, "", "frames per clip", ge=2, le=1000)
    display_bits: int = field(8, "bit", "display bit depth", ge=1, le=16)
    display_gamma: float = field(2.2, "", "display gamma (encoded = linear^(1/gamma))", ge=1.0, le=4.0)
    display_peak_nits: float = field(400.0, "cd/m^2", "display peak luminance in cd/m²", ge=1.0, le=10000.0)
    display_black_nits: float = field(0.3, "cd/m^2", "display black level in cd/m²", ge=0.0, le=100.0)
    upsample_factor: int = field(4, "", "temporal upsampling before display", ge=1, le=64)
    upsample: Literal["linear_light", "flow"] = field(
        "linear_light",
        "",
        "how the upsampled frames are made: 'linear_light' (blend in linear light, a cross-fade) or "
        "'flow' (optical-flow interpolation in log intensity with occlusion handling, fsdvs_hw.sensor.upsampling; "
        "closer to the paper's RIFE)",
    )
    camera: Literal[EMULATION_CAMERAS] = field(  # type: ignore[valid-type]
        "design",
        "",
        "the camera that recaptures the display: 'design' (the design's [sensor]) or a sensor preset "
        "with sourced parameters (fsdvs_hw.sensor.presets; 'imx636' is the paper's EVK4)",
    )


class RateSection(StrictModel):
    """``[rate]``: matched-event-rate losses of every point (fsdvs_hw.explore.matched)."""

    enabled: bool = field(
        False,
        "",
        "measure the reference kernels' rate curves and give every point its losses "
        "at equal event rate (costs one task evaluation per reference and threshold)",
    )
    thresholds: list[Annotated[float, Field(ge=1e-4, le=10.0)]] = field(
        [0.1, 0.125, 0.15, 0.3, 0.45],
        "",
        "ON = OFF contrast thresholds (log units) of the reference rate curves, "
        "besides the one the points were scored at; they must bracket every point's event rate (a rate outside a "
        "curve is refused, never extrapolated) and be dense where the rates are matched: a plain DVS's metric peaks "
        "near 0.125, and linear interpolation across a peak underestimates it",
        min_length=1,
        max_length=64,
    )
    references: list[Literal["delta", "learned"]] = field(
        ["delta", "learned"],
        "",
        "reference curves: 'delta' (a plain DVS with its threshold moved: the point's gain "
        "over it at equal rate) and 'learned' (the kernel being realised: the point's matched-rate loss)",
        min_length=1,
        max_length=2,
    )


class SweepSection(StrictModel):
    """``[sweep]``: the grid of design points."""

    axes: dict[str, Any] = field({}, "", "dotted key → list of values; points are the grid product")


class RunSection(StrictModel):
    """``[run]``: how the exploration runs."""

    workers: int = field(2, "", "local worker processes", ge=1, le=MAX_WORKERS)
    seed: int = field(0, "", "seed for fits and noise", ge=0, le=2**31 - 1)
    max_points: int = field(
        10000,
        "",
        "largest sweep accepted (design points); a bigger one is refused before its list is built",
        ge=1,
        le=10**9,
    )


def _default(model: type[StrictModel]) -> Any:
    return Field(default_factory=model, description=(model.__doc__ or "").strip().split("\n")[0])


_MODELS: dict[tuple[Any, ...], type[StrictModel]] = {}


def _realisations_section(names: tuple[str, ...], hardware: tuple[str, ...]) -> type[StrictModel]:
    """The ``[realisations]`` model: ``include`` among ``names``, a fit-options table per hardware realisation.

    Parameters
    ----------
    names : tuple of str
        Every registered realisation (:func:`~fsdvs_hw.realise.registry.realisation_names`).
    hardware : tuple of str
        Those with fit options (their ``[realisations.<name>]`` tables).

    Returns
    -------
    type of StrictModel
    """
    default_include = [n for n in names if get_realisation(n).in_default_design]
    tables: dict[str, Any] = {
        n: (
            get_realisation(n).options,
            Field(
                default_factory=get_realisation(n).options,
                description=f"keyword options of {get_realisation(n).fit_name}",
            ),
        )
        for n in hardware
    }
    realisations = create_model(
        "RealisationsSection",
        __base__=StrictModel,
        __doc__="``[realisations]``: what is fitted and scored.",
        include=(list[Literal[names]], field(default_include, "", "realisations to fit and score")),  # type: ignore[valid-type]
        **tables,
    )
    return realisations


def _codesign_section(hardware: tuple[str, ...]) -> type[StrictModel]:
    """The ``[codesign]`` model: its ``realisations`` among the differentiable ones of ``hardware``.

    Parameters
    ----------
    hardware : tuple of str
        The realisations with fit options.

    Returns
    -------
    type of StrictModel
    """
    diff = tuple(n for n in hardware if get_realisation(n).differentiable)
    real_item: Any = Literal[diff] if diff else Annotated[str, Field(max_length=0)]
    codesign = create_model(
        "CodesignSection",
        __base__=StrictModel,
        __doc__="``[codesign]``: networks trained with the realisations.",
        enabled=(
            bool,
            field(
                False,
                "",
                "add the 'fit then swap' / 'fit then fine-tune' / 'co-designed' rows "
                "(fsdvs_hw.explore.codesign; trains networks: minutes per cell)",
            ),
        ),
        realisations=(
            list[real_item],
            field(list(diff), "", "hardware realisations to co-design (those with a differentiable form)"),
        ),
        tasks=(
            list[str],
            field(
                [],
                "",
                "tasks to co-design for; [] = every task in tasks.checkpoints and "
                "tasks.datasets (a user-data task: its one network, weights or train)",
            ),
        ),
        cells=(
            list[str],
            field([], "", "'realisation/task' pairs to run (e.g. 'metalens/detection'); [] = every realisation x task"),
        ),
        seeds=(
            int,
            field(
                3,
                "",
                "networks per task: the first N of tasks.checkpoints (one per training seed); a user-data task has one",
                ge=1,
                le=1000,
            ),
        ),
        epochs=(int, field(4, "", "training epochs of the fine-tune and co-design rows", ge=1, le=1000)),
        n_train=(
            int,
            field(0, "", "training clips per network; 0 = the checkpoint's own training set", ge=0, le=100000),
        ),
        lr_network=(float, field(1e-3, "", "AdamW learning rate of the network", gt=0.0, le=10.0)),
        lr_filter=(float, field(1e-2, "", "AdamW learning rate of the realisation's parameters", gt=0.0, le=10.0)),
        modes=(list[_CodesignMode], field(list(CODESIGN_MODES), "", "rows to measure")),
    )
    return codesign


def design_model() -> type[StrictModel]:
    """The model of a whole design file, with ``[realisations]`` and ``[codesign]`` built from the
    registry as it is now: ``include`` and ``codesign.realisations`` choose among the registered
    names, and every hardware realisation's fit options are a ``[realisations.<name>]`` table
    (its :attr:`~fsdvs_hw.realise.registry.RealisationSpec.options` model)."""
    specs = [get_realisation(n) for n in realisation_names()]
    sig = tuple((s.name, s.kind, s.options, s.in_default_design, bool(s.differentiable)) for s in specs)
    if sig in _MODELS:
        return _MODELS[sig]
    names = realisation_names()
    hardware = _option_tables()
    realisations = _realisations_section(names, hardware)
    codesign = _codesign_section(hardware)
    sections: dict[str, type[StrictModel]] = {
        "design": DesignSection,
        "kernel": KernelSection,
        "sensor": SensorSection,
        "optics": OpticsSection,
        "analysis": AnalysisSection,
        "realisations": realisations,
        "tasks": TasksSection,
        "scoring": ScoringSection,
        "emulation": EmulationSection,
        "rate": RateSection,
        "sweep": SweepSection,
        "run": RunSection,
        "codesign": codesign,
        "costs": CostAssumptions,
    }
    fields: dict[str, Any] = {k: (m, _default(m)) for k, m in sections.items()}
    model = create_model(
        "DesignFile",
        __base__=StrictModel,
        __doc__="A design file of fsdvs_hw (fsdvs_hw.explore.design): every section optional.",
        **fields,
    )
    model.unknown_key = "unknown section"
    _MODELS[sig] = model
    return model


def _section_models() -> dict[str, type[StrictModel]]:
    """Section name → its model (of :func:`design_model`)."""
    return {k: f.annotation for k, f in design_model().model_fields.items()}  # type: ignore[misc]


def _section_keys(section: str) -> list[str]:
    """The keys of one section (for ``[realisations]``: ``include``, not the option tables)."""
    keys = list(_section_models()[section].model_fields)
    return [k for k in keys if not (section == "realisations" and k in _option_tables())]


def _is_table(model: type[StrictModel], name: str) -> bool:
    """The field takes a table (a dict, or a structured object given as a table)."""
    return any(m.get("type") == "object" for m in members(field_schema(model, name)))


def design_json_schema() -> dict[str, Any]:
    """JSON Schema (draft 2020-12) of a design file as the registry is now, for editors.

    Every key carries its default, its ``description`` (a few words of meaning) and its
    ``unit``; the cross-section checks (files exist, sizes agree, tasks match) are not in it.
    """
    schema = design_model().model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "fsdvs_hw design file"
    return schema


def _option_tables() -> tuple[str, ...]:
    """Realisations that take fit options (a ``[realisations.<name>]`` table): the hardware ones."""
    return realisation_names("hardware")


class _Problems:
    """Collects problems as ``key '<key>' = <value>: <why; what is allowed>`` lines for one file."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.problems: list[str] = []

    def add(self, key: str, value: Any, message: str) -> None:
        self.problems.append(f"key '{key}' = {short(value)}: {message}")

    def raise_if_any(self) -> None:
        if self.problems:
            n = len(self.problems)
            head = f"{self.source}: invalid design file ({n} problem{'s' if n > 1 else ''})"
            raise DesignError(head + ":\n  " + "\n  ".join(self.problems))


@dataclass(frozen=True, eq=False)
class Design:
    """A validated design: every section filled with defaults, the target kernel loaded.

    Attributes
    ----------
    data : dict
        The full, validated design (sections → keys), JSON-serialisable.
    source : str
        Where it came from (file path or ``"<string>"``); used in messages.
    base_dir : Path
        Folder that relative paths (kernel file, checkpoints) are resolved against.
    target : Kernel
        The kernel every realisation is fitted to, at ``sensor.pitch_m``.
    confine_paths : bool
        Paths in the design (kernel file, checkpoints) must stay inside ``base_dir``
        (:func:`fsdvs_hw.paths.confined_path`); always true for design files.
    spec : pydantic model of :func:`design_model`
        The same design, typed: ``design.spec.sensor.threshold_on``,
        ``design.spec.realisations.asic.bits`` (every option's value, its default where unset).
        Read values from here; :attr:`data` / :meth:`to_dict` is the JSON form stored with
        results and fingerprinted.
    """

    data: dict[str, Any]
    source: str
    base_dir: Path
    target: Kernel = dc_field(repr=False)
    confine_paths: bool = True
    spec: Any = dc_field(default=None, repr=False)

    @property
    def name(self) -> str:
        return str(self.spec.design.name)

    @property
    def slug(self) -> str:
        """The name as a safe file-name stem (:func:`fsdvs_hw.paths.safe_name`): use it in paths."""
        return safe_name(self.name)

    def section(self, name: str) -> dict[str, Any]:
        """A copy of one section (``"sensor"``, ``"realisations.asic"``, ...)."""
        node: Any = self.data
        for part in name.split("."):
            node = node[part]
        return copy.deepcopy(node)

    @property
    def realisations(self) -> list[str]:
        return list(self.spec.realisations.include)

    def realisation_options(self, name: str) -> dict[str, Any]:
        """Keyword options for one hardware realisation's fit function: the options the design sets
        (the fit function's defaults apply to the others); ``{}`` for a reference realisation."""
        options = getattr(self.spec.realisations, name, None)
        return {} if options is None else options.model_dump(exclude_unset=True)

    def checkpoints(self) -> dict[str, list[Path]]:
        """Task name → absolute checkpoint paths (one per training seed, in the design's order)."""
        return {
            t: [
                _resolve(self.base_dir, p, what=f"tasks.checkpoints.{t}", confine=self.confine_paths)
                for p in _as_list(v)
            ]
            for t, v in self.spec.tasks.checkpoints.items()
        }

    def n_test(self, task: str) -> int | None:
        """Test clips per network of ``task`` (``[tasks] n_test``, one number or a table task → clips);
        ``None`` where it is 0 (the checkpoint's own test-set size)."""
        n = self.spec.tasks.n_test
        n = n.get(task, 0) if isinstance(n, Mapping) else n
        return int(n or 0) or None

    def with_overrides(self, overrides: Mapping[str, Any]) -> Design:
        """A new, re-validated design with dotted keys replaced (``{"asic.bits": 4}``)."""
        data = copy.deepcopy(self.data)
        for key, value in overrides.items():
            _set_dotted(data, check_key(str(key), what="override"), value)
        data["sweep"] = {"axes": {}}
        return parse_design(
            data,
            source=f"{self.source} with {dict(overrides)}",
            base_dir=self.base_dir,
            confine_paths=self.confine_paths,
        )

    def fingerprint(self) -> str:
        """SHA-1 over the validated content and the target taps (changes when any input changes)."""
        return fingerprint({"data": self.data, "target": self.target.to_dict()})

    def to_dict(self) -> dict[str, Any]:
        return copy.deepcopy(self.data)


def _as_list(value: Any) -> list[Any]:
    """A checkpoint entry as a list (one path or a list of paths, one per training seed)."""
    return list(value) if isinstance(value, list) else [value]


def _resolve(base: Path, path: str, *, what: str, confine: bool) -> Path:
    if confine:
        return confined_path(base, path, what=what)
    p = Path(path)
    return (p if p.is_absolute() else base / p).resolve()


def _canonical_key(key: str) -> str:
    first = key.split(".", 1)[0]
    if first in _option_tables():
        return "realisations." + key
    return key


def _all_keys() -> list[str]:
    """Every dotted key a design accepts (sections' keys and realisation options), for messages."""
    keys = [f"{s}.{k}" for s in _section_models() for k in _section_keys(s)]
    for name in _option_tables():
        keys.extend(f"{name}.{opt}" for opt in get_realisation(name).options.model_fields)
    return keys


def check_key(key: str, *, what: str = "--set") -> str:
    """Check a dotted design key (``--set KEY=...``, a sweep axis) against the schema; return its
    canonical form (``"asic.bits"`` → ``"realisations.asic.bits"``).

    A key must name one value of the layout: ``section.key``, ``realisation.option`` (or
    ``realisations.realisation.option``), and one level deeper only inside a table-valued key
    (``kernel.params.sigma_centre_px``, ``tasks.n_test.detection``) or a structured fit option.

    Parameters
    ----------
    key : str
        The dotted key as the user wrote it.
    what : str
        How the key was given, for the message (``"--set"``, ``"sweep.axes"``).

    Raises
    ------
    DesignError
        One line naming the key, what is wrong and the closest allowed keys (or the allowed ones).
    """
    sections = _section_models()
    shown = repr(key[:80])
    parts = key.split(".")
    if not key or any(not p.strip() for p in parts):
        raise DesignError(
            f"{what} {shown}: not a dotted design key (an empty part); allowed: section.key, "
            "e.g. sensor.threshold_on or asic.bits"
        )
    ckey = _canonical_key(key)
    cparts = ckey.split(".")
    section = cparts[0]
    known = _all_keys()

    def unknown(why: str, allowed: str | None = None) -> DesignError:
        close = difflib.get_close_matches(key, known, n=3, cutoff=0.6)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        return DesignError(f"{what} {shown}: {why}; {hint}allowed: {allowed or 'sections ' + ', '.join(sections)}")

    if section not in sections:
        raise unknown(f"unknown section {section[:40]!r}")
    if len(cparts) == 1:
        sample = ", ".join(f"{section}.{k}" for k in _section_keys(section)[:6]) or ", ".join(_option_tables())
        raise DesignError(f"{what} {shown}: names a whole section, not a key; allowed: one key of it ({sample})")
    if section == "realisations" and cparts[1] in _option_tables():
        spec = get_realisation(cparts[1])
        options = sorted(spec.options.model_fields)
        if len(cparts) < 3:
            raise DesignError(
                f"{what} {shown}: names the [realisations.{cparts[1]}] table, not an option; "
                f"allowed: {cparts[1]}.<option> with option one of {', '.join(options)}"
            )
        if cparts[2] not in spec.options.model_fields:
            raise unknown(f"unknown option of {spec.fit_name}", ", ".join(options))
        if len(cparts) > (4 if _is_table(spec.options, cparts[2]) else 3):
            raise DesignError(
                f"{what} {shown}: {cparts[1]}.{cparts[2]} is a single value, not a table; "
                f"allowed: {cparts[1]}.{cparts[2]}=VALUE"
            )
        return ckey
    if cparts[1] not in _section_keys(section):
        extra = [*_option_tables()] if section == "realisations" else []
        raise unknown(f"unknown key {cparts[1][:40]!r} in [{section}]", ", ".join([*_section_keys(section), *extra]))
    table = _is_table(sections[section], cparts[1])
    if len(cparts) > (3 if table else 2):
        raise DesignError(
            f"{what} {shown}: {section}.{cparts[1]} is "
            f"{'a table of single values' if table else 'a single value, not a table'}"
            f"; allowed: {section}.{cparts[1]}" + ("[.NAME]" if table else "") + "=VALUE"
        )
    return ckey


def _set_dotted(data: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    node = data
    for p in parts[:-1]:
        if not isinstance(node.get(p), dict):  # a number where a table is set (tasks.n_test.detection)
            node[p] = {}
        node = node[p]
    node[parts[-1]] = value


def load_design(path: str | Path) -> Design:
    """Read and validate a TOML design file.

    Parameters
    ----------
    path : str or Path
        The ``.toml`` file. Relative paths inside it are resolved against its folder.

    Raises
    ------
    DesignError
        Missing or unparsable file, unknown section or key, wrong type, value out of range,
        missing or invalid kernel file, unknown realisation option — all problems found, in one
        message naming the file, each key, its value and what is allowed.

    Examples
    --------
    >>> from fsdvs_hw import load_design
    >>> load_design("designs/default.toml").spec.realisations.asic.bits
    8
    """
    path = Path(path)
    if not path.is_file():
        raise DesignError(f"{path}: design file not found")
    try:
        blob = path.read_bytes() if path.stat().st_size <= MAX_DESIGN_FILE_BYTES else None
    except OSError as exc:
        raise DesignError(f"{path}: cannot read the design file ({exc.strerror})") from None
    if blob is None:
        raise DesignError(f"{path}: larger than {MAX_DESIGN_FILE_BYTES} bytes; not a design file")
    try:
        raw = tomllib.loads(blob.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise DesignError(f"{path}: not UTF-8 text (invalid byte at offset {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise DesignError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:
        raise DesignError(f"{path}: not valid TOML (nested too deeply)") from None
    raw.setdefault("design", {}).setdefault("name", path.stem)
    return parse_design(raw, source=str(path), base_dir=path.parent)


def parse_design(
    raw: Mapping[str, Any], *, source: str = "<design>", base_dir: str | Path = ".", confine_paths: bool = True
) -> Design:
    """Validate a design given as nested mappings (what :func:`load_design` reads from TOML).

    Relative paths are resolved against ``base_dir``; with ``confine_paths`` (the default, and
    always for design files) every path must stay inside it. Pass ``confine_paths=False`` only
    for designs built in your own code that point at files elsewhere.
    """
    chk = _Problems(source)
    if not isinstance(raw, Mapping):
        raise DesignError(f"{source}: a design must be a table, got {type(raw).__name__}")
    model = design_model()
    spec = _validate_sections(chk, model, raw)
    data = spec.model_dump()
    for name in _option_tables():  # only the options the design sets, in its order
        given = raw.get("realisations", {})
        table = given.get(name, {}) if isinstance(given, Mapping) else {}
        dumped = getattr(spec.realisations, name).model_dump(exclude_unset=True)
        data["realisations"][name] = {
            k: dumped[k] for k in (table if isinstance(table, Mapping) else {}) if k in dumped
        }
    if data["design"]["name"] is None:
        data["design"]["name"] = "design"
    if "costs" not in raw:  # a design without [costs] keeps its content and fingerprint (defaults apply)
        del data["costs"]
    for key in ("camera", "upsample"):  # likewise [emulation] without camera (the design's sensor) or upsample
        if key not in (raw.get("emulation") or {}):
            del data["emulation"][key]
    base = Path(base_dir)
    _check_cross(chk, data)
    _expand_checkpoint_patterns(chk, data, base, confine_paths)
    _check_tasks(chk, data, base, confine_paths)
    _check_user_data(chk, data, base, confine_paths)
    _check_codesign(chk, data)
    _check_axes(chk, data)
    target = _load_target(chk, data, base, confine_paths)
    if target is not None:  # the simulator and the hardware fits need it representable in float32
        try:
            check_tap_magnitude(target)
        except KernelError as exc:
            key = "kernel.path" if data["kernel"]["source"] == "file" else "kernel.params"
            chk.add(
                key,
                data["kernel"]["path"] if key == "kernel.path" else data["kernel"]["params"],
                str(exc).split(": ", 1)[-1],
            )
    if target is not None and target.size > min(data["sensor"]["resolution"]):
        chk.add(
            "sensor.resolution",
            data["sensor"]["resolution"],
            f"smaller than the {target.size}x{target.size} kernel; allowed: at least {target.size} px each way",
        )
    _check_sizes(chk, data, base, confine_paths, target)
    _check_options_on_target(chk, data, target)
    chk.raise_if_any()
    assert target is not None
    typed = model.model_validate(data, context=DESIGN_CONTEXT)  # the final values (patterns expanded), typed
    return Design(data=data, source=source, base_dir=base, target=target, confine_paths=confine_paths, spec=typed)


def _validate_sections(chk: _Problems, model: type[StrictModel], raw: Mapping[str, Any]) -> Any:
    """Validate every section against ``model``; report each problem and validate again without
    the keys at fault, so the cross-section checks see defaults there and no mistake is reported
    twice. ``None`` in a section marks an unset key (re-validated data of :meth:`Design.with_overrides`)."""
    work: dict[Any, Any] = {}
    for section, given in raw.items():
        if not isinstance(given, Mapping):
            work[section] = given
            continue
        table = {k: v for k, v in given.items() if v is not None}
        if section == "realisations":
            table = {
                k: (dict(v) if isinstance(v, Mapping) and k in _option_tables() else v)
                for k, v in given.items()
                if v is not None or k in _option_tables()
            }
        work[section] = table
    for _ in range(8):
        try:
            return model.model_validate(work, context=DESIGN_CONTEXT)
        except ValidationError as exc:
            chk.problems.extend(problems(exc, model))
            for err in exc.errors():
                _drop(work, tuple(err["loc"]))
    raise DesignError(f"{chk.source}: invalid design file:\n  " + "\n  ".join(chk.problems))  # pragma: no cover


def _drop(work: dict[Any, Any], loc: tuple[Any, ...]) -> None:
    """Remove the key an error is about (a section, a key or a realisation's option) from ``work``."""
    section = loc[0]
    if len(loc) == 1 or not isinstance(work.get(section), dict):
        work.pop(section, None)
        return
    table, key = work[section], loc[1]
    if section == "realisations" and key in _option_tables() and len(loc) > 2 and isinstance(table.get(key), dict):
        table[key].pop(loc[2], None)
    else:
        table.pop(key, None)


def _check_options_on_target(chk: _Problems, data: dict[str, Any], target: Kernel | None) -> None:
    """Each included realisation's options against its fit's rules on the target kernel (its options
    model validated with the target in the context, as the fit does: the same rules and words)."""
    if target is None:
        return
    try:
        check_tap_magnitude(target)
    except KernelError:  # reported with the kernel; as in a fit, the rules need a representable target
        return
    for name in dict.fromkeys(data["realisations"]["include"]):
        if name not in _option_tables():
            continue
        options = get_realisation(name).options
        try:
            options.model_validate(data["realisations"][name], context={**DESIGN_CONTEXT, "target": target})
        except ValidationError as exc:
            chk.problems.extend(problems(exc, options, prefix=f"realisations.{name}."))


def _check_cross(chk: _Problems, data: dict[str, Any]) -> None:
    em = data["emulation"]
    if em["enabled"]:  # the display the emulation track builds must exist (black below peak, ...)
        from .emulation import DisplaySettings

        try:
            DisplaySettings.from_design(em)
        except InputError as exc:
            chk.add(
                "emulation.display_black_nits",
                em["display_black_nits"],
                f"the emulation display is invalid with emulation.display_peak_nits = "
                f"{em['display_peak_nits']:g} ({exc})",
            )
    k = data["kernel"]
    if k["source"] == "file" and not k["path"]:
        chk.add("kernel.path", k["path"], "required when kernel.source = 'file'")
    for key, value in k["params"].items():
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            chk.add(f"kernel.params.{key}", value, "reference kernel parameters must be numbers")
    methods = data["analysis"]["csf_methods"]
    for i, m in enumerate(methods):
        if m not in CSF_METHODS:
            chk.add(f"analysis.csf_methods[{i}]", m, f"unknown CSF model; allowed: {', '.join(CSF_METHODS)}")
    if len(set(data["realisations"]["include"])) != len(data["realisations"]["include"]):
        chk.add("realisations.include", data["realisations"]["include"], "lists a realisation twice")


def _check_sizes(chk: _Problems, data: dict[str, Any], base: Path, confine: bool, target: Kernel | None) -> None:
    """Sizes that must agree across sections, checked at load so no run fails after work started.

    The emulation track renders ``emulation.n_clips`` synthetic clips of ``sensor.resolution``
    (a :class:`~fsdvs_hw.scenes.synthetic.SceneConfig`: at most 2048 px a side, larger than its
    default 7 px radius objects) and upsamples them ``emulation.upsample_factor`` times; their
    video must fit the allocation limit (:mod:`fsdvs_hw.limits`). Every task checkpoint's clips
    (its stored scene) must be at least as large as the kernel.
    """
    from ..limits import max_alloc_bytes
    from ..scenes.synthetic import SceneConfig

    h, w = data["sensor"]["resolution"]
    em = data["emulation"]
    reported = any(p.startswith("key 'sensor.resolution'") for p in chk.problems)  # one problem per key
    if em["enabled"]:
        obj = SceneConfig().radius_px[1]
        if not reported and (max(h, w) > 2048 or 2 * obj + 2 >= min(h, w)):
            chk.add(
                "sensor.resolution",
                [h, w],
                f"the emulation track renders clips of this size with objects up to "
                f"{2 * obj + 2:g} px across; allowed with emulation.enabled = true: {int(2 * obj + 3)} to 2048 px "
                "each way (or emulation.enabled = false)",
            )
        frames = (em["n_frames"] - 1) * em["upsample_factor"] + 1
        n_bytes = 8.0 * em["n_clips"] * frames * h * w
        if n_bytes > max_alloc_bytes():
            chk.add(
                "emulation.n_clips",
                em["n_clips"],
                f"with emulation.n_frames = {em['n_frames']}, emulation.upsample_factor = {em['upsample_factor']} "
                f"and sensor.resolution = [{h}, {w}] the upsampled video is {n_bytes / 2**30:.3g} GiB, more than "
                f"the allocation limit of {max_alloc_bytes() / 2**30:.3g} GiB (fsdvs_hw.limits)",
            )
    if target is None:
        return
    for task, entry in data["tasks"]["checkpoints"].items():
        for i, path in enumerate(_as_list(entry)):
            if not isinstance(path, str):
                continue
            try:
                p = _resolve(base, path, what="checkpoint", confine=confine)
                if p.suffix != ".safetensors":
                    p = p.with_suffix(".safetensors") if p.suffix == ".json" else Path(str(p) + ".safetensors")
                with p.open("rb") as fh:
                    n = int.from_bytes(fh.read(8), "little")
                    header = json.loads(fh.read(min(n, 100 * 2**20)).decode("utf-8"))
                scene = json.loads(header["__metadata__"]["provenance"])["scene"]
                sh, sw = int(scene["height_px"]), int(scene["width_px"])
            except Exception:  # unreadable: _check_tasks has reported it
                continue
            if target.size > min(sh, sw):
                key = f"tasks.checkpoints.{task}" + (f"[{i}]" if isinstance(entry, list) else "")
                chk.add(
                    key,
                    path,
                    f"its clips are {sh}x{sw} px, smaller than the {target.size}x{target.size} "
                    f"kernel (kernel.size / kernel.path); allowed: checkpoints whose clips are at least "
                    f"{target.size} px each way",
                )


def _natural_key(path: str) -> list[Any]:
    """Sort key that puts ``s2`` before ``s10``."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path)]


#: Most directory entries one checkpoint glob pattern may look at before it is refused.
MAX_GLOB_ENTRIES = 20000


class _GlobTooWideError(Exception):
    """A pattern's walk looked at more than :data:`MAX_GLOB_ENTRIES` entries."""


def _bounded_glob(root: Path, parts: list[str], *, limit: int = MAX_GLOB_ENTRIES) -> list[Path]:
    """Paths under ``root`` matching the pattern components ``parts`` (one level each, like
    :func:`glob.glob` without ``recursive``: ``**`` is ``*``), hidden names only by a pattern that
    starts with ``.``; raises :class:`_GlobTooWideError` after ``limit`` entries are looked at."""
    level = [root]
    seen = 0
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        nxt: list[Path] = []
        for folder in level:
            if not glob.has_magic(part):
                cand = folder / part
                seen += 1
                if cand.exists() if last else cand.is_dir():
                    nxt.append(cand)
                continue
            try:
                with os.scandir(folder) as it:
                    for entry in it:
                        seen += 1
                        if seen > limit:
                            raise _GlobTooWideError
                        if entry.name.startswith(".") and not part.startswith("."):
                            continue
                        if fnmatch.fnmatchcase(entry.name, part) and (last or entry.is_dir()):
                            nxt.append(Path(entry.path))
            except (NotADirectoryError, FileNotFoundError, PermissionError):
                continue
        if seen > limit:
            raise _GlobTooWideError
        level = nxt
    return level


def _expand_checkpoint_patterns(chk: _Problems, data: dict[str, Any], base: Path, confine: bool = True) -> None:
    """Replace glob patterns in ``[tasks] checkpoints`` by the files they match, in natural order.

    ``"networks/detection_*_s*.safetensors"`` lists one network per training seed (``s2`` before
    ``s10``); the expanded list is what the design records, so a stored result names its networks.
    A pattern is matched inside the design's folder only (with ``confine``, always for design
    files): an absolute pattern or one with ``..`` is refused, a match that a link takes out of the
    folder is left out (and not named), and a walk that looks at more than
    :data:`MAX_GLOB_ENTRIES` directory entries is refused.
    """
    ckpts = data["tasks"]["checkpoints"]
    root = base.resolve()
    for task, entry in list(ckpts.items()):
        out: list[Any] = []
        for i, path in enumerate(_as_list(entry)):
            if not (isinstance(path, str) and glob.has_magic(path)):
                out.append(path)
                continue
            key = f"tasks.checkpoints.{task}" + (f"[{i}]" if isinstance(entry, list) else "")
            pattern = Path(path)
            parts = [p for p in pattern.parts if p not in ("", ".")]
            if "\x00" in path:
                chk.add(key, path, "contains a NUL byte")
                continue
            if confine and (pattern.is_absolute() or ".." in parts):
                chk.add(
                    key,
                    path,
                    f"a glob pattern must stay inside the design's folder {root}; allowed: a "
                    "relative pattern without '..' (e.g. 'networks/det_s*.safetensors')",
                )
                continue
            if pattern.is_absolute():  # confine_paths=False: walk from the pattern's fixed prefix
                n_fixed = next((j for j, p in enumerate(parts) if glob.has_magic(p)), len(parts))
                start, parts = Path(*parts[:n_fixed]), parts[n_fixed:]
            else:
                start = root
            try:
                found = _bounded_glob(start, parts, limit=MAX_GLOB_ENTRIES)
            except _GlobTooWideError:
                chk.add(
                    key,
                    path,
                    f"the pattern looks at more than {MAX_GLOB_ENTRIES} files and folders; allowed: "
                    "a narrower pattern (e.g. 'networks/det_s*.safetensors')",
                )
                continue
            inside = [m for m in found if not confine or m.resolve() == root or root in m.resolve().parents]
            matches = sorted(
                ((m.relative_to(root) if start == root else m).as_posix() for m in inside), key=_natural_key
            )
            if not matches:
                left = len(found) - len(inside)
                why = f" ({left} match(es) lead out of the folder through a link and are not used)" if left else ""
                chk.add(key, path, f"the pattern matches no file under {root}{why}")
            out.extend(matches)
        if out != _as_list(entry):
            ckpts[task] = out


def _check_tasks(chk: _Problems, data: dict[str, Any], base: Path, confine: bool) -> None:
    """Each task must be a registered evaluator and its checkpoint must exist."""
    ckpts = data["tasks"]["checkpoints"]
    known = {**ckpts, **data["tasks"]["datasets"]}  # tasks scored: trained checkpoints and user data
    if not known:
        return
    from ..tasks import EVALUATORS  # torch: imported only when a design names tasks

    for task, entry in ckpts.items():
        key = f"tasks.checkpoints.{task}"
        if task not in EVALUATORS:
            chk.add(key, entry, f"unknown task; allowed: {', '.join(EVALUATORS)}")
        if isinstance(entry, list) and not entry:
            chk.add(key, entry, "an empty list; allowed: a path or a non-empty list of paths (one per seed)")
        paths = _as_list(entry)
        if len({str(p) for p in paths}) != len(paths):
            chk.add(key, entry, "lists a checkpoint twice (each entry must be a different training seed)")
        for i, path in enumerate(paths):
            _check_checkpoint(chk, key if not isinstance(entry, list) else f"{key}[{i}]", path, base, confine)
    _check_task_clips(chk, data)
    _check_task_weights(chk, data, known)


def _check_checkpoint(chk: _Problems, key: str, path: Any, base: Path, confine: bool) -> None:
    """One checkpoint entry: a path string to a readable ``.safetensors`` file (``.json`` or no suffix: its pair)."""
    if not isinstance(path, str):
        chk.add(key, path, "must be a path string to a .safetensors checkpoint")
        return
    try:
        p = _resolve(base, path, what=key, confine=confine)
    except InputError as exc:
        chk.add(key, path, str(exc).split(": ", 1)[-1])
        return
    if p.suffix != ".safetensors":
        p = p.with_suffix(".safetensors") if p.suffix == ".json" else Path(str(p) + ".safetensors")
    if not p.is_file():
        chk.add(key, path, f"checkpoint file not found (looked for {p})")
    else:
        why = _safetensors_problem(p)
        if why is not None:
            chk.add(key, path, f"not a usable checkpoint ({why})")


def _check_task_clips(chk: _Problems, data: dict[str, Any]) -> None:
    """``tasks.n_test`` / ``tasks.n_test_emulation`` given as tables: each key a checkpoint task, each value a count."""
    ckpts = data["tasks"]["checkpoints"]
    for field_name in ("n_test", "n_test_emulation"):
        n_test = data["tasks"][field_name]
        if not isinstance(n_test, dict):
            continue
        for task, n in n_test.items():
            key = f"tasks.{field_name}.{task}"
            if task in data["tasks"]["datasets"]:
                chk.add(key, n, f"a user-data task; allowed: its clips are set by tasks.datasets.{task}.n_clips")
            elif task not in ckpts:
                chk.add(key, n, f"not a task in tasks.checkpoints; allowed: {', '.join(ckpts)}")
            elif isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= 100_000:
                chk.add(key, n, "allowed: an integer in [0, 100000] (0 = the default)")


def _check_task_weights(chk: _Problems, data: dict[str, Any], known: Mapping[str, Any]) -> None:
    """``scoring.task_weights``: each a scored task's finite weight >= 0, at least one positive."""
    for task, w in data["scoring"]["task_weights"].items():
        if task not in known:
            chk.add(
                f"scoring.task_weights.{task}",
                w,
                f"not a task in tasks.checkpoints or tasks.datasets; allowed: {', '.join(known)}",
            )
        elif isinstance(w, bool) or not isinstance(w, (int, float)) or not (math.isfinite(w) and w >= 0):
            chk.add(f"scoring.task_weights.{task}", w, "allowed: a finite number >= 0")
    weights = data["scoring"]["task_weights"]
    valid = all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
        for v in weights.values()
    )
    if weights and valid and not any(v > 0 for v in weights.values()):
        chk.add("scoring.task_weights", weights, "every weight is 0; allowed: at least one positive weight")


def _check_user_data(chk: _Problems, data: dict[str, Any], base: Path, confine: bool) -> None:
    """Each ``[tasks.datasets.<task>]`` opens (layout read, network built; fsdvs_hw.explore.user_data)."""
    from .user_data import check_user_task

    for task, entry in data["tasks"]["datasets"].items():
        if task in data["tasks"]["checkpoints"]:
            chk.add(
                f"tasks.datasets.{task}",
                entry,
                f"task {task!r} is also in tasks.checkpoints; allowed: a task "
                "scored either with trained checkpoints or on user data (one table per task)",
            )
            continue
        for key, value, why in check_user_task(task, entry, base, confine=confine):
            chk.add(key, value, why)


def _check_codesign(chk: _Problems, data: dict[str, Any]) -> None:
    """``[codesign]`` against ``[tasks]``: its tasks, cells and seeds must exist there; a user-data task
    needs a trained network (``weights`` or a ``train`` table)."""
    cd = data["codesign"]
    ckpts = data["tasks"]["checkpoints"]
    users = data["tasks"]["datasets"]
    known = [*ckpts, *users]
    tasks = cd["tasks"] or known
    for i, t in enumerate(cd["tasks"]):
        if t not in known:
            chk.add(
                f"codesign.tasks[{i}]",
                t,
                f"not a task in tasks.checkpoints or tasks.datasets; allowed: {', '.join(known) or 'none'}",
            )
    for i, cell in enumerate(cd["cells"]):
        real, _, task = cell.partition("/")
        if real not in cd["realisations"] or task not in tasks:
            chk.add(
                f"codesign.cells[{i}]",
                cell,
                "allowed: 'realisation/task' with a realisation of "
                f"codesign.realisations ({', '.join(cd['realisations'])}) and a task of "
                f"{', '.join(tasks) or 'none'}",
            )
    if len(set(cd["cells"])) != len(cd["cells"]):
        chk.add("codesign.cells", cd["cells"], "lists a cell twice")
    if not cd["enabled"]:
        return
    if not known:
        chk.add(
            "codesign.enabled",
            True,
            "needs trained networks; allowed: tasks.checkpoints or tasks.datasets set, or codesign.enabled = false",
        )
    if not cd["modes"]:
        chk.add("codesign.modes", cd["modes"], f"empty; allowed: a non-empty list of {', '.join(CODESIGN_MODES)}")
    if not cd["realisations"]:
        chk.add("codesign.realisations", cd["realisations"], "empty; allowed: a realisation with a differentiable form")
    if data["tasks"]["sensor"] != "checkpoint":
        chk.add(
            "tasks.sensor",
            data["tasks"]["sensor"],
            "codesign rows train and score with the checkpoint's "
            "simulator; allowed with codesign.enabled: 'checkpoint'",
        )
    for t in tasks:
        if t in ckpts:
            _check_codesign_checkpoint_task(chk, t, data)
        elif t in users:
            _check_codesign_user_task(chk, t, users[t])


def _check_codesign_checkpoint_task(chk: _Problems, task: str, data: dict[str, Any]) -> None:
    """A co-designed checkpoint task needs ``codesign.seeds`` networks and 2+ test clips per network."""
    seeds, n_nets = data["codesign"]["seeds"], len(_as_list(data["tasks"]["checkpoints"][task]))
    if seeds > n_nets:
        chk.add(
            "codesign.seeds",
            seeds,
            f"task {task!r} has {n_nets} network(s) in tasks.checkpoints; allowed: at most {n_nets}",
        )
    n = data["tasks"]["n_test"]
    n = n.get(task, 0) if isinstance(n, dict) else n
    if n == 1:
        chk.add("tasks.n_test", n, "codesign CIs need at least 2 test clips per network")


def _check_codesign_user_task(chk: _Problems, task: str, entry: dict[str, Any]) -> None:
    """A co-designed user-data task needs a trained network (``weights`` or ``train``) and 2+ scored clips."""
    if not entry["weights"] and entry.get("train") is None:
        chk.add(
            f"tasks.datasets.{task}",
            "no weights, no train",
            "codesign compares rows against a trained "
            f"network; allowed: weights = '...' or a train = {{...}} table, or codesign.tasks without {task!r}",
        )
    if entry["n_clips"] == 1:
        chk.add(f"tasks.datasets.{task}.n_clips", 1, "codesign CIs need at least 2 scored clips")


def _safetensors_problem(path: Path) -> str | None:
    """Why ``path`` is not a safetensors file with a ``kernel`` tensor (header only, no torch), or None."""
    try:
        size = path.stat().st_size
        with path.open("rb") as fh:
            head = fh.read(8)
            if len(head) < 8:
                return "shorter than a safetensors header"
            n = int.from_bytes(head, "little")
            if not 2 <= n <= min(size - 8, 100 * 2**20):
                return "not a safetensors file (bad header length)"
            header = json.loads(fh.read(n).decode("utf-8"))
    except OSError as exc:
        return f"cannot read: {exc.strerror}"
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        return "not a safetensors file (header is not JSON)"
    if not isinstance(header, dict) or "kernel" not in header:
        return "no 'kernel' tensor: not written by fsdvs_hw learn"
    return None


def _check_axes(chk: _Problems, data: dict[str, Any]) -> None:
    """Each sweep axis names one key (:func:`check_key`) and each of its values passes that key's model."""
    model = design_model()
    for key, values in data["sweep"]["axes"].items():
        full = f"sweep.axes.{key}"
        if not isinstance(values, list) or not values:
            chk.add(full, values, "a sweep axis must be a non-empty list of values")
            continue
        try:
            ckey = check_key(key, what="axis")
        except DesignError as exc:
            chk.add(full, values, str(exc).split(": ", 1)[-1])
            continue
        section, _, rest = ckey.partition(".")
        if section in ("sweep", "run", "design") or not rest:
            chk.add(
                full,
                values,
                "sweep axes must name a key inside [kernel], [sensor], [optics], [analysis], "
                "[tasks], [emulation] or a realisation (e.g. 'asic.bits')",
            )
            continue
        if section == "realisations" and rest.split(".")[0] not in _option_tables():
            chk.add(full, values, f"unknown realisation {rest.split('.')[0]!r}; allowed: {', '.join(_option_tables())}")
            continue
        for v in values:  # each value through the same model as a plain key
            probe: dict[str, Any] = {}
            _set_dotted(probe, ckey, v)
            try:
                model.model_validate(probe, context=DESIGN_CONTEXT)
            except ValidationError as exc:
                chk.problems.extend(p.replace(f"key '{ckey}", f"key '{full}", 1) for p in problems(exc, model))


def _load_target(chk: _Problems, data: dict[str, Any], base: Path, confine: bool) -> Kernel | None:
    k = data["kernel"]
    pitch = data["sensor"]["pitch_m"]
    try:
        if k["source"] == "file":
            if not k["path"]:
                return None
            try:
                path = _resolve(base, k["path"], what="kernel.path", confine=confine)
            except InputError as exc:
                chk.add("kernel.path", k["path"], str(exc).split(": ", 1)[-1])
                return None
            if not path.is_file():
                chk.add("kernel.path", k["path"], f"kernel file not found (looked for {path})")
                return None
            return load_kernel(path, pitch_m=pitch)
        return reference_kernel(k["family"], k["size"], pitch_m=pitch, **k["params"])
    except KernelError as exc:
        key = "kernel.path" if k["source"] == "file" else "kernel.params"
        chk.add(key, k["path"] if k["source"] == "file" else k["params"], f"invalid kernel ({exc})")
        return None


def axis_values(design: Design) -> dict[str, list[Any]]:
    """The sweep axes of a design as canonical dotted keys → values."""
    return {_canonical_key(k): list(v) for k, v in design.spec.sweep.axes.items()}
