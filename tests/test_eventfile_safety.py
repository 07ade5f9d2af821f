"""Event files that survive full disks, kills, Ctrl-C and bad input (issue 23).

Writers: a full disk (``RLIMIT_FSIZE`` in a subprocess, SIGXFSZ ignored so writes raise EFBIG)
or SIGKILL mid-write leaves no file at the target and a previous file there byte-identical.
``fsdvs-hw simulate`` stopped by SIGINT / SIGTERM exits 130 / 143 with nothing at ``--out``.
Readers: every bad case is one :class:`InputError` naming the file and the field; garbled files
(hypothesis, derandomized) read to valid events or raise InputError, never anything else.
"""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor.eventfiles import eventfile
from fsdvs_hw.sensor.eventfiles.eventfile import EventFile, read_events, write_events

ROOT = Path(__file__).resolve().parents[1]
HAS_DV = importlib.util.find_spec("dv_processing") is not None
NEEDS_DV = pytest.mark.skipif(not HAS_DV, reason="dv-processing not installed (pip install 'fsdvs_hw[eventfiles]')")
SUFFIXES = [".h5", ".npz", pytest.param(".aedat4", marks=NEEDS_DV)]
OLD = b"previous file: must survive byte for byte\n"

# Writes 50 000 random events per chunk (incompressible enough to fill any small limit), says
# "first" after the first chunk; "full": under RLIMIT_FSIZE = argv[3] bytes; "kill": forever.
WRITER = r"""
import resource, signal, sys
import numpy as np
from fsdvs_hw.sensor.eventfiles.eventfile import EventFile, EventFileWriter
mode, path, limit = sys.argv[1], sys.argv[2], int(sys.argv[3])
rng = np.random.default_rng(0)
n = 50_000
if mode == "full":
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
try:
    with EventFileWriter(path, 640, 480) as w:
        for i in range(40 if mode == "full" else 10**6):
            t = np.sort(rng.integers(0, 10**6, n)) + i * 10**6
            w.write(EventFile(t, rng.integers(0, 640, n), rng.integers(0, 480, n),
                              rng.choice(np.array([-1, 1], np.int8), n), 640, 480))
            if i == 0:
                print("first", flush=True)
except OSError as exc:
    print("OSError:", exc, flush=True)
    sys.exit(3)
print("done", flush=True)
"""


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}


