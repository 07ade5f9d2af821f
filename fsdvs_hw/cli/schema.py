"""``fsdvs-hw schema``: write the JSON Schema of design files (:func:`fsdvs_hw.design.sections.design_json_schema`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "write the JSON Schema of design files (units, ranges and meanings) for editors"
DESCRIPTION = (
    "Write the JSON Schema of a design file, built from the realisations registered now: every key\n"
    "with its type, range, default, unit and meaning. Point an editor's TOML support at it\n"
    "(e.g. a '#:schema ./design.schema.json' first line for Taplo / Even Better TOML).\n\n"
    "Examples:\n  fsdvs-hw schema --out design.schema.json\n  fsdvs-hw schema   (to stdout)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", type=Path, default=None, metavar="FILE", help="file to write (its folder is created; default: stdout)"
    )


def run(args: argparse.Namespace) -> int:
    import fsdvs_hw.realise  # noqa: F401  (registers the built-in realisations)

    from ..design import design_json_schema
    from ..paths import output_file, write_output

    out = None if args.out is None else output_file(args.out, flag="--out")  # checked before any work
    text = json.dumps(design_json_schema(), indent=2, ensure_ascii=False) + "\n"
    if out is None:
        sys.stdout.write(text)
    else:
        print(f"[schema] {write_output(out, text)}", file=sys.stderr)
    return 0
