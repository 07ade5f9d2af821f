"""One way to export names lazily (so ``import fsdvs_hw`` does not import torch or casadi).

A package lists ``name -> defining module`` once and gets its ``__getattr__`` and ``__dir__``
from :func:`lazy_exports`; the same names are imported under ``typing.TYPE_CHECKING`` in the
package, so IDEs and type checkers see every export (PEP 562 for the runtime half).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, names: Mapping[str, str], namespace: dict[str, Any], extra: tuple[str, ...] = ()
) -> tuple[list[str], Callable[[str], Any], Callable[[], list[str]]]:
    """``(__all__, __getattr__, __dir__)`` for a package whose public names load on first use.

    Parameters
    ----------
    package : str
        The package's dotted name (for the AttributeError message).
    names : mapping
        Public name → dotted module that defines it.
    namespace : dict
        The package's ``globals()``: a loaded name is cached there.
    extra : tuple of str
        Names defined in the package itself, listed first in ``__all__``.
    """
    exported = [*extra, *names]

    def __getattr__(name: str) -> Any:
        module = names.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(exported)

    return exported, __getattr__, __dir__
