"""User datasets and networks in a design file: ``[tasks.datasets.<task>]`` and its paired evidence.

A design scores its realisations on the user's own clips with the user's own network by naming
them per task::

    [tasks.datasets.recognition]
    dataset = { format = "video_folder", root = "data/ucf", split = "testlist01.txt", n_frames = 8,
                size = [64, 64], cache = { dir = "clip_cache", max_mb = 2000.0 } }   # cache: optional
    network = "mynets.video:tiny"          # "package.module:factory" (None: the built-in network)
    network_options = { width = 16 }       # more keyword arguments of the factory
    weights = "nets/tiny.safetensors"      # .safetensors / .pt / .pth state dict (optional)
    n_clips = 200                          # clips drawn with `seed` (0 = every clip)
    max_failed_clip_fraction = 0.05        # clips that fail to read are skipped, up to this fraction
    train = { split = "trainlist01.txt" }  # optional: train first, on the dataset's own training split

The ``format`` picks the reader (:mod:`fsdvs_hw.scenes.datasets`) and with it the task, which
must be the table's name: ``video_folder`` → recognition (UCF101 layout), ``coco_frames`` →
detection (frames + COCO JSON), ``mask_frames`` → segmentation (frames + label PNGs). ``root``
is relative to the design file and, like every path of a design, must stay inside its folder
(symbolic links are followed first); the reader's other paths are relative to ``root``.

``dataset.cache`` keeps decoded clips in a bounded folder (:mod:`fsdvs_hw.scenes.clip_cache`);
it changes no clip, so it is left out of the training fingerprint (and the exploration's point
keys). ``train.split`` trains on the dataset's own training split
(:func:`train_split_dataset`), refused when it shares a file with the scored clips
(:func:`check_disjoint_files`).

The factory is imported from ``sys.path`` or from the design file's folder, and called as
``factory(in_channels=2 * (n_frames - 1), num_classes=<the dataset's>, **network_options)``
(:func:`fsdvs_hw.tasks.user_networks.load_network_factory`).

:func:`dataset_evidence` scores a kernel on the drawn clips (:func:`fsdvs_hw.tasks.dataset_eval.
evaluate_on_dataset`) and keeps each clip's contribution as the same :mod:`fsdvs_hw.stats` metric
object :func:`fsdvs_hw.explore.paired.clip_evidence` keeps for a trained checkpoint, so
:func:`fsdvs_hw.explore.scoring.paired_losses` pairs every kernel with the learned one clip by clip.
Pairing: every kernel meets the same clips (one seeded draw) and the same noise draws (the
simulator is reseeded for every clip). A clip that fails to read (a video that does not decode, a
mask label beyond ``num_classes``, another frame size) is skipped, counted and named, up to
``max_failed_clip_fraction`` of the drawn clips; whether it fails is decided from its files alone
(:func:`fsdvs_hw.tasks.dataset_eval.read_clip`), so every kernel skips the same clips and the
comparison stays paired (the record's ``failed_clip_indices`` are compared again when losses are
paired). Beyond the fraction, or on a problem of the task (the network's output, an odd frame size
for the stride-2 detector), the task fails with a message naming the key, the file and the reason.
With one user network the loss CI resamples clips only (``n_seeds = 1``: network-to-network
variance cannot enter), which the track record says.

References
----------
Soomro, Zamir & Shah, "UCF101", CRCV-TR-12-01 (2012) — the class-folder layout.
Lin et al., "Microsoft COCO", ECCV (2014) — the annotation JSON.
Cordts et al., "The Cityscapes Dataset", CVPR (2016) — label-mask PNGs with an ignore index.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import functools
import hashlib
import json
import sys
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field

from ..errors import InputError
from ..limits import MAX_CLIPS, MAX_EPOCHS, MAX_SEED
from ..paths import confined_path
from ..schema import StrictModel, field

__all__ = [
    "DEFAULT_MAX_FAILED_CLIP_FRACTION",
    "FORMAT_TASK",
    "ONE_NETWORK_NOTE",
    "ClipCacheSpec",
    "CocoFramesSource",
    "DsecDetectionSource",
    "MaskFramesSource",
    "TrainSpec",
    "UserTask",
    "VideoFolderSource",
    "check_disjoint_files",
    "check_user_task",
    "dataset_evidence",
    "finetune_user_network",
    "open_dataset",
    "open_network",
    "train_split_dataset",
    "train_user_task",
    "user_network_identity",
    "user_task_record",
]

#: What a user-data task's record says about its loss CIs.
ONE_NETWORK_NOTE = (
    "one user network: the loss CI resamples the clips only (n_seeds = 1); network-to-network variance is not in it"
)

#: ``[tasks.datasets.<task>] max_failed_clip_fraction`` when a table does not set it.
DEFAULT_MAX_FAILED_CLIP_FRACTION = 0.05

#: Dataset format → the task (evaluator) its targets are for.
FORMAT_TASK: dict[str, str] = {
    "video_folder": "recognition",
    "coco_frames": "detection",
    "dsec_detection": "detection",
    "mask_frames": "segmentation",
}

_Side = Annotated[int, Field(ge=1, le=16384)]
_Count = Annotated[int, Field(ge=1, le=100_000)]


class ClipCacheSpec(StrictModel):
    """``dataset.cache = {dir = "...", max_mb = ...}``: decoded clips kept on disk (:mod:`fsdvs_hw.scenes.clip_cache`)."""

    unknown_key = "unknown key of a dataset's cache table"

    dir: str = field(
        ...,
        "",
        "folder of the cache entries, relative to the design file (must stay inside its "
        "folder); may be shared by datasets and designs: max_mb bounds the folder",
    )
    max_mb: float = field(
        ...,
        "MB",
        "most megabytes (10**6 bytes) of decoded clips kept; the least recently used are deleted beyond it",
        gt=0.0,
        le=1e9,
    )


class _Source(StrictModel):
    """Keys every dataset format shares."""

    root: str = field(..., "", "the dataset's folder, relative to the design file (must stay inside its folder)")
    n_frames: int = field(8, "frames", "frames per clip (T)", ge=2, le=10_000)
    size: list[_Side] | None = field(
        None,
        "px",
        "resize every frame to [H, W] pixels (linear light; boxes scaled, "
        "masks nearest-neighbour); None = the files' size (all must agree)",
        min_length=2,
        max_length=2,
    )
    transfer: str = field(
        "sRGB", "", "transfer function undone to get linear luminance (a colour-science CCTF_DECODINGS name)"
    )
    cache_clips: int = field(0, "clips", "decoded clips kept in memory (LRU; 0 = none)", ge=0, le=MAX_CLIPS)
    cache: ClipCacheSpec | None = field(
        None, "", "decoded clips kept on disk, bounded: {dir = 'folder', max_mb = size}; None = decode every time"
    )


class VideoFolderSource(_Source):
    """``format = "video_folder"``: ``root/<class>/<video>`` (UCF101 layout), one clip per video."""

    format: Literal["video_folder"] = field("video_folder", "", "class folders of videos (recognition)")
    split: str | None = field(
        None, "", "UCF101 split file (testlist01.txt) relative to root: only the videos it lists; None = every video"
    )
    fps: float | None = field(
        None, "Hz", "frame rate for the timestamps; None = each video container's", gt=0.0, le=1e6
    )
    stride: _Count = field(1, "frames", "take every stride-th frame of a video")
    start_frame: int = field(0, "frames", "first frame of a video used", ge=0, le=10**9)


class CocoFramesSource(_Source):
    """``format = "coco_frames"``: frame images plus a COCO JSON of boxes per frame (detection)."""

    format: Literal["coco_frames"] = field("coco_frames", "", "frames + COCO-JSON boxes (detection)")
    split: str = field("", "", "subfolder of root holding this split ('val'); '' = root itself")
    frames: str = field("frames", "", "folder of the frame images, relative to root/split")
    annotations: str = field("instances.json", "", "the COCO JSON, relative to root/split")
    fps: float = field(30.0, "Hz", "frame rate of the image sequence", gt=0.0, le=1e6)
    clip_stride: _Count | None = field(
        None, "frames", "a clip starts every clip_stride frames; None = n_frames (no overlap)"
    )
    require_annotations: bool = field(True, "", "every image must have at least one box")


class DsecDetectionSource(_Source):
    """``format = "dsec_detection"``: DSEC-Detection sequences (rectified left images + tracks.npy)."""

    format: Literal["dsec_detection"] = field("dsec_detection", "", "DSEC-Detection layout (detection)")
    split: str = field("", "", "subfolder of root holding this split's sequences ('test'); '' = root itself")
    clip_stride: _Count = field(1, "clips", "keep every clip_stride-th labelled image as a clip's last frame")
    class_names: list[str] | None = field(
        None, "", "names of the class_id values; None = DSEC's 8 classes", min_length=1
    )


class MaskFramesSource(_Source):
    """``format = "mask_frames"``: frame images plus label-mask PNGs (segmentation)."""

    format: Literal["mask_frames"] = field("mask_frames", "", "frames + label-mask PNGs (segmentation)")
    split: str = field("", "", "subfolder of root holding this split ('val'); '' = root itself")
    frames: str = field("frames", "", "folder of the frame images, relative to root/split")
    masks: str = field("masks", "", "folder of the label PNGs (a class per pixel), relative to root/split")
    num_classes: int = field(
        ..., "", "classes of the masks (labels in [0, num_classes) or ignore_index)", ge=2, le=65535
    )
    ignore_index: int | None = field(
        255, "", "label that is not scored (Cityscapes: 255); None = every pixel", ge=0, le=65535
    )
    frame_suffix: str = field("", "", "stem suffix of a frame removed to find its mask (Cityscapes: '_leftImg8bit')")
    mask_suffix: str = field(".png", "", "appended to the stem to name the mask ('_gtFine_labelTrainIds.png')")
    fps: float = field(30.0, "Hz", "frame rate of the image sequence", gt=0.0, le=1e6)
    clip_stride: _Count | None = field(None, "frames", "a clip starts every clip_stride frames; None = n_frames")


class TrainSpec(StrictModel):
    """``[tasks.datasets.<task>] train = {...}``: train the network (and learn a kernel) on the user's clips.

    The FS-DVS two-stage protocol (:func:`fsdvs_hw.tasks.dataset_training.train_on_dataset`):
    stage one trains the network with the kernel frozen (delta + noise), stage two trains both
    with decoupled AdamW rates. From scratch without ``weights``; fine-tuning from them with.
    The training clips are a seeded draw from the clips NOT scored (disjoint from them), or from
    the dataset's own training split (``split``), which must share no file with the scored clips.
    """

    unknown_key = "unknown key of a user-data task's train table"

    out: str = field(
        "",
        "",
        "file stem of the trained network + kernel (STEM.safetensors, STEM.json), relative "
        "to the design file; '' = trained/<task>",
    )
    split: str | None = field(
        None,
        "",
        "the dataset's own training split, read like dataset.split: video_folder a "
        "split file relative to root (UCF101 'trainlist01.txt'), the other formats a subfolder "
        "of root ('train'); None = a seeded draw from the clips not scored",
    )
    kernel_size: int = field(7, "px", "side of the learned kernel", ge=1, le=15, odd=True)
    learn_kernel: bool = field(
        True, "", "false: the kernel stays the delta in both stages (a network for a conventional DVS)"
    )
    epochs_frozen: int = field(2, "epochs", "stage one: network only, kernel frozen", ge=0, le=MAX_EPOCHS)
    epochs_joint: int = field(2, "epochs", "stage two: kernel and network jointly", ge=0, le=MAX_EPOCHS)
    lr_network: float = field(3e-3, "1/step", "AdamW rate of the network in stage one", ge=0.0, le=10.0)
    lr_kernel: float = field(
        1e-2, "1/step", "AdamW rate of the kernel taps in stage two (paper: 5e-4)", ge=0.0, le=10.0
    )
    lr_backbone: float | None = field(
        None,
        "1/step",
        "stage-two rate of the network's backbone; None = lr_kernel "
        "x the paper's ratio (detection 1e-6/5e-4, recognition 5e-5/5e-4)",
        ge=0.0,
        le=10.0,
    )
    lr_head: float | None = field(
        None,
        "1/step",
        "stage-two rate of the head (of the whole network if it has no "
        "backbone/head); None = lr_kernel x the paper's ratio (1e-5/5e-4, 1e-4/5e-4)",
        ge=0.0,
        le=10.0,
    )
    weight_decay: float = field(1e-4, "", "AdamW weight decay of the network", ge=0.0, le=10.0)
    batch_size: int = field(8, "clips", "clips per step", ge=1, le=100_000)
    n_train: int = field(
        0, "clips", "training clips, drawn with seed from the clips not scored; 0 = all of them", ge=0, le=MAX_CLIPS
    )
    seed: int = field(
        0, "", "seed of the training draw, the kernel noise, the initialisation and the batch order", ge=0, le=MAX_SEED
    )


class UserTask(StrictModel):
    """``[tasks.datasets.<task>]``: one task scored on the user's clips with the user's network."""

    unknown_key = "unknown key of a user-data task"

    dataset: Annotated[
        VideoFolderSource | CocoFramesSource | DsecDetectionSource | MaskFramesSource, Field(discriminator="format")
    ] = field(
        ...,
        "",
        "the dataset: format = 'video_folder' | 'coco_frames' | 'dsec_detection' | 'mask_frames', "
        "root, split, reader options",
    )
    network: str | None = field(
        None,
        "",
        "'package.module:factory' returning a torch.nn.Module (importable from "
        "sys.path or the design file's folder); None = the task's built-in network",
    )
    network_options: dict[str, Any] = field(
        {}, "", "more keyword arguments of the factory (besides in_channels and num_classes)"
    )
    weights: str | None = field(
        None,
        "",
        "state dict loaded into the network (.safetensors, .pt, .pth), relative "
        "to the design file; None = the factory's own weights",
    )
    n_clips: int = field(0, "clips", "clips scored, drawn with seed; 0 = every clip", ge=0, le=MAX_CLIPS)
    max_failed_clip_fraction: float = field(
        DEFAULT_MAX_FAILED_CLIP_FRACTION,
        "",
        "fraction of the drawn clips that may fail to read (a video that does not decode, a mask "
        "label beyond num_classes, another frame size) and be skipped, counted and named in the "
        "task's record; beyond it the task fails, naming the first files and reasons",
        ge=0.0,
        le=1.0,
    )
    seed: int = field(0, "", "seed of the clip draw (the same clips for every kernel)", ge=0, le=MAX_SEED)
    device: Literal["cpu", "cuda"] = field(
        "cpu",
        "",
        "where the simulator and the network run ('cuda' needs a "
        "CUDA build of torch and a GPU; its noise streams differ from the CPU's)",
    )
    train: TrainSpec | None = field(
        None,
        "",
        "train the network on the clips not scored first (two-stage "
        "protocol; resumes); None = score the network as given",
    )


def _path(base: Path, path: str, *, what: str, confine: bool) -> Path:
    """``path`` against the design's folder; with ``confine`` it must stay inside it."""
    if confine:
        return confined_path(base, path, what=what)
    return (base / path).resolve()


