"""The ``csf`` benchmark: speed/accuracy of the radial response and of the CSF-agreement fit."""

from __future__ import annotations

import numpy as np

from fsdvs_hw.csf import Geometry, csf_agreement
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.spectra import radial_response

from .harness import BenchRun, BenchSection, Column, Timing, kept_global_state, timed

__all__ = ["bench_csf"]


@kept_global_state()
def bench_csf(*, quick: bool = False) -> BenchRun:
    """Speed/accuracy of the radial response (method, resolution) and of the CSF agreement fit.

    Reference: exact angular DTFT with 4097 frequencies × 512 directions (1025 × 256 with
    ``quick``). Error: max absolute difference of the peak-normalised radial response,
    interpolated onto the reference grid, worst of a DoG 7×7 and a LoG 9×9. Time: per call (ms),
    mean over both kernels of ``repeats`` timed calls each; records carry the repeats and min–max.

    Returns
    -------
    BenchRun
        The Markdown table and one record per printed number.
    """
    kernels = [reference_kernel("dog", 7), reference_kernel("log", 9, sigma_px=1.2)]
    ref_n, ref_a = (1025, 256) if quick else (4097, 512)
    reps, fit_reps = (3, 2) if quick else (10, 5)
    settings: list[tuple[str, dict[str, int]]] = [
        ("angular", {"n_freq": 129, "n_angles": 8}),
        ("angular", {"n_freq": 257, "n_angles": 32}),
        ("angular", {"n_freq": 257, "n_angles": 64}),
        ("angular", {"n_freq": 1025, "n_angles": 128}),
        ("fft", {"n_freq": 65, "n_fft": 64}),
        ("fft", {"n_freq": 129, "n_fft": 256}),
        ("fft", {"n_freq": 257, "n_fft": 1024}),
    ]
    sec = BenchSection(
        "csf", settings={"quick": quick, "reference_n_freq": ref_n, "reference_n_angles": ref_a, "repeats": reps}
    )
    sec.text(
        "### Radial response and CSF agreement (`fsdvs-hw bench csf`)",
        "",
        f"Reference: exact angular DTFT, {ref_n} frequencies × {ref_a} directions. Error: max |Δ| of the",
        "peak-normalised radial response (DoG 7×7 and LoG 9×9, worst of the two). Time: per call.",
        "",
    )
    table = sec.table(
        Column.text("method"),
        Column.text("knobs"),
        Column.number("max error", ".2e"),
        Column.number("time (ms)", ".2f", metric="time per call", summary="mean"),
    )
    refs = [radial_response(k, n_freq=ref_n, n_angles=ref_a) for k in kernels]
    for method, kw in settings:
        errs, times = [], []
        for k, ref in zip(kernels, refs):
            t = timed(lambda k=k: radial_response(k, method=method, **kw), reps)
            rr = t.result
            times += t.times_s
            errs.append(float(np.max(np.abs(np.interp(ref.f_cpp, rr.f_cpp, rr.normalised()) - ref.normalised()))))
        table.row(method, ", ".join(f"{a}={b}" for a, b in kw.items()), max(errs), Timing(tuple(times), None))
    t_fit = timed(lambda: csf_agreement(kernels[0]), fit_reps)
    g = Geometry(kernels[0].pitch_m, 12e-3)
    t_geo = timed(lambda: csf_agreement(kernels[0], geometry=g), fit_reps)
    case = "csf_agreement, Mannos–Sakrison, DoG 7×7"
    sec.text(
        "",
        f"`csf_agreement` (Mannos–Sakrison, DoG 7×7): "
        f"{sec.value(case + ', scale fitted', 'time per call', t_fit, unit='ms', spec='.0f', summary='mean')} ms "
        f"with the scale fitted, "
        f"{sec.value(case + ', with a geometry', 'time per call', t_geo, unit='ms', spec='.0f', summary='mean')} ms "
        "with a geometry.",
    )
    return sec.run()
