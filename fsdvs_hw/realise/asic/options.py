"""Fit options of :func:`~fsdvs_hw.realise.asic.fit_asic_taps`: type, unit, range, default, meaning.

The design loader checks a ``[realisations.asic]`` table against :class:`AsicOptions` and
:func:`fit_asic_taps` checks its own arguments against it at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words. The ranges are the fit function's own (see its docstring).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from ...schema import PyObject, StrictModel, field
from ...validation import PITCH_RANGE_M

__all__ = ["AsicOptions"]


class AsicOptions(StrictModel):
    """Keyword options of :func:`~fsdvs_hw.realise.asic.fit_asic_taps`."""

    unknown_key = "unknown option of fit_asic_taps"

    bits: int = field(8, "bit", "signed tap width including the sign", ge=2, le=24)
    pitch_m: float | None = field(
        None, "m", "pixel pitch (default: the kernel's)", ge=PITCH_RANGE_M[0], le=PITCH_RANGE_M[1]
    )
    symmetry: Literal["auto", "none", "quadrant", "8-fold"] = field("auto", "", "symmetry imposed on the taps")
    scale: Annotated[float, Field(gt=0.0)] | Literal["free", "pow2"] = field(
        "free", "", "tap scale: 'free', 'pow2' or a fixed positive number"
    )
    adder_weight: float = field(0.0, "", "price of one adder in squared relative error", ge=0.0)
    input_bits: int = field(8, "bit", "unsigned pixel width the accumulator is sized for", ge=1, le=32)
    pre_add: bool = field(True, "", "count and build symmetric pre-adds")
    objective: Literal["kernel", "csf"] = field("kernel", "", "what the error term measures")
    csf_method: Literal["mannos_sakrison_1974", "barten_1999", "daly_1993", "watson_ahumada_2005"] = field(
        "mannos_sakrison_1974", "", "CSF model for objective 'csf'"
    )
    geometry: PyObject | None = field(None, "", "fsdvs_hw.csf.Geometry (pixels per degree) for objective 'csf'")
