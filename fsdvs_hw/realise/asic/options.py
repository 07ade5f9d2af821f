"""Fit options of :func:`~fsdvs_hw.realise.asic.fit_asic_taps`: type, unit, range, default, meaning, rules.

The design loader checks a ``[realisations.asic]`` table against :class:`AsicOptions` and
:func:`fit_asic_taps` builds its options object from its arguments at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words, the rules between options and on the target kernel included
(:mod:`fsdvs_hw.realise.fit_options`).
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from ...kernels import Kernel
from ...schema import PyObject, field
from ...validation import PITCH_RANGE_M
from ..fit_options import FitOptions, OptionProblem
from .arith import MAX_INPUT_BITS, MAX_TAP_BITS, resolve_symmetry, symmetry_classes

__all__ = ["MAX_PDK_FRAME_WORK", "AsicOptions"]

_Corner = Literal["tt", "ff", "ss", "sf", "fs"]

#: Largest ``H · W²`` of ``pdk_frame``: the gate-level simulation grows with the pixels streamed (H·W)
#: times the cells (line buffers of W pixels); 48 × 64 took 60 s on 2 cores, so this bound is about
#: 16 minutes (e.g. 128 × 128, or 48 × 256).
MAX_PDK_FRAME_WORK: int = 16 * 48 * 64 * 64


class AsicOptions(FitOptions):
    """Keyword options of :func:`~fsdvs_hw.realise.asic.fit_asic_taps`, validated, with their rules.

    Attributes
    ----------
    bits : int
        Signed tap width including the sign, 2…24 (``-2**(bits-1) ≤ q ≤ 2**(bits-1) - 1``).
    pitch_m : float, optional
        Pixel pitch in metres (default: the kernel's; an array's is
        :data:`~fsdvs_hw.kernels.DEFAULT_PITCH_M`). It matters only to ``objective="csf"``.
    symmetry : {"auto", "none", "quadrant", "8-fold"}
        Symmetry imposed on the taps. ``auto`` picks the highest symmetry the target has (to 1e-9
        relative); an explicit one projects the target onto it first.
    scale : {"free", "pow2"} or float
        ``free``: any positive scale (nlopt DIRECT-L over log2 s, then polished); ``pow2``:
        ``2**-e`` for an integer ``e``; a positive float fixes the scale (e.g. the gain one LSB of
        the comparator threshold stands for).
    adder_weight : float
        λ ≥ 0: the price of one adder in squared relative kernel error (0: lowest error, ties to
        fewer adders). Sweep it to trace error against adders.
    input_bits : int
        Unsigned pixel width the accumulator is sized for (1…32).
    pre_add : bool
        Count (and build) symmetric pre-adds.
    objective : {"kernel", "csf"}
        What the error term measures. ``kernel``: the relative L2 kernel error (separable; exact).
        ``csf``: the relative L2 error of the 2-D frequency response weighted by the CSF,
        ``‖w (K̂_q − K̂)‖ / ‖w K̂‖`` with ``w(f) = CSF(|f| · ppd) / max CSF`` on a 64×64 DFT grid —
        errors where the eye is sensitive cost more (coordinate-wise optimum).
    csf_method : str
        CSF model for ``objective="csf"`` (see :data:`fsdvs_hw.csf.CSF_METHODS`).
    geometry : fsdvs_hw.csf.Geometry, optional
        Pixel pitch and focal length giving pixels per degree for ``objective="csf"``; without it
        the scale that best aligns the target with the CSF is fitted (:func:`fsdvs_hw.csf.csf_agreement`).
    pdk : {"sky130"}, optional
        Build the fitted taps in this process (:meth:`~fsdvs_hw.realise.asic.AsicDesign.build_in_process`):
        synthesis onto its standard cells, gate-level simulation against the integer model, static
        timing and toggle energy; the cost record's area, clock and energy then come from them.
        None (default): the literature models.
    pdk_frame : (int, int)
        Frame (H, W) in pixels the process build is made and simulated for (line buffers of W pixels);
        with ``pdk`` set, ``H · W²`` at most :data:`MAX_PDK_FRAME_WORK` (gate-level time grows so).
    corners : list of str
        Device-model corners the process build is timed at by OpenSTA, each from its committed
        liberty (25 °C, 1.8 V; ``fsdvs-hw process-cells --corners …``); the highest clock is the
        slowest corner's. With ``[process]`` in a design, its ``corners``.

    Notes
    -----
    Rule between options: with ``objective="csf"`` a ``geometry`` is a :class:`fsdvs_hw.csf.Geometry`;
    with ``pdk`` set, ``pdk_frame``'s ``H · W²`` is at most :data:`MAX_PDK_FRAME_WORK` and every
    corner has a characterised liberty.
    Rule on the target: its part with the chosen ``symmetry`` is not all zeros.
    """

    unknown_key = "unknown option of fit_asic_taps"

    bits: int = field(8, "bit", "signed tap width including the sign", ge=2, le=MAX_TAP_BITS)
    pitch_m: float | None = field(
        None, "m", "pixel pitch (default: the kernel's)", ge=PITCH_RANGE_M[0], le=PITCH_RANGE_M[1]
    )
    symmetry: Literal["auto", "none", "quadrant", "8-fold"] = field("auto", "", "symmetry imposed on the taps")
    scale: Annotated[float, Field(gt=0.0)] | Literal["free", "pow2"] = field(
        "free", "", "tap scale: 'free', 'pow2' or a fixed positive number"
    )
    adder_weight: float = field(0.0, "", "price of one adder in squared relative error", ge=0.0)
    input_bits: int = field(8, "bit", "unsigned pixel width the accumulator is sized for", ge=1, le=MAX_INPUT_BITS)
    pre_add: bool = field(True, "", "count and build symmetric pre-adds")
    objective: Literal["kernel", "csf"] = field("kernel", "", "what the error term measures")
    csf_method: Literal["mannos_sakrison_1974", "barten_1999", "daly_1993", "watson_ahumada_2005"] = field(
        "mannos_sakrison_1974", "", "CSF model for objective 'csf'"
    )
    geometry: PyObject | None = field(None, "", "fsdvs_hw.csf.Geometry (pixels per degree) for objective 'csf'")
    pdk: Literal["sky130"] | None = field(
        None, "", "build the taps in this process (sky130 standard cells); None: literature models"
    )
    pdk_frame: (
        tuple[Annotated[int, Field(ge=3, le=1024)], Annotated[int, Field(ge=3, le=1024)]]
        | Annotated[list[Annotated[int, Field(ge=3, le=1024)]], Field(min_length=2, max_length=2)]
    ) = field((48, 64), "px", "frame (H, W) the process build is made and simulated for")
    corners: (
        Annotated[tuple[_Corner, ...], Field(min_length=1, max_length=5)]
        | Annotated[list[_Corner], Field(min_length=1, max_length=5)]
    ) = field(("tt",), "", "device-model corners the process build is timed at (the clock is the slowest's)")

    def option_problems(self) -> list[OptionProblem]:
        """The rules between options (class Notes)."""
        from ...csf import Geometry

        out = []
        if self.objective == "csf" and self.geometry is not None and not isinstance(self.geometry, Geometry):
            why = f"expected a fsdvs_hw.csf.Geometry or None, got {type(self.geometry).__name__}"
            out.append(OptionProblem("geometry", self.geometry, why))
        h, w = (int(v) for v in self.pdk_frame)
        if self.pdk is not None and h * w * w > MAX_PDK_FRAME_WORK:
            why = (
                f"H·W² = {h * w * w} exceeds {MAX_PDK_FRAME_WORK} (the gate-level simulation grows as H·W²: "
                "48×64 takes about 60 s on 2 cores, this bound about 16 min); e.g. [128, 128] or [48, 256]"
            )
            out.append(OptionProblem("pdk_frame", list(self.pdk_frame), why))
        if self.pdk is not None:
            from .cell_timing import characterised_corners

            have = characterised_corners()
            if missing := [c for c in self.corners if c not in have]:
                why = (
                    f"{missing} have no characterised liberty (have: {', '.join(have)}); "
                    f"run `fsdvs-hw process-cells --corners {' '.join(missing)}`"
                )
                out.append(OptionProblem("corners", list(self.corners), why))
        return out

    def target_problems(self, target: Kernel) -> list[OptionProblem]:
        """The target's part with the chosen symmetry must not be all zeros (nothing to quantise)."""
        sym = resolve_symmetry(target.taps, self.symmetry)
        if np.any(symmetry_classes(target.size, sym).class_means(target.taps)):
            return []
        why = f"the {sym}-symmetric part of kernel '{target.name}' is all zeros; choose symmetry='none'"
        return [OptionProblem("symmetry", self.symmetry, why)]
