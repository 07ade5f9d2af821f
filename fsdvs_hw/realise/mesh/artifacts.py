"""Buildable artifacts of a dual resistive mesh: the SPICE deck and the operating point it must reproduce.

:func:`write_mesh_artifacts` writes, for a fitted :class:`~fsdvs_hw.realise.mesh.MeshDesign`:

``mesh.cir``
    The ngspice deck of :func:`~fsdvs_hw.realise.mesh.spice.to_spice_netlist`: both meshes on a
    (2h+1)² open-edge patch, resistors ``1/g``, node capacitors, a DC current ``i_in_a`` into the
    centre node of each mesh, ``.op``. Run it with ``ngspice -b mesh.cir -r mesh.raw`` (ASCII raw
    file, every node voltage at full precision).
``operating_point.csv``
    What the deck must reproduce, from our model: per node (row ``y_px``, column ``x_px``) the
    voltages of the narrow and wide mesh (V), the currents they drive to ground through the
    vertical conductances (``g_v V``, A) and the realised kernel tap those imply,
    ``w δ + a g_vn V_n / I − b g_vw V_w / I`` (dimensionless). Our model is the exact nodal
    (KCL) solve of the same patch (:func:`~fsdvs_hw.realise.mesh.response.mesh_kcl_matrix`, sparse
    LU in float64).

:func:`check_mesh_artifacts` runs the command on the written deck and compares every node voltage
with the CSV (relative to the largest, :data:`OP_RTOL`).
"""

from __future__ import annotations

import csv
import shutil
import subprocess
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError, ToolMissingError
from ...paths import csv_text, write_output
from ..artifacts import Artifact
from .fit import MeshDesign
from .response import mesh_kcl_matrix
from .spice import parse_ascii_raw, resolve_half_width, to_spice_netlist

__all__ = ["NGSPICE_COMMAND", "OP_RTOL", "check_mesh_artifacts", "mesh_operating_point", "write_mesh_artifacts"]

#: Agreement required between ngspice's node voltages and the written operating point, relative to
#: the largest node voltage. ngspice solves the linear deck with one sparse LU (its reltol/abstol
#: only stop Newton iterations, which a linear circuit does not need), so the two agree to a few
#: ulp times the conductance spread; 1e-9 leaves margin for the deck's 17-digit resistor values.
OP_RTOL: float = 1e-9

#: The one-line command that runs the written deck (in its folder).
NGSPICE_COMMAND: str = "ngspice -b mesh.cir -r mesh.raw"

_I_IN_A = 1e-9
_COLUMNS = (
    "y_px",
    "x_px",
    "node_narrow",
    "node_wide",
    "v_narrow_V",
    "v_wide_V",
    "i_narrow_A",
    "i_wide_A",
    "kernel_tap_1",
)


def mesh_operating_point(
    design: MeshDesign, *, half_width: int | None = None, i_in_a: float = _I_IN_A
) -> dict[str, Any]:
    """Node voltages of both meshes of ``design`` on the SPICE patch, from the exact nodal solve.

    Returns
    -------
    dict
        ``half_width``, ``i_in_a`` (A), ``v_narrow_v``/``v_wide_v`` (V, shape (n, n), row y,
        column x) and ``kernel_taps`` (the kernel they imply on the patch).
    """
    import scipy.sparse.linalg as spla

    h = resolve_half_width(design, half_width)
    n = 2 * h + 1
    rhs = np.zeros(n * n)
    rhs[h * n + h] = i_in_a
    v = {}
    for tag, g_l, g_v in (
        ("narrow", design.g_lateral_narrow_s, design.g_vertical_narrow_s),
        ("wide", design.g_lateral_wide_s, design.g_vertical_wide_s),
    ):
        v[tag] = spla.spsolve(mesh_kcl_matrix(h, g_l, g_v), rhs).reshape(n, n)
    k = (
        design.gain_narrow * design.g_vertical_narrow_s * v["narrow"]
        - design.gain_wide * design.g_vertical_wide_s * v["wide"]
    ) / i_in_a
    k[h, h] += design.pixel_weight
    return {
        "half_width": h,
        "i_in_a": float(i_in_a),
        "v_narrow_v": v["narrow"],
        "v_wide_v": v["wide"],
        "kernel_taps": k,
    }


