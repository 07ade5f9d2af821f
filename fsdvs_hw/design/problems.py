"""A design file's problems: collected as one line each and raised together as one :class:`DesignError`."""

from __future__ import annotations

from typing import Any

from ..errors import InputError
from ..schema import short

__all__ = ["DesignError", "DesignProblems"]


class DesignError(InputError):
    """A design file is invalid; the message names the file, key, value and what is allowed."""


class DesignProblems:
    """Collects problems as ``key '<key>' = <value>: <why; what is allowed>`` lines for one file."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.problems: list[str] = []

    def add(self, key: str, value: Any, message: str) -> None:
        self.problems.append(f"key '{key}' = {short(value)}: {message}")

    def raise_if_any(self) -> None:
        if self.problems:
            n = len(self.problems)
            head = f"{self.source}: invalid design file ({n} problem{'s' if n > 1 else ''})"
            raise DesignError(head + ":\n  " + "\n  ".join(self.problems))
