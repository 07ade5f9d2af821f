"""One streamed run from a video file to an event file: decoding, simulation and the writer process.

:func:`simulate_video_to_file` is the ``simulate`` command's run, without its argument parsing
and printing. The video is probed and the event file's writer process started in a thread while
torch loads; the frames are decoded in a thread of their own, ahead of the simulation; every
chunk's events go to the writer as they are made, so memory does not grow with the clip. The
event file appears at ``options.out`` only when the run succeeds (the writer renames a hidden
temporary file onto it). SIGINT and SIGTERM stop the run at once (:class:`.run_control.Stopped`)
and nothing is written; any other failure also removes the partial file.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .run_control import (
    Stopped,
    collector_spares_imports,
    frozen_objects_restored,
    signals_deferred,
    stop_on_signals,
)

__all__ = [
    "PREFETCH_BYTES",
    "VideoToFileOptions",
    "VideoToFileRun",
    "frame_size",
    "open_writer",
    "prefetch_frame_count",
    "progress_total",
    "simulate_video_to_file",
    "video_frames",
]

#: Bytes of decoded frames the decoding thread may hold ahead of the simulation.
PREFETCH_BYTES = 64 << 20


@dataclass(frozen=True)
class VideoToFileOptions:
    """What a run reads, simulates and writes: the ``simulate`` command's options, whose ranges the
    command checks before it builds them (``fsdvs_hw.cli.simulate``); this class checks nothing.

    Attributes
    ----------
    out : Path
        The event file (.h5, .hdf5, .aedat4 or .npz).
    preset : str
        The sensor preset's name (recorded in the file's metadata).
    kernel : str or None
        Kernel file or reference spec; None for none (plain DVS).
    start_frame : int
        First frame decoded.
    frames : int or None
        Frames decoded; None to the end.
    size : (int, int) or None
        (H, W) the frames are resized to (pixels); None for the source's size.
    peak_intensity : float
        Intensity of display white (full scale 1.0).
    allow_truncated : bool
        Simulate the decodable frames of a truncated or corrupt video instead of refusing it.
    input_mapping : str
        How code values become intensity (:data:`fsdvs_hw.scenes.video.INPUT_MAPPINGS`).
    dtype : str
        ``"float32"`` or ``"float64"``: the simulation's precision.
    upsample : str
        Frame upsampling mode (:data:`~fsdvs_hw.sensor.simulation.upsampling.UPSAMPLE_MODES`).
    upsample_rate : float
        Frame rate after upsampling (Hz).
    threads : int or None
        torch intra-op threads; None for :func:`~fsdvs_hw.sensor.simulation.threads.event_list_threads`.
    chunk_frames : int or None
        Frame intervals per chunk; None for
        :func:`~fsdvs_hw.sensor.simulation.stream.chunk_frames_for` of the frame size.
    progress : bool or None
        Progress bar: None where stderr is a terminal, False never.
    """

    out: Path
    preset: str
    kernel: str | None
    start_frame: int
    frames: int | None
    size: tuple[int, int] | None
    peak_intensity: float
    allow_truncated: bool
    input_mapping: str
    dtype: str
    upsample: str
    upsample_rate: float
    threads: int | None
    chunk_frames: int | None
    progress: bool | None


def simulate_video_to_file(options: VideoToFileOptions, video: Path, config: Any) -> tuple[int, int, float]:
    """Simulate the video file ``video`` with ``config`` and write its events to ``options.out``.

    Parameters
    ----------
    options : VideoToFileOptions
        What to decode, simulate and write.
    video : Path
        The video file.
    config : SensorConfig
        The sensor's configuration.

    Returns
    -------
    (int, int, float)
        The events written, the ON events among them, and the seconds from the first frame to the
        file's completion.

    Raises
    ------
    Stopped
        SIGINT or SIGTERM arrived (nothing written at ``options.out``; a previous file is kept).
    """
    with frozen_objects_restored():
        run = VideoToFileRun(options, video)
        with stop_on_signals() as stopped:
            try:
                return run.simulate_to_file(config, stopped)
            except BaseException:
                run.abort()
                raise


def video_frames(options: VideoToFileOptions, video: Path) -> Iterator[Any]:
    """The video's frames as the run simulates them: decoded, mapped, upsampled if asked."""
    from ...scenes.video import iter_video

    frames = iter_video(
        video,
        start_frame=options.start_frame,
        n_frames=options.frames,
        size=options.size,
        peak_intensity=options.peak_intensity,
        allow_truncated=options.allow_truncated,
        input_mapping=options.input_mapping,
        dtype=options.dtype,
    )
    if options.upsample != "none":
        from ..simulation.upsampling import upsample_frames

        frames = upsample_frames(frames, mode=options.upsample, rate_hz=options.upsample_rate)
    return frames


