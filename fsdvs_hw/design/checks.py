"""A design's checks across sections, run once its sections are valid: every problem found before work starts.

The display the emulation track builds, the kernel and CSF models, the tasks and their
checkpoints (glob patterns expanded), the user-data tables (opened), ``[codesign]`` against
``[tasks]``, the sweep axes, the target kernel and the sizes that must agree, and each
realisation's options on the target. :func:`check_design` runs them in that order.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from ..csf import CSF_METHODS
from ..errors import InputError, KernelError
from ..kernels import Kernel, check_tap_magnitude, load_kernel, reference_kernel
from ..paths import Confinement
from ..realise.registry import get_realisation
from ..schema import DESIGN_CONTEXT, problems
from .checkpoints import check_checkpoint_entry, checkpoint_entries, expand_checkpoint_patterns
from .design_paths import resolve_design_path
from .display_settings import DisplaySettings
from .keys import check_key, set_dotted_key
from .problems import DesignError, DesignProblems
from .sections import CODESIGN_MODES, design_model, option_tables
from .user_data_inputs import check_user_task, pending_kernel

__all__ = ["check_design", "process_fit_options"]


def check_design(chk: DesignProblems, data: dict[str, Any], base: Path, confine: Confinement) -> Kernel | None:
    """Run every cross-section check on ``data`` (validated sections), adding each problem to ``chk``.

    Checkpoint glob patterns in ``data`` are replaced by the files they match.

    Parameters
    ----------
    chk : DesignProblems
        Collects the problems (raised together by the caller).
    data : dict
        The validated design (sections → keys); changed in place where patterns expand.
    base : Path
        The design file's folder.
    confine : bool
        Paths must stay inside ``base``.

    Returns
    -------
    Kernel or None
        The target kernel, or None where it could not be loaded (a problem says why).
    """
    _check_cross(chk, data)
    expand_checkpoint_patterns(chk, data, base, confine)
    _check_tasks(chk, data, base, confine)
    _check_user_data(chk, data, base, confine)
    _check_codesign(chk, data)
    _check_axes(chk, data)
    target = _load_target(chk, data, base, confine)
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
    _check_sizes(chk, data, base, confine, target)
    _check_options_on_target(chk, data, target)
    return target


def process_fit_options(data: Mapping[str, Any], name: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """``options`` of realisation ``name`` with the design's ``[process]`` keys as defaults.

    A realisation whose options include ``pdk`` (``mesh_process``; ``asic``, whose taps are then
    synthesised, simulated at gate level and timed in the PDK's standard cells) takes every
    ``[process]`` key it declares that the design's ``[realisations.<name>]`` table leaves unset;
    others, and designs without ``[process]``, get ``options`` unchanged.
    """
    process = data.get("process")
    fields = get_realisation(name).options.model_fields if name in option_tables() else {}
    if not process or "pdk" not in fields:
        return dict(options)
    defaults = {k: copy.deepcopy(v) for k, v in process.items() if k in fields and v is not None}
    return {**defaults, **options}


def _check_options_on_target(chk: DesignProblems, data: dict[str, Any], target: Kernel | None) -> None:
    """Each included realisation's options against its fit's rules on the target kernel (its options
    model validated with the target in the context, as the fit does: the same rules and words), with
    the ``[process]`` keys it takes (:func:`process_fit_options`)."""
    if target is None:
        return
    try:
        check_tap_magnitude(target)
    except KernelError:  # reported with the kernel; as in a fit, the rules need a representable target
        return
    for name in dict.fromkeys(data["realisations"]["include"]):
        if name not in option_tables():
            continue
        options = get_realisation(name).options
        given = process_fit_options(data, name, data["realisations"][name])
        try:
            options.model_validate(given, context={**DESIGN_CONTEXT, "target": target})
        except ValidationError as exc:
            chk.problems.extend(problems(exc, options, prefix=f"realisations.{name}."))


def _check_cross(chk: DesignProblems, data: dict[str, Any]) -> None:
    em = data["emulation"]
    if em["enabled"]:  # the display the emulation track builds must exist (black below peak, ...)
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


def _check_sizes(
    chk: DesignProblems, data: dict[str, Any], base: Path, confine: Confinement, target: Kernel | None
) -> None:
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
        for i, path in enumerate(checkpoint_entries(entry)):
            if not isinstance(path, str):
                continue
            try:
                p = resolve_design_path(base, path, what="checkpoint", confine=confine)
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


def _check_tasks(chk: DesignProblems, data: dict[str, Any], base: Path, confine: Confinement) -> None:
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
        paths = checkpoint_entries(entry)
        if len({str(p) for p in paths}) != len(paths):
            chk.add(key, entry, "lists a checkpoint twice (each entry must be a different training seed)")
        for i, path in enumerate(paths):
            check_checkpoint_entry(chk, key if not isinstance(entry, list) else f"{key}[{i}]", path, base, confine)
    _check_task_clips(chk, data)
    _check_task_weights(chk, data, known)


def _check_task_clips(chk: DesignProblems, data: dict[str, Any]) -> None:
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


def _check_task_weights(chk: DesignProblems, data: dict[str, Any], known: Mapping[str, Any]) -> None:
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


def _check_user_data(chk: DesignProblems, data: dict[str, Any], base: Path, confine: Confinement) -> None:
    """Each ``[tasks.datasets.<task>]`` opens (layout read, network built; fsdvs_hw.design.user_data_inputs)."""
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


def _check_codesign(chk: DesignProblems, data: dict[str, Any]) -> None:
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


def _check_codesign_checkpoint_task(chk: DesignProblems, task: str, data: dict[str, Any]) -> None:
    """A co-designed checkpoint task needs ``codesign.seeds`` networks and 2+ test clips per network."""
    seeds, n_nets = data["codesign"]["seeds"], len(checkpoint_entries(data["tasks"]["checkpoints"][task]))
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


def _check_codesign_user_task(chk: DesignProblems, task: str, entry: dict[str, Any]) -> None:
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


def _check_axes(chk: DesignProblems, data: dict[str, Any]) -> None:
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
        if section == "realisations" and rest.split(".")[0] not in option_tables():
            chk.add(full, values, f"unknown realisation {rest.split('.')[0]!r}; allowed: {', '.join(option_tables())}")
            continue
        for v in values:  # each value through the same model as a plain key
            probe: dict[str, Any] = {}
            set_dotted_key(probe, ckey, v)
            try:
                model.model_validate(probe, context=DESIGN_CONTEXT)
            except ValidationError as exc:
                chk.problems.extend(p.replace(f"key '{ckey}", f"key '{full}", 1) for p in problems(exc, model))


def _load_target(chk: DesignProblems, data: dict[str, Any], base: Path, confine: Confinement) -> Kernel | None:
    k = data["kernel"]
    pitch = data["sensor"]["pitch_m"]
    try:
        if k["source"] == "file":
            if not k["path"]:
                return None
            try:
                path = resolve_design_path(base, k["path"], what="kernel.path", confine=confine)
            except InputError as exc:
                chk.add("kernel.path", k["path"], str(exc).split(": ", 1)[-1])
                return None
            if not path.is_file():
                stand_in = pending_kernel(data["tasks"]["datasets"], base, confine, path, pitch)
                if stand_in is None:
                    chk.add("kernel.path", k["path"], f"kernel file not found (looked for {path})")
                return stand_in  # a file a train table will write (learn / explore write it first)
            return load_kernel(path, pitch_m=pitch)
        return reference_kernel(k["family"], k["size"], pitch_m=pitch, **k["params"])
    except KernelError as exc:
        key = "kernel.path" if k["source"] == "file" else "kernel.params"
        chk.add(key, k["path"] if k["source"] == "file" else k["params"], f"invalid kernel ({exc})")
        return None
