"""The benchmark registry: speed/accuracy tables of every component, as records and Markdown.

Each component registers a benchmark in :data:`BENCHMARKS` as ``"module:function"``; the function
has the signature ``f(*, quick: bool = False) -> BenchRun`` (a bench that draws figures also takes
``figures``): it measures into :class:`~fsdvs_hw.benchmarks.BenchRecord` records and renders its
Markdown section from them (:class:`~fsdvs_hw.benchmarks.BenchSection`). ``quick`` shrinks the
problem for smoke tests; the README tables are produced with ``quick=False``. Every bench runs
inside :func:`~fsdvs_hw.benchmarks.kept_global_state` (torch threads, dtype and random state,
numpy's error and random state, warnings filters and environment restored afterwards). The
command is ``fsdvs-hw bench`` (:mod:`fsdvs_hw.cli.bench`).
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

from .benchmarks import BenchRun, kept_global_state
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
    """Run one registered benchmark: its records and their Markdown (process-wide state restored after it).

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
    TypeError
        The registered function returned something other than a :class:`BenchRun`.
    """
    if name not in BENCHMARKS:
        raise InputError(f"benchmark {name!r} unknown; allowed: {', '.join(BENCHMARKS)}, all")
    module, func = BENCHMARKS[name].split(":")
    fn = getattr(importlib.import_module(module), func)
    kw = {"figures": Path(figures)} if figures is not None and "figures" in inspect.signature(fn).parameters else {}
    with kept_global_state():
        out = fn(quick=quick, **kw)
    if not isinstance(out, BenchRun):
        raise TypeError(f"benchmark {name!r} ({BENCHMARKS[name]}) returned {type(out).__name__}, not a BenchRun: "
                        "measure into fsdvs_hw.benchmarks.BenchSection and return its run()")
    return out


def run_benchmark(name: str, *, quick: bool = False) -> str:
    """Run one registered benchmark and return its Markdown section."""
    return benchmark_run(name, quick=quick).markdown
