"""``fsdvs-hw codesign-pilot``: retrain-the-network vs co-design losses of one realisation on one task."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "co-design pilot: loss of a realisation with the network retrained vs co-designed, with 95 % CIs"
DESCRIPTION = (
    "For one task and realisation: fit it to the learned detection kernel, then (a) train a network with\n"
    "the realised kernel frozen and (b) train a network and the realisation's own parameters together\n"
    "(co-design); each arm's loss against the learned kernel in its shipped networks, with the 95 % CI\n"
    "of the clips x seeds bootstrap. Writes checkpoints and pilot_REALISATION_TASK.json to --out.\n\n"
    "Example (README 'Co-design'): fsdvs-hw codesign-pilot --task recognition --realisation metalens "
    "--seeds 0 1 2"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", default="recognition", help="detection, recognition or segmentation")
    parser.add_argument("--realisation", default="metalens", help="a realisation with a differentiable form")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="training seeds")
    parser.add_argument("--out", type=Path, default=Path("out") / "codesign", help="output folder")


def run(args: argparse.Namespace) -> int:
    from ..paths import output_dir
    from ..studies.codesign_pilot import run_pilot

    out = output_dir(args.out, flag="--out")
    print(json.dumps(run_pilot(args.task, args.realisation, list(args.seeds), out), indent=1))
    return 0
