"""Compare two exploration ``scores.json`` files field by field, timings aside.

A refactor must leave ``make demo``'s scores unchanged (issue 43): every field of every row and
point the same, except what measures the machine rather than the method — wall and fit times (keys
naming ``wall``, ``seconds``, ``fit_time``, and the rows' ``fit_s``, ``analysis_s``, ``tasks_s``,
``emulation_s``, ``point_s`` and the fit's ``cpu_time_s``), the fit time printed inside a
realisation's ``describe`` text, library versions, worker names and timestamps. Other keys ending in
``_s`` are results in SI units (``g_lateral_narrow_s`` siemens, ``event_rate_per_s``, ``mev_s``) and
are compared.
Strings are compared after removing a given checkout prefix (a run from another folder stores
absolute checkpoint paths).

Usage::

    python benchmarks/compare_scores.py designs/results/demo/scores.json out/demo/scores.json

prints the number of differences and the first 40, and exits 1 when there is any.

Examples
--------
>>> compare({"rows": [{"a": 1.0, "wall_s": 3.0}]}, {"rows": [{"a": 1.0, "wall_s": 4.0}]})
[]
>>> compare({"rows": [{"a": 1.0}]}, {"rows": [{"a": 2.0}]})
['.rows[0].a: 1.0 vs 2.0']
"""

from __future__ import annotations

import json
import math
import re
import sys
from typing import Any

__all__ = ["compare", "main"]

#: Key fragments of what measures the machine, not the method.
_MACHINE = ("wall", "seconds", "fit_time", "versions", "worker", "timestamp", "finished_at", "started_at")
#: Seconds spent, by exact key (a key ending in ``_s`` is otherwise a result: siemens, events/s).
_TIMINGS = frozenset({"fit_s", "analysis_s", "tasks_s", "emulation_s", "point_s", "cpu_time_s"})
#: Seconds printed inside a describe text ("after 56 iterations, 0.543 s", "fit 4.1 s").
_SECONDS = re.compile(r"\d+(?:\.\d+)? s\b")


def _machine(key: str) -> bool:
    return any(m in key for m in _MACHINE) or key in _TIMINGS


def compare(a: Any, b: Any, *, strip: str = "", path: str = "") -> list[str]:
    """Every difference between ``a`` and ``b`` (JSON values) as ``"path: a vs b"``, timings aside."""
    out: list[str] = []
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if _machine(str(k)):
                continue
            if k not in a or k not in b:
                out.append(f"{path}.{k}: only in {'the second' if k not in a else 'the first'}")
                continue
            out += compare(a[k], b[k], strip=strip, path=f"{path}.{k}")
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} vs {len(b)} items"]
        for i, (x, y) in enumerate(zip(a, b)):
            out += compare(x, y, strip=strip, path=f"{path}[{i}]")
    else:
        if isinstance(a, str) and isinstance(b, str):
            a, b = a.replace(strip, "") if strip else a, b.replace(strip, "") if strip else b
            if path.endswith(".describe"):
                a, b = _SECONDS.sub("<s>", a), _SECONDS.sub("<s>", b)
        same = a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))
        if not same:
            out.append(f"{path}: {str(a)[:80]} vs {str(b)[:80]}")
    return out


def main(argv: list[str] | None = None) -> int:
    """``compare_scores.py FIRST SECOND [CHECKOUT_PREFIX]``; exit status 1 when they differ."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (2, 3):
        print(__doc__.split("Usage::")[0].strip(), file=sys.stderr)
        return 2
    with open(args[0], encoding="utf-8") as f, open(args[1], encoding="utf-8") as g:
        diffs = compare(json.load(f), json.load(g), strip=args[2] if len(args) == 3 else "")
    print(f"{len(diffs)} differences (timings, versions and workers aside)")
    for d in diffs[:40]:
        print(" ", d)
    return 1 if diffs else 0


if __name__ == "__main__":
    raise SystemExit(main())
