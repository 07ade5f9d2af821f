"""No function in fsdvs_hw grows past 100 lines, docstring included.

A function that long does several things; its parts want names (and their own tests). Each
``def`` in the package is read with :mod:`ast` (no code runs) and measured from its ``def`` line
to its last line, docstring and nested functions included. ``ALLOWED`` names the exceptions
with their reason; it is empty.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "fsdvs_hw"
MAX_LINES = 100

#: ``"path/relative/to/fsdvs_hw.py:function"`` → why it may be longer.
ALLOWED: dict[str, str] = {}


def long_functions(text: str, where: str) -> dict[str, int]:
    """``{"where:name": lines}`` for every function in ``text`` longer than ``MAX_LINES``."""
    found = {}
    for node in ast.walk(ast.parse(text, filename=where)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            n = (node.end_lineno or node.lineno) - node.lineno + 1
            if n > MAX_LINES:
                found[f"{where}:{node.name}"] = n
    return found


def test_no_function_is_longer_than_100_lines() -> None:
    sources = sorted(PACKAGE.rglob("*.py"))
    assert len(sources) > 100
    found: dict[str, int] = {}
    for path in sources:
        found |= long_functions(path.read_text(encoding="utf-8"), str(path.relative_to(PACKAGE)))
    assert {k: v for k, v in found.items() if k not in ALLOWED} == {}


def test_the_measure_counts_docstring_and_body() -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(97))
    exactly = f'def f():\n    """Doc."""\n{body}\n    return x0\n'  # 100 lines
    assert long_functions(exactly, "m.py") == {}
    longer = exactly.replace('"""Doc."""', '"""Doc.\n\n    More.\n    """')  # 103 lines
    assert long_functions(longer, "m.py") == {"m.py:f": 103}
