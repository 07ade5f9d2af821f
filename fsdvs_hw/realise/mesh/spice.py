"""SPICE export of a dual resistive mesh and an ngspice (batch mode) runner.

:func:`to_spice_netlist` writes the realised network of a :class:`~fsdvs_hw.realise.mesh.MeshDesign`
as a plain SPICE deck: for each mesh an n×n patch (n = 2h+1, open edges) of resistors
``R = 1/g`` between neighbours and to ground, a node capacitor to ground, and one DC current
source injecting ``i_in_a`` into the centre node of both meshes (the impulse response). The
operating point (``.op``) of that deck gives the node voltages; ``g_v V / I`` is the mesh's
normalised impulse response and ``w_p δ + a g_v,n V_n/I − b g_v,w V_w/I`` the realised kernel.

:func:`run_ngspice` drives the Debian ``ngspice`` binary as a subprocess in batch mode
(``ngspice -b deck.cir -r out.raw``) with an ASCII raw file and parses every node voltage at full
precision. Debian's ngspice (39) has no KLU sparse solver, so patches are limited to 64×64
(half-width ≤ 31); larger meshes are the casadi/scipy models' job.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError, ToolMissingError

__all__ = [
    "MAX_SPICE_HALF_WIDTH",
    "SpiceMeshResult",
    "SpiceStepResult",
    "run_ngspice",
    "simulate_mesh_spice",
    "simulate_mesh_step_spice",
    "to_spice_netlist",
]

#: Largest patch half-width exported for ngspice (63×63 nodes per mesh).
MAX_SPICE_HALF_WIDTH: int = 31


def _check_half_width(half_width: Any) -> int:
    if not (isinstance(half_width, (int, np.integer)) and 1 <= half_width <= MAX_SPICE_HALF_WIDTH):
        raise InputError(
            f"half_width: SPICE patches need an integer in 1..{MAX_SPICE_HALF_WIDTH} "
            f"(≤ 64×64 nodes; Debian ngspice has no KLU), got {half_width!r}"
        )
    return int(half_width)


def resolve_half_width(design: Any, half_width: int | None) -> int:
    """Half-width (pixels) of the netlist's grid: ``half_width`` checked, or the design's own."""
    from .fit import MeshDesign
    from .response import grid_half_width_for

    if not isinstance(design, MeshDesign):
        raise InputError(f"design: expected a MeshDesign, got {type(design).__name__}")
    if half_width is None:
        half_width = min(MAX_SPICE_HALF_WIDTH, grid_half_width_for(design.lambda_wide_px, design.size // 2))
    return _check_half_width(half_width)


def _mesh_lines(prefix: str, n: int, g_l: float, g_v: float, c_f: float) -> list[str]:
    node = lambda y, x: f"{prefix}{y}_{x}"  # noqa: E731
    g_l, g_v, c_f = float(g_l), float(g_v), float(c_f)
    rl, rv = float(1.0 / g_l), float(1.0 / g_v)  # repr: shortest exact round-trip
    out = [f"* mesh '{prefix}': {n}x{n} nodes, g_l = {g_l!r} S, g_v = {g_v!r} S, C = {c_f!r} F"]
    for y in range(n):
        for x in range(n):
            if x + 1 < n:
                out.append(f"RH{prefix}{y}_{x} {node(y, x)} {node(y, x + 1)} {rl!r}")
            if y + 1 < n:
                out.append(f"RV{prefix}{y}_{x} {node(y, x)} {node(y + 1, x)} {rl!r}")
            out.append(f"RG{prefix}{y}_{x} {node(y, x)} 0 {rv!r}")
            if c_f > 0:
                out.append(f"C{prefix}{y}_{x} {node(y, x)} 0 {c_f!r}")
    return out


def to_spice_netlist(
    design: Any,
    *,
    half_width: int | None = None,
    i_in_a: float = 1e-9,
    step_stop_s: float | None = None,
    n_points: int = 200,
) -> str:
    """An ngspice deck of ``design``'s two meshes on a (2h+1)² patch with an impulse at the centre.

    By default the deck computes the operating point (``.op``: the static kernel). With
    ``step_stop_s`` the current is a step switched on at t = 0 (rise time 1e-9 · step_stop_s) and
    the deck runs a transient (``.tran``) to ``step_stop_s`` with ``n_points`` output points
    (interpolated, tight tolerances): the settling of the meshes through their node capacitances.

    Parameters
    ----------
    design : MeshDesign
        The dual-mesh design (conductances in S, node capacitance in F).
    half_width : int, optional
        Patch half-width h in pixels (1 … 31). Default: ``min(31, r + 3 + ceil(3 λ_wide))``.
    i_in_a : float
        Injected current at the centre node, amperes (positive, ≤ 1 mA).
    step_stop_s : float, optional
        End time of a step-response transient, seconds (None: operating point only).
    n_points : int
        Output points of the transient (10 … 100000).

    Returns
    -------
    str
        The deck; node names ``n{y}_{x}`` (narrow) and ``w{y}_{x}`` (wide), row y, column x.

    Examples
    --------
    >>> from fsdvs_hw import fit_resistive_mesh, reference_kernel, to_spice_netlist
    >>> deck = to_spice_netlist(fit_resistive_mesh(reference_kernel("dog", 5)), half_width=3)
    >>> deck.splitlines()[0][:40], ".op" in deck
    ('* fsdvs_hw dual resistive mesh: 7x7 patc', True)
    """
    h = resolve_half_width(design, half_width)
    if not (isinstance(i_in_a, (int, float)) and 0 < i_in_a <= 1e-3):
        raise InputError(f"i_in_a: injected current must be in (0, 1e-3] A, got {i_in_a!r}")
    n = 2 * h + 1
    lines = [
        f"* fsdvs_hw dual resistive mesh: {n}x{n} patch, impulse {i_in_a:.6g} A at node ({h}, {h})",
        f"* K = {design.pixel_weight:.17g} delta + {design.gain_narrow:.17g} g_vn V_n/I - {design.gain_wide:.17g} g_vw V_w/I",
    ]
    lines += _mesh_lines("n", n, design.g_lateral_narrow_s, design.g_vertical_narrow_s, design.node_capacitance_f)
    lines += _mesh_lines("w", n, design.g_lateral_wide_s, design.g_vertical_wide_s, design.node_capacitance_f)
    # SPICE current sources push current from n+ through the source to n-: "I 0 node" injects into node
    if step_stop_s is None:
        src = f"DC {float(i_in_a)!r}"
        analysis = [".op"]
    else:
        if not (isinstance(step_stop_s, (int, float)) and 1e-15 < step_stop_s < 1e3):
            raise InputError(f"step_stop_s: transient end time must be in (1e-15, 1e3) s, got {step_stop_s!r}")
        if not (isinstance(n_points, int) and 10 <= n_points <= 100000):
            raise InputError(f"n_points: must be an integer in 10..100000, got {n_points!r}")
        t_stop, t_step = float(step_stop_s), float(step_stop_s) / n_points
        src = f"PWL(0 0 {1e-9 * t_stop!r} {float(i_in_a)!r})"
        analysis = [
            ".options interp reltol=1e-7 abstol=1e-20 vntol=1e-15 chgtol=1e-25 method=gear maxord=2",
            f".tran {t_step!r} {t_stop!r} 0 {t_step / 10!r}",
        ]
    lines.append(f"IINN 0 n{h}_{h} {src}")
    lines.append(f"IINW 0 w{h}_{h} {src}")
    lines += [".options filetype=ascii", *analysis, ".end", ""]
    return "\n".join(lines)


def parse_ascii_raw(text: str) -> dict[str, np.ndarray]:
    """The vectors of an ngspice ASCII ``.raw`` file, by variable name (one value per point)."""
    lines = text.splitlines()
    try:
        nvar = int(next(ln for ln in lines if ln.startswith("No. Variables:")).split(":")[1])
        i_var = next(i for i, ln in enumerate(lines) if ln.startswith("Variables:"))
        i_val = next(i for i, ln in enumerate(lines) if ln.startswith("Values:"))
    except StopIteration:
        raise InputError("ngspice raw file: missing 'No. Variables' / 'Variables:' / 'Values:' header") from None
    names = [lines[i_var + 1 + k].split()[1] for k in range(nvar)]
    tokens = " ".join(lines[i_val + 1 :]).split()
    if not tokens or len(tokens) % (nvar + 1):
        raise InputError(f"ngspice raw file: {len(tokens)} value tokens do not form points of {nvar} variables")
    table = np.array(tokens, dtype=object).reshape(-1, nvar + 1)[:, 1:].astype(np.float64)  # col 0: point index
    return {name.lower(): table[:, k] for k, name in enumerate(names)}


def run_ngspice(netlist: str, *, timeout_s: float = 300.0) -> dict[str, np.ndarray]:
    """Run ``netlist`` in ngspice batch mode and return every output vector.

    Returns
    -------
    dict
        ``{"v(n0_0)": volts, ...}`` (lower-case names as ngspice writes them), each an array with
        one value per output point (one point for ``.op``; ``"time"`` in seconds for ``.tran``).

    Raises
    ------
    ToolMissingError
        ngspice is not installed (``apt-get install ngspice``).
    InputError
        ngspice failed; the message carries the end of its output.
    """
    exe = shutil.which("ngspice")
    if exe is None:
        raise ToolMissingError("ngspice not found on PATH; install it with 'apt-get install ngspice'")
    with tempfile.TemporaryDirectory(prefix="fsdvs_spice_") as tmp:
        deck, raw = Path(tmp) / "mesh.cir", Path(tmp) / "mesh.raw"
        deck.write_text(netlist)
        try:
            proc = subprocess.run(
                [exe, "-b", str(deck), "-r", str(raw)], capture_output=True, text=True, timeout=timeout_s, cwd=tmp
            )
        except subprocess.TimeoutExpired:
            raise InputError(f"ngspice did not finish within timeout_s={timeout_s} s") from None
        if proc.returncode != 0 or not raw.is_file():
            tail = (proc.stdout + proc.stderr)[-2000:]
            raise InputError(f"ngspice failed (exit code {proc.returncode}):\n{tail}")
        return parse_ascii_raw(raw.read_text())


@dataclass(frozen=True)
class SpiceMeshResult:
    """Node voltages of both meshes from ngspice.

    Attributes
    ----------
    v_narrow_v, v_wide_v : ndarray, shape (n, n)
        Node voltages (V), row y, column x.
    i_in_a : float
        The injected current (A).
    kernel_taps : ndarray, shape (n, n)
        The realised kernel on the patch, from the voltages.
    wall_s : float
        ngspice wall time including deck writing and parsing, seconds.
    """

    v_narrow_v: np.ndarray
    v_wide_v: np.ndarray
    i_in_a: float
    kernel_taps: np.ndarray
    wall_s: float


def simulate_mesh_spice(design: Any, *, half_width: int | None = None, i_in_a: float = 1e-9) -> SpiceMeshResult:
    """Export ``design``, run ngspice, and return node voltages and the kernel they imply."""
    t0 = time.perf_counter()
    h = resolve_half_width(design, half_width)
    netlist = to_spice_netlist(design, half_width=h, i_in_a=i_in_a)
    n = 2 * h + 1
    v = run_ngspice(netlist)
    vn = np.array([[v[f"v(n{y}_{x})"][0] for x in range(n)] for y in range(n)])
    vw = np.array([[v[f"v(w{y}_{x})"][0] for x in range(n)] for y in range(n)])
    k = (
        design.gain_narrow * design.g_vertical_narrow_s * vn / i_in_a
        - design.gain_wide * design.g_vertical_wide_s * vw / i_in_a
    )
    k[h, h] += design.pixel_weight
    return SpiceMeshResult(vn, vw, float(i_in_a), k, time.perf_counter() - t0)


@dataclass(frozen=True)
class SpiceStepResult:
    """Step response of both meshes from an ngspice transient.

    Attributes
    ----------
    t_s : ndarray, shape (T,)
        Output times, seconds.
    v_narrow_v, v_wide_v : ndarray, shape (T, n, n)
        Node voltages (V) over time, row y, column x.
    i_in_a : float
        Step height of the injected current (A).
    wall_s : float
        ngspice wall time including deck writing and parsing, seconds.
    """

    t_s: np.ndarray
    v_narrow_v: np.ndarray
    v_wide_v: np.ndarray
    i_in_a: float
    wall_s: float


def simulate_mesh_step_spice(
    design: Any, *, t_stop_s: float, half_width: int | None = None, i_in_a: float = 1e-9, n_points: int = 200
) -> SpiceStepResult:
    """Transient of both meshes after a current step into the centre node, with ngspice."""
    t0 = time.perf_counter()
    h = resolve_half_width(design, half_width)
    netlist = to_spice_netlist(design, half_width=h, i_in_a=i_in_a, step_stop_s=t_stop_s, n_points=n_points)
    v = run_ngspice(netlist)
    n = 2 * h + 1
    grid = lambda p: np.stack([np.stack([v[f"v({p}{y}_{x})"] for x in range(n)], -1) for y in range(n)], -2)  # noqa: E731
    return SpiceStepResult(v["time"], grid("n"), grid("w"), float(i_in_a), time.perf_counter() - t0)
