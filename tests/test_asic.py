"""Quantised ASIC taps: CSD arithmetic, symmetry, the bit-exact integer model and the tap fit."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
from scipy.signal import correlate2d

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import Kernel, reference_kernel
from fsdvs_hw.realise.asic import AsicDesign, exhaustive_asic_taps, fit_asic_taps
from fsdvs_hw.realise.asic.arith import (
    tap_range,
    accumulator_bits,
    accumulator_range,
    adder_count,
    csd_digits,
    csd_weight,
    integer_correlate,
    output_bits,
    symmetry_classes,
)
from fsdvs_hw.realise import Realisation, kernel_error, realisation_from_dict


# ---------------------------------------------------------------------------- CSD
def _min_signed_digits(n: int, width: int = 12) -> int:
    """Brute force: fewest non-zero digits of any {-1,0,1} representation of n (oracle)."""
    best = math.inf
    for digits in itertools.product((-1, 0, 1), repeat=width):
        if sum(d << i for i, d in enumerate(digits)) == n:
            best = min(best, sum(d != 0 for d in digits))
    return best


@pytest.mark.parametrize("n", [0, 1, -1, 3, 7, 11, -11, 15, 21, 43, 85, 127, -128, 255, 341])
def test_csd_reconstructs_nonadjacent_and_minimal(n):
    d = csd_digits(n)
    assert sum(s * (1 << sh) for sh, s in d) == n
    shifts = [sh for sh, _ in d]
    assert all(b - a >= 2 for a, b in zip(shifts, shifts[1:])), "CSD digits must be non-adjacent"
    assert len(d) == csd_weight(n) == _min_signed_digits(n, width=10)


def test_csd_weight_vectorised_matches_digits_and_never_exceeds_binary():
    v = np.arange(-5000, 5001)
    w = csd_weight(v)
    assert np.array_equal(w, [len(csd_digits(int(x))) for x in v])
    assert np.all(w <= np.bitwise_count(np.abs(v)))
    assert csd_weight(7) == 2 and csd_weight(11) == 3 and csd_weight(0) == 0  # 8-1, 16-4-1


# ---------------------------------------------------------------------------- symmetry & adders
@pytest.mark.parametrize("size, counts", [(3, (9, 4, 3)), (7, (49, 16, 10)), (9, (81, 25, 15))])
def test_symmetry_class_counts_and_invariance(size, counts):
    for sym, n in zip(("none", "quadrant", "8-fold"), counts):
        c = symmetry_classes(size, sym)
        assert c.n_classes == n and c.sizes.sum() == size * size
        lab = c.labels
        if sym != "none":
            assert np.array_equal(lab, lab[::-1]) and np.array_equal(lab, lab[:, ::-1])
        if sym == "8-fold":
            assert np.array_equal(lab, lab.T)
        if sym == "quadrant":
            assert not np.array_equal(lab, lab.T) or size == 1


def test_adder_count_by_hand():
    q = np.array([[3, -1, 3], [-1, 7, -1], [3, -1, 3]])
    # per tap: corners 3 = 4-1 (2 terms) x4, edges 1 term x4, centre 7 = 8-1 (2 terms): 14 terms
    assert adder_count(q) == 13
    # 8-fold pre-adds: 3 + 3 pre-adders, then 2 + 1 + 2 = 5 terms -> 6 + 4
    assert adder_count(q, symmetry_classes(3, "8-fold")) == 10
    assert adder_count(np.array([[0, 0, 0], [0, 4, 0], [0, 0, 0]])) == 0
    with pytest.raises(InputError, match="not constant"):
        adder_count(np.array([[1, 0, 0], [0, 4, 0], [0, 0, 0]]), symmetry_classes(3, "8-fold"))


# ---------------------------------------------------------------------------- integer model
def test_integer_model_equals_scipy_correlation(rng):
    q = rng.integers(-100, 101, size=(5, 5))
    x = rng.integers(0, 1024, size=(3, 13, 11))
    y = integer_correlate(x, q, input_bits=10)
    assert y.dtype == np.int64 and y.shape == (3, 9, 7)
    for n in range(3):
        assert np.array_equal(y[n], correlate2d(x[n], q, mode="valid"))


def test_output_shift_rounds_half_up():
    x = np.array([[1]])
    assert integer_correlate(x, np.array([[3]]), input_bits=1, out_shift=1)[0, 0] == 2  # 1.5 -> 2
    assert integer_correlate(x, np.array([[-3]]), input_bits=1, out_shift=1)[0, 0] == -1  # -1.5 -> -1
    assert integer_correlate(x, np.array([[-5]]), input_bits=1, out_shift=2)[0, 0] == -1  # -1.25 -> -1
    assert integer_correlate(x, np.array([[-7]]), input_bits=1, out_shift=2)[0, 0] == -2  # -1.75 -> -2


def test_accumulator_width_is_tight_and_attained(rng):
    q = rng.integers(-300, 301, size=(7, 7))
    for b in (1, 8, 12):
        n = accumulator_bits(q, b)
        lo, hi = accumulator_range(q, b)
        xmax = (1 << b) - 1
        # the images that attain the extremes: all-max where the tap is positive (negative)
        assert integer_correlate(xmax * (q > 0).astype(np.int64), q, input_bits=b)[0, 0] == hi
        assert integer_correlate(xmax * (q < 0).astype(np.int64), q, input_bits=b)[0, 0] == lo
        assert -(1 << (n - 1)) <= lo and hi < (1 << (n - 1))
        assert lo < -(1 << (n - 2)) or hi >= (1 << (n - 2)), "one bit fewer must overflow"
    assert output_bits(q, 8, 4) < output_bits(q, 8, 0) == accumulator_bits(q, 8)


def test_accumulator_grows_then_clear_error_on_overflow():
    q = np.full((7, 7), (1 << 23) - 1, dtype=np.int64)
    widths = [accumulator_bits(q, b) for b in range(1, 31)]
    # all taps positive: the sign bit plus the bits of 49 * qmax * (2**b - 1)
    assert widths == [(49 * ((1 << 23) - 1) * ((1 << b) - 1)).bit_length() + 1 for b in range(1, 31)]
    assert widths[-1] == 60
    with pytest.raises(InputError, match=r"input_bits=32: the accumulator would need 62 bits.*input_bits <= 30"):
        accumulator_bits(q, 32, limit=60)
    with pytest.raises(InputError, match="input_bits"):
        integer_correlate(np.zeros((7, 7), dtype=np.int64), q, input_bits=40)


@pytest.mark.parametrize(
    "image, kwargs, match",
    [
        (np.full((8, 8), 256), {"input_bits": 8}, r"\[0, 255\]"),
        (np.full((8, 8), -1), {"input_bits": 8}, r"\[0, 255\]"),
        (np.zeros((8, 8)), {"input_bits": 8}, "integer array"),
        (np.zeros((2, 8), dtype=int), {"input_bits": 8}, "smaller than"),
        (np.zeros((8, 8), dtype=int), {"input_bits": 8, "out_shift": -1}, "out_shift"),
        (np.zeros((8, 8), dtype=int), {"input_bits": 0}, "input_bits"),
    ],
)
def test_integer_model_rejects_bad_input(image, kwargs, match):
    with pytest.raises(InputError, match=match):
        integer_correlate(image, np.ones((3, 3), dtype=np.int64), **kwargs)


# ---------------------------------------------------------------------------- the fit
def _tiny_kernels():
    dog3 = reference_kernel("dog", 3)
    quad = Kernel(np.array([[0.1, -0.35, 0.1], [0.22, 1.0, 0.22], [0.1, -0.35, 0.1]]), name="quadrant3")
    rough = Kernel(np.array([[0.3, -0.2, 0.05], [-0.6, 1.0, -0.45], [0.12, -0.3, 0.2]]), name="rough3")
    return [(dog3, "8-fold", (2, 3, 4, 5)), (quad, "quadrant", (2, 3, 4)), (rough, "none", (2,))]


@pytest.mark.parametrize("adder_weight", [0.0, 1e-3, 2e-2])
def test_integer_search_matches_exhaustive_optimum(adder_weight):
    for kernel, sym, bit_list in _tiny_kernels():
        for bits in bit_list:
            d = fit_asic_taps(kernel, bits, symmetry=sym, adder_weight=adder_weight)
            q, s, J = exhaustive_asic_taps(kernel, bits, symmetry=sym, adder_weight=adder_weight)
            assert d.fit_info["objective"] == pytest.approx(J, rel=1e-9, abs=1e-14), (kernel.name, bits)
            if adder_weight == 0:
                assert d.error == pytest.approx(kernel_error(s * q, kernel), rel=1e-9)


def test_error_falls_with_bits_and_nlopt_beats_naive_scale():
    k = reference_kernel("dog", 7)
    designs = [fit_asic_taps(k, b) for b in range(2, 17)]
    err = np.array([d.error for d in designs])
    assert np.all(np.diff(err) <= 1e-12), err  # more bits never hurt (nested candidate sets)
    assert err[-1] < 1e-4 and err[6] < 0.02  # 16 bits; 8 bits
    naive = np.array([d.fit_info["naive_error"] for d in designs])
    assert np.all(err <= naive + 1e-12)
    assert np.any(err < 0.8 * naive), "the scale search should beat max|k| scaling somewhere"
    # rounding bound: each class off by at most half a step (no clipping at the optimum)
    for d in designs[4:]:
        bound = 0.5 * d.scale * math.sqrt(k.taps.size) / np.linalg.norm(k.taps)
        assert d.error <= bound


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_free_scale_never_worse_than_naive_rounding_on_asymmetric_kernels(seed):
    r = np.random.default_rng(seed)
    t = 0.05 * r.normal(size=(7, 7))
    t[3, 3] = 1.0  # a learned-like kernel: dominant centre, small asymmetric surround
    k = Kernel(t, name=f"rough{seed}")
    for bits in (4, 8, 10, 12, 14):
        d = fit_asic_taps(k, bits)
        assert d.symmetry == "none"
        assert d.error <= d.fit_info["naive_error"] * (1 + 1e-12), (bits, d.error, d.fit_info["naive_error"])


def test_pow2_scale_is_a_power_of_two_and_no_better_than_free():
    k = reference_kernel("log", 7, sigma_px=1.2)
    for bits in (4, 8, 12):
        p2 = fit_asic_taps(k, bits, scale="pow2")
        free = fit_asic_taps(k, bits)
        e = p2.fit_info["scale_exponent"]
        assert p2.scale == 2.0**-e and p2.scale_mode == "pow2"
        assert free.error <= p2.error + 1e-12


def test_adder_weight_trades_error_for_adders():
    k = reference_kernel("dog", 7)
    ds = [fit_asic_taps(k, 10, adder_weight=lam) for lam in (0.0, 1e-6, 1e-5, 1e-4, 1e-3)]
    adders = [d.adders for d in ds]
    err = [d.error for d in ds]
    assert all(b <= a for a, b in zip(adders, adders[1:])) and adders[-1] < adders[0]
    assert all(b >= a - 1e-12 for a, b in zip(err, err[1:]))


def test_extreme_bit_widths():
    k = reference_kernel("dog", 7)
    d2 = fit_asic_taps(k, 2)
    assert set(np.unique(d2.taps)) <= {-2, -1, 0, 1} and d2.accumulator_bits <= 8 + 6
    d16 = fit_asic_taps(k, 16, input_bits=16)
    assert -32768 <= d16.taps.min() and d16.taps.max() <= 32767 and np.abs(d16.taps).max() > 16383
    assert d16.error < 1e-4 and d16.accumulator_bits == accumulator_bits(d16.taps, 16)
    assert np.all(np.isfinite(d16.kernel().taps))


def test_dominant_tap():
    t = np.full((5, 5), 1e-4)
    t[2, 2] = 1.0
    k = Kernel(t, name="dominant")
    surround = math.sqrt(24) * 1e-4 / np.linalg.norm(t)
    d8 = fit_asic_taps(k, 8)
    assert np.count_nonzero(d8.taps) == 1 and d8.taps[2, 2] != 0
    assert d8.error == pytest.approx(surround, rel=1e-9)  # the surround is lost, the centre exact
    d16 = fit_asic_taps(k, 16)
    assert np.count_nonzero(d16.taps) == 25 and d16.error < 0.1 * surround


def test_rounds_to_all_zeros_is_a_clear_error():
    k = reference_kernel("dog", 7)
    with pytest.raises(InputError, match="rounds to all-zero 8-bit taps at the fixed scale"):
        fit_asic_taps(k, 8, scale=10.0)
    with pytest.raises(InputError, match="adder_weight"):
        fit_asic_taps(k, 8, adder_weight=10.0)
    d = fit_asic_taps(k, 8, scale=0.003)  # a fixed scale that works
    assert d.scale == 0.003 and d.scale_mode == "fixed"
    assert np.array_equal(d.taps, np.clip(np.round(k.taps / 0.003), -127, 127))


def test_symmetry_auto_and_projection(rng):
    assert fit_asic_taps(reference_kernel("dog", 7), 6).symmetry == "8-fold"
    y, x = np.mgrid[-3:4, -3:4]
    aniso = Kernel(np.exp(-(x**2) / 2.0 - y**2 / 8.0), name="aniso")
    assert fit_asic_taps(aniso, 6).symmetry == "quadrant"
    rough = Kernel(rng.normal(size=(5, 5)), name="random")
    assert fit_asic_taps(rough, 6).symmetry == "none"
    forced = fit_asic_taps(rough, 12, symmetry="8-fold")
    cls = symmetry_classes(5, "8-fold")
    proj = cls.expand(cls.class_means(rough.taps))
    assert np.allclose(forced.taps, forced.taps.T) and np.allclose(forced.taps, forced.taps[::-1])
    assert forced.error >= kernel_error(proj, rough) - 1e-12  # cannot beat the symmetric projection


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"bits": 1}, "bits"),
        ({"bits": 25}, "bits"),
        ({"bits": 8.5}, "bits"),
        ({"symmetry": "radial"}, "symmetry"),
        ({"scale": "log"}, "scale"),
        ({"scale": -1.0}, "scale"),
        ({"adder_weight": -1.0}, "adder_weight"),
        ({"adder_weight": float("nan")}, "adder_weight"),
        ({"objective": "psnr"}, "objective"),
        ({"input_bits": 0}, "input_bits"),
    ],
)
def test_fit_rejects_bad_arguments(kwargs, match):
    kwargs = {"bits": 8, **kwargs}
    with pytest.raises(InputError, match=match):
        fit_asic_taps(reference_kernel("dog", 7), **kwargs)


def test_fit_rejects_an_input_width_that_overflows_the_exact_model():
    box = Kernel(np.ones((15, 15)), name="box15")  # 225 * (2**23 - 1) * (2**32 - 1) needs 64 bits
    full_scale = 1.0 / ((1 << 23) - 1)  # every tap at the largest 24-bit code
    with pytest.raises(InputError, match=r"input_bits=32: the accumulator would need 64 bits"):
        fit_asic_taps(box, 24, scale=full_scale, input_bits=32)
    assert fit_asic_taps(box, 24, scale=full_scale, input_bits=31).accumulator_bits == 63
    # with a free scale every equal tap is exact, and the fewest adders win: all taps 1
    assert np.all(fit_asic_taps(box, 24, input_bits=32).taps == 1)


def test_fit_takes_taps_as_an_array_and_rejects_what_is_not_a_kernel():
    k = reference_kernel("dog", 5)
    a, b = fit_asic_taps(k, 6), fit_asic_taps(np.asarray(k), 6, pitch_m=k.pitch_m)
    assert np.array_equal(a.taps, b.taps) and a.scale == b.scale
    with pytest.raises(InputError, match="Kernel"):
        fit_asic_taps({"taps": 1}, 8)
    with pytest.raises(InputError, match="odd"):
        fit_asic_taps(np.ones((4, 4)), 8)


# ---------------------------------------------------------------------------- protocol
def test_asic_design_satisfies_the_realisation_protocol(rng):
    k = reference_kernel("dog", 5)
    d = fit_asic_taps(k, 6, input_bits=10)
    assert isinstance(d, Realisation) and d.kind == "asic"
    realised = d.kernel()
    assert np.array_equal(realised.taps, d.scale * d.taps) and realised.pitch_m == k.pitch_m
    c = d.cost()
    assert c["adders"].value == d.adders and c["adders"].unit == "count"
    assert c["accumulator_bits"].value == accumulator_bits(d.taps, 10)
    assert c["csd_digits"].value == csd_weight(d.taps).sum()
    assert "6-bit" in d.describe() and "8-fold" in d.describe()
    back = realisation_from_dict(json.loads(json.dumps(d.to_dict())))
    assert isinstance(back, AsicDesign)
    assert np.array_equal(back.taps, d.taps) and back.scale == d.scale and back.input_bits == 10
    x = rng.integers(0, 1024, size=(9, 9))
    assert np.array_equal(back.apply(x), correlate2d(x, d.taps, mode="valid"))


def test_asic_design_validates_its_fields():
    k = reference_kernel("dog", 3)
    good = fit_asic_taps(k, 4)
    with pytest.raises(InputError, match="all integer taps are zero"):
        AsicDesign(target=k, taps=np.zeros((3, 3), dtype=int), scale=1.0, scale_mode="free", bits=4, symmetry="none")
    with pytest.raises(InputError, match=r"-8 ≤ q ≤ 7"):
        AsicDesign(target=k, taps=good.taps * 10, scale=1.0, scale_mode="free", bits=4, symmetry="8-fold")
    with pytest.raises(InputError, match=r"-8 ≤ q ≤ 7"):
        AsicDesign(target=k, taps=np.full((3, 3), -9), scale=1.0, scale_mode="free", bits=4, symmetry="8-fold")
    # the most negative two's-complement code is a valid tap
    AsicDesign(target=k, taps=np.full((3, 3), -8), scale=1.0, scale_mode="free", bits=4, symmetry="8-fold")
    asym = np.array([[1, 0, 0], [0, 2, 0], [0, 0, 0]])
    with pytest.raises(InputError, match="not 8-fold-symmetric"):
        AsicDesign(target=k, taps=asym, scale=1.0, scale_mode="free", bits=4, symmetry="8-fold")
    with pytest.raises(InputError, match="missing field"):
        AsicDesign.from_dict({"kind": "asic"})


# ---------------------------------------------------------------------------- CSF-weighted objective
def test_uniform_weights_reduce_to_the_kernel_objective(rng):
    from fsdvs_hw.realise.asic.fit import _CSF_NFFT, _TapProblem

    k = reference_kernel("dog", 5)
    cls = symmetry_classes(5, "quadrant")
    plain = _TapProblem(k.taps, cls, 8, 1e-4, True)
    flat = _TapProblem(k.taps, cls, 8, 1e-4, True, weights=np.ones((_CSF_NFFT, _CSF_NFFT)), n_fft=_CSF_NFFT)
    # Parseval: the spectral Gram matrix is n² diag(m)
    assert np.allclose(flat.M, _CSF_NFFT**2 * np.diag(cls.sizes), atol=1e-6)
    for s in (0.002, 0.01, 0.05):
        q = rng.integers(-100, 101, size=cls.n_classes)
        assert flat.objective(q, s) == pytest.approx(plain.objective(q, s), rel=1e-9)
        assert np.array_equal(flat.solve(s), plain.solve(s))


def test_csf_objective_matches_exhaustive_optimum():
    from fsdvs_hw.csf import Geometry

    k = reference_kernel("dog", 3)
    g = Geometry(k.pitch_m, 4e-3)
    for bits in (2, 3, 4, 5):
        for lam in (0.0, 1e-3):
            d = fit_asic_taps(k, bits, objective="csf", geometry=g, adder_weight=lam)
            _, _, J = exhaustive_asic_taps(k, bits, symmetry="8-fold", objective="csf", geometry=g, adder_weight=lam)
            assert d.fit_info["objective"] == pytest.approx(J, rel=1e-9, abs=1e-14), (bits, lam)


def test_csf_objective_keeps_the_band_pass_at_4_bits():
    from fsdvs_hw.csf import Geometry, csf_agreement

    k = reference_kernel("dog", 7)
    g = Geometry(k.pitch_m, csf_agreement(k).implied_focal_length_m)
    plain = fit_asic_taps(k, 4)
    weighted = fit_asic_taps(k, 4, objective="csf", geometry=g)
    a_plain = csf_agreement(plain.kernel(), geometry=g)
    a_weighted = csf_agreement(weighted.kernel(), geometry=g)
    # the L2-optimal 4-bit taps lose the band-pass shape; CSF weighting keeps it (at more L2 error)
    assert a_weighted.correlation > a_plain.correlation + 0.3
    assert a_weighted.rms_error < a_plain.rms_error
    assert weighted.error >= plain.error
    assert weighted.fit_info["pixels_per_degree"] == pytest.approx(g.pixels_per_degree)
    with pytest.raises(InputError, match="geometry"):
        fit_asic_taps(k, 4, objective="csf", geometry=12e-3)


@pytest.mark.parametrize("bits", [2, 3, 4, 8])
def test_full_twos_complement_range_fits_the_most_negative_code_exactly(bits):
    # issue 13: a 3-bit 3x3 target with centre -4 must fit with error 0 (-4 is one signed digit)
    lo = -(1 << (bits - 1))
    t = np.ones((3, 3))
    t[1, 1] = lo
    d = fit_asic_taps(Kernel(t, name=f"centre {lo}"), bits)
    assert d.error == pytest.approx(0.0, abs=1e-15)
    assert d.taps[1, 1] == lo * int(d.taps[0, 0]) and d.taps.min() >= lo
    assert csd_weight(np.array([lo]))[0] == 1  # a single (negated, shifted) digit
    assert tap_range(bits) == (lo, -lo - 1)
    if bits > 4:
        return
    # the exhaustive oracle searches the same range and agrees
    q, s, J = exhaustive_asic_taps(Kernel(t), bits, symmetry="8-fold")
    assert J == pytest.approx(0.0, abs=1e-15) and q[1, 1] == lo
