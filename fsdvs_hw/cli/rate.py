"""``fsdvs-hw rate``: bandwidth-matched comparison over :func:`fsdvs_hw.studies.rate_study.run_rate_study`."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..limits import MAX_CLIPS
from ._execution import int_in
from ._options import options_from_args

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = (
    "event rate vs threshold for w/o and the learned kernel; task gain at matched event rate with 95 % CIs; resumable"
)
DESCRIPTION = (
    "Sweep the ON/OFF contrast threshold for the plain DVS (w/o) and the design's learned kernel (and\n"
    "optionally its realisations) in the design's fixed trained networks, record event rate and task\n"
    "metric per threshold with bootstrap CIs over networks x clips, and compare the kernels at equal\n"
    "event rate (interpolation in log rate; extrapolation refused). Each finished point is saved in\n"
    "OUT/points, so a rerun resumes.\n\n"
    "Example:\n  fsdvs-hw rate designs/default.toml --task detection --networks 8 --n-test 32 --out out/rate\n"
)


def contrast_threshold(text: str) -> float:
    """argparse ``type`` of an ON = OFF contrast threshold flag (log units, allowed 1e-4 to 10)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 1e-4 <= v <= 10.0:
        raise argparse.ArgumentTypeError(f"{text!r}: allowed 1e-4..10 log units")
    return v


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..explore.rate import DEFAULT_THRESHOLDS

    parser.add_argument("design", type=Path, help="TOML design file, or a shipped design's name (default)")
    parser.add_argument("--task", default="detection", help="task of the design's checkpoints")
    parser.add_argument(
        "--thresholds",
        nargs="+",
        type=contrast_threshold,
        default=list(DEFAULT_THRESHOLDS),
        help="ON=OFF contrast thresholds, log units (the design's threshold is added)",
    )
    parser.add_argument(
        "--networks", type=int_in(1, 10_000), default=None, help="use the first N networks of the task (default: all)"
    )
    parser.add_argument(
        "--n-test",
        type=int_in(2, MAX_CLIPS),
        default=None,
        help="test clips per network (default: the design's tasks.n_test)",
    )
    parser.add_argument(
        "--realisations", nargs="*", default=[], help="also curve these realisations (mesh asic metalens)"
    )
    parser.add_argument(
        "--protocol",
        choices=["fixed", "retrained"],
        default="fixed",
        help="fixed: every kernel zero-shot in the design's networks; retrained: networks trained per "
        "kernel, threshold and seed (w/o and learned; minutes per network)",
    )
    parser.add_argument(
        "--seeds",
        type=int_in(1, 1000),
        default=3,
        help="retrained protocol: networks (training seeds 0..N-1) per kernel and threshold",
    )
    parser.add_argument(
        "--n-train", type=int_in(2, MAX_CLIPS), default=2048, help="retrained protocol: training clips per network"
    )
    parser.add_argument(
        "--zero-shot",
        action="store_true",
        help="retrained protocol: also swap the learned kernel into the w/o networks, threshold swept",
    )
    parser.add_argument(
        "--illuminance-lux",
        type=float,
        default=None,
        help="fixed protocol: photon shot noise of the scene at this sensor-plane illuminance (lx, at "
        "full scale), and noise_budget.json (which noise fires the events at each threshold)",
    )
    parser.add_argument(
        "--quantum-efficiency", type=float, default=0.5, help="photoelectrons per photon for --illuminance-lux"
    )
    parser.add_argument(
        "--resolution",
        nargs=2,
        type=int_in(1, 100_000),
        default=[720, 1280],
        metavar=("H", "W"),
        help="sensor size for the Mev/s column",
    )
    parser.add_argument("--n-resamples", type=int_in(100, 1_000_000), default=2000, help="bootstrap resamples per CI")
    parser.add_argument(
        "--interpolation-sensitivity",
        action="store_true",
        help="also write interpolation_sensitivity.json/.csv: every comparison with the curve read linearly, "
        "by pchip and quadratically in log rate (same resamples; on a finished --out folder it reuses points/)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out") / "rate",
        help="folder: points/, rate_curves.json/.csv, matched_rate.json",
    )


def run(args: argparse.Namespace) -> int:
    from ..studies.rate_study import RateOptions, run_rate_study

    study = run_rate_study(
        options_from_args(
            RateOptions,
            args,
            n_networks=args.networks,
            seeds=tuple(range(args.seeds)),
            resolution_px=(args.resolution[0], args.resolution[1]),
        )
    )
    print(study.text)
    for _name, path in study.files.items():
        print(f"wrote {path}")
    return 0
