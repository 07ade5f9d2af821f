"""CPU against CUDA on one machine, same frames (issue 29): the simulator (event list, event frames,
forward+backward), a 7x7 co-design step and v2e's EventEmulator on the GPU and the CPU.

Two steps, because a GPU machine may have no video decoder and no package index:

1. here: ``python -m benchmarks.gpu_check --make-frames out/frames.npz`` writes bikes.mp4 and
   carphone.mp4 as v2e's 8-bit gray code values (the v2e presets' input mapping, compressed);
2. on the GPU machine, from the checkout: ``OUT=DIR python -m benchmarks.gpu_check --frames
   out/frames.npz [--v2e V2E_SRC] [--part2]`` writes ``DIR/gpu_bench.json`` (every run's wall
   times, events, GPU peak memory; v2e's rows from :func:`benchmarks.sim.v2e_records`).

The record of 2026-11-27 on an NVIDIA H100 (16 CPU cores, torch 2.11.0+cu130) is
``benchmarks/records/device/h100_2026-11-27.json``; docs/speed.md shows its table.
"""

# ruff: noqa: E402
import argparse
import json
import os
import platform
import statistics
import sys
import time
import traceback

import numpy as np
import torch


def make_frames(path: str) -> None:
    """bikes and carphone as uint8 gray code values (``input_mapping="v2e_gray"``) in one ``.npz``."""
    from fsdvs_hw.scenes.video import example_clip_path, iter_video

    out = {}
    for name in ("bikes", "carphone"):
        frames = [f for _, f in iter_video(example_clip_path(name), input_mapping="v2e_gray")]
        out[name] = np.round(np.stack(frames) * 255.0).astype(np.uint8)
    np.savez_compressed(path, **out)


ap = argparse.ArgumentParser(prog="python -m benchmarks.gpu_check")
ap.add_argument("--make-frames", metavar="NPZ")
ap.add_argument("--frames", metavar="NPZ")
ap.add_argument("--v2e", metavar="V2E_SRC", default=None)
ap.add_argument("--part2", action="store_true", help="only the event list and event frames")
ARGS = ap.parse_args() if __name__ == "__main__" else ap.parse_args([])
if ARGS.make_frames:
    make_frames(ARGS.make_frames)
    sys.exit(0)
if not ARGS.frames:
    ap.error("--frames NPZ (made with --make-frames) or --make-frames NPZ")

OUT = os.environ.get("OUT", "/tmp/out")
res = {
    "torch": torch.__version__,
    "python": platform.python_version(),
    "cpu_count": os.cpu_count(),
    "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    "rows": [],
    "errors": [],
}
T0 = time.time()


def save():
    from fsdvs_hw.paths import write_output

    write_output(os.path.join(OUT, "gpu_bench.json"), json.dumps(res, indent=1) + "\n")


def log(*a):
    print(f"[{time.time() - T0:6.1f}s]", *a, flush=True)


d = np.load(ARGS.frames)
files = {}
for name in d.files:
    p = f"/tmp/{name}.npy"
    np.save(p, d[name].astype(np.float32) / np.float32(255.0))  # v2e code values / 255 (the v2e preset's input)
    files[name] = p
log("frames", {k: d[k].shape for k in d.files})

import benchmarks.sim as bs

# 1. the simulator: CPU (all cores) vs CUDA, same frames, same process
for clip in ("bikes", "carphone"):
    for path, settings in (
        (("event list", "v2e-default"), ("frames", "v2e-default"))
        if ARGS.part2
        else (
            ("event list", "v2e-default"),
            ("frames", "v2e-default"),
            ("forward+backward", "v2e-default + 7x7 DoG pre-log"),
        )
    ):
        for dev, chunk in (("cpu", None), ("cuda", None), ("cuda", 16)):
            if time.time() - T0 > 300:
                break
            case = dict(clip=clip, path=path, settings=settings, device=dev, frames_file=files[clip])
            try:
                r = bs._run_case(case, 3, False, chunk)
                w = r["walls"]
                mpf = r["n_frames"] * r["height"] * r["width"] / 1e6
                row = {
                    "clip": clip,
                    "path": path,
                    "settings": settings,
                    "device": dev,
                    "chunk_frames": r["chunk_frames"],
                    "torch_threads": torch.get_num_threads(),
                    "repeats": len(w),
                    "walls_s": w,
                    "mpix_frames_per_s_median": mpf / statistics.median(w),
                    "mpix_frames_per_s_min": mpf / max(w),
                    "mpix_frames_per_s_max": mpf / min(w),
                    "events": r["events"],
                    "gpu_peak_mb": r["gpu_peak_mb"],
                    "peak_rss_mb": r["peak_rss_mb"],
                    "shape": [r["n_frames"], r["height"], r["width"]],
                }
                res["rows"].append(row)
                log(clip, path, dev, chunk, f"{row['mpix_frames_per_s_median']:.1f} Mpf/s", r["events"])
            except Exception as exc:
                res["errors"].append(f"{clip}/{path}/{dev}: {exc!r}")
                traceback.print_exc()
            save()

