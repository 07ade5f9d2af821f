"""Benchmark records: one typed row per measured value, the one timing helper, JSON and Markdown views.

Every ``fsdvs-hw bench NAME`` returns a :class:`BenchRun`: its Markdown section (the tables quoted in
the README) and a list of :class:`BenchRecord` — one per numeric cell of those tables, with the
metric's unit, the repeats and spread of a timing, the torch threads, the machine, the library
versions and the bench settings — written as JSON by :func:`write_json` (``--json PATH``).
:func:`timed` is the timing helper every bench uses (wall clock, :func:`time.perf_counter`);
:func:`kept_torch_threads` restores torch's thread count after a bench that changes it.

This module is core layer: it imports nothing from the rest of the package except
:mod:`fsdvs_hw.errors`, and torch only if some caller already imported it.
"""

from __future__ import annotations

import json
import os
import platform
import re
import statistics
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Generic, TypeVar

__all__ = [
    "BenchRecord",
    "BenchRun",
    "Timing",
    "timed",
    "kept_torch_threads",
    "machine_info",
    "library_versions",
    "records_from_markdown",
    "records_markdown",
    "write_json",
    "read_json",
    "RECORD_SCHEMA",
]

#: Version of the JSON layout written by :func:`write_json`.
RECORD_SCHEMA = "fsdvs_hw.bench/1"

T = TypeVar("T")


@dataclass(frozen=True)
class BenchRecord:
    """One measured value of one benchmark.

    Attributes
    ----------
    bench : str
        Benchmark name (``csf``, ``mesh``, ...).
    table : str
        Title of the table (section heading) the value belongs to.
    case : str
        What was measured: the row label of the table (and its other text cells, ``k=v``).
    metric : str
        What the value is (the column header without its unit).
    unit : str
        Unit of ``value`` (``s``, ``µs``, ``MiB``, ``%``, ``""`` for a dimensionless number).
    value : float
        The measured value.
    repeats : int or None
        How many runs a timing is summarised over (None: not a timing, or not recorded).
    spread_min, spread_max : float or None
        Smallest and largest of the ``repeats`` runs, in ``unit`` (None when not recorded).
    threads : int or None
        torch intra-op threads when the bench ran (None: torch not used).
    machine : dict
        :func:`machine_info`: CPU count, platform, processor, load average.
    versions : dict
        :func:`library_versions`: python, numpy, torch, fsdvs_hw.
    settings : dict
        The bench's settings (``quick``, problem sizes).
    timestamp : str
        ISO 8601 UTC time the bench finished.
    """

    bench: str
    table: str
    case: str
    metric: str
    unit: str
    value: float
    repeats: int | None = None
    spread_min: float | None = None
    spread_max: float | None = None
    threads: int | None = None
    machine: dict[str, Any] = field(default_factory=dict)
    versions: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    timestamp: str = ""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (the fields, in order)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> BenchRecord:
        """The record of :meth:`to_dict`'s output (unknown keys refused)."""
        return cls(**dict(data))


@dataclass(frozen=True)
class BenchRun:
    """What one benchmark returns: its Markdown section and its records."""

    name: str
    markdown: str
    records: tuple[BenchRecord, ...] = ()


@dataclass(frozen=True)
class Timing(Generic[T]):
    """Wall-clock times of ``repeats`` calls of one function (seconds) and its last result."""

    times_s: tuple[float, ...]
    result: T

    @property
    def repeats(self) -> int:
        return len(self.times_s)

    @property
    def best_s(self) -> float:
        """Fastest run (s): the least disturbed by other load on a shared machine."""
        return min(self.times_s)

    @property
    def median_s(self) -> float:
        return statistics.median(self.times_s)

    @property
    def worst_s(self) -> float:
        return max(self.times_s)


