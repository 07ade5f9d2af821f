"""The sections of a design file as pydantic models, and the model of a whole design file.

Every section and key of the layout (:mod:`fsdvs_hw.design.design`) with its default, unit,
range and one line of meaning. ``[realisations]`` and ``[codesign]`` are built from the
realisation registry (:mod:`fsdvs_hw.realise.registry`) when :func:`design_model` is called, so a
realisation registered by any module is accepted without a change here;
:func:`design_json_schema` is the same model as a JSON Schema for editors.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, get_args

from pydantic import Field, create_model, field_validator

from ..costs.assumptions import CostAssumptions
from ..kernels import DEFAULT_PITCH_M, MAX_KERNEL_SIZE, REFERENCE_KERNELS
from ..limits import MAX_WORKERS
from ..realise.registry import get_realisation, realisation_names
from ..schema import StrictModel, field, field_schema, members
from .user_data_section import UserTask

__all__ = [
    "CODESIGN_MODES",
    "CSF_DEFAULT_METHODS",
    "EMULATION_CAMERAS",
    "AnalysisSection",
    "DesignSection",
    "EmulationSection",
    "KernelSection",
    "OpticsSection",
    "ProcessSection",
    "RateSection",
    "RunSection",
    "ScoringSection",
    "SensorSection",
    "SweepSection",
    "TasksSection",
    "design_json_schema",
    "design_model",
    "is_table_field",
    "option_tables",
    "section_keys",
    "section_models",
]

#: CSF models scored when a design names none (Mannos–Sakrison first: the paper's reference).
CSF_DEFAULT_METHODS: tuple[str, ...] = ("mannos_sakrison_1974", "barten_1999", "daly_1993", "watson_ahumada_2005")

_Placement = Literal["pre_log", "post_log"]
_Positivity = Literal["floor", "pedestal", "differential"]
_Track = Literal["simulator", "emulation"]
_PLACEMENTS = get_args(_Placement)
_POSITIVITY = get_args(_Positivity)
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
    """``[design]``: what the exploration is called, and the folders besides its own that its data may live in."""

    name: str | None = field(None, "", "short name used in reports")
    description: str = field("", "", "free text")
    data_roots: list[str] = field(
        [],
        "",
        "folders outside the design's folder that its paths may name (datasets and every file they "
        "name, weights, kernel, train.out, clip cache): absolute or relative to the design file",
        max_length=64,
    )


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
        "weights, n_clips, max_failed_clip_fraction; fsdvs_hw.design.user_data_section); {} = none",
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
        "'flow' (optical-flow interpolation in log intensity with occlusion handling, fsdvs_hw.sensor.simulation.upsampling; "
        "closer to the paper's RIFE)",
    )
    camera: Literal[EMULATION_CAMERAS] = field(  # type: ignore[valid-type]
        "design",
        "",
        "the camera that recaptures the display: 'design' (the design's [sensor]) or a sensor preset "
        "with sourced parameters (fsdvs_hw.sensor.cameras.presets; 'imx636' is the paper's EVK4)",
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


class ProcessSection(StrictModel):
    """``[process]``: build in a real process (PDK); without it the idealised models stay.

    With ``[process]`` a design that includes ``mesh`` also scores ``mesh_process`` (the mesh as the
    PDK's subthreshold transistors, :mod:`fsdvs_hw.process`), whose options default to these keys.
    """

    pdk: str = field("sky130", "", "registered process (fsdvs_hw.process.process_names)")
    corners: list[Literal["tt", "ff", "ss", "sf", "fs"]] = field(
        ["tt", "ff", "ss"], "", "global corners of the device models, the first nominal"
    )
    temperatures_c: list[Annotated[float, Field(ge=-55, le=150)]] = field(
        [27.0, 85.0], "", "temperatures in °C (-55 … 150), the first nominal"
    )
    supply_v: float | None = field(
        None, "V", "core supply (default: the PDK's nominal, 1.8 V in sky130)", ge=0.5, le=5.0
    )
    mismatch_samples: int = field(30, "", "Monte Carlo mismatch samples at the nominal corner (0: none)", ge=0, le=1000)
    reference_v: float = field(0.5, "V", "rest voltage of the mesh nodes", ge=0.1, le=1.2)

    @field_validator("pdk")
    @classmethod
    def _registered(cls, value: str) -> str:
        from ..process import get_process

        get_process(value)  # an InputError (a ValueError) naming the registered processes
        return value


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
    hardware = option_tables()
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
        "process": ProcessSection,
    }
    fields: dict[str, Any] = {k: (m, _default(m)) for k, m in sections.items()}
    model = create_model(
        "DesignFile",
        __base__=StrictModel,
        __doc__="A design file of fsdvs_hw (fsdvs_hw.design): every section optional.",
        **fields,
    )
    model.unknown_key = "unknown section"
    _MODELS[sig] = model
    return model


def section_models() -> dict[str, type[StrictModel]]:
    """Section name → its model (of :func:`design_model`)."""
    return {k: f.annotation for k, f in design_model().model_fields.items()}  # type: ignore[misc]


def section_keys(section: str) -> list[str]:
    """The keys of one section (for ``[realisations]``: ``include``, not the option tables)."""
    keys = list(section_models()[section].model_fields)
    return [k for k in keys if not (section == "realisations" and k in option_tables())]


def is_table_field(model: type[StrictModel], name: str) -> bool:
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


def option_tables() -> tuple[str, ...]:
    """Realisations that take fit options (a ``[realisations.<name>]`` table): the hardware ones."""
    return realisation_names("hardware")