def _visible(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_full_disk_leaves_no_file_and_keeps_the_previous_one(tmp_path, suffix):
    """EFBIG mid-write: the writer raises an OSError naming the target, removes its temporary
    file (nothing hidden left either), and the previous file at the target is untouched."""
    target = tmp_path / f"ev{suffix}"
    target.write_bytes(OLD)
    r = subprocess.run(
        [sys.executable, "-c", WRITER, "full", str(target), str(256 * 1024)],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 3, (r.returncode, r.stdout, r.stderr[-2000:])
    assert "OSError:" in r.stdout and str(target) in r.stdout
    assert target.read_bytes() == OLD
    time.sleep(0.2)  # the AEDAT4 child process removes its file as it exits
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_kill_mid_write_leaves_only_a_hidden_temporary_file(tmp_path, suffix):
    """SIGKILL while writing: no file appears at the target name, the previous one is intact,
    and whatever remains is hidden (``.ev.partial-PID...``)."""
    target = tmp_path / f"ev{suffix}"
    target.write_bytes(OLD)
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, "kill", str(target), "0"],
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "first", proc.stderr.read()[-2000:]
        proc.kill()
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    assert target.read_bytes() == OLD
    assert _visible(tmp_path) == [target.name]
    assert all(name.startswith(".ev.partial-") for name in os.listdir(tmp_path) if name != target.name)


def _fast_video(path: Path, n: int = 40, side: int = 64, faststart: bool = True) -> Path:
    import imageio

    rng = np.random.default_rng(0)
    params = ["-movflags", "+faststart"] if faststart else None
    with imageio.get_writer(str(path), fps=20, quality=5, macro_block_size=16, output_params=params) as w:
        for _ in range(n):
            w.append_data(rng.integers(0, 255, (side, side, 3), dtype=np.uint8))
    return path


@pytest.mark.parametrize("suffix", [".npz", ".h5"])
@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_simulate_stopped_by_signal_exits_nonzero_without_a_file(tmp_path, sig, code, suffix):
    """Ctrl-C / SIGTERM sent as soon as the temporary file appears (the writer is opened from a
    thread while torch loads, so this lands during start-up or the first chunks): exit 130 / 143,
    one line on stderr naming the signal, the previous file at --out untouched, no temporary
    left, no writer process left."""
    video = _fast_video(tmp_path / "clip.mp4", n=400, side=128)
    out = tmp_path / "out" / f"ev{suffix}"
    out.parent.mkdir()
    out.write_bytes(OLD)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "fsdvs_hw.cli",
            "simulate",
            str(video),
            "--out",
            str(out),
            "--no-progress",
            "--preset",
            "v2e-noisy",
        ],
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not any(p.name.startswith(".ev.partial-") for p in out.parent.iterdir()):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the writer never started"
            time.sleep(0.02)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == code, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and sig.name in lines[0] and "nothing written" in lines[0], err
    assert out.read_bytes() == OLD
    assert os.listdir(out.parent) == [out.name]
    if sys.platform.startswith("linux"):  # the writer process (.h5) went with the run
        left = []
        for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
            try:
                if str(out.parent).encode() in cmdline.read_bytes():
                    left.append(cmdline.parent.name)
            except OSError:  # a process that ended meanwhile
                pass
        assert not left, left


# ------------------------------------------------------------------------------------------ readers


def _npz(path: Path, **arrays) -> Path:
    base = {
        "t": np.array([0, 5, 9], np.int64),
        "x": np.array([0, 1, 2], np.uint16),
        "y": np.array([0, 1, 1], np.uint16),
        "p": np.array([1, -1, 1], np.int8),
        "width": np.int64(4),
        "height": np.int64(3),
    }
    base.update(arrays)
    np.savez(path, **{k: v for k, v in base.items() if v is not None})
    return path


def _h5(path: Path, events=None, *, attrs=None, build=None) -> Path:
    import h5py

    with h5py.File(path, "w") as f:
        if build is not None:
            build(f)
        else:
            a = np.array([[0, 0, 0, 1], [5, 1, 1, 0], [9, 2, 1, 1]], np.uint32) if events is None else events
            f.create_dataset("events", data=a)
        for k, v in {"width": 4, "height": 3, **(attrs or {})}.items():
            f.attrs[k] = v
    return path


def _truncate(path: Path, fraction: float = 0.5) -> Path:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])
    return path


def _good_aedat4(path: Path) -> Path:
    rng = np.random.default_rng(0)
    n = 3000
    t = np.sort(rng.integers(0, 10**6, n))
    write_events(
        path,
        EventFile(t, rng.integers(0, 40, n), rng.integers(0, 30, n), rng.choice(np.array([-1, 1], np.int8), n), 40, 30),
        40,
        30,
    )
    return path


