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
    "--init-kernel designs/kernels/learned_detection_7x7.json --realisation asic --out out/codesign/asic_det\n"
    "Your data (the design's [tasks.datasets.TASK] with a train table; files at its train.out; resumes):\n"
    "  fsdvs-hw learn recognition --design my_design.toml"
)

#: Options of the synthetic-data run (refused with --design: the design's train table sets them).
_SYNTHETIC_ONLY = (
    "size",
    "seed",
    "n_train",
    "n_test",
    "epochs_frozen",
    "epochs_joint",
    "lr_filter",
    "out",
    "realisation",
    "init_kernel",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("task", help="task name: detection, recognition, segmentation")
    parser.add_argument(
        "--size", type=int_in(1, MAX_KERNEL_SIZE), default=None, help="odd kernel size in pixels (default 7; 1 = w/o)"
    )
    parser.add_argument(
        "--seed", type=int_in(0, MAX_SEED), default=None, help=f"training seed, 0..{MAX_SEED} (default 0)"
    )
    parser.add_argument("--n-train", type=int_in(1, MAX_CLIPS), default=None, help="training clips (default 2048)")
    parser.add_argument("--n-test", type=int_in(1, MAX_CLIPS), default=None, help="test clips (default 2048)")
    parser.add_argument(
        "--epochs-frozen", type=int_in(0, MAX_EPOCHS), default=None, help="frozen-filter epochs (staged tasks)"
    )
    parser.add_argument("--epochs-joint", type=int_in(0, MAX_EPOCHS), default=None, help="joint epochs")
    parser.add_argument("--lr-filter", type=float, default=None, help="filter learning rate")
    parser.add_argument("--out", type=Path, default=None, help="file stem for kernel/checkpoint/provenance")
    parser.add_argument(
        "--realisation",
        default=None,
        metavar="NAME",
        help="co-design: fit this realisation (mesh, asic, metalens) to --init-kernel, then train "
        "the network and the realisation's own parameters together",
    )
    parser.add_argument(
        "--init-kernel",
        type=Path,
        default=None,
        metavar="FILE",
        help="kernel file to start from (with --realisation: the kernel it is first fitted to)",
    )
    parser.add_argument(
        "--design",
        type=Path,
        default=None,
        metavar="FILE",
        help="train on the user data of this design's [tasks.datasets.TASK] (its train table sets "
        "the protocol; the kernel and network go to train.out); the options above are refused",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="with --design: replace one design key for this run, keys inside a dataset table "
        "included (--set tasks.datasets.recognition.dataset.root='/data/UCF-101' --set "
        "tasks.datasets.recognition.train.epochs_joint=10); repeatable",
    )


def _run_on_design(args: argparse.Namespace) -> int:
    """``--design``: train the user-data task's network and kernel (:func:`fsdvs_hw.explore.user_data.train_user_task`)."""
    from ..design import load_design
    from ..design.user_data_inputs import open_dataset
    from ..errors import InputError
    from ..explore.trained_kernel import write_pending_kernel
    from ..explore.user_data import train_user_task
    from ..tasks.dataset_eval import evaluate_sampled

    given = [f"--{k.replace('_', '-')}" for k in _SYNTHETIC_ONLY if getattr(args, k) is not None]
    if given:
        raise InputError(
            f"{' '.join(given)} with --design: the design's [tasks.datasets.{args.task}] train table "
            "sets the protocol and train.out the files; allowed: no other option with --design"
        )
    design = load_design(args.design)
    if args.overrides:
        from .explore import parse_overrides

        design = design.with_overrides(parse_overrides(args.overrides))
    user = design.spec.tasks.datasets
    if args.task not in user:
        raise InputError(
            f"--design {args.design}: no [tasks.datasets.{args.task}] table; allowed tasks: {', '.join(user) or 'none'}"
        )
    entry = user[args.task].model_dump()
    res = train_user_task(args.task, entry, design.base_dir, confine=design.confine_paths, verbose=True)
    design_kernel = write_pending_kernel(design, args.task, res.kernel)  # [kernel] path named before it existed
    ds = open_dataset(
        entry["dataset"], design.base_dir, confine=design.confine_paths, key=f"tasks.datasets.{args.task}.dataset"
    )
    scored = evaluate_sampled(  # several clips per video with a sampling table, scored per video
        res.kernel,
        args.task,
        ds,
        res.network,
        sampling=entry.get("sampling"),
        n_clips=entry["n_clips"] or None,
        seed=entry["seed"],
        device=entry["device"],
    )
    print(
        json.dumps(
            {
                "task": args.task,
                "size": res.kernel.size,
                "n_train": len(res.train_indices),
                "n_scored": len(scored.clip_indices),
                "epochs_trained_now": res.epochs_trained,
                "metrics": scored.metrics,
                "files": {
                    **{k: str(v) for k, v in res.paths.items()},
                    **({"design_kernel": str(design_kernel)} if design_kernel else {}),
                },
            },
            indent=1,
        )
    )
    return 0


def run(args: argparse.Namespace) -> int:
    import torch

    from ..paths import output_file
    from ..tasks.learn import TrainingSettings, learn_kernel

    if args.design is not None:
        return _run_on_design(args)
    if args.overrides:
        from ..errors import InputError

        raise InputError("--set without --design: it replaces keys of a design; allowed: --set with --design FILE")
    defaults = {"size": 7, "seed": 0, "n_train": 2048, "n_test": 2048}
    for k, v in defaults.items():
        if getattr(args, k) is None:
            setattr(args, k, v)

    if args.out is not None:  # checked before training: STEM.json etc. must be writable
        output_file(Path(str(args.out) + ".json"), flag="--out")
    torch.set_num_threads(1)
    kw = {
        k: v
        for k, v in (
            ("epochs_frozen", args.epochs_frozen),
            ("epochs_joint", args.epochs_joint),
            ("lr_filter", args.lr_filter),
        )
        if v is not None
    }
    res = learn_kernel(
        args.task,
        args.size,
        seed=args.seed,
        n_train=args.n_train,
        n_test=args.n_test,
        settings=TrainingSettings(**kw),
        out=args.out,
        verbose=True,
        init_kernel=args.init_kernel,
        realisation=args.realisation,
    )
    print(
        json.dumps(
            {
                "task": args.task,
                "size": args.size,
                "metrics": res.metrics,
                "files": {k: str(v) for k, v in res.paths.items()},
            },
            indent=1,
        )
    )
    return 0