def progress_total(options: VideoToFileOptions, props: dict) -> int | None:
    """Frames the progress bar counts: the simulated (upsampled) ones; None if the file does not say.

    Parameters
    ----------
    options : VideoToFileOptions
        The run's frames and upsampling.
    props : dict
        :func:`fsdvs_hw.scenes.video.video_properties` of the video.
    """
    total = props.get("nframes")
    total = (
        options.frames if options.frames is not None else (max(int(total) - options.start_frame, 0) if total else None)
    )
    if total and options.upsample != "none" and props.get("fps"):
        total = (total - 1) * max(math.ceil(options.upsample_rate / float(props["fps"]) - 1e-9), 1) + 1
    return total


def open_writer(writer_class: Any, options: VideoToFileOptions, video: Path, h_w: tuple[int, int]) -> Any:
    """The event file writer for ``options.out``, for frames of ``h_w`` = (H, W) pixels, with the
    run's metadata."""
    upsample = options.upsample if options.upsample == "none" else f"{options.upsample} {options.upsample_rate:g} Hz"
    metadata = {
        "source": str(video),
        "preset": options.preset,
        "kernel": options.kernel or "none",
        "input_mapping": options.input_mapping,
        "dtype": options.dtype,
        "upsample": upsample,
    }
    return writer_class(options.out, int(h_w[1]), int(h_w[0]), metadata=metadata)


def frame_size(props: dict, size: tuple[int, int] | None) -> tuple[int, int] | None:
    """(H, W) of the simulated frames (pixels): ``size``, else the source's; None if the file does not say.

    Parameters
    ----------
    props : dict
        :func:`fsdvs_hw.scenes.video.video_properties` of the video.
    size : (int, int) or None
        The requested (H, W), or None.
    """
    if size is not None:
        return size
    src = props.get("source_size")
    return (int(src[1]), int(src[0])) if src else None


