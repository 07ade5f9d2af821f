"""The kernel a user network was trained with, and the design's kernel: written, chained, compared.

A network trained through the simulator learns *with* one kernel in front of it (its events are
that kernel's), so scoring realisations of another kernel in it measures the wrong thing. This
module chains the toolkit's own results:

* :func:`trained_kernel` — the kernel a ``[tasks.datasets.<task>]`` network was trained with: the
  checkpoint its ``train`` table wrote (``train.out``), or the ``weights`` when they are a
  checkpoint of this toolkit (:func:`fsdvs_hw.tasks.checkpoints.is_task_checkpoint`); None for
  the user's own weights (nothing recorded to compare with).
* :func:`write_pending_kernel` — after training, the learned kernel written to the design's
  ``[kernel] path`` when that file did not exist yet (:attr:`fsdvs_hw.design.Design.pending_kernel_task`).
* :func:`settle_design_kernel` — what ``explore`` runs after training and before scoring: the
  pending kernel written and the design re-read, then every table's trained kernel compared with
  the design's by :func:`fsdvs_hw.tasks.checkpoints.kernel_fingerprint`; a mismatch is refused
  with the fix.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..design import Design
from ..design.design_paths import resolve_design_path
from ..design.user_data_inputs import learned_kernel_path
from ..errors import InputError

__all__ = ["settle_design_kernel", "trained_kernel", "write_pending_kernel"]


def trained_kernel(design: Design, task: str) -> tuple[Any, Path] | None:
    """``(kernel, checkpoint file)`` a table's network was trained with, or None where none is recorded.

    A table with a ``train`` table: the checkpoint at ``train.out`` (None while it is not trained).
    Otherwise: its ``weights`` when they are a checkpoint this toolkit wrote.

    Examples
    --------
    >>> kernel, path = trained_kernel(design, "recognition")   # doctest: +SKIP
    >>> path.name                                               # doctest: +SKIP
    'recognition.safetensors'
    """
    from ..tasks.checkpoints import checkpoint_paths, checkpoint_stem, is_task_checkpoint, load_checkpoint

    entry = design.spec.tasks.datasets[task].model_dump()
    confine = design.confine_paths
    if entry["train"] is not None:
        ckpt = checkpoint_paths(checkpoint_stem(learned_kernel_path(task, entry, design.base_dir, confine=confine)))
        path = ckpt["checkpoint"]
    elif entry["weights"]:
        key = f"tasks.datasets.{task}.weights"
        path = resolve_design_path(design.base_dir, entry["weights"], what=key, confine=confine)
    else:
        return None
    if not is_task_checkpoint(path):
        return None
    return load_checkpoint(path)[2], path


def write_pending_kernel(design: Design, task: str, kernel: Any) -> Path | None:
    """Write ``kernel`` (learned by ``task``'s training) to the design's ``[kernel] path`` if it is pending.

    Returns the file written, or None (the design's kernel file exists, or another task writes
    it). The file that ``train.out`` names is written by the training itself.

    Examples
    --------
    >>> write_pending_kernel(design, "recognition", result.kernel)   # doctest: +SKIP
    PosixPath('.../kernels/mine.json')
    """
    if design.pending_kernel_task != task:
        return None
    path = Path(str(design.target.provenance["path"]))
    if path.is_file():  # the training's own STEM.json, or written meanwhile
        return None
    kernel.save(path)
    return path


def _mismatch(design: Design, task: str, trained: Any, ckpt: Path) -> str:
    from ..tasks.checkpoints import checkpoint_paths, checkpoint_stem, kernel_fingerprint

    k = design.spec.kernel
    mine = f"[kernel] path = {k.path!r}" if k.source == "file" else f"[kernel] source = 'reference' ({k.family})"
    learned = checkpoint_paths(checkpoint_stem(ckpt))["kernel"]
    try:
        fix = repr(learned.relative_to(design.base_dir.resolve()).as_posix())
    except ValueError:
        fix = repr(str(learned))
    return (
        f"{design.source}: {mine} ({design.target.size}x{design.target.size}, fingerprint "
        f"{kernel_fingerprint(design.target.taps)[:12]}) is not the kernel tasks.datasets.{task}'s network was "
        f"trained with ({ckpt.name}: {trained.size}x{trained.size}, fingerprint "
        f"{kernel_fingerprint(trained.taps)[:12]}): explore would score realisations of one kernel in a "
        f"network trained with another. Fix: set [kernel] source = 'file' and path = {fix} (the kernel "
        "learn wrote with the network), or delete the kernel file to have learn write it there, or "
        "score a network trained with this kernel"
    )


def settle_design_kernel(design: Design) -> Design:
    """The design ready to score its user networks: pending kernel written, re-read, and checked.

    Run after every ``train`` table has trained (``explore`` does it before its workers start).

    Returns
    -------
    Design
        ``design``, or the design re-read when its ``[kernel] path`` was pending.

    Raises
    ------
    InputError
        The kernel is still pending (its table did not train), or a table's network was trained
        with another kernel than the design's: naming both files, their fingerprints and the fix.

    Examples
    --------
    >>> design = settle_design_kernel(design)   # doctest: +SKIP
    """
    from ..tasks.checkpoints import kernel_fingerprint

    task = design.pending_kernel_task
    if task is not None:
        found = trained_kernel(design, task)
        if found is None:
            raise InputError(
                f"{design.source}: [kernel] path {design.target.provenance['path']!r} does not exist and "
                f"tasks.datasets.{task} has not trained yet; run `fsdvs-hw learn {task} --design ...` first"
            )
        write_pending_kernel(design, task, found[0])
        design = design.reloaded()
    for name in design.spec.tasks.datasets:
        got = trained_kernel(design, name)
        if got is not None and kernel_fingerprint(got[0].taps) != kernel_fingerprint(design.target.taps):
            raise InputError(_mismatch(design, name, *got))
    return design
