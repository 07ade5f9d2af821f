"""Fit options of :func:`~fsdvs_hw.realise.asic.fit_asic_taps`: type, unit, range, default, meaning.

The design loader checks a ``[realisations.asic]`` table against :data:`OPTIONS` and
:func:`fit_asic_taps` checks its own arguments against it at its first line
(:func:`fsdvs_hw.validation.check_fit_arguments`), so both refuse the same values with the same
words. The ranges are the fit function's own (see its docstring).
"""

from __future__ import annotations

from ...validation import PITCH_RANGE_M, Option, option

__all__ = ["OPTIONS"]

#: option → schema
OPTIONS: dict[str, Option] = {
    "bits": option("int", 8, "bit", "signed tap width including the sign", lo=2, hi=24),
    "pitch_m": option("float", None, "m", "pixel pitch (default: the kernel's)", nullable=True,
                      lo=PITCH_RANGE_M[0], hi=PITCH_RANGE_M[1]),
    "symmetry": option("str", "auto", "", "symmetry imposed on the taps",
                       choices=("auto", "none", "quadrant", "8-fold")),
    "scale": option("float|str", "free", "", "tap scale: 'free', 'pow2' or a fixed positive number",
                    lo=0.0, lo_open=True, choices=("free", "pow2")),
    "adder_weight": option("float", 0.0, "", "price of one adder in squared relative error", lo=0.0),
    "input_bits": option("int", 8, "bit", "unsigned pixel width the accumulator is sized for", lo=1, hi=32),
    "pre_add": option("bool", True, "", "count and build symmetric pre-adds"),
    "objective": option("str", "kernel", "", "what the error term measures", choices=("kernel", "csf")),
    "csf_method": option("str", "mannos_sakrison_1974", "", "CSF model for objective 'csf'",
                         choices=("mannos_sakrison_1974", "barten_1999", "daly_1993", "watson_ahumada_2005")),
    "geometry": option("object", None, "", "fsdvs_hw.csf.Geometry (pixels per degree) for objective 'csf'",
                       nullable=True),
}
