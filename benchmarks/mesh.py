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
import sys

import numpy as np

from .harness import BenchRun, BenchSection, Column, Measured, kept_global_state, timed

__all__ = ["bench_mesh"]


def _log(msg: str) -> None:
    print(f"[bench mesh] {msg}", file=sys.stderr, flush=True)


def _fit_table(sec: BenchSection, quick: bool) -> None:
    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.realise.mesh.fit import MeshDesign, _mesh_solver, fit_resistive_mesh

    repeats = 2 if quick else 5

    def whole_response(*args: float) -> object:
        d = MeshDesign.from_space_constants(*args[:4], pixel_weight=args[4], size=7)
        return d.kernel(d.response_size(1e-14))

    def canonical(k: int) -> object:
        return reference_kernel(
            "dog", k, pitch_m=4.86e-6, sigma_centre_px=0.8, sigma_surround_px=2.2, w_centre=1.0, w_surround=0.7
        )

    cases = [
        (
            "known dual mesh λ 0.8/2.5 px (whole response)",
            lambda k: whole_response(0.8, 2.5, 1.5, 1.2, 1.0),
            {},
            (None,),
        ),
        (
            "known dual mesh λ 0.5/1.0 px (whole response)",
            lambda k: whole_response(0.5, 1.0, 1.0, 1.4, 0.5),
            {},
            (None,),
        ),
        ("DoG 0.8/2.2 px, 0.7 (issue 13)", canonical, {}, (3, 5, 7, 9)),
        ("DoG 0.7/2.0 px, 0.8 (reference)", lambda k: reference_kernel("dog", k), {}, (7,)),
        ("DoG 0.8/2.2 px, paper's sketch w_p=1, gain fixed", canonical, {"pixel_weight": 1.0, "gain": "fixed"}, (7,)),
        ("DoG 0.8/2.2 px, w_p=1, gain free", canonical, {"pixel_weight": 1.0}, (7,)),
        ("DoG 0.8/2.2 px, whole DC unconstrained", canonical, {"nonnegative_dc": False}, (7,)),
    ]
    table = sec.table(
        Column.text("target"),
        Column.text("options"),
        Column.text("size"),
        Column.number("first call (s)", ".2f", metric="first call time"),
        Column.number("median later (s) [min–max]", ".3f", unit="s", metric="later call time", spread=True),
        Column.number("error (whole response)", ".3g", unit="", metric="kernel error (whole response)"),
        Column.number("error (window)", ".3g", unit="", metric="kernel error (window)"),
        Column.number("whole DC", ".3g", metric="whole DC gain"),
        Column.number("window DC", ".3g", metric="window DC gain"),
        Column.number("tail energy", ".2g", metric="tail energy fraction"),
        Column.number("IPOPT iterations", "d", unit="count"),
        Column.text("at a bound"),
        settings={"repeats": repeats},
    )
    for label, make, opts, sizes in cases:
        for k in sizes:
            target = make(k)
            _log(f"fit {label} {target.size}x{target.size}")
            _mesh_solver.cache_clear()
            first = timed(lambda: fit_resistive_mesh(target, **opts))
            later = timed(lambda: fit_resistive_mesh(target, **opts), repeats)
            f = later.result.fit
            bounds = "; ".join(b.split(" (")[0] for b in f["on_bound"]) or "none"
            table.row(
                label,
                ", ".join(f"{a}={v}" for a, v in opts.items()) or "defaults",
                f"{target.size}x{target.size}",
                first,
                later,
                f["error"],
                f["error_window"],
                f["whole_dc_gain"],
                f["window_dc_gain"],
                f["tail_energy_fraction"],
                f["iterations"],
                bounds,
            )