def timed(fn: Callable[[], T], repeats: int = 1) -> Timing[T]:
    """Call ``fn`` ``repeats`` times and time each call with :func:`time.perf_counter`.

    Parameters
    ----------
    fn : callable
        No-argument function; its last result is kept.
    repeats : int
        Number of calls, >= 1.

    Returns
    -------
    Timing
        ``times_s`` (s, one per call) and ``result``; ``best_s``, ``median_s``, ``worst_s``.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return Timing(tuple(times), out)


@contextmanager
def kept_torch_threads() -> Iterator[None]:
    """Restore torch's intra-op thread count on exit (a bench may set 1 thread for its timings)."""
    torch = sys.modules.get("torch")
    if torch is None:
        import torch
    threads = torch.get_num_threads()
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def machine_info() -> dict[str, Any]:
    """CPU count, platform, processor and 1-minute load average of this machine."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {"cpu_count": os.cpu_count(), "platform": platform.platform(), "processor": platform.machine(),
            "load_average_1min": load}


def library_versions() -> dict[str, str | None]:
    """Versions of python, numpy, torch (if importable) and fsdvs_hw."""
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in ("numpy", "torch", "fsdvs_hw"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out


_UNIT = re.compile(r"^(?P<metric>.*?)\s*\((?P<unit>[^()]*)\)\s*$")
_NUMBER = re.compile(r"^[<>≤≥~≈]?\s*(?P<num>[-+−]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(?P<unit>%|[a-zA-Zµ/]+)?$")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


_SPREAD = re.compile(r"^(?P<value>.*?)\s*\[(?P<low>[^–\]]+)[–-](?P<high>[^\]]+)\]\s*$")


def _number(text: str) -> tuple[float, str, float | None, float | None] | None:
    """``(value, unit, low, high)`` of a cell ``"1.2e-3"``, ``"12 %"`` or ``"0.31 [0.29–0.35]"``."""
    text = text.replace("**", "").replace("`", "").strip()
    low = high = None
    spread = _SPREAD.match(text)
    if spread is not None:
        lo, hi = _number(spread["low"]), _number(spread["high"])
        if lo is None or hi is None:
            return None
        text, low, high = spread["value"], lo[0], hi[0]
    m = _NUMBER.match(text)
    if m is None:
        return None
    return float(m["num"].replace("−", "-")), m["unit"] or "", low, high


def records_from_markdown(bench: str, markdown: str, *, settings: Mapping[str, Any] | None = None,
                          threads: int | None = None,
                          timings: Mapping[tuple[str, str], Timing[Any]] | None = None) -> list[BenchRecord]:
    """One :class:`BenchRecord` per numeric cell of the Markdown tables of a bench section.

    The table title is the nearest heading (``#`` or a bold line) above the table; the case is the row's
    first cell plus its other non-numeric cells (``header=value``); the metric is the column
    header, its unit the header's parenthesised suffix (``wall (s)``) or the cell's own suffix
    (``12 %``); a cell ``"0.31 [0.29–0.35]"`` is a value with its min–max spread. Cells that are
    not a single number are context, not records.

    Parameters
    ----------
    timings : mapping, optional
        ``(case, metric) -> Timing`` for cells that are timings: their records carry repeats and
        the min/max spread (in the column's unit, converted from seconds for ``ms`` and ``µs``).
    """
    machine, versions, stamp = machine_info(), library_versions(), datetime.now(timezone.utc).isoformat()
    scale = {"s": 1.0, "ms": 1e3, "µs": 1e6, "us": 1e6, "min": 1 / 60}
    records: list[BenchRecord] = []
    lines = markdown.splitlines()
    title = bench
    i = 0
    while i < len(lines):
        line = lines[i].strip()
        is_table = line.startswith("|") and i + 1 < len(lines) and re.match(r"^\|\s*:?-{3,}", lines[i + 1].strip())
        if not is_table:
            if line.startswith(("#", "**")):  # a heading names the tables below it
                title = line.lstrip("#* ").rstrip("*: ") or title
            i += 1
            continue
        header = _cells(line)
        i += 2
        while i < len(lines) and lines[i].strip().startswith("|"):
            cells = _cells(lines[i])
            i += 1
            if not cells:
                continue
            values, context = [], [cells[0]]
            for head, cell in zip(header[1:], cells[1:]):
                num = _number(cell)
                if num is None:
                    if cell and cell not in ("—", "-", "n/a"):
                        context.append(f"{head}={cell}")
                else:
                    values.append((head, num))
            case = "; ".join(context)
            for head, (value, cell_unit, low, high) in values:
                m = _UNIT.match(re.sub(r"\s*\[[^\]]*\]\s*$", "", head))
                metric, unit = (m["metric"], m["unit"]) if m else (head, "")
                unit = unit or cell_unit
                t = (timings or {}).get((cells[0], metric))
                factor = scale.get(unit, 1.0)
                records.append(BenchRecord(
                    bench=bench, table=title, case=case, metric=metric, unit=unit, value=value,
                    repeats=t.repeats if t else None, spread_min=t.best_s * factor if t else low,
                    spread_max=t.worst_s * factor if t else high, threads=threads, machine=machine,
                    versions=versions, settings=dict(settings or {}), timestamp=stamp))
    return records


def records_markdown(records: Sequence[BenchRecord]) -> str:
    """A compact Markdown view of records: one table per (bench, table), one row per record."""
    out: list[str] = []
    key = None
    for r in records:
        if (r.bench, r.table) != key:
            key = (r.bench, r.table)
            out += ["", f"**{r.bench}: {r.table}**", "", "| case | metric | value | unit | repeats | min | max |",
                    "|---|---|---|---|---|---|---|"]
        spread = ("—", "—") if r.spread_min is None else (f"{r.spread_min:.4g}", f"{r.spread_max:.4g}")
        out.append(f"| {r.case} | {r.metric} | {r.value:.6g} | {r.unit} | {r.repeats or '—'} | {spread[0]} | {spread[1]} |")
    return "\n".join(out).strip() + "\n"


def write_json(records: Sequence[BenchRecord], path: str | Path) -> Path:
    """Write records as ``{"schema": RECORD_SCHEMA, "records": [...]}`` (UTF-8, indented)."""
    p = Path(path)
    p.write_text(json.dumps({"schema": RECORD_SCHEMA, "records": [r.to_dict() for r in records]},
                            indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return p


def read_json(path: str | Path) -> list[BenchRecord]:
    """The records of a file written by :func:`write_json`."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    if data.get("schema") != RECORD_SCHEMA:
        from .errors import InputError

        raise InputError(f"{path}: schema {data.get('schema')!r}, expected {RECORD_SCHEMA!r}")
    return [BenchRecord.from_dict(r) for r in data["records"]]
