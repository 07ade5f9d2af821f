"""Running ngspice on a process deck: batch mode, one thread, AC (complex) raw files parsed.

:func:`run_deck` writes a deck to a temporary folder, runs ``ngspice -b deck.cir -r deck.raw``
(Debian's ngspice 39) with one thread and at lowered priority (``nice``), and returns every vector of
the ASCII raw file: real for ``.op``/``.dc``/``.tran``, complex for ``.ac``. Small-signal kernels
come from an ``.ac`` analysis at a frequency far below every node's corner (the linearisation of
the device currents at the operating point, which ngspice computes from the device models).

Examples
--------
>>> from fsdvs_hw.process.ngspice import parse_raw
>>> head = "No. Variables: 2\\nNo. Points: 1\\nVariables:\\n\\t0\\tfrequency\\tfrequency\\n"
>>> raw = head + "\\t1\\tv(a)\\tvoltage\\nValues:\\n0\\t1e-3,0\\n\\t2.5,-1\\n"
>>> complex(parse_raw(raw)["v(a)"][0])
(2.5-1j)
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ..errors import InputError, ToolMissingError

__all__ = ["NGSPICE_OPTIONS", "ngspice_version", "parse_raw", "run_deck"]

#: Solver options every process deck carries: ngspice's default gmin (1e-12 S) is near the
#: subthreshold conductances (nS and below), and abstol must resolve pA currents.
NGSPICE_OPTIONS = ".options gmin=1e-15 abstol=1e-15 reltol=1e-6 vntol=1e-9"


def parse_raw(text: str) -> dict[str, np.ndarray]:
    """Every vector of an ngspice ASCII raw file by lower-case name (complex when the plot is)."""
    lines = text.splitlines()
    try:
        nvar = int(next(ln for ln in lines if ln.startswith("No. Variables:")).split(":")[1])
        i_var = next(i for i, ln in enumerate(lines) if ln.startswith("Variables:"))
        i_val = next(i for i, ln in enumerate(lines) if ln.startswith("Values:"))
    except StopIteration:
        raise InputError("ngspice raw file: missing 'No. Variables' / 'Variables:' / 'Values:' header") from None
    names = [lines[i_var + 1 + k].split()[1].lower() for k in range(nvar)]
    tokens = " ".join(lines[i_val + 1 :]).split()
    if not tokens or len(tokens) % (nvar + 1):
        raise InputError(f"ngspice raw file: {len(tokens)} value tokens do not form points of {nvar} variables")
    rows = np.array(tokens, dtype=object).reshape(-1, nvar + 1)[:, 1:]
    if "," in rows[0, 0]:
        to_c = np.vectorize(lambda s: complex(*(float(p) for p in s.split(","))), otypes=[np.complex128])
        table = to_c(rows)
    else:
        table = rows.astype(np.float64)
    return {name: table[:, k] for k, name in enumerate(names)}


def ngspice_version() -> str:
    """``"ngspice 39"`` (the installed binary's version line), or ``"ngspice"`` when it says none."""
    exe = shutil.which("ngspice")
    if exe is None:
        raise ToolMissingError("ngspice not found on PATH; install it with 'apt-get install ngspice'")
    out = subprocess.run([exe, "-v"], capture_output=True, text=True, timeout=30).stdout
    for token in out.replace("-", " ").split():
        if token[:1].isdigit():
            return f"ngspice {token}"
    return "ngspice"


def run_deck(deck: str, *, timeout_s: float = 600.0, keep: Path | None = None) -> dict[str, np.ndarray]:
    """Run ``deck`` in ngspice batch mode (one thread, ``nice -n 10``) and return its vectors.

    Parameters
    ----------
    deck : str
        A complete deck (``.lib`` lines, devices, analysis, ``.end``).
    timeout_s : float
        Wall-clock limit (s).
    keep : Path, optional
        A folder to copy the deck and its log into (for a designer to rerun).

    Raises
    ------
    ToolMissingError
        ngspice is not installed.
    InputError
        ngspice failed or ran out of time; the message ends with its output.
    """
    exe = shutil.which("ngspice")
    if exe is None:
        raise ToolMissingError("ngspice not found on PATH; install it with 'apt-get install ngspice'")
    cmd = [exe, "-b", "deck.cir", "-r", "deck.raw"]
    if shutil.which("nice"):
        cmd = ["nice", "-n", "10", *cmd]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    with tempfile.TemporaryDirectory(prefix="fsdvs_process_") as tmp:
        folder = Path(tmp)
        (folder / "deck.cir").write_text(deck)
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, cwd=tmp, env=env)
        except subprocess.TimeoutExpired:
            raise InputError(f"ngspice did not finish within timeout_s={timeout_s} s") from None
        raw = folder / "deck.raw"
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
            shutil.copy(folder / "deck.cir", keep / "deck.cir")
            (keep / "ngspice.log").write_text(proc.stdout + proc.stderr)
        if proc.returncode != 0 or not raw.is_file():
            raise InputError(f"ngspice failed (exit code {proc.returncode}):\n{(proc.stdout + proc.stderr)[-2000:]}")
        return parse_raw(raw.read_text())
