"""Generated Verilog against the bit-exact integer model (Icarus Verilog) and yosys synthesis."""

from __future__ import annotations

import re

import numpy as np
import pytest

from fsdvs_hw.errors import InputError, ToolMissingError
from fsdvs_hw.kernels import Kernel, reference_kernel
from fsdvs_hw.realise.asic import rtl as asic_rtl
from fsdvs_hw.realise.asic import fit_asic_taps
from fsdvs_hw.realise.asic.arith import accumulator_range, integer_correlate
from fsdvs_hw.realise.asic.rtl import LIBERTY_PATH, generate_verilog, simulate_rtl, synthesise_verilog

from conftest import require_tool


def _test_images(rng, input_bits: int, n_random: int = 2, side: int = 16) -> np.ndarray:
    """Random, all-zero, all-maximum and the two images that drive the accumulator to its extremes' signs."""
    xmax = (1 << input_bits) - 1
    rand = rng.integers(0, xmax + 1, size=(n_random, side, side), dtype=np.int64)
    checker = xmax * ((np.indices((side, side)).sum(axis=0) % 2) == 0)
    return np.concatenate([rand, np.zeros((1, side, side), np.int64), np.full((1, side, side), xmax), checker[None]])


def _assert_bit_exact(taps, images, input_bits, out_shift=0, symmetry="none"):
    rtl = simulate_rtl(taps, images, input_bits=input_bits, out_shift=out_shift, symmetry=symmetry)
    model = integer_correlate(images, taps, input_bits=input_bits, out_shift=out_shift)
    mismatches = int(np.count_nonzero(rtl != model))
    assert mismatches == 0, f"{mismatches} RTL/model mismatches"
    return rtl


@pytest.mark.tools
@pytest.mark.parametrize(
    "name, size, bits, symmetry, out_shift",
    [("dog", 3, 8, "8-fold", 0), ("dog", 5, 6, "8-fold", 3), ("log", 7, 8, "8-fold", 0), ("dog", 7, 8, "none", 5)],
)
def test_rtl_matches_integer_model_on_reference_kernels(rng, name, size, bits, symmetry, out_shift):
    require_tool("iverilog")
    d = fit_asic_taps(reference_kernel(name, size), bits)
    images = _test_images(rng, d.input_bits)
    rtl = _assert_bit_exact(d.taps, images, d.input_bits, out_shift, symmetry if d.symmetry == "8-fold" else "none")
    assert np.any(rtl != 0)  # the comparison is not between two all-zero arrays
    assert np.all(rtl[2] == 0)  # the all-zero image
    if out_shift == 0:  # all-max image: every window gives the sum of the taps times xmax
        assert np.all(rtl[3] == d.taps.sum() * 255)


@pytest.mark.tools
def test_rtl_extreme_taps_and_widths(rng):
    require_tool("iverilog")
    # 2-bit taps on 1-bit pixels, 16-bit taps on 16-bit pixels, a random asymmetric kernel
    d2 = fit_asic_taps(reference_kernel("dog", 5), 2, input_bits=1)
    _assert_bit_exact(d2.taps, _test_images(rng, 1, side=12), 1)
    d16 = fit_asic_taps(reference_kernel("dog", 3), 16, input_bits=16)
    rtl = _assert_bit_exact(d16.taps, _test_images(rng, 16, side=10), 16, symmetry="8-fold")
    lo, hi = accumulator_range(d16.taps, 16)
    assert rtl.max() <= hi and rtl.min() >= lo
    assert d16.accumulator_bits >= 16 + int(np.abs(d16.taps).max()).bit_length() + 1  # sign + pixel + tap bits
    rough = Kernel(rng.normal(size=(5, 5)), name="random")
    dr = fit_asic_taps(rough, 10, input_bits=10)
    assert dr.symmetry == "none"
    x = _test_images(rng, 10, side=11)
    _assert_bit_exact(dr.taps, x, 10, out_shift=4)
    # the accumulator extremes are reached exactly: all-max where taps are positive / negative
    for sign in (1, -1):
        xm = (1023 * (sign * dr.taps > 0)).astype(np.int64)
        img = np.tile(xm, (3, 3))[:11, :11][None]
        _assert_bit_exact(dr.taps, img, 10)


@pytest.mark.tools
def test_rtl_dominant_tap_is_a_delay_line(rng):
    require_tool("iverilog")
    t = np.full((3, 3), 1e-4)
    t[1, 1] = 1.0
    d = fit_asic_taps(Kernel(t, name="dominant"), 8)
    assert np.count_nonzero(d.taps) == 1
    x = _test_images(rng, 8, side=9)
    rtl = simulate_rtl(d.taps, x, input_bits=8)
    assert np.array_equal(rtl, d.taps[1, 1] * x[:, 1:-1, 1:-1])


