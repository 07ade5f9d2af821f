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
                    (fsdvs_hw.design.user_data_section)
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
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from dataclasses import field as dc_field
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from ..fingerprints import fingerprint
from ..kernels import Kernel
from ..paths import Confinement, DataRoots, safe_name
from ..schema import DESIGN_CONTEXT, StrictModel, problems
from .checkpoints import checkpoint_entries
from .checks import check_design, process_fit_options
from .design_paths import resolve_design_path
from .keys import canonical_key, check_key, set_dotted_key
from .problems import DesignError, DesignProblems
from .sections import design_model, option_tables

__all__ = [
    "MAX_DESIGN_FILE_BYTES",
    "Design",
    "axis_values",
    "load_design",
    "parse_design",
    "process_fit_options",
]

#: Largest design file read (bytes).
MAX_DESIGN_FILE_BYTES = 1 * 2**20


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
    confine_paths : bool or DataRoots
        Paths in the design (kernel file, checkpoints, datasets) must stay inside ``base_dir``
        (:func:`fsdvs_hw.paths.confined_path`); always true for design files. A design with
        ``[design] data_roots`` holds them here (:class:`~fsdvs_hw.paths.DataRoots`, truthy):
        its paths may lie in those folders too.
    spec : pydantic model of :func:`design_model`
        The same design, typed: ``design.spec.sensor.threshold_on``,
        ``design.spec.realisations.asic.bits`` (every option's value, its default where unset).
        Read values from here; :attr:`data` / :meth:`to_dict` is the JSON form stored with
        results and fingerprinted.

    Examples
    --------
    >>> from fsdvs_hw import parse_design
    >>> design = parse_design({"design": {"name": "demo"}, "sensor": {"threshold_on": 0.15}})
    >>> design.name, design.spec.sensor.threshold_on, design.target.size
    ('demo', 0.15, 7)
    """

    data: dict[str, Any]
    source: str
    base_dir: Path
    target: Kernel = dc_field(repr=False)
    confine_paths: Confinement = True
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
        (the fit function's defaults apply to the others), with ``[process]`` keys as defaults where the
        realisation builds in a process (:func:`process_fit_options`); ``{}`` for a reference realisation."""
        options = getattr(self.spec.realisations, name, None)
        given = {} if options is None else options.model_dump(exclude_unset=True)
        return process_fit_options(self.data, name, given) if options is not None else given

    def checkpoints(self) -> dict[str, list[Path]]:
        """Task name → absolute checkpoint paths (one per training seed, in the design's order)."""
        return {
            t: [
                resolve_design_path(self.base_dir, p, what=f"tasks.checkpoints.{t}", confine=self.confine_paths)
                for p in checkpoint_entries(v)
            ]
            for t, v in self.spec.tasks.checkpoints.items()
        }

    def n_test(self, task: str) -> int | None:
        """Test clips per network of ``task`` (``[tasks] n_test``, one number or a table task → clips);
        ``None`` where it is 0 (the checkpoint's own test-set size)."""
        n = self.spec.tasks.n_test
        n = n.get(task, 0) if isinstance(n, Mapping) else n
        return int(n or 0) or None

    @property
    def pending_kernel_task(self) -> str | None:
        """The task whose ``train`` table will write the ``[kernel] path`` file not there yet, else None.

        Such a design's :attr:`target` is a stand-in (a delta): train first (``fsdvs-hw learn``,
        or ``explore``, which trains and then calls :meth:`reloaded`).
        """
        task = self.target.provenance.get("pending_training")
        return None if task is None else str(task)

    def reloaded(self) -> Design:
        """The same design read again (its kernel file re-read: after training has written it)."""
        return parse_design(self.data, source=self.source, base_dir=self.base_dir, confine_paths=self.confine_paths)

    def with_overrides(self, overrides: Mapping[str, Any]) -> Design:
        """A new, re-validated design with dotted keys replaced (``{"asic.bits": 4}``)."""
        data = copy.deepcopy(self.data)
        for key, value in overrides.items():
            set_dotted_key(data, check_key(str(key), what="override"), value)
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


def _apply_process(data: dict[str, Any]) -> None:
    """``[process]``: a design that includes ``mesh`` also scores ``mesh_process`` (the mesh in the PDK's transistors)."""
    from ..realise.registry import realisation_names

    include = data["realisations"]["include"]
    if "mesh_process" in realisation_names() and "mesh" in include and "mesh_process" not in include:
        include.insert(include.index("mesh") + 1, "mesh_process")


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
    raw: Mapping[str, Any],
    *,
    source: str = "<design>",
    base_dir: str | Path = ".",
    confine_paths: Confinement = True,
) -> Design:
    """Validate a design given as nested mappings (what :func:`load_design` reads from TOML).
    Relative paths are resolved against ``base_dir``; with ``confine_paths`` (the default, and
    always for design files) every path must stay inside it. Pass ``confine_paths=False`` only
    for designs built in your own code that point at files elsewhere.

    Raises
    ------
    DesignError
        Every problem found, in one message (as :func:`load_design`).

    Examples
    --------
    >>> from fsdvs_hw import parse_design
    >>> parse_design({"realisations": {"include": ["learned", "asic"], "asic": {"bits": 4}}}).realisations
    ['learned', 'asic']
    """
    chk = DesignProblems(source)
    if not isinstance(raw, Mapping):
        raise DesignError(f"{source}: a design must be a table, got {type(raw).__name__}")
    model = design_model()
    spec = _validate_sections(chk, model, raw)
    data = spec.model_dump()
    for name in option_tables():  # only the options the design sets, in its order
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
    if "process" not in raw:  # without [process]: the idealised models, the same content and fingerprint
        del data["process"]
    else:
        _apply_process(data)
    tables = data["realisations"]
    if "mesh_process" in tables and not tables["mesh_process"] and "mesh_process" not in tables["include"]:
        del tables["mesh_process"]  # likewise: a design that does not build in a process keeps its fingerprint
    for key in ("camera", "upsample"):  # likewise [emulation] without camera (the design's sensor) or upsample
        if key not in (raw.get("emulation") or {}):
            del data["emulation"][key]
    given = raw.get("design")
    if not (isinstance(given, Mapping) and given.get("data_roots")):  # without data_roots: the same fingerprint
        del data["design"]["data_roots"]
    base = Path(base_dir)
    confine_paths = _data_roots(chk, data, base, confine_paths)
    target = check_design(chk, data, base, confine_paths)
    chk.raise_if_any()
    assert target is not None
    typed = model.model_validate(data, context=DESIGN_CONTEXT)  # the final values (patterns expanded), typed
    return Design(data=data, source=source, base_dir=base, target=target, confine_paths=confine_paths, spec=typed)


