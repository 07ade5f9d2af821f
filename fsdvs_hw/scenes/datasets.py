"""User clip datasets: a sequence of clips (linear intensity, timestamps, task targets) read from disk.

A :class:`ClipDataset` is a ``Sequence`` of :class:`Clip`; a clip is decoded when it is asked
for (``dataset[i]``), never the whole dataset at load, with an optional in-memory LRU cache of
``cache_clips`` decoded clips. Loading a dataset only reads its layout (folder names, the JSON,
image headers) and checks it; a problem raises :class:`~fsdvs_hw.errors.InputError` naming the
file, the clip and the field.

Frames
    ``Clip.frames`` is LINEAR relative luminance, float64, shape (T, H, W), 1.0 = display white:
    8-bit code values are divided by 255, the sRGB transfer function (IEC 61966-2-1) is undone
    (``transfer="sRGB"``, default; any colour-science ``CCTF_DECODINGS`` name is accepted) and
    the Rec. 709 luminance weights (0.2126, 0.7152, 0.0722) combine R, G, B. A grey of code 128
    becomes ``((128/255 + 0.055) / 1.055) ** 2.4 = 0.21586``.
Resolution
    Every clip of a dataset has one stated size ``(H, W)``: ``size=None`` keeps the files' size
    (all frames must share it, checked), ``size=(H, W)`` resizes in linear light (area
    anti-aliasing); boxes are scaled with the frame and label masks resized nearest-neighbour.
    No cropping.
Timestamps
    Seconds, ``frame index / fps`` from the clip's first frame: ``fps`` as stated, else the
    video container's frame rate.
Targets
    The structure the built-in evaluators (:mod:`fsdvs_hw.tasks.evaluators`) consume, for the
    clip's LAST frame, without the clip axis (:func:`stack_targets` adds it):

    * recognition: ``{"motion": int64 ()}`` — class index in ``[0, num_classes)``;
    * detection: ``{"boxes": float64 (M, 4), "labels": int64 (M,)}`` — ``(x0, y0, x1, y1)`` in
      pixels of the returned frame, unused slots ``-1`` (box) and ``-1`` (label); ``M`` is the
      dataset's most objects in one image;
    * segmentation: ``{"mask": int64 (H, W)}`` — class per pixel, ``ignore_index`` kept as is.

Readers: :class:`VideoFolderDataset` (UCF101 layout), :class:`CocoFramesDataset` (frames + COCO
JSON), :class:`DsecDetectionDataset` (DSEC-Detection: rectified left images + ``tracks.npy``),
:class:`MaskFramesDataset` (frames + label-mask PNGs).
"""

from __future__ import annotations

import collections
import json
import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..limits import MAX_CLIPS, check_allocation, check_count
from .clip_cache import ClipDiskCache

__all__ = [
    "DSEC_DETECTION_CLASSES",
    "DSEC_TRACK_FIELDS",
    "IMAGE_SUFFIXES",
    "VIDEO_SUFFIXES",
    "Clip",
    "ClipDataset",
    "CocoFramesDataset",
    "DsecDetectionDataset",
    "MaskFramesDataset",
    "VideoFolderDataset",
    "code_to_linear",
    "stack_targets",
]

#: File endings read as videos (recognition folders).
VIDEO_SUFFIXES: tuple[str, ...] = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".mpg", ".mpeg")
#: File endings read as frame images.
IMAGE_SUFFIXES: tuple[str, ...] = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass(frozen=True)
class Clip:
    """One clip of a user dataset.

    Attributes
    ----------
    frames : numpy.ndarray, float64, shape (T, H, W)
        Linear relative luminance (1.0 = display white).
    timestamps_s : numpy.ndarray, float64, shape (T,)
        Frame times in seconds from the clip's first frame.
    targets : dict of str to numpy.ndarray
        The evaluator's targets for the last frame, without the clip axis (see the module text).
    source : str
        The file(s) the clip came from (for messages).
    index : int
        Position in its dataset.
    """

    frames: np.ndarray
    timestamps_s: np.ndarray
    targets: dict[str, np.ndarray | np.generic]  # a class label may be a NumPy scalar
    source: str
    index: int
    metadata: dict[str, Any] = field(default_factory=dict)

    def as_batch(self, dtype: Any = None) -> Any:
        """The frames as a (1, T, H, W) torch tensor for :func:`fsdvs_hw.sensor.event_frames`."""
        import torch

        return torch.from_numpy(np.ascontiguousarray(self.frames))[None].to(dtype or torch.float64)


def stack_targets(clips: Sequence[Clip]) -> dict[str, np.ndarray]:
    """The clips' targets with a leading clip axis, as the evaluators' ``score`` expects.

    Example
    -------
    >>> c = Clip(np.zeros((2, 1, 1)), np.arange(2.0), {"motion": np.int64(1)}, "x", 0)
    >>> stack_targets([c, c])["motion"].tolist()
    [1, 1]
    """
    if not clips:
        raise InputError("stack_targets: no clips")
    return {k: np.stack([np.asarray(c.targets[k]) for c in clips]) for k in clips[0].targets}


def code_to_linear(code: np.ndarray, transfer: str = "sRGB") -> np.ndarray:
    """Display code values (uint8/uint16 grey or RGB, or floats in [0, 1]) → linear luminance (float64).

    Undoes ``transfer`` (default sRGB) and weights R, G, B with Rec. 709 luminance.

    Example
    -------
    >>> round(float(code_to_linear(np.array([[128]], np.uint8))[0, 0]), 5)
    0.21586
    """
    from .video import display_to_linear

    arr = np.asarray(code)
    if arr.ndim == 3 and arr.shape[-1] == 4:
        arr = arr[..., :3]  # drop alpha
    return display_to_linear(arr, transfer=transfer, colourspace="ITU-R BT.709")


