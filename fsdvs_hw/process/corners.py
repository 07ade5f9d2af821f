r"""The transistor mesh across corners, temperatures and mismatch: the kernel it realises and its error.

The gate biases are fitted once, at the nominal condition (:func:`~fsdvs_hw.process.mesh_devices.fit_mesh_bias`,
sky130 tt 27 °C) and then held (fixed bias voltages). At each global corner and temperature every
device of one role shares one conductance, so the transistor mesh is the ideal lattice with that
condition's conductances — the agreement of the full ngspice transistor deck with the lattice
model is checked in tests/test_process_mesh.py — and the realised kernel of that condition is the
:class:`~fsdvs_hw.realise.mesh.MeshDesign` with the four conductances ngspice gives the devices there
(:func:`condition_conductances`: one ngspice run of four devices).

Mismatch: one ngspice run of the corner's mismatch section (``tt_mm``, ``.option seed=N``) draws a
population of devices per role (:func:`mismatch_population`; every instance draws its own threshold
and mobility from SkyWater's mismatch model); each Monte Carlo sample assembles a patch from
that population (per-device lateral and vertical conductances, resampled) and solves it as a lattice
(Kirchhoff's law, :func:`lattice_response_per_device`). The sample's kernel error against the
nominal (no-mismatch) kernel and against the target are summarised by their mean with a percentile
bootstrap 95 % interval (2000 resamples).

Examples
--------
>>> import numpy as np
>>> from fsdvs_hw.process.corners import mean_ci
>>> m, lo, hi = mean_ci(np.array([1.0, 2.0, 3.0, 4.0]))
>>> m, lo <= m <= hi
(2.5, True)
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError
from .mesh_devices import CONDUCTANCE_NAMES, MeshBias, characterisation_deck
from .ngspice import run_deck

__all__ = [
    "CI_CONFIDENCE",
    "ConditionResult",
    "MismatchSummary",
    "condition_conductances",
    "condition_design",
    "full_patch_mismatch",
    "lattice_response_per_device",
    "mean_ci",
    "mismatch_kernels",
    "mismatch_population",
]

#: Confidence of the Monte Carlo intervals.
CI_CONFIDENCE = 0.95
_BOOTSTRAP = 2000


def mean_ci(values: np.ndarray, confidence: float = CI_CONFIDENCE, seed: int = 0) -> tuple[float, float, float]:
    """Mean and percentile-bootstrap interval of ``values`` (2000 resamples, fixed seed)."""
    v = np.asarray(values, dtype=float)
    if v.size < 2:
        raise InputError(f"mean_ci: needs at least 2 values, got {v.size}")
    rng = np.random.default_rng(seed)
    means = v[rng.integers(0, v.size, size=(_BOOTSTRAP, v.size))].mean(axis=1)
    a = (1 - confidence) / 2
    return float(v.mean()), float(np.quantile(means, a)), float(np.quantile(means, 1 - a))


def _run_devices(bias: MeshBias, corner: str, temperature_c: float, gates: np.ndarray, seed: int | None) -> np.ndarray:
    deck = characterisation_deck(bias.pdk, corner, temperature_c, bias.reference_v, gates, bias.size)
    if seed is not None:
        from . import sky130

        deck = deck.replace(
            sky130.lib_line(corner), sky130.lib_line(corner, mismatch=True) + f"\n.option seed={int(seed)}"
        )
    out = run_deck(deck)
    return np.array([-out[f"i(vd{k})"][0].real for k in range(len(gates))])


def condition_conductances(bias: MeshBias, corner: str, temperature_c: float) -> dict[str, float]:
    """The four conductances (S) the fixed biases give at a global corner and temperature (ngspice)."""
    gates = np.array([bias.gate_v[n] for n in CONDUCTANCE_NAMES])
    return dict(zip(CONDUCTANCE_NAMES, (float(g) for g in _run_devices(bias, corner, temperature_c, gates, None))))


def condition_design(design: Any, conductances: dict[str, float]) -> Any:
    """``design`` (a MeshDesign) with its four conductances replaced by a condition's."""
    return dataclasses.replace(
        design,
        g_lateral_narrow_s=conductances["lateral_narrow"],
        g_vertical_narrow_s=conductances["vertical_narrow"],
        g_lateral_wide_s=conductances["lateral_wide"],
        g_vertical_wide_s=conductances["vertical_wide"],
    )


def mismatch_population(
    bias: MeshBias, *, corner: str = "tt", temperature_c: float = 27.0, per_role: int = 128, seed: int = 1
) -> dict[str, np.ndarray]:
    """Conductances (S) of ``per_role`` devices per role drawn by the PDK's mismatch models (one ngspice run)."""
    if not (isinstance(per_role, int) and 8 <= per_role <= 1024):
        raise InputError(f"per_role: allowed an integer in 8 … 1024 devices, got {per_role!r}")
    gates = np.repeat([bias.gate_v[n] for n in CONDUCTANCE_NAMES], per_role)
    g = _run_devices(bias, corner, temperature_c, gates, seed)
    return {n: g[i * per_role : (i + 1) * per_role] for i, n in enumerate(CONDUCTANCE_NAMES)}


