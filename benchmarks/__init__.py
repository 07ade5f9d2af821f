"""fsdvs_hw's benchmarks: speed/accuracy tables of every component, as records and Markdown.

Not part of the library (not shipped in the wheel): run from a checkout with ``fsdvs-hw bench``
(:mod:`fsdvs_hw.cli.bench`) or ``python -c "import benchmarks; print(benchmarks.run_benchmark('csf'))"``
in the repository root. ``benchmarks/README.md`` describes the method.

Each component's benchmark is registered in :data:`BENCHMARKS` as ``"module:function"``; the
function has the signature ``f(*, quick: bool = False) -> BenchRun`` (a bench that draws figures
also takes ``figures``): it measures into :class:`~benchmarks.harness.BenchRecord` records and
renders its Markdown section from them (:class:`~benchmarks.harness.BenchSection`). ``quick``
shrinks the problem for smoke tests; the published tables are produced with ``quick=False``.
Every bench runs inside :func:`~benchmarks.harness.kept_global_state` (torch threads, dtype and
random state, numpy's error and random state, warnings filters and environment restored afterwards).
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

from fsdvs_hw.errors import InputError

from . import harness
from .harness import BenchRun, kept_global_state

__all__ = ["BENCHMARKS", "benchmark_run", "harness", "run_benchmark"]

#: benchmark name -> "module:function"
BENCHMARKS: dict[str, str] = {
    "csf": "benchmarks.csf:bench_csf",
    "tasks": "benchmarks.tasks:bench_tasks",
    "asic": "benchmarks.asic:bench_asic",
    "asic_sky130": "benchmarks.asic_sky130:bench_asic_sky130",
    "mesh": "benchmarks.mesh:bench_mesh",
    "mesh_sky130": "benchmarks.mesh_sky130:bench_mesh_sky130",
    "metalens": "benchmarks.metalens:bench_metalens",
    "sim": "benchmarks.sim:bench_sim",
    "explore": "benchmarks.explore:bench_explore",
    "stats": "benchmarks.stats:bench_stats",
    "sensors": "benchmarks.sensors:bench_sensors",
    "user_data": "benchmarks.user_data:bench_user_data",
    "user_data_stages": "benchmarks.user_data_stages:bench_user_data_stages",
    "upsampling": "benchmarks.upsampling:bench_upsampling",
    "demo": "benchmarks.demo:bench_demo",
}


def benchmark_run(name: str, *, quick: bool = False, figures: str | Path | None = None, long: bool = False) -> BenchRun:
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
    long : bool
        Also the long cases, passed to benches that have them (``sim``: the 2-minute clip written
        to files, streaming memory); others ignore it.

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
    params = inspect.signature(fn).parameters
    kw: dict = {"figures": Path(figures)} if figures is not None and "figures" in params else {}
    if long and "long" in params:
        kw["long"] = True
    with kept_global_state():
        out = fn(quick=quick, **kw)
    if not isinstance(out, BenchRun):
        raise TypeError(
            f"benchmark {name!r} ({BENCHMARKS[name]}) returned {type(out).__name__}, not a BenchRun: "
            "measure into benchmarks.harness.BenchSection and return its run()"
        )
    return out


def run_benchmark(name: str, *, quick: bool = False) -> str:
    """Run one registered benchmark and return its Markdown section."""
    return benchmark_run(name, quick=quick).markdown
