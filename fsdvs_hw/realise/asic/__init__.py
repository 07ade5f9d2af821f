"""Quantised integer-tap ASIC realisation: a shift-add digital filter with bit-exact RTL.

Modules
-------
fit
    :class:`AsicDesign` and :func:`fit_asic_taps` (nlopt scale search + integer tap search).
arith
    The bit-exact integer model every score and the RTL are checked against.
rtl
    Verilog generation, Icarus simulation and yosys synthesis on the liberty file shipped in
    ``data/fsdvs_demo45.lib``.
bench
    ``fsdvs-hw bench asic``.
"""

from .fit import OBJECTIVES, SCALE_MODES, AsicDesign, exhaustive_asic_taps, fit_asic_taps

__all__ = ["AsicDesign", "fit_asic_taps", "SCALE_MODES", "OBJECTIVES", "exhaustive_asic_taps"]
