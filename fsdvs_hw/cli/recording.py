"""``fsdvs-hw recording info | compare | calibrate``: inspect a camera's recording, compare two
event streams, fit the simulator's sensor parameters to a recording.

Every file is read by :func:`fsdvs_hw.sensor.eventfiles.recordings.read_recording` (Prophesee
RAW EVT 2.0/3.0 and DAT, DSEC and v2e HDF5, AEDAT4, npz), which refuses a malformed file with
one line naming the file and the field; every number is checked before anything is read.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ..errors import InputError

__all__ = ["ACTIONS", "DESCRIPTION", "HELP", "add_arguments", "run"]

#: The actions of the verb.
ACTIONS = ("info", "compare", "calibrate")

HELP = "inspect a camera's recording (info), compare two event streams (compare), fit sensor parameters (calibrate)"
DESCRIPTION = """\
Work with an event camera's recording (.raw EVT 2.0/3.0, .dat, .h5 DSEC or v2e, .aedat4, .npz).

  info FILE                      format, sensor size, events, ON fraction, time span and rate,
                                 the header's time offset (% t0) and trigger events
  compare SIM REC                counts, ON fraction, rate correlation, inter-event-interval KS,
                                 lag, count-map correlation and noise rates of two streams
  calibrate REC --video VIDEO    thresholds, mismatch, refractory period, leak and shot noise
                                 (intervals; a model check says "fits" or "model mismatch")
  calibrate REC --static         shot-noise and leak rates of a recording of a static scene

Each action's --help lists its options with their defaults. Bad input (a malformed file, a
number out of range) is one line on stderr and exit status 2.

Examples:
  fsdvs-hw recording info drive.raw
  fsdvs-hw recording compare sim.h5 drive.raw --bin-ms 5
  fsdvs-hw recording calibrate rec.raw --video clip.mp4 --preset imx636
