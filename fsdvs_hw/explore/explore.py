"""The main job: fit every realisation of a design's kernel, score each, write the report.

``fsdvs-hw explore designs/default.toml --out out/demo`` (:mod:`fsdvs_hw.cli.explore`) runs :func:`run_exploration`: it validates
the design (all errors before any work), expands its design points, runs those not already in
``DIR/results.sqlite`` (local processes or a Dask scheduler, with a progress bar), and writes
``DIR/report.html`` with ``DIR/scores.csv`` and ``DIR/scores.json``, and every hardware point's buildable
files under ``DIR/artifacts/`` with ``DIR/artifacts/index.json`` (:mod:`fsdvs_hw.explore.point_artifacts`); with
``[codesign] enabled`` also ``DIR/codesign.json`` and ``DIR/codesign.csv`` (:mod:`fsdvs_hw.explore.codesign`).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..design import Design, load_design
from ..paths import output_dir
from ..records import ScoredPoint
from .costing import with_physical_costs
from .matched import with_matched_rates
from .measurability import measured_losses
from .point_artifacts import with_point_artifacts
from .reporting import report_input
from .sweep import SweepSummary, run_design
from .trained_kernel import settle_design_kernel

__all__ = ["Exploration", "run_exploration"]


@dataclass(frozen=True)
class Exploration:
    """What :func:`run_exploration` produced (paths, the run summary, the scored design points)."""

    report: Path
    scores_csv: Path
    scores_json: Path
    store: Path
    summary: SweepSummary
    wall_s: float
    points: tuple[ScoredPoint, ...] = ()
    artifacts_index: Path | None = None


def run_exploration(
    design: Design | str | Path,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool | None = None,
    retry_errors: bool = False,
    max_points: int | None = None,
    security: Any = None,
) -> Exploration:
    """Explore one design: fit, score and report every design point.

    After every point has run, each point's task losses against the learned kernel are computed
    with paired bootstrap CIs (:func:`fsdvs_hw.explore.scoring.paired_losses`); the points handed to
    the report (and :attr:`Exploration.points`, :class:`~fsdvs_hw.records.ScoredPoint`) carry them
    (:attr:`~fsdvs_hw.records.ScoredPoint.paired_loss`), without the bulky per-clip evidence (which
    stays in ``results.sqlite``), with their matched-rate and measurability records, their
    buildable files (:func:`fsdvs_hw.explore.point_artifacts.with_point_artifacts`) and their
    physical cost (also over the design's ``costs.*`` sweep axes:
    :func:`fsdvs_hw.explore.costing.with_physical_costs`). With ``[codesign]`` enabled the co-design
    comparison runs last and its summary goes to the report as it is.

    Parameters
    ----------
    design : Design or path
        A validated design or a TOML design file.
    out_dir : path
        Output folder (created): ``report.html``, ``scores.csv``, ``scores.json``, ``results.sqlite``,
        ``artifacts/`` (with ``artifacts/index.json``).
    workers : int, optional
        Local worker processes (default: the design's ``[run] workers``).
    scheduler : str, optional
        Dask scheduler address ``tcp://HOST:PORT``.
    progress : bool, optional
        Progress bar on stderr (None, the default: when stderr is a terminal; see :mod:`fsdvs_hw.progress`).
    retry_errors : bool
        Rerun points that failed in an earlier run into the same ``out_dir``.
    max_points : int, optional
        Refuse designs of more points (default: the design's ``[run] max_points``).
    security : distributed.Security, optional
        TLS for a ``tls://`` scheduler (:func:`fsdvs_hw.explore.sweep.dask_security`).

    Examples
    --------
    A small design (the two references and 8-bit ASIC taps; no emulation track, no task networks):

    >>> import tempfile
    >>> from fsdvs_hw import run_exploration
    >>> from fsdvs_hw.design import parse_design
    >>> design = parse_design({"realisations": {"include": ["learned", "delta", "asic"]},
    ...                        "emulation": {"enabled": False}, "run": {"workers": 1},
    ...                        "analysis": {"csf_methods": ["mannos_sakrison_1974"]}})
    >>> with tempfile.TemporaryDirectory() as out:
    ...     ex = run_exploration(design, out, progress=False)
    ...     written = sorted(p.name for p in (ex.report, ex.scores_csv, ex.scores_json) if p.is_file())
    >>> written
    ['report.html', 'scores.csv', 'scores.json']
    >>> [(p.realisation, p.status) for p in ex.points]
    [('learned', 'ok'), ('delta', 'ok'), ('asic', 'ok')]
    >>> ex.points[0].score.kernel_error  # the learned kernel is the target itself
    0.0
    """
    from ..report import write_report

    t0 = time.perf_counter()
    if not isinstance(design, Design):
        design = load_design(design)
    out = output_dir(out_dir, flag="--out")  # checked before any work: a file, unwritable, ...
    store_path = out / "results.sqlite"
    _train_user_networks(design)
    design = settle_design_kernel(design)  # the kernel learn wrote; refused if not the networks' own
    summary, points = run_design(
        design,
        store_path,
        workers=workers,
        scheduler=scheduler,
        progress=progress,
        retry_errors=retry_errors,
        max_points=max_points,
        security=security,
    )
    index, points = _enriched(points, design, out, progress=progress)
    codesign = None
    if design.spec.codesign.enabled:  # the fit-then-swap / fine-tune / co-designed rows
        from .codesign import run_codesign, write_codesign

        codesign = run_codesign(design, out, progress=progress)
        write_codesign(codesign, out)
    report = write_report(points, report_input(design, codesign=codesign), out)
    return Exploration(
        report=report,
        scores_csv=out / "scores.csv",
        scores_json=out / "scores.json",
        store=store_path,
        summary=summary,
        wall_s=time.perf_counter() - t0,
        points=tuple(points),
        artifacts_index=index,
    )


def _enriched(
    points: list[ScoredPoint], design: Design, out: Path, *, progress: bool | None
) -> tuple[Path, list[ScoredPoint]]:
    """What the exploration adds to the stored points, in order: matched rates (they need the
    per-clip evidence), paired losses with measurability (the evidence dropped), buildable files
    (``artifacts/index.json``'s path is returned) and physical costs."""
    sc = design.spec.scoring
    points = with_matched_rates(points, design, out, progress=progress)  # [rate]: needs the per-clip evidence
    points = measured_losses(  # paired losses; tasks at chance or degenerate weigh 0 (explore.measurability)
        points,
        task_weights=sc.task_weights or None,
        n_resamples=sc.n_resamples,
        confidence=sc.confidence,
        rng=design.spec.run.seed,
        target_half_width=sc.target_half_width,
    )
    index, points = with_point_artifacts(points, out, resolution=tuple(design.spec.sensor.resolution))
    return index, with_physical_costs(points, design)  # SI cost records, and per [costs] sweep setting


def _train_user_networks(design: Design) -> None:
    """Train (or reuse / resume) every ``[tasks.datasets.<task>]`` network with a ``train`` table once,
    here, before the sweep's workers load the finished checkpoints (:func:`fsdvs_hw.explore.user_data.
    train_user_task`)."""
    from .user_data import train_user_task

    for task, table in design.spec.tasks.datasets.items():
        if table.train is not None:
            res = train_user_task(task, table.model_dump(), design.base_dir, confine=design.confine_paths, verbose=True)
            print(
                f"[explore] {task}: network trained on {len(res.train_indices)} clips not scored "
                f"({res.epochs_trained} epochs now; {res.paths.get('checkpoint')})",
                file=sys.stderr,
                flush=True,
            )
