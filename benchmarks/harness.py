"""Benchmark records: one typed row per measured value, the one timing helper, JSON and Markdown views.

Every ``fsdvs-hw bench NAME`` returns a :class:`BenchRun`: its Markdown section (the tables quoted in
the README) and a list of :class:`BenchRecord` — one per number printed in those tables, with the
metric's unit, the repeats and spread of a timing, the torch threads, the machine, the library
versions and the bench settings — written as JSON by :func:`write_json` (``--json PATH``).

A bench measures into records first and renders its Markdown from them: :class:`BenchSection`
holds the section's text and :class:`Table` s of :class:`Column` s (text columns name the case,
value columns carry a metric, a unit and a print format); each value cell — a number, a
:class:`Measured` (value, repeats, spread) or a :class:`Timing` — is printed and recorded at once,
so the Markdown can show nothing the records do not hold.
:func:`timed` is the timing helper every bench uses (wall clock, :func:`time.perf_counter`);
:func:`kept_global_state` restores what a bench may change process-wide (torch threads, default
dtype and random state, numpy's error and random state, warnings filters, environment variables).

This module is core layer: it imports nothing from the rest of the package except
:mod:`fsdvs_hw.errors`; torch only inside :func:`kept_global_state`.
"""

from __future__ import annotations

import json
import math
import os
import platform
import re
import statistics
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Generic, TypeVar

from fsdvs_hw.provenance import library_versions

__all__ = [
    "RECORD_SCHEMA",
    "BenchRecord",
    "BenchRun",
    "BenchSection",
    "Column",
    "Measured",
    "Table",
    "Timing",
    "kept_global_state",
    "library_versions",
    "machine_info",
    "read_json",
    "records_markdown",
    "timed",
    "write_json",
]

#: Version of the JSON layout written by :func:`write_json`.
RECORD_SCHEMA = "fsdvs_hw.bench/1"  # unchanged since the move out of the package: records stay readable

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
        :func:`fsdvs_hw.provenance.library_versions`: python and every numerical dependency (IPOPT included).
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

    def measured(self, unit: str = "s", summary: str = "median") -> Measured:
        """The timing as a :class:`Measured` in ``unit`` (s, ms, µs, min): ``summary`` (best,
        median, mean, worst) of the runs, their count and min–max."""
        return Measured.of(self.times_s, summary).scaled(_time_scale(unit))


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

    Raises
    ------
    InputError
        ``repeats`` is not an integer >= 1.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        from fsdvs_hw.errors import InputError

        raise InputError(f"timed: repeats must be an integer >= 1, got {repeats!r}")
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return Timing(tuple(times), out)


@contextmanager
def kept_global_state() -> Iterator[None]:
    """Restore, on exit, the process-wide state a benchmark may change (also a function decorator).

    torch (imported here if installed): intra-op threads, default dtype and the CPU random state;
    numpy: the floating-point error state and the global random state; the :mod:`warnings` filters;
    the environment variables (a sweep executor sets its workers' thread count there). torch's inter-op thread count
    cannot be set back once parallel work ran, so no bench may change it (a test checks).
    """
    import warnings

    import numpy as np

    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        torch = None
    torch_state = None if torch is None else (torch.get_num_threads(), torch.get_default_dtype(), torch.get_rng_state())
    np_err, np_random = np.geterr(), np.random.get_state()
    environ = dict(os.environ)
    try:
        with warnings.catch_warnings():
            yield
    finally:
        np.seterr(**np_err)
        np.random.set_state(np_random)
        for key in set(os.environ) - set(environ):
            del os.environ[key]
        os.environ.update({k: v for k, v in environ.items() if os.environ.get(k) != v})
        if torch is not None and torch_state is not None:
            threads, dtype, rng = torch_state
            torch.set_num_threads(threads)
            torch.set_default_dtype(dtype)
            torch.set_rng_state(rng)


