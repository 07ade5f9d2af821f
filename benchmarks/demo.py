"""``fsdvs-hw bench demo``: the wall time of the main job, ``make demo``, on this machine.

Runs ``fsdvs-hw explore designs/default.toml`` in a fresh process into an empty folder (no stored
points, no cached rate curves: what a user's first ``make demo`` costs), with the design's own
``[run] workers``, and records

* the wall time of the whole command (from process start to exit) and its peak resident memory
  (the largest of the command and its worker processes, from ``resource.getrusage``);
* from the run's ``scores.json``: the sum of the points' own wall times (fit, analysis, tasks,
  emulation; split over the workers), the points' count and their statuses.

The budget (issue 38): under 10 minutes on 2 CPU cores with the matched-rate control on. ``quick``
runs the README's quick look instead (one network per task, 16 clips, simulator track only). The
exploration is kept under ``FIGURES/demo`` (default: a temporary folder) so its report can be read.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .harness import BenchRun, BenchSection, Column, Measured

__all__ = ["QUICK_SETTINGS", "bench_demo"]

#: The README's quick look (``--set`` arguments of ``fsdvs-hw explore``).
QUICK_SETTINGS: tuple[str, ...] = (
    'tasks.checkpoints={detection="kernels/networks/detection_with_learned_detection_7x7_s0.safetensors", '
    'recognition="kernels/networks/recognition_with_learned_detection_7x7_s0.safetensors", '
    'segmentation="kernels/networks/segmentation_with_learned_detection_7x7_s0.safetensors"}',
    "tasks.n_test={detection=16, recognition=16, segmentation=16}",
    'tasks.tracks=["simulator"]',
    "emulation.enabled=false",
)

_ROOT = Path(__file__).resolve().parents[1]


def _explore(out: Path, quick: bool) -> tuple[float, float, dict]:
    """Run the command once; (wall s, peak RSS MiB of it and its children, scores.json)."""
    # the design by its path relative to the checkout, as `make demo` names it (the stored checkpoint
    # paths stay relative, not this machine's)
    cmd = [sys.executable, "-m", "fsdvs_hw.cli", "explore", "designs/default.toml", "--out", str(out)]
    cmd.append("--no-progress")
    for s in QUICK_SETTINGS if quick else ():
        cmd += ["--set", s]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=_ROOT, capture_output=True, text=True, env={**os.environ}, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"fsdvs-hw explore exited {proc.returncode}: {proc.stderr[-2000:]}")
    peak_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss  # Linux: KiB, largest child
    return wall, peak_kib / 1024.0, json.loads((out / "scores.json").read_text())


def bench_demo(*, quick: bool = False, figures: str | Path | None = None, repeats: int = 1) -> BenchRun:
    """The main job's wall time and memory (module docstring), as records and their Markdown.

    Parameters
    ----------
    quick : bool
        The README's quick look instead of the full default design.
    figures : path, optional
        The exploration is kept in ``figures/demo`` (replaced); default a temporary folder.
    repeats : int
        Cold runs (each into an emptied folder).
    """
    sec = BenchSection("demo", settings={"quick": quick, "repeats": repeats})
    sec.text("## demo: the main job", "")
    keep = Path(figures) / "demo" if figures is not None else None
    walls, peaks, point_s = [], [], []
    scores: dict = {}
    with tempfile.TemporaryDirectory(prefix="fsdvs_demo_") as tmp:
        for _ in range(max(1, int(repeats))):
            out = keep if keep is not None else Path(tmp) / "demo"
            if out.exists():
                shutil.rmtree(out)
            wall, peak, scores = _explore(out, quick)
            walls.append(wall)
            peaks.append(peak)
            point_s.append(sum(float(p.get("wall_s") or 0.0) for p in scores.get("points", [])))
    points = scores.get("points", [])
    statuses = sorted({str(p.get("status")) for p in points})
    rate_on = any((p.get("matched_rate") or {}).get("status") == "ok" for p in points)
    t = sec.table(
        Column.text("design"),
        Column.number("wall time (s)", ".0f", spread=True),
        Column.number("points' own time, summed (s)", ".0f", spread=True),
        Column.number("points", ".0f", unit=""),
        Column.number("peak memory (MiB)", ".0f", summary="worst", spread=True),
        title="The main job, cold (no stored points, no cached curves)",
    )
    t.row(
        ("README quick look" if quick else "designs/default.toml") + (", matched rate on" if rate_on else ""),
        Measured.of(walls),
        Measured.of(point_s),
        float(len(points)),
        Measured.of(peaks, summary="worst"),
    )
    sec.text(
        "",
        f"{len(walls)} cold run(s); statuses {', '.join(statuses)}; {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f} at the end.",
    )
    return sec.run()
