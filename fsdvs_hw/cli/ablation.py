"""``fsdvs-hw ablation``: the kernel-size ablation over :func:`fsdvs_hw.studies.kernel_size_ablation.run_ablation_study`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..kernels import MAX_KERNEL_SIZE
from ..limits import MAX_CLIPS, MAX_EPOCHS, MAX_SEED, MAX_WORKERS
from ._execution import int_in, scheduler_address
from ._options import options_from_args

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "kernel-size ablation (w/o, 3, 5, 7, 9) on detection and recognition, gains with 95 % CIs; resumable"
DESCRIPTION = (
    "Train one network per (task, kernel size, seed) with the FS-DVS protocol on the sweep executor\n"
    "(local processes or Dask; SQLite store; a rerun resumes) and print the paper-style tables: mean\n"
    "± std over seeds, the gain over w/o with a 95 % CI (bootstrap over the paired test clips and the\n"
    "seeds), the learned kernels' shape, and the transfer of the 7x7 detection kernel to segmentation.\n\n"
    "Example (the README table):\n"
    "  fsdvs-hw ablation --seeds 0 1 2 --workers 2 --transfer from-run --out out/ablation\n"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tasks", nargs="+", default=["detection", "recognition"], help="tasks (default: both)")
    parser.add_argument(
        "--sizes",
        nargs="+",
        type=int_in(1, MAX_KERNEL_SIZE),
        default=[1, 3, 5, 7, 9],
        help="odd kernel sizes; 1 = w/o (default 1 3 5 7 9)",
    )
    parser.add_argument(
        "--seeds",
        nargs="+",
        type=int_in(0, MAX_SEED),
        default=[0, 1, 2],
        help=f"training seeds, each 0..{MAX_SEED} (default 0 1 2)",
    )
    parser.add_argument("--n-train", type=int_in(1, MAX_CLIPS), default=None, help="training clips (default 2048)")
    parser.add_argument("--n-test", type=int_in(1, MAX_CLIPS), default=None, help="test clips (default 2048)")
    parser.add_argument(
        "--epochs-frozen", type=int_in(0, MAX_EPOCHS), default=None, help="frozen-filter epochs (default 16)"
    )
    parser.add_argument("--epochs-joint", type=int_in(0, MAX_EPOCHS), default=None, help="joint epochs (default 16)")
    parser.add_argument(
        "--workers",
        type=int_in(1, MAX_WORKERS),
        default=1,
        help=f"local worker processes, 1..{MAX_WORKERS} (default 1)",
    )
    parser.add_argument(
        "--scheduler",
        type=scheduler_address,
        default=None,
        metavar="tcp://HOST:PORT",
        help="run on a Dask distributed scheduler instead of local processes",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument(
        "--transfer",
        default=None,
        metavar="KERNEL",
        help="also run the segmentation transfer with this kernel file, or 'from-run' for the "
        "7x7 detection kernel of the first seed learned here",
    )
    parser.add_argument(
        "--frozen-tasks",
        nargs="*",
        default=[],
        metavar="TASK",
        help="with --transfer: also train these tasks' networks with that kernel frozen (e.g. detection recognition)",
    )
    parser.add_argument("--transfer-only", action="store_true", help="skip the size ablation (needs a kernel file)")
    parser.add_argument(
        "--frozen-only",
        action="store_true",
        help="with --transfer KERNEL_FILE: train only the frozen-kernel networks of --frozen-tasks "
        "(segmentation allowed), seed by seed, so any prefix of the seeds is complete for every "
        "task (how the exploration's networks are made)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out") / "ablation",
        help="folder: store (runs.sqlite), predictions/, ablation.md, ablation.json (default out/ablation)",
    )
    parser.add_argument(
        "--ship-dir",
        type=Path,
        default=None,
        help="save the 7x7 learned kernels (every seed) as learned_{task}_7x7[_sSEED].* and the "
        "frozen-kernel networks as networks/{task}_with_KERNEL_sSEED.* here, e.g. out/shipped; copy them "
        "into designs/kernels to ship them (default: not saved)",
    )
    parser.add_argument("--from-store", action="store_true", help="do not train: rebuild the tables from the store")
    parser.add_argument(
        "--design",
        type=Path,
        default=None,
        metavar="FILE",
        help="ablate on the user data of this design's [tasks.datasets.TASK] (with a train table; "
        "one --tasks entry): one network per --sizes x --seeds (--workers local processes), gains "
        "over w/o with paired-clip CIs; the synthetic-only options are refused",
    )


#: Options of the synthetic ablation (refused with --design, which sets clips and epochs in its train table).
_SYNTHETIC_ONLY: dict[str, Any] = {
    "n_train": None,
    "n_test": None,
    "epochs_frozen": None,
    "epochs_joint": None,
    "scheduler": None,
    "transfer": None,
    "frozen_tasks": [],
    "transfer_only": False,
    "frozen_only": False,
    "ship_dir": None,
    "from_store": False,
}


def _run_on_design(args: argparse.Namespace) -> int:
    from ..design import load_design
    from ..errors import InputError
    from ..studies.user_kernel_size_ablation import run_user_ablation

    given = [f"--{k.replace('_', '-')}" for k, v in _SYNTHETIC_ONLY.items() if getattr(args, k) != v]
    if given:
        raise InputError(
            f"{' '.join(given)} with --design: not supported on user data (the design's train table "
            "sets clips and epochs; runs use local processes, not Dask); allowed with --design: "
            "--tasks TASK, --sizes, --seeds, --workers, --out"
        )
    if len(args.tasks) != 1:
        raise InputError(f"--tasks {' '.join(args.tasks)} with --design: allowed: exactly one user-data task")
    res = run_user_ablation(
        load_design(args.design),
        args.tasks[0],
        args.out,
        sizes=args.sizes,
        seeds=args.seeds,
        verbose=not args.no_progress,
        workers=args.workers,
    )
    print(res["markdown"])
    return 0


def run(args: argparse.Namespace) -> int:
    from ..studies.kernel_size_ablation import AblationOptions, run_ablation_study

    if args.design is not None:
        return _run_on_design(args)

    options = options_from_args(AblationOptions, args)
    study = run_ablation_study(options)
    print(study.markdown)
    return 0
