"""Design exploration: design files, scoring, sweeps, the results store and the main job.

``fsdvs-hw explore DESIGN --out DIR`` (:mod:`fsdvs_hw.explore.explore`) fits every realisation
of a design's kernel, scores each (:mod:`~fsdvs_hw.explore.scoring`), stores one row per design
point (:mod:`~fsdvs_hw.explore.store`) and writes the HTML report (:mod:`fsdvs_hw.report`, from the
scored points and the design's report input, :mod:`~fsdvs_hw.explore.reporting`).
``fsdvs-hw sweep DESIGN`` (:mod:`~fsdvs_hw.explore.sweep`) runs a design's sweep axes on a local
process pool or a Dask cluster. Design files are read and validated by
:mod:`fsdvs_hw.design`; the sensor-in-the-loop emulation track lives in
:mod:`~fsdvs_hw.explore.emulation`; ``fsdvs-hw bench explore`` is ``benchmarks/explore.py`` (a checkout).
Per-clip task evidence (same clips, noise and networks for every kernel) is
:mod:`~fsdvs_hw.explore.paired`; the losses' confidence intervals come from :mod:`fsdvs_hw.stats`;
:mod:`~fsdvs_hw.explore.sizing` sizes the test sets from a pilot run; :mod:`~fsdvs_hw.explore.point_artifacts` writes
every hardware point's buildable files (SPICE deck, Verilog and testbench, phase profile) and their index.
With ``[rate] enabled`` every point also gets its losses at equal event rate (:mod:`~fsdvs_hw.explore.matched`,
on the rate curves of :mod:`~fsdvs_hw.explore.rate`).
"""

from __future__ import annotations

from .matched import with_matched_rates
from .scoring import accuracy_losses, fit_realisation, paired_losses, score, with_paired_losses
from .store import ResultsStore
from .sweep import DesignPoint, evaluate_point, expand_points, run_design, run_points

__all__ = [
    "DesignPoint",
    "ResultsStore",
    "accuracy_losses",
    "evaluate_point",
    "expand_points",
    "fit_realisation",
    "paired_losses",
    "run_design",
    "run_exploration",
    "run_points",
    "score",
    "with_matched_rates",
    "with_paired_losses",
]


def __getattr__(name: str):
    if name == "run_exploration":
        from .explore import run_exploration

        return run_exploration
    raise AttributeError(f"module 'fsdvs_hw.explore' has no attribute {name!r}")
