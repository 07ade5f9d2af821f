"""``fsdvs-hw bench asic``: quantisation time, RTL simulation/synthesis time, and the bit sweep.

Tables (Markdown):

1. Quantisation: :func:`~fsdvs_hw.realise.asic.fit_asic_taps` wall time on a 7×7 DoG (free scale
   with nlopt, power-of-two scale, 16-bit taps) and the error of the naive ``max|k|`` scale.
2. RTL: Icarus simulation of random, all-zero and all-maximum 16×16 images (mismatches against
   the integer model) and yosys synthesis (cells, flip-flops, area) for 3×3, 5×5, 7×7 kernels.
3. Bit sweep 2…16 on a DoG and on a learned kernel from ``designs/kernels/`` (or a LoG when none
   is shipped): kernel error, CSF agreement (Mannos–Sakrison, at the target's fitted pixels per
   degree), adders, accumulator width, yosys cells and area, RTL mismatches.
4. Error against adders: the adder weight λ at 8 bits.

The highest-fidelity reference is the float kernel itself (error 0, its own CSF agreement).
"""

from __future__ import annotations

import sys

import numpy as np

from fsdvs_hw.kernels import Kernel, load_kernel, reference_kernel
from fsdvs_hw.realise.asic.fit import fit_asic_taps
from fsdvs_hw.resources import shipped_path

from .harness import BenchRun, BenchSection, Column, kept_global_state, timed

__all__ = ["bench_asic", "learned_or_fallback_kernel"]

_IMAGE_SIDE = 16


def _log(msg: str) -> None:
    print(f"[bench asic] {msg}", file=sys.stderr, flush=True)


def learned_or_fallback_kernel() -> tuple[Kernel, str]:
    """The first learned kernel in ``designs/kernels/`` (provenance without a ``reference`` key and
    a name not marked reference), else a 7×7 LoG (σ = 1 px); returns the kernel and a note."""
    root = shipped_path("kernels")
    for path in sorted(root.glob("*")) if root.is_dir() else []:
        if path.suffix.lower() not in (".npy", ".csv", ".json", ".pt"):
            continue
        try:
            k = load_kernel(path)
        except Exception:  # noqa: BLE001 - an unreadable file is skipped, not fatal to the benchmark
            continue
        if "reference" in k.provenance or "reference" in k.name.lower():
            continue
        return k, f"the learned kernel `designs/kernels/{path.name}` ('{k.name}')"
    return (
        reference_kernel("log", 7, sigma_px=1.0),
        "a 7×7 LoG (`reference_kernel('log', 7)`, σ = 1 px), standing in because designs/kernels/ has no learned kernel yet",
    )


def _images(rng: np.random.Generator, input_bits: int, n_random: int = 2) -> np.ndarray:
    xmax = (1 << input_bits) - 1
    s = _IMAGE_SIDE
    return np.concatenate(
        [
            rng.integers(0, xmax + 1, size=(n_random, s, s)),
            np.zeros((1, s, s), np.int64),
            np.full((1, s, s), xmax, np.int64),
        ]
    )


def _mismatches(d, rng) -> int:
    x = _images(rng, d.input_bits)
    return int(np.count_nonzero(d.simulate(x) != d.apply(x)))


def _count(header: str, metric: str | None = None) -> Column:
    return Column.number(header, "d", unit="count", metric=metric or header)


