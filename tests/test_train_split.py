"""``[tasks.datasets.<task>] train.split``: train on the dataset's own training split, score its test split.

UCF101 layout with ``trainlist01.txt`` ("<class>/<video> <label>") and ``testlist01.txt``
("<class>/<video>"): the video files are only listed, never decoded, so they may be empty. The
frame formats use ``root/train`` and ``root/val`` subfolders (frames + label PNGs). The training
itself is replaced by a recorder: what is checked is WHICH clips would be trained on.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
from test_user_datasets import _masks, _write_masks

from fsdvs_hw.design.user_data_inputs import check_user_task, train_split_dataset
from fsdvs_hw.design.user_data_section import UserTask
from fsdvs_hw.errors import InputError
from fsdvs_hw.explore.user_data import train_user_task

CLASSES = ("ApplyEyeMakeup", "Archery")


@pytest.fixture()
def ucf(tmp_path) -> Path:
    root = tmp_path / "ucf"
    for c in CLASSES:
        (root / c).mkdir(parents=True)
        for g in range(1, 4):
            (root / c / f"v_{c}_g0{g}_c01.avi").write_bytes(b"")
    train = [f"{c}/v_{c}_g0{g}_c01.avi {k + 1}" for k, c in enumerate(CLASSES) for g in (1, 2)]
    (root / "trainlist01.txt").write_text("\n".join(train) + "\n")
    (root / "testlist01.txt").write_text("".join(f"{c}/v_{c}_g03_c01.avi\n" for c in CLASSES))
    (root / "leaky.txt").write_text(
        f"{CLASSES[0]}/v_{CLASSES[0]}_g01_c01.avi 1\n{CLASSES[1]}/v_{CLASSES[1]}_g03_c01.avi 2\n"
    )
    return root


def _entry(dataset: dict, train: dict, n_clips: int = 0) -> dict:
    return UserTask(dataset=dataset, n_clips=n_clips, train=train).model_dump()


def _names(ds, indices) -> set[str]:
    return {p.name for i in indices for p in ds.clip_files(int(i)) if p.suffix != ".json"}


@pytest.fixture()
def recorded(monkeypatch) -> list[tuple]:
    """``train_on_dataset`` replaced: each call's (dataset, training indices) is recorded."""
    import fsdvs_hw.tasks.dataset_training as training

    calls: list[tuple] = []
    monkeypatch.setattr(
        training,
        "train_on_dataset",
        lambda ds, task, net, *, train_indices, **kw: calls.append((ds, np.asarray(train_indices))),
    )
    return calls


def test_ucf101_trainlist_trains_and_testlist_scores_disjoint_by_file(ucf, recorded):
    from fsdvs_hw.design.user_data_inputs import open_dataset

    entry = _entry(
        {"format": "video_folder", "root": "ucf", "split": "testlist01.txt", "n_frames": 4},
        {"split": "trainlist01.txt", "n_train": 0},
    )
    assert check_user_task("recognition", entry, ucf.parent) == []
    train = train_split_dataset(entry, ucf.parent, key="k")
    assert len(train) == 4 and [lab for _, lab in train.items] == [0, 0, 1, 1]  # the label column is ignored
    train_user_task("recognition", entry, ucf.parent)  # n_clips = 0: every test clip scored, allowed with a split
    ((ds, idx),) = recorded
    test = open_dataset(entry["dataset"], ucf.parent)
    assert _names(ds, idx) == {f"v_{c}_g0{g}_c01.avi" for c in CLASSES for g in (1, 2)}
    assert not _names(ds, idx) & _names(test, range(len(test)))
    n2 = _entry(entry["dataset"], {"split": "trainlist01.txt", "n_train": 2, "seed": 3})
    train_user_task("recognition", n2, ucf.parent)
    assert len(recorded[1][1]) == 2 and set(recorded[1][1]) <= set(range(4))


def test_a_training_split_sharing_a_scored_file_is_refused_naming_it(ucf, recorded):
    entry = _entry(
        {"format": "video_folder", "root": "ucf", "split": "testlist01.txt", "n_frames": 4}, {"split": "leaky.txt"}
    )
    ((key, value, msg),) = check_user_task("recognition", entry, ucf.parent)
    assert key == "tasks.datasets.recognition.train.split" and value == "leaky.txt"
    assert "v_Archery_g03_c01.avi" in msg and "scored" in msg
    with pytest.raises(InputError, match=r"v_Archery_g03_c01\.avi"):
        train_user_task("recognition", entry, ucf.parent)
    assert recorded == []
    whole = _entry({"format": "video_folder", "root": "ucf", "n_frames": 4}, {"split": "trainlist01.txt"})
    assert "train.split" in check_user_task("recognition", whole, ucf.parent)[0][0]  # every video scored
    missing = _entry(entry["dataset"], {"split": "trainlist09.txt"})
    ((key, _, msg),) = check_user_task("recognition", missing, ucf.parent)
    assert key.endswith("train.split") and "trainlist09.txt" in msg and "does not exist" in msg
    too_many = _entry(entry["dataset"], {"split": "trainlist01.txt", "n_train": 5})
    ((key, value, msg),) = check_user_task("recognition", too_many, ucf.parent)
    assert key.endswith("train.n_train") and value == 5 and "has 4 clips" in msg


def test_frame_formats_train_on_a_subfolder(tmp_path, recorded):
    for split, n in (("train", 8), ("val", 6)):
        _write_masks(tmp_path / "seg" / split, *_masks(n))
    entry = _entry(
        {
            "format": "mask_frames",
            "root": "seg",
            "split": "val",
            "frames": "img",
            "masks": "lbl",
            "num_classes": 3,
            "n_frames": 3,
            "clip_stride": 1,
        },
        {"split": "train", "n_train": 3, "seed": 1},
    )
    assert check_user_task("segmentation", entry, tmp_path) == []
    train_user_task("segmentation", entry, tmp_path)
    ((ds, idx),) = recorded
    assert ds.frames_dir == (tmp_path / "seg" / "train" / "img").resolve() and len(idx) == 3
    same = _entry({**entry["dataset"], "split": "train"}, {"split": "train"})
    ((key, _, msg),) = check_user_task("segmentation", same, tmp_path)
    assert key.endswith("train.split") and "also in a scored clip" in msg
    default = _entry(entry["dataset"], {}, n_clips=2)  # no split: the seeded draw from the clips not scored
    train_user_task("segmentation", default, tmp_path)
    ds2, idx2 = recorded[1]
    assert ds2.frames_dir.name == "img" and ds2.frames_dir.parent.name == "val" and len(idx2) == 2
