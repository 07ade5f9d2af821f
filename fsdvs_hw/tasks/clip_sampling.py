"""Clips sampled from videos as the field samples them: k clips per video, aspect kept, cropped, flipped.

A UCF101-style video is seconds long; a clip is ``n_frames`` frames of it. The action
recognition literature trains on **random clips** (a new start frame every epoch), with a
**random crop** of the aspect-preserving resized frames and a **horizontal flip**, and tests on
**several clips per video, evenly spaced**, with a **centre crop**, the video's prediction being
the mean of its clips' class probabilities (Wang et al., TSN, ECCV 2016; Carreira & Zisserman,
I3D, CVPR 2017; Feichtenhofer et al., SlowFast, ICCV 2019: 10 clips × 3 crops, here 1 crop).

:class:`SampledVideoClips` is a :class:`~fsdvs_hw.scenes.datasets.ClipDataset` over a
:class:`~fsdvs_hw.scenes.datasets.VideoFolderDataset`: clip ``j`` is slot ``j % k`` of video
``j // k``. Each clip is decoded on demand (through the video dataset's disk cache, keyed on its
start frame and size) at the **aspect-preserving size** :func:`short_side_size` (the short side
scaled to cover the output, the other side scaled alike: a 320×240 video to 64×64 is decoded at
85×64, not squashed) and cropped to the output size: centre crop at test time, a seeded random
crop and flip in training. The start frames are :func:`even_starts` at test time (the centres of
``k`` equal segments of the video) and :func:`random_starts` in training (drawn per epoch, video
and slot from ``seed``: the same clips whatever the worker processes).

Example
-------
>>> even_starts(100, 16, 3).tolist()
[14, 42, 70]
>>> short_side_size(240, 320, (64, 64))
(64, 85)
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..limits import MAX_SEED, check_count
from ..scenes.datasets import Clip, ClipDataset

__all__ = [
    "SampledVideoClips",
    "SamplingSpec",
    "crop_offset",
    "even_starts",
    "random_starts",
    "resize_crop",
    "short_side_size",
]

#: Most clips per video (test or training).
MAX_CLIPS_PER_VIDEO = 100


@dataclass(frozen=True)
class SamplingSpec:
    """How clips are taken from videos.

    Attributes
    ----------
    clips_per_video : int
        Test time: clips per video, evenly spaced (:func:`even_starts`), 1 … 100; the video's
        score is the mean of its clips' (:func:`fsdvs_hw.tasks.dataset_eval.per_video_evaluation`).
    train_clips_per_video : int
        Training: random clips per video per epoch (:func:`random_starts`), 1 … 100.
    resize : str
        ``"short_side"``: aspect-preserving resize then crop (:func:`short_side_size`);
        ``"stretch"``: each frame resized to the output size (the aspect is lost; no crop).
    train_crop : str
        ``"random"`` (a seeded random crop in training) or ``"center"``.
    train_flip : bool
        A seeded horizontal flip of half the training clips.
    seed : int
        Seeds the training starts, crops and flips (with the epoch, the video and the slot).

    Example
    -------
    >>> SamplingSpec(clips_per_video=5).clips_per_video
    5
    """

    clips_per_video: int = 1
    train_clips_per_video: int = 1
    resize: str = "short_side"
    train_crop: str = "random"
    train_flip: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        check_count("sampling.clips_per_video", self.clips_per_video, 1, MAX_CLIPS_PER_VIDEO)
        check_count("sampling.train_clips_per_video", self.train_clips_per_video, 1, MAX_CLIPS_PER_VIDEO)
        check_count("sampling.seed", self.seed, 0, MAX_SEED)
        if self.resize not in ("short_side", "stretch"):
            raise InputError(f"sampling.resize = {self.resize!r}; allowed: 'short_side' or 'stretch'")
        if self.train_crop not in ("random", "center"):
            raise InputError(f"sampling.train_crop = {self.train_crop!r}; allowed: 'random' or 'center'")
        if not isinstance(self.train_flip, bool):
            raise InputError(f"sampling.train_flip = {self.train_flip!r}; allowed: true or false")


def even_starts(n_available: int, span: int, k: int) -> np.ndarray:
    """Start frames of ``k`` clips of ``span`` frames evenly spaced over ``n_available`` frames.

    The centres of ``k`` equal segments of the possible starts ``0 … n_available - span``
    (``k = 1``: the middle clip), rounded down.

    Raises
    ------
    InputError
        The video is shorter than one clip.

    Examples
    --------
    >>> even_starts(10, 10, 2).tolist()
    [0, 0]
    >>> even_starts(100, 10, 1).tolist()
    [45]
    """
    last = _last_start(n_available, span)
    return np.floor((last + 1) * (np.arange(k) + 0.5) / k).astype(np.int64).clip(0, last)


def random_starts(n_available: int, span: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """``k`` start frames drawn uniformly from ``0 … n_available - span`` (with replacement).

    Example
    -------
    >>> int(random_starts(20, 20, 1, np.random.default_rng(0))[0])
    0
    """
    return rng.integers(0, _last_start(n_available, span) + 1, size=k).astype(np.int64)


def _last_start(n_available: int, span: int) -> int:
    if n_available < span:
        raise InputError(
            f"field 'frames': the video has {n_available} frames, fewer than one clip's {span} "
            "(n_frames, stride and start_frame)"
        )
    return n_available - span


def short_side_size(h: int, w: int, size: Sequence[int]) -> tuple[int, int]:
    """The aspect-preserving size (H', W') ⊇ ``size`` = (H, W) of an ``h`` × ``w`` frame.

    The frame is scaled by ``max(H / h, W / w)`` so that it covers the output, each side rounded
    to the nearest pixel and at least the output's.

    Examples
    --------
    >>> short_side_size(240, 320, (64, 64))
    (64, 85)
    >>> short_side_size(240, 320, (120, 160))
    (120, 160)
    """
    out_h, out_w = int(size[0]), int(size[1])
    scale = max(out_h / h, out_w / w)
    return max(out_h, round(h * scale)), max(out_w, round(w * scale))


def crop_offset(h: int, w: int, size: Sequence[int], where: tuple[float, float] = (0.5, 0.5)) -> tuple[int, int]:
    """Top-left (y0, x0) of a ``size`` crop of an ``h`` × ``w`` frame; ``where`` = (0.5, 0.5) is the centre.

    Example
    -------
    >>> crop_offset(64, 85, (64, 64))
    (0, 10)
    """
    return int((h - int(size[0])) * where[0]), int((w - int(size[1])) * where[1])


def resize_crop(
    frames: np.ndarray, size: Sequence[int], where: tuple[float, float] = (0.5, 0.5), flip: bool = False
) -> np.ndarray:
    """Frames (T, h, w) resized keeping their aspect (:func:`short_side_size`) and cropped to ``size``.

    Linear-light area resize (scikit-image, anti-aliased); ``where`` places the crop (0.5, 0.5 =
    centre); ``flip`` mirrors left-right after the crop.

    Example
    -------
    >>> resize_crop(np.ones((2, 240, 320)), (64, 64)).shape
    (2, 64, 64)
    """
    from skimage.transform import resize

    _, h, w = frames.shape
    hh, ww = short_side_size(h, w, size)
    if (hh, ww) != (h, w):
        frames = np.stack([resize(f, (hh, ww), anti_aliasing=True, preserve_range=True) for f in frames])
    return crop_frames(frames, crop_offset(hh, ww, size, where), size, flip)


def crop_frames(frames: np.ndarray, offset: tuple[int, int], size: Sequence[int], flip: bool = False) -> np.ndarray:
    """``frames[:, y0:y0+H, x0:x0+W]`` (flipped left-right when ``flip``), contiguous."""
    y0, x0 = offset
    out = frames[:, y0 : y0 + int(size[0]), x0 : x0 + int(size[1])]
    return np.ascontiguousarray(out[:, :, ::-1] if flip else out)


def _video_probe(path: str) -> tuple[int, int, int]:
    """(frames, height, width) of a video from its container (frames counted by ffmpeg without decoding)."""
    import imageio
    import imageio_ffmpeg

    try:
        reader = imageio.get_reader(path, "ffmpeg")
        try:
            w, h = reader.get_meta_data()["size"]
        finally:
            reader.close()
        n, _ = imageio_ffmpeg.count_frames_and_secs(path)
    except Exception as exc:  # imageio / ffmpeg raise several types for a file that is not a video
        raise InputError(f"video {path!r}: field 'frames': the video does not decode ({type(exc).__name__})") from None
    return int(n), int(h), int(w)


class SampledVideoClips(ClipDataset):
    """k clips per video of a :class:`~fsdvs_hw.scenes.datasets.VideoFolderDataset`, aspect kept and cropped.

    A :class:`~fsdvs_hw.scenes.datasets.ClipDataset`: ``len`` = videos × k; clip ``j`` is slot
    ``j % k`` of video ``j // k``; :attr:`video_of` maps clips to videos. Test mode
    (``train=False``): :func:`even_starts` and a centre crop. Training mode: :func:`random_starts`
    drawn from (``seed``, :attr:`epoch`, video, slot), a random crop and a flip
    (:class:`SamplingSpec`); set :attr:`epoch` before each epoch for new clips.

    Parameters
    ----------
    videos : VideoFolderDataset
        Read at the files' size or any ``size`` (its ``size`` is replaced per video by the
        aspect-preserving one); its ``start_frame``, ``stride`` and disk cache hold.
    size : (H, W)
        Output frame size in pixels.
    spec : SamplingSpec
    train : bool
        Training sampling (random) or test sampling (even, centre).
    video_indices : array of int, optional
        Only these videos of ``videos`` (a scored draw), in this order; :attr:`video_of` names
        them by their index in ``videos``.

    Example
    -------
    >>> clips = SampledVideoClips(VideoFolderDataset("ucf", n_frames=8), (64, 64),
    ...                           SamplingSpec(clips_per_video=3))      # doctest: +SKIP
    >>> len(clips) == 3 * len(clips.videos), clips[0].frames.shape     # doctest: +SKIP
    (True, (8, 64, 64))
    """

    def __init__(
        self, videos: Any, size: Sequence[int], spec: SamplingSpec, *, train: bool = False, video_indices: Any = None
    ) -> None:
        from ..scenes.datasets import VideoFolderDataset

        if not isinstance(videos, VideoFolderDataset):
            raise InputError(
                f"sampling: the dataset is a {type(videos).__name__}; clips per video, crop and flip apply "
                "to format = 'video_folder' (frame sequences: dataset.size and clip_stride)"
            )
        if not isinstance(spec, SamplingSpec):
            raise InputError(f"sampling: spec is a {type(spec).__name__}; allowed: a SamplingSpec")
        super().__init__(cache_clips=0, disk_cache=videos.disk_cache)
        if len(size) != 2 or not all(isinstance(v, int) and 1 <= v <= 16384 for v in size):
            raise InputError(f"sampling: size = {list(size)!r}; allowed: [H, W], integers in [1, 16384]")
        self.videos = videos
        self.spec = spec
        self.train = bool(train)
        self.epoch = 0
        self.k = spec.train_clips_per_video if train else spec.clips_per_video
        self.task, self.num_classes, self.class_names = videos.task, videos.num_classes, videos.class_names
        self.n_frames, self.transfer = videos.n_frames, videos.transfer
        self.out_size = (int(size[0]), int(size[1]))
        self.size = self.out_size
        self._probes: dict[int, tuple[int, int, int]] = {}
        chosen = np.arange(len(videos)) if video_indices is None else np.asarray(list(video_indices), dtype=np.int64)
        if len(chosen) == 0 or chosen.min() < 0 or chosen.max() >= len(videos):
            raise InputError(f"sampling: video_indices must be video indices in [0, {len(videos)}), got {len(chosen)}")
        self.chosen = chosen

    def __len__(self) -> int:
        return len(self.chosen) * self.k

    @property
    def video_of(self) -> np.ndarray:
        """The video (its index in ``videos``) of every clip (int64, shape (len,))."""
        return np.repeat(self.chosen, self.k)

    def clip_files(self, i: int) -> tuple[Any, ...]:
        """The video of clip ``i``."""
        return tuple(self.videos.clip_files(int(self.chosen[i // self.k])))

    def probe(self, v: int) -> tuple[int, int, int]:
        """(frames, height, width) of video ``v`` (read once per process)."""
        if v not in self._probes:
            self._probes[v] = _video_probe(str(self.videos.clip_files(v)[0]))
        return self._probes[v]

    def placement(self, j: int) -> dict[str, Any]:
        """Clip ``j``'s video, start frame, crop placement (fractions) and flip."""
        n_th, slot = divmod(int(j), self.k)
        v = int(self.chosen[n_th])
        n, _, _ = self.probe(v)
        base = self.videos.start_frame
        span = (self.n_frames - 1) * self.videos.stride + 1
        try:
            if not self.train:
                return {
                    "video": v,
                    "start": base + int(even_starts(n - base, span, self.k)[slot]),
                    "where": (0.5, 0.5),
                    "flip": False,
                }
            rng = np.random.default_rng([self.spec.seed, int(self.epoch), v, slot])
            start = base + int(random_starts(n - base, span, 1, rng)[0])
            where = (float(rng.random()), float(rng.random())) if self.spec.train_crop == "random" else (0.5, 0.5)
            flip = bool(self.spec.train_flip and rng.random() < 0.5)
        except InputError as exc:
            raise InputError(f"SampledVideoClips: clip {j} ({self.videos.clip_files(v)[0]!s}): {exc}") from None
        return {"video": v, "start": start, "where": where, "flip": flip}

    def _load(self, j: int) -> Clip:
        at = self.placement(j)
        _, h, w = self.probe(at["video"])
        decoded_size = short_side_size(h, w, self.out_size) if self.spec.resize == "short_side" else self.out_size
        view = copy.copy(self.videos)  # the same layout read at this clip's start frame and size
        view.cache_clips, view.start_frame, view.size = 0, at["start"], decoded_size
        clip = view[at["video"]]
        offset = crop_offset(decoded_size[0], decoded_size[1], self.out_size, at["where"])
        frames = crop_frames(clip.frames, offset, self.out_size, at["flip"])
        meta = {**clip.metadata, "video": at["video"], "start_frame": at["start"], "crop": offset, "flip": at["flip"]}
        return Clip(frames, clip.timestamps_s, clip.targets, clip.source, int(j), meta)