@kept_global_state()
def bench_asic(*, quick: bool = False) -> BenchRun:
    """Run the ASIC benchmark: its records and their Markdown tables (see the module docstring)."""
    from fsdvs_hw.csf import Geometry, csf_agreement

    rng = np.random.default_rng(0)
    dog = reference_kernel("dog", 7)
    other, note = learned_or_fallback_kernel()
    reps = 2 if quick else 5
    bit_list = [2, 4, 8, 12, 16] if quick else list(range(2, 17))
    sec = BenchSection(
        "asic", settings={"quick": quick, "repeats": reps, "image_side_px": _IMAGE_SIDE, "bits": bit_list}
    )
    sec.text("### Quantised ASIC taps (`fsdvs-hw bench asic`)", "")

    # 1. quantisation time
    _log("quantisation time")
    sec.text(
        "Quantisation of a 7×7 DoG (`reference_kernel('dog', 7)`, 8-fold symmetry, 10 coefficients); best of "
        f"{reps} runs. Error: relative L2 against the float kernel; naive: taps rounded at scale max|k| / (2^(b-1) - 1).",
        "",
    )
    table = sec.table(
        Column.text("fit"),
        Column.number("kernel error", ".3e"),
        Column.number("naive-scale error", ".3e"),
        _count("adders"),
        Column.number("time (ms)", ".1f", summary="best", metric="fit time"),
        title="Quantisation time",
    )
    for label, kw in [
        ("free scale (nlopt DIRECT-L + polish), 8 bit", {"bits": 8}),
        ("power-of-two scale, 8 bit", {"bits": 8, "scale": "pow2"}),
        ("free scale, 8 bit, λ = 1e-4", {"bits": 8, "adder_weight": 1e-4}),
        ("free scale, 16 bit", {"bits": 16}),
        ("free scale, 8 bit, objective='csf' (fixed geometry)", {"bits": 8, "objective": "csf", "geometry": "dog"}),
    ]:
        if kw.get("geometry") == "dog":
            kw = {**kw, "geometry": Geometry(dog.pitch_m, csf_agreement(dog).implied_focal_length_m)}
        tm = timed(lambda kw=kw: fit_asic_taps(dog, **kw), reps)
        d = tm.result
        naive = d.fit_info.get("naive_error")
        table.row(label, d.error, "" if naive is None else naive, d.adders, tm)
    sec.text("")

    # 2. RTL simulation and synthesis
    _log("RTL simulation and synthesis")
    sec.text(
        f"Streaming RTL (8-bit taps, 8-bit pixels, {_IMAGE_SIDE}-pixel line buffers, symmetric pre-adds). "
        f"Simulation: Icarus Verilog on {2} random + all-zero + all-max {_IMAGE_SIDE}×{_IMAGE_SIDE} images "
        "(with input stalls), compared bit for bit with the integer model. Synthesis: yosys → "
        "`fsdvs_demo45.lib` (areas ≈ NanGate 45 nm X1 cells, µm²); line buffers are flip-flops here.",
        "Datapath: the arithmetic alone (pre-adds, shift-add, rounding, output register), synthesised separately. "
        "Synth time covers both runs.",
        "",
    )
    table = sec.table(
        Column.text("kernel"),
        _count("adders"),
        Column.number("acc bits", "d", unit="bit", metric="accumulator width"),
        Column.text("images"),
        _count("mismatches", "RTL mismatches"),
        Column.number("sim (s)", ".2f", metric="RTL simulation time"),
        _count("cells"),
        _count("flip-flops"),
        Column.number("area (µm²)", ".0f"),
        _count("datapath cells"),
        Column.number("datapath area (µm²)", ".0f"),
        Column.number("synth (s)", ".2f", metric="synthesis time"),
        title="RTL simulation and synthesis",
    )
    for size in (3, 5, 7):
        d = fit_asic_taps(reference_kernel("dog", size), 8)
        x = _images(rng, 8)
        t_sim = timed(lambda d=d, x=x: d.simulate(x), 1)
        mism = int(np.count_nonzero(t_sim.result != d.apply(x)))
        t_syn = timed(lambda d=d: d.synthesise(image_width=_IMAGE_SIDE, image_height=_IMAGE_SIDE), 1)
        syn = t_syn.result.synthesis
        table.row(
            f"{size}×{size}",
            d.adders,
            d.accumulator_bits,
            str(x.shape[0]),
            mism,
            t_sim,
            syn["cells"],
            syn["flip_flops"],
            syn["area_m2"] * 1e12,
            syn["datapath_cells"],
            syn["datapath_area_m2"] * 1e12,
            t_syn,
        )
    sec.text("")

    # 3. bit sweep
    for kernel, label in [(dog, "DoG 7×7 (`reference_kernel('dog', 7)`)"), (other, note)]:
        _log(f"bit sweep on {kernel.name}")
        ref_csf = csf_agreement(kernel)
        geo = Geometry(kernel.pitch_m, ref_csf.implied_focal_length_m)
        sec.text(
            f"Bit sweep on {label}: symmetry {fit_asic_taps(kernel, 8).symmetry}, free scale, λ = 0. "
            f"CSF: Mannos–Sakrison, at the target's fitted {ref_csf.pixels_per_degree:.1f} px/deg (linear RMS "
            "difference of the peak-normalised curves, and their correlation). Cells/area: yosys, "
            f"{_IMAGE_SIDE}-pixel lines. Mismatches: RTL vs integer model on 4 images.",
            "",
        )
        sweep = sec.table(
            Column.text("bits"),
            Column.number("kernel error", ".3e"),
            Column.number("naive-scale error", ".3e"),
            Column.number("shape error", ".3e"),
            Column.number("CSF rms error", ".4f"),
            Column.number("CSF correlation", ".4f"),
            _count("adders (pre-add)", "adders with symmetric pre-adds"),
            _count("adders (per tap)", "adders per tap"),
            Column.number("acc bits", "d", unit="bit", metric="accumulator width"),
            _count("cells"),
            Column.number("area (µm²)", ".0f"),
            _count("datapath cells"),
            Column.number("datapath area (µm²)", ".0f"),
            _count("mismatches", "RTL mismatches"),
            title=f"Bit sweep on {kernel.name}",
        )
        sweep.row("float", "0", "–", "0", ref_csf.rms_error, ref_csf.correlation, *["–"] * 8)
        sec.text("", "Same kernel, `objective='csf'` (CSF-weighted frequency-response error, same geometry):", "")
        csf_sweep = sec.table(
            Column.text("bits"),
            Column.number("kernel error", ".3e"),
            Column.number("CSF rms error", ".4f"),
            Column.number("CSF correlation", ".4f"),
            _count("adders (pre-add)", "adders with symmetric pre-adds"),
            Column.number("fit (s)", ".2f", metric="fit time"),
            title=f"Bit sweep on {kernel.name}, objective='csf'",
        )
        for b in bit_list:
            tm = timed(lambda b=b: fit_asic_taps(kernel, b, objective="csf", geometry=geo), 1)
            dc = tm.result
            ac = csf_agreement(dc.kernel(), geometry=geo)
            csf_sweep.row(str(b), dc.error, ac.rms_error, ac.correlation, dc.adders, tm)
            d = fit_asic_taps(kernel, b)
            a = csf_agreement(d.kernel(), geometry=geo)
            syn = d.synthesise(image_width=_IMAGE_SIDE, image_height=_IMAGE_SIDE).synthesis
            sweep.row(
                str(b),
                d.error,
                d.fit_info["naive_error"],
                d.shape_error,
                a.rms_error,
                a.correlation,
                d.adders,
                d.adders_per_tap,
                d.accumulator_bits,
                syn["cells"],
                syn["area_m2"] * 1e12,
                syn["datapath_cells"],
                syn["datapath_area_m2"] * 1e12,
                _mismatches(d, rng),
            )
        sec.text("")

    # 4. error against adders
    _log("adder weight trade")
    sec.text(
        "Error against adders on the 7×7 DoG at 8 bits (adder weight λ = price of one adder in squared relative error).",
        "",
    )
    table = sec.table(
        Column.text("λ"),
        Column.number("kernel error", ".3e"),
        _count("adders"),
        _count("non-zero taps"),
        _count("cells"),
        _count("datapath cells"),
        title="Error against adders",
    )
    for lam in [0.0, 1e-4] if quick else [0.0, 1e-5, 1e-4, 3e-4, 1e-3, 3e-3]:
        d = fit_asic_taps(dog, 8, adder_weight=lam)
        syn = d.synthesise(image_width=_IMAGE_SIDE, image_height=_IMAGE_SIDE).synthesis
        table.row(f"{lam:g}", d.error, d.adders, int((d.taps != 0).sum()), syn["cells"], syn["datapath_cells"])
    return sec.run()
