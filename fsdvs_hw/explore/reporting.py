"""The design's hand-off to the report: :func:`report_input` reads once what the report states.

The report layer sits below explore and takes a :class:`fsdvs_hw.report.report_input.ReportInput`
instead of a design; ``fsdvs-hw explore``, ``sweep --report`` and ``report`` build it here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..design import Design
from ..report.report_input import CodesignSummary, ReportInput

__all__ = ["report_input"]


def report_input(design: Design, *, codesign: Mapping[str, Any] | None = None) -> ReportInput:
    """The report's input for ``design``.

    Parameters
    ----------
    design : Design
        A validated design.
    codesign : mapping, optional
        The co-design summary this run produced (:func:`fsdvs_hw.explore.codesign.run_codesign`);
        shown only when the design's ``[codesign]`` is enabled.

    Returns
    -------
    ReportInput
    """
    spec = design.spec
    return ReportInput(
        name=design.name,
        source=design.source,
        fingerprint=design.fingerprint(),
        design_data=design.to_dict(),
        target=design.target,
        focal_length_m=spec.optics.focal_length_m,
        csf_methods=tuple(spec.analysis.csf_methods),
        placement=spec.sensor.placement,
        positivity=spec.sensor.positivity,
        codesign_enabled=bool(spec.codesign.enabled),
        codesign=CodesignSummary.from_dict(codesign) if codesign is not None and spec.codesign.enabled else None,
    )
