"""The dataset and network a ``[tasks.datasets.<task>]`` table names: opened, and checked when a design is read.

:func:`open_dataset` opens the reader of a table's ``dataset`` (its layout only; clips are
decoded when scored), :func:`open_untrained_network` builds the table's network with its
``weights`` (both cached per process), :func:`train_split_dataset` opens a ``train.split`` and
:func:`check_disjoint_files` refuses training clips that share a file with the scored ones.
:func:`check_user_task` is what reading a design checks of each table. Training the network
and scoring on the clips is :mod:`fsdvs_hw.explore.user_data`.
"""

from __future__ import annotations

import contextlib
import functools
import json
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..paths import Confinement
from .design_paths import resolve_design_path
from .user_data_section import FORMAT_TASK

__all__ = [
    "build_user_network",
    "check_dataset_files",
    "check_disjoint_files",
    "check_user_task",
    "learned_kernel_path",
    "open_dataset",
    "open_untrained_network",
    "pending_kernel",
    "train_split_dataset",
]


def _reader_paths(source: Mapping[str, Any], base: Path, confine: Confinement, key: str) -> dict[str, Path]:
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
    return {name: resolve_design_path(base, str(p), what=f"{key}.{name}", confine=confine) for name, p in rel.items()}


#: Each ``dataset.format``: its reader (a class of :mod:`fsdvs_hw.scenes.datasets`), the paths the
#: reader takes first, in order (named as in :func:`_reader_paths`), and the table's fields it takes
#: by name. Besides: ``video_folder``'s ``split_file`` (the split path, if any), ``dsec_detection``'s
#: ``class_names`` (the DSEC classes when none are given) and every reader's :func:`_open_dataset` ``common``.
_READERS: dict[str, tuple[str, tuple[str, ...], tuple[str, ...]]] = {
    "video_folder": ("VideoFolderDataset", ("root",), ("fps", "stride", "start_frame")),
    "dsec_detection": ("DsecDetectionDataset", ("root",), ("clip_stride",)),
    "coco_frames": ("CocoFramesDataset", ("frames", "annotations"), ("clip_stride", "fps", "require_annotations")),
    "mask_frames": (
        "MaskFramesDataset",
        ("frames", "masks"),
        ("num_classes", "clip_stride", "fps", "ignore_index", "frame_suffix", "mask_suffix"),
    ),
}


@functools.lru_cache(maxsize=16)
def _open_dataset(blob: str, base: str, confine: Confinement, key: str) -> Any:
    from ..scenes import datasets
    from ..scenes.clip_cache import ClipDiskCache

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
        folder = resolve_design_path(Path(base), s["cache"]["dir"], what=f"{key}.cache.dir", confine=confine)
        common["disk_cache"] = ClipDiskCache(folder, s["cache"]["max_mb"])
    reader, positional, named = _READERS[s["format"]]
    options = {name: s[name] for name in named}
    if s["format"] == "video_folder":
        options["split_file"] = paths.get("split")
    elif s["format"] == "dsec_detection":
        options["class_names"] = s["class_names"] or datasets.DSEC_DETECTION_CLASSES
    ds = getattr(datasets, reader)(*(paths[name] for name in positional), **options, **common)
    if confine:
        check_dataset_files(ds, Path(base), confine, key)
    return ds


def check_dataset_files(dataset: Any, base: Path, confine: Confinement, key: str) -> None:
    """Refuse a dataset that names a file outside the design's folder and its data roots.

    Every file a clip is decoded from (:meth:`~fsdvs_hw.scenes.datasets.ClipDataset.clip_files`:
    videos, frame images, masks, a COCO ``file_name`` with ``../``) and, for COCO, every image of
    the annotations, is resolved (links followed: a class folder or a file inside a root that links
    out of it) and must lie inside the design's folder or a ``[design] data_roots`` folder.

    Raises
    ------
    InputError
        One, naming the key, the clip, the file and where it resolves to.

    Examples
    --------
    >>> check_dataset_files(ds, Path("designs"), True, "tasks.datasets.detection.dataset")   # doctest: +SKIP
    """
    seen: set[Path] = set()
    named: list[tuple[str, Path]] = [(f"clip {i}", p) for i in range(len(dataset)) for p in dataset.clip_files(i)]
    frames_dir, images = getattr(dataset, "frames_dir", None), getattr(dataset, "images", None)
    if frames_dir is not None and isinstance(images, Mapping):  # COCO: images outside every clip too
        named += [(f"image id {iid}", Path(frames_dir) / str(im["file_name"])) for iid, im in images.items()]
    for where, path in named:
        if path in seen:
            continue
        seen.add(path)
        try:
            resolve_design_path(base, str(path), what=f"{key}: {where}: file", confine=confine)
        except InputError as exc:
            raise InputError(f"{exc} (a file the dataset names, e.g. through a link or '../')") from None