"""

_SEED_MAX = 2**32 - 1


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    fmt = parser.formatter_class
    info = sub.add_parser("info", help="what a recording holds", formatter_class=fmt)
    info.add_argument("file", type=Path, help="the recording")
    _size_options(info)
    info.add_argument("--json", action="store_true", help="print JSON instead of the table")

    cmp_ = sub.add_parser("compare", help="compare a simulation with a recording", formatter_class=fmt)
    cmp_.add_argument("sim", type=Path, help="simulated events (any event file)")
    cmp_.add_argument("rec", type=Path, help="the recording")
    _size_options(cmp_)
    cmp_.add_argument("--bin-ms", type=float, default=10.0, help="rate bin width in ms (default 10)")
    cmp_.add_argument("--max-lag-ms", type=float, default=100.0, help="largest lag searched in ms (default 100)")
    cmp_.add_argument(
        "--support-ms",
        type=float,
        default=10.0,
        help="window of the isolated-event (noise) criterion in ms (default 10)",
    )
    cmp_.add_argument("--json", action="store_true", help="print the scalar statistics as JSON")

    cal = sub.add_parser("calibrate", help="fit the simulator's sensor parameters to a recording", formatter_class=fmt)
    _calibrate_arguments(cal)
    for p in (info, cmp_, cal):
        p.add_argument("--no-progress", action="store_true", help="no progress bars")


def _size_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--width", type=int, default=None, help="sensor width (px) for files that do not store it")
    p.add_argument("--height", type=int, default=None, help="sensor height (px) for files that do not store it")


def _calibrate_arguments(cal: argparse.ArgumentParser) -> None:
    from ..scenes.video import INPUT_MAPPINGS
    from ..sensor.cameras.presets import SENSOR_PRESETS
    from ..sensor.simulation.config import PRESETS

    cal.add_argument("rec", type=Path, help="the recording")
    _size_options(cal)
    src = cal.add_mutually_exclusive_group(required=True)
    src.add_argument("--video", default=None, help="the known video the camera saw (file or example:NAME)")
    src.add_argument("--static", action="store_true", help="a recording of a static scene (noise rates only)")
    cal.add_argument(
        "--preset",
        choices=list(dict.fromkeys([*PRESETS, *SENSOR_PRESETS])),
        default="default",
        help="base sensor model: the choices not fitted (response, bandwidth unless --fit-cutoff) (default: default)",
    )
    cal.add_argument("--start-frame", type=int, default=0, help="first video frame (default 0)")
    cal.add_argument("--frames", type=int, default=None, help="video frames to use (default: to the end)")
    cal.add_argument(
        "--video-offset-s",
        type=float,
        default=0.0,
        help="time of the video's frame 0 on the recording's clock, s (default 0: the recording's "
        "times are the video's, as a simulation of it writes them)",
    )
    cal.add_argument(
        "--input-mapping",
        choices=INPUT_MAPPINGS,
        default=None,
        help="video code values to intensity (default: the preset's)",
    )
    cal.add_argument("--peak-intensity", type=float, default=1.0, help="intensity of display white (default 1.0)")
    cal.add_argument("--fit-cutoff", action="store_true", help="also fit the photoreceptor bandwidth")
    cal.add_argument("--duration-s", type=float, default=None, help="static scene: the recording's length in s")
    cal.add_argument("--n-boot", type=int, default=200, help="bootstrap resamples over pixels (default 200)")
    cal.add_argument("--level", type=float, default=0.95, help="confidence level of the intervals (default 0.95)")
    cal.add_argument(
        "--seed", type=int, default=0, help="seed of the bootstrap and the check's simulations (default 0)"
    )
    cal.add_argument("--no-check", action="store_true", help="skip the posterior-predictive model check")
    cal.add_argument(
        "--error-recordings",
        type=int,
        default=0,
        help="recordings simulated at the fit to fold the estimator's own error into the intervals (default 0)",
    )
    cal.add_argument("--json", action="store_true", help="print the estimates as JSON")


def _check_side(flag: str, v: int | None) -> int | None:
    if v is not None and not 1 <= v <= 32767:
        raise InputError(f"{flag} {v}: must be in [1, 32767] pixels")
    return v


def _positive(flag: str, v: float | None, unit: str) -> float | None:
    if v is not None and not (math.isfinite(v) and v > 0):
        raise InputError(f"{flag} {v!r}: must be a positive finite number of {unit}")
    return v


def _read(path: Path, args: argparse.Namespace) -> Any:
    from ..sensor.eventfiles.recordings import read_recording

    return read_recording(path, width=_check_side("--width", args.width), height=_check_side("--height", args.height))


def info_lines(rec: Any, path: Path) -> dict[str, Any]:
    """The facts ``recording info`` prints, as a dict (JSON-ready)."""
    import numpy as np

    n = len(rec)
    t = rec.t_us
    span_us = int(t[-1] - t[0]) if n else 0
    out: dict[str, Any] = {
        "file": str(path),
        "format": rec.metadata.get("format"),
        "width": int(rec.width),
        "height": int(rec.height),
        "events": n,
        "on_fraction": float((rec.p > 0).mean()) if n else None,
        "first_t_us": int(t[0]) if n else None,
        "last_t_us": int(t[-1]) if n else None,
        "duration_s": span_us * 1e-6,
        "rate_ev_per_s": n / (span_us * 1e-6) if span_us else None,
        "rate_ev_per_pixel_s": n / (span_us * 1e-6 * rec.width * rec.height) if span_us else None,
        "active_pixels": int(np.unique(rec.y * rec.width + rec.x).size) if n else 0,
        "time_offset_us": rec.metadata.get("t0_us", rec.metadata.get("t_offset", 0)),
        "triggers": int(rec.triggers.size),
    }
    if rec.triggers.size:
        out["trigger_channels"] = sorted({int(v) for v in rec.triggers["id"]})
    return out


def _print_table(d: dict[str, Any]) -> None:
    for k, v in d.items():
        if isinstance(v, float):
            v = f"{v:.6g}"
        print(f"{k:<22} {'—' if v is None else v}")


def _info(args: argparse.Namespace) -> int:
    d = info_lines(_read(args.file, args), args.file)
    print(json.dumps(d, indent=1)) if args.json else _print_table(d)
    return 0


def _compare(args: argparse.Namespace) -> int:
    from ..sensor.cameras.compare import compare_events

    bin_s = _positive("--bin-ms", args.bin_ms, "ms") * 1e-3  # type: ignore[operator]
    lag_s = _positive("--max-lag-ms", args.max_lag_ms, "ms") * 1e-3  # type: ignore[operator]
    support_s = _positive("--support-ms", args.support_ms, "ms") * 1e-3  # type: ignore[operator]
    sim, rec = _read(args.sim, args), _read(args.rec, args)
    c = compare_events(sim, rec, bin_s=bin_s, max_lag_s=lag_s, support_s=support_s)
    print(json.dumps(c.summary(), indent=1)) if args.json else print(c)
    return 0


def _check_calibrate_numbers(args: argparse.Namespace) -> None:
    if args.start_frame < 0:
        raise InputError(f"--start-frame {args.start_frame}: must be >= 0")
    if args.frames is not None and args.frames < 2:
        raise InputError(f"--frames {args.frames}: must be >= 2 (the fit needs changes between frames)")
    if args.n_boot < 20:
        raise InputError(f"--n-boot {args.n_boot}: must be >= 20")
    if not (math.isfinite(args.level) and 0.5 <= args.level < 1):
        raise InputError(f"--level {args.level!r}: must be in [0.5, 1)")
    if not 0 <= args.seed <= _SEED_MAX:
        raise InputError(f"--seed {args.seed}: must be in [0, {_SEED_MAX}] (2**32 - 1)")
    if not 0 <= args.error_recordings <= 1000:
        raise InputError(f"--error-recordings {args.error_recordings}: must be in [0, 1000]")
    if not math.isfinite(args.video_offset_s):
        raise InputError(f"--video-offset-s {args.video_offset_s!r}: must be a finite number of seconds")
    _positive("--peak-intensity", args.peak_intensity, "(full scale 1.0)")
    _positive("--duration-s", args.duration_s, "seconds")
    if args.duration_s is not None and not args.static:
        raise InputError("--duration-s: only with --static (with --video the video's frames give the span)")


def _load_video(args: argparse.Namespace, height: int, width: int) -> Any:
    """The video (T, H, W) resized to the recording's sensor, and its frame times on the recording's clock."""
    from ..limits import check_allocation
    from ..scenes.video import example_clip_path, load_video, video_properties
    from ..sensor.cameras.presets import preset_input_mapping

    path = example_clip_path(args.video.split(":", 1)[1]) if args.video.startswith("example:") else Path(args.video)
    props = video_properties(path)  # a missing or unreadable file: its one-line error
    n = args.frames
    if n is None:
        declared = props.get("nframes")
        if not declared:
            raise InputError(f"--video {args.video}: the container gives no frame count; say --frames")
        n = int(declared) - args.start_frame
        if n < 2:
            raise InputError(f"--start-frame {args.start_frame}: the video has about {declared} frames")
    check_allocation(f"--video {args.video}: {n} frames of {width}x{height} (float64)", n * height * width * 8)
    clip = load_video(
        path,
        start_frame=args.start_frame,
        n_frames=n,
        size=(height, width),
        peak_intensity=args.peak_intensity,
        input_mapping=args.input_mapping or preset_input_mapping(args.preset),
    )
    return clip.intensity, clip.timestamps_s + args.video_offset_s


def _calibrate(args: argparse.Namespace) -> int:
    from ..sensor.cameras.calibrate import calibrate_sensor
    from ..sensor.cameras.presets import sensor_config

    _check_calibrate_numbers(args)
    rec = _read(args.rec, args)
    config = sensor_config(args.preset, seed=args.seed)
    options: dict[str, Any] = dict(config=config, n_boot=args.n_boot, level=args.level, seed=args.seed)
    if args.static:
        cal = calibrate_sensor(rec, None, duration_s=args.duration_s, **options)
    else:
        video, times = _load_video(args, rec.height, rec.width)
        cal = calibrate_sensor(
            rec,
            video,
            timestamps_s=times,
            fit_cutoff=args.fit_cutoff,
            check=not args.no_check,
            error_recordings=args.error_recordings,
            **options,
        )
    if args.json:
        rows = cal.table()
        print(
            json.dumps(
                {
                    "outcome": cal.outcome,
                    "level": cal.level,
                    "estimates": rows,
                    "warnings": cal.warnings,
                    "notes": cal.notes,
                },
                indent=1,
                default=float,
            )
        )
    else:
        print(cal)
    return 0


def run(args: argparse.Namespace) -> int:
    """Run the action; returns the exit status."""
    return {"info": _info, "compare": _compare, "calibrate": _calibrate}[args.action](args)
