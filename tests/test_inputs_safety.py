"""Inputs that cannot hurt: paths stay in their folder, loaders and CLI flags fail with one clear
line (exit 2), nothing silently wrong, sizes refused before allocation, no data lost, no orphans."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import cheap_design

from fsdvs_hw.cli import main
from fsdvs_hw.design import DesignError, load_design, parse_design
from fsdvs_hw.errors import InputError

REPO = Path(__file__).resolve().parents[1]
KERNEL_JSON = REPO / "designs" / "kernels" / "learned_detection_7x7.json"


def _cli(argv: list[str], capsys) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # a flag refused while parsing (argparse exits 2 after one line)
        code = int(exc.code or 0)
    return code, capsys.readouterr().err


def _one_clear_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("[")]
    assert "Traceback" not in err
    assert len(lines) == 1 and ": error: " in lines[0], err
    return lines[0]


# ---------------------------------------------------------------------- security: paths
@pytest.mark.parametrize("name", ["../../escaped", "/tmp/fsdvs_abs_escape_{pid}", "a/../../b", "..", "."])
def test_design_name_never_writes_outside_the_store_folder(tmp_path, monkeypatch, capsys, name):
    name = name.format(pid=os.getpid())
    work = tmp_path / "work"
    work.mkdir()
    (work / "d.toml").write_text(cheap_design(name))
    monkeypatch.chdir(work)
    before = set(Path("/tmp").glob("fsdvs_abs_escape_*"))
    code, err = _cli(["sweep", "d.toml", "--no-progress"], capsys)
    assert code == 0, err
    stores = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*.sqlite"))
    assert len(stores) == 1 and stores[0].parent == Path("work/out/sweeps"), stores
    assert set(Path("/tmp").glob("fsdvs_abs_escape_*")) == before


@pytest.mark.parametrize("where", ["parent", "absolute", "symlink"])
def test_design_kernel_path_outside_the_design_folder_is_refused(tmp_path, where):
    design_dir = tmp_path / "designs"
    design_dir.mkdir()
    outside = tmp_path / "secret.json"
    outside.write_text(KERNEL_JSON.read_text())
    if where == "parent":
        ref = "../secret.json"
    elif where == "absolute":
        ref = str(outside)
    else:
        (design_dir / "link.json").symlink_to(outside)
        ref = "link.json"
    (design_dir / "d.toml").write_text(f'[kernel]\nsource = "file"\npath = {ref!r}\n')
    with pytest.raises(DesignError) as info:
        load_design(design_dir / "d.toml")
    assert "kernel.path" in str(info.value) and "outside the design's folder" in str(info.value)


def test_design_checkpoint_outside_the_design_folder_is_refused(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "x.toml").write_text('[tasks]\ncheckpoints = { detection = "../../etc/passwd" }\n')
    with pytest.raises(DesignError, match=r"tasks\.checkpoints\.detection.*outside the design's folder"):
        load_design(tmp_path / "d" / "x.toml")


def test_a_garbage_checkpoint_is_refused_when_the_design_loads(tmp_path):
    (tmp_path / "junk.safetensors").write_bytes(b"\xff" * 64)
    (tmp_path / "x.toml").write_text('[tasks]\ncheckpoints = { detection = "junk.safetensors" }\n')
    with pytest.raises(DesignError, match=r"tasks\.checkpoints\.detection.*not a usable checkpoint"):
        load_design(tmp_path / "x.toml")


def test_paths_inside_the_design_folder_still_work():
    d = load_design(REPO / "designs" / "default.toml")
    assert d.target.size == 7 and all(p.is_file() for paths in d.checkpoints().values() for p in paths)
    # one network per training seed, listed by a glob pattern inside the design's folder
    assert {t: len(paths) for t, paths in d.checkpoints().items()} == {
        "detection": 32,
        "recognition": 64,
        "segmentation": 32,
    }


def test_yosys_top_cannot_inject_script_commands(tmp_path):
    from fsdvs_hw.realise.asic.rtl import synthesise_verilog

    marker = tmp_path / "pwned"
    for top in [f"x; !touch {marker}", "x\n!id", "1abc", "", "a b"]:
        with pytest.raises(InputError, match="top"):
            synthesise_verilog("module x(); endmodule\n", top=top)
    assert not marker.exists()


@pytest.mark.tools
def test_liberty_path_with_script_characters_is_used_safely(tmp_path):
    from conftest import require_tool

    require_tool("yosys")
    from fsdvs_hw.realise.asic.rtl import LIBERTY_PATH, synthesise_verilog

    odd = tmp_path / "cells; !echo hi.lib"
    odd.write_bytes(LIBERTY_PATH.read_bytes())
    src = "module t(input wire clk, input wire a, output reg q); always @(posedge clk) q <= ~a; endmodule\n"
    rep = synthesise_verilog(src, top="t", liberty=odd)
    assert rep.flip_flops == 1


# ---------------------------------------------------------------------- loaders and flags: exit 2, one line
@pytest.mark.parametrize("content", [b"this is not sqlite, just text" * 10, b"\x00" * 4096])
def test_non_sqlite_store_is_one_clear_error(tmp_path, capsys, content):
    (tmp_path / "d.toml").write_text(cheap_design("d"))
    store = tmp_path / "s.sqlite"
    store.write_bytes(content)
    code, err = _cli(["sweep", str(tmp_path / "d.toml"), "--store", str(store), "--no-progress"], capsys)
    assert code == 2
    line = _one_clear_line(err)
    assert str(store) in line and "results store" in line and "just text" not in line


def test_store_with_a_foreign_points_table_is_refused(tmp_path):
    from fsdvs_hw.explore.store import ResultsStore

    db = tmp_path / "other.sqlite"
    with sqlite3.connect(db) as c:
        c.execute("CREATE TABLE points (x INTEGER)")
    with pytest.raises(InputError, match="another layout"):
        ResultsStore(db)


def test_another_applications_database_is_refused_and_left_unchanged(tmp_path):
    from fsdvs_hw.explore.store import ResultsStore

    db = tmp_path / "app.sqlite"
    with sqlite3.connect(db) as c:
        c.execute("CREATE TABLE users (name TEXT)")
        c.execute("INSERT INTO users VALUES ('ada')")
    c.close()
    before = db.read_bytes()
    with pytest.raises(InputError, match="other tables \\(users\\).*left unchanged"):
        ResultsStore(db)
    assert db.read_bytes() == before and not (tmp_path / "app.sqlite-wal").exists()


def test_a_corrupt_stored_row_is_an_input_error(tmp_path):
    from fsdvs_hw.explore.store import ResultsStore

    db = tmp_path / "r.sqlite"
    with ResultsStore(db) as s:
        s.add("k", design="d", realisation="asic", params={}, status="ok", result={"v": 1}, wall_s=0)
    with sqlite3.connect(db) as c:
        c.execute("UPDATE points SET result = '{broken' WHERE key = 'k'")
    c.close()
    with ResultsStore(db) as s:
        with pytest.raises(InputError, match="'k' is corrupt"):
            list(s.rows())


def test_store_that_is_a_folder_is_refused(tmp_path):
    from fsdvs_hw.explore.store import ResultsStore

    with pytest.raises(InputError, match="is a folder"):
        ResultsStore(tmp_path)


def test_file_valued_out_is_one_clear_error_before_work(tmp_path, capsys):
    (tmp_path / "d.toml").write_text(cheap_design("d"))
    out = tmp_path / "out"
    out.write_text("a file")
    code, err = _cli(["explore", str(tmp_path / "d.toml"), "--out", str(out), "--no-progress"], capsys)
    assert code == 2
    assert "not a folder" in _one_clear_line(err)
    code, err = _cli(["explore", str(tmp_path / "d.toml"), "--out", str(out / "sub"), "--no-progress"], capsys)
    assert code == 2
    _one_clear_line(err)


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root can write anywhere")
def test_unwritable_out_is_one_clear_error(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        code, err = _cli(["analyse", "dog", "--out", str(ro / "x")], capsys)
        assert code == 2 and str(ro / "x") in _one_clear_line(err)
        code, err = _cli(["analyse", "dog", "--out", str(ro)], capsys)
        assert code == 2 and "not writable" in _one_clear_line(err)
    finally:
        ro.chmod(0o700)


def test_out_folder_that_cannot_be_created_is_one_clear_error(tmp_path, capsys):
    (tmp_path / "d.toml").write_text(cheap_design("d"))
    bad = "/proc/fsdvs-no-such-dir/out"  # not creatable, even by root
    code, err = _cli(["explore", str(tmp_path / "d.toml"), "--out", bad, "--no-progress"], capsys)
    assert code == 2 and bad in _one_clear_line(err)
    code, err = _cli(["sweep", str(tmp_path / "d.toml"), "--store", bad + "/s.sqlite", "--no-progress"], capsys)
    assert code == 2 and bad in _one_clear_line(err)


@pytest.mark.parametrize("content", [b"\xff\xfe[design]\n", b"[design\n", b"a = [" * 2000])
def test_malformed_design_file_is_one_clear_error(tmp_path, capsys, content):
    p = tmp_path / "bad.toml"
    p.write_bytes(content)
    code, err = _cli(["sweep", str(p), "--no-progress"], capsys)
    assert code == 2 and str(p) in _one_clear_line(err)


@pytest.mark.parametrize("suffix,content", [(".npy", b""), (".pt", b"junk"), (".json", b"\xff"), (".csv", b"a,b")])
def test_garbage_kernel_file_on_the_command_line_is_one_clear_error(tmp_path, capsys, suffix, content):
    p = tmp_path / f"k{suffix}"
    p.write_bytes(content)
    code, err = _cli(["analyse", str(p)], capsys)
    assert code == 2 and str(p) in _one_clear_line(err)


@pytest.mark.parametrize(
    "flag,value",
    [("--pitch-um", "0"), ("--pitch-um", "-3"), ("--pitch-um", "nan"), ("--focal-mm", "0"), ("--focal-mm", "inf")],
)
def test_zero_negative_or_nan_pitch_and_focal_are_refused_not_ignored(capsys, flag, value):
    code, err = _cli(["analyse", "dog", flag, value], capsys)
    assert code == 2 and flag in _one_clear_line(err)


def test_ablation_workers_zero_is_refused_not_run_serially(capsys):
    code, err = _cli(["ablation", "--workers", "0", "--sizes", "1", "--seeds", "0", "--n-train", "2"], capsys)
    assert code == 2 and "--workers" in _one_clear_line(err)


def test_from_store_garbage_is_one_clear_error(tmp_path, capsys):
    (tmp_path / "runs.sqlite").write_bytes(b"not a database, just text\n" * 10)
    code, err = _cli(["ablation", "--from-store", "--out", str(tmp_path), "--sizes", "1", "--seeds", "0"], capsys)
    assert code == 2 and "runs.sqlite" in _one_clear_line(err)


def test_ablation_out_naming_a_file_is_one_clear_error(tmp_path, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    code, err = _cli(["ablation", "--out", str(f), "--sizes", "1", "--seeds", "0"], capsys)
    assert code == 2 and "--out" in _one_clear_line(err)


# ---------------------------------------------------------------------- limits
def test_a_million_point_sweep_is_refused_before_it_is_built(monkeypatch):
    axes = {
        "optics.focal_length_m": [1e-3 + 1e-6 * i for i in range(1000)],
        "sensor.threshold_on": [0.1 + 1e-4 * i for i in range(1000)],
    }
    d = parse_design({"realisations": {"include": ["delta"]}, "sweep": {"axes": axes}})
    from fsdvs_hw.explore.sweep import expand_points

    def build_point(self, over):  # refused before any point is built: with_overrides never runs
        raise AssertionError(f"a point was built before the size check: {over}")

    monkeypatch.setattr(type(d), "with_overrides", build_point)
    with pytest.raises(InputError) as info:
        expand_points(d)
    msg = str(info.value)
    assert "1,000,000 design points" in msg and "10,000" in msg and "GiB" in msg and "max_points" in msg
    from fsdvs_hw.explore.sweep import count_points

    assert count_points(d) == 10**6


def test_the_sweep_limit_can_be_raised():
    d = parse_design(
        {
            "realisations": {"include": ["delta"]},
            "run": {"max_points": 3},
            "sweep": {"axes": {"optics.focal_length_m": [1e-3, 2e-3, 3e-3, 4e-3]}},
        }
    )
    from fsdvs_hw.explore.sweep import expand_points

    with pytest.raises(InputError, match="4 design points"):
        expand_points(d)
    assert len(expand_points(d, max_points=4)) == 4


def test_sweep_command_builds_the_point_list_once(tmp_path, monkeypatch, capsys):
    import fsdvs_hw.explore.sweep as sweep

    calls = []
    real = sweep.expand_points
    monkeypatch.setattr(sweep, "expand_points", lambda *a, **k: calls.append(1) or real(*a, **k))
    (tmp_path / "d.toml").write_text(cheap_design("once"))
    code, err = _cli(
        ["sweep", str(tmp_path / "d.toml"), "--store", str(tmp_path / "s.sqlite"), "--no-progress"], capsys
    )
    assert code == 0, err
    assert len(calls) == 1


def test_a_huge_voxel_grid_is_refused_with_its_size_before_allocation():
    torch = pytest.importorskip("torch")
    from fsdvs_hw.sensor.simulation.events import EventList
    from fsdvs_hw.sensor.simulation.voxels import voxel_grid

    z = torch.zeros(1, dtype=torch.int64)
    ev = EventList(z, z.clone(), z.clone(), torch.zeros(1, dtype=torch.float64), torch.ones(1, dtype=torch.int8))
    with pytest.raises(InputError) as info:
        voxel_grid(ev, 10**6, timestamps_s=[0.0, 1.0], height=16, width=16)
    assert "3.81 GiB" in str(info.value) and "limit of 1 GiB" in str(info.value)
    frames = torch.zeros(1, 2, 2, 16, 16)
    with pytest.raises(InputError, match="voxel_grid"):
        voxel_grid(frames, 10**6)
    from fsdvs_hw.limits import allocation_limit

    with allocation_limit(2**20):  # overridable, here downwards: 1 MiB
        with pytest.raises(InputError, match="limit of 0.000977 GiB"):
            voxel_grid(ev, 4096, timestamps_s=[0.0, 1.0], height=16, width=16)
    assert voxel_grid(ev, 4, timestamps_s=[0.0, 1.0], height=16, width=16).shape == (1, 4, 16, 16)


# ---------------------------------------------------------------------- no data lost
def test_retry_errors_touches_only_the_design_being_run(tmp_path):
    from fsdvs_hw.explore.store import ResultsStore
    from fsdvs_hw.explore.sweep import run_design

    store = tmp_path / "shared.sqlite"
    failing = {"realisations": {"include": ["asic"], "asic": {"scale": 1e6}}, "emulation": {"enabled": False}}
    a = parse_design({**failing, "design": {"name": "a"}})
    b = parse_design({**failing, "design": {"name": "b"}, "sensor": {"threshold_on": 0.3}})
    run_design(a, store, workers=1, progress=False)
    run_design(b, store, workers=1, progress=False)
    with ResultsStore(store) as s:
        b_rows = {r["key"]: r["finished_at"] for r in s.rows(design="b")}
    assert len(b_rows) == 1
    summary, _ = run_design(a, store, workers=1, progress=False, retry_errors=True)
    assert summary.ran == 1
    with ResultsStore(store) as s:
        assert {r["key"]: r["finished_at"] for r in s.rows(design="b")} == b_rows


def _children(pid: int) -> set[int]:
    out = set()
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.add(int(d.name))
    return out


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except OSError:
        return "resource_tracker"  # gone already: not a worker to wait for


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_sweep_workers_die_when_the_main_process_is_killed(tmp_path):
    focals = [round(2e-3 + 1e-5 * i, 8) for i in range(400)]
    design = tmp_path / "many.toml"
    design.write_text(cheap_design("many") + f'[sweep]\naxes = {{ "optics.focal_length_m" = {focals} }}\n')
    cmd = [
        sys.executable,
        "-m",
        "fsdvs_hw.cli",
        "sweep",
        str(design),
        "--store",
        str(tmp_path / "s.sqlite"),
        "--workers",
        "2",
        "--no-progress",
    ]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers: set[int] = set()
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            # spawn's resource tracker is a child too; the pool's workers are the other ones
            kids = {k for k in _children(proc.pid) if "resource_tracker" not in _cmdline(k)}
            if len(kids) >= 2:
                workers = kids
                break
            time.sleep(0.1)
        assert len(workers) >= 2, "the sweep did not start its worker processes"
        time.sleep(1.0)  # let them pick up points
        os.kill(proc.pid, signal.SIGKILL)  # the main process only, no clean-up
        proc.wait(timeout=30)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.1)
        assert not any(_alive(w) for w in workers), "worker processes outlived their parent"
    finally:
        for w in workers:  # only the processes this test started
            try:
                os.kill(w, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if proc.poll() is None:
            proc.kill()


# ---------------------------------------------------------------------- Dask with TLS
def _make_certs(d: Path) -> tuple[Path, Path, Path]:
    """A throw-away CA and one certificate signed by it (for 127.0.0.1), with openssl."""
    import shutil

    if shutil.which("openssl") is None:
        pytest.skip("openssl not installed")
    ca_key, ca, key, csr, cert = (d / n for n in ("ca.key", "ca.pem", "node.key", "node.csr", "node.pem"))
    run = lambda *a: subprocess.run(a, check=True, capture_output=True)  # noqa: E731
    run(
        "openssl",
        "req",
        "-x509",
        "-nodes",
        "-newkey",
        "rsa:2048",
        "-days",
        "1",
        "-keyout",
        str(ca_key),
        "-out",
        str(ca),
        "-subj",
        "/CN=fsdvs test CA",
    )
    run(
        "openssl",
        "req",
        "-nodes",
        "-newkey",
        "rsa:2048",
        "-keyout",
        str(key),
        "-out",
        str(csr),
        "-subj",
        "/CN=127.0.0.1",
    )
    ext = d / "ext.cnf"
    ext.write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    run(
        "openssl",
        "x509",
        "-req",
        "-in",
        str(csr),
        "-CA",
        str(ca),
        "-CAkey",
        str(ca_key),
        "-CAcreateserial",
        "-out",
        str(cert),
        "-days",
        "1",
        "-extfile",
        str(ext),
    )
    return ca, cert, key


def test_sweep_runs_on_a_tls_only_dask_cluster_and_plain_clients_are_refused(tmp_path):
    distributed = pytest.importorskip("distributed")
    from fsdvs_hw.explore.store import ResultsStore
    from fsdvs_hw.explore.sweep import dask_security, expand_points, run_points

    ca, cert, key = _make_certs(tmp_path)
    sec = distributed.Security(
        tls_ca_file=str(ca),
        tls_scheduler_cert=str(cert),
        tls_scheduler_key=str(key),
        tls_worker_cert=str(cert),
        tls_worker_key=str(key),
        tls_client_cert=str(cert),
        tls_client_key=str(key),
        require_encryption=True,
    )
    (tmp_path / "d.toml").write_text(
        cheap_design("tls") + '[sweep]\naxes = { "optics.focal_length_m" = [2e-3, 3e-3] }\n'
    )
    pts = expand_points(load_design(tmp_path / "d.toml"))
    with distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        host="127.0.0.1",
        dashboard_address=None,
        protocol="tls://",
        security=sec,
    ) as cluster:
        assert cluster.scheduler_address.startswith("tls://")
        with ResultsStore(tmp_path / "s.sqlite") as store:
            summary = run_points(
                pts, store, scheduler=cluster.scheduler_address, progress=False, security=dask_security(ca, cert, key)
            )
        assert summary.statuses == {"ok": len(pts)} and "Dask" in summary.executor
        plain = cluster.scheduler_address.replace("tls://", "tcp://")
        with ResultsStore(tmp_path / "t.sqlite") as store:
            with pytest.raises(InputError, match="cannot connect"):
                run_points(pts, store, scheduler=plain, progress=False)


def test_tls_flags_need_a_tls_scheduler_and_existing_files(tmp_path, capsys):
    pytest.importorskip("distributed")
    (tmp_path / "d.toml").write_text(cheap_design("d"))
    code, err = _cli(
        [
            "sweep",
            str(tmp_path / "d.toml"),
            "--tls-ca-file",
            "ca.pem",
            "--tls-cert",
            "c.pem",
            "--scheduler",
            "tcp://127.0.0.1:1",
            "--no-progress",
        ],
        capsys,
    )
    assert code == 2 and "tls://" in _one_clear_line(err)
    code, err = _cli(
        [
            "sweep",
            str(tmp_path / "d.toml"),
            "--tls-ca-file",
            str(tmp_path / "none.pem"),
            "--tls-cert",
            "c.pem",
            "--scheduler",
            "tls://127.0.0.1:1",
            "--no-progress",
        ],
        capsys,
    )
    assert code == 2 and "none.pem" in _one_clear_line(err)


def test_plain_tcp_to_a_remote_scheduler_warns_about_pickles():
    from fsdvs_hw.explore.sweep import _loopback

    assert _loopback("tcp://127.0.0.1:8786") and _loopback("tcp://localhost:1") and _loopback("tcp://[::1]:1")
    assert not _loopback("tcp://10.0.0.5:8786") and not _loopback("tcp://example.org:8786")
