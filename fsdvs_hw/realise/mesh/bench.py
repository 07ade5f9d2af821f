"""``fsdvs-hw bench mesh``: speed-for-accuracy tables of the dual resistive-mesh realisation.

Tables (Markdown):

1. Fit time for 3×3 … 9×9 targets (a known dual mesh, recovered; a Gaussian DoG with a free pixel
   weight): first call (includes building the symbolic IPOPT problem, cached afterwards) and the
   median of later calls, with kernel error and IPOPT iterations.
2. Single-mesh model fidelity: infinite-lattice Green's function (quadrature) and finite grids of
   growing half-width (exact DCT, sparse LU, casadi symbolic KCL) — boundary error against the
   lattice Green's function evaluated with 4× the quadrature nodes, versus run time.
3. ngspice (batch, subprocess) versus the casadi circuit model on the same patch: wall time and
   the largest relative node-voltage difference; ngspice step-response transients versus the
   exact modal (DCT) solution.
4. Monte Carlo mismatch and the transient decision: run time per call.
"""

from __future__ import annotations

import math
import statistics
import sys
import time

import numpy as np

from ...benchmarks import timed

__all__ = ["bench_mesh"]


def _log(msg: str) -> None:
    print(f"[bench mesh] {msg}", file=sys.stderr, flush=True)


