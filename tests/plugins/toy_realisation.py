"""A fourth realisation added from outside the package, in this one file: a box filter.

A ``width`` × ``width`` uniform (moving-average) window times one gain, the least-squares fit of
that shape to the target; one option (``width``, odd, in pixels) and one cost item
(``box_width``, in pixels — a unit no built-in realisation uses for its Pareto axis, so a test can
see that the report keeps it). Registering it takes no edit anywhere in fsdvs_hw: importing this
module calls :func:`~fsdvs_hw.realise.registry.register_realisation`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

from fsdvs_hw import schema
from fsdvs_hw.kernels import MAX_KERNEL_SIZE, Kernel
from fsdvs_hw.realise import CostItem, CostSpec, RealisationSpec, register_realisation
from fsdvs_hw.validation import PITCH_RANGE_M, check_fit_arguments

__all__ = ["BoxDesign", "fit_box", "BoxOptions", "SPEC"]


class BoxOptions(schema.StrictModel):
    """Keyword options of :func:`fit_box`."""

    unknown_key = "unknown option of fit_box"

    width: int = schema.field(3, "px", "side of the uniform window", ge=1, le=MAX_KERNEL_SIZE, odd=True)
    pitch_m: Optional[float] = schema.field(
        None, "m", "pixel pitch (default: the kernel's)", ge=PITCH_RANGE_M[0], le=PITCH_RANGE_M[1]
    )


@dataclass(frozen=True, eq=False)
class BoxDesign:
    """A uniform ``width`` × ``width`` window of total gain ``gain``, on the target's grid."""

    target: Kernel
    width: int
    gain: float
    pitch_m: float
    kind: str = field(default="box", init=False)

    def kernel(self) -> Kernel:
        k = self.target.size
        taps = np.zeros((k, k))
        lo = (k - self.width) // 2
        taps[lo : lo + self.width, lo : lo + self.width] = self.gain / self.width**2
        return Kernel(taps, pitch_m=self.pitch_m, name=f"box {self.width}x{self.width}")

    def cost(self) -> dict[str, CostItem]:
        return {
            "box_width": CostItem(self.width, "px", "side of the uniform window"),
            "adders": CostItem(self.width**2 - 1, "count", "two-input adders of a direct sum"),
        }

    def describe(self) -> str:
        return f"box filter {self.width}x{self.width}, gain {self.gain:.4g}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "target": self.target.to_dict(),
            "width": self.width,
            "gain": self.gain,
            "pitch_m": self.pitch_m,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> BoxDesign:
        return cls(Kernel.from_dict(data["target"]), int(data["width"]), float(data["gain"]), float(data["pitch_m"]))


def fit_box(kernel: Kernel, *, width: int = 3, pitch_m: float | None = None) -> BoxDesign:
    """Least-squares gain of a ``width`` × ``width`` box against ``kernel`` (width ≤ kernel size)."""
    check_fit_arguments(BoxOptions, locals())
    width = min(width, kernel.size)
    shape = BoxDesign(kernel, width, 1.0, kernel.pitch_m if pitch_m is None else pitch_m).kernel().taps
    gain = float((shape * kernel.taps).sum() / (shape * shape).sum())
    return BoxDesign(kernel, width, gain, kernel.pitch_m if pitch_m is None else pitch_m)


SPEC = register_realisation(
    RealisationSpec(
        name="box",
        fit=fit_box,
        options=BoxOptions,
        record_type=BoxDesign,
        costs=(CostSpec("box_width", "px", "box width", pareto=True, headline=True), CostSpec("adders", "count")),
        artifacts={},
        colour="#8c564b",
        description="uniform box filter (test plugin)",
    ),
    replace=True,
)