def _reader_paths(source: Mapping[str, Any], base: Path, confine: bool, key: str) -> dict[str, Path]:
    """The reader's paths, resolved against the design's folder (and confined to it)."""
    root = Path(str(source["root"]))
    split = source.get("split") or ""
    if source["format"] == "video_folder":
        rel = {"root": root, **({"split": root / split} if split else {})}
    elif source["format"] == "coco_frames":
        rel = {"frames": root / split / source["frames"], "annotations": root / split / source["annotations"]}
    elif source["format"] == "dsec_detection":
        rel = {"root": root / split}
    else:
        rel = {"frames": root / split / source["frames"], "masks": root / split / source["masks"]}
    return {name: _path(base, str(p), what=f"{key}.{name}", confine=confine) for name, p in rel.items()}


@functools.lru_cache(maxsize=16)
def _open_dataset(blob: str, base: str, confine: bool, key: str) -> Any:
    from ..scenes.clip_cache import ClipDiskCache
    from ..scenes.datasets import (
        DSEC_DETECTION_CLASSES,
        CocoFramesDataset,
        DsecDetectionDataset,
        MaskFramesDataset,
        VideoFolderDataset,
    )

    s = json.loads(blob)
    paths = _reader_paths(s, Path(base), confine, key)
    common = {
        "n_frames": s["n_frames"],
        "size": tuple(s["size"]) if s["size"] else None,
        "transfer": s["transfer"],
        "cache_clips": s["cache_clips"],
        "disk_cache": None,
    }
    if s.get("cache"):
        folder = _path(Path(base), s["cache"]["dir"], what=f"{key}.cache.dir", confine=confine)
        common["disk_cache"] = ClipDiskCache(folder, s["cache"]["max_mb"])
    if s["format"] == "video_folder":
        return VideoFolderDataset(
            paths["root"],
            split_file=paths.get("split"),
            fps=s["fps"],
            stride=s["stride"],
            start_frame=s["start_frame"],
            **common,
        )
    if s["format"] == "dsec_detection":
        return DsecDetectionDataset(
            paths["root"],
            clip_stride=s["clip_stride"],
            class_names=s["class_names"] or DSEC_DETECTION_CLASSES,
            **common,
        )
    if s["format"] == "coco_frames":
        return CocoFramesDataset(
            paths["frames"],
            paths["annotations"],
            clip_stride=s["clip_stride"],
            fps=s["fps"],
            require_annotations=s["require_annotations"],
            **common,
        )
    return MaskFramesDataset(
        paths["frames"],
        paths["masks"],
        num_classes=s["num_classes"],
        clip_stride=s["clip_stride"],
        fps=s["fps"],
        ignore_index=s["ignore_index"],
        frame_suffix=s["frame_suffix"],
        mask_suffix=s["mask_suffix"],
        **common,
    )


