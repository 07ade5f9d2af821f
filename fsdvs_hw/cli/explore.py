"""``fsdvs-hw explore``: the main job over :func:`fsdvs_hw.explore.explore.run_exploration`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._execution import add_execution_arguments, security_from_args

__all__ = ["HELP", "DESCRIPTION", "add_arguments", "run"]

HELP = "the main job: fit every realisation of a design's kernel, score it, write the HTML report"
DESCRIPTION = (
    "Fit every realisation (resistive mesh, ASIC taps, metalens, plus the learned kernel and the delta\n"
    "baseline) of the design's kernel, score kernel error, CSF agreement, task accuracy loss, cost and\n"
    "wall time, and write DIR/report.html, DIR/scores.csv, DIR/scores.json and DIR/results.sqlite.\n"
    "A rerun into the same DIR skips points already scored.\n\n"
    "Example: fsdvs-hw explore designs/default.toml --out out/demo"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("design", type=Path, help="TOML design file (see designs/default.toml)")
    parser.add_argument("--out", type=Path, default=Path("out/explore"), metavar="DIR", help="output folder")
    add_execution_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from ..explore.design import load_design
    from ..explore.explore import run_exploration
    from ..paths import output_dir
    from ..report.tables import networks_note, score_rows, summary_markdown

    design = load_design(args.design)
    output_dir(args.out, flag="--out")  # before any work
    print(f"[explore] {design.name}: target {design.target!r}", file=sys.stderr, flush=True)
    res = run_exploration(design, args.out, workers=args.workers, scheduler=args.scheduler,
                          progress=False if args.no_progress else None, retry_errors=args.retry_errors, max_points=args.max_points,
                          security=security_from_args(args))
    print(f"[explore] {res.summary}", file=sys.stderr)
    print(summary_markdown(score_rows(res.points)) + "\n")
    nets = networks_note(res.points)
    if nets:
        print(f"losses measured in: {nets}\n")
    print(f"report: {res.report}\nscores: {res.scores_csv}, {res.scores_json}\nstore:  {res.store}\n"
          f"total {res.wall_s:.1f} s")
    return 0 if res.summary.statuses.get("error", 0) == 0 else 1