def machine_info() -> dict[str, Any]:
    """CPU count, platform, processor and 1-minute load average of this machine."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "processor": platform.machine(),
        "load_average_1min": load,
    }


#: Seconds to each time unit a timing cell may be shown in.
_TIME_SCALE = {"s": 1.0, "ms": 1e3, "µs": 1e6, "us": 1e6, "min": 1 / 60}
#: The statistic a :class:`Measured` summarises its samples with.
_SUMMARIES: dict[str, Callable[[Sequence[float]], float]] = {
    "best": min,
    "min": min,
    "median": statistics.median,
    "mean": statistics.fmean,
    "worst": max,
    "max": max,
}
#: Units a header's parenthesised suffix may name (``"time (ms)"``); other suffixes need ``unit=``.
_HEADER_UNITS = frozenset({*_TIME_SCALE, "MB", "MiB", "GB", "%", "µm²", "µm", "mm", "px", "bit", "Mpixel-frames/s"})
_UNIT_SUFFIX = re.compile(r"^(?P<metric>.*?)\s*\((?P<unit>[^()]*)\)\s*$")


@dataclass(frozen=True)
class Measured:
    """A measured value with the repeats and the spread it summarises.

    Attributes
    ----------
    value : float
        The value (a timing's median or best, a mean over runs, a single measurement).
    repeats : int or None
        How many runs ``value`` summarises (None: one measurement, or not recorded).
    low, high : float or None
        Smallest and largest of those runs, in the unit of ``value``.
    """

    value: float
    repeats: int | None = None
    low: float | None = None
    high: float | None = None

    @classmethod
    def of(cls, samples: Sequence[float], summary: str = "median") -> Measured:
        """``summary`` (best, median, mean, worst) of ``samples``, with their count, min and max.

        Raises
        ------
        InputError
            No samples, or an unknown ``summary``.
        """
        values = [float(v) for v in samples]
        if not values:
            from fsdvs_hw.errors import InputError

            raise InputError("Measured.of: samples is empty; give at least one value")
        return cls(_summary(summary)(values), len(values), min(values), max(values))

    def scaled(self, factor: float) -> Measured:
        """The same measurement in another unit: every value times ``factor``."""
        return Measured(
            self.value * factor,
            self.repeats,
            None if self.low is None else self.low * factor,
            None if self.high is None else self.high * factor,
        )


def _summary(name: str) -> Callable[[Sequence[float]], float]:
    if name not in _SUMMARIES:
        from fsdvs_hw.errors import InputError

        raise InputError(f"summary {name!r} unknown; allowed: {', '.join(_SUMMARIES)}")
    return _SUMMARIES[name]


def _time_scale(unit: str) -> float:
    if unit not in _TIME_SCALE:
        from fsdvs_hw.errors import InputError

        raise InputError(f"a timing shown in {unit!r}: allowed time units are {', '.join(_TIME_SCALE)}")
    return _TIME_SCALE[unit]


@dataclass(frozen=True)
class _Part:
    """One number of a table cell: its record's metric and unit, and how it is printed."""

    metric: str
    unit: str
    spec: str
    summary: str = "median"
    spread: str = ""


#: What a value cell may hold: a number, a :class:`Measured`, a :class:`Timing` (summarised in the
#: column's time unit), None (printed ``—``, no record) or a string (printed as is, no record).
Cell = Any


@dataclass(frozen=True)
class Column:
    """One column of a benchmark table: a text column (part of each row's case) or a value column.

    Build columns with :meth:`text`, :meth:`number` and :meth:`numbers`.

    Attributes
    ----------
    header : str
        The column header as printed.
    parts : tuple
        The numbers one cell prints, each a record (empty for a text column).
    template : str
        How the printed numbers make the cell: ``"{0}"``, ``"[{0}, {1}]"``, ...
    """

    header: str
    parts: tuple[_Part, ...] = ()
    template: str = "{0}"

    @classmethod
    def text(cls, header: str) -> Column:
        """A text column: its cells name the row's case (``header=cell``), they are not records."""
        return cls(header)

    @classmethod
    def number(
        cls,
        header: str,
        spec: str = ".4g",
        *,
        unit: str | None = None,
        metric: str | None = None,
        suffix: str = "",
        summary: str = "median",
        spread: bool | str = False,
    ) -> Column:
        """A column of one number per cell.

        Parameters
        ----------
        header : str
            Printed header; a parenthesised suffix (``"time (ms)"``) is the unit and the rest the
            metric unless ``unit`` / ``metric`` are given.
        spec : str
            :func:`format` spec of the number (``".2e"``, ``".3f"``, ``"d"``).
        unit : str, optional
            Unit of the records (``""``: dimensionless).
        metric : str, optional
            Metric name of the records.
        suffix : str
            Printed after the number (``"×"``, ``" %"``).
        summary : str
            Statistic a :class:`Timing` cell is shown as: best, median, mean or worst.
        spread : bool or str
            Print the cell's min–max after its value: True as ``value [min–max]``, a string as its
            template (``" ({}–{})"``); False: the value alone (the records keep the spread).
        """
        m = _UNIT_SUFFIX.match(header)
        if unit is None and m is not None and m["unit"] not in _HEADER_UNITS:
            from fsdvs_hw.errors import InputError

            raise InputError(
                f"column {header!r}: {m['unit']!r} is not a unit ({', '.join(sorted(_HEADER_UNITS))}); "
                "give unit= and metric= explicitly"
            )
        _summary(summary)
        return cls(
            header,
            (
                _Part(
                    metric if metric is not None else (m["metric"] if m else header),
                    unit if unit is not None else (m["unit"] if m else ""),
                    spec,
                    summary,
                    " [{}–{}]" if spread is True else (spread or ""),
                ),
            ),
            "{0}" + suffix.replace("{", "{{").replace("}", "}}"),
        )

    @classmethod
    def numbers(cls, header: str, template: str, *parts: tuple[str, str, str]) -> Column:
        """A column of several numbers per cell: ``parts`` are ``(metric, unit, spec)`` and
        ``template`` places them (``"[{0}, {1}]"``); a cell is a tuple with one value per part."""
        return cls(header, tuple(_Part(metric, unit, spec) for metric, unit, spec in parts), template)

    @property
    def is_text(self) -> bool:
        return not self.parts

    def _render(self, cell: Cell) -> tuple[str, list[tuple[_Part, Measured]]]:
        """The printed cell and the ``(part, measured)`` of each number it prints."""
        if self.is_text:
            return str(cell), []
        if isinstance(cell, str):
            return cell, []
        cells = cell if len(self.parts) > 1 else (cell,)
        if not isinstance(cells, tuple) or len(cells) != len(self.parts):
            from fsdvs_hw.errors import InputError

            raise InputError(f"column {self.header!r}: a cell is a tuple of {len(self.parts)} values, got {cell!r}")
        texts, out = [], []
        for part, value in zip(self.parts, cells):
            m = _as_measured(value, part)
            if m is None:
                texts.append("n/a" if value is not None else "—")
                continue
            text = _format(m.value, part.spec)
            if part.spread and m.low is not None and m.high is not None:
                text += part.spread.format(_format(m.low, part.spec), _format(m.high, part.spec))
            texts.append(text)
            out.append((part, m))
        if not out and len(texts) == 1:  # nothing measured: the marker alone, without the suffix
            return texts[0], out
        return self.template.format(*texts), out


def _as_measured(value: Any, part: _Part) -> Measured | None:
    """A cell value as a :class:`Measured` in the part's unit (None: missing or not a number)."""
    if value is None:
        return None
    if isinstance(value, Timing):
        value = Measured.of(value.times_s, part.summary).scaled(_time_scale(part.unit))
    elif not isinstance(value, Measured):
        value = Measured(float(value))
    if part.unit in _TIME_SCALE and (value.repeats is None or value.low is None or value.high is None):
        from fsdvs_hw.errors import InputError

        raise InputError(
            f"{part.metric!r} is a time ({part.unit}): give a Timing or a Measured with repeats and "
            f"min–max (Measured.of([t]) for a single run), got {value!r}"
        )
    return None if math.isnan(value.value) else value


def _format(value: float, spec: str) -> str:
    return format(int(round(value)), spec) if spec.endswith("d") else format(value, spec)


def _plain(text: str) -> str:
    return text.replace("**", "").replace("`", "").strip()


def _torch_threads() -> int | None:
    torch = sys.modules.get("torch")
    return None if torch is None else int(torch.get_num_threads())


@dataclass(frozen=True)
class _Pending:
    """A record before the run's machine, versions and time stamp are attached."""

    table: str
    case: str
    metric: str
    unit: str
    measured: Measured
    threads: int | None
    settings: dict[str, Any]


class Table:
    """A Markdown table whose value cells are records; made by :meth:`BenchSection.table`."""

    def __init__(
        self,
        section: BenchSection,
        title: str,
        columns: Sequence[Column],
        settings: Mapping[str, Any],
        threads: int | str | None,
    ) -> None:
        if not columns:
            from fsdvs_hw.errors import InputError

            raise InputError(f"table {title!r}: give at least one column")
        self._section, self.title, self.columns = section, title, tuple(columns)
        self._settings, self._threads = dict(settings), threads
        self._lines: list[str] = []

    def row(self, *cells: Cell, case: str | None = None, threads: int | str | None = "auto") -> None:
        """Add a row: one cell per column (see :data:`Cell`); its value cells become records.

        ``case``: the records' case (default: ``header=cell`` of the text cells, joined by ``; ``);
        ``threads``: torch threads the row was measured with (default: the table's, else torch's
        thread count now, None when torch is not imported).

        Raises
        ------
        InputError
            Not one cell per column, or a composite cell of the wrong length.
        """
        if len(cells) != len(self.columns):
            from fsdvs_hw.errors import InputError

            raise InputError(f"table {self.title!r}: a row has {len(self.columns)} cells, got {len(cells)}")
        threads = self._threads if threads == "auto" else threads
        threads = _torch_threads() if threads == "auto" else threads
        rendered = [col._render(cell) for col, cell in zip(self.columns, cells)]
        if case is None:
            case = "; ".join(
                f"{col.header}={_plain(text)}"
                for col, (text, _) in zip(self.columns, rendered)
                if col.is_text and _plain(text)
            )
        for _text, values in rendered:
            for part, m in values:
                self._section._pending.append(
                    _Pending(self.title, case, part.metric, part.unit, m, threads, self._settings)
                )  # type: ignore[arg-type]
        self._lines.append("| " + " | ".join(text for text, _ in rendered) + " |")

    def markdown(self) -> str:
        """The table: header, ``|---|`` rule and the rows added so far."""
        head = "| " + " | ".join(c.header for c in self.columns) + " |"
        return "\n".join([head, "|" + "---|" * len(self.columns), *self._lines])


class BenchSection:
    """A benchmark's Markdown section built from its measurements: records first, Markdown their view.

    Text lines, tables and values quoted in text are added in order; :meth:`run` gives the
    :class:`BenchRun` (the Markdown and one :class:`BenchRecord` per printed number). A Markdown
    heading line (``#`` …) names the tables and values below it (their records' ``table``).

    Parameters
    ----------
    bench : str
        Benchmark name.
    settings : mapping, optional
        The bench's settings (``quick``, problem sizes), copied into every record.

    Examples
    --------
    >>> s = BenchSection("demo", settings={"quick": True})
    >>> s.text("### Fits", "")
    >>> t = s.table(Column.text("case"), Column.number("error", ".2e"), Column.number("time (ms)", ".1f"))
    >>> t.row("dog 7", 1.5e-3, Measured(12.5, 3, 12.0, 13.1))
    >>> run = s.run()
    >>> print(run.markdown)
    ### Fits
    <BLANKLINE>
    | case | error | time (ms) |
    |---|---|---|
    | dog 7 | 1.50e-03 | 12.5 |
    >>> [(r.table, r.case, r.metric, r.unit, r.value, r.repeats) for r in run.records][1]
    ('Fits', 'case=dog 7', 'time', 'ms', 12.5, 3)
    """

    def __init__(self, bench: str, *, settings: Mapping[str, Any] | None = None) -> None:
        self.bench = bench
        self.settings = dict(settings or {})
        self._parts: list[str | Table] = []
        self._title = bench
        self._pending: list[_Pending] = []

    def text(self, *lines: str) -> None:
        """Add Markdown lines; a heading line (``#`` …) names the tables and values below it."""
        for line in lines:
            if line.lstrip().startswith("#"):
                self._title = _plain(line.lstrip().lstrip("#")) or self._title
            self._parts.append(line)

    def table(
        self,
        *columns: Column,
        title: str | None = None,
        settings: Mapping[str, Any] | None = None,
        threads: int | str | None = "auto",
    ) -> Table:
        """Add a table here (rows may be added later); ``title`` defaults to the last heading,
        ``settings`` extend the section's, ``threads`` fixes the torch threads of its records."""
        t = Table(self, title or self._title, columns, {**self.settings, **(settings or {})}, threads)
        self._parts.append(t)
        return t

    def value(
        self,
        case: str,
        metric: str,
        value: Any,
        *,
        unit: str = "",
        spec: str = ".4g",
        summary: str = "median",
        threads: int | str | None = "auto",
    ) -> str:
        """Record a value quoted in the text; returns it printed (``spec``; a :class:`Timing` in
        ``unit`` as ``summary``) for the caller's sentence."""
        part = _Part(metric, unit, spec, summary)
        m = _as_measured(value, part)
        if m is None:
            return "n/a" if value is not None else "—"
        self._pending.append(
            _Pending(
                self._title,
                case,
                metric,
                unit,
                m,
                _torch_threads() if threads == "auto" else threads,  # type: ignore[arg-type]
                self.settings,
            )
        )
        return _format(m.value, spec)

    @property
    def markdown(self) -> str:
        """The section so far: its lines and tables joined with newlines."""
        return "\n".join(p if isinstance(p, str) else p.markdown() for p in self._parts)

    def records(self) -> list[BenchRecord]:
        """One record per number printed so far, with this machine, the library versions and the time."""
        machine, versions = machine_info(), library_versions()
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        return [
            BenchRecord(
                bench=self.bench,
                table=p.table,
                case=p.case,
                metric=p.metric,
                unit=p.unit,
                value=float(p.measured.value),
                repeats=p.measured.repeats,
                spread_min=p.measured.low,
                spread_max=p.measured.high,
                threads=p.threads,
                machine=machine,
                versions=versions,
                settings=dict(p.settings),
                timestamp=stamp,
            )
            for p in self._pending
        ]

    def run(self, extra: Sequence[BenchRecord] = ()) -> BenchRun:
        """The :class:`BenchRun`: this Markdown and its records (after ``extra`` records, if any)."""
        return BenchRun(self.bench, self.markdown, tuple(extra) + tuple(self.records()))


def records_markdown(records: Sequence[BenchRecord]) -> str:
    """A compact Markdown view of records: one table per (bench, table), one row per record."""
    out: list[str] = []
    key = None
    for r in records:
        if (r.bench, r.table) != key:
            key = (r.bench, r.table)
            out += [
                "",
                f"**{r.bench}: {r.table}**",
                "",
                "| case | metric | value | unit | repeats | min | max |",
                "|---|---|---|---|---|---|---|",
            ]
        spread = ("—", "—") if r.spread_min is None else (f"{r.spread_min:.4g}", f"{r.spread_max:.4g}")
        out.append(
            f"| {r.case} | {r.metric} | {r.value:.6g} | {r.unit} | {r.repeats or '—'} | {spread[0]} | {spread[1]} |"
        )
    return "\n".join(out).strip() + "\n"


def write_json(records: Sequence[BenchRecord], path: str | Path) -> Path:
    """Write records as ``{"schema": RECORD_SCHEMA, "records": [...]}`` (UTF-8, indented)."""
    from fsdvs_hw.paths import write_output

    return write_output(
        Path(path),
        json.dumps({"schema": RECORD_SCHEMA, "records": [r.to_dict() for r in records]}, indent=1, ensure_ascii=False)
        + "\n",
        flag="--json",
    )


def read_json(path: str | Path) -> list[BenchRecord]:
    """The records of a file written by :func:`write_json`."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    if data.get("schema") != RECORD_SCHEMA:
        from fsdvs_hw.errors import InputError

        raise InputError(f"{path}: schema {data.get('schema')!r}, expected {RECORD_SCHEMA!r}")
    return [BenchRecord.from_dict(r) for r in data["records"]]
