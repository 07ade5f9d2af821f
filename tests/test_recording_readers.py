"""Strict camera-file readers (issue 41): header lines, versions, event types and malformed files.

Every malformed file is built here, byte by byte, and must be refused with one
:class:`~fsdvs_hw.errors.InputError` naming the file and the field (or byte offset), before any
large allocation.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor.eventfiles.eventfile import EventFile, read_events
from fsdvs_hw.sensor.eventfiles.prophesee import decode_evt2, decode_evt3_all, read_prophesee, write_prophesee
from fsdvs_hw.sensor.eventfiles.recordings import read_recording


def _events(n: int = 500, width: int = 64, height: int = 48, span_us: int = 100_000, seed: int = 0) -> EventFile:
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, span_us, n))
    return EventFile(
        t,
        rng.integers(0, width, n),
        rng.integers(0, height, n),
        np.where(rng.random(n) < 0.5, 1, -1).astype(np.int8),
        width,
        height,
    )


def _raw(path, header: str, words, dtype: str):
    path.write_bytes(header.encode() + np.asarray(words, dtype=dtype).tobytes())
    return path


def _dat(path, header: str, records, etype: int = 0x0C):
    path.write_bytes(header.encode() + bytes([etype, 8]) + np.asarray(records, dtype="<u4").tobytes())
    return path


_EVT3_HEAD = "% evt 3.0\n% format EVT3;width=64;height=48\n% end\n"
_EVT2_HEAD = "% evt 2.0\n% format EVT2;width=64;height=48\n% end\n"


# ---------------------------------------------------------------------------- header lines
@pytest.mark.parametrize("encoding,suffix", [("evt2", ".raw"), ("evt3", ".raw"), ("dat", ".dat")])
def test_t0_header_line_is_applied(tmp_path, encoding, suffix):
    """``% t0 T``: stored times + T (the encoder subtracted T); metadata says how much."""
    ev = _events()
    path = write_prophesee(tmp_path / f"rec{suffix}", ev, encoding=encoding)
    data = path.read_bytes()
    line = b"% T0 123456\n" if encoding == "dat" else b"% t0 123456\n"
    path.write_bytes(line + data)
    back = read_recording(path)
    np.testing.assert_array_equal(back.t_us, ev.t_us + 123456)
    assert back.metadata["t0_us"] == 123456
    for bad in (b"% t0 soon\n", b"% t0 -5\n", b"% t0 99999999999999999999\n"):
        path.write_bytes(bad + data)
        with pytest.raises(InputError, match=rf"rec{suffix}.*header t0"):
            read_recording(path)


def test_evt21_refused_as_unsupported(tmp_path):
    for head in ("% evt 2.1\n% end\n", "% format EVT21;width=640;height=480\n% end\n"):
        path = _raw(tmp_path / "r21.raw", head, [0, 0], "<u8")
        with pytest.raises(InputError, match=r"r21\.raw.*header format.*EVT 2\.1 is not supported"):
            read_recording(path)


def test_dat_versions(tmp_path):
    """Version 1 (9-bit x, 8-bit y, polarity bit 17) and 2 read; another version refused, named."""
    rec1 = [[5, 3 | (7 << 9) | (1 << 17)], [9, 300 | (200 << 9)]]
    back = read_recording(_dat(tmp_path / "v1.dat", "% Version 1\n% Width 304\n% Height 240\n", rec1))
    assert back.t_us.tolist() == [5, 9] and back.x.tolist() == [3, 300] and back.y.tolist() == [7, 200]
    assert back.p.tolist() == [1, -1] and back.metadata["format"] == "dat1" and (back.width, back.height) == (304, 240)
    rec2 = [[5, 3 | (7 << 14) | (1 << 28)]]
    back = read_recording(_dat(tmp_path / "v2.dat", "% Version 2\n% Width 640\n% Height 480\n", rec2))
    assert (back.x.tolist(), back.y.tolist(), back.p.tolist()) == ([3], [7], [1])
    with pytest.raises(InputError, match=r"v3\.dat.*header Version.*unsupported DAT version '3'"):
        read_recording(_dat(tmp_path / "v3.dat", "% Version 3\n% Width 640\n% Height 480\n", rec2))
    with pytest.raises(InputError, match=r"v1big\.dat.*header width.*outside \[1, 512\]"):
        read_recording(_dat(tmp_path / "v1big.dat", "% Version 1\n% Width 640\n% Height 240\n", rec1))


def test_dat_unknown_event_type_refused(tmp_path):
    with pytest.raises(InputError, match=r"t\.dat.*event type.*0x2A.*unsupported"):
        read_recording(_dat(tmp_path / "t.dat", "% Version 2\n", [[1, 1]], etype=0x2A))


# ---------------------------------------------------------------------------- trigger events
def test_triggers_returned_beside_cd_events(tmp_path):
    # EVT 2.0: TIME_HIGH 1 (64 µs), CD ON at +5, trigger id 3 rising at +7, CD OFF at +9
    w2 = [0x80000001, 0x10000000 | (5 << 22) | (2 << 11) | 4, 0xA0000000 | (7 << 22) | (3 << 8) | 1, 9 << 22]
    back = read_recording(_raw(tmp_path / "t2.raw", _EVT2_HEAD, w2, "<u4"))
    assert back.t_us.tolist() == [69, 73] and back.p.tolist() == [1, -1]
    assert back.triggers.tolist() == [(71, 3, 1)]
    # EVT 3.0: TIME_HIGH 0, TIME_LOW 10, y 1, x 2 ON, trigger id 5 falling, TIME_LOW 20, trigger id 5 rising
    w3 = [0x8000, 0x600A, 0x0001, 0x2802, 0xA500, 0x6014, 0xA501]
    back = read_recording(_raw(tmp_path / "t3.raw", _EVT3_HEAD, w3, "<u2"))
    assert back.t_us.tolist() == [10] and back.triggers.tolist() == [(10, 5, 0), (20, 5, 1)]
    # DAT trigger file (event type 0x0E): channel where x is, edge where the polarity is
    back = read_recording(_dat(tmp_path / "tr.dat", "% Version 2\n% T0 100\n", [[10, 1 << 28], [20, 3]], etype=0x0E))
    assert len(back) == 0 and back.triggers.tolist() == [(110, 0, 1), (120, 3, 0)]
    assert read_recording(write_prophesee(tmp_path / "none.raw", _events())).triggers.size == 0


# ---------------------------------------------------------------------------- geometry
@pytest.mark.parametrize(
    "name,head,match",
    [
        (
            "zero.raw",
            "% evt 3.0\n% format EVT3;width=0;height=0\n% end\n",
            r"header width.*0 pixels outside \[1, 2048\]",
        ),
        (
            "huge.raw",
            "% evt 3.0\n% format EVT3;width=2000000000;height=2000000000\n% end\n",
            r"header width.*2000000000",
        ),
        ("geo.raw", "% evt 3.0\n% geometry 64x-1\n% end\n", r"header height.*-1 pixels outside"),
        ("text.raw", "% evt 3.0\n% geometry axb\n% end\n", r"header width.*'a' is not an integer"),
    ],
)
def test_declared_geometry_checked(tmp_path, name, head, match):
    with pytest.raises(InputError, match=name.replace(".", r"\.") + ".*" + match):
        read_recording(_raw(tmp_path / name, head, [0x8000, 0x6001, 0x0001, 0x2001], "<u2"))


def test_dat_huge_geometry_and_outside_events_refused(tmp_path):
    with pytest.raises(InputError, match=r"big\.dat.*header width.*1000000000 pixels outside \[1, 16384\]"):
        read_recording(_dat(tmp_path / "big.dat", "% Width 1000000000\n% Height 1000000000\n", [[1, 1]]))
    with pytest.raises(InputError, match=r"out\.raw.*x: value 100 outside \[0, 64\)"):
        read_recording(_raw(tmp_path / "out.raw", _EVT3_HEAD, [0x8000, 0x6001, 0x0001, 0x2064], "<u2"))
    with pytest.raises(InputError, match=r"given width.*0 pixels"):
        read_prophesee(_dat(tmp_path / "nogeo.dat", "% Version 2\n", [[1, 1]]), width=0, height=5)


# ---------------------------------------------------------------------------- time: wraps and going backwards
def test_dat_time_going_backwards_is_not_a_wrap(tmp_path):
    head = "% Version 2\n% Width 64\n% Height 48\n"
    with pytest.raises(InputError, match=r"back\.dat.*time goes back from 30 to 5 µs at byte offset \d+"):
        read_recording(_dat(tmp_path / "back.dat", head, [[30, 1], [5, 2]]))
    back = read_recording(_dat(tmp_path / "wrap.dat", head, [[2**32 - 10, 1], [5, 2]]))
    assert back.t_us.tolist() == [2**32 - 10, 2**32 + 5]


def test_evt_time_high_backwards_and_wrap(tmp_path):
    with pytest.raises(InputError, match=r"EVT_TIME_HIGH.*time goes back from 20480 to 12288 µs"):
        read_recording(_raw(tmp_path / "b3.raw", _EVT3_HEAD, [0x8005, 0x0001, 0x2001, 0x8003, 0x2002], "<u2"))
    with pytest.raises(InputError, match=r"EVT_TIME_HIGH.*time goes back from 320 to 192 µs"):
        read_recording(_raw(tmp_path / "b2.raw", _EVT2_HEAD, [0x80000005, 0x10000001, 0x80000003, 0x10000002], "<u4"))
    ev = decode_evt2(np.array([0x8FFFFFFF, 0x10000001, 0x80000000, 0x10000002], dtype="<u4")).events
    assert ev["t"].tolist() == [(2**28 - 1) << 6, 2**34]


# ---------------------------------------------------------------------------- malformed EVT 3.0 streams
@pytest.mark.parametrize(
    "words,text,offset",
    [
        ([0x8000, 0x0001, 0x4FFF], "VECT_12 / VECT_8 word at byte offset {} before any VECT_BASE_X", 4),
        ([0x0001, 0x2001], "event or trigger word at byte offset {} before any EVT_TIME_HIGH", 2),
        ([0x8000, 0x2001], "event word at byte offset {} before any EVT_ADDR_Y", 2),
        ([0x8000, 0x0001, 0x9001], r"reserved EVT 3\.0 word type 0x9 at byte offset {}", 4),
    ],
)
def test_malformed_evt3_refused(tmp_path, words, text, offset):
    """Words that need a state never sent (a vector without a base, an event without a time or
    a row) and reserved word types: refused naming the byte offset in the file."""
    path = _raw(tmp_path / "m.raw", _EVT3_HEAD, words, "<u2")
    with pytest.raises(InputError, match=r"m\.raw.*\(body\): " + text.format(len(_EVT3_HEAD) + offset)):
        read_recording(path)
    with pytest.raises(InputError, match=text.format(offset)):  # the decoder alone counts from its first word
        decode_evt3_all(np.array(words, dtype="<u2"))


def test_evt2_reserved_type_and_early_event_refused(tmp_path):
    with pytest.raises(InputError, match=r"r\.raw.*reserved EVT 2\.0 word type 0x3"):
        read_recording(_raw(tmp_path / "r.raw", _EVT2_HEAD, [0x80000000, 0x30000000], "<u4"))
    with pytest.raises(InputError, match=r"e\.raw.*before any EVT_TIME_HIGH"):
        read_recording(_raw(tmp_path / "e.raw", _EVT2_HEAD, [0x10000001], "<u4"))


# ---------------------------------------------------------------------------- DSEC
def test_dsec_offset_and_declared_sizes_capped(tmp_path):
    import h5py

    from fsdvs_hw.sensor.eventfiles.dsec import write_dsec

    ev = _events(width=640, height=480)
    path = write_dsec(tmp_path / "events.h5", ev)
    with h5py.File(path, "r+") as f:
        del f["t_offset"]
        f.create_dataset("t_offset", data=np.int64(2**63 - 10))
    with pytest.raises(InputError, match=r"events\.h5.*t_offset.*outside \[0, 2\*\*53\)"):
        read_recording(path)
    path = write_dsec(tmp_path / "idx.h5", ev)
    with h5py.File(path, "r+") as f:  # 2e9 declared entries, none stored: a few KB on disk
        del f["ms_to_idx"]
        f.create_dataset("ms_to_idx", shape=(2_000_000_000,), dtype="<u8", chunks=(1 << 16,), compression="gzip")
    assert os.path.getsize(path) < 100_000
    with pytest.raises(InputError, match=r"idx\.h5.*ms_to_idx.*declares shape \(2000000000,\)"):
        read_recording(path)
    path = tmp_path / "declared.h5"
    with h5py.File(path, "w") as f:  # 20 M declared events, no chunk stored
        g = f.create_group("events")
        for c, dt in (("x", "<u2"), ("y", "<u2"), ("t", "<u4"), ("p", "u1")):
            g.create_dataset(c, shape=(20_000_000,), dtype=dt, chunks=(1 << 16,), compression="gzip")
    with pytest.raises(InputError, match=r"declared\.h5.*events/x.*stores only 0 of its \d+ chunks"):
        read_recording(path)


# ---------------------------------------------------------------------------- files that are not files
def test_directory_link_loop_and_dangling_link(tmp_path):
    d = tmp_path / "rec.raw"
    d.mkdir()
    with pytest.raises(InputError, match=r"rec\.raw.*is a directory"):
        read_recording(d)
    loop = tmp_path / "loop.dat"
    os.symlink(loop, loop)
    with pytest.raises(InputError, match=r"loop\.dat.*loop of symbolic links"):
        read_recording(loop)
    dangling = tmp_path / "gone.h5"
    os.symlink(tmp_path / "nowhere.h5", dangling)
    with pytest.raises(InputError, match=r"gone\.h5.*symbolic link to .*nowhere\.h5.*does not exist"):
        read_recording(dangling)
    with pytest.raises(InputError, match=r"missing\.npz' does not exist"):
        read_recording(tmp_path / "missing.npz")
    (tmp_path / "dir.npz").mkdir()
    with pytest.raises(InputError, match=r"dir\.npz.*is a directory"):
        read_events(tmp_path / "dir.npz")


def test_scrambled_aedat4_refused(tmp_path):
    """Bytes that are not AEDAT 4 are refused before dv-processing starts; a file whose body is
    scrambled is refused by dv-processing (or by the reader's per-batch timeout, 5 s)."""
    pytest.importorskip("dv_processing")
    from fsdvs_hw.sensor.eventfiles.eventfile import write_events

    good = tmp_path / "good.aedat4"
    write_events(good, _events(n=3000), 64, 48)
    data = np.frombuffer(good.read_bytes(), np.uint8)
    rng = np.random.default_rng(1)
    scrambled = tmp_path / "scrambled.aedat4"
    scrambled.write_bytes(rng.permutation(data).tobytes())
    with pytest.raises(InputError, match=r"scrambled\.aedat4.*not an AEDAT 4 file"):
        read_recording(scrambled)
    body = tmp_path / "body.aedat4"
    body.write_bytes(data[:200].tobytes() + rng.permutation(data[200:]).tobytes())
    with pytest.raises(InputError, match=r"body\.aedat4"):
        read_recording(body)
