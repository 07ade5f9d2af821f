"""Exceptions raised by fsdvs_hw.

Every error a user can cause by bad input is an :class:`InputError` (a ``ValueError``) whose
message names the problem: the file or argument, the field, the value and what is allowed.
"""

from __future__ import annotations

from typing import Any

__all__ = ["FsdvsError", "InputError", "KernelError", "ToolMissingError", "one_line"]


class FsdvsError(Exception):
    """Base class of all fsdvs_hw errors."""


class InputError(FsdvsError, ValueError):
    """Bad user input (argument, file, design field); the message says what and what is allowed.

    Examples
    --------
    >>> from fsdvs_hw import InputError, fit_asic_taps, reference_kernel
    >>> try:
    ...     fit_asic_taps(reference_kernel("dog", 5), bits=1)
    ... except InputError as e:
    ...     print(e)
    key 'bits' = 1: out of range; allowed: an integer in [2, 24] bit (signed tap width including the sign)
    """


class KernelError(InputError):
    """A kernel's taps or metadata are invalid (shape, size, values, file format).

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw import Kernel, KernelError
    >>> try:
    ...     Kernel(np.ones((2, 2)))
    ... except KernelError as e:
    ...     print(e)
    taps: kernel size must be odd (so it has a centre tap), got 2x2
    """


class ToolMissingError(FsdvsError, RuntimeError):
    """An external program (ngspice, iverilog, yosys) is not installed; the message says how to get it."""


def one_line(value: Any, limit: int = 60) -> str:
    """``repr(value)`` on one line (numpy arrays print on several), cut to ``limit`` characters.

    Example
    -------
    >>> import numpy as np
    >>> one_line(np.array([["a", "b"], ["c", "d"]]))
    "array([['a', 'b'], ['c', 'd']], dtype='<U1')"
    """
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."
