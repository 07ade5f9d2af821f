r"""The dual mesh as sky130 transistors: the ngspice deck, its small-signal kernel, and the toolkit's own model of it.

:func:`transistor_mesh_deck` writes both meshes of a :class:`~fsdvs_hw.realise.mesh.MeshDesign` on a
(2h+1)² patch (open edges) as NMOS pass transistors (:mod:`fsdvs_hw.process.mesh_devices`): per node
two lateral devices (to the right and lower neighbours), one vertical device to :math:`V_r` through
a 0 V source ``VO…`` that measures its current (the node's output), a node capacitor, and an AC
current injected into the centre node of each mesh. It starts with the PDK's ``.lib`` line
(``tt``, or ``tt_mm`` with ``.option seed=N`` for a mismatch sample) and the solver options
:data:`~fsdvs_hw.process.ngspice.NGSPICE_OPTIONS`.

:func:`simulate_transistor_mesh` runs it (``.ac`` at 1 mHz: far below every node's corner
:math:`g_v / 2\pi C`, so the node capacitors do not enter) and returns each mesh's normalised
response :math:`H = i_v / i_{in}` and the kernel :math:`K = w_p\,\delta + a H_n - b H_w`.

:func:`lattice_model_response` is the toolkit's own transistor-level model of the same circuit:
the devices linearised at the operating point (their small-signal conductances, measured one
device at a time by :func:`~fsdvs_hw.process.mesh_devices.device_conductances`) solved as a
lattice by Kirchhoff's current law (a sparse linear solve). Without mismatch the two agree to the
solver's tolerance (tests/test_process_mesh.py).

Examples
--------
>>> from fsdvs_hw import MeshDesign
>>> from fsdvs_hw.process.mesh_deck import lattice_model_response
>>> h = lattice_model_response(1e-8, 1e-8, half_width=3)
>>> round(float(h.sum()), 6)  # every injected ampere leaves through a vertical device
1.0
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError
from .mesh_devices import MeshBias
from .ngspice import NGSPICE_OPTIONS, run_deck

__all__ = [
    "MAX_TRANSISTOR_HALF_WIDTH",
    "TransistorMeshResult",
    "deck_responses",
    "lattice_model_response",
    "settling_time_transient",
    "simulate_transistor_mesh",
    "transistor_mesh_deck",
]

#: Largest patch half-width written (a 25×25 patch per mesh: 2 × 1825 transistors).
MAX_TRANSISTOR_HALF_WIDTH = 12
#: Injected AC current (A); the analysis is linear, so its size only scales the printout.
_I_AC = 1e-12


def _check_half_width(half_width: Any) -> int:
    if not (isinstance(half_width, (int, np.integer)) and 1 <= half_width <= MAX_TRANSISTOR_HALF_WIDTH):
        raise InputError(f"half_width: allowed an integer in 1 … {MAX_TRANSISTOR_HALF_WIDTH}, got {half_width!r}")
    return int(half_width)


def _mesh_lines(
    prefix: str, n: int, gate_l: str, gate_v: str, nfet: str, w: float, l_um: float, c_f: float
) -> list[str]:
    node = lambda y, x: f"{prefix}{y}_{x}"  # noqa: E731
    dev = f"0 {nfet} w={w!r} l={l_um!r}"
    out = [f"* mesh '{prefix}': {n}x{n} nodes; lateral gates {gate_l}, vertical gates {gate_v}"]
    for y in range(n):
        for x in range(n):
            if x + 1 < n:
                out.append(f"XH{prefix}{y}_{x} {node(y, x)} {gate_l} {node(y, x + 1)} {dev}")
            if y + 1 < n:
                out.append(f"XV{prefix}{y}_{x} {node(y, x)} {gate_l} {node(y + 1, x)} {dev}")
            out.append(f"XG{prefix}{y}_{x} {node(y, x)} {gate_v} o{prefix}{y}_{x} {dev}")
            out.append(f"VO{prefix}{y}_{x} o{prefix}{y}_{x} vref DC 0")
            if c_f > 0:
                out.append(f"C{prefix}{y}_{x} {node(y, x)} 0 {c_f!r}")
    return out


def transistor_mesh_deck(
    bias: MeshBias,
    *,
    half_width: int,
    corner: str = "tt",
    temperature_c: float = 27.0,
    mismatch_seed: int | None = None,
    node_capacitance_f: float = 0.0,
    step_stop_s: float | None = None,
    copies: int = 1,
) -> str:
    """The ngspice deck of both meshes as sky130 transistors, AC impulse at the centre.

    Parameters
    ----------
    bias : MeshBias
        Gate biases, rest voltage and device size (:func:`~fsdvs_hw.process.mesh_devices.fit_mesh_bias`).
    half_width : int
        Patch half-width h (1 … :data:`MAX_TRANSISTOR_HALF_WIDTH`); the patch is (2h+1)² per mesh.
    corner : str
        Global corner (``tt``, ``ff``, ``ss``, ``sf``, ``fs``; the first letter is the NMOS).
    temperature_c : float
        Temperature (°C).
    mismatch_seed : int, optional
        Load the corner's mismatch section (``tt_mm``) and draw the devices with ``.option seed=N``.
    node_capacitance_f : float
        Capacitor per node (F), the MIM capacitor (ideal here).
    step_stop_s : float, optional
        Instead of the AC analysis, a transient to this time (s) after a current step of 1 pA into
        each centre node at t = 0 (500 output points).
    copies : int
        Independent copies of the pair of patches in the one deck (1 … 64), each with its own
        injections: with ``mismatch_seed`` every device of every copy draws its own mismatch, so one
        ngspice run (one model load) gives ``copies`` Monte Carlo samples of the whole patch.

    Returns
    -------
    str
        The deck; output currents ``i(von{y}_{x})`` (narrow) and ``i(vow{y}_{x})`` (wide), or with
        several copies ``i(voc{c}n{y}_{x})`` and ``i(voc{c}w{y}_{x})`` for copy ``c``.
    """
    from . import sky130

    h = _check_half_width(half_width)
    n = 2 * h + 1
    mm = mismatch_seed is not None
    if mm and not (isinstance(mismatch_seed, int) and 0 < mismatch_seed < 2**31):
        raise InputError(f"mismatch_seed: allowed an integer in 1 … 2³¹−1, got {mismatch_seed!r}")
    size, g = bias.size, bias.gate_v
    drawn = f" mismatch seed {mismatch_seed}" if mm else ""
    lines = [
        f"* fsdvs_hw dual transistor mesh: {n}x{n} patch per mesh, sky130 {corner}{drawn}, {temperature_c} °C",
        f"* devices {sky130.NFET} W/L = {size.w_um}/{size.l_um} µm; output = current of each vertical device (VO*)",
        sky130.lib_line(corner, mismatch=mm),
        NGSPICE_OPTIONS,
        *([f".option seed={int(mismatch_seed)}"] if mm else []),  # type: ignore[arg-type]
        f".temp {float(temperature_c)!r}",
        f"VREF vref 0 DC {bias.reference_v!r}",
        f"VGLN gln 0 DC {g['lateral_narrow']!r}",
        f"VGVN gvn 0 DC {g['vertical_narrow']!r}",
        f"VGLW glw 0 DC {g['lateral_wide']!r}",
        f"VGVW gvw 0 DC {g['vertical_wide']!r}",
    ]
    if not (isinstance(copies, int) and 1 <= copies <= 64):
        raise InputError(f"copies: allowed an integer in 1 … 64, got {copies!r}")
    c_f = float(node_capacitance_f)
    prefixes = [("n", "w")] if copies == 1 else [(f"c{c}n", f"c{c}w") for c in range(copies)]
    for pn, pw in prefixes:
        lines += _mesh_lines(pn, n, "gln", "gvn", sky130.NFET, size.w_um, size.l_um, c_f)
        lines += _mesh_lines(pw, n, "glw", "gvw", sky130.NFET, size.w_um, size.l_um, c_f)
    if step_stop_s is None:
        src, analysis = f"DC 0 AC {_I_AC!r}", ".ac lin 1 1e-3 1e-3"
    else:
        if not (isinstance(step_stop_s, (int, float)) and 1e-12 < step_stop_s < 1.0):
            raise InputError(f"step_stop_s: allowed (1e-12, 1) s, got {step_stop_s!r}")
        t = float(step_stop_s)
        src, analysis = f"PWL(0 0 {t * 1e-4!r} {_I_AC!r})", f".tran {t / 500!r} {t!r}"
    for pn, pw in prefixes:
        tag = pn[:-1].upper()
        lines += [f"IIN{tag}N 0 {pn}{h}_{h} {src}", f"IIN{tag}W 0 {pw}{h}_{h} {src}"]
    lines += [analysis, ".options filetype=ascii", ".end", ""]
    return "\n".join(lines)


@dataclass(frozen=True)
class TransistorMeshResult:
    """Normalised responses of both transistor meshes and the kernel they give.

    Attributes
    ----------
    h_narrow, h_wide : ndarray, shape (n, n)
        Output current of each node's vertical device per injected current (1), row y, column x.
    kernel_taps : ndarray, shape (n, n)
        :math:`w_p \\delta + a H_n - b H_w` on the patch.
    corner : str
    temperature_c : float
    mismatch_seed : int or None
    wall_s : float
        Wall time of the ngspice run (s).
    """

    h_narrow: np.ndarray
    h_wide: np.ndarray
    kernel_taps: np.ndarray
    corner: str
    temperature_c: float
    mismatch_seed: int | None
    wall_s: float


def simulate_transistor_mesh(
    design: Any,
    bias: MeshBias,
    *,
    half_width: int,
    corner: str = "tt",
    temperature_c: float = 27.0,
    mismatch_seed: int | None = None,
) -> TransistorMeshResult:
    """Run the transistor deck in ngspice and return both meshes' responses and the kernel."""
    t0 = time.perf_counter()
    deck = transistor_mesh_deck(
        bias, half_width=half_width, corner=corner, temperature_c=temperature_c, mismatch_seed=mismatch_seed
    )
    ((hn, hw),) = deck_responses(run_deck(deck), half_width=half_width)
    k = design.gain_narrow * hn - design.gain_wide * hw
    k[half_width, half_width] += design.pixel_weight
    return TransistorMeshResult(hn, hw, k, corner, float(temperature_c), mismatch_seed, time.perf_counter() - t0)