def open_dataset(source: Mapping[str, Any], base_dir: str | Path, *, confine: bool = True, key: str = "dataset") -> Any:
    """The :class:`~fsdvs_hw.scenes.datasets.ClipDataset` a design's ``dataset`` table names.

    Opened once per process (cached): only the layout is read; clips are decoded when scored.

    Parameters
    ----------
    source : mapping
        A validated ``dataset`` table (:class:`VideoFolderSource`, :class:`CocoFramesSource`,
        :class:`MaskFramesSource` dumped), e.g. ``UserTask(...).model_dump()["dataset"]``.
    base_dir : path
        The design file's folder (``root`` is relative to it).
    confine : bool
        Refuse paths outside ``base_dir`` (always for design files).
    key : str
        The design key, for messages (``"tasks.datasets.recognition.dataset"``).

    Raises
    ------
    InputError
        A path outside the design folder, or any reader error (naming the file and field).

    Examples
    --------
    >>> src = VideoFolderSource(root="ucf", size=[64, 64]).model_dump()   # doctest: +SKIP
    >>> len(open_dataset(src, "designs"))                                  # doctest: +SKIP
    4
    """
    return _open_dataset(json.dumps(dict(source), sort_keys=True), str(Path(base_dir).resolve()), bool(confine), key)


@contextlib.contextmanager
def _importable_from(folder: Path) -> Iterator[None]:
    """``folder`` first on ``sys.path`` while a user factory is imported."""
    entry = str(folder)
    added = entry not in sys.path
    if added:
        sys.path.insert(0, entry)
    try:
        yield
    finally:
        if added:
            with contextlib.suppress(ValueError):
                sys.path.remove(entry)