def _cases():
    c = {
        "npz truncated": ("(file)", lambda d: _truncate(_npz(d / "a.npz"))),
        "npz float times (seconds)": ("t", lambda d: _npz(d / "a.npz", t=np.array([0.0, 0.5, 0.9]))),
        "npz NaN times": ("t", lambda d: _npz(d / "a.npz", t=np.array([0.0, np.nan, 1.0]))),
        "npz negative time": ("t", lambda d: _npz(d / "a.npz", t=np.array([-3, 5, 9]))),
        "npz decreasing time": ("t", lambda d: _npz(d / "a.npz", t=np.array([0, 9, 5]))),
        "npz polarity 0": ("p", lambda d: _npz(d / "a.npz", p=np.array([1, 0, 1], np.int8))),
        "npz float x": ("x", lambda d: _npz(d / "a.npz", x=np.array([0.0, 1.5, 2.0]))),
        "npz x beyond width": ("x", lambda d: _npz(d / "a.npz", x=np.array([0, 1, 4], np.uint16))),
        "npz y beyond height": ("y", lambda d: _npz(d / "a.npz", y=np.array([0, 3, 1], np.uint16))),
        "npz ragged columns": ("x", lambda d: _npz(d / "a.npz", x=np.array([0, 1], np.uint16))),
        "npz 2-D column": ("y", lambda d: _npz(d / "a.npz", y=np.zeros((3, 2), np.uint16))),
        "npz missing width": ("width", lambda d: _npz(d / "a.npz", width=None)),
        "npz width 0": ("width", lambda d: _npz(d / "a.npz", width=np.int64(0))),
        "npz float height": ("height", lambda d: _npz(d / "a.npz", height=np.float64(3.0))),
        "npz is one .npy": (
            "(file)",
            lambda d: (np.save(d / "a.npy", np.arange(3)), os.replace(d / "a.npy", d / "a.npz"), d / "a.npz")[-1],
        ),
        "npz not a zip": ("(file)", lambda d: (d / "a.npz").write_bytes(b"PK\x03\x04garbage") and d / "a.npz"),
        "h5 truncated": ("(file)", lambda d: _truncate(_h5(d / "a.h5"))),
        "h5 group where the dataset belongs": (
            "events",
            lambda d: _h5(d / "a.h5", build=lambda f: f.create_group("events")),
        ),
        "h5 no events": ("events", lambda d: _h5(d / "a.h5", build=lambda f: f.create_dataset("other", data=[1]))),
        "h5 declares 1e10 events": (
            "events",
            lambda d: _h5(
                d / "a.h5",
                build=lambda f: f.create_dataset(
                    "events", shape=(10**10, 4), maxshape=(None, 4), chunks=(65536, 4), dtype="uint32"
                ),
            ),
        ),
        "h5 declared events absent": (
            "events",
            lambda d: _h5(
                d / "a.h5",
                build=lambda f: f.create_dataset(
                    "events", shape=(1000, 4), maxshape=(None, 4), chunks=(256, 4), dtype="uint32"
                ),
            ),
        ),
        "h5 float times (seconds)": ("t_us", lambda d: _h5(d / "a.h5", np.array([[0.0, 0, 0, 1], [0.5, 1, 1, 0]]))),
        "h5 shape (N, 3)": ("events", lambda d: _h5(d / "a.h5", np.zeros((3, 3), np.uint32))),
        "h5 polarity 2": ("(p)", lambda d: _h5(d / "a.h5", np.array([[0, 0, 0, 2]], np.uint32))),
        "h5 x beyond width": ("(x)", lambda d: _h5(d / "a.h5", np.array([[0, 4, 0, 1]], np.uint32))),
        "h5 negative time": ("t_us", lambda d: _h5(d / "a.h5", np.array([[-1, 0, 0, 1]], np.int64))),
        "h5 decreasing time": ("t_us", lambda d: _h5(d / "a.h5", np.array([[5, 0, 0, 1], [4, 0, 0, 1]], np.uint32))),
        "h5 width attribute -5": ("width", lambda d: _h5(d / "a.h5", attrs={"width": -5})),
    }
    out = [pytest.param(field, make, id=name) for name, (field, make) in c.items()]
    for name, fraction in (("aedat4 truncated", 0.5), ("aedat4 header only", 0.01)):
        out.append(
            pytest.param(
                "(file)", lambda d, f=fraction: _truncate(_good_aedat4(d / "a.aedat4"), f), id=name, marks=NEEDS_DV
            )
        )
    out.append(
        pytest.param(
            "(file)",
            lambda d: (d / "a.aedat4").write_bytes(b"#!AER-DAT4.0\r\n" + b"\0" * 64) and d / "a.aedat4",
            id="aedat4 garbage after the magic",
            marks=NEEDS_DV,
        )
    )
    return out