def _data_roots(chk: DesignProblems, data: dict[str, Any], base: Path, confine: Confinement) -> Confinement:
    """``[design] data_roots`` resolved (absolute, or relative to ``base``): each must be a folder.

    Returns the confinement of the design's paths: :class:`~fsdvs_hw.paths.DataRoots` when the
    design confines its paths and names roots, else ``confine`` as given (``True`` / ``False``).
    """
    roots = []
    for i, text in enumerate(data["design"].get("data_roots", [])):
        if "\x00" in text:
            chk.add(f"design.data_roots[{i}]", text, "contains a NUL byte")
            continue
        p = Path(text).expanduser()
        folder = (p if p.is_absolute() else base / p).resolve()
        if not folder.is_dir():
            chk.add(
                f"design.data_roots[{i}]", text, f"not a folder (resolves to {folder}); allowed: an existing folder"
            )
        else:
            roots.append(folder)
    return DataRoots(tuple(roots)) if confine and roots else bool(confine)


def _validate_sections(chk: DesignProblems, model: type[StrictModel], raw: Mapping[str, Any]) -> Any:
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
                k: (dict(v) if isinstance(v, Mapping) and k in option_tables() else v)
                for k, v in given.items()
                if v is not None or k in option_tables()
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
    if section == "realisations" and key in option_tables() and len(loc) > 2 and isinstance(table.get(key), dict):
        table[key].pop(loc[2], None)
    else:
        table.pop(key, None)


def axis_values(design: Design) -> dict[str, list[Any]]:
    """The sweep axes of a design as canonical dotted keys → values."""
    return {canonical_key(k): list(v) for k, v in design.spec.sweep.axes.items()}
