"""``fsdvs-hw bench explore``: speed for accuracy of the exploration layer.

Two tables:

1. **Emulation track fidelity.** The sensor-in-the-loop emulation scores (event-count ratio and
   signed-frame correlation against the in-pixel kernel) estimated from fewer clips or a coarser
   temporal upsampling, against the highest-fidelity setting, with the wall time of each.
2. **Executors.** The same cheap sweep (ideal references over a viewing-geometry axis) in this
   process, on a local process pool and on a Dask ``LocalCluster`` over loopback: wall time and
   points per second, and whether every executor stores identical scores.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .design import parse_design
from .emulation import emulation_scores
from .store import ResultsStore
from .sweep import expand_points, run_points

__all__ = ["bench_explore"]


def _emulation_table(quick: bool) -> str:
    d = parse_design({"kernel": {"family": "dog", "size": 7}})
    sensor, base = d.data["sensor"], d.data["emulation"]
    clips = [1, 2] if quick else [1, 2, 4, 8]
    ref_clips = 4 if quick else 16
    ups = [1, 2] if quick else [1, 2, 4]
    ref_up = 4 if quick else 8

    def run(n_clips: int, up: int) -> tuple[dict, float]:
        t0 = time.perf_counter()
        res = emulation_scores(d.target, sensor=sensor, emulation={**base, "n_clips": n_clips, "upsample_factor": up})
        return res, time.perf_counter() - t0

    lines = ["| setting | event ratio | error vs reference | signed r | error vs reference | time (s) |",
             "|---|---|---|---|---|---|"]
    run(1, 1)  # warm-up: first-call imports and allocations are not part of any setting's time
    ref, t_ref = run(ref_clips, ref_up)
    print(f"[bench explore] emulation reference ({ref_clips} clips, x{ref_up}) {t_ref:.1f} s", file=sys.stderr)
    rows = [(f"{n} clips, x{ref_up}", n, ref_up) for n in clips] + [(f"{ref_clips} clips, x{u}", ref_clips, u) for u in ups]
    for label, n, up in rows:
        res, t = run(n, up)
        lines.append(f"| {label} | {res['event_ratio']:.3f} | {abs(res['event_ratio'] - ref['event_ratio']):.3f} "
                     f"| {res['signed_correlation']:.3f} | {abs(res['signed_correlation'] - ref['signed_correlation']):.3f} "
                     f"| {t:.2f} |")
    lines.append(f"| **reference: {ref_clips} clips, x{ref_up}** | {ref['event_ratio']:.3f} | 0 "
                 f"| {ref['signed_correlation']:.3f} | 0 | {t_ref:.2f} |")
    return ("### Emulation track: estimate vs clips and temporal upsampling\n\n"
            "7×7 DoG at the default design's sensor (48×64 px, thresholds 0.2, σ 0.03, v2e noise), "
            "8-bit γ 2.2 display. Error = |estimate − reference|.\n\n" + "\n".join(lines))


def _executor_table(quick: bool) -> str:
    n_focal = 3 if quick else 8
    focals = [2e-3 * (1.5 ** i) for i in range(n_focal)]
    d = parse_design({"realisations": {"include": ["learned", "delta"]},
                      "analysis": {"csf_methods": ["mannos_sakrison_1974"]}, "emulation": {"enabled": False},
                      "sweep": {"axes": {"optics.focal_length_m": focals}}})
    points = expand_points(d)
    results: dict[str, dict[str, float]] = {}
    lines = ["| executor | points | wall time (s) | points/s | scores identical to in-process |", "|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        def one(name: str, **kw: object) -> None:
            with ResultsStore(Path(tmp) / f"{name.replace(' ', '_')}.sqlite") as store:
                t0 = time.perf_counter()
                run_points(points, store, progress=False, **kw)  # type: ignore[arg-type]
                dt = time.perf_counter() - t0
                scores = {r["key"]: r["result"]["csf"]["mannos_sakrison_1974"]["correlation"] for r in store.rows()}
            results[name] = scores
            same = "yes" if name == "this process" or scores == results["this process"] else "NO"
            lines.append(f"| {name} | {len(points)} | {dt:.2f} | {len(points) / dt:.2f} | {same} |")
            print(f"[bench explore] {name}: {dt:.1f} s", file=sys.stderr)

        one("this process", workers=1)
        one("2 local processes", workers=2)
        try:
            from distributed import LocalCluster
        except ImportError:  # pragma: no cover - optional extra
            lines.append("| Dask LocalCluster | – | – | – | dask[distributed] not installed |")
        else:
            with LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as cluster:
                one("Dask LocalCluster (2 workers, loopback)", scheduler=cluster.scheduler_address)
    return ("### Sweep executors\n\nIdeal references over a viewing-geometry axis (Mannos–Sakrison agreement only; "
            "each point ≈ 0.1–0.3 s of work), so the table shows executor overhead: process start-up "
            "(spawn) and Dask scheduling.\n\n" + "\n".join(lines))


def bench_explore(*, quick: bool = False) -> str:
    """Markdown speed/accuracy tables of the exploration layer (see the module docstring)."""
    np.seterr(all="ignore")
    return "## explore\n\n" + _emulation_table(quick) + "\n\n" + _executor_table(quick) + "\n"