if ARGS.part2:
    log("done (part 2)")
    sys.exit(0)
# 2. a 7x7 co-design step: kernel + classifier through the differentiable event frames
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.sensor.simulation.config import SensorConfig
from fsdvs_hw.sensor.simulation.events import event_frames
from fsdvs_hw.tasks.networks import Classifier, event_representation

bikes = torch.from_numpy(np.load(files["bikes"]))
for dev in ("cpu", "cuda"):
    for B, S in ((16, 64), (32, 128)):
        try:
            g = torch.Generator().manual_seed(0)
            ys = torch.randint(0, 272 - S, (B,), generator=g)
            xs = torch.randint(0, 640 - S, (B,), generator=g)
            ts = torch.randint(0, 250 - 8, (B,), generator=g)
            video = (
                torch.stack([bikes[t : t + 8, y : y + S, x : x + S] for t, y, x in zip(ts, ys, xs)]).to(dev) * 0.98
                + 0.01
            )
            labels = torch.randint(0, 10, (B,), generator=g).to(dev)
            torch.manual_seed(0)
            net = Classifier(14, 10).to(dev)
            k = torch.tensor(reference_kernel("dog", 7).taps, dtype=torch.float32, device=dev, requires_grad=True)
            opt = torch.optim.AdamW([{"params": net.parameters(), "lr": 1e-3}, {"params": [k], "lr": 1e-2}])
            cfg = SensorConfig.ideal()
            walls, losses = [], []
            for i in range(8):
                if dev == "cuda":
                    torch.cuda.synchronize()
                t0 = time.perf_counter()
                opt.zero_grad()
                fr = event_frames(video, k, config=cfg)
                loss = torch.nn.functional.cross_entropy(net(event_representation(fr.float())), labels)
                loss.backward()
                opt.step()
                if dev == "cuda":
                    torch.cuda.synchronize()
                if i >= 2:
                    walls.append(time.perf_counter() - t0)
                losses.append(float(loss.detach()))
            res["rows"].append(
                {
                    "path": "7x7 co-design step",
                    "device": dev,
                    "batch": B,
                    "size": S,
                    "frames": 8,
                    "torch_threads": torch.get_num_threads(),
                    "repeats": len(walls),
                    "walls_s": walls,
                    "median_s": statistics.median(walls),
                    "losses": losses,
                }
            )
            log("codesign step", dev, B, S, f"{statistics.median(walls) * 1e3:.1f} ms", losses[0], losses[-1])
        except Exception as exc:
            res["errors"].append(f"codesign/{dev}/{B}: {exc!r}")
            traceback.print_exc()
        save()

# 3. v2e's EventEmulator on the same frames: GPU and CPU
bs._V2E_STUBS.update({"dv_processing": "", "tkinter": "filedialog = None\n"})
for dev, threads, reps in (("cuda", 1, 3), ("cpu", 16, 2)) if ARGS.v2e else ():
    if time.time() - T0 > 420:
        break
    try:
        rows = bs.v2e_records(
            ARGS.v2e, modes=("default",), repeats=reps, threads=threads, device=dev, frames_file=files["bikes"]
        )
        for r in rows:
            r["walls_note"] = "rates per wall second (median, min, max over repeats)"
            res["rows"].append({"path": "v2e EventEmulator", "device": dev, **r})
            log("v2e", dev, r.get("events"), {k: v for k, v in r.items() if "rate" in k or "median" in k})
    except Exception as exc:
        res["errors"].append(f"v2e/{dev}: {exc!r}")
        traceback.print_exc()
    save()
log("done")