@functools.lru_cache(maxsize=16)
def _open_network(
    blob: str, base: str, confine: bool, key: str, in_channels: int, num_classes: int, trained: bool = True
) -> Any:
    from ..tasks.user_networks import builtin_network, load_network_factory, load_weights

    entry = json.loads(blob)
    task = FORMAT_TASK[entry["dataset"]["format"]]
    if entry["network"] is None:
        net = builtin_network(task, in_channels, num_classes)
    else:
        clash = sorted({"in_channels", "num_classes"} & set(entry["network_options"]))
        if clash:
            raise InputError(
                f"{key}.network_options: {clash} are set from the dataset; allowed: other keyword "
                "arguments of the factory"
            )
        with _importable_from(Path(base)):
            net = load_network_factory(
                entry["network"], in_channels=in_channels, num_classes=num_classes, **entry["network_options"]
            )
    if entry["weights"]:
        load_weights(net, _path(Path(base), entry["weights"], what=f"{key}.weights", confine=confine))
    if trained and entry.get("train") is not None:
        net = _train(FORMAT_TASK[entry["dataset"]["format"]], entry, Path(base), confine, key, net, False).network
    return net.eval()


def _file_digest(path: Path) -> str:
    """SHA-256 of a file (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def train_split_dataset(
    entry: Mapping[str, Any], base_dir: str | Path, *, confine: bool = True, key: str = "dataset"
) -> Any:
    """The dataset of a table's training split (``train.split``): ``dataset`` with its ``split`` replaced.

    ``video_folder``: the split file (UCF101 ``trainlist01.txt``, lines ``<class>/<video> <label>``;
    the class is the folder) relative to ``root``; the other formats: the subfolder of ``root``.

    Raises
    ------
    InputError
        No ``train.split``; the split does not open (naming ``<key>.train.split``), or its classes
        differ from the scored split's (a network needs one label set).

    Examples
    --------
    >>> len(train_split_dataset(entry, "designs", key="tasks.datasets.recognition"))   # doctest: +SKIP
    9537
    """
    split = (entry.get("train") or {}).get("split")
    if split is None:
        raise InputError(f"{key}.train.split is not set; allowed: a split file (video_folder) or a subfolder of root")
    source = {**entry["dataset"], "split": split}
    ds = open_dataset(entry["dataset"], base_dir, confine=confine, key=f"{key}.dataset")
    try:
        train = open_dataset(source, base_dir, confine=confine, key=f"{key}.train.split")
    except InputError as exc:
        raise InputError(f"{key}.train.split = {split!r}: {exc}") from None
    if (train.num_classes, tuple(train.class_names)) != (ds.num_classes, tuple(ds.class_names)):
        raise InputError(
            f"{key}.train.split = {split!r}: its classes {list(train.class_names)} differ from the "
            f"scored split's {list(ds.class_names)}; allowed: splits of one label set"
        )
    return train


def check_disjoint_files(train: Any, train_indices: Any, test: Any, test_indices: Any, *, what: str) -> None:
    """Refuse training clips that share a video, frame image or mask file with the scored clips.

    Files are compared after resolving links (:meth:`~fsdvs_hw.scenes.datasets.ClipDataset.clip_files`;
    annotation files such as a COCO JSON are not clip files and are left out).

    Raises
    ------
    InputError
        Naming ``what``, how many files are shared and one of them.

    Examples
    --------
    >>> check_disjoint_files(ds, [0, 1], ds, [1], what="train.split")   # doctest: +SKIP
    Traceback (most recent call last):
    InputError: train.split: 1 file of the training clips is also in a scored clip, e.g. ...
    """
    from ..scenes.datasets import IMAGE_SUFFIXES, VIDEO_SUFFIXES

    def files(ds: Any, indices: Any) -> set[Path]:
        return {
            p.resolve()
            for i in indices
            for p in ds.clip_files(int(i))
            if p.suffix.lower() in IMAGE_SUFFIXES + VIDEO_SUFFIXES
        }

    shared = sorted(files(train, train_indices) & files(test, test_indices))
    if shared:
        raise InputError(
            f"{what}: {len(shared)} file(s) of the training clips also in a scored clip, e.g. "
            f"{str(shared[0])!r}; allowed: a training split disjoint from the scored one (UCF101: "
            "trainlist0N.txt with testlist0N.txt of the same N)"
        )


def _training_clips(
    entry: Mapping[str, Any], spec: Mapping[str, Any], base: Path, confine: bool, key: str
) -> tuple[Any, np.ndarray]:
    """(dataset, clip indices) a table trains on: ``spec["split"]`` (the dataset's own training split,
    disjoint files checked) or a draw of ``spec["n_train"]`` with ``spec["seed"]`` from the clips not scored."""
    from ..tasks.dataset_training import disjoint_train_indices

    ds = open_dataset(entry["dataset"], base, confine=confine, key=f"{key}.dataset")
    scored = ds.draw(entry["n_clips"], entry["seed"]) if entry["n_clips"] else np.arange(len(ds))
    train_ds, train_idx = ds, None
    if spec.get("split") is not None:
        train_ds = train_split_dataset(entry, base, confine=confine, key=key)
        train_idx = (
            train_ds.draw(spec["n_train"], spec["seed"])
            if spec["n_train"]
            else np.arange(len(train_ds), dtype=np.int64)
        )
        if len(train_idx) < 2:
            raise InputError(
                f"{key}.train.split = {spec['split']!r}: {len(train_idx)} training clip; allowed: 2 or "
                "more (train.n_train = 0: all of the split)"
            )
        check_disjoint_files(train_ds, train_idx, ds, scored, what=f"{key}.train.split = {spec['split']!r}")
    elif len(scored) >= len(ds):
        raise InputError(
            f"{key}.n_clips = {entry['n_clips']}: every one of the {len(ds)} clips is scored, none is "
            f"left to train on ({key}.train); allowed: 1 to {len(ds) - 2}, or a training split "
            f"({key}.train.split)"
        )
    else:
        train_idx = disjoint_train_indices(len(ds), scored, spec["n_train"], spec["seed"])
    return train_ds, train_idx


def _scored_source(entry: Mapping[str, Any]) -> dict[str, Any]:
    """The table's dataset without its disk cache (which changes no clip): what fingerprints hold."""
    return {k: v for k, v in entry["dataset"].items() if k != "cache"}


