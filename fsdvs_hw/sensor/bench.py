"""``fsdvs-hw bench sim``: simulator throughput, peak memory, and speed versus accuracy.

Two tables, reproducible with one command (``fsdvs-hw bench sim``):

1. **Throughput** at the paper's detection size (B=1, 17 frames of 480×640 → 16×2×480×640) with a
   7×7 kernel, on the noiseless training sensor (``SensorConfig.ideal()``), float32: forward and
   forward+backward Mpixel-frames/s (wall clock, median of repeats), the process CPU time, and
   the peak resident-memory increase of a fresh child process. The machine's load average is
   printed, because on a shared machine wall-clock figures are contention-bound.
2. **Speed/accuracy**: a textured natural image (scikit-image ``camera``) translating in dim light
   (10 % of full scale: the photoreceptor low-pass matters), every fidelity setting against the highest-fidelity
   reference (256 fixed sub-steps per frame interval, float64, every effect on). Error columns:
   relative event-count error and event-frame L1 error ``Σ|F - F_ref| / Σ F_ref``.
3. **Region stepping**: adaptive sub-steps chosen per frame interval (one count for the frame,
   as ESIM's global step) versus per square region, on a scene where only a small dim object moves.
4. **Streaming**: exact event list of a translating random texture, whole clip in memory versus
   :func:`fsdvs_hw.sensor.simulate` chunk by chunk (frames generated one at a time), at two clip
   lengths: wall, CPU time and the peak resident-memory increase of a fresh child process (the
   stream's peak should not grow with the clip's length).
"""

from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import time
from typing import Any

__all__ = ["bench_sim", "moving_texture"]


def moving_texture(T: int = 17, H: int = 120, W: int = 160, *, speed_px: float = 2.0,
                   level: float = 0.02, contrast: float = 0.6, dtype: Any = None) -> Any:
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
import json, resource, sys, time, statistics, torch
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
print(json.dumps({"wall": statistics.median(walls), "wall_min": min(walls), "cpu": statistics.median(cpus),
                  "peak_mb": (rss1 - rss0) / 1024, "threads": torch.get_num_threads()}))
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


def _streaming(quick: bool) -> str:
    H, W = (60, 80) if quick else (240, 320)
    lengths = (17, 65) if quick else (33, 257)
    threads = min(2, os.cpu_count() or 1)
    lines = [f"### Streaming vs whole clip: exact event list, translating random texture {H}×{W}, "
             f"mismatch σ 0.03, chunks of 16 intervals, {threads} torch threads", "",
             "| clip (frames) | path | events | wall (s) | CPU time (s) | Mpixel-frames/s (wall) | peak memory increase (MB) |",
             "|---|---|---|---|---|---|---|"]
    for T in lengths:
        for mode in ("whole", "stream"):
            out = subprocess.run([sys.executable, "-c", _STREAM_CHILD, mode, str(T), str(H), str(W), str(threads)],
                                 capture_output=True, text=True, env=dict(os.environ), check=False)
            if out.returncode != 0:
                raise RuntimeError(f"benchmark child failed: {out.stderr[-2000:]}")
            r = json.loads(out.stdout.strip().splitlines()[-1])
            lines.append(f"| {T} | {mode} | {r['events']} | {r['wall']:.2f} | {r['cpu']:.2f} | "
                         f"{H * W * T / r['wall'] / 1e6:.2f} | {r['peak_mb']:.0f} |")
    return "\n".join(lines)