def _resize(img: np.ndarray, size: tuple[int, int], *, labels: bool = False) -> np.ndarray:
    from skimage.transform import resize

    if img.shape == tuple(size):
        return img
    if labels:
        return resize(img, size, order=0, anti_aliasing=False, preserve_range=True).astype(img.dtype)
    return resize(img, size, anti_aliasing=True, preserve_range=True)


def _check_size(size: Any, who: str) -> tuple[int, int] | None:
    if size is None:
        return None
    if (
        not isinstance(size, (tuple, list))
        or len(size) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 16384 for v in size)
    ):
        raise InputError(f"{who}: size={size!r}; allowed: None or (H, W), integers in [1, 16384]")
    return int(size[0]), int(size[1])


def _check_fps(fps: Any, who: str) -> float | None:
    if fps is None:
        return None
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not 0 < float(fps) <= 1e6:
        raise InputError(f"{who}: fps={fps!r}; allowed: None (the container's) or a frame rate in (0, 1e6] Hz")
    return float(fps)


def _image_size(path: Path, who: str, field_name: str = "file") -> tuple[int, int]:
    """(H, W) from an image's header, without decoding its pixels."""
    from PIL import Image

    if not path.is_file():
        raise InputError(f"{who}: {field_name} {str(path)!r} does not exist")
    try:
        with Image.open(path) as im:
            w, h = im.size
    except Exception as exc:  # PIL raises several types for unreadable files
        raise InputError(f"{who}: {field_name} {str(path)!r} is not a readable image ({type(exc).__name__})") from None
    return h, w


def _read_image(path: Path, who: str) -> np.ndarray:
    from PIL import Image

    try:
        with Image.open(path) as im:
            return np.asarray(im)
    except Exception as exc:
        raise InputError(f"{who}: image {str(path)!r} cannot be decoded ({type(exc).__name__})") from None


