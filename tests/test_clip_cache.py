"""The bounded disk cache of decoded clips (fsdvs_hw.scenes.clip_cache) under the user datasets.

Decoder calls are counted by wrapping each reader's ``_decode``; the datasets are the tiny
layouts of test_user_datasets (6 frames + label PNGs, 32 x 32 px; one H.264 video of real
bigbuckbunny frames).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("torch")
imageio = pytest.importorskip("imageio")
from test_user_datasets import FPS, _bbb_frames, _masks, _write_masks

from fsdvs_hw.design.user_data_inputs import open_dataset
from fsdvs_hw.design.user_data_section import MaskFramesSource
from fsdvs_hw.errors import InputError
from fsdvs_hw.scenes.clip_cache import ENTRY_SUFFIX, ClipDiskCache
from fsdvs_hw.scenes.datasets import MaskFramesDataset, VideoFolderDataset


@pytest.fixture()
def seg(tmp_path) -> tuple[Path, Path]:
    return _write_masks(tmp_path / "seg", *_masks())


@pytest.fixture()
def decodes(monkeypatch) -> list[int]:
    """Clip indices decoded (every reader's ``_decode`` call), in order."""
    calls: list[int] = []
    for cls in (MaskFramesDataset, VideoFolderDataset):
        original = cls._decode

        def counted(self, i, _original=original):
            calls.append(i)
            return _original(self, i)

        monkeypatch.setattr(cls, "_decode", counted)
    return calls


def _seg(seg: tuple[Path, Path], cache: ClipDiskCache | None, **kw) -> MaskFramesDataset:
    return MaskFramesDataset(*seg, num_classes=3, n_frames=3, clip_stride=1, size=(16, 16), disk_cache=cache, **kw)


def _same(a, b) -> bool:
    return (
        np.array_equal(a.frames, b.frames)
        and np.array_equal(a.timestamps_s, b.timestamps_s)
        and a.frames.dtype == b.frames.dtype
        and all(np.array_equal(a.targets[k], b.targets[k]) for k in a.targets)
    )


def test_second_pass_reads_the_cache_and_gives_the_decoded_arrays(seg, tmp_path, decodes):
    plain = [c for c in _seg(seg, None)]
    n = len(plain)
    assert n == 4 and decodes == [0, 1, 2, 3]
    decodes.clear()
    first = list(_seg(seg, ClipDiskCache(tmp_path / "cache", max_mb=10)))
    assert decodes == [0, 1, 2, 3]
    decodes.clear()
    cache = ClipDiskCache(tmp_path / "cache", max_mb=10)  # a new process: only the folder is shared
    second = list(_seg(seg, cache))
    assert decodes == [] and (cache.hits, cache.misses, cache.rejected) == (n, 0, 0)
    for p, f, s in zip(plain, first, second):
        assert _same(p, f) and _same(p, s)
    assert s.targets["mask"].dtype == np.int64 and (s.targets["mask"] == 255).any()
    decodes.clear()
    list(_seg(seg, cache, fps=50.0))  # timestamps are not decoded: another frame rate reuses the entries
    assert decodes == []
    list(_seg(seg, cache, transfer="ITU-R BT.709"))  # another decode option: another key
    assert decodes == [0, 1, 2, 3]


def test_a_changed_source_file_invalidates_only_its_clips(seg, tmp_path, decodes):
    cache = ClipDiskCache(tmp_path / "cache", max_mb=10)
    list(_seg(seg, cache))
    frame = seg[0] / "s_005.png"  # the last frame: only clip 3 (frames 3-5) reads it
    Image.fromarray(np.full((32, 32, 3), 255, np.uint8)).save(frame)
    st = frame.stat()
    os.utime(frame, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    decodes.clear()
    clips = list(_seg(seg, cache))
    assert decodes == [3]
    assert clips[3].frames[-1] == pytest.approx(1.0)  # the new white frame, not the cached one


def test_the_cap_holds_and_the_least_recently_used_entry_goes_first(seg, tmp_path, decodes):
    probe = ClipDiskCache(tmp_path / "probe", max_mb=10)
    ds = _seg(seg, probe)
    ds[0]
    one = probe.usage_bytes()
    cache = ClipDiskCache(tmp_path / "cache", max_mb=2.5 * one / 1e6)  # room for two entries
    ds = _seg(seg, cache)
    ds[0], ds[1]
    os.utime(cache.path(cache.key(ds.clip_files(0), ds.decode_options())), ns=(0, 0))  # clip 0 used longest ago ...
    ds[1]  # ... and clip 1 just now
    ds[2]
    assert cache.usage_bytes() <= cache.max_bytes and cache.evicted == 1
    kept = {i for i in range(4) if cache.path(cache.key(ds.clip_files(i), ds.decode_options())).is_file()}
    assert kept == {1, 2}
    (cache.folder / "notes.txt").write_text("not an entry")
    list(ds)
    assert cache.usage_bytes() <= cache.max_bytes and (cache.folder / "notes.txt").is_file()
    tiny = ClipDiskCache(tmp_path / "tiny", max_mb=0.5 * one / 1e6)  # an entry over the cap is not written
    _seg(seg, tiny)[0]
    assert tiny.usage_bytes() == 0


@pytest.mark.parametrize("damage", ["garble", "truncate", "other_key"])
def test_a_corrupt_entry_is_deleted_and_decoded_again(seg, tmp_path, decodes, damage):
    cache = ClipDiskCache(tmp_path / "cache", max_mb=10)
    ds = _seg(seg, cache)
    want = ds[1]
    path = cache.path(cache.key(ds.clip_files(1), ds.decode_options()))
    blob = path.read_bytes()
    if damage == "garble":
        blob = blob[:-200] + bytes(b ^ 0xFF for b in blob[-200:-100]) + blob[-100:]
    elif damage == "truncate":
        blob = blob[: len(blob) // 2]
    else:  # a well-formed entry of another clip copied over this one
        ds[0]
        blob = cache.path(cache.key(ds.clip_files(0), ds.decode_options())).read_bytes()
    path.write_bytes(blob)
    decodes.clear()
    again = _seg(seg, cache)[1]
    assert decodes == [1] and cache.rejected == 1 and _same(want, again)
    assert cache.load(cache.key(ds.clip_files(1), ds.decode_options())) is not None  # rewritten, whole


def test_video_clips_from_the_cache_equal_the_decoded_ones(tmp_path, decodes):
    root = tmp_path / "ucf"
    (root / "Jump").mkdir(parents=True)
    with imageio.get_writer(
        str(root / "Jump" / "v_Jump_g01.mp4"),
        fps=FPS,
        codec="libx264",
        quality=9,
        macro_block_size=1,
        ffmpeg_log_level="error",
    ) as w:
        for f in _bbb_frames(start=0, n=6):
            w.append_data(f)
    cache = ClipDiskCache(tmp_path / "cache", max_mb=10)
    a = VideoFolderDataset(root, n_frames=4, stride=1, disk_cache=cache)[0]
    b = VideoFolderDataset(root, n_frames=4, stride=1, disk_cache=cache)[0]
    c = VideoFolderDataset(root, n_frames=3, stride=2, disk_cache=cache)[0]
    assert decodes == [0, 0] and _same(a, b) and b.metadata["fps"] == pytest.approx(FPS)
    assert c.timestamps_s == pytest.approx([0.0, 2 / FPS, 4 / FPS]) and np.array_equal(c.frames[1], a.frames[2])


def test_design_key_opens_a_confined_bounded_cache(seg, tmp_path):
    src = MaskFramesSource(
        root="seg", frames="img", masks="lbl", num_classes=3, n_frames=3, cache={"dir": "clip_cache", "max_mb": 64.0}
    ).model_dump()
    ds = open_dataset(src, tmp_path)
    assert ds.disk_cache.folder == (tmp_path / "clip_cache").resolve() and ds.disk_cache.max_bytes == 64_000_000
    ds[0]
    assert len(list((tmp_path / "clip_cache").glob("*" + ENTRY_SUFFIX))) == 1
    with pytest.raises(InputError, match=r"cache\.dir.*outside the design's folder"):
        open_dataset({**src, "cache": {"dir": "../elsewhere", "max_mb": 64.0}}, tmp_path, key="d")
    with pytest.raises(ValueError, match="max_mb"):
        MaskFramesSource(root="seg", num_classes=3, cache={"dir": "c", "max_mb": 0.0})
    with pytest.raises(InputError, match="max_mb"):
        ClipDiskCache(tmp_path / "c", max_mb=-1)


def test_the_cache_settings_change_no_explored_point_key(seg, tmp_path):
    from conftest import cheap_design

    from fsdvs_hw.design import load_design
    from fsdvs_hw.explore.sweep import expand_points

    source = (
        'format = "mask_frames", root = "seg", frames = "img", masks = "lbl", num_classes = 3, n_frames = 3, fps = 25.0'
    )
    keys = []
    for name, extra in (("plain", ""), ("cached", ', cache = { dir = "cc", max_mb = 50.0 }')):
        path = tmp_path / f"{name}.toml"
        path.write_text(cheap_design(name) + f"[tasks.datasets.segmentation]\ndataset = {{ {source}{extra} }}\n")
        design = load_design(path)
        keys.append(sorted(p.key for p in expand_points(design)))
    assert keys[0] == keys[1] and len(keys[0]) == 2
    assert design.data["tasks"]["datasets"]["segmentation"]["dataset"]["cache"]["max_mb"] == 50.0
