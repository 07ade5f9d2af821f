"""From a verb's parsed flags to the typed options object of the library function it calls."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from typing import Any, TypeVar

__all__ = ["command_line", "options_from_args"]

T = TypeVar("T")


def command_line(verb: str) -> str:
    """The command as typed, ``fsdvs-hw VERB ARGS...``, recorded in a study's outputs.

    Parameters
    ----------
    verb : str
        The verb's name (``ablation``, ``rate``, ...).

    Returns
    -------
    str
        ``fsdvs-hw VERB`` and the words after the verb on the command line, space-separated.
    """
    return f"fsdvs-hw {verb} " + " ".join(sys.argv[2:]) if len(sys.argv) > 2 else f"fsdvs-hw {verb}"


def options_from_args(cls: type[T], args: argparse.Namespace, **given: Any) -> T:
    """The options dataclass ``cls`` of the parsed flags ``args``, field by field.

    A field takes, in this order: its value in ``given`` (the flags named or typed otherwise than
    the field); for ``progress``, False under ``--no-progress``, else None (bars when stderr is a
    terminal); for ``command``, :func:`command_line` of the verb; else the flag of the field's
    name, a list (``nargs``) as a tuple. A field with no such flag keeps its default.

    Parameters
    ----------
    cls : type
        A dataclass of options (e.g. :class:`~fsdvs_hw.studies.rate_study.RateOptions`).
    args : argparse.Namespace
        The verb's parsed flags (``args.command`` is the verb's name).
    **given : Any
        Field values set explicitly.

    Returns
    -------
    T
        ``cls(**fields)``: its own checks run as when written field by field.
    """
    values: dict[str, Any] = {}
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        name = field.name
        if name in given or not field.init:
            continue
        if name == "progress":
            values[name] = False if args.no_progress else None
        elif name == "command":
            values[name] = command_line(args.command)
        elif hasattr(args, name):
            value = getattr(args, name)
            values[name] = tuple(value) if isinstance(value, list) else value
    return cls(**values, **given)
