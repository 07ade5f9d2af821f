"""Flags shared by the verbs that run design points (``explore``, ``sweep``): where and how to run."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..limits import MAX_POINTS, MAX_WORKERS, check_count

__all__ = ["add_execution_arguments", "int_in", "scheduler_address", "security_from_args"]


def int_in(lo: int, hi: int) -> Any:
    """argparse ``type`` of an integer flag with documented limits ``[lo, hi]`` (:mod:`fsdvs_hw.limits`):
    a value outside is refused while parsing, one line naming the flag, the value and the range."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text[:40]!r} is not an integer; allowed: [{lo}, {hi}]") from None
        try:
            return check_count("", value, lo, hi)
        except InputError as exc:
            raise argparse.ArgumentTypeError(str(exc).strip()) from None

    parse.__name__ = "integer"  # argparse names the type in its messages
    return parse


def scheduler_address(text: str) -> str:
    """argparse ``type`` of ``--scheduler``: the address checked before any work
    (:func:`fsdvs_hw.explore.sweep.check_scheduler_address`); a bad one is one line, exit 2."""
    from ..explore.sweep import check_scheduler_address

    try:
        return check_scheduler_address(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--scheduler ")) from None


def add_execution_arguments(parser: argparse.ArgumentParser) -> None:
    """``--workers``, ``--scheduler``, ``--tls-*``, ``--no-progress``, ``--retry-errors``, ``--max-points``."""
    parser.add_argument(
        "--workers",
        type=int_in(1, MAX_WORKERS),
        default=None,
        help=f"local worker processes, 1..{MAX_WORKERS} (default: [run] workers)",
    )
    parser.add_argument(
        "--scheduler",
        type=scheduler_address,
        default=None,
        metavar="tls://HOST:PORT",
        help="run on a Dask distributed scheduler instead of local processes (tls:// with the "
        "--tls-* files; plain tcp:// only on a trusted network)",
    )
    parser.add_argument(
        "--tls-ca-file",
        type=Path,
        default=None,
        metavar="PEM",
        help="CA certificate of the Dask cluster (tls:// schedulers)",
    )
    parser.add_argument("--tls-cert", type=Path, default=None, metavar="PEM", help="this client's certificate")
    parser.add_argument("--tls-key", type=Path, default=None, metavar="PEM", help="this client's private key")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument(
        "--retry-errors",
        action="store_true",
        help="rerun this design's points stored as failed (finished points, and other "
        "designs' points in the same store, are always kept)",
    )
    parser.add_argument(
        "--max-points",
        type=int_in(1, MAX_POINTS),
        default=None,
        metavar="N",
        help="refuse sweeps of more than N design points (default: [run] max_points)",
    )


def security_from_args(args: argparse.Namespace) -> Any:
    """The :func:`~fsdvs_hw.explore.sweep.dask_security` of the ``--tls-*`` flags, or None when none is given."""
    files = (args.tls_ca_file, args.tls_cert, args.tls_key)
    if all(f is None for f in files):
        return None
    if args.scheduler is None or not args.scheduler.startswith("tls://"):
        raise InputError("--tls-ca-file/--tls-cert/--tls-key need --scheduler tls://HOST:PORT")
    from ..explore.sweep import dask_security

    return dask_security(*files)
