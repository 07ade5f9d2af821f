"""``fsdvs-hw bench upsampling``: event timing from low frame rates, with and without frame upsampling.

Ground truth: synthetic clips (:func:`fsdvs_hw.scenes.make_scenes`: textured ``1/f`` background
panning, 2–3 moving shapes with 50 % edges) rendered at 400 Hz and simulated at 400 Hz. Each clip
is subsampled to 25, 50 and 100 Hz and simulated again (same sensor, same seed, so the same
per-pixel thresholds) after upsampling back to 400 Hz with each mode of
:func:`fsdvs_hw.sensor.simulation.upsampling.upsample_frames` (``none`` simulates the low-rate frames as they
are: the simulator interpolates linearly in log between them). Two scene speeds: objects at
40 px/s and 160 px/s (the pan a quarter of that), i.e. 1.6 and 6.4 px per frame at 25 Hz.

Metrics, each against the 400 Hz reference of the same clip:

count error
    ``(N − N_ref) / N_ref`` in %;
median |Δt|
    for every reference event, the time to the nearest event of the same pixel and polarity in
    the test stream (ms); the median over all reference events of the clip (pixels without such
    an event leave theirs unmatched: the unmatched fraction is reported beside it);
van Rossum distance per event
    van Rossum (Neural Comput. 13, 2001) with τ = 10 ms, per pixel and polarity: ``D² = (1/τ) ∫ (f −
    g)² dt`` with ``f``, ``g`` the event trains filtered by ``exp(−t/τ)``, summed over pixels and
    divided by ``N_ref``. A missing or extra event adds 0.5, an event moved by Δt adds
    ``1 − exp(−|Δt|/τ)`` (0.1 at 1 ms, 0.39 at 5 ms). Evaluated on a 0.25 ms grid;
time per input frame
    wall time of upsampling plus simulation divided by the low-rate frames (ms); the 400 Hz
    reference's own time per 400 Hz frame is given in the text.

Each cell: the mean over clips with its 95 % t-interval (n clips, the scene seed varies), the
interval of a non-negative quantity cut at 0.
"""

from __future__ import annotations

import math
import statistics
import time
from typing import Any

import numpy as np

from .harness import BenchRun, BenchSection, Column, Measured, kept_global_state

__all__ = ["RATES_HZ", "REFERENCE_HZ", "SPEEDS_PX_S", "bench_upsampling", "event_distances"]

#: Frame rate of the ground truth (Hz), the FS-DVS paper's upsampling rate.
REFERENCE_HZ = 400
#: Low frame rates simulated (Hz); each divides REFERENCE_HZ.
RATES_HZ = (25, 50, 100)
#: Object speeds of the two scene classes (px/s); the background pans at a quarter of it.
SPEEDS_PX_S = (40.0, 160.0)
#: van Rossum time constant (s).
VAN_ROSSUM_TAU_S = 0.01
_GRID_S = 0.25e-3


