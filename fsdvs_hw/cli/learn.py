"""``fsdvs-hw learn``: learn one FS-DVS kernel end to end and save kernel + checkpoint + provenance."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..kernels import MAX_KERNEL_SIZE
from ..limits import MAX_CLIPS, MAX_EPOCHS, MAX_SEED
from ._execution import int_in

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "learn a k×k FS-DVS kernel end to end on a task (detection, recognition, segmentation)"
DESCRIPTION = (
    "Learn a spatial kernel through the differentiable event simulator with the FS-DVS protocol\n"
    "(delta + noise start; frozen filter, then joint with the paper's decoupled learning-rate\n"
    "ratios). Writes STEM.json (kernel), STEM.safetensors (network + kernel) and\n"
    "STEM.provenance.json.\n\n"
    "Example (the shipped kernel): fsdvs-hw learn detection --size 7 --seed 0 "
    "--out out/kernels/learned_detection_7x7\n"
    "Co-design (the kernel is a realisation's at every step): fsdvs-hw learn detection "
    "--init-kernel designs/kernels/learned_detection_7x7.json --realisation asic --out out/codesign/asic_det"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("task", help="task name: detection, recognition, segmentation")
    parser.add_argument(
        "--size", type=int_in(1, MAX_KERNEL_SIZE), default=7, help="odd kernel size in pixels (default 7; 1 = w/o)"
    )
    parser.add_argument("--seed", type=int_in(0, MAX_SEED), default=0, help=f"training seed, 0..{MAX_SEED} (default 0)")
    parser.add_argument("--n-train", type=int_in(1, MAX_CLIPS), default=2048, help="training clips (default 2048)")
    parser.add_argument("--n-test", type=int_in(1, MAX_CLIPS), default=2048, help="test clips (default 2048)")
    parser.add_argument(
        "--epochs-frozen", type=int_in(0, MAX_EPOCHS), default=None, help="frozen-filter epochs (staged tasks)"
    )
    parser.add_argument("--epochs-joint", type=int_in(0, MAX_EPOCHS), default=None, help="joint epochs")
    parser.add_argument("--lr-filter", type=float, default=None, help="filter learning rate")
    parser.add_argument("--out", type=Path, default=None, help="file stem for kernel/checkpoint/provenance")
    parser.add_argument("--realisation", default=None, metavar="NAME",
                        help="co-design: fit this realisation (mesh, asic, metalens) to --init-kernel, then train "
                             "the network and the realisation's own parameters together")
    parser.add_argument("--init-kernel", type=Path, default=None, metavar="FILE",
                        help="kernel file to start from (with --realisation: the kernel it is first fitted to)")


def run(args: argparse.Namespace) -> int:
    import torch

    from ..paths import output_file
    from ..tasks.learn import TrainingSettings, learn_kernel

    if args.out is not None:  # checked before training: STEM.json etc. must be writable
        output_file(Path(str(args.out) + ".json"), flag="--out")
    torch.set_num_threads(1)
    kw = {k: v for k, v in (("epochs_frozen", args.epochs_frozen), ("epochs_joint", args.epochs_joint),
                            ("lr_filter", args.lr_filter)) if v is not None}
    res = learn_kernel(args.task, args.size, seed=args.seed, n_train=args.n_train, n_test=args.n_test,
                       settings=TrainingSettings(**kw), out=args.out, verbose=True,
                       init_kernel=args.init_kernel, realisation=args.realisation)
    print(json.dumps({"task": args.task, "size": args.size, "metrics": res.metrics,
                      "files": {k: str(v) for k, v in res.paths.items()}}, indent=1))
    return 0
