"""Cross-check of the Prophesee / AEDAT4 readers and writers against faery, an independent
encoder and decoder (github.com/aestream/faery; used here only, never by the package).

Files faery writes (EVT 2.0, EVT 3.0 with vector words across the 24-bit clock wrap, DAT 1 and
2, AEDAT4; times stored from the first event with a ``% t0`` line, or absolute) read back
bit-identical; the project's EVT 2.0, EVT 3.0 and DAT files read identically in faery.
"""

from __future__ import annotations

import numpy as np
import pytest

from fsdvs_hw.sensor.eventfiles.eventfile import EventFile
from fsdvs_hw.sensor.eventfiles.prophesee import write_prophesee
from fsdvs_hw.sensor.eventfiles.recordings import read_recording

faery = pytest.importorskip("faery")


def _faery_events(n: int, width: int, height: int, span_us: int, seed: int = 0) -> np.ndarray:
    """Random events plus dense rows (one time, one row, consecutive columns: EVT 3.0 vector
    words) just before and after each 2**24 µs turn of the EVT 3.0 clock."""
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, dtype=faery.EVENTS_DTYPE)
    t = rng.integers(1000, span_us, n)
    x, y = rng.integers(0, width, n), rng.integers(0, height, n)
    k = 0
    for turn in range(1, span_us >> 24):
        for t_burst in (turn * 2**24 - 3, turn * 2**24 + 5):
            sl = slice(k, k + 60)
            t[sl], y[sl], x[sl] = t_burst, (k // 60) % height, 10 + np.arange(60)
            k += 60
    order = np.lexsort((x, y, t))
    ev["t"], ev["x"], ev["y"], ev["on"] = t[order], x[order], y[order], rng.random(n)[order] < 0.5
    return ev


def _same(ev: np.ndarray, back: EventFile, width: int, height: int) -> None:
    np.testing.assert_array_equal(back.t_us, ev["t"].astype(np.int64))
    np.testing.assert_array_equal(back.x, ev["x"])
    np.testing.assert_array_equal(back.y, ev["y"])
    np.testing.assert_array_equal(back.p, np.where(ev["on"], 1, -1))
    assert (back.width, back.height) == (width, height)


@pytest.mark.parametrize("zero_t0", [True, False])
@pytest.mark.parametrize(
    "version,suffix,width,height,span_us",
    [
        ("evt2", ".raw", 1280, 720, 60_000_000),
        ("evt3", ".raw", 1280, 720, 60_000_000),  # three 2**24 µs turns of the EVT 3.0 clock
        ("dat2", ".dat", 640, 480, 60_000_000),
        ("dat1", ".dat", 304, 240, 60_000_000),  # version 1: 9-bit x, 8-bit y
    ],
)
def test_faery_files_read_bit_identical(tmp_path, version, suffix, width, height, span_us, zero_t0):
    ev = _faery_events(4000, width, height, span_us)
    path = tmp_path / f"faery{suffix}"
    faery.events_stream_from_array(ev, dimensions=(width, height)).to_file(path, version=version, zero_t0=zero_t0)
    if zero_t0:  # faery stores times from the first event and writes the offset in a % t0 line
        assert b"t0 1" in path.read_bytes()[:300].lower()
    back = read_recording(path)
    _same(ev, back, width, height)
    assert back.metadata["t0_us"] == (int(ev["t"][0]) if zero_t0 else 0)
    if version == "evt3":  # the file exercises vector words (VECT_BASE_X and VECT_12 / VECT_8)
        data, pos = path.read_bytes(), 0
        while data[pos : pos + 1] == b"%":  # the header's lines
            pos = data.index(b"\n", pos) + 1
        typ = np.frombuffer(data[pos:], "<u2") >> 12
        assert (typ == 3).sum() >= 6 and np.isin(typ, (4, 5)).sum() >= 6 * 5  # a base, then 60 columns of vectors
        assert (back.t_us >= 3 * 2**24).any()


def test_faery_aedat4_reads_identically(tmp_path):
    pytest.importorskip("dv_processing")
    ev = _faery_events(3000, 346, 260, 5_000_000)
    path = tmp_path / "faery.aedat4"
    faery.events_stream_from_array(ev, dimensions=(346, 260)).to_file(path)
    _same(ev, read_recording(path), 346, 260)


@pytest.mark.parametrize("encoding,suffix", [("evt2", ".raw"), ("evt3", ".raw"), ("dat", ".dat")])
def test_project_files_read_identically_in_faery(tmp_path, encoding, suffix):
    rng = np.random.default_rng(3)
    n = 5000
    t = np.sort(rng.integers(0, 16_000_000, n))
    t[100:160] = t[100]  # ties
    ev = EventFile(
        t, rng.integers(0, 1280, n), rng.integers(0, 720, n), np.where(rng.random(n) < 0.5, 1, -1).astype(np.int8),
        1280, 720,
    )  # fmt: skip
    path = write_prophesee(tmp_path / f"ours{suffix}", ev, encoding=encoding)
    if suffix == ".raw":
        with faery.evt.Decoder(path, None, None) as d:
            assert d.dimensions == (1280, 720)
            got = np.concatenate([p["events"] for p in d if "events" in p])
        on = got["on"]
    else:
        with faery.dat.Decoder(path, None, None) as d:
            assert d.dimensions == (1280, 720) and d.event_type == "cd"
            got = np.concatenate(list(d))
        on = got["payload"] == 1
    np.testing.assert_array_equal(got["t"].astype(np.int64), ev.t_us)
    np.testing.assert_array_equal(got["x"], ev.x)
    np.testing.assert_array_equal(got["y"], ev.y)
    np.testing.assert_array_equal(on, ev.p > 0)


@pytest.mark.parametrize("version,suffix", [("evt2", ".raw"), ("evt3", ".raw"), ("dat2", ".dat"), ("dat1", ".dat")])
@pytest.mark.parametrize("chunk", [3, 7, 64])
def test_chunked_decoding_carries_the_stream_state(tmp_path, monkeypatch, version, suffix, chunk):
    """Decoded a few words at a time (time, row, vector base and clock turns handed from chunk to
    chunk, vectors cut in the middle), faery's files give the same events as in one piece."""
    from fsdvs_hw.sensor.eventfiles import prophesee

    width, height = (304, 240) if version == "dat1" else (640, 480)
    ev = _faery_events(600, width, height, 60_000_000, seed=2)
    path = tmp_path / f"faery{suffix}"
    faery.events_stream_from_array(ev, dimensions=(width, height)).to_file(path, version=version)
    monkeypatch.setattr(prophesee, "CHUNK_WORDS", chunk)
    _same(ev, read_recording(path), width, height)


def _random_stream(encoding: str, n: int, seed: int) -> np.ndarray:
    """A random, well-formed EVT 2.0 / 3.0 word stream with CD and EXT_TRIGGER words interleaved."""
    rng = np.random.default_rng(seed)
    if encoding == "evt2":
        words = [0x80000000]
        for th in range(1, n):
            words.append(0x80000000 | th)
            for low in np.sort(rng.integers(0, 64, rng.integers(0, 4))).tolist():
                if rng.random() < 0.3:
                    words.append(0xA0000000 | (low << 22) | (int(rng.integers(0, 32)) << 8) | int(rng.integers(0, 2)))
                else:
                    cd = (int(rng.integers(0, 2)) << 28) | (low << 22) | (int(rng.integers(0, 64)) << 11)
                    words.append(cd | int(rng.integers(0, 48)))
        return np.array(words, dtype="<u4")
    words = []
    for th in range(n):
        words.append(0x8000 | th)
        for tl in np.sort(rng.integers(0, 4096, rng.integers(1, 4))):
            words += [0x6000 | int(tl), 0x0000 | int(rng.integers(0, 48))]
            if rng.random() < 0.3:
                words.append(0xA000 | (int(rng.integers(0, 16)) << 8) | int(rng.integers(0, 2)))
            else:
                words.append(0x2000 | (int(rng.integers(0, 2)) << 11) | int(rng.integers(0, 64)))
    return np.array(words, dtype="<u2")


@pytest.mark.parametrize("encoding", ["evt2", "evt3"])
def test_trigger_events_match_faerys_decoder(tmp_path, encoding):
    """EXT_TRIGGER words between CD words: the same CD events and the same triggers (time,
    channel, edge) as faery's decoder returns."""
    words = _random_stream(encoding, 300, seed=7)
    path = tmp_path / "trig.raw"
    head = f"% evt {encoding[-1]}.0\n% format {encoding.upper()};width=64;height=48\n% end\n"
    path.write_bytes(head.encode() + words.tobytes())
    ours = read_recording(path)
    with faery.evt.Decoder(path, None, None) as d:
        packets = list(d)
    ev = np.concatenate([p["events"] for p in packets if "events" in p])
    tr = np.concatenate([p["triggers"] for p in packets if "triggers" in p])
    _same(ev, ours, 64, 48)
    assert tr.size > 20
    np.testing.assert_array_equal(ours.triggers["t_us"], tr["t"].astype(np.int64))
    np.testing.assert_array_equal(ours.triggers["id"], tr["source"])
    np.testing.assert_array_equal(ours.triggers["value"], tr["rising"].astype(np.int8))