def deck_responses(
    vectors: dict[str, np.ndarray], *, half_width: int, copies: int = 1
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each copy's normalised responses ``(H_narrow, H_wide)`` (shape (2h+1)²) from the AC vectors of :func:`transistor_mesh_deck`."""
    n = 2 * int(half_width) + 1

    def grid(p: str) -> np.ndarray:
        return np.array([[vectors[f"i(vo{p}{y}_{x})"][0].real for x in range(n)] for y in range(n)]) / _I_AC

    prefixes = [("n", "w")] if copies == 1 else [(f"c{c}n", f"c{c}w") for c in range(copies)]
    return [(grid(pn), grid(pw)) for pn, pw in prefixes]


def lattice_model_response(g_lateral_s: float, g_vertical_s: float, *, half_width: int) -> np.ndarray:
    """Normalised response :math:`g_v V / i_{in}` of an open-edged (2h+1)² lattice (the toolkit's own model).

    Kirchhoff's current law at every node, :math:`(4 g_l + g_v) V_i - g_l \\sum_{j \\sim i} V_j = i_i`
    (fewer neighbours at the edges), solved with a sparse LU for a unit injection at the centre.

    Parameters
    ----------
    g_lateral_s, g_vertical_s : float
        Small-signal conductances of the lateral and vertical devices at the operating point (S).
    half_width : int
        Patch half-width h.
    """
    h = _check_half_width(half_width)
    if not (g_lateral_s > 0 and g_vertical_s > 0 and math.isfinite(g_lateral_s + g_vertical_s)):
        raise InputError(f"conductances must be finite and > 0, got g_l={g_lateral_s!r}, g_v={g_vertical_s!r}")
    n = 2 * h + 1
    idx = np.arange(n * n).reshape(n, n)
    rows, cols = [], []
    for a, b in ((idx[:, :-1], idx[:, 1:]), (idx[:-1, :], idx[1:, :])):
        rows += [a.ravel(), b.ravel()]
        cols += [b.ravel(), a.ravel()]
    r, c = np.concatenate(rows), np.concatenate(cols)
    adj = sp.csr_matrix((np.full(r.size, g_lateral_s), (r, c)), shape=(n * n, n * n))
    lap = sp.diags(np.asarray(adj.sum(axis=1)).ravel() + g_vertical_s) - adj
    rhs = np.zeros(n * n)
    rhs[idx[h, h]] = 1.0
    v = spla.spsolve(lap.tocsc(), rhs)
    return (g_vertical_s * v).reshape(n, n)


def settling_time_transient(
    bias: MeshBias,
    *,
    node_capacitance_f: float,
    half_width: int = 2,
    corner: str = "tt",
    temperature_c: float = 27.0,
) -> dict[str, float]:
    """Time (s) for each mesh's centre output to reach 63 % of its final value after a current step (ngspice ``.tran``).

    The transient runs to 10 C / g_v of the slower mesh (the biases' fitted conductances); returns
    ``{"narrow": s, "wide": s}``. The centre node settles faster than a single node's C/g_v, since its
    neighbours share the charge.
    """
    if not node_capacitance_f > 0:
        raise InputError(f"node_capacitance_f: a transient needs a node capacitance > 0 F, got {node_capacitance_f!r}")
    g_min = min(bias.fitted_s.get("vertical_narrow", 0.0) or 1.0, bias.fitted_s.get("vertical_wide", 0.0) or 1.0)
    t_stop = 10.0 * node_capacitance_f / g_min
    deck = transistor_mesh_deck(
        bias,
        half_width=half_width,
        corner=corner,
        temperature_c=temperature_c,
        node_capacitance_f=node_capacitance_f,
        step_stop_s=t_stop,
    )
    out = run_deck(deck)
    t = out["time"].real
    settled = {}
    for name, p in (("narrow", "n"), ("wide", "w")):
        i = out[f"i(vo{p}{half_width}_{half_width})"].real
        final = i[-1]
        k = int(np.argmax(i >= 0.632 * final)) if final > 0 else 0
        settled[name] = float(np.interp(0.632 * final, i[k - 1 : k + 1], t[k - 1 : k + 1])) if k > 0 else float(t[k])
    return settled