def prefetch_frame_count(h_w: tuple[int, int] | None, dtype: str) -> int:
    """Frames the decoding thread may hold ahead: :data:`PREFETCH_BYTES` of frames of ``h_w`` =
    (H, W) pixels, at least 2 and at most 256; 8 if the size is unknown."""
    if not h_w:
        return 8
    per_frame = int(h_w[0]) * int(h_w[1]) * (8 if dtype == "float64" else 4)
    return int(min(max(PREFETCH_BYTES // max(per_frame, 1), 2), 256))


class VideoToFileRun:
    """One run: the video's properties and its writer (opened in a thread while torch loads), its
    frames (decoded in a thread), its progress bar; :meth:`abort` stops them all and leaves no file.

    ``options`` and ``video`` are those of :func:`simulate_video_to_file`, which drives a run.
    """

    def __init__(self, options: VideoToFileOptions, video: Path) -> None:
        self.options, self.video = options, video
        self.props: dict = {}
        self.probe: Future | None = None
        self.frames: Any = None
        self.writer: Any = None
        self.bar: Any = None

    def simulate_to_file(self, config: Any, stopped: list[int]) -> tuple[int, int, float]:
        """Simulate and write every chunk; the events, ON events and seconds since the first frame.

        ``stopped``: the signals recorded by :func:`.run_control.stop_on_signals`; one there stops
        the run (:class:`.run_control.Stopped`) even where a library swallowed its exception."""
        from .eventfile import EventFileWriter

        options = self.options
        # The video is probed (an ffmpeg process) and the writer process started, where the file
        # says its frame size, in a thread while this one loads torch: the writer loads h5py or
        # dv-processing on the other core meanwhile (docs/speed.md).
        pool = ThreadPoolExecutor(1, thread_name_prefix="fsdvs-probe")
        self.probe = pool.submit(self._probe_and_open_writer)
        pool.shutdown(wait=False)  # its thread ends with the probe; nothing waits here
        with signals_deferred(stopped):
            simulate = self._import()
        self.probe.result()  # the probe's error (an unreadable video) is raised here
        h_w = frame_size(self.props, options.size)
        kernel, chunk_frames = self._start(h_w)
        t0 = time.perf_counter()
        n_events = n_on = 0
        for chunk in simulate(self.frames, kernel, config=config, chunk_frames=chunk_frames):
            if stopped:  # the signal's exception was swallowed on its way up
                raise Stopped(stopped[0])
            if self.writer is None or (self.writer.width, self.writer.height) != (chunk.width, chunk.height):
                if self.writer is not None:  # the container's declared size was not the frames' size
                    self.writer.abort()
                self.writer = open_writer(EventFileWriter, options, self.video, (chunk.height, chunk.width))
            assert chunk.events is not None  # simulate() yields events by default (events=True)
            self.writer.write(chunk.events)
            n_events += len(chunk.events)
            n_on += int((chunk.events.p > 0).sum())
            self.bar.update(chunk.n_frames)
            self.bar.set_postfix_str(f"{n_events / max(time.perf_counter() - t0, 1e-9):.3g} ev/s, {n_events} events")
            del chunk  # free this chunk's events before the next one is simulated
        if stopped:
            raise Stopped(stopped[0])
        if self.writer is not None:
            self.writer.close()  # renames the finished file onto options.out
        self._release()
        return n_events, n_on, time.perf_counter() - t0

    def _probe_and_open_writer(self) -> None:
        """The video's properties, then the writer where they give the frame size."""
        from ...scenes.video import video_properties
        from .eventfile import EventFileWriter

        self.props = video_properties(self.video)
        h_w = frame_size(self.props, self.options.size)
        if h_w:
            self.writer = open_writer(EventFileWriter, self.options, self.video, h_w)

    def _import(self) -> Any:
        """torch and the simulator loaded: the streaming ``simulate``."""
        with collector_spares_imports():
            import torch  # noqa: F401  the bulk of the command's start-up

            from ..simulation.stream import simulate
        return simulate

    def _start(self, h_w: tuple[int, int] | None) -> tuple[Any, int]:
        """Decoding started, threads set, the progress bar open: ``(kernel, chunk_frames)``."""
        import torch

        from ...kernels import load_kernel_or_reference
        from ...prefetch import prefetch
        from ...progress import progress_bar
        from ..simulation.stream import MIN_CHUNK_FRAMES, chunk_frames_for
        from ..simulation.threads import event_list_threads

        options = self.options
        # Decoding runs in its own thread, beside the simulation (docs/speed.md); at most
        # PREFETCH_BYTES of frames wait ahead.
        frames = video_frames(options, self.video)
        self.frames = prefetch(frames, max_items=prefetch_frame_count(h_w, options.dtype), name="fsdvs-decode")
        torch.set_num_threads(options.threads if options.threads is not None else event_list_threads())
        kernel = load_kernel_or_reference(options.kernel) if options.kernel else None
        chunk_frames = options.chunk_frames
        if chunk_frames is None:
            chunk_frames = chunk_frames_for(*h_w) if h_w else MIN_CHUNK_FRAMES
        total = progress_total(options, self.props)
        self.bar = progress_bar(total=total, unit="frame", desc="simulate", progress=options.progress)
        return kernel, chunk_frames

    def _release(self) -> None:
        """Stop the decoding thread (and its ffmpeg) and close the progress bar."""
        if self.frames is not None:
            self.frames.close()
        if self.bar is not None:
            self.bar.close()

    def abort(self) -> None:
        """Remove the partial file, stop decoding, close the bar."""
        if self.probe is not None:
            futures_wait([self.probe])  # a writer it is opening is aborted below
        if self.writer is not None:
            self.writer.abort()
        self._release()