def _child(mode: str, reps: int, H: int, W: int, T: int, threads: int) -> dict[str, float]:
    env = dict(os.environ)
    out = subprocess.run([sys.executable, "-c", _CHILD, mode, str(reps), str(H), str(W), str(T), str(threads)],
                         capture_output=True, text=True, env=env, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"benchmark child failed: {out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _throughput(quick: bool) -> str:
    H, W, T = (120, 160, 17) if quick else (480, 640, 17)
    reps = 2 if quick else 5
    px_frames = H * W * T
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    threads = min(2, os.cpu_count() or 1)
    runs = {}
    for n_threads in sorted({threads, 1}, reverse=True):
        runs[n_threads] = (_child("fwd", reps, H, W, T, n_threads), _child("fwdbwd", reps, H, W, T, n_threads))
    fwd, both = runs[threads]
    lines = [
        f"### Throughput: {T}×{H}×{W} float32, 7×7 DoG kernel, ideal sensor (B=1 → 16×2×{H}×{W})",
        "",
        f"load average at start: {load:.2f} on {os.cpu_count()} CPUs "
        "(a load above the CPU count means the wall-clock figures are contention-bound).",
        "",
        "| pass | torch threads | wall median (s) | Mpixel-frames/s (wall median) | best wall (s) | Mpixel-frames/s (best) | CPU time (s) | peak memory (MB) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for n_threads, (f_run, b_run) in runs.items():
        for name, r in (("forward", f_run), ("forward+backward", b_run)):
            lines.append(f"| {name} | {n_threads} | {r['wall']:.3f} | {px_frames / r['wall'] / 1e6:.1f} | {r['wall_min']:.3f} | "
                         f"{px_frames / r['wall_min'] / 1e6:.1f} | {r['cpu']:.3f} | {r['peak_mb']:.0f} |")
    lines.append("")
    for n_threads, (f_run, b_run) in runs.items():
        lines.append(f"{n_threads} thread(s): backward alone / forward = "
                     f"{(b_run['wall_min'] - f_run['wall_min']) / f_run['wall_min']:.2f} (best walls), "
                     f"{(b_run['cpu'] - f_run['cpu']) / f_run['cpu']:.2f} (CPU time).")
    lines.append("Targets: forward >= 20 Mpixel-frames/s, backward <= 3x forward on 2 cores.")
    return "\n".join(lines)


def _accuracy(quick: bool) -> str:
    import torch

    from ..kernels import reference_kernel
    from .config import SensorConfig
    from .events import event_frames
    from .plan import plan_model

    H, W = (48, 64) if quick else (120, 160)
    video64 = moving_texture(17, H, W, speed_px=2.0, level=0.1)
    kernel = reference_kernel("dog", 7)
    full = SensorConfig(substeps=256, leak_rate_hz=0.01, shot_noise_rate_hz=0.001, seed=1)

    def run(video: Any, **kw: Any) -> tuple[Any, float]:
        best, out = math.inf, None
        for _ in range(1 if quick else 2):
            t0 = time.perf_counter()
            out = event_frames(video, kernel, **kw)
            best = min(best, time.perf_counter() - t0)
        return out.double(), best

    ref, t_ref = run(video64, config=full)
    n_ref = float(ref.sum())
    rows: list[tuple[str, Any, float]] = []
    for s in (1, 4, 16, 64):
        f, t = run(video64, config=full.replace(substeps=s))
        rows.append((f"fixed {s} sub-steps", f, t))
    for frac in (1.0, 0.5, 0.25):
        f, t = run(video64, config=full.replace(adaptive_fraction=frac, adaptive_region_px=0))
        rows.append((f"adaptive, one count per frame interval (ESIM-like), {frac:g} C per step", f, t))
    for frac in (0.5,):
        f, t = run(video64, config=full.replace(adaptive_fraction=frac, adaptive_region_px=32))
        rows.append((f"adaptive per 32×32 region, {frac:g} C per step", f, t))
    for tol in (0.2, 0.05, 0.01):
        plan = plan_model(video64, tol, config=full, kernel=kernel)
        f, t = run(video64, plan=plan)
        rows.append((f"plan_model tol {tol:g} ({sum(plan.substeps)} steps; skips {', '.join(plan.skipped) or '-'})", f, t))
    f, t = run(video64.float(), config=full.replace(substeps=64))
    rows.append(("float32, 64 sub-steps", f, t))
    f, t = run(video64, config=full.replace(substeps=64, convolution="direct"))
    rows.append(("conv2d instead of FFT, 64 sub-steps", f, t))
    f, t = run(video64, config=SensorConfig.ideal())
    rows.append(("ideal sensor (no pixel effects)", f, t))
    lines = [
        f"### Speed vs accuracy: camera image moving 2 px/frame at 10 % of full scale, 17×{H}×{W}, 7×7 DoG",
        "",
        f"Reference: 256 fixed sub-steps per interval, float64, every effect on (v2e defaults): "
        f"{n_ref:.0f} events in {t_ref:.2f} s.",
        "",
        "| setting | events | count error | frame L1 error | wall (s) | speed-up |",
        "|---|---|---|---|---|---|",
    ]
    for name, f, t in rows:
        n = float(f.sum())
        lines.append(f"| {name} | {n:.0f} | {abs(n - n_ref) / max(n_ref, 1):.4f} | "
                     f"{float((f - ref).abs().sum()) / max(n_ref, 1):.4f} | {t:.3f} | {t_ref / t:.1f}× |")
    return "\n".join(lines)


def _regions(quick: bool) -> str:
    import torch

    from .config import SensorConfig
    from .events import event_frames

    H, W = (64, 96) if quick else (128, 160)
    T = 9
    video = torch.full((1, T, H, W), 0.5, dtype=torch.float64)  # bright still background
    for t in range(T):
        video[0, t, H // 2 - 6:H // 2 + 6, 8 + 4 * t:18 + 4 * t] = 0.05  # small dim object, 4 px/frame
    base = SensorConfig(threshold_sigma=0.0, refractory_s=0.0, leak_rate_hz=0.0, shot_noise_rate_hz=0.0,
                        dark_intensity=1e-3)
    ref = event_frames(video, None, config=base.replace(substeps=256)).double()
    n_ref = float(ref.sum())
    lines = [f"### Adaptive steps per frame vs per region: one small dim object moving 4 px/frame over a "
             f"bright still background, {T}×{H}×{W}", "",
             f"Reference: 256 fixed sub-steps per interval ({n_ref:.0f} events).", "",
             "| stepping | pixel sub-steps | frame L1 error | wall (s) |", "|---|---|---|---|"]
    for name, cfg in (("fixed 256", base.replace(substeps=256)),
                      ("adaptive 0.5 C, one count per frame interval", base.replace(adaptive_fraction=0.5, adaptive_region_px=0)),
                      ("adaptive 0.5 C per 16×16 region", base.replace(adaptive_fraction=0.5, adaptive_region_px=16)),
                      ("adaptive 0.5 C per 32×32 region", base.replace(adaptive_fraction=0.5, adaptive_region_px=32))):
        t0 = time.perf_counter()
        f, info = event_frames(video, None, config=cfg, return_info=True)
        t = time.perf_counter() - t0
        lines.append(f"| {name} | {info.pixel_steps} | {float((f.double() - ref).abs().sum()) / max(n_ref, 1):.4f} | {t:.3f} |")
    return "\n".join(lines)


def bench_sim(*, quick: bool = False) -> str:
    """Markdown: throughput/memory at 480×640×17 and the speed/accuracy table (``quick``: small)."""
    import torch

    torch.manual_seed(0)
    parts = ["## sim — differentiable FS-DVS event simulator", "", _throughput(quick), "", _streaming(quick), ""]
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small frames, many steps: one thread avoids sync overhead
    try:
        parts.append(_accuracy(quick))
        parts.append("")
        parts.append(_regions(quick))
    finally:
        torch.set_num_threads(threads)
    parts.append("\n(speed/accuracy table timed with 1 torch thread)")
    return "\n".join(parts)


if __name__ == "__main__":  # pragma: no cover
    print(bench_sim(quick="--quick" in sys.argv))
