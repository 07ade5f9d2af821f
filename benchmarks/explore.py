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
from pathlib import Path

import numpy as np

from fsdvs_hw.design import parse_design
from fsdvs_hw.explore.emulation import emulation_scores
from fsdvs_hw.explore.store import ResultsStore
from fsdvs_hw.explore.sweep import expand_points, run_points

from .harness import BenchRun, BenchSection, Column, Timing, kept_global_state, timed

__all__ = ["bench_explore"]


def _emulation_table(sec: BenchSection, quick: bool) -> None:
    d = parse_design({"kernel": {"family": "dog", "size": 7}})
    sensor, base = d.data["sensor"], d.data["emulation"]
    clips = [1, 2] if quick else [1, 2, 4, 8]
    ref_clips = 4 if quick else 16
    ups = [1, 2] if quick else [1, 2, 4]
    ref_up = 4 if quick else 8

    def run(n_clips: int, up: int) -> Timing[dict]:
        return timed(
            lambda: emulation_scores(
                d.target, sensor=sensor, emulation={**base, "n_clips": n_clips, "upsample_factor": up}
            )
        )

    sec.text(
        "### Emulation track: estimate vs clips and temporal upsampling",
        "",
        "7×7 DoG at the default design's sensor (48×64 px, thresholds 0.2, σ 0.03, v2e noise), "
        "8-bit γ 2.2 display. Error = |estimate − reference|.",
        "",
    )
    table = sec.table(
        Column.text("setting"),
        Column.number("event ratio", ".3f"),
        Column.number("error vs reference", ".3f", metric="event ratio error vs reference"),
        Column.number("signed r", ".3f", metric="signed correlation"),
        Column.number("error vs reference", ".3f", metric="signed correlation error vs reference"),
        Column.number("time (s)", ".2f", metric="time"),
    )
    run(1, 1)  # warm-up: first-call imports and allocations are not part of any setting's time
    t_ref = run(ref_clips, ref_up)
    ref = t_ref.result
    print(f"[bench explore] emulation reference ({ref_clips} clips, x{ref_up}) {t_ref.best_s:.1f} s", file=sys.stderr)
    rows = [(f"{n} clips, x{ref_up}", n, ref_up) for n in clips] + [
        (f"{ref_clips} clips, x{u}", ref_clips, u) for u in ups
    ]
    for label, n, up in rows:
        t = run(n, up)
        res = t.result
        table.row(
            label,
            res["event_ratio"],
            abs(res["event_ratio"] - ref["event_ratio"]),
            res["signed_correlation"],
            abs(res["signed_correlation"] - ref["signed_correlation"]),
            t,
        )
    table.row(
        f"**reference: {ref_clips} clips, x{ref_up}**", ref["event_ratio"], "0", ref["signed_correlation"], "0", t_ref
    )  # its own error is 0 by definition: printed, not measured


def _executor_table(sec: BenchSection, quick: bool) -> None:
    n_focal = 3 if quick else 8
    focals = [2e-3 * (1.5**i) for i in range(n_focal)]
    d = parse_design(
        {
            "realisations": {"include": ["learned", "delta"]},
            "analysis": {"csf_methods": ["mannos_sakrison_1974"]},
            "emulation": {"enabled": False},
            "sweep": {"axes": {"optics.focal_length_m": focals}},
        }
    )
    points = expand_points(d)
    results: dict[str, dict[str, float]] = {}
    sec.text(
        "### Sweep executors",
        "",
        "Ideal references over a viewing-geometry axis (Mannos–Sakrison agreement only; "
        "each point ≈ 0.1–0.3 s of work), so the table shows executor overhead: process start-up "
        "(spawn) and Dask scheduling.",
        "",
    )
    table = sec.table(
        Column.text("executor"),
        Column.text("points"),
        Column.number("wall time (s)", ".2f"),
        Column.number("points/s", ".2f", unit="points/s", metric="throughput"),
        Column.text("scores identical to in-process"),
    )
    with tempfile.TemporaryDirectory() as tmp:

        def one(name: str, **kw: object) -> None:
            with ResultsStore(Path(tmp) / f"{name.replace(' ', '_')}.sqlite") as store:
                t = timed(lambda: run_points(points, store, progress=False, **kw))  # type: ignore[arg-type]
                scores = {r["key"]: r["result"]["csf"]["mannos_sakrison_1974"]["correlation"] for r in store.rows()}
            results[name] = scores
            same = "yes" if name == "this process" or scores == results["this process"] else "NO"
            table.row(name, str(len(points)), t, len(points) / t.best_s, same)
            print(f"[bench explore] {name}: {t.best_s:.1f} s", file=sys.stderr)

        one("this process", workers=1)
        one("2 local processes", workers=2)
        try:
            from distributed import LocalCluster
        except ImportError:  # pragma: no cover - optional extra
            table.row("Dask LocalCluster", "–", "–", "–", "dask[distributed] not installed")
        else:
            with LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as cluster:
                one("Dask LocalCluster (2 workers, loopback)", scheduler=cluster.scheduler_address)


def bench_explore(*, quick: bool = False) -> BenchRun:
    """Speed/accuracy tables of the exploration layer (see the module docstring), as records and
    their Markdown; numpy's error state and the environment are left as they were."""
    sec = BenchSection("explore", settings={"quick": quick})
    sec.text("## explore", "")
    with kept_global_state(), np.errstate(all="ignore"):
        _emulation_table(sec, quick)
        sec.text("")
        _executor_table(sec, quick)
    sec.text("")
    return sec.run()