def _train_on_clips(
    train_ds: Any,
    train_indices: np.ndarray | None,
    task: str,
    net: Any,
    spec: Mapping[str, Any],
    device: str,
    *,
    out: Path | str | None,
    fingerprint: dict[str, Any] | None,
    verbose: bool,
    **stages: Any,
) -> Any:
    """Train a copy of ``net`` on a table's training clips with its ``train`` table's common settings.

    Parameters
    ----------
    train_ds : ClipDataset
        The dataset trained on (:func:`_training_clips`).
    train_indices : ndarray or None
        Its training clips.
    task : str
    net : torch.nn.Module
        Copied; the original is left as it is.
    spec : mapping
        The ``train`` table: ``weight_decay``, ``batch_size`` and ``seed`` are used.
    device : str
    out : path, optional
        File stem of the trained network (resumes; a finished one is reused).
    fingerprint : dict, optional
        Identity of the run stored with the checkpoint and compared on resume.
    verbose : bool
        One line per epoch on stderr.
    **stages
        The stages and their rates (:func:`fsdvs_hw.tasks.dataset_training.train_on_dataset`).

    Returns
    -------
    DatasetTrainingResult
    """
    from ..tasks.dataset_training import train_on_dataset

    return train_on_dataset(
        train_ds,
        task,
        copy.deepcopy(net),
        train_indices=train_indices,
        weight_decay=spec["weight_decay"],
        batch_size=spec["batch_size"],
        seed=spec["seed"],
        device=device,
        out=out,
        fingerprint=fingerprint,
        verbose=verbose,
        **stages,
    )


def _train(
    task: str,
    entry: Mapping[str, Any],
    base: Path,
    confine: bool,
    key: str,
    net: Any,
    verbose: bool,
    out_stem: Path | None = None,
) -> Any:
    """Train ``net`` (a copy) on the task's clips not scored (or reuse / resume ``train.out``)."""
    spec = dict(entry["train"])
    train_ds, train_idx = _training_clips(entry, spec, base, confine, key)
    out = out_stem or _path(base, spec["out"] or f"trained/{task}", what=f"{key}.train.out", confine=confine)
    weights = _path(base, entry["weights"], what=f"{key}.weights", confine=confine) if entry["weights"] else None
    fingerprint = {
        "dataset": _scored_source(entry),
        "network": entry["network"],
        "options": entry["network_options"],
        "weights_sha256": _file_digest(weights) if weights else None,
        "scored": [entry["n_clips"], entry["seed"]],
        "sensor": "default",
        # train.split only when set: checkpoints trained before the key existed keep their fingerprint
        "train": {k: v for k, v in spec.items() if k != "out" and not (k == "split" and v is None)},
    }
    return _train_on_clips(
        train_ds,
        train_idx,
        task,
        net,
        spec,
        entry["device"],
        out=out,
        fingerprint=fingerprint,
        verbose=verbose,
        kernel_size=spec["kernel_size"],
        learn_filter=spec["learn_kernel"],
        epochs_frozen=spec["epochs_frozen"],
        epochs_joint=spec["epochs_joint"],
        lr_network=spec["lr_network"],
        lr_kernel=spec["lr_kernel"],
        lr_backbone=spec["lr_backbone"],
        lr_head=spec["lr_head"],
    )


def train_user_task(
    task: str,
    entry: Mapping[str, Any],
    base_dir: str | Path,
    *,
    confine: bool = True,
    verbose: bool = False,
    overrides: Mapping[str, Any] | None = None,
    out: str | Path | None = None,
) -> Any:
    """Train (or reuse / resume) the network of a ``[tasks.datasets.<task>]`` table with a ``train`` table.

    The training clips are drawn with ``train.seed`` from the clips the table does not score
    (``n_clips`` drawn with ``seed``), so training and scoring never share a clip; the network
    starts from the factory (from scratch) or from ``weights`` (fine-tuning). The result is
    written to ``train.out`` (inside the design's folder) and reused by a rerun with the same
    data, network and settings (:func:`fsdvs_hw.tasks.dataset_training.train_on_dataset`).

    Parameters
    ----------
    task : str
    entry : mapping
        A validated :class:`UserTask` dumped, with ``train`` set.
    base_dir : path
        The design file's folder.
    verbose : bool
        One line per epoch on stderr.
    overrides : mapping, optional
        ``train`` keys replaced for this run (the ablation's ``kernel_size`` and ``seed``).
    out : path, optional
        File stem used instead of ``train.out`` (a command's own output folder).

    Returns
    -------
    DatasetTrainingResult
        The learned kernel (``paths["kernel"]``: what ``[kernel] path`` can name) and the network.

    Raises
    ------
    InputError
        No ``train`` table, every clip scored (none left to train on), too few clips for
        ``n_train``, a checkpoint at ``train.out`` trained with other settings.

    Examples
    --------
    >>> res = train_user_task("recognition", design.spec.tasks.datasets["recognition"].model_dump(), "designs")  # doctest: +SKIP
    >>> res.paths["kernel"].name                                                                         # doctest: +SKIP
    'recognition.json'
    """
    key = f"tasks.datasets.{task}"
    if entry.get("train") is None:
        raise InputError(f"{key}.train is not set; allowed: a train = {{...}} table to train on the user's clips")
    base = Path(base_dir).resolve()
    ds = open_dataset(entry["dataset"], base, confine=confine, key=f"{key}.dataset")
    blob = json.dumps(dict(entry), sort_keys=True)
    net = _open_network(blob, str(base), bool(confine), key, 2 * (int(ds.n_frames) - 1), int(ds.num_classes), False)
    if overrides:
        entry = {**entry, "train": TrainSpec.model_validate({**entry["train"], **overrides}).model_dump()}
    return _train(task, entry, base, confine, key, net, verbose, None if out is None else Path(out))


def user_network_identity(entry: Mapping[str, Any], base_dir: str | Path, *, confine: bool = True) -> dict[str, Any]:
    """What determines a table's scores besides the kernel: data, clip draw, network, weights, training.

    JSON-able, for result keys (:mod:`fsdvs_hw.explore.codesign` units): the dataset (its disk
    cache left out: it changes no clip), ``n_clips`` and ``seed``, the factory and its options, the
    SHA-256 of ``weights`` and the ``train`` table.

    Examples
    --------
    >>> entry = UserTask(dataset={"format": "video_folder", "root": "ucf"}).model_dump()
    >>> sorted(user_network_identity(entry, "."))[:3]
    ['clip_seed', 'dataset', 'device']
    """
    weights = (
        _path(Path(base_dir).resolve(), entry["weights"], what="weights", confine=confine) if entry["weights"] else None
    )
    return {
        "dataset": _scored_source(entry),
        "n_test": entry["n_clips"],
        "clip_seed": entry["seed"],
        "network": entry["network"] or "built-in",
        "options": dict(entry["network_options"]),
        "weights_sha256": _file_digest(weights) if weights else None,
        "train": entry.get("train"),
        "device": entry["device"],
    }


