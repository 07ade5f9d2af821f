"""Sweeps and the results store: one row per point, resume after a real kill, Dask on loopback."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.design import load_design, parse_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.explore.scoring import accuracy_losses, fit_realisation, score
from fsdvs_hw.explore.store import ResultsStore
from fsdvs_hw.explore.sweep import evaluate_point, expand_points, run_points
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.realise.base import kernel_error
from fsdvs_hw.records import ScoredPoint
from fsdvs_hw.report.tables import score_rows

REPO = Path(__file__).resolve().parents[1]

# Cheap points: the ideal references only, swept over the optics (each point ~0.1-0.5 s).
_CHEAP = """
[realisations]
include = ["learned", "delta"]
[analysis]
csf_methods = ["mannos_sakrison_1974"]
[emulation]
enabled = false
[sweep]
axes = {{ "optics.focal_length_m" = {focals} }}
[run]
workers = 1
"""


def _cheap_design(tmp_path: Path, n_focal: int) -> Path:
    focals = [round(2e-3 + 0.5e-3 * i, 6) for i in range(n_focal)]
    p = tmp_path / "cheap.toml"
    p.write_text(_CHEAP.format(focals=focals))
    return p


# ---------------------------------------------------------------------- store
def test_store_keeps_the_first_final_row_and_replaces_skipped(tmp_path):
    with ResultsStore(tmp_path / "r.sqlite") as s:
        assert s.add("a", design="d", realisation="mesh", params={}, status="skipped", result={"reason": "x"}, wall_s=0)
        assert "a" not in s.done()  # skipped points are retried
        assert s.add("a", design="d", realisation="mesh", params={}, status="ok", result={"v": 1}, wall_s=1)
        assert not s.add("a", design="d", realisation="mesh", params={}, status="ok", result={"v": 2}, wall_s=1)
        assert s.done() == {"a"} and len(s) == 1
        (row,) = list(s.rows())
        assert row["result"] == {"v": 1} and row["status"] == "ok"
        s.add("b", design="d", realisation="asic", params={"asic.bits": 4}, status="error", result={}, wall_s=0)
        assert s.forget(status="error", keys=["a", "b"]) == 1 and s.done() == {"a"}
    with ResultsStore(tmp_path / "r.sqlite") as s:  # persisted
        assert s.done() == {"a"}


def test_store_rejects_a_file_that_is_not_sqlite(tmp_path):
    p = tmp_path / "bad.sqlite"
    p.write_text("definitely not a database " * 100)
    with pytest.raises(InputError, match="not a usable results store"):
        ResultsStore(p)


# ---------------------------------------------------------------------- scoring plumbing
def test_reference_scores_are_exact():
    k = reference_kernel("dog", 7)
    real, _ = fit_realisation("delta", k)
    rec = score(real, target=k, csf_methods=["mannos_sakrison_1974"])
    delta = np.zeros((7, 7))
    delta[3, 3] = 1.0
    assert rec.kernel_error == pytest.approx(np.linalg.norm(delta - k.taps) / np.linalg.norm(k.taps))
    assert rec.kernel_error == pytest.approx(kernel_error(real.kernel(), k))
    # a delta has a flat response: no correlation with any CSF
    assert rec.csf_correlation("mannos_sakrison_1974") == 0.0
    learned, _ = fit_realisation("learned", k)
    rec2 = score(learned, target=k, csf_methods=["mannos_sakrison_1974"])
    assert rec2.kernel_error == 0.0
    from fsdvs_hw.csf import Geometry, csf_agreement

    direct = csf_agreement(k, method="mannos_sakrison_1974", geometry=Geometry(k.pitch_m, 4e-3))
    assert rec2.csf_correlation("mannos_sakrison_1974") == pytest.approx(direct.correlation)
    assert rec2.tasks.status == "not requested" and rec2.tasks.metrics() == {}


def test_an_unregistered_realisation_is_an_input_error_naming_the_registered_ones():
    with pytest.raises(
        InputError, match="realisation 'fpga' unknown; allowed: learned, delta, mesh, mesh_process, asic, metalens"
    ):
        fit_realisation("fpga", reference_kernel("dog", 7))


def test_paired_losses_through_a_plugged_per_clip_evaluator(monkeypatch, tmp_path):
    """A stand-in per-clip evaluator: clip i is 'correct' when i < 100·centre tap. The loss of the delta
    against the learned row must be exact (learned − delta) with a CI from the clip resampling."""
    from fsdvs_hw.explore import paired, scoring
    from fsdvs_hw.stats import ClipMeans

    calls = []

    def clip_evidence(kernel, task, checkpoint, *, n_test=None, sensor=None, seed_offset=0, clip_set=0, events_fn=None):
        calls.append((task, Path(checkpoint).name, n_test, seed_offset, clip_set))
        if task == "segmentation":
            raise InputError("checkpoint missing")
        values = (np.arange(100) < 100 * float(kernel.centre)).astype(float)
        return paired.ClipEvidence(
            task,
            "top1",
            float(values.mean()),
            100,
            ClipMeans(values),
            str(checkpoint),
            seed_offset,
            0.0,
            test_seed=1000 + clip_set,
            event_rate=0.1,
        )

    monkeypatch.setattr(paired, "clip_evidence", clip_evidence)
    monkeypatch.setattr(scoring, "task_sensor", lambda ckpt, design_sensor: (None, {"source": "checkpoint"}))
    k = reference_kernel("dog", 7)
    rows = []
    for name in ("learned", "delta"):
        real, _ = fit_realisation(name, k)
        rec = score(
            real,
            target=k,
            csf_methods=["mannos_sakrison_1974"],
            checkpoints={
                "recognition": [tmp_path / "r0.safetensors", tmp_path / "r1.safetensors"],
                "segmentation": tmp_path / "s",
            },
            task_options={"n_test": 100, "tracks": ["simulator"]},
        )
        rows.append({"key": name, "realisation": name, "params": {}, "status": "ok", "result": rec.to_dict()})
    # each network its own mismatch pattern and its own clip set (the default test_clips = "per_network")
    assert calls[:2] == [("recognition", "r0.safetensors", 100, 0, 0), ("recognition", "r1.safetensors", 100, 1, 1)]
    rec = rows[1]["result"]["tasks"]["recognition"]["simulator"]
    assert rec["n_seeds"] == 2 and rec["n_clips"] == 200 and rec["n_clips_per_network"] == 100
    assert rec["test_seeds"] == [1000, 1001] and rec["metric"] == 1.0  # delta's centre tap is 1
    assert rows[1]["result"]["tasks"]["segmentation"]["simulator"]["status"] == "unavailable: checkpoint missing"
    losses = scoring.paired_losses(rows, n_resamples=500)
    d = losses["delta"]["simulator"]["recognition"]
    expected = np.count_nonzero(np.arange(100) < 100 * k.centre) / 100 - 1.0
    assert d["estimate"] == pytest.approx(rows[0]["result"]["tasks"]["recognition"]["simulator"]["metric"] - 1.0)
    assert d["estimate"] == pytest.approx(expected)
    assert d["low"] <= d["estimate"] <= d["high"] and d["n_seeds_reference"] == 2 and d["clip_design"] == "nested"
    assert losses["learned"]["simulator"]["recognition"]["estimate"] == 0.0
    assert losses["delta"]["simulator"]["weighted"]["estimate"] == pytest.approx(d["estimate"])  # one task scored
    lean = scoring.with_paired_losses([ScoredPoint.from_dict(r) for r in rows], n_resamples=200)
    assert "evidence" not in lean[1].score.tasks.tracks["recognition"]["simulator"].extra
    assert "evidence" in rows[1]["result"]["tasks"]["recognition"]["simulator"]  # the stored record is untouched
    assert lean[1].paired_loss.reference == "learned"


# ---------------------------------------------------------------------- running points
def test_run_resume_skips_finished_points(tmp_path):
    d = load_design(_cheap_design(tmp_path, 3))
    pts = expand_points(d)
    assert len(pts) == 6
    with ResultsStore(tmp_path / "s.sqlite") as store:
        first = run_points(pts[:4], store, progress=False)
        assert first.ran == 4 and first.already_done == 0
        again = run_points(pts, store, progress=False, workers=2)  # the rest on a spawned local pool
        assert again.already_done == 4 and again.ran == 2 and again.statuses == {"ok": 2}
        assert again.executor == "2 local processes"
        rows = list(store.rows())
    pool_rows = [r for r in rows if r["key"] in {p.key for p in pts[4:]}]
    assert all(not r["worker"].endswith(f":{os.getpid()}") for r in pool_rows)
    assert sorted(r["key"] for r in rows) == sorted(p.key for p in pts)
    # the ppd follows the swept focal length: a longer lens gives more pixels per degree
    learned = sorted(
        (r for r in rows if r["realisation"] == "learned"), key=lambda r: r["params"]["optics.focal_length_m"]
    )
    ppd = [r["result"]["csf"]["mannos_sakrison_1974"]["pixels_per_degree"] for r in learned]
    assert ppd == sorted(ppd) and ppd[0] < ppd[-1]


def test_failed_point_is_recorded_with_its_reason(tmp_path):
    # a fixed scale at which every tap rounds to zero: valid on its own, fails only at the fit
    d = parse_design({"realisations": {"include": ["asic"], "asic": {"scale": 1e6}}, "emulation": {"enabled": False}})
    (p,) = expand_points(d)
    res = evaluate_point(p)
    assert res["status"] == "error"
    assert "all-zero" in res["result"]["reason"]


def test_fitter_warnings_are_kept_with_the_score():
    # a DoG with centre tap 0.29 is out of reach of a mesh with pixel weight 1, the absolute gain
    # fixed (not the default) and λ ≥ 1 px
    d = parse_design(
        {
            "realisations": {
                "include": ["mesh"],
                "mesh": {
                    "n_init": 3,
                    "max_iter": 30,
                    "pixel_weight": 1.0,
                    "gain": "fixed",
                    "bounds": {"conductance_s": [1e-10, 1e-8]},
                },
            },
            "analysis": {"csf_methods": ["mannos_sakrison_1974"]},
            "emulation": {"enabled": False},
        }
    )
    (p,) = expand_points(d)
    res = evaluate_point(p)
    assert res["status"] == "ok"
    assert any(w.startswith("MeshFitWarning") and "out of reach" in w for w in res["result"]["warnings"])
    rows = score_rows([ScoredPoint.from_dict({**res, "realisation": "mesh", "params": {}})])
    assert "MeshFitWarning" in rows[0]["warnings"]


def test_failed_points_are_final_unless_retried(tmp_path):
    from fsdvs_hw.explore.sweep import run_design

    d = parse_design({"realisations": {"include": ["asic"], "asic": {"scale": 1e6}}, "emulation": {"enabled": False}})
    s1, rows = run_design(d, tmp_path / "e.sqlite", workers=1, progress=False)
    assert s1.statuses == {"error": 1} and rows[0].status == "error"
    s2, _ = run_design(d, tmp_path / "e.sqlite", workers=1, progress=False)
    assert s2.ran == 0 and s2.already_done == 1
    s3, rows3 = run_design(d, tmp_path / "e.sqlite", workers=1, progress=False, retry_errors=True)
    assert s3.ran == 1 and len(rows3) == 1


def _count(db: Path) -> int:
    if not db.exists():
        return 0
    try:
        with sqlite3.connect(db, timeout=5) as c:
            return int(c.execute("SELECT COUNT(*) FROM points").fetchone()[0])
    except sqlite3.OperationalError:
        return 0


def test_killed_sweep_resumes_with_every_point_exactly_once(tmp_path):
    design = _cheap_design(tmp_path, 12)
    n_points = 24
    db = tmp_path / "killed.sqlite"
    cmd = [
        sys.executable,
        "-m",
        "fsdvs_hw.cli",
        "sweep",
        str(design),
        "--store",
        str(db),
        "--workers",
        "1",
        "--no-progress",
    ]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.monotonic() + 120
    while _count(db) < 3 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # the process and anything it started, no clean-up
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    with ResultsStore(db) as store:
        before = {r["key"]: (r["finished_at"], r["worker"]) for r in store.rows()}
    assert 3 <= len(before) < n_points, "the kill must land mid-sweep"

    r = subprocess.run(
        [*cmd, "--report", str(tmp_path / "report")], cwd=REPO, capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "report" / "report.html").is_file()
    assert f"{len(before)} already in the store, {n_points - len(before)} run now" in r.stderr
    with ResultsStore(db) as store:
        rows = list(store.rows())
    keys = [r["key"] for r in rows]
    assert len(keys) == len(set(keys)) == n_points
    assert set(keys) == {p.key for p in expand_points(load_design(design))}
    for row in rows:  # rows finished before the kill are untouched
        if row["key"] in before:
            assert (row["finished_at"], row["worker"]) == before[row["key"]]
    assert all(r["status"] == "ok" for r in rows)


def test_sweep_on_a_dask_local_cluster_over_loopback(tmp_path):
    distributed = pytest.importorskip("distributed")
    d = load_design(_cheap_design(tmp_path, 2))
    pts = expand_points(d)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None, protocol="tcp"
    ) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        with ResultsStore(tmp_path / "dask.sqlite") as store:
            summary = run_points(pts, store, scheduler=cluster.scheduler_address, progress=False)
            rows = {r["key"]: r for r in store.rows()}
    assert summary.statuses == {"ok": len(pts)} and "Dask" in summary.executor
    assert set(rows) == {p.key for p in pts}
    assert all(not r["worker"].endswith(f":{os.getpid()}") for r in rows.values())  # ran in the workers
    local = evaluate_point(pts[1])  # same point in this process gives the same score
    assert rows[pts[1].key]["result"]["kernel_error"] == pytest.approx(local["result"]["kernel_error"], rel=1e-12)


def test_bad_scheduler_address_is_a_clear_error(tmp_path):
    pytest.importorskip("distributed")
    d = load_design(_cheap_design(tmp_path, 1))
    with ResultsStore(tmp_path / "x.sqlite") as store:
        with pytest.raises(InputError, match="expected an address like tcp://HOST:PORT"):
            run_points(expand_points(d), store, scheduler="localhost:8786", progress=False)


@pytest.mark.slow
def test_explore_benchmark_quick_runs_and_executors_agree():
    from benchmarks.explore import bench_explore

    md = bench_explore(quick=True).markdown
    assert "### Emulation track" in md and "### Sweep executors" in md
    rows = [
        line for line in md.splitlines() if line.startswith("| ") and "points" not in line and "executor" not in line
    ]
    executor_rows = [r for r in rows if "process" in r or "Dask" in r]
    assert len(executor_rows) >= 2 and all(r.rstrip().endswith("| yes |") for r in executor_rows)


def test_real_task_evaluation_gives_accuracy_loss_against_the_learned_kernel(tmp_path):
    """Zero-shot swap into the shipped detection network (8 test clips): the delta's loss is exactly
    metric(learned) − metric(delta), and the design's sensor replaces the checkpoint's on request."""
    pytest.importorskip("torch")
    ckpt = REPO / "designs" / "kernels" / "learned_detection_7x7.safetensors"
    if not ckpt.is_file():
        pytest.skip("no shipped detection checkpoint in this checkout")
    from fsdvs_hw.explore.sweep import run_design

    raw = {
        "kernel": {"source": "file", "path": str(REPO / "designs" / "kernels" / "learned_detection_7x7.json")},
        "realisations": {"include": ["learned", "delta"]},
        "analysis": {"csf_methods": ["mannos_sakrison_1974"]},
        "emulation": {"enabled": False},
        "tasks": {"checkpoints": {"detection": str(ckpt)}, "n_test": 8},
    }
    _, rows = run_design(parse_design(raw, base_dir=REPO), tmp_path / "t.sqlite", workers=1, progress=False)
    rows = [r.to_dict() for r in rows]  # the stored records, JSON-ready
    res = {r["realisation"]: r["result"]["tasks"]["detection"]["simulator"] for r in rows}
    assert all(v["status"] == "ok" and 0.0 <= v["metric"] <= 1.0 for v in res.values())
    assert res["learned"]["sensor"]["source"] == "checkpoint"
    losses = accuracy_losses(rows)
    delta_key = next(r["key"] for r in rows if r["realisation"] == "delta")
    assert losses[delta_key]["detection/simulator"] == res["learned"]["metric"] - res["delta"]["metric"]
    raw["tasks"]["sensor"] = "design"
    raw["sensor"] = {"placement": "post_log", "threshold_on": 0.3, "threshold_off": 0.3}
    raw["realisations"]["include"] = ["learned"]
    _, rows2 = run_design(parse_design(raw, base_dir=REPO), tmp_path / "t.sqlite", workers=1, progress=False)
    det = rows2[0].to_dict()["result"]["tasks"]["detection"]["simulator"]
    assert det["sensor"] == {
        "source": "design",
        "threshold_on": 0.3,
        "threshold_off": 0.3,
        "threshold_sigma": 0.03,
        "placement": "post_log",
        "positivity": "pedestal",
    }
    assert rows2[0].key not in {r["key"] for r in rows}  # a different sensor is a different point
