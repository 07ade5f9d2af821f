"""What the report needs of the design besides its points: one typed, read-only record.

The report sits below the explore layer and never reads a design itself: the explore layer
(:func:`fsdvs_hw.explore.reporting.report_input`) hands it a :class:`ReportInput` — the design's
name, source, fingerprint and validated data (for ``scores.json`` and the JSON appendix), the
target kernel, the optics, sensor and CSF settings the page states, and the co-design summary
(:class:`CodesignSummary`) when ``[codesign]`` is enabled and ran.

Examples
--------
>>> from fsdvs_hw.kernels import reference_kernel
>>> r = ReportInput(name="demo", source="demo.toml", fingerprint="ab12", design_data={},
...                 target=reference_kernel("delta", 3), focal_length_m=4e-3)
>>> r.codesign_enabled, r.codesign is None
(False, True)
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from ..kernels import Kernel

__all__ = ["CodesignSummary", "ReportInput"]


@dataclass(frozen=True)
class CodesignSummary:
    """The co-design comparison as ``codesign.json`` holds it (:func:`fsdvs_hw.explore.codesign.summarise_codesign`).

    Parameters
    ----------
    cells : tuple of mapping
        One record per (realisation, task) cell: its rows (``swap``, ``finetune``, ``codesign``,
        each with its ``loss`` interval and ``recovered`` fraction), networks and clips, kernel
        errors and CSF drift, and verdict.
    settings : mapping
        The co-design settings (``epochs``, ``n_train``, ...).
    """

    cells: tuple[Mapping[str, Any], ...] = ()
    settings: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "cells", tuple(self.cells))
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))

    @classmethod
    def from_dict(cls, summary: Mapping[str, Any]) -> CodesignSummary:
        """The summary as written to ``codesign.json`` (numbers as JSON holds them), without the file.

        Parameters
        ----------
        summary : mapping
            What :func:`fsdvs_hw.explore.codesign.run_codesign` returns, or ``codesign.json``'s content.
        """
        data = json.loads(json.dumps(dict(summary), default=float))
        return cls(cells=tuple(data.get("cells", [])), settings=data.get("settings", {}))


@dataclass(frozen=True)
class ReportInput:
    """The design's settings the report reads, and the co-design summary it shows.

    Parameters
    ----------
    name, source : str
        The design's name and where it came from (its TOML file).
    fingerprint : str
        :meth:`fsdvs_hw.design.Design.fingerprint` (SHA-1 of the validated content and target taps).
    design_data : mapping
        The validated design (:meth:`fsdvs_hw.design.Design.to_dict`), JSON-ready.
    target : Kernel
        The target kernel (pitch in metres).
    focal_length_m : float
        The optics' focal length (m).
    csf_methods : tuple of str
        The CSF models of ``[analysis] csf_methods``.
    placement, positivity : str
        The sensor's filter placement and positivity handling (``[sensor]``).
    codesign_enabled : bool
        ``[codesign] enabled``.
    codesign : CodesignSummary or None
        The co-design comparison, when enabled and run (None otherwise).
    """

    name: str
    source: str
    fingerprint: str
    design_data: Mapping[str, Any]
    target: Kernel
    focal_length_m: float
    csf_methods: tuple[str, ...] = ()
    placement: str = ""
    positivity: str = ""
    codesign_enabled: bool = False
    codesign: CodesignSummary | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "csf_methods", tuple(self.csf_methods))

    def stamp(self) -> dict[str, Any]:
        """What ``scores.json`` records of the design its points came from: name, fingerprint and
        the validated data, so that a report redrawn from it can refuse another design."""
        return {"name": self.name, "fingerprint": self.fingerprint, "data": dict(self.design_data)}
