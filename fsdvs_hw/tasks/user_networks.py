"""User networks by import path, the event representation they read, and user weights.

A user network is a factory named ``"package.module:callable"`` that returns a
``torch.nn.Module``; :func:`load_network_factory` imports it, calls it with the keyword arguments
given, checks the result and reads the event representation the network declares in an
attribute ``event_input`` (default ``"frames"``):

``"frames"``
    ``(B, 2(T-1), H, W)``: ON/OFF counts per frame interval, ``log1p``-compressed
    (:func:`fsdvs_hw.tasks.networks.event_representation`, what the built-in networks read).
``"voxel:N"``
    ``(B, N, H, W)``: a signed voxel grid with ``N`` time bins (:func:`fsdvs_hw.sensor.voxel_grid`
    from the event frames, differentiable).

The network's output must be what the task's evaluator ``predict`` consumes (recognition:
logits ``(B, C)``; segmentation: logits ``(B, C, H, W)``; detection: the CenterNet dict
``heatmap`` / ``size`` / ``offset`` at stride 2). Without a user network the built-in ones
(:mod:`fsdvs_hw.tasks.networks`) are used: :func:`builtin_network`.
"""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError, one_line

__all__ = [
    "EventInput",
    "builtin_network",
    "event_input_of",
    "load_network_factory",
    "load_weights",
    "network_for",
]


@dataclass(frozen=True)
class EventInput:
    """The event representation a network reads.

    Attributes
    ----------
    kind : str
        ``"frames"`` or ``"voxel"``.
    n_bins : int or None
        Time bins of a voxel grid.

    Example
    -------
    >>> EventInput.parse("voxel:5").channels(n_frames=9)
    5
    """

    kind: str = "frames"
    n_bins: int | None = None

    @classmethod
    def parse(cls, spec: Any, where: str = "event_input") -> EventInput:
        """``"frames"`` / ``"voxel:N"`` (or an :class:`EventInput`) → :class:`EventInput`."""
        if isinstance(spec, EventInput):
            return spec
        if spec == "frames":
            return cls("frames")
        m = re.fullmatch(r"voxel:(\d{1,4})", spec) if isinstance(spec, str) else None
        if m and 1 <= int(m.group(1)) <= 1024:
            return cls("voxel", int(m.group(1)))
        raise InputError(f"{where}={one_line(spec)}; allowed: 'frames' or 'voxel:N' with N time bins in [1, 1024]")

    def channels(self, n_frames: int) -> int:
        """Input channels for clips of ``n_frames`` frames."""
        return 2 * (n_frames - 1) if self.kind == "frames" else int(self.n_bins or 0)

    def __call__(self, frames: Any, timestamps_s: Any = None) -> Any:
        """Event frames ``(B, T-1, 2, H, W)`` → the network input."""
        from .networks import event_representation

        if self.kind == "frames":
            return event_representation(frames)
        from ..sensor import voxel_grid

        return voxel_grid(frames, int(self.n_bins or 1), timestamps_s=timestamps_s, signed=True)


def event_input_of(network: Any) -> EventInput:
    """The :class:`EventInput` a network declares (attribute ``event_input``; default frames)."""
    return EventInput.parse(getattr(network, "event_input", "frames"), f"{type(network).__name__}.event_input")


def load_network_factory(spec: str, **kwargs: Any) -> Any:
    """Import ``"package.module:factory"``, call it with ``kwargs`` and return the ``nn.Module``.

    Parameters
    ----------
    spec : str
        ``"module.path:callable"`` (importable from ``sys.path``).
    **kwargs
        Passed to the factory (e.g. ``in_channels=16, num_classes=2``).

    Returns
    -------
    torch.nn.Module
        With ``event_input`` checked (:func:`event_input_of`).

    Raises
    ------
    InputError
        ``spec`` malformed, the module does not import, the name is missing or not callable, the
        factory raises, returns no ``nn.Module``, or declares a bad ``event_input``.

    Example
    -------
    >>> net = load_network_factory("mypkg.nets:tiny", in_channels=16, num_classes=2)   # doctest: +SKIP
    """
    from torch import nn

    if not isinstance(spec, str) or not re.fullmatch(r"[A-Za-z_][\w.]*:[A-Za-z_]\w*", spec):
        raise InputError(f"network factory {one_line(spec)}: allowed: 'package.module:callable'")
    mod_name, attr = spec.split(":")
    try:
        module = importlib.import_module(mod_name)
    except Exception as exc:  # any import failure is the user's module
        raise InputError(
            f"network factory {spec!r}: module {mod_name!r} does not import "
            f"({type(exc).__name__}: {one_line(str(exc), 120)})"
        ) from None
    factory = getattr(module, attr, None)
    if factory is None:
        raise InputError(f"network factory {spec!r}: module {mod_name!r} has no attribute {attr!r}")
    if not callable(factory):
        raise InputError(f"network factory {spec!r}: {attr!r} is a {type(factory).__name__}, not callable")
    try:
        net = factory(**kwargs)
    except Exception as exc:
        raise InputError(
            f"network factory {spec!r}: calling it with {sorted(kwargs)} raised "
            f"{type(exc).__name__}: {one_line(str(exc), 120)}"
        ) from None
    if not isinstance(net, nn.Module):
        raise InputError(f"network factory {spec!r} returned a {type(net).__name__}; allowed: a torch.nn.Module")
    event_input_of(net)
    return net


