"""``fsdvs-hw bench``: speed/accuracy benchmarks (:mod:`fsdvs_hw.bench`), Markdown and JSON records."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..bench import BENCHMARKS
from ..errors import InputError

__all__ = ["HELP", "DESCRIPTION", "add_arguments", "run"]

HELP = "speed/accuracy benchmarks (error vs run time) for each component"
DESCRIPTION = (
    "Run the speed/accuracy benchmarks and print Markdown tables.\n\n"
    "Each table compares a fidelity knob's settings against the highest-fidelity reference:\n"
    "error (in the component's own metric) versus wall time on this machine.\n"
    "--json writes every measured value as a record (bench, table, case, metric, unit, value,\n"
    "repeats, spread, threads, machine, versions, settings, timestamp).\n"
    "Example: fsdvs-hw bench csf --out out/bench.md --json out/bench.json"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("names", nargs="*", default=["all"], metavar="NAME",
                        help=f"benchmarks to run: {', '.join(BENCHMARKS)} or all (default)")
    parser.add_argument("--quick", action="store_true", help="small problem sizes (smoke test)")
    parser.add_argument("--out", type=Path, default=None, help="also write the Markdown to this file")
    parser.add_argument("--json", type=Path, default=None, metavar="PATH",
                        help="also write the benchmark records (JSON) to this file")
    parser.add_argument("--figures", type=Path, default=None, metavar="DIR",
                        help="folder for the figures a bench draws (default: next to --out, else out/bench)")


def run(args: argparse.Namespace) -> int:
    from ..bench import benchmark_run
    from ..benchmarks import write_json
    from ..paths import output_dir, output_file

    names = list(BENCHMARKS) if "all" in args.names else args.names
    for n in names:
        if n not in BENCHMARKS:
            raise InputError(f"benchmark {n!r} unknown; allowed: {', '.join(BENCHMARKS)}, all")
    # checked before the benchmarks, not after them
    if args.out is not None:
        output_file(args.out, flag="--out")
    if args.json is not None:
        output_file(args.json, flag="--json")
    figures = args.figures or (args.out.parent if args.out is not None else Path("out") / "bench")
    sections, records = [], []
    for n in names:
        t0 = time.perf_counter()
        print(f"[bench] {n} ...", file=sys.stderr, flush=True)
        if n == "metalens" and not args.quick:
            output_dir(figures, flag="--figures")
        res = benchmark_run(n, quick=args.quick, figures=figures)
        print(f"[bench] {n} done in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
        print(res.markdown, flush=True)
        sections.append(res.markdown)
        records += res.records
    if args.out is not None:
        args.out.write_text("\n\n".join(sections) + "\n")
    if args.json is not None:
        write_json(records, args.json)
        print(f"[bench] {len(records)} records -> {args.json}", file=sys.stderr, flush=True)
    return 0
