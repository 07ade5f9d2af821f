"""``fsdvs-hw sizing``: size a design's test sets from a pilot run (:func:`fsdvs_hw.explore.sizing.size_test_sets`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from ..limits import MAX_CLIPS
from ._execution import int_in

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "size a design's test sets: run a small pilot and print the clips each task needs for a target CI half-width"
DESCRIPTION = (
    "Run the design with --pilot test clips per task and network, then print, per track and task, the\n"
    "number of clips that brings every realisation's loss CI to the target half-width (or says which\n"
    "realisations are seed-limited: more clips cannot help).\n\n"
    "Examples:\n  fsdvs-hw sizing designs/default.toml --pilot 512\n"
    "  fsdvs-hw sizing designs/default.toml --from out/demo   (a finished run as the pilot)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("design", type=Path, help="TOML design file, or a shipped design's name (default)")
    parser.add_argument("--pilot", type=int_in(1, MAX_CLIPS), default=512, help="pilot test clips per task and network")
    parser.add_argument(
        "--target", type=float, default=None, help="CI half-width (default: the design's [scoring] target_half_width)"
    )
    parser.add_argument("--margin", type=float, default=1.15, help="safety factor on the clip count")
    parser.add_argument("--out", type=Path, default=Path("out/sizing"), metavar="DIR", help="pilot output folder")
    parser.add_argument(
        "--from",
        dest="from_run",
        type=Path,
        default=None,
        metavar="DIR",
        help="size from a finished exploration's DIR/results.sqlite (e.g. out/demo) instead of a pilot",
    )


def run(args: argparse.Namespace) -> int:
    from ..design import load_design
    from ..explore.explore import run_exploration
    from ..explore.sizing import budget_table, size_test_sets
    from ..explore.store import ResultsStore
    from ..paths import output_dir
    from ..resources import resolve_design

    # checked before the pilot runs (minutes), not after
    if args.target is not None and not (0 < args.target < 1):
        raise InputError(f"--target {args.target!r}: a CI half-width must lie in (0, 1)")
    if not args.margin >= 1.0:
        raise InputError(f"--margin {args.margin!r}: must be >= 1")
    if args.from_run is None and args.pilot < 2:
        raise InputError(f"--pilot {args.pilot!r}: must be >= 2 test clips")
    design = load_design(resolve_design(args.design))
    target = design.spec.scoring.target_half_width if args.target is None else args.target
    if args.from_run is not None:
        store_path = args.from_run / "results.sqlite"
        if not store_path.is_file():
            raise InputError(f"--from {str(args.from_run)!r}: no results.sqlite there (run fsdvs-hw explore first)")
        what = f"run {args.from_run} as the pilot"
    else:
        output_dir(args.out, flag="--out")  # before the pilot run
        pilot = design.with_overrides({"tasks.n_test": args.pilot, "tasks.n_test_emulation": 0})
        run_exploration(pilot, args.out, progress=False if args.no_progress else None)
        store_path = args.out / "results.sqlite"
        what = f"pilot {args.pilot} clips per task and network"
    with ResultsStore(store_path) as store:
        rows = list(store.rows())
    print(f"{what}; target half-width {target}; margin {args.margin}")
    print(budget_table(size_test_sets(rows, target_half_width=target, margin=args.margin)))
    return 0