def open_dataset(
    source: Mapping[str, Any], base_dir: str | Path, *, confine: Confinement = True, key: str = "dataset"
) -> Any:
    """The :class:`~fsdvs_hw.scenes.datasets.ClipDataset` a design's ``dataset`` table names.

    Opened once per process (cached): only the layout is read; clips are decoded when scored.

    Parameters
    ----------
    source : mapping
        A validated ``dataset`` table (a source model of :mod:`fsdvs_hw.design.user_data_section`:
        ``VideoFolderSource``, ``CocoFramesSource``, ``DsecDetectionSource``, ``MaskFramesSource``,
        dumped), e.g. ``UserTask(...).model_dump()["dataset"]``.
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
    return _open_dataset(json.dumps(dict(source), sort_keys=True), str(Path(base_dir).resolve()), confine, key)


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


def build_user_network(
    entry: Mapping[str, Any], base: Path, confine: Confinement, key: str, in_channels: int, num_classes: int
) -> Any:
    """A new network of a ``[tasks.datasets.<task>]`` table (not cached, not trained): its factory
    (or the task's built-in network) with its ``weights`` loaded.

    Parameters
    ----------
    entry : mapping
        A validated :class:`~fsdvs_hw.design.user_data_section.UserTask` dumped.
    base : Path
        The design file's folder (factory import, ``weights``).
    confine : bool
        Refuse paths outside ``base``.
    key : str
        The design key, for messages.
    in_channels, num_classes : int
        Set from the dataset.

    Returns
    -------
    torch.nn.Module

    Raises
    ------
    InputError
        The factory does not import, fails or returns no module; a weights file that is missing
        or does not fit; ``network_options`` that set ``in_channels`` or ``num_classes``.
    """
    from ..tasks.user_networks import builtin_network, load_network_factory, load_weights

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
        with _importable_from(base):
            net = load_network_factory(
                entry["network"], in_channels=in_channels, num_classes=num_classes, **entry["network_options"]
            )
    if entry["weights"]:
        load_weights(net, resolve_design_path(base, entry["weights"], what=f"{key}.weights", confine=confine))
    return net


@functools.lru_cache(maxsize=16)
def _open_untrained_network(
    blob: str, base: str, confine: Confinement, key: str, in_channels: int, num_classes: int
) -> Any:
    return build_user_network(json.loads(blob), Path(base), confine, key, in_channels, num_classes).eval()


def open_untrained_network(
    entry: Mapping[str, Any], dataset: Any, base_dir: str | Path, *, confine: Confinement = True, key: str = "network"
) -> Any:
    """The network a ``[tasks.datasets.<task>]`` table names, built for ``dataset`` with its ``weights``
    and not trained (its ``train`` table ignored; cached per process).

    Parameters
    ----------
    entry : mapping
        A validated :class:`~fsdvs_hw.design.user_data_section.UserTask` dumped.
    dataset : ClipDataset
        Sets ``in_channels = 2 (T - 1)`` and ``num_classes``.
    base_dir : path
        The design file's folder (factory import, ``weights``).
    confine : bool
        Refuse paths outside ``base_dir``.
    key : str
        The design key, for messages.

    Returns
    -------
    torch.nn.Module
        In eval mode, with the weights loaded.
    """
    return _open_untrained_network(*network_cache_key(entry, dataset, base_dir, confine=confine, key=key))


def network_cache_key(
    entry: Mapping[str, Any], dataset: Any, base_dir: str | Path, *, confine: Confinement, key: str
) -> tuple[str, str, Confinement, str, int, int]:
    """The hashable arguments under which a table's network is cached per process.

    ``(entry as canonical JSON, base_dir resolved, confine, key, input channels, classes)``: the
    network's input has ``2 (n_frames - 1)`` channels (ON and OFF counts per frame interval).
    """
    return (
        json.dumps(dict(entry), sort_keys=True),
        str(Path(base_dir).resolve()),
        confine,
        key,
        2 * (int(dataset.n_frames) - 1),
        int(dataset.num_classes),
    )


def train_split_dataset(
    entry: Mapping[str, Any], base_dir: str | Path, *, confine: Confinement = True, key: str = "dataset"
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


def check_user_task(
    task: str, entry: Mapping[str, Any], base_dir: str | Path, *, confine: Confinement = True
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
        open_untrained_network(entry, ds, base_dir, confine=confine, key=key)
    except InputError as exc:
        where = "weights" if "weights file" in str(exc) or ".weights" in str(exc) else "network"
        problems.append((f"{key}.{where}", entry[where], str(exc)))
    return problems


def _train_split_problems(
    entry: Mapping[str, Any], ds: Any, base_dir: str | Path, confine: Confinement, key: str
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


def learned_kernel_path(task: str, entry: Mapping[str, Any], base_dir: str | Path, *, confine: Confinement) -> Path:
    """The kernel file a table's ``train`` table writes: ``train.out`` (default ``trained/<task>``) + ``.json``.

    Examples
    --------
    >>> from fsdvs_hw.design.user_data_section import UserTask
    >>> entry = UserTask(dataset={"format": "video_folder", "root": "ucf"}, train={}).model_dump()
    >>> learned_kernel_path("recognition", entry, "/d", confine=False).as_posix()
    '/d/trained/recognition.json'
    """
    from ..tasks.checkpoints import checkpoint_paths, checkpoint_stem

    out = (entry.get("train") or {}).get("out") or f"trained/{task}"
    stem = resolve_design_path(Path(base_dir), out, what=f"tasks.datasets.{task}.train.out", confine=confine)
    return checkpoint_paths(checkpoint_stem(stem))["kernel"]


def pending_kernel(
    tables: Mapping[str, Mapping[str, Any]], base_dir: str | Path, confine: Confinement, path: Path, pitch_m: float
) -> Any:
    """The stand-in for a ``[kernel] path`` that does not exist yet because training will write it, or None.

    The file is the one a table with a ``train`` table writes (its :func:`learned_kernel_path`),
    or any missing file when exactly one table trains (``learn`` / ``explore`` then write the
    learned kernel there too). The stand-in is the Dirac delta of ``train.kernel_size`` with
    ``provenance["pending_training"]`` = the task: nothing is scored with it (``explore`` trains,
    writes and re-reads the design first; :func:`fsdvs_hw.explore.user_data.settle_design_kernel`).

    Returns
    -------
    Kernel or None
        None when no table trains (a missing kernel file is then an error).

    Examples
    --------
    >>> pending_kernel({}, ".", True, Path("k.json"), 4.86e-6) is None
    True
    """
    from ..kernels import Kernel

    trained = {t: e for t, e in tables.items() if e.get("train") is not None}
    task = None
    for t, e in trained.items():
        try:
            if learned_kernel_path(t, e, base_dir, confine=confine) == Path(path):
                task = t
        except InputError:
            continue
    if task is None and len(trained) == 1:
        task = next(iter(trained))
    if task is None:
        return None
    import numpy as np

    size = int(trained[task]["train"]["kernel_size"])
    taps = np.zeros((size, size))
    taps[size // 2, size // 2] = 1.0
    return Kernel(
        taps,
        pitch_m=pitch_m,
        name=f"not trained yet (tasks.datasets.{task}.train writes {Path(path).name})",
        provenance={"pending_training": task, "path": str(path)},
    )
