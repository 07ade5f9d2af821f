"""Buildable artifacts of a realisation: what a writer returns, and the index that lists them.

A hardware realisation declares a writer in its registry entry
(:attr:`fsdvs_hw.realise.registry.RealisationSpec.write_artifacts`, a ``"module:function"``
string): ``writer(record, out_dir, *, resolution) -> sequence of Artifact`` writes the files a
builder needs into ``out_dir`` (the SPICE deck of a mesh, the Verilog and testbench of an ASIC,
the phase profile of a metalens) and says, per file, what it is and how to check it with the real
tool. ``fsdvs-hw explore`` calls the writer of every scored hardware point and lists every file in
``OUT/artifacts/index.json`` (:func:`write_index`); the report links them.

Each realisation's check functions (``check_*_artifacts`` in its ``artifacts`` module) run that
tool on the written files and compare with what our model wrote beside them; the test suite calls
them (``tests/test_artifacts.py``).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..paths import write_output

__all__ = ["INDEX_VERSION", "Artifact", "read_index", "write_index"]

#: Version of the ``index.json`` layout written by :func:`write_index`.
INDEX_VERSION: int = 1


@dataclass(frozen=True)
class Artifact:
    """One written file.

    Parameters
    ----------
    name : str
        Its name in the realisation's declared :attr:`~fsdvs_hw.realise.registry.RealisationSpec.artifacts`.
    path : Path
        Where it was written.
    what : str
        A few words: what the file is (units where it holds numbers).
    checked_by : str
        How to check it: the tool's command line (run in the file's folder) and what it must print
        or match; empty for a file that is the check's data (e.g. expected vectors).
    """

    name: str
    path: Path
    what: str
    checked_by: str = ""

    def entry(self, root: Path, **extra: Any) -> dict[str, Any]:
        """The index entry: ``name, file`` (relative to ``root``, POSIX), ``what, checked_by`` and ``extra``."""
        try:
            rel = Path(self.path).resolve().relative_to(Path(root).resolve()).as_posix()
        except ValueError:
            raise InputError(f"artifact {self.name!r}: {self.path} is not under {root}") from None
        return {**extra, "name": self.name, "file": rel, "what": self.what, "checked_by": self.checked_by}


def write_index(entries: Iterable[Mapping[str, Any]], path: str | Path) -> Path:
    """Write ``index.json``: ``{"version", "artifacts": [entry, ...]}``; return its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_output(
        path,
        json.dumps({"version": INDEX_VERSION, "artifacts": [dict(e) for e in entries]}, indent=1) + "\n",
        flag="artifacts",
    )
    return path


def read_index(path: str | Path) -> list[dict[str, Any]]:
    """The entries of an ``index.json`` written by :func:`write_index`.

    Raises
    ------
    InputError
        Not a file, not JSON, or not this layout.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise InputError(f"{path}: cannot read the artifact index ({type(exc).__name__})") from None
    if not (
        isinstance(data, dict) and data.get("version") == INDEX_VERSION and isinstance(data.get("artifacts"), list)
    ):
        raise InputError(
            f"{path}: not an artifact index of version {INDEX_VERSION} ({{'version': 1, 'artifacts': [...]}})"
        )
    return [dict(e) for e in data["artifacts"] if isinstance(e, dict)]
