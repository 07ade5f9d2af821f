"""The Examples sections of the public names (``fsdvs_hw.__all__``) run as doctests.

Each public name's docstring examples run in the repository folder (they read ``designs/``), with
``ELLIPSIS`` and ``NORMALIZE_WHITESPACE``; an example whose printed value changes fails here. The
names without an Examples section yet would be listed in :data:`WITHOUT_EXAMPLES`: it is empty, and
the expensive calls (a metalens fit, a training run, an exploration) run with small arguments.
"""

from __future__ import annotations

import doctest
import inspect
import os
from pathlib import Path

import pytest

import fsdvs_hw

REPO = Path(__file__).resolve().parents[1]

#: Public names whose docstring has no Examples section yet: none (the list may only shrink).
WITHOUT_EXAMPLES: set[str] = set()

PUBLIC = sorted(n for n in fsdvs_hw.__all__ if n != "__version__")


def _tests(name: str) -> list[doctest.DocTest]:
    obj = getattr(fsdvs_hw, name)
    finder = doctest.DocTestFinder(recurse=False)
    # globals: the defining module's (as ``--doctest-modules`` gives), so older examples may use its names
    return [t for t in finder.find(obj, name, module=inspect.getmodule(obj)) if t.examples]


def test_every_public_name_has_examples_except_the_listed_ones():
    without = {n for n in PUBLIC if "Examples\n" not in (inspect.getdoc(getattr(fsdvs_hw, n)) or "")}
    assert without == WITHOUT_EXAMPLES


@pytest.mark.parametrize("name", [n for n in PUBLIC if n not in WITHOUT_EXAMPLES])
def test_public_examples_run(name: str, monkeypatch):
    monkeypatch.chdir(REPO)
    monkeypatch.setenv("MPLBACKEND", os.environ.get("MPLBACKEND", "Agg"))
    tests = _tests(name)
    assert tests, f"{name}: no doctest examples found"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report: list[str] = []
    failed = sum(runner.run(test, out=report.append).failed for test in tests)
    assert failed == 0, "".join(report)
