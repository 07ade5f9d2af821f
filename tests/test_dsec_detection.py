"""The DSEC-Detection reader on a tiny generated sequence in the dataset's layout.

``seq/images/timestamps.txt`` (µs), ``seq/images/left/rectified/*.png`` and
``seq/object_detections/left/tracks.npy`` (the published structured dtype: t, x, y, w, h,
class_id, class_confidence, track_id); clips end at labelled images, timestamps come from the
file, boxes past the edge are clipped, and a design file reads the layout as ``dsec_detection``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fsdvs_hw.errors import InputError
from fsdvs_hw.scenes.datasets import DsecDetectionDataset

TRACKS_DTYPE = np.dtype(
    [
        ("t", "<u8"),
        ("x", "<f4"),
        ("y", "<f4"),
        ("w", "<f4"),
        ("h", "<f4"),
        ("class_id", "u1"),
        ("class_confidence", "<f4"),
        ("track_id", "<u4"),
    ]
)
T0 = 58_000_000  # µs, DSEC timestamps are absolute


def _sequence(root: Path, class_id: int = 2) -> Path:
    seq = root / "zurich_city_00_a"
    img = seq / "images" / "left" / "rectified"
    img.mkdir(parents=True)
    stamps = T0 + 50_000 * np.arange(6)
    for k in range(6):
        frame = np.full((24, 32, 3), 40 + 30 * k, np.uint8)
        Image.fromarray(frame).save(img / f"{k:06d}.png")
    np.savetxt(seq / "images" / "timestamps.txt", stamps, fmt="%d")
    (seq / "object_detections" / "left").mkdir(parents=True)
    tracks = np.array(
        [
            (stamps[3], 4.0, 5.0, 10.0, 6.0, class_id, 0.9, 1),
            (stamps[5], 26.0, -3.0, 10.0, 8.0, 0, 0.8, 2),  # past the right and top edges
            (stamps[5], 2.0, 2.0, 4.0, 4.0, 5, 0.7, 3),
            (T0 - 1, 0.0, 0.0, 4.0, 4.0, 1, 0.5, 4),
        ],  # at no image: not used
        dtype=TRACKS_DTYPE,
    )
    np.save(seq / "object_detections" / "left" / "tracks.npy", tracks)
    return seq


def test_clips_end_at_labelled_images_with_file_timestamps_and_clipped_boxes(tmp_path):
    _sequence(tmp_path)
    ds = DsecDetectionDataset(tmp_path, n_frames=3)
    assert len(ds) == 2 and ds.num_classes == 8 and ds.class_names[2] == "car"
    c0, c1 = ds[0], ds[1]
    np.testing.assert_allclose(c0.timestamps_s, [0.0, 0.05, 0.1])
    assert c0.frames.shape == (3, 24, 32)
    np.testing.assert_allclose(c0.targets["boxes"][0], [4, 5, 14, 11])
    assert c0.targets["labels"].tolist() == [2, -1]
    np.testing.assert_allclose(c1.targets["boxes"], [[26, 0, 32, 5], [2, 2, 6, 6]])
    assert c1.targets["labels"].tolist() == [0, 5]
    half = DsecDetectionDataset(tmp_path / "zurich_city_00_a", n_frames=3, size=(12, 16))
    np.testing.assert_allclose(half[1].targets["boxes"][0], [13, 0, 16, 2.5])
    assert len(DsecDetectionDataset(tmp_path, n_frames=5)) == 1  # image 3 has only 3 images before it


def test_bad_layouts_name_the_file_and_field(tmp_path):
    seq = _sequence(tmp_path / "a", class_id=9)
    with pytest.raises(InputError, match=r"tracks.npy'?: field 'class_id' 9 is beyond the 8 classes"):
        DsecDetectionDataset(tmp_path / "a")
    np.save(seq / "object_detections" / "left" / "tracks.npy", np.zeros(3))
    with pytest.raises(InputError, match=r"fields \['t', 'x', 'y', 'w', 'h', 'class_id'\] missing"):
        DsecDetectionDataset(seq)
    (seq / "images" / "timestamps.txt").write_text("1\n2\n")
    with pytest.raises(InputError, match=r"has 2 timestamps for 6 images"):
        DsecDetectionDataset(seq)
    with pytest.raises(InputError, match=r"holds no sequence"):
        DsecDetectionDataset(tmp_path / "a" / "zurich_city_00_a" / "images")


def test_design_reads_dsec_detection_and_scores_it(tmp_path):
    pytest.importorskip("torch")
    from conftest import cheap_design
    from test_user_datasets import PLUGINS

    from fsdvs_hw.design import load_design
    from fsdvs_hw.explore.user_data import dataset_evidence

    _sequence(tmp_path / "dsec" / "test")
    shutil.copy(PLUGINS / "toy_network.py", tmp_path / "toy_network.py")
    path = tmp_path / "d.toml"
    path.write_text(
        cheap_design("dsec") + '[tasks.datasets.detection]\nnetwork = "toy_network:make"\n'
        'network_options = { task = "detection" }\n'
        'dataset = { format = "dsec_detection", root = "dsec", split = "test", n_frames = 3 }\n'
    )
    entry = load_design(path).data["tasks"]["datasets"]["detection"]
    ev, _ = dataset_evidence(None, "detection", entry, tmp_path)
    assert ev.n_clips == 2 and ev.metric_name == "map" and 0.0 <= ev.value <= 1.0


@pytest.mark.parametrize("claimed", [10**4, 10**10])
def test_a_tracks_header_claiming_more_than_the_file_holds_is_refused_before_allocating(tmp_path, claimed):
    """A ``tracks.npy`` whose header claims ``claimed`` records (one record of data present, up to
    400 GB claimed) is refused with the file named, without allocating what the header claims
    (the header is read memory-mapped first)."""
    seq = _sequence(tmp_path / "a")
    path = seq / "object_detections" / "left" / "tracks.npy"
    with open(path, "wb") as f:
        header = {"descr": np.lib.format.dtype_to_descr(TRACKS_DTYPE), "fortran_order": False, "shape": (claimed,)}
        np.lib.format.write_array_header_2_0(f, header)
        f.write(np.zeros(1, TRACKS_DTYPE).tobytes())
    with pytest.raises(InputError, match=r"tracks\.npy"):
        DsecDetectionDataset(seq)
