"""``fsdvs-hw information``: MI and bits per event over :func:`fsdvs_hw.studies.information.run_information_study`."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..limits import MAX_CLIPS
from ._execution import int_in
from ._options import options_from_args
from .rate import contrast_threshold

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = (
    "mutual information (bits/pixel) between ground truth and a reconstruction from events, and bits per "
    "event, for w/o, the learned kernel and its realisations, with 95 % CIs; resumable"
)
DESCRIPTION = (
    "Train a small reconstruction network (events -> intensity) per kernel condition (w/o = 1x1 delta,\n"
    "the design's learned kernel, each realisation, and w/o with its threshold lowered to the learned\n"
    "kernel's event rate), and measure the mutual information between reconstruction and noise-free\n"
    "ground truth (equal-mass joint histogram, Miller-Madow corrected) and the bits per event, with\n"
    "bootstrap CIs over networks x clips. Networks and scored conditions are saved under OUT, so a\n"
    "rerun resumes.\n\n"
    "Example:\n  fsdvs-hw information designs/default.toml --networks 3 --n-train 512 --n-test 64 --out out/info\n"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..studies.information import DEFAULT_RATE_THRESHOLDS

    parser.add_argument("design", type=Path, help="TOML design file, or a shipped design's name (default)")
    parser.add_argument("--networks", type=int_in(2, 1000), default=3, help="reconstruction networks per condition")
    parser.add_argument("--n-train", type=int_in(2, MAX_CLIPS), default=512, help="training clips per network")
    parser.add_argument("--n-test", type=int_in(2, MAX_CLIPS), default=64, help="test clips (shared by all networks)")
    parser.add_argument("--epochs", type=int_in(1, 10_000), default=16, help="training epochs per network")
    parser.add_argument("--width", type=int_in(4, 256), default=16, help="network width (channels)")
    parser.add_argument(
        "--realisations",
        nargs="*",
        default=["mesh", "asic", "metalens"],
        help="realisations to add (fitted with the design's options)",
    )
    parser.add_argument(
        "--no-matched-rate", action="store_true", help="leave out w/o retrained at the learned kernel's event rate"
    )
    parser.add_argument(
        "--rate-thresholds",
        nargs="+",
        type=contrast_threshold,
        default=list(DEFAULT_RATE_THRESHOLDS),
        help="ON=OFF thresholds (log units) along which the w/o rate is measured for the match",
    )
    parser.add_argument("--bins", type=int_in(2, 4096), default=32, help="equal-mass bins per axis of the MI estimator")
    parser.add_argument("--n-resamples", type=int_in(100, 1_000_000), default=2000, help="bootstrap resamples per CI")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out") / "info",
        help="folder: networks/, evidence/, kernels/, information.json/.csv",
    )


def run(args: argparse.Namespace) -> int:
    import torch

    from ..studies.information import InformationOptions, run_information_study

    # one thread: on a shared machine PyTorch's second thread spins (measured ~10x the CPU time)
    torch.set_num_threads(1)
    study = run_information_study(
        options_from_args(
            InformationOptions,
            args,
            n_networks=args.networks,
            matched_rate=not args.no_matched_rate,
            n_bins=args.bins,
        )
    )
    print(study.text)
    for path in study.files.values():
        print(f"wrote {path}")
    return 0
