"""Design-rule check of a metalens layout with KLayout, in a separate process.

KLayout's Python package (``klayout``, GPL-3) is never imported by fsdvs_hw (MIT): :func:`run_drc`
runs a short script in a child Python process (``sys.executable -c``) that reads the GDSII file,
merges the pillars of one layer/datatype into a region and runs a **width** check with
projection metrics (the default Euclidean metric flags the facets of a polygonised circle) and a
**space** check with Euclidean metrics (the strictest for the gaps between neighbouring pillars).
When the package is not installed the result says so (``ran=False``) and the caller goes on.

KLayout: M. Köfferlein, https://www.klayout.de (``Region.width_check``, ``Region.space_check``,
``Metrics.Projection``).

Example
-------
>>> from fsdvs_hw.realise.metalens.drc import drc_available
>>> isinstance(drc_available(), bool)
True
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

__all__ = ["DrcResult", "drc_available", "run_drc"]

_SCRIPT = r"""
import json, sys
import klayout.db as db
path, layer, datatype, width_m, space_m = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
ly = db.Layout()
ly.read(path)
top = ly.top_cells()[0]
um = 1e6
region = db.Region(top.begin_shapes_rec(ly.layer(layer, datatype)))
region.merge()
dbu = ly.dbu
w = int(round(width_m * um / dbu))
s = int(round(space_m * um / dbu))
width = region.width_check(w, False, db.Metrics.Projection)
space = region.space_check(s, False, db.Metrics.Euclidian)
print(json.dumps({"shapes": region.count(), "width_violations": width.count(), "space_violations": space.count(),
                  "dbu_um": dbu, "klayout": db.__version__ if hasattr(db, "__version__") else ""}))
"""


@dataclass(frozen=True)
class DrcResult:
    """The outcome of :func:`run_drc`.

    Attributes
    ----------
    ran : bool
        KLayout ran (False: not installed or failed; ``message`` says why).
    passed : bool
        Ran and found no violation.
    shapes : int
        Merged pillar polygons checked.
    width_violations, space_violations : int
        Edge pairs closer than ``min_width_m`` inside a pillar / ``min_space_m`` between pillars.
    min_width_m, min_space_m : float
        The rules (m).
    seconds : float
        Wall time of the check (s).
    message : str
        One line for the user.
    """

    ran: bool
    passed: bool
    shapes: int
    width_violations: int
    space_violations: int
    min_width_m: float
    min_space_m: float
    seconds: float
    message: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def drc_available() -> bool:
    """Whether the ``klayout`` Python package can be run (checked in a child process)."""
    try:
        done = subprocess.run([sys.executable, "-c", "import klayout.db"], capture_output=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def run_drc(
    gds_path: str | Path, *, layer: int, datatype: int, min_width_m: float, min_space_m: float, timeout_s: float = 600
) -> DrcResult:
    """Width and space check of the pillars on ``layer``/``datatype`` of ``gds_path`` (module docstring)."""
    t0 = time.perf_counter()
    args = [
        sys.executable,
        "-c",
        _SCRIPT,
        str(gds_path),
        str(layer),
        str(datatype),
        repr(min_width_m),
        repr(min_space_m),
    ]
    try:
        done = subprocess.run(args, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return DrcResult(
            False,
            False,
            0,
            0,
            0,
            min_width_m,
            min_space_m,
            time.perf_counter() - t0,
            f"DRC timed out after {timeout_s:g} s",
        )
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        missing = "No module named 'klayout'" in done.stderr
        why = (
            "DRC skipped: the klayout Python package is not installed (pip install klayout)"
            if missing
            else f"DRC failed: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else done.returncode}"
        )
        return DrcResult(False, False, 0, 0, 0, min_width_m, min_space_m, seconds, why)
    out = json.loads(done.stdout.strip().splitlines()[-1])
    w, s = int(out["width_violations"]), int(out["space_violations"])
    passed = w == 0 and s == 0
    msg = (
        f"KLayout DRC {'passed' if passed else 'FAILED'}: {out['shapes']} pillars, width ≥ {min_width_m * 1e9:.0f} nm "
        f"(projection) {w} violations, space ≥ {min_space_m * 1e9:.0f} nm {s} violations, {seconds:.1f} s"
    )
    return DrcResult(True, passed, int(out["shapes"]), w, s, min_width_m, min_space_m, seconds, msg)
