"""``fsdvs-hw bench``: speed/accuracy tables for every component, in one command.

Each component registers a benchmark in :data:`BENCHMARKS` as ``"module:function"``; the function
has the signature ``f(*, quick: bool = False) -> str`` and returns a Markdown section (title line
plus tables: error against the highest-fidelity reference versus run time, and throughput/memory
where relevant). ``quick`` shrinks the problem for smoke tests; the README tables are produced with
``quick=False``. Benchmarks print progress to stderr and their result to stdout.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

from .errors import InputError

__all__ = ["BENCHMARKS", "run_benchmark", "HELP", "add_arguments", "run"]

#: benchmark name -> "module:function"
BENCHMARKS: dict[str, str] = {
    "csf": "fsdvs_hw.analysis:bench_analysis",
    "tasks": "fsdvs_hw.tasks.bench:bench_tasks",
    "asic": "fsdvs_hw.realise.asic.bench:bench_asic",
    "mesh": "fsdvs_hw.realise.mesh.bench:bench_mesh",
    "metalens": "fsdvs_hw.realise.metalens.bench:bench_metalens",
    "sim": "fsdvs_hw.sensor.bench:bench_sim",
    "explore": "fsdvs_hw.explore.bench:bench_explore",
    "stats": "fsdvs_hw.explore.stats_bench:bench_stats",
}

HELP = "speed/accuracy benchmarks (error vs run time) for each component"
DESCRIPTION = (
    "Run the speed/accuracy benchmarks and print Markdown tables.\n\n"
    "Each table compares a fidelity knob's settings against the highest-fidelity reference:\n"
    "error (in the component's own metric) versus wall time on this machine.\n"
    "Example: fsdvs-hw bench csf --out out/bench.md"
)


def run_benchmark(name: str, *, quick: bool = False) -> str:
    """Run one registered benchmark and return its Markdown section."""
    if name not in BENCHMARKS:
        raise InputError(f"benchmark {name!r} unknown; allowed: {', '.join(BENCHMARKS)}, all")
    module, func = BENCHMARKS[name].split(":")
    return getattr(importlib.import_module(module), func)(quick=quick)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("names", nargs="*", default=["all"], metavar="NAME",
                        help=f"benchmarks to run: {', '.join(BENCHMARKS)} or all (default)")
    parser.add_argument("--quick", action="store_true", help="small problem sizes (smoke test)")
    parser.add_argument("--out", type=Path, default=None, help="also write the Markdown to this file")


def run(args: argparse.Namespace) -> int:
    names = list(BENCHMARKS) if "all" in args.names else args.names
    for n in names:
        if n not in BENCHMARKS:
            raise InputError(f"benchmark {n!r} unknown; allowed: {', '.join(BENCHMARKS)}, all")
    if args.out is not None:
        from .paths import output_file

        output_file(args.out, flag="--out")  # before the benchmarks, not after them
    sections = []
    for n in names:
        t0 = time.perf_counter()
        print(f"[bench] {n} ...", file=sys.stderr, flush=True)
        text = run_benchmark(n, quick=args.quick)
        print(f"[bench] {n} done in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
        print(text, flush=True)
        sections.append(text)
    if args.out is not None:
        args.out.write_text("\n\n".join(sections) + "\n")
    return 0
