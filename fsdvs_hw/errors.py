"""Exceptions raised by fsdvs_hw.

Every error a user can cause by bad input is an :class:`InputError` (a ``ValueError``) whose
message names the problem: the file or argument, the field, the value and what is allowed.
"""

from __future__ import annotations

__all__ = ["FsdvsError", "InputError", "KernelError", "ToolMissingError"]


class FsdvsError(Exception):
    """Base class of all fsdvs_hw errors."""


class InputError(FsdvsError, ValueError):
    """Bad user input (argument, file, design field); the message says what and what is allowed."""


class KernelError(InputError):
    """A kernel's taps or metadata are invalid (shape, size, values, file format)."""


class ToolMissingError(FsdvsError, RuntimeError):
    """An external program (ngspice, iverilog, yosys) is not installed; the message says how to get it."""