@pytest.mark.parametrize("field, make", _cases())
def test_readers_refuse_bad_files_naming_file_and_field(tmp_path, field, make):
    path = make(tmp_path)
    with pytest.raises(InputError) as info:
        read_events(path)
    msg = str(info.value)
    assert str(path) in msg and field in msg, msg
    assert "\n" not in msg


def test_reader_checks_memory_before_allocating(tmp_path):
    """A file within the limit reads; the same file under a smaller limit is refused by name."""
    from fsdvs_hw.limits import allocation_limit

    path = _npz(tmp_path / "a.npz")
    assert len(read_events(path)) == 3
    with allocation_limit(64), pytest.raises(InputError, match="would allocate"):
        read_events(path)


def _valid_events(ev: EventFile) -> None:
    assert ev.t_us.dtype == np.int64 and ev.x.dtype == np.int64 and ev.p.dtype == np.int8
    assert len(ev.x) == len(ev.y) == len(ev.p) == len(ev)
    assert 1 <= ev.width <= 32767 and 1 <= ev.height <= 32767
    if len(ev):
        assert ev.t_us.min() >= 0 and (np.diff(ev.t_us) >= 0).all()
        assert 0 <= ev.x.min() and ev.x.max() < ev.width and 0 <= ev.y.min() and ev.y.max() < ev.height
        assert set(np.unique(ev.p)) <= {-1, 1}


def _good_file(d: Path, suffix: str) -> bytes:
    rng = np.random.default_rng(3)
    n = 200
    t = np.sort(rng.integers(0, 10**5, n))
    path = d / f"good{suffix}"
    write_events(
        path,
        EventFile(t, rng.integers(0, 16, n), rng.integers(0, 12, n), rng.choice(np.array([-1, 1], np.int8), n), 16, 12),
        16,
        12,
    )
    return path.read_bytes()


MUTATIONS = st.tuples(
    st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)), min_size=1, max_size=8),
    st.one_of(st.none(), st.floats(0, 1)),
)


def _mutate(data: bytes, mutation) -> bytes:
    edits, cut = mutation
    b = bytearray(data)
    for where, value in edits:
        b[int(where * len(b))] = value
    return bytes(b[: int(cut * len(b))]) if cut is not None else bytes(b)


def garbled_outcomes(good: bytes, path: Path, read, examples: int) -> dict[str, int]:
    """Write ``good`` garbled by each drawn mutation to ``path`` and read it with ``read(path)``:
    every file must read to valid events or raise one InputError naming it (one line), never
    another exception; returns how many were read and refused (derandomized examples)."""
    outcomes = {"read": 0, "refused": 0}

    @settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )
    @given(mutation=MUTATIONS)
    def check(mutation):
        path.write_bytes(_mutate(good, mutation))
        try:
            ev = read(path)
        except InputError as exc:
            assert str(path) in str(exc) and "\n" not in str(exc)
            outcomes["refused"] += 1
            return
        _valid_events(ev)
        outcomes["read"] += 1

    check()
    return outcomes


@pytest.mark.parametrize("suffix, examples", [(".npz", 50), (".h5", 50), pytest.param(".aedat4", 12, marks=NEEDS_DV)])
def test_garbled_files_read_valid_or_raise_input_error(tmp_path_factory, suffix, examples):
    """Any file with up to 8 changed bytes and/or cut short reads to valid events or raises
    InputError, never another exception (derandomized: the same examples every run)."""
    d = tmp_path_factory.mktemp("fuzz")
    good = _good_file(d, suffix)
    saved = eventfile.AEDAT4_READ_TIMEOUT_S
    eventfile.AEDAT4_READ_TIMEOUT_S = 5.0  # a garbled AEDAT4 file can make dv-processing loop forever
    try:
        outcomes = garbled_outcomes(good, d / f"bad{suffix}", read_events, examples)
    finally:
        eventfile.AEDAT4_READ_TIMEOUT_S = saved
    assert outcomes["refused"] > 0  # the mutations do reach the checks (measured: npz 49 of 50 refused, h5 43 of 50)
    if suffix != ".aedat4":
        assert outcomes["read"] > 0  # and harmless ones still read (npz 4, h5 18)


