"""A design file's problems: collected as one line each and raised together as one :class:`DesignError`."""

from __future__ import annotations

from typing import Any

from ..errors import InputError
from ..schema import short

__all__ = ["DesignError", "DesignProblems"]


class DesignError(InputError):
    """A design file is invalid; the message names the file, key, value and what is allowed.

    Examples
    --------
    >>> from fsdvs_hw import DesignError, parse_design
    >>> try:
    ...     parse_design({"sensor": {"pitch_m": -1}}, source="demo.toml")
    ... except DesignError as exc:
    ...     print(exc)
    demo.toml: invalid design file (1 problem):
      key 'sensor.pitch_m' = -1: out of range; allowed: a number in [1e-07, 0.001] m (pixel pitch in metres)
    """


class DesignProblems:
    """Collects problems as ``key '<key>' = <value>: <why; what is allowed>`` lines for one file.

    Parameters
    ----------
    source : str
        Where the design came from (file path or ``"<design>"``), the head of the message.

    Examples
    --------
    >>> chk = DesignProblems("demo.toml")
    >>> chk.add("sensor.pitch_m", -1, "allowed: 1e-07 to 0.001")
    >>> chk.problems
    ["key 'sensor.pitch_m' = -1: allowed: 1e-07 to 0.001"]
    """

    def __init__(self, source: str) -> None:
        self.source = source
        self.problems: list[str] = []

    def add(self, key: str, value: Any, message: str) -> None:
        """Add one problem: the dotted ``key``, the ``value`` given (shortened) and what is wrong and allowed."""
        self.problems.append(f"key '{key}' = {short(value)}: {message}")

    def raise_if_any(self) -> None:
        """Raise every problem collected as one :class:`DesignError` (nothing when there is none)."""
        if self.problems:
            n = len(self.problems)
            head = f"{self.source}: invalid design file ({n} problem{'s' if n > 1 else ''})"
            raise DesignError(head + ":\n  " + "\n  ".join(self.problems))