def _finetune_stages(kernel: Any, realisation: Any, epochs: int, lr_network: float, lr_filter: float) -> dict[str, Any]:
    """The training stages of :func:`finetune_user_network`: frozen ``kernel``, or co-designed ``realisation``.

    Parameters
    ----------
    kernel : Kernel or None
        Trained frozen (stage one only) when ``realisation`` is None.
    realisation : Realisation or None
        Otherwise co-designed (stage two only).
    epochs : int
    lr_network, lr_filter : float
        AdamW rates (1/step) of the network and of the realisation's parameters.

    Returns
    -------
    dict
        Keyword arguments of :func:`fsdvs_hw.tasks.dataset_training.train_on_dataset`.
    """
    if realisation is None:
        return {"init_kernel": kernel, "learn_filter": False, "epochs_frozen": epochs, "epochs_joint": 0}
    return {
        "realisation": realisation,
        "epochs_frozen": 0,
        "epochs_joint": epochs,
        "lr_kernel": lr_filter,
        "lr_backbone": lr_network,
        "lr_head": lr_network,
    }


def finetune_user_network(
    task: str,
    entry: Mapping[str, Any],
    base_dir: str | Path,
    *,
    kernel: Any = None,
    realisation: Any = None,
    epochs: int = 4,
    n_train: int = 0,
    lr_network: float = 1e-3,
    lr_filter: float = 1e-2,
    out: str | Path | None = None,
    fingerprint: Mapping[str, Any] | None = None,
    confine: bool = True,
    verbose: bool = False,
) -> Any:
    """Train a table's network further with a realised kernel: frozen, or co-designed (user data).

    The user-data counterpart of :func:`fsdvs_hw.tasks.learn.finetune_network` (the
    ``finetune`` and ``codesign`` rows of :mod:`fsdvs_hw.explore.codesign`): the network the table
    scores (:func:`open_network`: ``weights``, or the ``train`` table's checkpoint) trains on the
    clips :func:`train_user_task` trains on (``train.split``, or the seeded draw from the clips not
    scored: never a scored clip), through
    :func:`~fsdvs_hw.tasks.dataset_training.train_on_dataset`'s loop:

    * ``kernel`` given: stage one only, ``epochs`` epochs, the kernel frozen, the whole network at
      ``lr_network``;
    * ``realisation`` given: stage two only, ``epochs`` epochs, the realisation's physical
      parameters at ``lr_filter`` and the network (backbone and head) at ``lr_network``.

    Parameters
    ----------
    task : str
    entry : mapping
        A validated :class:`UserTask` dumped.
    base_dir : path
        The design file's folder.
    kernel : Kernel, optional
        The frozen kernel (exactly one of ``kernel`` and ``realisation``).
    realisation : Realisation, optional
        The fitted realisation to co-design (a differentiable form).
    epochs : int
        Training epochs (≥ 1).
    n_train : int
        Training clips; 0 = ``train.n_train`` (0 there: every clip not scored).
    lr_network, lr_filter : float
        AdamW rates (1/step) of the network and of the realisation's parameters.
    out : path, optional
        File stem of the trained network (resumes; a finished one is reused).
    fingerprint : mapping, optional
        Identity of the run stored with the checkpoint and compared on resume.

    Returns
    -------
    DatasetTrainingResult
        ``network`` (CPU, eval mode) and the kernel it ends with; co-designed, the provenance's
        ``realisation_design`` is the realisation after training.

    Raises
    ------
    InputError
        Both or neither of ``kernel`` / ``realisation``, too few clips left to train on, a
        checkpoint at ``out`` trained with another fingerprint.

    Examples
    --------
    >>> res = finetune_user_network("segmentation", entry, "designs", kernel=fitted.kernel(), epochs=1)  # doctest: +SKIP
    >>> res.history[-1]["stage"]                                                                         # doctest: +SKIP
    'frozen_filter'
    """
    if (kernel is None) == (realisation is None):
        raise InputError("finetune_user_network: give exactly one of kernel= (frozen) and realisation= (co-designed)")
    key = f"tasks.datasets.{task}"
    base = Path(base_dir).resolve()
    spec = dict(entry.get("train") or TrainSpec().model_dump())
    spec["n_train"] = n_train or spec["n_train"]
    try:
        train_ds, train_idx = _training_clips(entry, spec, base, confine, key)
    except InputError as exc:  # name the key that asked for the clips
        raise InputError(
            f"{key} trained further with codesign.n_train = {n_train} (0 = its train.n_train): {exc}"
        ) from None
    ds = open_dataset(entry["dataset"], base, confine=confine, key=f"{key}.dataset")
    net = open_network(entry, ds, base, confine=confine, key=key)
    stages = _finetune_stages(kernel, realisation, epochs, lr_network, lr_filter)
    return _train_on_clips(
        train_ds,
        train_idx,
        task,
        net,
        spec,
        entry["device"],
        out=out,
        fingerprint=None if fingerprint is None else dict(fingerprint),
        verbose=verbose,
        lr_network=lr_network,
        **stages,
    )


def open_network(
    entry: Mapping[str, Any],
    dataset: Any,
    base_dir: str | Path,
    *,
    confine: bool = True,
    key: str = "network",
    trained: bool = True,
) -> Any:
    """The network a ``[tasks.datasets.<task>]`` table names, built for ``dataset`` (cached per process).

    Parameters
    ----------
    entry : mapping
        A validated :class:`UserTask` dumped.
    dataset : ClipDataset
        Sets ``in_channels = 2 (T - 1)`` and ``num_classes``.
    base_dir : path
        The design file's folder (factory import, ``weights``).
    trained : bool
        With a ``train`` table: True returns the network trained on the clips not scored (trained
        now, or reused from ``train.out``: :func:`train_user_task`); False the untrained one.

    Returns
    -------
    torch.nn.Module
        In eval mode, with the weights loaded.

    Raises
    ------
    InputError
        The factory does not import, fails or returns no module; a weights file that is missing
        or does not fit (naming the file and parameter).

    Examples
    --------
    >>> net = open_network(entry, open_dataset(entry["dataset"], "."), ".")   # doctest: +SKIP
    """
    blob = json.dumps(dict(entry), sort_keys=True)
    return _open_network(
        blob,
        str(Path(base_dir).resolve()),
        bool(confine),
        key,
        2 * (int(dataset.n_frames) - 1),
        int(dataset.num_classes),
        bool(trained),
    )


