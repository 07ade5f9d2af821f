"""``fsdvs-hw sweep``: a design's sweep axes over :func:`fsdvs_hw.explore.sweep.run_design`."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from ._execution import add_execution_arguments, security_from_args

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "run a design sweep (local process pool, or a Dask cluster) into a SQLite results store"
DESCRIPTION = (
    "Expand a design file's [sweep] axes into design points, fit and score each, and store one row\n"
    "per point in a SQLite file as it finishes. A rerun skips finished points (resume after a kill).\n\n"
    "Examples:\n"
    "  fsdvs-hw sweep designs/sweep_asic_bits.toml\n"
    "  fsdvs-hw sweep designs/sweep_asic_bits.toml --scheduler tls://10.0.0.5:8786 \\\n"
    "      --tls-ca-file ca.pem --tls-cert client.pem --tls-key client.key   (README: Dask with TLS)\n"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "design",
        type=Path,
        help="TOML design file with a [sweep] section, or a shipped design's name (sweep_asic_bits)",
    )
    parser.add_argument(
        "--store",
        type=Path,
        default=None,
        help="SQLite results file (default: out/sweeps/<design name, made file-safe>.sqlite)",
    )
    parser.add_argument(
        "--report",
        type=Path,
        default=None,
        metavar="DIR",
        help="also write the HTML report of the stored points to DIR",
    )
    add_execution_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from ..design import load_design
    from ..explore.sweep import expand_points, run_design
    from ..explore.trained_kernel import settle_design_kernel
    from ..paths import output_dir, output_file
    from ..resources import resolve_design

    # user networks trained with another kernel than the design's are refused (as explore does)
    design = settle_design_kernel(load_design(resolve_design(args.design)))
    # the design's name is text, not a path: its safe form names the default store
    store_path = output_file(args.store or Path("out") / "sweeps" / f"{design.slug}.sqlite", flag="--store")
    if args.report is not None:
        output_dir(args.report, flag="--report")
    points = expand_points(design, max_points=args.max_points)
    print(f"[sweep] {design.name}: {len(points)} design points -> {store_path}", file=sys.stderr, flush=True)
    summary, rows = run_design(
        design,
        store_path,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=False if args.no_progress else None,
        retry_errors=args.retry_errors,
        points=points,
        security=security_from_args(args),
    )
    print(f"[sweep] {summary}", file=sys.stderr, flush=True)
    if args.report is not None:
        from ..explore.costing import with_physical_costs
        from ..explore.measurability import measured_losses
        from ..explore.reporting import report_input
        from ..report import write_report
        from ..report.redraw import read_codesign

        sc = design.spec.scoring
        scored = measured_losses(  # as explore: tasks at chance or with degenerate intervals weigh 0
            rows,
            task_weights=sc.task_weights or None,
            n_resamples=sc.n_resamples,
            confidence=sc.confidence,
            rng=design.spec.run.seed,
            target_half_width=sc.target_half_width,
        )
        scored = with_physical_costs(scored, design)
        stored = Path(args.report) / "codesign.json"  # an earlier co-design run's rows beside the report
        report = report_input(design)
        if design.spec.codesign.enabled and stored.is_file():
            report = replace(report, codesign=read_codesign(stored))
        page = write_report(scored, report, args.report)
        print(f"[sweep] report: {page}", file=sys.stderr, flush=True)
    return 0 if summary.statuses.get("error", 0) == 0 else 1