def load_weights(network: Any, path: str | Path, *, strict: bool = True) -> Any:
    """Load a ``.pt`` / ``.pth`` or ``.safetensors`` state dict into ``network``, shapes checked.

    A checkpoint this toolkit wrote (``fsdvs-hw learn``, a ``train`` table's ``STEM.safetensors``:
    :func:`fsdvs_hw.tasks.checkpoints.is_task_checkpoint`) loads too: its ``network.*`` tensors
    without the prefix; its ``kernel`` (the taps the network was trained with) is not a network
    parameter and is left out (``explore`` compares it with the design's kernel).

    Raises
    ------
    InputError
        Naming the file and the parameter: missing file, unknown suffix, unreadable file, a
        tensor whose shape differs from the network's, missing or unexpected keys (``strict``).

    Example
    -------
    >>> load_weights(net, "weights.safetensors")   # doctest: +SKIP
    """
    import torch

    from .checkpoints import is_task_checkpoint, load_checkpoint

    p = Path(path)
    if not p.is_file():
        raise InputError(f"weights file {str(p)!r} does not exist")
    try:
        if is_task_checkpoint(p):
            state = load_checkpoint(p)[1]
        elif p.suffix == ".safetensors":
            from safetensors.torch import load_file

            state = load_file(str(p))
        elif p.suffix in (".pt", ".pth"):
            state = torch.load(str(p), map_location="cpu", weights_only=True)
        else:
            raise InputError(f"weights file {str(p)!r}: suffix {p.suffix!r}; allowed: .pt, .pth, .safetensors")
    except InputError:
        raise
    except Exception as exc:
        raise InputError(
            f"weights file {str(p)!r} cannot be read ({type(exc).__name__}: {one_line(str(exc), 120)})"
        ) from None
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputError(f"weights file {str(p)!r}: not a state dict of tensors")
    own = network.state_dict()
    for k, v in state.items():
        if k in own and tuple(own[k].shape) != tuple(v.shape):
            raise InputError(
                f"weights file {str(p)!r}: parameter {k!r} has shape {tuple(v.shape)}, the network's "
                f"is {tuple(own[k].shape)}"
            )
    missing, unexpected = sorted(set(own) - set(state)), sorted(set(state) - set(own))
    if strict and (missing or unexpected):
        raise InputError(f"weights file {str(p)!r}: missing parameters {missing[:5]}, unexpected {unexpected[:5]}")
    network.load_state_dict(state, strict=strict)
    return network


def builtin_network(task: str, in_channels: int, num_classes: int, width: int = 12) -> Any:
    """The built-in network of ``task`` (frames input) for ``num_classes`` classes."""
    from .networks import CenterNetDetector, Classifier, Segmenter

    cls = {"detection": CenterNetDetector, "recognition": Classifier, "segmentation": Segmenter}.get(task)
    if cls is None:
        raise InputError(f"builtin_network: task {task!r}; allowed: detection, recognition, segmentation")
    return cls(in_channels, num_classes, width)


def network_for(network: Any, task: str, in_channels: int, num_classes: int) -> Any:
    """The network to train or score: the task's built-in one, a factory's, or the module given.

    Parameters
    ----------
    network : None, str or torch.nn.Module
        None: :func:`builtin_network`; ``"package.module:factory"``: :func:`load_network_factory`
        called with ``in_channels`` and ``num_classes``; a module is returned as it is.
    task : str
    in_channels : int
        Channels of the built-in representation, 2(T-1).
    num_classes : int

    Raises
    ------
    InputError
        Anything else (the message names ``evaluate_on_dataset``'s ``network=``).
    """
    from torch import nn

    if network is None:
        return builtin_network(task, in_channels, num_classes)
    if isinstance(network, str):
        return load_network_factory(network, in_channels=in_channels, num_classes=num_classes)
    if isinstance(network, nn.Module):
        return network
    raise InputError(
        f"evaluate_on_dataset: network={one_line(network)}; allowed: None (built-in), "
        "'package.module:factory', or a torch.nn.Module"
    )
