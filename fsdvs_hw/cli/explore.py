"""``fsdvs-hw explore``: the main job over :func:`fsdvs_hw.explore.explore.run_exploration`."""

from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path
from typing import Any

from ..errors import InputError
from ._execution import add_execution_arguments, security_from_args

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "parse_overrides", "run", "with_device"]

HELP = "the main job: fit every realisation of a design's kernel, score it, write the HTML report"
DESCRIPTION = (
    "Fit every realisation (resistive mesh, ASIC taps, metalens, plus the learned kernel and the delta\n"
    "baseline) of the design's kernel, score kernel error, CSF agreement, task accuracy loss, cost and\n"
    "wall time, and write DIR/report.html, DIR/scores.csv, DIR/scores.json and DIR/results.sqlite,\n"
    "and each hardware point's buildable files (SPICE deck, Verilog + testbench, phase profile) under\n"
    "DIR/artifacts/ with DIR/artifacts/index.json.\n"
    "A rerun into the same DIR skips points already scored. With no DESIGN, the embedded default design\n"
    "(designs/default.toml, shipped with the package) runs.\n\n"
    "Examples:\n  fsdvs-hw explore --out out/demo\n  fsdvs-hw explore my_design.toml --out out/mine\n"
    "  fsdvs-hw explore --set tasks.tracks='[\"simulator\"]' --set emulation.enabled=false --out out/quick\n\n"
    "Exit status: 0 every point and every requested task scored; 1 a design point failed; 2 bad input\n"
    "(before any work); 3 every point ran but a requested task failed on some of them (one line each on\n"
    "stderr; the report's first section lists them, with the clips skipped). The report and the scores\n"
    "are written in every case but 2."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "design",
        type=Path,
        nargs="?",
        default=None,
        help="TOML design file, or the name of a shipped design (default: the embedded designs/default.toml)",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("out/explore"), metavar="DIR", help="output folder (default: %(default)s)"
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="replace one design key for this run (dotted key, TOML value: "
        "--set asic.bits=6 --set 'tasks.n_test={detection=16}'); repeatable",
    )
    parser.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        default=None,
        help="run the simulator and the network of every [tasks.datasets.<task>] (user data) on "
        "this device (default: each table's 'device', cpu unless set)",
    )
    add_execution_arguments(parser)


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``["asic.bits=6", "tasks.n_test={detection=16}"]`` → ``{"asic.bits": 6, ...}`` (values are TOML).

    A value that is not valid TOML is taken as a string (``--set design.name=quick``).

    Raises
    ------
    InputError
        An item without ``=`` or with an empty key; a key that is not in the design schema
        (:func:`fsdvs_hw.design.keys.check_key`: one line with the closest allowed keys).
    """
    from ..design import check_key

    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise InputError(f"--set {item[:80]!r}: expected KEY=VALUE (a dotted design key and a TOML value)")
        check_key(key, what="--set")  # with_overrides canonicalises; the key is kept as written
        try:
            out[key] = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = text
    return out


def with_device(design: Any, device: str) -> Any:
    """``design`` with every ``[tasks.datasets.<task>]`` run on ``device`` (``--device``).

    Raises
    ------
    InputError
        The design scores no task on user data (trained checkpoints run on the CPU), or the
        device is not available (naming the key).
    """
    user = design.spec.tasks.datasets
    if not user:
        raise InputError(
            f"--device {device}: {design.source} has no [tasks.datasets.<task>] table; allowed: "
            "--device with user-data tasks (tasks from tasks.checkpoints are scored on the CPU)"
        )
    return design.with_overrides({f"tasks.datasets.{t}": {**e.model_dump(), "device": device} for t, e in user.items()})


def run(args: argparse.Namespace) -> int:
    from ..design import load_design
    from ..explore.explore import run_exploration
    from ..paths import output_dir
    from ..report.failures import EXIT_TASK_FAILED, failure_lines, task_failures
    from ..report.tables import networks_note, score_rows, summary_markdown
    from ..resources import resolve_design

    design = load_design(resolve_design(args.design))
    if args.overrides:
        design = design.with_overrides(parse_overrides(args.overrides))
    if args.device is not None:
        design = with_device(design, args.device)
    output_dir(args.out, flag="--out")  # before any work
    print(f"[explore] {design.name}: target {design.target!r}", file=sys.stderr, flush=True)
    res = run_exploration(
        design,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=False if args.no_progress else None,
        retry_errors=args.retry_errors,
        max_points=args.max_points,
        security=security_from_args(args),
    )
    print(f"[explore] {res.summary}", file=sys.stderr)
    failed = task_failures(res.points)
    for line in failure_lines(res.points):  # after the work: the report and scores are written
        print(line, file=sys.stderr)
    print(summary_markdown(score_rows(res.points)) + "\n")
    nets = networks_note(res.points)
    if nets:
        print(f"losses measured in: {nets}\n")
    print(
        f"report: {res.report}\nscores: {res.scores_csv}, {res.scores_json}\nstore:  {res.store}\n"
        f"artifacts: {res.artifacts_index}\n"
        f"total {res.wall_s:.1f} s"
    )
    if res.summary.statuses.get("error", 0):
        return 1
    return EXIT_TASK_FAILED if failed else 0