# ------------------------------------------------------------------------------------------ CLI


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--size", "100000x100000"], "--size"),
        (["--size", "20000x20000"], "--size"),  # within the side limit, beyond the memory limit
        (["--threads", "10000"], "--threads"),
        (["--threads", "0"], "--threads"),
        (["--seed", str(2**62)], "--seed"),
        (["--seed", "-1"], "--seed"),
        (["--frames", "0"], "--frames"),
        (["--chunk-frames", "0"], "--chunk-frames"),
    ],
    ids=["size side", "size memory", "threads many", "threads 0", "seed 2**62", "seed -1", "frames 0", "chunk 0"],
)
def test_simulate_limits_are_one_line_errors(tmp_path, capsys, argv, flag):
    from fsdvs_hw.cli import main

    out = tmp_path / "ev.npz"
    assert main(["simulate", "example:carphone", "--out", str(out), "--no-progress", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert flag in err and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_seed_limit_in_sensor_config():
    from fsdvs_hw.sensor import SensorConfig
    from fsdvs_hw.sensor.simulation.config import MAX_SEED

    assert SensorConfig(seed=MAX_SEED).seed == MAX_SEED
    with pytest.raises(InputError, match="seed"):
        SensorConfig(seed=MAX_SEED + 1)


@pytest.mark.parametrize("preset", ["default", "v2e-default"], ids=["imageio decoder", "OpenCV decoder"])
def test_simulate_refuses_a_truncated_video_unless_allowed(tmp_path, capfd, preset):
    """Half a 40-frame clip decodes 17-19 frames: refused (exit 2, one line on the process's
    stderr, libav's own messages included, no file at --out); --allow-truncated simulates the
    decodable frames. Both decoders: imageio's ffmpeg (linear light) and OpenCV's (v2e's gray
    frames, as v2e reads a video)."""
    from fsdvs_hw.cli import main

    video = _truncate(_fast_video(tmp_path / "clip.mp4"))
    out = tmp_path / "ev.npz"
    base = ["simulate", str(video), "--out", str(out), "--no-progress", "--preset", preset]
    assert main(base) == 2
    err = capfd.readouterr().err.strip()
    assert "truncated" in err and "declares 40" in err and len(err.splitlines()) == 1, err
    assert not out.exists() and os.listdir(tmp_path) == ["clip.mp4"]
    assert main([*base, "--allow-truncated"]) == 0
    assert len(read_events(out)) > 0


def test_undecodable_video_error_is_one_line_without_ffmpeg_banner(tmp_path, capsys):
    from fsdvs_hw.cli import main

    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video")
    assert main(["simulate", str(bad), "--out", str(tmp_path / "ev.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Invalid data" in err and "ffmpeg version" not in err, err


def test_writer_abort_and_failed_with_block_keep_the_previous_file(tmp_path):
    """An exception inside ``with EventFileWriter`` (here bad events) leaves the old file."""
    target = tmp_path / "ev.npz"
    target.write_bytes(OLD)
    ev = EventFile(np.array([5, 1]), np.array([0, 0]), np.array([0, 0]), np.array([1, 1], np.int8), 4, 4)
    with pytest.raises(InputError, match="non-decreasing"):
        write_events(target, ev, 4, 4)
    assert target.read_bytes() == OLD and os.listdir(tmp_path) == ["ev.npz"]
    good = EventFile(np.array([1, 5]), np.array([0, 3]), np.array([0, 2]), np.array([1, -1], np.int8), 4, 4)
    write_events(target, good, 4, 4)
    assert zipfile.is_zipfile(target) and read_events(target).x.tolist() == [0, 3]