def _columns(events: Any, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(pixel-polarity key, time s) of an EventList."""
    x, y, t, p = (np.asarray(getattr(events, k)) for k in ("x", "y", "t", "p"))
    return ((y.astype(np.int64) * width + x) * 2 + (p > 0)), t.astype(np.float64)


def event_distances(ref: Any, test: Any, width: int, tau_s: float = VAN_ROSSUM_TAU_S) -> dict[str, float]:
    """Count error (%), median nearest-event |Δt| (ms), unmatched fraction and van Rossum distance per
    reference event between two EventLists of one sensor (module documentation)."""
    kr, tr = _columns(ref, width)
    kt, tt = _columns(test, width)
    n_ref = len(tr)
    out = {"count_error_pct": 100.0 * (len(tt) - n_ref) / max(n_ref, 1)}
    # nearest test event of the same key: search in (key, t) order on one composite axis
    span = 10.0 * (max(tr.max(initial=0.0), tt.max(initial=0.0)) + 1.0)
    comp_t = np.sort(kt * span + tt)
    comp_r = kr * span + tr
    i = np.searchsorted(comp_t, comp_r)
    best = np.full(n_ref, np.inf)
    for j in (i - 1, i):
        ok = (j >= 0) & (j < len(comp_t))
        cand = np.full(n_ref, np.inf)
        jj = j[ok]
        same = np.floor(comp_t[jj] / span + 1e-9).astype(np.int64) == kr[ok]
        cand[np.flatnonzero(ok)[same]] = np.abs(comp_t[jj][same] - comp_r[ok][same])
        best = np.minimum(best, cand)
    matched = np.isfinite(best)
    out["median_dt_ms"] = float(np.median(best[matched]) * 1e3) if matched.any() else float("nan")
    out["unmatched_pct"] = 100.0 * (1 - matched.mean()) if n_ref else 0.0
    # van Rossum: one signed train per key (+ reference, − test), filtered on a grid
    keys, inv = np.unique(np.concatenate([kr, kt]), return_inverse=True)
    times = np.concatenate([tr, tt])
    sign = np.concatenate([np.ones(n_ref), -np.ones(len(tt))])
    n_bins = int(math.ceil((times.max(initial=0.0) + 6 * tau_s) / _GRID_S)) + 1
    k = np.ceil(times / _GRID_S - 1e-9).astype(np.int64)
    w = np.zeros((n_bins, len(keys)))
    np.add.at(w, (k, inv), sign * np.exp(-(k * _GRID_S - times) / tau_s))
    decay, trace, d2 = math.exp(-_GRID_S / tau_s), np.zeros(len(keys)), 0.0
    for row in w:
        trace = trace * decay + row
        d2 += float(trace @ trace)
    out["van_rossum_per_event"] = d2 * _GRID_S / tau_s / max(n_ref, 1)
    return out


def _mean_ci(values: list[float], *, floor: float = -math.inf) -> tuple[Measured, Measured, Measured]:
    """Mean over clips (with the clip count and min–max) and its 95 % t-interval's bounds (each a
    derived value: its own min–max), the low bound cut at ``floor`` (0 for a non-negative quantity)."""
    from scipy import stats

    v = [x for x in values if math.isfinite(x)]
    m = statistics.fmean(v)
    h = stats.t.ppf(0.975, len(v) - 1) * statistics.stdev(v) / math.sqrt(len(v)) if len(v) > 1 else 0.0
    lo, hi = max(m - h, floor), m + h
    return Measured(m, len(v), min(v), max(v)), Measured(lo, len(v), lo, lo), Measured(hi, len(v), hi, hi)


def _simulate(frames: list[np.ndarray], times: list[float], config: Any) -> Any:
    import torch

    from fsdvs_hw.sensor import event_list

    video = torch.as_tensor(np.stack(frames))[None]
    return event_list(video, timestamps_s=torch.as_tensor(np.asarray(times))[None], config=config)


@kept_global_state()
def bench_upsampling(*, quick: bool = False) -> BenchRun:
    """The table: scene speed, frame rate, mode → timing error, count error, van Rossum, time per frame.

    Returns
    -------
    BenchRun
        Markdown and records (one per printed number).
    """
    import torch

    from fsdvs_hw.scenes.synthetic import SceneConfig, make_scenes
    from fsdvs_hw.sensor import SensorConfig
    from fsdvs_hw.sensor.simulation.upsampling import UPSAMPLE_MODES, motion_px_per_frame, upsample_frames

    torch.set_num_threads(1)
    h, w = (32, 48) if quick else (64, 96)
    n_clips = 2 if quick else 5
    n_frames = (2 if quick else 12) * (REFERENCE_HZ // min(RATES_HZ)) + 1  # 0.08 / 0.48 s
    config = SensorConfig.ideal(0.2, threshold_sigma=0.03, seed=0)
    sec = BenchSection(
        "upsampling",
        settings={
            "quick": quick,
            "pixels": f"{h}x{w}",
            "clips": n_clips,
            "reference_hz": REFERENCE_HZ,
            "duration_s": (n_frames - 1) / REFERENCE_HZ,
            "sensor": "ideal, C = 0.2, sigma 0.03, seed 0",
            "threads": 1,
            "van_rossum_tau_s": VAN_ROSSUM_TAU_S,
        },
    )
    sec.text(
        "### Event timing from low frame rates vs the 400 Hz reference (fsdvs-hw bench upsampling)",
        "",
        f"{n_clips} synthetic clips per speed ({h}x{w} px, {(n_frames - 1) / REFERENCE_HZ:g} s at {REFERENCE_HZ} Hz), "
        "subsampled and upsampled back to 400 Hz; ideal sensor with mismatch (C = 0.2, σ = 0.03, seed 0). "
        "Mean over clips [95 % t-interval]; time: median [min–max] over clips.",
        "",
    )
    table = sec.table(
        Column.text("object speed px/s"),
        Column.text("frame rate Hz"),
        Column.text("px / frame (flow p99)"),
        Column.text("upsampling"),
        Column.numbers(
            "median abs dt ms [95 % CI]",
            "{0} [{1}, {2}]",
            ("median abs dt", "ms", ".3g"),
            ("median abs dt ci low", "ms", ".3g"),
            ("median abs dt ci high", "ms", ".3g"),
        ),
        Column.number("unmatched %", ".2g", unit="%", metric="unmatched reference events"),
        Column.numbers(
            "count error % [95 % CI]",
            "{0} [{1}, {2}]",
            ("count error", "%", "+.2f"),
            ("count error ci low", "%", "+.2f"),
            ("count error ci high", "%", "+.2f"),
        ),
        Column.numbers(
            "van Rossum per event [95 % CI]",
            "{0} [{1}, {2}]",
            ("van Rossum per event", "", ".3f"),
            ("van Rossum ci low", "", ".3f"),
            ("van Rossum ci high", "", ".3f"),
        ),
        Column.number("ms per input frame", ".3g", unit="ms", metric="wall time per input frame"),
    )
    ref_ms: list[float] = []
    for speed in SPEEDS_PX_S:
        scene = SceneConfig(
            height_px=h,
            width_px=w,
            n_frames=n_frames,
            frame_rate_hz=float(REFERENCE_HZ),
            n_objects=(2, 3),
            radius_px=(5.0, 9.0),
            edge_contrast=0.5,
            speed_px_per_frame=speed / REFERENCE_HZ,
            texture_contrast=0.3,
            background_speed_px_per_frame=0.25 * speed / REFERENCE_HZ,
        )
        batch = make_scenes(scene, n_clips, seed=0)
        times = np.arange(n_frames) / REFERENCE_HZ
        refs = []
        for clip in batch.video:
            t0 = time.perf_counter()
            refs.append(_simulate(list(clip), list(times), config))
            ref_ms.append((time.perf_counter() - t0) * 1e3 / n_frames)
        for rate in RATES_HZ:
            stride = REFERENCE_HZ // rate
            motion = statistics.fmean(motion_px_per_frame(clip[::stride], max_pairs=64) or 0.0 for clip in batch.video)
            for mode in UPSAMPLE_MODES:
                rows: dict[str, list[float]] = {}
                for clip, ref in zip(batch.video, refs, strict=True):
                    low = list(zip(times[::stride], clip[::stride], strict=True))
                    t0 = time.perf_counter()
                    up = list(upsample_frames(low, mode=mode, rate_hz=REFERENCE_HZ))
                    ev = _simulate([f for _, f in up], [t for t, _ in up], config)
                    rows.setdefault("ms", []).append((time.perf_counter() - t0) * 1e3 / len(low))
                    for k, v in event_distances(ref, ev, w).items():
                        rows.setdefault(k, []).append(v)
                table.row(
                    f"{speed:g}",
                    str(rate),
                    f"{motion:.2g}",
                    mode,
                    _mean_ci(rows["median_dt_ms"], floor=0.0),
                    statistics.fmean(rows["unmatched_pct"]),
                    _mean_ci(rows["count_error_pct"]),
                    _mean_ci(rows["van_rossum_per_event"], floor=0.0),
                    Measured.of(rows["ms"], "median"),
                )
    sec.text(
        "",
        f"The 400 Hz reference itself: {statistics.median(ref_ms):.3g} ms per 400 Hz frame "
        f"(median of {len(ref_ms)} clips, {h}x{w} px, 1 torch thread); each cell over {n_clips} clips.",
    )
    return sec.run()


if __name__ == "__main__":  # pragma: no cover
    print(bench_upsampling(quick=True).markdown)
