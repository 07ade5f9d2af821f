"""The display of the sensor-in-the-loop emulation track, as the ``[emulation]`` section sets it.

:mod:`fsdvs_hw.explore.emulation` shows the filtered video on this display; reading a design
checks that the display it describes can be built (black below peak, ...).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import InputError

__all__ = ["DisplaySettings"]


@dataclass(frozen=True)
class DisplaySettings:
    """The monitor of the sensor-in-the-loop track.

    Parameters
    ----------
    bits : int
        Bit depth of the drive code (1 … 16).
    gamma : float
        Display gamma (1 … 4); emitted luminance ∝ code^γ.
    peak_nits, black_nits : float
        Peak and black luminance in cd/m² (black < peak).
    upsample_factor : int
        Temporal upsampling before display (1 = none).
    upsample : {"linear_light", "flow"}
        How the new frames are made (:mod:`fsdvs_hw.explore.emulation`, step 3).
    """

    bits: int = 8
    gamma: float = 2.2
    peak_nits: float = 400.0
    black_nits: float = 0.3
    upsample_factor: int = 4
    upsample: str = "linear_light"

    def __post_init__(self) -> None:
        if not (isinstance(self.bits, int) and 1 <= self.bits <= 16):
            raise InputError(f"DisplaySettings.bits must be an integer in [1, 16], got {self.bits!r}")
        if not (1.0 <= float(self.gamma) <= 4.0):
            raise InputError(f"DisplaySettings.gamma must be in [1, 4], got {self.gamma!r}")
        if not (0.0 <= float(self.black_nits) < float(self.peak_nits)):
            raise InputError(
                f"DisplaySettings: need 0 ≤ black_nits < peak_nits, got {self.black_nits}, {self.peak_nits}"
            )
        if not (isinstance(self.upsample_factor, int) and 1 <= self.upsample_factor <= 64):
            raise InputError(
                f"DisplaySettings.upsample_factor must be an integer in [1, 64], got {self.upsample_factor!r}"
            )
        if self.upsample not in ("linear_light", "flow"):
            raise InputError(f"DisplaySettings.upsample {self.upsample!r} unknown; allowed: linear_light, flow")

    @classmethod
    def from_design(cls, section: Mapping[str, Any]) -> DisplaySettings:
        """From a design's ``[emulation]`` section."""
        return cls(
            bits=int(section["display_bits"]),
            gamma=float(section["display_gamma"]),
            peak_nits=float(section["display_peak_nits"]),
            black_nits=float(section["display_black_nits"]),
            upsample_factor=int(section["upsample_factor"]),
            upsample=str(section.get("upsample", "linear_light")),
        )
