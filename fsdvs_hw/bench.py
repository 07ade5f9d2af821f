"""The benchmark registry: speed/accuracy tables of every component, as records and Markdown.

Each component registers a benchmark in :data:`BENCHMARKS` as ``"module:function"``; the function
has the signature ``f(*, quick: bool = False) -> BenchRun | str``: a
:class:`~fsdvs_hw.benchmarks.BenchRun` (Markdown section plus :class:`~fsdvs_hw.benchmarks.BenchRecord`
records), or a Markdown section whose table cells :func:`benchmark_run` turns into records.
``quick`` shrinks the problem for smoke tests; the README tables are produced with ``quick=False``.
Every bench runs with torch's thread count restored afterwards. The command is
``fsdvs-hw bench`` (:mod:`fsdvs_hw.cli.bench`).
"""

from __future__ import annotations

import importlib
import inspect
import sys
from pathlib import Path

from .benchmarks import BenchRun, kept_torch_threads, records_from_markdown
from .errors import InputError

__all__ = ["BENCHMARKS", "run_benchmark", "benchmark_run"]

#: benchmark name -> "module:function"
BENCHMARKS: dict[str, str] = {
    "csf": "fsdvs_hw.analysis:bench_analysis",
    "tasks": "fsdvs_hw.tasks.bench:bench_tasks",
    "asic": "fsdvs_hw.realise.asic.bench:bench_asic",
    "mesh": "fsdvs_hw.realise.mesh.bench:bench_mesh",
    "metalens": "fsdvs_hw.realise.metalens.bench:bench_metalens",
    "sim": "fsdvs_hw.sensor.bench:bench_sim",
    "explore": "fsdvs_hw.explore.bench:bench_explore",
    "stats": "fsdvs_hw.explore.stats_bench:bench_stats",
}


def benchmark_run(name: str, *, quick: bool = False, figures: str | Path | None = None) -> BenchRun:
    """Run one registered benchmark; its Markdown and records (torch threads restored after it).

    Parameters
    ----------
    name : str
        A key of :data:`BENCHMARKS`.
    quick : bool
        Small problem sizes (smoke test).
    figures : path, optional
        Folder for figures, passed to benches that draw one (their default: a temporary folder;
        never the package or source tree).

    Raises
    ------
    InputError
        ``name`` is not in :data:`BENCHMARKS`.
    """
    if name not in BENCHMARKS:
        raise InputError(f"benchmark {name!r} unknown; allowed: {', '.join(BENCHMARKS)}, all")
    module, func = BENCHMARKS[name].split(":")
    with kept_torch_threads():
        fn = getattr(importlib.import_module(module), func)
        kw = {"figures": Path(figures)} if figures is not None and "figures" in inspect.signature(fn).parameters else {}
        out = fn(quick=quick, **kw)
        threads = sys.modules["torch"].get_num_threads() if "torch" in sys.modules else None
    if isinstance(out, BenchRun):
        return out
    return BenchRun(name, out, tuple(records_from_markdown(name, out, settings={"quick": quick}, threads=threads)))


def run_benchmark(name: str, *, quick: bool = False) -> str:
    """Run one registered benchmark and return its Markdown section."""
    return benchmark_run(name, quick=quick).markdown