class ClipDataset(Sequence[Clip], ABC):
    """A sequence of clips decoded on demand, with a seeded draw and an optional LRU cache.

    Subclasses set :attr:`task`, :attr:`num_classes`, :attr:`class_names`, :attr:`size`,
    :attr:`n_frames` and implement :meth:`_load` (decode clip ``i``) and :meth:`__len__`.

    Attributes
    ----------
    task : str
        ``"recognition"``, ``"detection"`` or ``"segmentation"`` (an evaluator name).
    num_classes : int
        Classes of the targets (segmentation: including background, excluding ``ignore_index``).
    class_names : tuple of str
    size : (H, W) or None
        The stated frame size in pixels (None: the files' size, checked per clip).
    n_frames : int
        Frames per clip (T).
    ignore_index : int or None
        Segmentation label that is not scored.
    """

    task: str = ""
    num_classes: int = 0
    class_names: tuple[str, ...] = ()
    size: tuple[int, int] | None = None
    n_frames: int = 0
    ignore_index: int | None = None
    transfer: str = "sRGB"

    def __init__(self, *, cache_clips: int = 0, disk_cache: ClipDiskCache | None = None) -> None:
        self.cache_clips = check_count("cache_clips", cache_clips, 0, MAX_CLIPS)
        self._cache: collections.OrderedDict[int, Clip] = collections.OrderedDict()
        self.disk_cache = disk_cache

    @abstractmethod
    def __len__(self) -> int:
        """Number of clips."""

    @abstractmethod
    def _load(self, i: int) -> Clip:
        """Decode clip ``i`` (0 <= i < len)."""

    def clip_files(self, i: int) -> tuple[Path, ...]:
        """The files clip ``i``'s pixels are decoded from (video, frame images, label mask).

        Used for the disk cache's key and to check that a training split shares no file with the
        scored one. A reader that cannot name them cannot use a ``disk_cache``.
        """
        raise NotImplementedError(f"{type(self).__name__} does not name its clips' files")

    def decode_options(self) -> dict[str, Any]:
        """Every setting that changes a clip's decoded arrays (part of the disk cache's key)."""
        return {"reader": type(self).__name__, "n_frames": self.n_frames, "size": self.size, "transfer": self.transfer}

    def _decoded(self, i: int, decode: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """``decode()``'s arrays for clip ``i``, through the disk cache when there is one."""
        if self.disk_cache is None:
            return decode()
        return self.disk_cache.decoded(self.disk_cache.key(self.clip_files(i), self.decode_options()), decode)

    def __getitem__(self, i: Any) -> Any:  # Sequence: int → Clip, slice → list of clips
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not -len(self) <= int(i) < len(self):
            raise IndexError(f"clip index {i!r} out of range for {len(self)} clips")
        i = int(i) % len(self)
        hit = self._cache.get(i)
        if hit is not None:
            self._cache.move_to_end(i)
            return hit
        h, w = self.size if self.size is not None else (0, 0)
        if self.size is not None:
            check_allocation(
                f"{type(self).__name__} clip {i} (T={self.n_frames}, H={h}, W={w}, float64)", 8 * self.n_frames * h * w
            )
        clip = self._load(i)
        if self.cache_clips:
            self._cache[i] = clip
            while len(self._cache) > self.cache_clips:
                self._cache.popitem(last=False)
        return clip

    def draw(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` distinct clip indices drawn at random with ``seed`` (same seed → same indices).

        Example
        -------
        >>> ds.draw(2, seed=0).tolist() == ds.draw(2, seed=0).tolist()   # doctest: +SKIP
        True
        """
        n = check_count("n_clips", n, 1, len(self))
        seed = check_count("seed", seed, 0, 2**32 - 1)
        return np.sort(np.random.default_rng(seed).choice(len(self), size=n, replace=False))

    def iter_clips(self, indices: Sequence[int] | None = None) -> Iterator[Clip]:
        """Clips ``indices`` (default all), decoded one at a time."""
        for i in range(len(self)) if indices is None else indices:
            yield self[int(i)]

    def _frames(self, images: Sequence[np.ndarray], where: str) -> np.ndarray:
        """Stack code-value images into linear (T, H, W) at the stated size."""
        out: list[np.ndarray] = []
        for k, img in enumerate(images):
            lum = code_to_linear(img, self.transfer)
            if lum.ndim != 2:
                raise InputError(
                    f"{where}: frame {k} has shape {img.shape}; allowed: (H, W) grey or (H, W, 3|4) colour"
                )
            if self.size is not None:
                lum = _resize(lum, self.size)
            elif out and lum.shape != out[0].shape:
                raise InputError(
                    f"{where}: frame {k} is {lum.shape[0]}x{lum.shape[1]}, frame 0 "
                    f"{out[0].shape[0]}x{out[0].shape[1]}; field 'size': pass size=(H, W) to resize"
                )
            out.append(lum)
        return np.stack(out)


def _window_starts(n_total: int, n_frames: int, clip_stride: int) -> list[int]:
    return list(range(0, n_total - n_frames + 1, clip_stride))


# --------------------------------------------------------------------------- recognition
class VideoFolderDataset(ClipDataset):
    """Recognition clips from a folder of videos, one subfolder per class (UCF101 layout).

    ``root/<class>/<video>.mp4``; classes are the subfolder names in sorted order (label = index).
    Each video gives one clip: its frames ``start_frame, start_frame + stride, ...`` (``n_frames``).

    Parameters
    ----------
    root : path
        The folder of class folders.
    n_frames : int
        Frames per clip (T >= 2).
    size : (H, W), optional
        Resize every frame to this size (default: keep; all videos must then share one size).
    split_file : path, optional
        UCF101 ``trainlist0N.txt`` / ``testlist0N.txt``: one ``<class>/<video>`` path relative to
        ``root`` per line, optionally followed by a (1-based) label, which is ignored: the class
        is the folder. Only the listed videos are used.
    fps : float, optional
        Frame rate in Hz for the timestamps (default: each container's).
    stride, start_frame : int
        Which frames of each video.
    transfer : str
        Transfer function undone (default ``"sRGB"``).
    cache_clips : int
        Decoded clips kept in memory (LRU; 0 = none).
    disk_cache : ClipDiskCache, optional
        Decoded clips kept on disk, bounded (:mod:`fsdvs_hw.scenes.clip_cache`).

    Raises
    ------
    InputError
        Missing root, no class folders, an empty class folder (field ``videos``), a split-file
        line naming a missing file (field ``path``); on access, a video that does not decode or
        is too short (field ``frames``).

    Example
    -------
    >>> ds = VideoFolderDataset("UCF101/videos", n_frames=9, size=(32, 32))   # doctest: +SKIP
    >>> ds[0].frames.shape, ds.class_names[int(ds[0].targets["motion"])]      # doctest: +SKIP
    ((9, 32, 32), 'ApplyEyeMakeup')
    """

    task = "recognition"

    def __init__(
        self,
        root: str | Path,
        *,
        n_frames: int = 9,
        size: tuple[int, int] | None = None,
        split_file: str | Path | None = None,
        fps: float | None = None,
        stride: int = 1,
        start_frame: int = 0,
        transfer: str = "sRGB",
        cache_clips: int = 0,
        disk_cache: ClipDiskCache | None = None,
    ) -> None:
        super().__init__(cache_clips=cache_clips, disk_cache=disk_cache)
        who = "VideoFolderDataset"
        self.root = Path(root)
        self.n_frames = check_count(f"{who}: n_frames", n_frames, 2, 100_000)
        self.stride = check_count(f"{who}: stride", stride, 1, 100_000)
        self.start_frame = check_count(f"{who}: start_frame", start_frame, 0, 10**9)
        self.size = _check_size(size, who)
        self.fps = _check_fps(fps, who)
        self.transfer = transfer
        if not self.root.is_dir():
            raise InputError(f"{who}: root {str(self.root)!r} is not a folder")
        classes = sorted(p.name for p in self.root.iterdir() if p.is_dir() and not p.name.startswith("."))
        if not classes:
            raise InputError(f"{who}: root {str(self.root)!r} has no class folders (layout: root/<class>/<video>)")
        videos: dict[str, list[Path]] = {}
        for c in classes:
            files = sorted(p for p in (self.root / c).iterdir() if p.suffix.lower() in VIDEO_SUFFIXES)
            if not files:
                raise InputError(
                    f"{who}: class folder {str(self.root / c)!r} is empty: field 'videos' needs at "
                    f"least one file ending in {', '.join(VIDEO_SUFFIXES)}"
                )
            videos[c] = files
        self.class_names = tuple(classes)
        self.num_classes = len(classes)
        label = {c: k for k, c in enumerate(classes)}
        if split_file is None:
            self.items = [(p, label[c]) for c in classes for p in videos[c]]
        else:
            self.items = self._read_split(Path(split_file), label)
        check_count(f"{who}: number of clips", len(self.items), 1, MAX_CLIPS)

    def _read_split(self, split: Path, label: dict[str, int]) -> list[tuple[Path, int]]:
        who = "VideoFolderDataset"
        if not split.is_file():
            raise InputError(f"{who}: split_file {str(split)!r} does not exist")
        items = []
        for n, line in enumerate(split.read_text(encoding="utf-8", errors="replace").splitlines(), start=1):
            rel = line.strip().split(" ")[0] if line.strip() else ""
            if not rel:
                continue
            path = self.root / rel
            cls = Path(rel).parts[0] if len(Path(rel).parts) == 2 else None
            if cls not in label:
                raise InputError(
                    f"{who}: split_file {str(split)!r} line {n}: field 'path' {rel!r} is not "
                    f"<class>/<video> with a class folder of {str(self.root)!r}"
                )
            if not path.is_file():
                raise InputError(
                    f"{who}: split_file {str(split)!r} line {n}: field 'path' {rel!r}: "
                    f"file {str(path)!r} does not exist"
                )
            items.append((path, label[cls]))
        if not items:
            raise InputError(f"{who}: split_file {str(split)!r} lists no videos")
        return items

    def __len__(self) -> int:
        return len(self.items)

    def clip_files(self, i: int) -> tuple[Path, ...]:
        """The video of clip ``i``."""
        return (self.items[i][0],)

    def decode_options(self) -> dict[str, Any]:
        """The base options plus ``fps``, ``stride`` and ``start_frame``."""
        return {**super().decode_options(), "fps": self.fps, "stride": self.stride, "start_frame": self.start_frame}

    def _load(self, i: int) -> Clip:
        path, lab = self.items[i]
        arrays = self._decoded(i, lambda: self._decode(i))
        fps = float(arrays["fps"])
        wanted = np.arange(self.n_frames, dtype=np.float64) * self.stride
        return Clip(arrays["frames"], wanted / fps, {"motion": np.int64(lab)}, str(path), i, {"fps": fps})

    def _decode(self, i: int) -> dict[str, np.ndarray]:
        """Clip ``i``'s frames (linear, at the stated size) and its frame rate, from the video."""
        import imageio

        from .video import ffmpeg_failure_reason

        path, _ = self.items[i]
        where = f"VideoFolderDataset: clip {i} ({str(path)!r})"
        try:
            reader = imageio.get_reader(str(path), "ffmpeg")
        except Exception as exc:
            raise InputError(
                f"{where}: field 'frames': the video does not decode ({ffmpeg_failure_reason(exc)})"
            ) from None
        try:
            fps = self.fps or float(reader.get_meta_data().get("fps") or 0.0)
            if not fps > 0:
                raise InputError(f"{where}: field 'fps': the container states no frame rate; pass fps=")
            wanted = [self.start_frame + k * self.stride for k in range(self.n_frames)]
            images: list[np.ndarray] = []
            try:
                # imageio's stub has Reader.__iter__ return one Array, not an iterator of them
                frame: np.ndarray
                for j, frame in enumerate(reader):  # type: ignore[arg-type]
                    if j in wanted:
                        images.append(np.asarray(frame))
                    if j >= wanted[-1]:
                        break
            except Exception as exc:
                raise InputError(
                    f"{where}: field 'frames': decoding stopped after {j} frames ({ffmpeg_failure_reason(exc)})"
                ) from None
        finally:
            reader.close()
        if len(images) < self.n_frames:
            raise InputError(
                f"{where}: field 'frames': {len(images)} of the {self.n_frames} frames wanted "
                f"(start_frame={self.start_frame}, stride={self.stride})"
            )
        return {"frames": self._frames(images, where), "fps": np.asarray(fps, dtype=np.float64)}


# --------------------------------------------------------------------------- detection
def _coco_document(path: Path, who: str) -> dict[str, Any]:
    """A COCO annotations file read: a JSON object with the lists ``images``, ``annotations``, ``categories``."""
    j = str(path)
    if not path.is_file():
        raise InputError(f"{who}: annotations file {j!r} does not exist")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{who}: annotations file {j!r} is not JSON ({exc})") from None
    for key in ("images", "annotations", "categories"):
        if not isinstance(doc, dict) or not isinstance(doc.get(key), list):
            raise InputError(f"{who}: annotations file {j!r}: field {key!r} missing or not a list")
    return doc


def _coco_categories(doc: Mapping[str, Any], who: str, j: str) -> tuple[list[int], dict[int, str]]:
    """The sorted category ids and their names (the id where a category has no name)."""
    cats = doc["categories"]
    try:
        cat_ids = sorted(int(c["id"]) for c in cats)
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{who}: annotations file {j!r}: field 'categories' entries need an integer 'id'") from None
    if not cat_ids:
        raise InputError(f"{who}: annotations file {j!r}: field 'categories' is empty")
    names = {int(c["id"]): str(c.get("name", c["id"])) for c in cats}
    return cat_ids, names


def _coco_images(doc: Mapping[str, Any], frames_dir: Path, who: str, j: str) -> dict[int, dict[str, Any]]:
    """Image id → its entry, each with the required fields and an existing frame file."""
    images: dict[int, dict[str, Any]] = {}
    for k, im in enumerate(doc["images"]):
        if not isinstance(im, dict) or not all(f in im for f in ("id", "file_name", "width", "height")):
            raise InputError(
                f"{who}: annotations file {j!r}: images[{k}] needs fields 'id', 'file_name', 'width', 'height'"
            )
        path = frames_dir / str(im["file_name"])
        if not path.is_file():
            raise InputError(
                f"{who}: annotations file {j!r}: images[{k}] field 'file_name': image {str(path)!r} does not exist"
            )
        images[int(im["id"])] = im
    return images


def _coco_boxes(
    doc: Mapping[str, Any], images: Mapping[int, Mapping[str, Any]], rank: Mapping[int, int], who: str, j: str
) -> dict[int, list[tuple[list[float], int]]]:
    """Image id → its boxes ``([x0, y0, x1, y1] px, class index)``, each checked against its image and categories."""
    boxes: dict[int, list[tuple[list[float], int]]] = {i: [] for i in images}
    for k, a in enumerate(doc["annotations"]):
        aid = a.get("id", k) if isinstance(a, dict) else k
        try:
            iid, cid = int(a["image_id"]), int(a["category_id"])
            x, y, w, h = (float(v) for v in a["bbox"])
        except (KeyError, TypeError, ValueError):
            raise InputError(
                f"{who}: annotations file {j!r}: annotation {aid}: fields 'image_id', "
                "'category_id' and 'bbox' [x, y, w, h] are required"
            ) from None
        if iid not in images:
            raise InputError(f"{who}: annotations file {j!r}: annotation {aid}: field 'image_id' {iid} names no image")
        if cid not in rank:
            raise InputError(
                f"{who}: annotations file {j!r}: annotation {aid}: field 'category_id' {cid} "
                f"is not among the categories {list(rank)}"
            )
        im = images[iid]
        W, H = float(im["width"]), float(im["height"])
        if not (
            np.isfinite([x, y, w, h]).all()
            and w > 0
            and h > 0
            and x >= 0
            and y >= 0
            and x + w <= W + 1e-6
            and y + h <= H + 1e-6
        ):
            raise InputError(
                f"{who}: annotations file {j!r}: annotation {aid} (image "
                f"{im['file_name']!r}): field 'bbox' {[x, y, w, h]} lies outside the "
                f"{W:g}x{H:g} image or is empty"
            )
        boxes[iid].append(([x, y, x + w, y + h], rank[cid]))
    return boxes


class CocoFramesDataset(ClipDataset):
    """Detection clips from a folder of frame images and a COCO JSON of boxes.

    The JSON's ``images`` (``id``, ``file_name`` relative to ``frames_dir``, ``width``,
    ``height``; optional ``video_id`` and ``frame_id`` group and order sequences, else one
    sequence in ``file_name`` order), ``annotations`` (``image_id``, ``bbox`` = ``[x, y, w, h]``
    in pixels, ``category_id``) and ``categories`` (``id``, ``name``; label = rank of the id).
    Clips are ``n_frames`` consecutive frames of one sequence, starting every ``clip_stride``
    frames (default ``n_frames``: no overlap); the targets are the last frame's boxes.

    Parameters
    ----------
    frames_dir : path
    annotations : path
        The COCO JSON.
    n_frames, clip_stride : int
    size : (H, W), optional
        Resize frames (boxes scaled with them).
    fps : float
        Frame rate in Hz (images carry none).
    require_annotations : bool
        True (default): every image must have at least one annotation (field ``annotations``).
    transfer : str
    cache_clips : int
    disk_cache : ClipDiskCache, optional

    Raises
    ------
    InputError
        Naming the JSON or image file and the field: unreadable JSON, missing ``images`` /
        ``annotations`` / ``categories``, a missing image file, an image without annotations
        (when required), a ``bbox`` outside the image or not positive, a ``category_id`` not
        among the categories, an image whose size differs from its ``width`` / ``height``.

    Example
    -------
    >>> ds = CocoFramesDataset("seq/frames", "seq/instances.json", n_frames=4, fps=30.0)   # doctest: +SKIP
    >>> ds[0].targets["boxes"].shape                                                        # doctest: +SKIP
    (2, 4)
    """

    task = "detection"

    def __init__(
        self,
        frames_dir: str | Path,
        annotations: str | Path,
        *,
        n_frames: int = 4,
        clip_stride: int | None = None,
        size: tuple[int, int] | None = None,
        fps: float = 30.0,
        require_annotations: bool = True,
        transfer: str = "sRGB",
        cache_clips: int = 0,
        disk_cache: ClipDiskCache | None = None,
    ) -> None:
        super().__init__(cache_clips=cache_clips, disk_cache=disk_cache)
        who = "CocoFramesDataset"
        self.frames_dir, self.json_path = Path(frames_dir), Path(annotations)
        self.n_frames = check_count(f"{who}: n_frames", n_frames, 2, 100_000)
        self.clip_stride = check_count(
            f"{who}: clip_stride", self.n_frames if clip_stride is None else clip_stride, 1, 100_000
        )
        self.size = _check_size(size, who)
        fps_checked = _check_fps(fps, who)
        if fps_checked is None:
            raise InputError(f"{who}: fps is required (frame images carry no frame rate)")
        self.fps = fps_checked
        self.transfer = transfer
        j = str(self.json_path)
        doc = _coco_document(self.json_path, who)
        cat_ids, names = _coco_categories(doc, who, j)
        self.category_ids = tuple(cat_ids)
        self.class_names = tuple(names[c] for c in cat_ids)
        self.num_classes = len(cat_ids)
        rank = {c: k for k, c in enumerate(cat_ids)}
        images = _coco_images(doc, self.frames_dir, who, j)
        boxes = _coco_boxes(doc, images, rank, who, j)
        if require_annotations:
            for iid, im in images.items():
                if not boxes[iid]:
                    raise InputError(
                        f"{who}: annotations file {j!r}: image {im['file_name']!r} (id {iid}) has "
                        "no entry in field 'annotations' (pass require_annotations=False to allow)"
                    )
        seqs: dict[Any, list[int]] = collections.defaultdict(list)
        for iid, im in images.items():
            seqs[im.get("video_id", 0)].append(iid)
        self.images, self.boxes = images, boxes
        self.max_objects = max(1, max(len(b) for b in boxes.values()) if boxes else 1)
        self.clips: list[list[int]] = []
        for key in sorted(seqs, key=str):
            order = sorted(seqs[key], key=lambda i: (images[i].get("frame_id", 0), str(images[i]["file_name"])))
            self.clips += [
                order[s : s + self.n_frames] for s in _window_starts(len(order), self.n_frames, self.clip_stride)
            ]
        if not self.clips:
            raise InputError(f"{who}: annotations file {j!r}: no sequence has {self.n_frames} frames (field 'images')")
        check_count(f"{who}: number of clips", len(self.clips), 1, MAX_CLIPS)

    def __len__(self) -> int:
        return len(self.clips)

    def clip_files(self, i: int) -> tuple[Path, ...]:
        """The frame images of clip ``i`` and the annotations file (its stated image sizes are checked)."""
        return (*(self.frames_dir / str(self.images[iid]["file_name"]) for iid in self.clips[i]), self.json_path)

    def _load(self, i: int) -> Clip:
        ids = self.clips[i]
        frames = self._decoded(i, lambda: {"frames": self._decode(i)})["frames"]
        last = self.images[ids[-1]]
        sy = frames.shape[1] / float(last["height"])
        sx = frames.shape[2] / float(last["width"])
        b = np.full((self.max_objects, 4), -1.0)
        lab = np.full(self.max_objects, -1, np.int64)
        for k, (box, c) in enumerate(self.boxes[ids[-1]]):
            b[k] = np.asarray(box) * [sx, sy, sx, sy]
            lab[k] = c
        ts = np.arange(len(ids), dtype=np.float64) / self.fps
        return Clip(
            frames,
            ts,
            {"boxes": b, "labels": lab},
            str(self.frames_dir / str(last["file_name"])),
            i,
            {"image_ids": list(ids)},
        )

    def _decode(self, i: int) -> np.ndarray:
        """Clip ``i``'s frames (linear, at the stated size), each image checked against its stated size."""
        imgs = []
        for iid in self.clips[i]:
            im = self.images[iid]
            path = self.frames_dir / str(im["file_name"])
            where = f"CocoFramesDataset: clip {i} ({str(path)!r})"
            arr = _read_image(path, where)
            if arr.shape[:2] != (int(im["height"]), int(im["width"])):
                raise InputError(
                    f"{where}: image is {arr.shape[1]}x{arr.shape[0]} but the annotations file "
                    f"{str(self.json_path)!r} states field 'width'x'height' {im['width']}x{im['height']}"
                )
            imgs.append(arr)
        return self._frames(imgs, f"CocoFramesDataset: clip {i}")


# --------------------------------------------------------------------------- segmentation
class MaskFramesDataset(ClipDataset):
    """Segmentation clips from frame images and label-mask PNGs (Cityscapes / DSEC-Semantic style).

    ``frames_dir`` holds the frames (sorted by name = time order); the mask of frame ``<stem><frame_suffix>.ext``
    is ``masks_dir/<stem><mask_suffix>`` (defaults: same stem, ``.png``), an integer class per pixel
    (8- or 16-bit grey PNG), ``ignore_index`` (default 255) for unlabelled pixels. Clips are
    ``n_frames`` consecutive frames every ``clip_stride``; the target is the last frame's mask.

    Parameters
    ----------
    frames_dir, masks_dir : path
    num_classes : int
        Declared classes: labels must lie in ``[0, num_classes)`` or equal ``ignore_index``.
    n_frames, clip_stride : int
    size : (H, W), optional
        Resize frames (linear light) and masks (nearest neighbour).
    fps : float
        Frame rate in Hz.
    ignore_index : int or None
    frame_suffix, mask_suffix : str
        Cityscapes: ``"_leftImg8bit"`` and ``"_gtFine_labelTrainIds.png"``.
    transfer : str
    cache_clips : int
    disk_cache : ClipDiskCache, optional

    Raises
    ------
    InputError
        No frames, a frame without its mask file (field ``mask``), a mask whose size differs from
        its frame's (field ``size``, checked from the headers at load); on access, a class id
        beyond the declared classes (field ``class id``).

    Example
    -------
    >>> ds = MaskFramesDataset("seq/frames", "seq/labels", num_classes=19, n_frames=3)   # doctest: +SKIP
    >>> ds[0].targets["mask"].shape                                                      # doctest: +SKIP
    (64, 128)
    """

    task = "segmentation"

    def __init__(
        self,
        frames_dir: str | Path,
        masks_dir: str | Path,
        *,
        num_classes: int,
        n_frames: int = 3,
        clip_stride: int | None = None,
        size: tuple[int, int] | None = None,
        fps: float = 30.0,
        ignore_index: int | None = 255,
        frame_suffix: str = "",
        mask_suffix: str = ".png",
        class_names: Sequence[str] | None = None,
        transfer: str = "sRGB",
        cache_clips: int = 0,
        disk_cache: ClipDiskCache | None = None,
    ) -> None:
        super().__init__(cache_clips=cache_clips, disk_cache=disk_cache)
        who = "MaskFramesDataset"
        self.frames_dir, self.masks_dir = Path(frames_dir), Path(masks_dir)
        self.num_classes = check_count(f"{who}: num_classes", num_classes, 2, 65535)
        self.n_frames = check_count(f"{who}: n_frames", n_frames, 2, 100_000)
        self.clip_stride = check_count(
            f"{who}: clip_stride", self.n_frames if clip_stride is None else clip_stride, 1, 100_000
        )
        self.size = _check_size(size, who)
        fps_checked = _check_fps(fps, who)
        if fps_checked is None:
            raise InputError(f"{who}: fps is required (frame images carry no frame rate)")
        self.fps = fps_checked
        if ignore_index is not None:
            ignore_index = check_count(f"{who}: ignore_index", ignore_index, self.num_classes, 65535)
        self.ignore_index = ignore_index
        self.transfer = transfer
        self.class_names = (
            tuple(class_names) if class_names is not None else tuple(str(k) for k in range(self.num_classes))
        )
        if len(self.class_names) != self.num_classes:
            raise InputError(f"{who}: class_names has {len(self.class_names)} names for num_classes={num_classes}")
        for d, name in ((self.frames_dir, "frames_dir"), (self.masks_dir, "masks_dir")):
            if not d.is_dir():
                raise InputError(f"{who}: {name} {str(d)!r} is not a folder")
        frames = sorted(p for p in self.frames_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not frames:
            raise InputError(
                f"{who}: frames_dir {str(self.frames_dir)!r} holds no images ({', '.join(IMAGE_SUFFIXES)})"
            )
        self.pairs: list[tuple[Path, Path]] = []
        for f in frames:
            stem = re.sub(re.escape(frame_suffix) + "$", "", f.stem) if frame_suffix else f.stem
            m = self.masks_dir / (stem + mask_suffix)
            if not m.is_file():
                raise InputError(f"{who}: frame {str(f)!r}: field 'mask': label file {str(m)!r} does not exist")
            fs, ms = _image_size(f, who, "frame"), _image_size(m, who, "mask")
            if fs != ms:
                raise InputError(
                    f"{who}: mask {str(m)!r}: field 'size' {ms[1]}x{ms[0]} differs from its frame "
                    f"{str(f)!r} {fs[1]}x{fs[0]} (W x H)"
                )
            self.pairs.append((f, m))
        self.clips = [
            list(range(s, s + self.n_frames)) for s in _window_starts(len(self.pairs), self.n_frames, self.clip_stride)
        ]
        if not self.clips:
            raise InputError(
                f"{who}: frames_dir {str(self.frames_dir)!r} has {len(self.pairs)} frames, fewer than "
                f"n_frames={self.n_frames}"
            )
        check_count(f"{who}: number of clips", len(self.clips), 1, MAX_CLIPS)

    def __len__(self) -> int:
        return len(self.clips)

    def clip_files(self, i: int) -> tuple[Path, ...]:
        """The frame images of clip ``i`` and its last frame's label mask."""
        idx = self.clips[i]
        return (*(self.pairs[k][0] for k in idx), self.pairs[idx[-1]][1])

    def decode_options(self) -> dict[str, Any]:
        """The base options plus the classes and ignore index the mask is checked against."""
        return {**super().decode_options(), "num_classes": self.num_classes, "ignore_index": self.ignore_index}

    def _load(self, i: int) -> Clip:
        idx = self.clips[i]
        arrays = self._decoded(i, lambda: self._decode(i))
        frames, mask, mpath = arrays["frames"], arrays["mask"], self.pairs[idx[-1]][1]
        ts = np.arange(len(idx), dtype=np.float64) / self.fps
        return Clip(frames, ts, {"mask": mask}, str(mpath), i, {"frames": [str(self.pairs[k][0]) for k in idx]})

    def _decode(self, i: int) -> dict[str, np.ndarray]:
        """Clip ``i``'s frames (linear, at the stated size) and its last frame's checked, resized mask."""
        idx = self.clips[i]
        where = f"MaskFramesDataset: clip {i}"
        frames = self._frames([_read_image(self.pairs[k][0], where) for k in idx], where)
        mpath = self.pairs[idx[-1]][1]
        mask = _read_image(mpath, where)
        if mask.ndim != 2:
            raise InputError(
                f"{where}: mask {str(mpath)!r}: field 'mode' has shape {mask.shape}; allowed: a "
                "single-channel (grey / palette) PNG of class ids"
            )
        mask = mask.astype(np.int64)
        bad = (mask >= self.num_classes) & (mask != (-1 if self.ignore_index is None else self.ignore_index))
        if bad.any():
            v = int(mask[bad][0])
            raise InputError(
                f"{where}: mask {str(mpath)!r}: field 'class id' {v} is beyond the declared "
                f"{self.num_classes} classes (ignore_index={self.ignore_index})"
            )
        if self.size is not None:
            mask = _resize(mask, self.size, labels=True)
        return {"frames": frames, "mask": mask}


# --------------------------------------------------------------------------- DSEC-Detection
#: The DSEC-Detection classes, in ``class_id`` order (Gehrig & Scaramuzza, Nature 2024).
DSEC_DETECTION_CLASSES: tuple[str, ...] = (
    "pedestrian",
    "rider",
    "car",
    "bus",
    "truck",
    "bicycle",
    "motorcycle",
    "train",
)
#: Fields of a DSEC-Detection ``tracks.npy`` record read here (``t`` in µs; box top-left x, y and w, h in px).
DSEC_TRACK_FIELDS: tuple[str, ...] = ("t", "x", "y", "w", "h", "class_id")


class DsecDetectionDataset(ClipDataset):
    """Detection clips from DSEC-Detection sequences: rectified left images and the tracks array.

    A sequence folder holds ``images/timestamps.txt`` (one integer per image, µs, in the order of
    the sorted file names), ``images/left/rectified/*.png`` and ``object_detections/left/tracks.npy``
    (a structured array with fields ``t`` [µs], ``x``, ``y``, ``w``, ``h`` [px, top-left corner],
    ``class_id``, ``class_confidence``, ``track_id``). ``root`` is one sequence or a folder of
    sequences (every subfolder with ``images/timestamps.txt``). A clip is ``n_frames`` consecutive
    images whose LAST image has detections (a ``t`` equal to its timestamp); the clips of a
    sequence start every ``clip_stride`` images. Boxes reaching past the image edge are clipped to
    it (DSEC labels do); boxes left empty by the clipping are dropped. Timestamps come from the file,
    not from a stated frame rate.

    Parameters
    ----------
    root : path
    n_frames, clip_stride : int
    size : (H, W), optional
        Resize frames (boxes scaled with them).
    class_names : sequence of str
        Names of the ``class_id`` values (default :data:`DSEC_DETECTION_CLASSES`).
    transfer : str
    cache_clips : int
    disk_cache : ClipDiskCache, optional

    Raises
    ------
    InputError
        No sequence under ``root``; per sequence, naming the file and field: a missing or
        unreadable ``timestamps.txt``, a count of timestamps differing from the images, timestamps
        not increasing, a ``tracks.npy`` that is not a structured array with the fields above, a
        ``class_id`` beyond the classes, no labelled image with ``n_frames`` images before it.

    References
    ----------
    Gehrig & Scaramuzza, "Low-latency automotive vision with event cameras", Nature (2024);
    Gehrig et al., "DSEC: A stereo event camera dataset for driving scenarios", RA-L (2021).

    Examples
    --------
    >>> ds = DsecDetectionDataset("DSEC/train/zurich_city_00_a", n_frames=4, size=(240, 320))  # doctest: +SKIP
    >>> ds.class_names[int(ds[0].targets["labels"][0])]                                          # doctest: +SKIP
    'car'
    """

    task = "detection"

    def __init__(
        self,
        root: str | Path,
        *,
        n_frames: int = 4,
        clip_stride: int = 1,
        size: tuple[int, int] | None = None,
        class_names: Sequence[str] = DSEC_DETECTION_CLASSES,
        transfer: str = "sRGB",
        cache_clips: int = 0,
        disk_cache: ClipDiskCache | None = None,
    ) -> None:
        super().__init__(cache_clips=cache_clips, disk_cache=disk_cache)
        who = "DsecDetectionDataset"
        self.root = Path(root)
        self.n_frames = check_count(f"{who}: n_frames", n_frames, 2, 100_000)
        self.clip_stride = check_count(f"{who}: clip_stride", clip_stride, 1, 100_000)
        self.size = _check_size(size, who)
        self.transfer = transfer
        self.class_names = tuple(str(c) for c in class_names)
        self.num_classes = check_count(f"{who}: number of class_names", len(self.class_names), 1, 65535)
        if not self.root.is_dir():
            raise InputError(f"{who}: root {str(self.root)!r} is not a folder")
        seqs = (
            [self.root]
            if (self.root / "images" / "timestamps.txt").is_file()
            else sorted(p for p in self.root.iterdir() if (p / "images" / "timestamps.txt").is_file())
        )
        if not seqs:
            raise InputError(
                f"{who}: root {str(self.root)!r} holds no sequence (layout: <seq>/images/timestamps.txt, "
                "<seq>/images/left/rectified/*.png, <seq>/object_detections/left/tracks.npy)"
            )
        self.images: list[list[Path]] = []
        self.stamps: list[np.ndarray] = []
        self.boxes: list[dict[int, list[tuple[list[float], int]]]] = []
        self.clips: list[tuple[int, int]] = []  # (sequence, index of the clip's last image)
        for s, seq in enumerate(seqs):
            images, stamps, boxes = self._read_sequence(seq, who)
            self.images.append(images)
            self.stamps.append(stamps)
            self.boxes.append(boxes)
            ends = [k for k in range(self.n_frames - 1, len(images)) if boxes.get(k)]
            self.clips += [(s, k) for k in ends[:: self.clip_stride]]
        if not self.clips:
            raise InputError(
                f"{who}: root {str(self.root)!r}: no labelled image has {self.n_frames - 1} images "
                "before it (field 'tracks.t')"
            )
        check_count(f"{who}: number of clips", len(self.clips), 1, MAX_CLIPS)
        self.max_objects = max(len(b) for bx in self.boxes for b in bx.values())

    def _read_sequence(self, seq: Path, who: str) -> tuple[list[Path], np.ndarray, dict[int, Any]]:
        ts_path = seq / "images" / "timestamps.txt"
        try:
            stamps = np.loadtxt(ts_path, dtype=np.int64, ndmin=1)
        except (OSError, ValueError) as exc:
            raise InputError(f"{who}: {str(ts_path)!r} is not one integer timestamp (µs) per line ({exc})") from None
        images = sorted((seq / "images" / "left" / "rectified").glob("*.png"))
        if len(images) != len(stamps):
            raise InputError(
                f"{who}: {str(ts_path)!r} has {len(stamps)} timestamps for {len(images)} images in "
                f"{str(seq / 'images' / 'left' / 'rectified')!r}"
            )
        if len(stamps) > 1 and np.any(np.diff(stamps) <= 0):
            raise InputError(f"{who}: {str(ts_path)!r}: timestamps must increase")
        tr_path = seq / "object_detections" / "left" / "tracks.npy"
        try:  # the header first (memory-mapped): a file cut short, or claiming more than it holds, is refused
            mapped = np.load(tr_path, allow_pickle=False, mmap_mode="r")
            check_allocation(f"{who}: {str(tr_path)!r} ({mapped.shape[0] if mapped.ndim else 1} tracks)", mapped.nbytes)
            tracks = np.array(mapped)
            del mapped
        except (OSError, ValueError) as exc:
            raise InputError(f"{who}: {str(tr_path)!r} cannot be read as a NumPy array ({exc})") from None
        missing = [f for f in DSEC_TRACK_FIELDS if tracks.dtype.names is None or f not in tracks.dtype.names]
        if missing:
            raise InputError(
                f"{who}: {str(tr_path)!r}: fields {missing} missing; allowed: a structured array with "
                f"{', '.join(DSEC_TRACK_FIELDS)}"
            )
        bad = tracks["class_id"].astype(np.int64) >= self.num_classes
        if bad.any():
            raise InputError(
                f"{who}: {str(tr_path)!r}: field 'class_id' {int(tracks['class_id'][bad][0])} is beyond "
                f"the {self.num_classes} classes {list(self.class_names)}"
            )
        h, w = _image_size(images[0], who, "image") if images else (0, 0)
        where = {int(t): k for k, t in enumerate(stamps)}
        boxes: dict[int, list[tuple[list[float], int]]] = {}
        for r in tracks:
            k = where.get(int(r["t"]))
            if k is None:
                continue
            x0, y0 = max(0.0, float(r["x"])), max(0.0, float(r["y"]))
            x1, y1 = min(float(w), float(r["x"] + r["w"])), min(float(h), float(r["y"] + r["h"]))
            if x1 > x0 and y1 > y0:
                boxes.setdefault(k, []).append(([x0, y0, x1, y1], int(r["class_id"])))
        return images, stamps, boxes

    def __len__(self) -> int:
        return len(self.clips)

    def clip_files(self, i: int) -> tuple[Path, ...]:
        """The rectified left images of clip ``i``."""
        s, last = self.clips[i]
        return tuple(self.images[s][k] for k in range(last - self.n_frames + 1, last + 1))

    def _load(self, i: int) -> Clip:
        s, last = self.clips[i]
        idx = range(last - self.n_frames + 1, last + 1)
        where = f"DsecDetectionDataset: clip {i}"
        frames = self._decoded(
            i, lambda: {"frames": self._frames([_read_image(p, where) for p in self.clip_files(i)], where)}
        )["frames"]
        h0, w0 = _image_size(self.images[s][last], where, "image")
        sy, sx = frames.shape[1] / h0, frames.shape[2] / w0
        b = np.full((self.max_objects, 4), -1.0)
        lab = np.full(self.max_objects, -1, np.int64)
        for k, (box, c) in enumerate(self.boxes[s][last]):
            b[k] = np.asarray(box) * [sx, sy, sx, sy]
            lab[k] = c
        t = self.stamps[s][list(idx)]
        return Clip(
            frames,
            (t - t[0]) * 1e-6,
            {"boxes": b, "labels": lab},
            str(self.images[s][last]),
            i,
            {"sequence": str(self.images[s][last].parents[3])},
        )
