"""Event files: round trips for HDF5 (v2e layout), AEDAT4 and npz; conventions; bad input."""

import importlib.util

import numpy as np
import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import SensorConfig, simulate
from fsdvs_hw.sensor.eventfiles.eventfile import EventFileWriter, read_events, write_events

HAS_DV = importlib.util.find_spec("dv_processing") is not None
FORMATS = [
    ".h5",
    ".npz",
    pytest.param(
        ".aedat4",
        marks=pytest.mark.skipif(not HAS_DV, reason="dv-processing not installed (pip install 'fsdvs_hw[eventfiles]')"),
    ),
]


def _chunks(T=9, H=12, W=20):
    g = torch.Generator().manual_seed(1)
    video = (torch.rand(1, 1, H, W, generator=g) * (1 + torch.linspace(0, 2, T).view(1, T, 1, 1))).double()
    cfg = SensorConfig(shot_noise_rate_hz=20.0, seed=2)
    return list(simulate(video, config=cfg, chunk_frames=3)), H, W


@pytest.mark.parametrize("write_slice", [1 << 18, 7], ids=["one slice", "slices of 7"])
@pytest.mark.parametrize("suffix", FORMATS)
def test_round_trip_chunk_by_chunk(tmp_path, suffix, write_slice, monkeypatch):
    """Chunks written one by one read back exactly; also when each write is cut into slices of 7
    events (the writer bounds its memory by slicing large chunks)."""
    from fsdvs_hw.sensor.eventfiles import eventfile

    monkeypatch.setattr(eventfile, "WRITE_SLICE", write_slice)
    chunks, H, W = _chunks()
    path = tmp_path / f"ev{suffix}"
    with EventFileWriter(path, W, H) as w:
        for c in chunks:
            w.write(c.events)
    ev = read_events(path)
    t = torch.cat([c.events.t for c in chunks])
    assert len(ev) == len(t) == w.count > 50
    assert (ev.width, ev.height) == (W, H)
    assert np.array_equal(ev.t_us, np.rint(t.numpy() * 1e6).astype(np.int64))  # microseconds
    for name in ("x", "y", "p"):
        want = torch.cat([getattr(c.events, name) for c in chunks]).numpy()
        assert np.array_equal(getattr(ev, name), want), name
    assert set(np.unique(ev.p)) == {-1, 1}
    back = ev.to_event_list()
    assert torch.allclose(back.t, t, atol=5e-7, rtol=0)


def test_hdf5_is_v2e_layout(tmp_path):
    import h5py

    chunks, H, W = _chunks()
    ev = chunks[0].events
    write_events(tmp_path / "v2e.h5", ev, W, H)
    with h5py.File(tmp_path / "v2e.h5", "r") as f:
        d = f["events"]
        assert (
            d.dtype == np.uint32
            and d.shape == (len(ev), 4)
            and d.compression == "gzip"
            and d.compression_opts == 1
            and d.shuffle
        )
        a = d[()]
    assert np.array_equal(a[:, 3], (ev.p.numpy() > 0).astype(np.uint32))  # v2e: 1 = ON, 0 = OFF
    assert np.array_equal(a[:, 1], ev.x.numpy()) and np.array_equal(a[:, 2], ev.y.numpy())


def test_event_file_errors(tmp_path):
    chunks, H, W = _chunks()
    with pytest.raises(InputError, match="suffix"):
        write_events(tmp_path / "ev.txt", chunks[0].events, W, H)
    with pytest.raises(InputError, match="outside"):
        write_events(tmp_path / "ev.npz", chunks[0].events, W - 5, H)
    with pytest.raises(InputError, match="does not exist"):
        read_events(tmp_path / "missing.h5")
    with pytest.raises(InputError, match="non-decreasing"):
        with EventFileWriter(tmp_path / "ev2.npz", W, H) as w:
            w.write(chunks[1].events)
            w.write(chunks[0].events)
    from fsdvs_hw.sensor.simulation.events import EventList

    for bad in (0, 2, -2, 127, -128):  # -128: abs() overflows back to -128 in int8
        p = torch.tensor([1, bad, -1], dtype=torch.int8)
        three = EventList(
            torch.zeros(3, dtype=torch.int64),
            torch.zeros(3, dtype=torch.int64),
            torch.zeros(3, dtype=torch.int64),
            torch.tensor([0.0, 0.1, 0.2], dtype=torch.float64),
            p,
        )
        with pytest.raises(InputError, match="polarity must be"):
            write_events(tmp_path / f"bad{bad}.npz", three, W, H)
        assert not (tmp_path / f"bad{bad}.npz").exists()


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