def check_user_task(
    task: str, entry: Mapping[str, Any], base_dir: str | Path, *, confine: bool = True
) -> list[tuple[str, Any, str]]:
    """Problems of one validated ``[tasks.datasets.<task>]`` table, as ``(key, value, message)``.

    The format must hold the task's targets, a detection dataset's ``size`` must be even (the
    network works at stride 2), the dataset must open (its layout is read: folders, the JSON, image
    headers; no clip is decoded), ``n_clips`` must not exceed its clips, and the network must build
    with its weights.

    Examples
    --------
    >>> check_user_task("detection", entry, "designs")   # doctest: +SKIP
    []
    """
    key = f"tasks.datasets.{task}"
    if entry["device"] == "cuda":
        import torch

        if not torch.cuda.is_available():
            return [
                (
                    f"{key}.device",
                    "cuda",
                    f"CUDA is not available on this machine (torch {torch.__version__}); allowed here: 'cpu'",
                )
            ]
    fmt = entry["dataset"]["format"]
    if FORMAT_TASK[fmt] != task:
        allowed = [f for f, t in FORMAT_TASK.items() if t == task]
        return [
            (
                f"{key}.dataset.format",
                fmt,
                f"holds {FORMAT_TASK[fmt]} targets, not {task}; allowed for "
                f"[tasks.datasets.{task}]: {', '.join(map(repr, allowed)) or 'none (unknown task)'}",
            )
        ]
    size = entry["dataset"].get("size")
    if task == "detection" and size and (size[0] % 2 or size[1] % 2):
        return [
            (
                f"{key}.dataset.size",
                size,
                "the detection network works at stride 2; allowed: even H and W, e.g. "
                f"[{size[0] + size[0] % 2}, {size[1] + size[1] % 2}]",
            )
        ]
    try:
        ds = open_dataset(entry["dataset"], base_dir, confine=confine, key=f"{key}.dataset")
    except InputError as exc:
        return [(f"{key}.dataset", entry["dataset"].get("root"), str(exc))]
    problems = []
    if entry["n_clips"] > len(ds):
        problems.append(
            (f"{key}.n_clips", entry["n_clips"], f"the dataset has {len(ds)} clips; allowed: 0 (all) to {len(ds)}")
        )
    if entry.get("train") is not None and entry["train"].get("split") is not None:
        problems += _train_split_problems(entry, ds, base_dir, confine, key)
    elif entry.get("train") is not None:
        n_scored = entry["n_clips"] or len(ds)
        n_train = entry["train"]["n_train"]
        if n_scored > len(ds) - 2:
            problems.append(
                (
                    f"{key}.n_clips",
                    entry["n_clips"],
                    f"with {key}.train, clips are needed for training "
                    f"too; allowed: 1 to {len(ds) - 2} of the {len(ds)} clips",
                )
            )
        elif n_train > len(ds) - n_scored:
            problems.append(
                (
                    f"{key}.train.n_train",
                    n_train,
                    f"{len(ds) - n_scored} clips are not scored; allowed: 0 (all of them) or 2 to {len(ds) - n_scored}",
                )
            )
    try:
        open_network(entry, ds, base_dir, confine=confine, key=key, trained=False)
    except InputError as exc:
        where = "weights" if "weights file" in str(exc) or ".weights" in str(exc) else "network"
        problems.append((f"{key}.{where}", entry[where], str(exc)))
    return problems


def _train_split_problems(
    entry: Mapping[str, Any], ds: Any, base_dir: str | Path, confine: bool, key: str
) -> list[tuple[str, Any, str]]:
    """A ``train.split`` must open, hold ``n_train`` clips and share no file with the scored clips."""
    split, n_train = entry["train"]["split"], entry["train"]["n_train"]
    try:
        train = train_split_dataset(entry, base_dir, confine=confine, key=key)
        if n_train > len(train):
            return [
                (
                    f"{key}.train.n_train",
                    n_train,
                    f"the training split {split!r} has {len(train)} clips; allowed: 0 (all) to {len(train)}",
                )
            ]
        if (n_train or len(train)) < 2:
            return [
                (
                    f"{key}.train.n_train",
                    n_train,
                    f"1 training clip (the split {split!r} has {len(train)}); allowed: 2 or more",
                )
            ]
        scored = ds.draw(entry["n_clips"], entry["seed"]) if entry["n_clips"] else range(len(ds))
        picked = train.draw(n_train, entry["train"]["seed"]) if n_train else range(len(train))
        check_disjoint_files(train, picked, ds, scored, what=f"{key}.train.split = {split!r}")
    except InputError as exc:
        return [(f"{key}.train.split", split, str(exc))]
    return []


#: ``SensorConfig`` fields recorded with a user-data task's scores.
_RECORDED_SENSOR_FIELDS = ("threshold_on", "threshold_off", "threshold_sigma", "placement", "positivity")


def _design_sensor(frame_rate_hz: float, design_sensor: Mapping[str, Any] | None) -> tuple[Any, dict[str, Any]]:
    """The simulator of a user-data task and its record: the training default at the clips' rate,
    with the given ``SensorConfig`` fields (the design's ``[sensor]`` thresholds, ...) where asked."""
    from types import SimpleNamespace

    from ..tasks.learn import default_sensor

    cfg = default_sensor(SimpleNamespace(frame_rate_hz=frame_rate_hz))
    if design_sensor is not None:
        cfg = dataclasses.replace(cfg, **dict(design_sensor))
    return cfg, {
        "source": "design" if design_sensor is not None else "default",
        **{k: getattr(cfg, k) for k in _RECORDED_SENSOR_FIELDS},
    }


def _evaluate_table(
    kernel: Any,
    task: str,
    entry: Mapping[str, Any],
    dataset: Any,
    network: Any,
    evaluator: Any,
    sensor: Any,
    events_fn: Any,
    max_failed_fraction: float,
) -> Any:
    """Evaluate ``kernel`` on a table's drawn clips, its errors naming the table's keys.

    Parameters
    ----------
    kernel : Kernel or None
    task : str
        The table's name.
    entry : mapping
        A validated :class:`UserTask` dumped (``n_clips``, ``seed``, ``device``, ``network``).
    dataset : ClipDataset
    network : torch.nn.Module
    evaluator : Evaluator
        The dataset's task evaluator (its ``name`` enters the messages).
    sensor : SensorConfig
    events_fn : callable or None
    max_failed_fraction : float
        Drawn clips that may fail to read (fraction).

    Returns
    -------
    DatasetEvaluation
        As :func:`fsdvs_hw.tasks.dataset_eval.evaluate_on_dataset`.

    Raises
    ------
    ClipFailuresError
        Naming ``tasks.datasets.<task>.max_failed_clip_fraction``.
    NetworkOutputError, InputError
        Prefixed with the table's key (and its network, or its dataset).
    """
    from ..tasks.dataset_eval import ClipFailuresError, NetworkOutputError, evaluate_on_dataset

    key = f"tasks.datasets.{task}"
    try:
        return evaluate_on_dataset(
            kernel,
            task,
            dataset,
            network,
            sensor=sensor,
            n_clips=entry["n_clips"] or None,
            seed=entry["seed"],
            events_fn=events_fn,
            device=entry["device"],
            max_failed_fraction=max_failed_fraction,
        )
    except ClipFailuresError as exc:
        raise ClipFailuresError(
            exc.detail, exc.failures, exc.n_drawn, max_failed_fraction, setting=f"{key}.max_failed_clip_fraction"
        ) from None
    except NetworkOutputError as exc:
        name = entry["network"] or f"built-in {evaluator.name} network"
        raise NetworkOutputError(f"{key}.network = {name!r}: {exc}") from None
    except InputError as exc:
        raise InputError(f"{key} ({entry['dataset']['format']} at {entry['dataset']['root']!r}): {exc}") from None


