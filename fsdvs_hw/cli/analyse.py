"""``fsdvs-hw analyse``: spectrum, band summary and CSF agreement of one kernel."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from ..errors import InputError

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "analyse a kernel: spectrum, radial response, agreement with CSF models; writes PNGs + JSON"
DESCRIPTION = """\
Analyse a spatial kernel (a file, or a reference family) as an FS-DVS front end.

KERNEL is a kernel file (.npy, .csv, .json, .pt) or a reference family with optional
parameters, e.g.  dog   dog:size=7,sigma_centre_px=0.7,w_surround=1.0   log:size=9   gaussian:sigma_px=1.2
(families: delta, gaussian, dog, log; sizes odd, sigmas in pixels).

Prints a table: DC gain, peak frequency and half-maximum band (cycles/pixel), Q, and per CSF
model the pixels/degree scale (from --focal-mm, or fitted), peak-frequency ratio, correlation
and RMS / log-RMS difference of the peak-normalised curves. With --out it writes kernel.png,
spectrum.png, radial_csf.png and metrics.json.

Example:
  fsdvs-hw analyse designs/kernels/dog_7x7.json --focal-mm 12 --out out/dog
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("kernel", metavar="KERNEL_OR_REFERENCE", help="kernel file or reference spec (see above)")
    p.add_argument(
        "--pitch-um", type=float, default=None, help="pixel pitch in micrometres (default: the file's, else 4.86)"
    )
    p.add_argument(
        "--focal-mm",
        type=float,
        default=None,
        help="lens focal length in millimetres; ties cycles/pixel to cycles/degree "
        "(without it the best scale is fitted and reported)",
    )
    p.add_argument(
        "--csf",
        action="append",
        default=None,
        metavar="MODEL",
        help="CSF model (repeatable; default all: mannos_sakrison_1974, barten_1999, daly_1993, watson_ahumada_2005)",
    )
    p.add_argument("--out", type=Path, default=None, help="directory for PNG figures and metrics.json")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON instead of the table")


def _positive(flag: str, value: float | None, unit: str) -> float | None:
    """``value`` unchanged when None or a positive finite number; :class:`InputError` otherwise."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise InputError(f"{flag} {value!r}: must be a positive finite number of {unit}")
    return value


def run(args: argparse.Namespace) -> int:
    from ..analysis import analyse_kernel, format_analysis, write_analysis
    from ..csf import CSF_METHODS, Geometry
    from ..kernels import load_kernel_or_reference
    from ..paths import output_dir

    _positive("--pitch-um", args.pitch_um, "micrometres")
    _positive("--focal-mm", args.focal_mm, "millimetres")
    if args.out is not None:
        output_dir(args.out, flag="--out")  # before the analysis, not after it
    pitch_m = None if args.pitch_um is None else args.pitch_um * 1e-6
    kernel = load_kernel_or_reference(args.kernel, pitch_m)
    geometry = None
    if args.focal_mm is not None:
        geometry = Geometry(kernel.pitch_m, args.focal_mm * 1e-3)
    methods = args.csf or list(CSF_METHODS)
    analysis = analyse_kernel(kernel, geometry=geometry, methods=methods)
    if args.json:
        print(json.dumps(analysis.to_dict(), indent=1))
    else:
        print(format_analysis(analysis))
    if args.out is not None:
        paths = write_analysis(analysis, args.out)
        print("\nwrote " + ", ".join(str(p) for p in paths.values()))
    return 0
