"""``fsdvs-hw report``: redraw the HTML report of an earlier run from its ``scores.json``
(:func:`fsdvs_hw.report.write_report_from_scores`), without rerunning anything."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "redraw DIR/report.html from the scores an earlier explore or sweep run stored (nothing is rerun)"
DESCRIPTION = (
    "Read DIR/scores.json (written by `fsdvs-hw explore DESIGN --out DIR` or `sweep --report DIR`) and\n"
    "write report.html, scores.csv and scores.json again, into DIR or into --to. Use it after updating\n"
    "fsdvs_hw, or to get the report of a run made elsewhere. Nothing is fitted or scored again. The design\n"
    "(with the run's --set options) must be the one the run used: scores.json keeps its fingerprint, and\n"
    "another design is refused.\n\n"
    "Example: fsdvs-hw report designs/default.toml --out out/demo --to out/demo_redrawn"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("design", type=Path, help="the TOML design file the run used")
    parser.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="output folder of the earlier run (holds scores.json)"
    )
    parser.add_argument(
        "--to",
        type=Path,
        default=None,
        metavar="DIR",
        help="folder to write the report into (default: replace the report in --out)",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="the --set options the run used (the design must match the run's: a report of "
        "another design is refused); repeatable",
    )


def run(args: argparse.Namespace) -> int:
    from ..design import load_design
    from ..explore.reporting import report_input
    from ..paths import output_dir
    from ..report import write_report_from_scores
    from .explore import parse_overrides

    design = load_design(args.design)
    if args.overrides:
        design = design.with_overrides(parse_overrides(args.overrides))
    if args.to is not None:
        output_dir(args.to, flag="--to")
    print(f"report: {write_report_from_scores(args.out, report_input(design), to=args.to)}")
    return 0