def _fit_table(quick: bool) -> list[str]:
    from ...kernels import reference_kernel
    from .fit import MeshDesign, _mesh_solver, fit_resistive_mesh

    repeats = 2 if quick else 5

    def whole_response(*args: float) -> object:
        d = MeshDesign.from_space_constants(*args[:4], pixel_weight=args[4], size=7)
        return d.kernel(d.response_size(1e-14))

    def canonical(k: int) -> object:
        return reference_kernel("dog", k, pitch_m=4.86e-6, sigma_centre_px=0.8, sigma_surround_px=2.2, w_centre=1.0, w_surround=0.7)

    cases = [
        ("known dual mesh λ 0.8/2.5 px (whole response)", lambda k: whole_response(0.8, 2.5, 1.5, 1.2, 1.0), {}, (None,)),
        ("known dual mesh λ 0.5/1.0 px (whole response)", lambda k: whole_response(0.5, 1.0, 1.0, 1.4, 0.5), {}, (None,)),
        ("DoG 0.8/2.2 px, 0.7 (issue 13)", canonical, {}, (3, 5, 7, 9)),
        ("DoG 0.7/2.0 px, 0.8 (reference)", lambda k: reference_kernel("dog", k), {}, (7,)),
        ("DoG 0.8/2.2 px, paper's sketch w_p=1, gain fixed", canonical, {"pixel_weight": 1.0, "gain": "fixed"}, (7,)),
        ("DoG 0.8/2.2 px, w_p=1, gain free", canonical, {"pixel_weight": 1.0}, (7,)),
        ("DoG 0.8/2.2 px, whole DC unconstrained", canonical, {"nonnegative_dc": False}, (7,)),
    ]
    rows = [
        "| target | options | size | first call (s) | median later (s) [min–max] | error (whole response) | error (window) |"
        " whole DC | window DC | tail energy | IPOPT iterations | at a bound |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, make, opts, sizes in cases:
        for k in sizes:
            target = make(k)
            _log(f"fit {label} {target.size}x{target.size}")
            _mesh_solver.cache_clear()
            t0 = time.perf_counter()
            fit_resistive_mesh(target, **opts)
            first = time.perf_counter() - t0
            times, d = [], None
            for _ in range(repeats):
                t1 = time.perf_counter()
                d = fit_resistive_mesh(target, **opts)
                times.append(time.perf_counter() - t1)
            f = d.fit
            bounds = "; ".join(b.split(" (")[0] for b in f["on_bound"]) or "none"
            rows.append(
                f"| {label} | {', '.join(f'{a}={v}' for a, v in opts.items()) or 'defaults'} | {target.size}x{target.size} |"
                f" {first:.2f} | {statistics.median(times):.3f} [{min(times):.3f}–{max(times):.3f}] | {f['error']:.3g} |"
                f" {f['error_window']:.3g} | {f['whole_dc_gain']:.3g} | {f['window_dc_gain']:.3g} | {f['tail_energy_fraction']:.2g} |"
                f" {f['iterations']} | {bounds} |"
            )
    return rows


def _model_table(quick: bool) -> list[str]:
    from .response import (
        _unfold_quarter,
        casadi_mesh_model,
        finite_grid_response,
        grid_half_width_for,
        lattice_green_quarter,
        quadrature_nodes,
    )

    radius = 3
    repeats = 3 if quick else 9
    rows = [
        "| λ (px) | model | grid half-width (px) | max error / max tap | time (ms) |",
        "|---|---|---|---|---|",
    ]
    for lam in (1.0, 3.0) if quick else (1.0, 3.0, 10.0):
        k, w = quadrature_nodes(max(lam, 1.0), radius)
        n4 = 4 * k.size
        th = (np.arange(n4) + 0.5) * (np.pi / n4)
        s = 1.0 / math.sqrt(1.0 + 2.8 * max(lam, 1.0))
        t = np.tan(th / 2)
        ref_nodes = (2 * np.arctan(s * t), s * (1 + t * t) / (1 + s * s * t * t) / n4)
        ref = _unfold_quarter(lattice_green_quarter(lam, radius, nodes=ref_nodes))
        scale = np.abs(ref).max()
        rt = timed(lambda: _unfold_quarter(lattice_green_quarter(lam, radius)), repeats)
        tm, g = rt.median_s, rt.result
        rows.append(f"| {lam:g} | lattice Green's function ({k.size} nodes) | ∞ | {np.abs(g - ref).max() / scale:.1e} | {1e3 * tm:.3f} |")
        rule = grid_half_width_for(lam, radius)
        halves = sorted({radius, radius + 2, rule, 2 * rule} if not quick else {radius + 2, rule})
        for h in halves:
            for method in ("dct", "sparse"):
                rt = timed(lambda: finite_grid_response(lam, radius, h, method=method), repeats)
                tm, g = rt.median_s, rt.result
                tag = " (rule r+3+3λ)" if h == rule else ""
                rows.append(f"| {lam:g} | finite grid, {method} | {h}{tag} | {np.abs(g - ref).max() / scale:.1e} | {1e3 * tm:.3f} |")
            n = 2 * h + 1
            i_in = np.zeros(n * n)
            i_in[h * n + h] = 1.0
            t0 = time.perf_counter()
            f = casadi_mesh_model(h)
            build = time.perf_counter() - t0
            rt = timed(lambda: np.array(f(lam * lam, 1.0, i_in)).reshape(n, n), repeats)
            tm, v = rt.median_s, rt.result
            g = v[h - radius : h + radius + 1, h - radius : h + radius + 1]
            rows.append(
                f"| {lam:g} | finite grid, casadi KCL (MX, ldl; build {1e3 * build:.0f} ms) | {h} | "
                f"{np.abs(g - ref).max() / scale:.1e} | {1e3 * tm:.3f} |"
            )
    return rows


def _spice_table(quick: bool) -> list[str]:
    import shutil

    from .fit import MeshDesign
    from .response import casadi_mesh_model
    from .dynamics import mesh_step_response
    from .spice import simulate_mesh_spice, simulate_mesh_step_spice

    if shutil.which("ngspice") is None:
        return ["ngspice not installed: table skipped (apt-get install ngspice)."]
    d = MeshDesign.from_space_constants(0.8, 2.5, 1.5, 1.2, size=7)
    rows = [
        "| patch | nodes (2 meshes) | ngspice wall (s) | casadi build + solve (s) | casadi solve (ms) | max rel. difference |",
        "|---|---|---|---|---|---|",
    ]
    for h in (8, 16) if quick else (8, 16, 31):
        _log(f"ngspice patch {2 * h + 1}")
        res = simulate_mesh_spice(d, half_width=h)
        n = 2 * h + 1
        i_in = np.zeros(n * n)
        i_in[h * n + h] = res.i_in_a
        t0 = time.perf_counter()
        f = casadi_mesh_model(h)
        vn = np.array(f(d.g_lateral_narrow_s, d.g_vertical_narrow_s, i_in)).reshape(n, n)
        vw = np.array(f(d.g_lateral_wide_s, d.g_vertical_wide_s, i_in)).reshape(n, n)
        total = time.perf_counter() - t0
        rt = timed(lambda: f(d.g_lateral_wide_s, d.g_vertical_wide_s, i_in), 3)
        ts, _ = rt.median_s, rt.result
        diff = max(np.abs(vn - res.v_narrow_v).max() / np.abs(vn).max(), np.abs(vw - res.v_wide_v).max() / np.abs(vw).max())
        rows.append(f"| {n}x{n} | {2 * n * n} | {res.wall_s:.2f} | {total:.3f} | {1e3 * ts:.2f} | {diff:.1e} |")
    rows += [
        "",
        "| step-response transient | output points | ngspice wall (s) | exact DCT modes (s) | max rel. difference |",
        "|---|---|---|---|---|",
    ]
    for h, npts in ((5, 50),) if quick else ((5, 50), (8, 200)):  # 33x33 takes ~90 s: no KLU
        _log(f"ngspice transient patch {2 * h + 1}")
        res = simulate_mesh_step_spice(d, t_stop_s=3 * d.tau_wide_s, half_width=h, n_points=npts)
        t0 = time.perf_counter()
        diff = 0.0
        for v, g_l, g_v in (
            (res.v_narrow_v, d.g_lateral_narrow_s, d.g_vertical_narrow_s),
            (res.v_wide_v, d.g_lateral_wide_s, d.g_vertical_wide_s),
        ):
            exact = mesh_step_response(g_l, g_v, d.node_capacitance_f, h, res.t_s) * res.i_in_a
            diff = max(diff, float(np.abs(v - exact).max() / np.abs(exact).max()))
        te = time.perf_counter() - t0
        rows.append(f"| {2 * h + 1}x{2 * h + 1}, 0…3τ_wide | {npts} | {res.wall_s:.2f} | {te:.3f} | {diff:.1e} |")
    return rows


def _misc_table(quick: bool) -> list[str]:
    from .fit import MeshDesign
    from .dynamics import mesh_needs_transient, moving_edge_response
    from .mismatch import mismatch_monte_carlo

    d = MeshDesign.from_space_constants(0.8, 2.5, 1.5, 1.2, size=7)
    trials = 20 if quick else 200
    rows = ["| task | setting | result | time (s) |", "|---|---|---|---|"]
    t0 = time.perf_counter()
    r = mismatch_monte_carlo(d, sigma=0.01, n_trials=trials)
    s = r.summary()
    rows.append(
        f"| Monte Carlo mismatch | σ = 1 %, {trials} trials, grid half-width {r.half_width} | "
        f"median error {s['median']:.2e}, p95 {s['p95']:.2e}, yield(≤ 5 %) {s['yield']:.0%} | {time.perf_counter() - t0:.2f} |"
    )
    for v in (1e3, 1e5):
        t0 = time.perf_counter()
        dec = mesh_needs_transient(d, v)
        rows.append(
            f"| transient decision | {v:g} px/s, tolerance 1 % | {'model' if dec.needed else 'skip'} "
            f"(kernel error {dec.kernel_error:.1e}) | {time.perf_counter() - t0:.3f} |"
        )
        t0 = time.perf_counter()
        e = moving_edge_response(d, v)
        rows.append(
            f"| moving-edge transient | {v:g} px/s, {e.x_px.size} px chain | max error vs static {e.max_relative_error():.1e} | "
            f"{time.perf_counter() - t0:.3f} |"
        )
    return rows


def bench_mesh(*, quick: bool = False) -> str:
    """Run the dual-mesh benchmarks and return Markdown (see the module docstring)."""
    parts = ["## Dual resistive mesh (`fsdvs-hw bench mesh`)", ""]
    parts += ["### Fit time (IPOPT via casadi)", ""] + _fit_table(quick) + [""]
    parts += ["### Single-mesh model: boundary error vs run time (window 7×7)", ""] + _model_table(quick) + [""]
    parts += ["### ngspice vs casadi circuit model (impulse at the patch centre)", ""] + _spice_table(quick) + [""]
    parts += ["### Monte Carlo and dynamics (design λ = 0.8 / 2.5 px)", ""] + _misc_table(quick)
    return "\n".join(parts)
