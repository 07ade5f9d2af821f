"""The ``[tasks.datasets.<task>]`` section of a design file: the user's clips and network, as pydantic models.

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
(:func:`fsdvs_hw.design.user_data_inputs.train_split_dataset`), refused when it shares a file
with the scored clips (:func:`fsdvs_hw.design.user_data_inputs.check_disjoint_files`).

The factory is imported from ``sys.path`` or from the design file's folder, and called as
``factory(in_channels=2 * (n_frames - 1), num_classes=<the dataset's>, **network_options)``
(:func:`fsdvs_hw.tasks.user_networks.load_network_factory`). Opening the dataset and the network
is :mod:`fsdvs_hw.design.user_data_inputs`; training and scoring is :mod:`fsdvs_hw.explore.user_data`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, model_validator

from ..limits import MAX_CLIPS, MAX_EPOCHS, MAX_SEED
from ..schema import StrictModel, field

__all__ = [
    "DEFAULT_MAX_FAILED_CLIP_FRACTION",
    "FORMAT_TASK",
    "ClipCacheSpec",
    "CocoFramesSource",
    "DsecDetectionSource",
    "MaskFramesSource",
    "SamplingTable",
    "TrainSpec",
    "UserTask",
    "VideoFolderSource",
    "source_models",
]

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

    root: str = field(
        ...,
        "",
        "the dataset's folder, relative to the design file (inside its folder or a [design] data_roots folder)",
    )
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


def source_models() -> tuple[type[StrictModel], ...]:
    """The models of a ``dataset`` table, one per ``format`` (for the keys ``--set`` may reach).

    Examples
    --------
    >>> "root" in source_models()[0].model_fields
    True
    """
    return (VideoFolderSource, CocoFramesSource, DsecDetectionSource, MaskFramesSource)


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
    memory_mb: float | None = field(
        None,
        "MB",
        "stream the training clips from disk, at most this many megabytes (10**6 bytes) of clips in "
        "memory at once (fsdvs_hw.tasks.clip_stream); None = decoded once and held in memory, or 1024 "
        "when sampling or val_fraction asks for streaming",
        gt=0.0,
        le=1e6,
    )
    workers: int = field(
        0, "processes", "decoding processes of the streamed loader (0 = the training process)", ge=0, le=64
    )
    val_fraction: float = field(
        0.0,
        "",
        "fraction of the training videos held out (seeded) and scored after every epoch; the best "
        "epoch's network and kernel are kept; 0 = none",
        ge=0.0,
        le=0.9,
    )


class SamplingTable(StrictModel):
    """``[tasks.datasets.<task>] sampling = {...}``: clips per video, crop and flip, as the field samples them.

    For ``format = "video_folder"`` with a ``dataset.size``
    (:class:`fsdvs_hw.tasks.clip_sampling.SamplingSpec`): scored on ``clips_per_video`` evenly
    spaced clips per video (the video's score the mean of its clips' class probabilities),
    trained on ``train_clips_per_video`` random clips per video per epoch; frames resized keeping
    their aspect and centre-cropped (a seeded random crop and flip in training).
    """

    unknown_key = "unknown key of a user-data task's sampling table"

    clips_per_video: int = field(1, "clips", "clips scored per video, evenly spaced", ge=1, le=100)
    train_clips_per_video: int = field(1, "clips", "random clips per video per training epoch", ge=1, le=100)
    resize: Literal["short_side", "stretch"] = field(
        "short_side", "", "'short_side': keep the aspect and crop to dataset.size; 'stretch': resize each frame"
    )
    train_crop: Literal["random", "center"] = field("random", "", "where the training crop is taken")
    train_flip: bool = field(True, "", "flip half the training clips left-right (seeded)")
    seed: int = field(0, "", "seeds the training clips' start frames, crops and flips", ge=0, le=MAX_SEED)


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
    sampling: SamplingTable | None = field(
        None,
        "",
        "clips per video, crop and flip (video_folder with a size): {clips_per_video = 5, "
        "train_clips_per_video = 1}; None = one clip per video, its first frames, resized to size",
    )
    train: TrainSpec | None = field(
        None,
        "",
        "train the network on the clips not scored first (two-stage "
        "protocol; resumes); None = score the network as given",
    )

    @model_validator(mode="after")
    def _sampling_needs_videos_of_one_size(self) -> UserTask:
        """``sampling`` crops video clips to ``dataset.size``: a ``video_folder`` dataset with a size."""
        if self.sampling is not None and (self.dataset.format != "video_folder" or self.dataset.size is None):
            raise ValueError(
                "sampling (clips per video, crop, flip) needs dataset.format = 'video_folder' and a "
                f"dataset.size = [H, W] to crop to; got format {self.dataset.format!r}, size {self.dataset.size!r}"
            )
        return self
