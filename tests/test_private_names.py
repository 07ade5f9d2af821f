"""No module reaches into another module's private names.

A leading underscore says "this may change without notice"; a module that imports such a name
from another module couples itself to a detail its owner feels free to break. What another
module needs gets a public name in its home module. Every import in fsdvs_hw — at module level
and inside functions — is read with :mod:`ast` (no code runs) and checked:

- no imported name starts with ``_`` (``from .learn import _train_epochs``, ``from . import
  _native``), dunders aside;
- a private module (a path component starting with ``_``) is imported only from inside the
  package that holds it (``fsdvs_hw/__init__.py`` may use ``fsdvs_hw._lazy``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "fsdvs_hw"


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _package_of(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1])


def _resolve(path: Path, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = _package_of(path).split(".")
    base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
    return ".".join([*base, *([node.module] if node.module else [])])


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_imports(path: Path, text: str | None = None) -> list[str]:
    """Every import in ``path`` (or in ``text``, placed at ``path``) that takes a private name."""
    source_text = path.read_text(encoding="utf-8") if text is None else text
    tree = ast.parse(source_text, filename=str(path))
    package = _package_of(path)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            source = _resolve(path, node)
            for alias in node.names:
                if _private(alias.name):
                    found.append(f"line {node.lineno}: from {source} import {alias.name}")
            modules = [source]
        elif isinstance(node, ast.Import):
            modules = [a.name for a in node.names]
        else:
            continue
        for module in modules:
            parts = module.split(".")
            for i, part in enumerate(parts):
                holder = ".".join(parts[:i])
                if _private(part) and parts[0] == "fsdvs_hw" and not package.startswith(holder):
                    found.append(f"line {node.lineno}: {module} (private module of {holder})")
    return found


SOURCES = sorted(PACKAGE.rglob("*.py"))


def test_the_scan_sees_the_package() -> None:
    assert len(SOURCES) > 100


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_private_name_crosses_a_module(path: Path) -> None:
    assert private_imports(path) == [], f"{path.relative_to(PACKAGE.parent)} imports private names"


def test_the_check_catches_what_it_forbids() -> None:
    """The scan itself: each forbidden form is reported, the allowed ones are not."""
    text = (
        "from .events import _advance\n"  # 1: a private name
        "from . import _native\n"  # 2: a private module of this package, as a name
        "def f():\n    from ..tasks.learn import _train_epochs, train\n"  # 4: inside a function
        "import fsdvs_hw.tasks._hidden\n"  # 5: another package's private module
        "from .._lazy import lazy\n"  # 6: fsdvs_hw._lazy from fsdvs_hw.sensor: its holder is fsdvs_hw
        "from .events import __all__, advance\n"  # 7: allowed
    )
    found = private_imports(PACKAGE / "sensor" / "probe.py", text)
    assert sorted(f.split(":")[0] for f in found) == ["line 1", "line 2", "line 4", "line 5"]