# 10 examples: each HDF5/AEDAT4 write and AEDAT4 read starts a child process (~0.2 s), 25 took 15 s
@settings(max_examples=10, deadline=None)
@given(
    n=st.integers(0, 40),
    w=st.integers(1, 32767),
    h=st.integers(1, 32767),
    t_max=st.sampled_from([1, 1000, 4_294_967_295]),
    seed=st.integers(0, 2**31),
)
def test_round_trip_property_at_extremes(tmp_path_factory, n, w, h, t_max, seed):
    """Any sorted events, sensor sizes up to 32767 px and times up to v2e's uint32 µs limit
    survive every format unchanged (also the empty file)."""
    from fsdvs_hw.sensor import EventList

    rng = np.random.default_rng(seed)
    t_us = np.sort(rng.integers(0, t_max + 1, n))
    x, y = rng.integers(0, w, n), rng.integers(0, h, n)
    x[:1], y[:1] = w - 1, h - 1  # corner pixel
    p = rng.choice(np.array([-1, 1], dtype=np.int8), n)
    ev = EventList(
        torch.zeros(n, dtype=torch.int64),
        torch.from_numpy(x),
        torch.from_numpy(y),
        torch.from_numpy(t_us * 1e-6),
        torch.from_numpy(p),
    )
    d = tmp_path_factory.mktemp("rt")
    for suffix in (".h5", ".npz") + ((".aedat4",) if HAS_DV else ()):
        if suffix == ".aedat4" and (w > 32767 or h > 32767):
            continue
        write_events(d / f"e{suffix}", ev, w, h)
        back = read_events(d / f"e{suffix}")
        assert (back.width, back.height) == (w, h), suffix
        for got, want in ((back.t_us, t_us), (back.x, x), (back.y, y), (back.p, p)):
            assert np.array_equal(got, want), suffix


def test_hdf5_refuses_times_beyond_uint32_microseconds(tmp_path):
    from fsdvs_hw.sensor import EventList

    one = torch.zeros(1, dtype=torch.int64)
    ev = EventList(one, one, one, torch.tensor([4295.0]), torch.ones(1, dtype=torch.int8))
    with pytest.raises(InputError, match="uint32"):
        write_events(tmp_path / "late.h5", ev, 4, 4)
    write_events(tmp_path / "late.npz", ev, 4, 4)
    assert read_events(tmp_path / "late.npz").t_us.tolist() == [4_295_000_000]


def test_hdf5_chunks_deflated_in_parallel_decode_as_hdf5_filters_define(tmp_path):
    """Writes of odd sizes across the 65 536-row chunks: the file reads back exactly, and each
    stored chunk is what HDF5's shuffle (element size 4) + deflate filters define — a zlib stream
    of the byte-shuffled rows, the edge chunk zero-padded."""
    import zlib

    import h5py

    from fsdvs_hw.sensor.simulation.events import EventList

    rng = np.random.default_rng(5)
    sizes = [70_000, 65_536, 1, 130_000, 3]
    n = sum(sizes)
    t = np.sort(rng.uniform(0, 2.0, n))
    x, y = rng.integers(0, 346, n), rng.integers(0, 260, n)
    p = rng.choice(np.array([-1, 1], dtype=np.int8), n)
    with EventFileWriter(tmp_path / "odd.h5", 346, 260) as w:
        start = 0
        for k in sizes:
            sl = slice(start, start + k)
            w.write(
                EventList(
                    torch.zeros(k, dtype=torch.int64),
                    torch.from_numpy(x[sl]),
                    torch.from_numpy(y[sl]),
                    torch.from_numpy(t[sl]),
                    torch.from_numpy(p[sl]),
                )
            )
            start += k
    want = np.stack([np.rint(t * 1e6), x, y, p > 0], axis=1).astype(np.uint32)
    with h5py.File(tmp_path / "odd.h5", "r") as f:
        d = f["events"]
        assert np.array_equal(d[()], want)
        assert (d.compression, d.compression_opts, d.shuffle, d.chunks) == ("gzip", 1, True, (65536, 4))
        n_chunks = -(-n // 65536)
        assert d.id.get_num_chunks() == n_chunks
        for i in (0, n_chunks - 1):  # a whole chunk and the edge chunk
            mask, raw = d.id.read_direct_chunk((i * 65536, 0))
            rows = np.frombuffer(zlib.decompress(raw), np.uint8).reshape(4, -1).T.copy().view(np.uint32).reshape(-1, 4)
            assert mask == 0 and rows.shape == (65536, 4)
            part = want[i * 65536 : (i + 1) * 65536]
            assert np.array_equal(rows[: len(part)], part) and not rows[len(part) :].any()


@pytest.mark.skipif(not hasattr(__import__("fcntl"), "F_GETPIPE_SZ"), reason="Linux pipe sizes only")
def test_writer_pipe_is_widened_to_one_mebibyte(tmp_path):
    """The pipe to the writer child holds 1 MiB (not Linux's 64 KiB default): fewer hand-offs
    between a busy parent and its writer (docs/speed.md). Skipped where the system caps pipes lower."""
    import fcntl

    from pathlib import Path

    cap = int(Path("/proc/sys/fs/pipe-max-size").read_text())
    if cap < 1 << 20:
        pytest.skip(f"/proc/sys/fs/pipe-max-size is {cap}")
    with EventFileWriter(tmp_path / "e.h5", 4, 4) as w:
        assert fcntl.fcntl(w._child.stdin.fileno(), fcntl.F_GETPIPE_SZ) == 1 << 20
