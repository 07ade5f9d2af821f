"""``fsdvs-hw bench``: the speed/accuracy benchmarks of a source checkout, Markdown and JSON records.

The benchmarks are not part of the library: they live in the top-level ``benchmarks/`` folder of
the repository (its README describes their method) and are not shipped in the wheel. This verb
finds that folder beside the ``fsdvs_hw`` package it belongs to (a plain or editable checkout)
and runs its registry (``benchmarks.BENCHMARKS``).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path
from types import ModuleType

from ..errors import InputError

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "load_benchmarks", "run"]

_NAMES = (
    "csf, tasks, asic, asic_sky130, mesh, mesh_sky130, metalens, sim, explore, stats, sensors, user_data, "
    "user_data_stages, upsampling, demo"
)

HELP = "speed/accuracy benchmarks (error vs run time) for each component"
DESCRIPTION = (
    "Run the speed/accuracy benchmarks and print Markdown tables.\n\n"
    "Each table compares a fidelity knob's settings against the highest-fidelity reference:\n"
    "error (in the component's own metric) versus wall time on this machine.\n"
    "--json writes every measured value as a record (bench, table, case, metric, unit, value,\n"
    "repeats, spread, threads, machine, versions, settings, timestamp).\n"
    "--long adds the long cases (sim: the 2-minute clip written to files, streaming memory).\n"
    "Example: fsdvs-hw bench csf --out out/bench.md --json out/bench.json"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "names", nargs="*", default=["all"], metavar="NAME", help=f"benchmarks to run: {_NAMES} or all (default)"
    )
    parser.add_argument("--quick", action="store_true", help="small problem sizes (smoke test)")
    parser.add_argument(
        "--long",
        action="store_true",
        help="also the long cases of benches that have them (sim: the 2-minute clip written to "
        ".aedat4/.h5 and streaming memory, tens of minutes); default runs finish in minutes",
    )
    parser.add_argument("--out", type=Path, default=None, help="also write the Markdown to this file")
    parser.add_argument(
        "--json", type=Path, default=None, metavar="PATH", help="also write the benchmark records (JSON) to this file"
    )
    parser.add_argument(
        "--figures",
        type=Path,
        default=None,
        metavar="DIR",
        help="folder for the figures a bench draws (default: next to --out, else out/bench)",
    )


def load_benchmarks() -> ModuleType:
    """The ``benchmarks`` package of the checkout this ``fsdvs_hw`` belongs to.

    Raises
    ------
    InputError
        ``fsdvs_hw`` is installed from a wheel (no ``benchmarks/`` beside it), or another
        ``benchmarks`` module shadows the checkout's.
    """
    root = Path(__file__).resolve().parents[2]
    folder = root / "benchmarks"
    if not (folder / "__init__.py").is_file():
        raise InputError(
            f"fsdvs-hw bench runs the benchmarks of a source checkout ({folder} not found: "
            "an installed wheel does not ship them); clone the repository and run it there"
        )
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    module = importlib.import_module("benchmarks")
    where = Path(module.__file__ or "").resolve().parent
    if where != folder:
        raise InputError(f"fsdvs-hw bench: the module 'benchmarks' imported from {where}, not the checkout's {folder}")
    return module


def run(args: argparse.Namespace) -> int:
    from ..paths import output_dir, output_file, write_output

    suite = load_benchmarks()
    BENCHMARKS, benchmark_run = suite.BENCHMARKS, suite.benchmark_run
    write_json = suite.harness.write_json

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
        res = benchmark_run(n, quick=args.quick, figures=figures, long=args.long)
        print(f"[bench] {n} done in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
        print(res.markdown, flush=True)
        sections.append(res.markdown)
        records += res.records
    if args.out is not None:
        write_output(args.out, "\n\n".join(sections) + "\n")
    if args.json is not None:
        write_json(records, args.json)
        print(f"[bench] {len(records)} records -> {args.json}", file=sys.stderr, flush=True)
    return 0