def dataset_evidence(
    kernel: Any,
    task: str,
    entry: Mapping[str, Any],
    base_dir: str | Path,
    *,
    design_sensor: Mapping[str, Any] | None = None,
    events_fn: Any = None,
    confine: bool = True,
    network: Any = None,
) -> tuple[Any, dict[str, Any]]:
    """Score ``kernel`` on a user dataset with the user network and keep every clip's contribution.

    The counterpart of :func:`fsdvs_hw.explore.paired.clip_evidence` for a
    ``[tasks.datasets.<task>]`` table: the same per-clip metric objects
    (:data:`fsdvs_hw.explore.paired.PER_CLIP_METRICS`: COCO matches, top-1 per clip, per-clip
    confusion matrices with the dataset's ignore index) and per-clip event rates.

    Parameters
    ----------
    kernel : Kernel or None
        The realised kernel (None: a 1×1 delta, a conventional DVS).
    task : str
        ``"detection"``, ``"recognition"`` or ``"segmentation"`` (the table's name).
    entry : mapping
        A validated :class:`UserTask` dumped.
    base_dir : path
        The design file's folder.
    design_sensor : mapping, optional
        ``SensorConfig`` fields replacing the training default's (``tasks.sensor = "design"``: the
        design's ``[sensor]`` thresholds, mismatch, placement and positivity); None: the training
        default (:func:`fsdvs_hw.tasks.learn.default_sensor`) at the clips' frame rate.
    events_fn : callable, optional
        Event frames instead of the in-pixel simulator (the emulation track).
    network : torch.nn.Module, optional
        Score this network instead of the table's (a fine-tuned or co-designed one,
        :func:`finetune_user_network`).

    Returns
    -------
    evidence : ClipEvidence
        ``checkpoint`` names the network; ``test_seed`` is the clip-draw seed; ``failures`` the
        drawn clips skipped (at most ``max_failed_clip_fraction`` of ``n_drawn``).
    sensor_record : dict
        Which simulator settings were used.

    Raises
    ------
    ClipFailuresError
        More than ``max_failed_clip_fraction`` of the drawn clips failed to read (naming the key,
        the first files and reasons; ``failures`` lists them all).
    InputError
        Any dataset or network problem, or a problem of the task (the network's output, an odd
        frame size for the detector), naming the key, the file and the field.

    Examples
    --------
    >>> ev, _ = dataset_evidence(None, "recognition", entry, "designs")   # doctest: +SKIP
    >>> ev.metric_name, ev.n_clips                                       # doctest: +SKIP
    ('top1', 4)
    """
    from ..tasks.dataset_eval import evaluator_for_dataset, read_clip
    from .paired import PER_CLIP_METRICS, ClipEvidence

    t0 = time.perf_counter()
    key = f"tasks.datasets.{task}"
    ds = open_dataset(entry["dataset"], base_dir, confine=confine, key=f"{key}.dataset")
    net = open_network(entry, ds, base_dir, confine=confine, key=key) if network is None else network
    evaluator = evaluator_for_dataset(task, ds)
    fraction = float(entry.get("max_failed_clip_fraction", DEFAULT_MAX_FAILED_CLIP_FRACTION))
    drawn = ds.draw(entry["n_clips"], entry["seed"]) if entry["n_clips"] else np.arange(len(ds))
    first = next((c for c in (read_clip(ds, int(i))[0] for i in drawn) if c is not None), None)
    # the first readable clip's frame rate (none readable: evaluate_on_dataset names every failure)
    rate_hz = 1.0 if first is None else 1.0 / float(np.diff(first.timestamps_s)[0])
    sensor, sensor_rec = _design_sensor(rate_hz, design_sensor)
    ev = _evaluate_table(kernel, task, entry, ds, net, evaluator, sensor, events_fn, fraction)
    metric = PER_CLIP_METRICS[evaluator.name](ev.predictions, ev.targets, evaluator)
    n = len(ev.clip_indices)
    t, h, w = (first if first is not None else ds[int(ev.clip_indices[0])]).frames.shape
    evidence = ClipEvidence(
        task=evaluator.name,
        metric_name=evaluator.primary_metric,
        value=float(metric.weighted(np.ones((1, n)))[0]),
        n_clips=n,
        metric=metric,
        checkpoint=entry["network"] or f"built-in {evaluator.name} network",
        sensor_seed=int(sensor.seed),
        seconds=time.perf_counter() - t0,
        test_seed=int(entry["seed"]),
        event_rate=float(np.mean(ev.event_counts)) / (h * w * (t - 1)),
        clip_event_rates=np.asarray(ev.event_counts, dtype=np.float64) / (h * w * ev.durations_s),
        failures=ev.failures,
        n_drawn=len(drawn),
    )
    return evidence, sensor_rec


def user_task_record(entry: Mapping[str, Any]) -> dict[str, Any]:
    """What a task track's record says about a user-data task: the dataset, the network, the CI.

    Examples
    --------
    >>> rec = user_task_record(UserTask(dataset={"format": "video_folder", "root": "ucf"}).model_dump())
    >>> rec["dataset"]["format"], rec["network"]["factory"]
    ('video_folder', 'built-in')
    """
    src = entry["dataset"]
    return {
        "dataset": {k: src.get(k) for k in ("format", "root", "split", "n_frames", "size")}
        | {"n_clips": entry["n_clips"], "seed": entry["seed"]},
        "network": {
            "factory": entry["network"] or "built-in",
            "options": dict(entry["network_options"]),
            "weights": entry["weights"],
            "device": entry["device"],
        },
        "train": dict(entry["train"]) if entry.get("train") else None,
        "ci_note": ONE_NETWORK_NOTE,
    }