@pytest.mark.tools
def test_synthesis_reports_cells_and_liberty_area():
    require_tool("yosys")
    small = fit_asic_taps(reference_kernel("dog", 3), 3)
    big = fit_asic_taps(reference_kernel("dog", 3), 10)
    r_small = synthesise_verilog(small.verilog(image_width=8, image_height=8))
    r_big = synthesise_verilog(big.verilog(image_width=8, image_height=8))
    lib = LIBERTY_PATH.read_text()
    area_um2 = {c: float(a) for c, a in re.findall(r"cell \((\w+)\) \{\s*area : ([0-9.]+);", lib)}
    for r in (r_small, r_big):
        assert set(r.cell_types) <= set(area_um2)
        assert r.cells == sum(r.cell_types.values())
        assert r.area_m2 == pytest.approx(sum(n * area_um2[c] * 1e-12 for c, n in r.cell_types.items()), rel=1e-6)
        # at least the two 8-pixel line buffers of 8-bit words are flip-flops
        assert r.flip_flops >= 2 * 8 * 8
    assert big.adders > small.adders and r_big.cells > r_small.cells
    d = big.synthesise(image_width=8, image_height=8)
    c = d.cost()
    assert c["yosys_cells"].value == r_big.cells and c["area_m2"].unit == "m^2"
    assert c["area_m2"].value == pytest.approx(r_big.area_m2)
    # the arithmetic alone: fewer cells than the whole filter, only the output register as flip-flops
    assert 0 < c["datapath_cells"].value < c["yosys_cells"].value
    assert d.synthesis["datapath_flip_flops"] <= big.output_bits()
    small_dp = small.synthesise(image_width=8, image_height=8).cost()["datapath_cells"].value
    assert small_dp < c["datapath_cells"].value


def test_verilog_generator_checks_its_arguments():
    q = np.array([[1, 0, 0], [0, 2, 0], [0, 0, 0]])
    with pytest.raises(InputError, match="not 8-fold-symmetric"):
        generate_verilog(q, input_bits=8, image_width=8, image_height=8, symmetry="8-fold")
    with pytest.raises(InputError, match="image_width"):
        generate_verilog(q, input_bits=8, image_width=2, image_height=8)
    with pytest.raises(InputError, match="module_name"):
        generate_verilog(q, input_bits=8, image_width=8, image_height=8, module_name="1bad")
    with pytest.raises(InputError, match="out_shift"):
        generate_verilog(q, input_bits=8, image_width=8, image_height=8, out_shift=40)
    src = generate_verilog(q, input_bits=8, image_width=8, image_height=8)
    code = "\n".join(line.split("//")[0] for line in src.splitlines())
    assert "*" not in code and "<<" in code  # constant coefficients as shifts and adds, no multipliers


def test_missing_simulator_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(asic_rtl.shutil, "which", lambda name: None)
    with pytest.raises(ToolMissingError, match="iverilog not found"):
        simulate_rtl(np.ones((3, 3), dtype=np.int64), np.zeros((5, 5), dtype=np.int64), input_bits=8)
    with pytest.raises(ToolMissingError, match="yosys not found"):
        synthesise_verilog("module m; endmodule")


@pytest.mark.slow
@pytest.mark.tools
def test_rtl_larger_kernel_and_image_bit_exact(rng):
    """9×9 kernel, 12-bit taps, 12-bit pixels, 40×33 frames streamed back to back, rounding shift."""
    require_tool("iverilog")
    d = fit_asic_taps(reference_kernel("log", 9, sigma_px=1.5), 12, input_bits=12, symmetry="quadrant")
    x = np.concatenate(
        [rng.integers(0, 4096, size=(3, 40, 33)), np.zeros((1, 40, 33), np.int64), np.full((1, 40, 33), 4095, np.int64)]
    )
    for shift in (0, 7):
        _assert_bit_exact(d.taps, x, 12, out_shift=shift, symmetry="quadrant")


@pytest.mark.tools
@pytest.mark.parametrize("bits, input_bits", [(3, 8), (16, 16)])
def test_rtl_bit_exact_with_the_most_negative_twos_complement_tap(rng, bits, input_bits):
    # issue 13: taps use the full range -2**(bits-1) .. 2**(bits-1)-1; the RTL must agree bit for bit
    require_tool("iverilog")
    lo = -(1 << (bits - 1))
    t = np.ones((3, 3))
    t[1, 1] = lo
    d = fit_asic_taps(Kernel(t, name="most negative centre"), bits, input_bits=input_bits)
    assert d.taps[1, 1] == lo and d.error == 0.0
    spot = np.zeros((1, 9, 9), np.int64)
    spot[0, 4, 4] = (1 << input_bits) - 1  # one bright pixel under the centre tap: the most negative sum
    x = np.concatenate([_test_images(rng, input_bits, side=9), spot])
    rtl = _assert_bit_exact(d.taps, x, input_bits, symmetry="8-fold")
    lo_acc, hi_acc = accumulator_range(d.taps, input_bits)
    assert rtl.min() == lo_acc  # the all-max image drives the centre to its most negative value
    assert lo_acc == lo * ((1 << input_bits) - 1)
    if bits == 3:
        require_tool("yosys")
        r = synthesise_verilog(d.verilog(image_width=8, image_height=8))
        assert r.cells > 0 and r.area_m2 > 0


@pytest.mark.parametrize("out_shift", [0, 3])
def test_datapath_module_applies_the_output_shift(out_shift):
    """The synthesis datapath registers ``acc_r`` shifted right by ``out_shift`` (bits ``[.. : 3]`` of the
    rounded sum) or the plain accumulator at 0."""
    d = fit_asic_taps(reference_kernel("dog", 5), 6)
    src = asic_rtl.generate_datapath_verilog(d.taps, input_bits=8, out_shift=out_shift)
    last = [line.strip() for line in src.splitlines() if "out_value <=" in line]
    assert last == [f"out_value <= {'acc_s' if out_shift else 'acc'};"]
    if out_shift:
        assert re.search(r"wire signed \[\d+:0\] acc_s = acc_r\[\d+:3\];", src)
