"""Redraw the report of an earlier run from the files it left, without rerunning anything.

:func:`write_report_from_scores` is the one place that reads a finished run back: it loads
``scores.json`` (the scored points) and, with ``[codesign]`` enabled, ``codesign.json`` (the
co-design summary) once, builds the same typed records an exploration hands the report
(:class:`~fsdvs_hw.records.ScoredPoint`, :class:`~fsdvs_hw.report.report_input.CodesignSummary`),
refuses a design other than the run's (:func:`check_same_design`) and writes the report
(:func:`fsdvs_hw.report.html.write_report`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..paths import write_output
from ..records import ScoredPoint
from .html import write_report
from .report_input import CodesignSummary, ReportInput

__all__ = ["check_same_design", "read_codesign", "write_report_from_scores"]


def _flat(data: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(data, Mapping) and data:
        out: dict[str, Any] = {}
        for k, v in data.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: data}


def check_same_design(src: Path, stored: Any, points: Sequence[ScoredPoint], report: ReportInput) -> None:
    """Refuse to redraw the points of ``src`` (a ``scores.json``) with a design other than theirs.

    Compares the stored fingerprint (:meth:`ReportInput.stamp`) with ``report``'s; a ``scores.json``
    written before fingerprints were kept is checked by the design name its points carry.

    Parameters
    ----------
    src : Path
        The ``scores.json`` read.
    stored : object
        Its ``"design"`` record (name, fingerprint, data), or whatever stands there.
    points : sequence of ScoredPoint
        Its points.
    report : ReportInput
        The design given for the redraw.

    Raises
    ------
    InputError
        Naming both designs (source, name, fingerprint) and the first keys that differ.
    """
    given = f"{report.source} (design {report.name!r}"
    if isinstance(stored, Mapping) and isinstance(stored.get("fingerprint"), str):
        if stored["fingerprint"] == report.fingerprint:
            return
        run_flat = _flat(stored.get("data") or {})
        now_flat = _flat(dict(report.design_data))
        diff = [
            k for k in dict.fromkeys([*run_flat, *now_flat]) if run_flat.get(k, "<unset>") != now_flat.get(k, "<unset>")
        ]
        shown = "; ".join(
            f"{k}: run {json.dumps(run_flat.get(k, '<unset>'), default=str)[:40]}, given "
            f"{json.dumps(now_flat.get(k, '<unset>'), default=str)[:40]}"
            for k in diff[:3]
        )
        more = f" and {len(diff) - 3} more" if len(diff) > 3 else ""
        raise InputError(
            f"{given}, fingerprint {report.fingerprint[:12]}) does not match the design of the run "
            f"in {src} (design {str(stored.get('name'))[:60]!r}, fingerprint "
            f"{stored['fingerprint'][:12]}); differs in {shown or 'the target kernel'}{more}; pass "
            "the design file (and --set options) the run used"
        )
    names = {str(p.extra.get("design")) for p in points if p.extra.get("design") is not None}
    if names and names != {report.name}:
        raise InputError(
            f"{given}) does not match the design of the run in {src} (its points are of design "
            f"{', '.join(repr(n[:60]) for n in sorted(names)[:3])}); pass the design file the run used"
        )


def _read_scores(out_dir: str | Path) -> tuple[Path, Mapping[str, Any], list[ScoredPoint]]:
    """``out_dir/scores.json``: its path, its content and its points as records."""
    if not Path(out_dir).is_dir():
        raise InputError(f"{out_dir}: not a folder (the --out folder of an earlier explore or sweep run)")
    src = Path(out_dir) / "scores.json"
    if src.is_symlink():  # it would be read from, and the report rewrites it, elsewhere
        raise InputError(f"--out: {src} is a symbolic link; refusing to read or write through it (remove the link)")
    try:
        data = json.loads(src.read_text())
    except FileNotFoundError:
        raise InputError(
            f"{src}: no scores.json here (write one with `fsdvs-hw explore DESIGN --out {out_dir}`)"
        ) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{src}: not a scores file (not JSON: {exc})") from None
    points = data.get("points") if isinstance(data, Mapping) else None
    if not isinstance(points, list):
        raise InputError(f"{src}: field 'points' must be the list of stored points that write_report saves")
    return src, data, [ScoredPoint.from_dict(p, where=f"{src}: points[{i}]") for i, p in enumerate(points)]


def read_codesign(path: Path) -> CodesignSummary:
    """The co-design summary in ``path`` (a ``codesign.json``); an InputError when it is not one."""
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a co-design summary (not JSON: {exc})") from None
    if not isinstance(data, Mapping) or not isinstance(data.get("cells", []), list):
        raise InputError(f"{path}: not a co-design summary (expected a JSON object with a 'cells' list)")
    return CodesignSummary.from_dict(data)


def write_report_from_scores(out_dir: str | Path, report: ReportInput, *, to: str | Path | None = None) -> Path:
    """Rebuild ``report.html`` from the ``scores.json`` an earlier run wrote, without rerunning anything.

    ``scores.json`` keeps every stored point with its paired task losses (``"points"``), so the
    report of ``fsdvs-hw explore`` (or ``sweep --report``) can be redrawn after a change to the
    report code, or into another folder. With ``[codesign]`` enabled, the run's ``codesign.json``
    is read too (and copied along when the report goes into another folder).

    Parameters
    ----------
    out_dir : path
        Folder of the earlier run (holds ``scores.json``).
    report : ReportInput
        The design the run used (:func:`fsdvs_hw.explore.reporting.report_input` of
        :func:`fsdvs_hw.design.load_design`; the report layer sits below explore and does
        not load designs itself).
    to : path, optional
        Folder to write ``report.html``, ``scores.csv`` and ``scores.json`` into (default:
        ``out_dir`` itself, replacing the report there).

    Returns
    -------
    Path
        The written ``report.html``.

    Raises
    ------
    InputError
        ``out_dir`` is not a folder; ``out_dir/scores.json`` is missing, is not JSON, or holds no
        ``"points"`` list of stored points, or ``codesign.json`` is not a co-design summary; ``report``
        is not a loaded design's report input, or not of the design the run used
        (:func:`check_same_design`); a file to write is a symbolic link.

    Examples
    --------
    >>> from fsdvs_hw.design import load_design
    >>> from fsdvs_hw.explore.reporting import report_input
    >>> write_report_from_scores("out/demo", report_input(load_design("designs/default.toml")))  # doctest: +SKIP
    PosixPath('out/demo/report.html')
    """
    src, data, points = _read_scores(out_dir)
    if not isinstance(report, ReportInput):
        raise InputError(
            f"write_report_from_scores: design must be a loaded design "
            f"(fsdvs_hw.explore.reporting.report_input(fsdvs_hw.design.load_design(path))), "
            f"got {type(report).__name__}"
        )
    check_same_design(src, data.get("design"), points, report)
    dest = Path(to) if to is not None else Path(out_dir)
    extra = Path(out_dir) / "codesign.json"  # the co-design rows shown beside the report
    if extra.is_file() and dest.resolve() != Path(out_dir).resolve():
        dest.mkdir(parents=True, exist_ok=True)
        write_output(dest / extra.name, extra.read_bytes(), flag="--to")
    shown = dest / extra.name  # the copy beside the report
    if report.codesign_enabled and shown.is_file():
        report = replace(report, codesign=read_codesign(shown))
    return write_report(points, report, dest)
