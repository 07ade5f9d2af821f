"""Execute the design-sweep notebooks in place and store them with their outputs (``make notebooks``).

Usage::

    python notebooks/execute.py [--fast] [--timeout S] [NOTEBOOK.ipynb ...]

Each notebook runs top to bottom in a fresh ``python3`` (ipykernel) kernel through nbclient, at
full size unless ``--fast`` (which sets ``FSDVS_NOTEBOOK_QUICK=1``, the small settings the tests
use). The executed notebook is written back over the file, outputs and figures included (so they
show on a code host), with the wall time of the run and the settings recorded in the notebook's
metadata under ``fsdvs_hw`` (``wall_s``, and ``cpu_s``: the kernel's CPU time, which a shared
machine does not inflate). Progress bars in the outputs are stored in their final state
(carriage-return redraws collapsed). A notebook that fails is left unchanged and the command exits
with status 1 after running the others.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["collapse_redraws", "execute_notebook", "main", "tidy_streams"]

HERE = Path(__file__).resolve().parent


def collapse_redraws(text: str) -> str:
    r"""Keep what a terminal would show: of each line's ``\r``-separated redraws, the last non-empty one."""
    lines = []
    for line in text.split("\n"):
        parts = [p for p in line.split("\r") if p.strip()]
        lines.append(parts[-1] if parts else line.replace("\r", ""))
    return "\n".join(lines)


def tidy_streams(nb: Any) -> None:
    r"""Merge each cell's consecutive stdout/stderr outputs (as a notebook front end shows them) and
    collapse progress-bar redraws (``\r``) to their final state, in place."""
    for cell in nb.cells:
        merged: list[Any] = []
        for out in cell.get("outputs", []):
            prev = merged[-1] if merged else None
            if (out.get("output_type") == "stream" and prev is not None and prev.get("output_type") == "stream"
                    and prev.get("name") == out.get("name")):
                prev["text"] += out["text"]
            else:
                merged.append(out)
        for out in merged:
            if out.get("output_type") == "stream":
                out["text"] = collapse_redraws(out["text"])
        if "outputs" in cell:
            cell["outputs"] = merged


def _children_cpu_s() -> float:
    """User + system CPU seconds of this process's finished child processes (the kernels)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def execute_notebook(path: Path, *, fast: bool = False, timeout: int = 1800) -> tuple[float, float]:
    """Run ``path`` in a fresh kernel and write it back with outputs; return (wall, CPU) seconds.

    Parameters
    ----------
    path : Path
        The notebook (.ipynb, nbformat 4).
    fast : bool
        Small settings (``FSDVS_NOTEBOOK_QUICK=1``).
    timeout : int
        Seconds one cell may run.
    """
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    env = {"FSDVS_NOTEBOOK_QUICK": "1" if fast else "0", "MPLBACKEND": "module://matplotlib_inline.backend_inline"}
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)  # the kernel inherits this process's environment
    try:
        client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                         resources={"metadata": {"path": str(path.parent)}})
        t0, c0 = time.perf_counter(), _children_cpu_s()
        client.execute()  # starts the kernel, runs every cell, shuts the kernel down and reaps it
        wall, cpu = time.perf_counter() - t0, _children_cpu_s() - c0
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    tidy_streams(nb)
    nb.metadata["fsdvs_hw"] = {
        "settings": "fast" if fast else "full",
        "wall_s": round(wall, 1),
        "cpu_s": round(cpu, 1),  # the kernel's user + system CPU time (all its threads)
        "executed": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": f"{platform.machine()}, {os.cpu_count()} logical CPUs (possibly shared)",
    }
    nbformat.write(nb, path)
    return wall, cpu


def main(argv: list[str] | None = None) -> int:
    """Command line: run the given notebooks (default: every ``notebooks/*.ipynb``); exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("notebooks", nargs="*", type=Path, help="notebooks (default: all in notebooks/)")
    parser.add_argument("--fast", action="store_true", help="small settings (as the tests run them)")
    parser.add_argument("--timeout", type=int, default=1800, help="seconds per cell (default 1800)")
    args = parser.parse_args(argv)
    paths = args.notebooks or sorted(HERE.glob("*.ipynb"))
    failed = []
    for path in paths:
        print(f"{path}: running ({'fast' if args.fast else 'full'} settings) ...", file=sys.stderr, flush=True)
        try:
            wall, cpu = execute_notebook(path, fast=args.fast, timeout=args.timeout)
        except Exception as exc:  # noqa: BLE001 - report and go on with the others
            first = str(exc).strip().splitlines()
            print(f"{path}: FAILED ({type(exc).__name__}: {first[-1] if first else ''}); left unchanged",
                  file=sys.stderr, flush=True)
            failed.append(path)
            continue
        print(f"{path}: done in {wall:.1f} s wall ({cpu:.1f} s kernel CPU), stored with outputs", file=sys.stderr, flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