def _model_table(sec: BenchSection, quick: bool) -> None:
    from fsdvs_hw.realise.mesh.response import (
        casadi_mesh_model,
        finite_grid_response,
        grid_half_width_for,
        lattice_green_quarter,
        quadrature_nodes,
        unfold_quarter,
    )

    radius = 3
    repeats = 3 if quick else 9
    table = sec.table(
        Column.text("λ (px)"),
        Column.text("model"),
        Column.text("grid half-width (px)"),
        Column.number("max error / max tap", ".1e", unit="", metric="max error / max tap"),
        Column.number("time (ms)", ".3f", metric="time"),
        settings={"repeats": repeats},
    )
    for lam in (1.0, 3.0) if quick else (1.0, 3.0, 10.0):
        k, _w = quadrature_nodes(max(lam, 1.0), radius)
        n4 = 4 * k.size
        th = (np.arange(n4) + 0.5) * (np.pi / n4)
        s = 1.0 / math.sqrt(1.0 + 2.8 * max(lam, 1.0))
        t = np.tan(th / 2)
        ref_nodes = (2 * np.arctan(s * t), s * (1 + t * t) / (1 + s * s * t * t) / n4)
        ref = unfold_quarter(lattice_green_quarter(lam, radius, nodes=ref_nodes))
        scale = np.abs(ref).max()
        rt = timed(lambda: unfold_quarter(lattice_green_quarter(lam, radius)), repeats)
        table.row(
            f"{lam:g}", f"lattice Green's function ({k.size} nodes)", "∞", np.abs(rt.result - ref).max() / scale, rt
        )
        rule = grid_half_width_for(lam, radius)
        halves = sorted({radius, radius + 2, rule, 2 * rule} if not quick else {radius + 2, rule})
        for h in halves:
            tag = " (rule r+3+3λ)" if h == rule else ""
            for method in ("dct", "sparse"):
                rt = timed(lambda: finite_grid_response(lam, radius, h, method=method), repeats)
                table.row(f"{lam:g}", f"finite grid, {method}", f"{h}{tag}", np.abs(rt.result - ref).max() / scale, rt)
            n = 2 * h + 1
            i_in = np.zeros(n * n)
            i_in[h * n + h] = 1.0
            build = timed(lambda: casadi_mesh_model(h))
            f = build.result
            rt = timed(lambda: np.array(f(lam * lam, 1.0, i_in)).reshape(n, n), repeats)
            g = rt.result[h - radius : h + radius + 1, h - radius : h + radius + 1]
            case = f"λ (px)={lam:g}; model=finite grid, casadi KCL (MX, ldl); grid half-width (px)={h}"
            built = sec.value(case, "casadi build time", build, unit="ms", spec=".0f")
            table.row(
                f"{lam:g}",
                f"finite grid, casadi KCL (MX, ldl; build {built} ms)",
                str(h),
                np.abs(g - ref).max() / scale,
                rt,
                case=case,
            )


def _spice_table(sec: BenchSection, quick: bool) -> None:
    import shutil

    from fsdvs_hw.realise.mesh.dynamics import mesh_step_response
    from fsdvs_hw.realise.mesh.fit import MeshDesign
    from fsdvs_hw.realise.mesh.response import casadi_mesh_model
    from fsdvs_hw.realise.mesh.spice import (
        simulate_mesh_spice,
        simulate_mesh_step_spice,
    )

    if shutil.which("ngspice") is None:
        sec.text("ngspice not installed: table skipped (apt-get install ngspice).")
        return
    d = MeshDesign.from_space_constants(0.8, 2.5, 1.5, 1.2, size=7)
    table = sec.table(
        Column.text("patch"),
        Column.text("nodes (2 meshes)"),
        Column.number("ngspice wall (s)", ".2f", metric="ngspice wall time"),
        Column.number("casadi build + solve (s)", ".3f", metric="casadi build + solve time"),
        Column.number("casadi solve (ms)", ".2f", metric="casadi solve time"),
        Column.number("max rel. difference", ".1e", metric="max relative node-voltage difference"),
        title="ngspice vs casadi circuit model (impulse at the patch centre)",
    )
    for h in (8, 16) if quick else (8, 16, 31):
        _log(f"ngspice patch {2 * h + 1}")
        res = simulate_mesh_spice(d, half_width=h)
        n = 2 * h + 1
        i_in = np.zeros(n * n)
        i_in[h * n + h] = res.i_in_a

        def build_and_solve() -> tuple[np.ndarray, np.ndarray, object]:
            f = casadi_mesh_model(h)
            return (
                np.array(f(d.g_lateral_narrow_s, d.g_vertical_narrow_s, i_in)).reshape(n, n),
                np.array(f(d.g_lateral_wide_s, d.g_vertical_wide_s, i_in)).reshape(n, n),
                f,
            )

        total = timed(build_and_solve)
        vn, vw, f = total.result
        solve = timed(lambda: f(d.g_lateral_wide_s, d.g_vertical_wide_s, i_in), 3)
        diff = max(
            np.abs(vn - res.v_narrow_v).max() / np.abs(vn).max(), np.abs(vw - res.v_wide_v).max() / np.abs(vw).max()
        )
        table.row(f"{n}x{n}", str(2 * n * n), Measured.of([res.wall_s]), total, solve, diff)
    sec.text("")
    table = sec.table(
        Column.text("step-response transient"),
        Column.text("output points"),
        Column.number("ngspice wall (s)", ".2f", metric="ngspice wall time"),
        Column.number("exact DCT modes (s)", ".3f", metric="exact DCT modes time"),
        Column.number("max rel. difference", ".1e", metric="max relative difference"),
        title="ngspice step-response transients vs exact modal solution",
    )
    for h, npts in ((5, 50),) if quick else ((5, 50), (8, 200)):  # 33x33 takes ~90 s: no KLU
        _log(f"ngspice transient patch {2 * h + 1}")
        res = simulate_mesh_step_spice(d, t_stop_s=3 * d.tau_wide_s, half_width=h, n_points=npts)

        def exact_diff() -> float:
            diff = 0.0
            for v, g_l, g_v in (
                (res.v_narrow_v, d.g_lateral_narrow_s, d.g_vertical_narrow_s),
                (res.v_wide_v, d.g_lateral_wide_s, d.g_vertical_wide_s),
            ):
                exact = mesh_step_response(g_l, g_v, d.node_capacitance_f, h, res.t_s) * res.i_in_a
                diff = max(diff, float(np.abs(v - exact).max() / np.abs(exact).max()))
            return diff

        te = timed(exact_diff)
        table.row(f"{2 * h + 1}x{2 * h + 1}, 0…3τ_wide", str(npts), Measured.of([res.wall_s]), te, te.result)