def lattice_response_per_device(g_right: np.ndarray, g_down: np.ndarray, g_vertical: np.ndarray) -> np.ndarray:
    """Normalised response :math:`g_{v,i} V_i / i_{in}` of an n×n lattice with per-device conductances.

    Parameters
    ----------
    g_right : ndarray, shape (n, n-1)
        Conductance between node (y, x) and (y, x+1) (S).
    g_down : ndarray, shape (n-1, n)
        Conductance between node (y, x) and (y+1, x) (S).
    g_vertical : ndarray, shape (n, n)
        Conductance of each node's vertical device (S).
    """
    n = g_vertical.shape[0]
    if g_vertical.shape != (n, n) or g_right.shape != (n, n - 1) or g_down.shape != (n - 1, n) or n % 2 == 0:
        raise InputError(
            f"lattice_response_per_device: shapes {g_right.shape}, {g_down.shape}, {g_vertical.shape} do not form an odd n×n patch"
        )
    idx = np.arange(n * n).reshape(n, n)
    a = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    b = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    g = np.concatenate([g_right.ravel(), g_down.ravel()])
    adj = sp.csr_matrix(
        (np.concatenate([g, g]), (np.concatenate([a, b]), np.concatenate([b, a]))), shape=(n * n, n * n)
    )
    lap = sp.diags(np.asarray(adj.sum(axis=1)).ravel() + g_vertical.ravel()) - adj
    rhs = np.zeros(n * n)
    rhs[idx[n // 2, n // 2]] = 1.0
    v = spla.spsolve(lap.tocsc(), rhs)
    return (g_vertical.ravel() * v).reshape(n, n)


def _sample_patch(rng: np.random.Generator, pool_l: np.ndarray, pool_v: np.ndarray, n: int) -> np.ndarray:
    return lattice_response_per_device(
        rng.choice(pool_l, size=(n, n - 1)), rng.choice(pool_l, size=(n - 1, n)), rng.choice(pool_v, size=(n, n))
    )


def _patch_kernel(design: Any, hn: np.ndarray, hw: np.ndarray) -> np.ndarray:
    """:math:`w_p \\delta + a H_n - b H_w` on an odd patch (the pixel weight at its centre)."""
    k = design.gain_narrow * hn - design.gain_wide * hw
    k[hn.shape[0] // 2, hn.shape[1] // 2] += design.pixel_weight
    return k


def _nominal_kernel(design: Any, conductances: dict[str, float], h: int) -> np.ndarray:
    """The no-mismatch kernel on a (2h+1)² patch: both meshes solved as lattices with the condition's conductances."""
    from .mesh_deck import lattice_model_response

    return _patch_kernel(
        design,
        lattice_model_response(conductances["lateral_narrow"], conductances["vertical_narrow"], half_width=h),
        lattice_model_response(conductances["lateral_wide"], conductances["vertical_wide"], half_width=h),
    )


@dataclass(frozen=True)
class MismatchSummary:
    """Monte Carlo mismatch of the transistor mesh at one corner.

    Attributes
    ----------
    corner, temperature_c
        The condition (mismatch section ``<corner>_mm``).
    samples : int
        Monte Carlo samples (patches).
    seed : int
        ``.option seed`` of the ngspice run that drew the device population.
    devices_per_role : int
        Devices drawn per role (lateral/vertical × narrow/wide).
    sigma_ln_g : dict
        Standard deviation of ln g per role (the devices' relative conductance spread).
    error_vs_nominal : list of float
        Each sample's relative L2 kernel error against the no-mismatch kernel on the same patch.
    error_vs_target : list of float
        Each sample's relative L2 kernel error against the target (whole patch response).
    half_width : int
        Patch half-width of the samples (px).
    wall_s : float
        Wall time (s), ngspice included.
    """

    corner: str
    temperature_c: float
    samples: int
    seed: int
    devices_per_role: int
    sigma_ln_g: dict[str, float]
    error_vs_nominal: list[float]
    error_vs_target: list[float]
    half_width: int
    wall_s: float = 0.0
    ci: dict[str, list[float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (with the means and 95 % intervals under ``ci``)."""
        return dataclasses.asdict(self)


def mismatch_kernels(
    design: Any,
    bias: MeshBias,
    *,
    samples: int = 30,
    corner: str = "tt",
    temperature_c: float = 27.0,
    half_width: int | None = None,
    devices_per_role: int = 128,
    seed: int = 1,
) -> MismatchSummary:
    """Monte Carlo kernels of the transistor mesh under device mismatch (see the module text)."""
    t0 = time.perf_counter()
    if not (isinstance(samples, int) and 2 <= samples <= 10000):
        raise InputError(f"[process] mismatch_samples = {samples!r}: allowed an integer in 2 … 10000")
    h = (
        int(half_width)
        if half_width is not None
        else min(12, max(design.size // 2 + 2, int(math.ceil(4 * design.lambda_wide_px))))
    )
    n = 2 * h + 1
    if design.target is not None and design.target.taps.shape[0] > n:
        raise InputError(
            f"half_width = {h}: the {n}x{n} patch is smaller than the {design.target.taps.shape[0]}-tap target; "
            f"allowed {design.target.taps.shape[0] // 2} … 12"
        )
    pool = mismatch_population(bias, corner=corner, temperature_c=temperature_c, per_role=devices_per_role, seed=seed)
    k0 = _nominal_kernel(design, condition_conductances(bias, corner, temperature_c), h)
    target = np.zeros((n, n))
    t = design.target.taps if design.target is not None else k0
    r = t.shape[0] // 2
    target[h - r : h + r + 1, h - r : h + r + 1] = t
    rng = np.random.default_rng(seed)
    e_nom, e_tgt = [], []
    for _ in range(samples):
        hn = _sample_patch(rng, pool["lateral_narrow"], pool["vertical_narrow"], n)
        hw = _sample_patch(rng, pool["lateral_wide"], pool["vertical_wide"], n)
        k = _patch_kernel(design, hn, hw)
        e_nom.append(float(np.linalg.norm(k - k0) / np.linalg.norm(k0)))
        e_tgt.append(float(np.linalg.norm(k - target) / np.linalg.norm(target)))
    ci = {name: list(mean_ci(np.array(v))) for name, v in (("error_vs_nominal", e_nom), ("error_vs_target", e_tgt))}
    sig = {k: float(np.std(np.log(v), ddof=1)) for k, v in pool.items()}
    return MismatchSummary(
        corner,
        float(temperature_c),
        samples,
        int(seed),
        devices_per_role,
        sig,
        e_nom,
        e_tgt,
        h,
        time.perf_counter() - t0,
        ci,
    )


def full_patch_mismatch(
    design: Any,
    bias: MeshBias,
    *,
    copies: int = 16,
    half_width: int = 2,
    corner: str = "tt",
    temperature_c: float = 27.0,
    seed: int = 1,
) -> dict[str, Any]:
    """Monte Carlo of the *whole transistor patch* in ngspice: the cross-check of :func:`mismatch_kernels`.

    One deck holds ``copies`` independent copies of both meshes (:func:`~fsdvs_hw.process.mesh_deck.transistor_mesh_deck`
    with ``copies``), loaded with the corner's mismatch section and ``.option seed``: every
    transistor draws its own threshold and mobility, and ngspice solves each copy's AC response
    itself (no linearisation, no device pool). Each copy's kernel error against the no-mismatch
    lattice kernel on the same patch is one sample of what :func:`mismatch_kernels` estimates by
    resampling a device population.

    Returns
    -------
    dict
        ``error_vs_nominal`` (one per copy), ``ci`` (mean and 95 % bootstrap interval),
        ``copies``, ``half_width``, ``transistors``, ``corner``, ``temperature_c``, ``seed``, ``wall_s``.
    """
    from .mesh_deck import deck_responses, transistor_mesh_deck

    t0 = time.perf_counter()
    h, n = int(half_width), 2 * int(half_width) + 1
    deck = transistor_mesh_deck(
        bias, half_width=h, corner=corner, temperature_c=temperature_c, mismatch_seed=int(seed), copies=copies
    )
    out = run_deck(deck, timeout_s=1800.0)
    k0 = _nominal_kernel(design, condition_conductances(bias, corner, temperature_c), h)

    errors = []
    for hn, hw in deck_responses(out, half_width=h, copies=copies):
        k = _patch_kernel(design, hn, hw)
        errors.append(float(np.linalg.norm(k - k0) / np.linalg.norm(k0)))
    return {
        "error_vs_nominal": errors,
        "ci": list(mean_ci(np.array(errors))),
        "copies": int(copies),
        "half_width": h,
        "transistors": int(copies) * 2 * (n * n + 2 * n * (n - 1)),
        "corner": corner,
        "temperature_c": float(temperature_c),
        "seed": int(seed),
        "wall_s": time.perf_counter() - t0,
    }


@dataclass(frozen=True)
class ConditionResult:
    """The transistor mesh at one corner and temperature (fixed biases).

    Attributes
    ----------
    corner : str
    temperature_c : float
    conductances_s : dict
        The four small-signal conductances there (S).
    kernel_error : float
        Relative L2 error of the whole response against the target.
    error_vs_ideal : float
        Relative L2 distance of its kernel (design window) from the ideal mesh's.
    lambda_narrow_px, lambda_wide_px, tau_wide_s : float
        Space constants (px) and the wide mesh's settling time constant C/g_v (s).
    """

    corner: str
    temperature_c: float
    conductances_s: dict[str, float]
    kernel_error: float
    error_vs_ideal: float
    lambda_narrow_px: float
    lambda_wide_px: float
    tau_wide_s: float

    @property
    def label(self) -> str:
        """``"sky130 ss 85 °C"``-style label (without the PDK)."""
        return f"{self.corner} {self.temperature_c:g} °C"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return dataclasses.asdict(self)
