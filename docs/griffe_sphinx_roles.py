"""Griffe extension: Sphinx roles in fsdvs_hw's docstrings become mkdocstrings cross-references.

The docstrings are numpydoc with Sphinx roles (``:func:`evaluate_kernel```, ``:class:`~fsdvs_hw.kernels.Kernel```,
``:mod:`fsdvs_hw.stats```), which mkdocstrings does not read. Before rendering, each role is
replaced by an *optional* autorefs cross-reference, ``<autoref identifier="PATH" optional><code>TEXT</code></autoref>``:

* ``PATH`` is the name resolved in the docstring owner's scope (:meth:`griffe.Object.resolve`:
  its members, then its parents' — so ``:data:`BENCHMARKS``` in a module's docstring finds that
  module's ``BENCHMARKS``), or the name as written when it does not resolve;
* ``TEXT`` is the name as written, or its last component with Sphinx's ``~`` prefix;
* *optional*: a target that no API page renders (the standard library, a private helper) stays
  plain code instead of a broken link, so ``mkdocs build --strict`` does not fail on it.

Loaded by ``mkdocs.yml`` (``plugins: mkdocstrings: handlers: python: options: extensions``).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|exc|obj|const):`(~?)([^`<>]+?)(?:\s*<([^`>]+)>)?`")


def _resolve(obj: griffe.Object, name: str) -> str:
    name = name.strip().rstrip("()")
    if name.startswith("."):
        name = name.lstrip(".")
    head, _, rest = name.partition(".")
    try:
        base = obj.resolve(head)
    except Exception:  # noqa: BLE001 - any failure means: keep the name as written
        return name
    return f"{base}.{rest}" if rest else base


def convert(text: str, obj: griffe.Object) -> str:
    """``text`` with every Sphinx role replaced by an optional autorefs cross-reference."""

    def sub(m: re.Match) -> str:
        tilde, name, explicit = m.groups()
        target = explicit or name
        shown = name.strip() if explicit else (target.rsplit(".", 1)[-1] if tilde else target)
        path = _resolve(obj, target)
        return f'<autoref identifier="{path}" optional><code>{shown}</code></autoref>'

    return _ROLE.sub(sub, text)


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring of a loaded package."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        self._walk(pkg, set())

    def _walk(self, obj: griffe.Object, seen: set[str]) -> None:
        if obj.path in seen:
            return
        seen.add(obj.path)
        if obj.docstring is not None:
            obj.docstring.value = convert(obj.docstring.value, obj)
        for member in obj.members.values():
            if not member.is_alias:
                self._walk(member, seen)