def _misc_table(sec: BenchSection, quick: bool) -> None:
    from fsdvs_hw.realise.mesh.dynamics import (
        mesh_needs_transient,
        moving_edge_response,
    )
    from fsdvs_hw.realise.mesh.fit import MeshDesign
    from fsdvs_hw.realise.mesh.mismatch import mismatch_monte_carlo

    d = MeshDesign.from_space_constants(0.8, 2.5, 1.5, 1.2, size=7)
    trials = 20 if quick else 200
    table = sec.table(
        Column.text("task"),
        Column.text("setting"),
        Column.number("result", unit="", metric="result"),  # cells: text quoting recorded values
        Column.number("time (s)", ".3f", metric="time"),
    )
    mc = timed(lambda: mismatch_monte_carlo(d, sigma=0.01, n_trials=trials))
    r = mc.result
    s = r.summary()
    setting = f"σ = 1 %, {trials} trials, grid half-width {r.half_width}"
    case = f"task=Monte Carlo mismatch; setting={setting}"
    result = (
        f"median error {sec.value(case, 'median kernel error', s['median'], spec='.2e')}, "
        f"p95 {sec.value(case, 'p95 kernel error', s['p95'], spec='.2e')}, "
        f"yield(≤ 5 %) {sec.value(case, 'yield (error ≤ 5 %)', 100 * s['yield'], unit='%', spec='.0f')}%"
    )
    table.row("Monte Carlo mismatch", setting, result, mc, case=case)
    for v in (1e3, 1e5):
        setting = f"{v:g} px/s, tolerance 1 %"
        case = f"task=transient decision; setting={setting}"
        t = timed(lambda: mesh_needs_transient(d, v))
        dec = t.result
        err = sec.value(case, "kernel error", dec.kernel_error, spec=".1e")
        table.row(
            "transient decision", setting, f"{'model' if dec.needed else 'skip'} (kernel error {err})", t, case=case
        )
        t = timed(lambda: moving_edge_response(d, v))
        e = t.result
        setting = f"{v:g} px/s, {e.x_px.size} px chain"
        case = f"task=moving-edge transient; setting={setting}"
        err = sec.value(case, "max error vs static", e.max_relative_error(), spec=".1e")
        table.row("moving-edge transient", setting, f"max error vs static {err}", t, case=case)


@kept_global_state()
def bench_mesh(*, quick: bool = False) -> BenchRun:
    """Run the dual-mesh benchmarks: their records and Markdown tables (see the module docstring)."""
    sec = BenchSection("mesh", settings={"quick": quick})
    sec.text("## Dual resistive mesh (`fsdvs-hw bench mesh`)", "")
    sec.text("### Fit time (IPOPT via casadi)", "")
    _fit_table(sec, quick)
    sec.text("", "### Single-mesh model: boundary error vs run time (window 7×7)", "")
    _model_table(sec, quick)
    sec.text("", "### ngspice vs casadi circuit model (impulse at the patch centre)", "")
    _spice_table(sec, quick)
    sec.text("", "### Monte Carlo and dynamics (design λ = 0.8 / 2.5 px)", "")
    _misc_table(sec, quick)
    return sec.run()