def write_mesh_artifacts(
    design: MeshDesign, out_dir: str | Path, *, resolution: tuple[int, int] | None = None
) -> tuple[Artifact, ...]:
    """Write ``mesh.cir`` and ``operating_point.csv`` for ``design`` into ``out_dir`` (module docstring).

    ``resolution`` is accepted for the writer protocol and not used (the patch size follows the
    wide mesh's space constant, :func:`~fsdvs_hw.realise.mesh.spice.to_spice_netlist`).
    """
    if not isinstance(design, MeshDesign):
        raise InputError(f"write_mesh_artifacts: expected a MeshDesign, got {type(design).__name__}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    op = mesh_operating_point(design)
    h, n = op["half_width"], 2 * op["half_width"] + 1
    deck = to_spice_netlist(design, half_width=h, i_in_a=op["i_in_a"])
    deck = f"* run: {NGSPICE_COMMAND}   (then compare v(n*)/v(w*) in mesh.raw with operating_point.csv)\n" + deck
    write_output(out / "mesh.cir", deck, flag="artifacts")
    rows: list[Sequence[object]] = [_COLUMNS]
    for y in range(n):
        for x in range(n):
            vn, vw = op["v_narrow_v"][y, x], op["v_wide_v"][y, x]
            rows.append(
                [
                    y,
                    x,
                    f"n{y}_{x}",
                    f"w{y}_{x}",
                    repr(float(vn)),
                    repr(float(vw)),
                    repr(float(design.g_vertical_narrow_s * vn)),
                    repr(float(design.g_vertical_wide_s * vw)),
                    repr(float(op["kernel_taps"][y, x])),
                ]
            )
    write_output(out / "operating_point.csv", csv_text(rows), flag="artifacts")
    check = (
        f"{NGSPICE_COMMAND}; every v(n<y>_<x>), v(w<y>_<x>) in mesh.raw equals operating_point.csv within "
        f"1 part in {1 / OP_RTOL:,.0f} of the largest (fsdvs_hw.realise.mesh.artifacts.check_mesh_artifacts)"
    )
    return (
        Artifact(
            "spice_netlist",
            out / "mesh.cir",
            f"ngspice deck: both meshes on a {n}x{n} patch, {op['i_in_a'] * 1e6:.3g} µA into the centre node, .op",
            check,
        ),
        Artifact(
            "operating_point",
            out / "operating_point.csv",
            "node voltages (V), ground currents g_v V (A) and kernel taps the deck must reproduce (exact KCL solve)",
            "",
        ),
    )


def _read_operating_point(path: Path) -> dict[str, np.ndarray]:
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
        y = np.array([int(r["y_px"]) for r in rows])
        x = np.array([int(r["x_px"]) for r in rows])
        cols = {c: np.array([float(r[c]) for r in rows]) for c in ("v_narrow_V", "v_wide_V", "kernel_tap_1")}
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(f"{path}: not an operating_point.csv of write_mesh_artifacts ({exc})") from None
    n = int(y.max()) + 1
    out = {}
    for c, v in cols.items():
        grid = np.full((n, n), np.nan)
        grid[y, x] = v
        out[c] = grid
    return out


def check_mesh_artifacts(folder: str | Path, *, timeout_s: float = 300.0) -> dict[str, float]:
    """Run :data:`NGSPICE_COMMAND` in ``folder`` and compare with ``operating_point.csv``.

    Returns
    -------
    dict
        ``max_rel_error`` (largest |ngspice − model| over both meshes, relative to the largest node
        voltage), ``nodes`` (compared), ``ngspice_s`` (wall time of the ngspice run, s).

    Raises
    ------
    ToolMissingError
        ngspice is not installed.
    InputError
        ngspice failed, or a node voltage differs by more than :data:`OP_RTOL`.
    """
    folder = Path(folder)
    exe = shutil.which("ngspice")
    if exe is None:
        raise ToolMissingError("ngspice not found on PATH; install it with 'apt-get install ngspice'")
    expected = _read_operating_point(folder / "operating_point.csv")
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(
            [exe, *NGSPICE_COMMAND.split()[1:]],
            cwd=folder,
            capture_output=True,
            text=True,
            check=False,
            timeout=timeout_s,
        )
    except subprocess.TimeoutExpired:
        raise InputError(f"ngspice did not finish within {timeout_s} s") from None
    wall = time.perf_counter() - t0
    raw = folder / "mesh.raw"
    if proc.returncode != 0 or not raw.is_file():
        raise InputError(f"ngspice failed (exit code {proc.returncode}):\n{(proc.stdout + proc.stderr)[-2000:]}")
    v = parse_ascii_raw(raw.read_text())
    n = expected["v_narrow_V"].shape[0]
    got_n = np.array([[v[f"v(n{y}_{x})"][0] for x in range(n)] for y in range(n)])
    got_w = np.array([[v[f"v(w{y}_{x})"][0] for x in range(n)] for y in range(n)])
    scale = max(np.abs(expected["v_narrow_V"]).max(), np.abs(expected["v_wide_V"]).max())
    err = max(np.abs(got_n - expected["v_narrow_V"]).max(), np.abs(got_w - expected["v_wide_V"]).max()) / scale
    if not err <= OP_RTOL:
        raise InputError(
            f"{folder}: ngspice's node voltages differ from operating_point.csv by {err:.3g} of the "
            f"largest (allowed {OP_RTOL:g})"
        )
    return {"max_rel_error": float(err), "nodes": int(2 * n * n), "ngspice_s": wall}
