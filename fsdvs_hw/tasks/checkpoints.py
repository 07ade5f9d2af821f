"""Task checkpoints on disk: the finished run's files, and the partial state a resumed run continues from.

Checkpoint files (written next to each other from one stem, e.g. ``designs/kernels/learned_detection_7x7``):

``STEM.json``
    The kernel (:class:`~fsdvs_hw.kernels.Kernel` JSON) with the provenance inside.
``STEM.safetensors``
    Network weights (``network.*``) and the kernel taps (``kernel``); metadata ``format``
    (:data:`CHECKPOINT_FORMAT`), ``version`` (:data:`CHECKPOINT_VERSION`) and ``provenance`` (JSON,
    with ``kernel_fingerprint``: :func:`kernel_fingerprint` of the taps the network was trained with).
    It loads as a user table's ``weights`` too (:func:`is_task_checkpoint`, the ``network.`` prefix
    stripped and the kernel set aside).
``STEM.provenance.json``
    The provenance, with ``checkpoint`` and ``kernel_file`` (the two files' names).
``STEM.partial.pt``
    While :func:`~fsdvs_hw.tasks.dataset_training.train_on_dataset` trains: the state after the
    last finished epoch (network, kernel, optimiser, batch-order generator, history, position,
    fingerprint), written atomically (:func:`save_partial`, :func:`load_partial`).
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..fingerprints import text_fingerprint
from ..kernels import Kernel

__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_VERSION",
    "check_fingerprint",
    "checkpoint_paths",
    "checkpoint_stem",
    "is_task_checkpoint",
    "kernel_fingerprint",
    "load_checkpoint",
    "load_partial",
    "save_checkpoint",
    "save_partial",
]

CHECKPOINT_FORMAT = "fsdvs_hw.task_checkpoint"
#: The checkpoint layout version this library writes and reads.
CHECKPOINT_VERSION = "1"


def checkpoint_stem(out: str | Path) -> Path:
    """The file stem of a checkpoint path (``.json`` / ``.safetensors`` suffix dropped)."""
    p = Path(out)
    return p.with_suffix("") if p.suffix in (".json", ".safetensors") else p


def checkpoint_paths(stem: Path) -> dict[str, Path]:
    """``kernel``, ``checkpoint`` and ``provenance`` file paths of a checkpoint stem."""
    return {
        "kernel": Path(str(stem) + ".json"),
        "checkpoint": Path(str(stem) + ".safetensors"),
        "provenance": Path(str(stem) + ".provenance.json"),
    }


def kernel_fingerprint(taps: Any) -> str:
    """SHA-1 (hex) of a kernel's taps as float64 and their shape: equal exactly when the taps are equal.

    What a checkpoint stores as ``provenance["kernel_fingerprint"]`` and what ``explore`` compares
    with the design's kernel (the pitch and the name are left out: they do not change what the
    network sees).

    Examples
    --------
    >>> kernel_fingerprint(np.eye(3)) == kernel_fingerprint(np.eye(3).tolist())
    True
    >>> kernel_fingerprint(np.eye(3)) == kernel_fingerprint(np.eye(3) * 1.0000001)
    False
    """
    a = np.ascontiguousarray(np.asarray(taps, dtype=np.float64))
    return text_fingerprint(repr(a.shape).encode() + a.tobytes())


def is_task_checkpoint(path: str | Path) -> bool:
    """Whether ``path`` is a ``.safetensors`` checkpoint this toolkit wrote (metadata ``format``).

    Examples
    --------
    >>> is_task_checkpoint("designs/kernels/learned_detection_7x7.safetensors")   # doctest: +SKIP
    True
    """
    p = Path(path)
    if p.suffix != ".safetensors" or not p.is_file():
        return False
    try:
        from safetensors import safe_open

        with safe_open(str(p), framework="pt") as f:
            return (f.metadata() or {}).get("format") == CHECKPOINT_FORMAT
    except Exception:  # not readable: not ours (the weights loader names the problem)
        return False


def save_checkpoint(stem: Path, kernel: Kernel, network: Any, provenance: dict[str, Any]) -> dict[str, Path]:
    """Write ``STEM.safetensors``, ``STEM.json`` and ``STEM.provenance.json``; their paths.

    Parameters
    ----------
    stem : Path
        File stem (a ``.json`` / ``.safetensors`` suffix is dropped); parent folders are made.
    kernel : Kernel
        The kernel (its taps go into the checkpoint too).
    network : torch.nn.Module
        Its state dict is stored as ``network.*``.
    provenance : dict
        JSON-able record of the run; ``kernel_fingerprint`` (:func:`kernel_fingerprint` of
        ``kernel``) is added.

    Returns
    -------
    dict of str to Path
        ``kernel``, ``checkpoint``, ``provenance``.
    """
    import torch
    from safetensors.torch import save

    from ..paths import write_output

    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = checkpoint_paths(checkpoint_stem(stem))
    provenance = {**provenance, "kernel_fingerprint": kernel_fingerprint(kernel.taps)}
    tensors = {f"network.{k}": v.detach().contiguous() for k, v in network.state_dict().items()}
    tensors["kernel"] = torch.as_tensor(np.array(kernel.taps))
    ckpt = paths["checkpoint"]
    write_output(
        ckpt,
        save(
            tensors,
            metadata={
                "format": CHECKPOINT_FORMAT,
                "version": CHECKPOINT_VERSION,
                "provenance": json.dumps(provenance),
            },
        ),
        flag=str(ckpt),
    )
    kpath = kernel.save(paths["kernel"])
    ppath = paths["provenance"]
    write_output(
        ppath,
        json.dumps({**provenance, "checkpoint": ckpt.name, "kernel_file": kpath.name}, indent=1) + "\n",
        flag=str(ppath),
    )
    return {"kernel": kpath, "checkpoint": ckpt, "provenance": ppath}


def load_checkpoint(checkpoint: str | Path) -> tuple[dict[str, Any], dict[str, Any], Kernel]:
    """Read a task checkpoint: ``(provenance, network state dict, training kernel)``.

    ``checkpoint`` may be the ``.safetensors`` file or its stem (``STEM.json`` alongside is
    accepted too). Raises :class:`InputError` naming the file for a missing, unreadable or
    foreign file.
    """
    from safetensors import safe_open

    path = checkpoint_paths(checkpoint_stem(checkpoint))["checkpoint"]
    if not path.is_file():
        raise InputError(f"checkpoint {str(path)!r} not found (expected a .safetensors file written by learn_kernel)")
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
            tensors = {k: f.get_tensor(k) for k in f.keys()}  # noqa: SIM118 - safe_open is not a dict
    except Exception as exc:  # safetensors raises its own error types for corrupt headers
        raise InputError(f"checkpoint {str(path)!r}: not a readable safetensors file ({exc})") from None
    if meta.get("format") != CHECKPOINT_FORMAT:
        raise InputError(
            f"checkpoint {str(path)!r}: metadata 'format' is not {CHECKPOINT_FORMAT!r}: not a "
            "checkpoint written by fsdvs_hw learn"
        )
    if meta.get("version") != CHECKPOINT_VERSION:
        raise InputError(
            f"checkpoint {str(path)!r}: version {str(meta.get('version'))[:12]!r} not supported "
            f"(this library reads version {CHECKPOINT_VERSION})"
        )
    try:
        provenance = json.loads(meta["provenance"])
    except (KeyError, json.JSONDecodeError, RecursionError) as exc:
        raise InputError(f"checkpoint {str(path)!r}: metadata 'provenance' missing or not JSON ({exc})") from None
    if not isinstance(provenance, dict):
        raise InputError(f"checkpoint {str(path)!r}: metadata 'provenance' is not a JSON object")
    if "kernel" not in tensors:
        raise InputError(f"checkpoint {str(path)!r}: tensor 'kernel' missing")
    state = {k[len("network.") :]: v for k, v in tensors.items() if k.startswith("network.")}
    kernel = Kernel(
        tensors["kernel"].double().numpy(),
        name=f"training kernel of {path.name}",
        provenance={k: v for k, v in provenance.items() if k != "history"},
    )
    return provenance, state, kernel


def check_fingerprint(stored: Any, wanted: dict[str, Any] | None, path: Path) -> None:
    """Refuse a checkpoint or partial file at ``path`` whose stored fingerprint is not ``wanted``.

    ``wanted`` None accepts any; it is compared after the JSON round trip the stored one went
    through. Raises :class:`InputError` naming the differing keys.
    """
    if wanted is None:
        return
    wanted = json.loads(json.dumps(wanted))  # the JSON round trip the stored one went through
    if stored != wanted:
        stored = stored if isinstance(stored, dict) else {}
        diff = sorted(k for k in set(stored) | set(wanted) if stored.get(k) != wanted.get(k))
        raise InputError(
            f"{path}: trained with other settings (differing: {', '.join(diff) or 'all'}); allowed: "
            "the same data, network and train settings, or another train.out (delete the file to "
            "retrain)"
        )


def save_partial(
    path: Path,
    net: Any,
    kernel_param: Any,
    gen: Any,
    opt: Any,
    history: list[dict[str, Any]],
    position: tuple[int, int],
    fingerprint: Any,
) -> None:
    """The state after a finished epoch, written atomically to ``path`` (``STEM.partial.pt``).

    Parameters
    ----------
    path : Path
    net : torch.nn.Module
    kernel_param : torch.Tensor or torch.nn.Module
        The kernel's taps, or the realisation module whose state dict is stored.
    gen : torch.Generator
        The batch-order generator (its state).
    opt : torch.optim.Optimizer
        The stage's optimiser (its state dict).
    history : list of dict
    position : (int, int)
        (stage index, next epoch).
    fingerprint : JSON-able
    """
    import torch

    from ..paths import write_output

    buf = io.BytesIO()
    kernel = (
        {k: v.cpu() for k, v in kernel_param.state_dict().items()}
        if isinstance(kernel_param, torch.nn.Module)
        else kernel_param.detach().cpu()
    )
    torch.save(
        {
            "network": {k: v.cpu() for k, v in net.state_dict().items()},
            "kernel": kernel,
            "generator": gen.get_state(),
            "optimizer": opt.state_dict(),
            "history": json.dumps(history),
            "stage": position[0],
            "epoch": position[1],
            "fingerprint": json.dumps(fingerprint),
        },
        buf,
    )
    write_output(path, buf.getvalue(), flag=str(path))


def load_partial(
    partial: Path | None, fingerprint: Any, net: Any, kernel_param: Any, gen: Any
) -> tuple[list[dict[str, Any]], tuple[int, int], Any]:
    """Load ``STEM.partial.pt`` into the network, kernel and generator.

    Returns
    -------
    (history, (stage index, next epoch), optimizer state dict)
        ``([], (0, 0), None)`` without a partial file.

    Raises
    ------
    InputError
        The partial file was written with another fingerprint.
    """
    if partial is None or not partial.is_file():
        return [], (0, 0), None
    import torch

    state = torch.load(str(partial), map_location="cpu", weights_only=True)
    check_fingerprint(json.loads(state["fingerprint"]), fingerprint, partial)
    net.load_state_dict(state["network"])
    if isinstance(kernel_param, torch.nn.Module):  # a realisation's parameters
        kernel_param.load_state_dict(state["kernel"])
    else:
        with torch.no_grad():
            kernel_param.copy_(state["kernel"].to(kernel_param.device))
    gen.set_state(state["generator"])
    return json.loads(state["history"]), (int(state["stage"]), int(state["epoch"])), state["optimizer"]
