"""`fsdvs-hw bench sim` (slow) and config round trips."""

from __future__ import annotations

import json
import re

import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import SensorConfig


def test_config_dict_round_trip_and_unknown_fields():
    cfg = SensorConfig(threshold_on=0.3, placement="post_log", surround_lambda_px=2.0, seed=9)
    assert SensorConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(InputError, match="unknown sensor field"):
        SensorConfig.from_dict({"treshold_on": 0.2})
    ideal = SensorConfig.ideal()
    assert not ideal.has_photoreceptor and ideal.shot_noise_rate_hz == 0 and ideal.threshold_sigma == 0


@pytest.mark.slow
def test_bench_sim_quick_tables():
    from benchmarks import BENCHMARKS, run_benchmark

    assert BENCHMARKS["sim"] == "benchmarks.sim:bench_sim"
    text = run_benchmark("sim", quick=True)
    assert "forward+backward" in text and "Mpixel-frames/s" in text
    # every plan row stays within its tolerance of the reference (frame L1 error column)
    rows = re.findall(r"\| plan_model tol ([0-9.]+) .*?\| \d+ \| ([0-9.]+) \| ([0-9.]+) \|", text)
    assert len(rows) == 3
    for tol, count_err, frame_err in rows:
        assert float(count_err) <= float(tol) and float(frame_err) <= float(tol)


def test_records_markdown_and_bad_cases():
    from benchmarks.sim import SIM_CASES, records_markdown, sim_records

    rec = {
        "case": "bikes/event list",
        "clip": "bikes",
        "path": "event list",
        "resolution": "272x640",
        "n_frames": 250,
        "events": 10,
        "mpf_s_mean": 4.0,
        "mpf_s_std": 0.5,
        "mpf_s_min": 3.5,
        "mpf_s_max": 4.5,
        "cpu_s_mean": 1.0,
        "mpf_cpu_s_mean": 5.0,
        "mpf_cpu_s_std": 0.1,
        "repeats": 3,
        "peak_rss_mb": 600.0,
        "rss_base_mb": 400.0,
        "threads": 2,
        "settings": "v2e-default",
        "chunk_frames": 8,
        "torch": "x",
        "load_avg": 1.0,
    }
    text = records_markdown([rec])
    assert (
        "| bikes/event list | event list | bikes 272x640 | 250 | 10 | 4.00 ± 0.50 [3.50–4.50] | 5.00 ± 0.10 | 3 | 600 |"
        in text
    )
    # the same record as typed bench records (what `fsdvs-hw bench sim --json` writes): value, unit, spread
    from benchmarks.harness import BenchRecord
    from benchmarks.sim import _bench_records

    wall, cpu, rss = _bench_records([rec], quick=False)
    assert all(isinstance(r, BenchRecord) for r in (wall, cpu, rss))
    assert (wall.metric, wall.unit, wall.value, wall.repeats, wall.spread_min, wall.spread_max) == (
        "throughput (wall)",
        "Mpixel-frames/s",
        4.0,
        3,
        3.5,
        4.5,
    )
    assert (cpu.value, rss.metric, rss.unit, rss.value, wall.threads) == (5.0, "peak RSS", "MB", 600.0, 2)
    assert wall.case.startswith("bikes/event list: event list, bikes 272x640, 250 frames") and wall.timestamp
    assert BenchRecord.from_dict(wall.to_dict()) == wall
    assert {c["path"] for c in SIM_CASES.values()} >= {"frames", "event list", "forward+backward", "centre-surround"}
    with pytest.raises(InputError, match="unknown"):
        sim_records(cases=["bikes/nope"])
    with pytest.raises(InputError, match="repeats"):
        sim_records(cases=["bikes/frames"], repeats=0)


@pytest.mark.slow
def test_sim_records_child_measures_a_case():
    import json

    from benchmarks.sim import sim_records

    (r,) = sim_records(quick=True, cases=["synthetic/frames"], threads=1)
    json.dumps(r)  # plain values only
    assert r["n_frames"] == 17 and r["resolution"] == "120x160" and r["events"] > 0
    assert r["mpf_s_min"] <= r["mpf_s_mean"] <= r["mpf_s_max"] and r["mpf_s_mean"] > 0
    assert r["peak_rss_mb"] >= r["rss_base_mb"] > 50  # a fresh child's own peak, torch imported


def test_v2e_records_needs_a_v2e_checkout(tmp_path):
    from benchmarks.sim import v2e_records

    with pytest.raises(InputError, match="v2ecore/emulator.py"):
        v2e_records(str(tmp_path))


def test_default_cases_leave_out_the_long_and_absent_device_cases(monkeypatch):
    """`fsdvs-hw bench sim` runs the three clips' event lists by default; the 2-minute file cases
    only with --long; CUDA cases only where torch sees a CUDA device."""
    import torch

    from benchmarks.sim import SIM_CASES, V2E_CLIPS, default_cases

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    short, long = default_cases(), default_cases(long=True)
    assert {f"{c}/event list" for c in V2E_CLIPS} <= set(short)
    assert "long/h5" not in short and "long/h5" in long and set(short) < set(long)
    assert not any(SIM_CASES[n].get("device") == "cuda" for n in long)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert "bikes/event list cuda" in default_cases()


def test_comparisons_refuse_bad_input_and_print_the_ratio(tmp_path):
    from benchmarks.sim import compare_checkouts, compare_v2e, compare_v2e_markdown

    with pytest.raises(InputError, match="rounds"):
        compare_v2e(str(tmp_path), rounds=0)
    with pytest.raises(InputError, match="clip 'nope' unknown"):
        compare_v2e(str(tmp_path), clips=("nope",))
    with pytest.raises(InputError, match="no fsdvs_hw checkout"):
        compare_checkouts(str(tmp_path))
    row = {
        "clip": "bikes",
        "resolution": "272x640",
        "n_frames": 250,
        "events": 10,
        "v2e_events": 11,
        "ours_mpf_s": [40.0, 50.0, 60.0],
        "v2e_mpf_s": [4.0, 5.0, 6.0],
        "ours_mpf_cpu_s": [30.0],
        "v2e_mpf_cpu_s": [3.0],
        "ratio_median": 10.0,
        "ours_peak_rss_mb": 600.0,
        "v2e_peak_rss_mb": 700.0,
        "rounds": 3,
        "threads": 2,
        "device": "cpu",
        "load_avg": [1.0, 2.0, 1.5],
    }
    text = compare_v2e_markdown([row])
    assert "| bikes 272x640 × 250 | 5.00 [4.00–6.00] | 50.00 [40.00–60.00] | **10.00×** | 10.00× | 10 / 11 |" in text


@pytest.mark.skipif(not __import__("torch").cuda.is_available(), reason="needs a CUDA device")
def test_cuda_event_list_and_frames_match_the_cpu():
    """The torch path on CUDA against the CPU path (compiled kernels) on a small moving texture,
    v2e-clean without threshold mismatch (no random draws): event frames equal to within 0.1 % of the events (float32
    rounding of the comparator may move a crossing across a frame time), event counts per
    polarity within 0.5 %, event times within one frame interval of each other in order."""
    import torch

    from benchmarks.sim import moving_texture
    from fsdvs_hw.sensor import event_frames, event_list

    video = moving_texture(9, 48, 64, speed_px=1.5, level=0.3).float()
    # v2e-clean less its threshold mismatch: the mismatch pattern is drawn from each device's own
    # random stream (docs/your_data.md), so with it the two paths simulate different sensors
    cfg = SensorConfig.preset("v2e-clean").replace(threshold_sigma=0.0)
    cpu_f, gpu_f = event_frames(video, config=cfg), event_frames(video.cuda(), config=cfg).cpu()
    assert float((cpu_f - gpu_f).abs().sum()) <= 1e-3 * float(cpu_f.sum())
    cpu_e, gpu_e = event_list(video, config=cfg), event_list(video.cuda(), config=cfg)
    for pol in (1, -1):
        n_cpu, n_gpu = int((cpu_e.p == pol).sum()), int((gpu_e.p == pol).sum())
        assert abs(n_cpu - n_gpu) <= 0.005 * max(n_cpu, 1)
    assert bool((gpu_e.t[1:] >= gpu_e.t[:-1]).all())


def test_whole_command_comparison_runs_both_commands_and_counts_their_files(tmp_path):
    """The orchestration of ``--v2e-command`` with a stand-in v2e.py (it writes v2e's layout with
    as many events as the file's frames): both commands run, both files are counted, the
    ratio is v2e's median wall over ours; bad input is refused by name."""
    import json

    from benchmarks.sim import compare_v2e_command, compare_v2e_command_markdown

    with pytest.raises(InputError, match="no v2e.py there"):
        compare_v2e_command(str(tmp_path))
    (tmp_path / "v2e.py").write_text(
        "import argparse, h5py, json, numpy as np, os, sys\n"
        "ap = argparse.ArgumentParser(); ap.add_argument('-i'); ap.add_argument('--dvs_h5')\n"
        "ap.add_argument('--output_folder'); ap.add_argument('--output_width', type=int)\n"
        "ap.add_argument('--output_height', type=int)\n"
        "a, rest = ap.parse_known_args()\n"
        "assert {'--disable_slomo', '--skip_video_output', '--no_preview'} <= set(rest), rest\n"
        "import torchvision  # v2e.py imports it: the comparison's stub must be on the path\n"
        "os.makedirs(a.output_folder, exist_ok=True)\n"
        "with h5py.File(os.path.join(a.output_folder, a.dvs_h5), 'w') as f:\n"
        "    f['events'] = np.zeros((a.output_width * 0 + 7, 4), np.uint32)\n"
        "print(json.dumps([a.output_width, a.output_height]))\n"
    )
    with pytest.raises(InputError, match="rounds"):
        compare_v2e_command(str(tmp_path), rounds=0)
    with pytest.raises(InputError, match="clip 'nope' unknown"):
        compare_v2e_command(str(tmp_path), clips=("nope",))
    (row,) = compare_v2e_command(str(tmp_path), clips=("carphone",), rounds=1)
    assert row["v2e_events"] == 7 and row["events"] > 1000  # carphone at v2e-default: ~357 000
    assert row["resolution"] == "144×176" and len(row["ours_s"]) == len(row["v2e_s"]) == 1
    assert row["ratio_median"] == pytest.approx(row["v2e_s"][0] / row["ours_s"][0])
    assert row["ours_cpu_s"][0] > 0 and row["ours_peak_rss_mb"] > 50
    json.dumps(row)  # the record is JSON
    text = compare_v2e_command_markdown([{**row, "v2e_s": [6.0, 4.0], "ours_s": [2.0, 1.0]}])
    assert "| 5.00 [4.00–6.00] | 1.50 [1.00–2.00] |" in text


def test_comparison_records_carry_their_command_and_render_their_table():
    from benchmarks.sim import comparison_markdown, comparison_record

    row = {
        "clip": "bikes",
        "resolution": "272×640",
        "n_frames": 250,
        "events": 17_303_741,
        "v2e_events": 17_304_972,
        "ours_s": [8.0, 7.5, 8.5],
        "v2e_s": [19.0, 19.5, 18.0],
        "ours_cpu_s": [11.0],
        "v2e_cpu_s": [27.5],
        "ratio_median": 19.0 / 8.0,
        "ours_peak_rss_mb": 340.0,
        "v2e_peak_rss_mb": 590.0,
        "rounds": 3,
        "load_avg": [1.5, 1.6, 1.6],
    }
    rec = comparison_record("command", [row], "python -m benchmarks.sim --v2e-command SRC")
    assert rec["commit"] and rec["machine"]["cpu_count"] >= 1 and rec["versions"]["torch"]
    text = comparison_markdown(json.loads(json.dumps(rec)))
    assert "| bikes 272×640 × 250 | 19.00 [18.00–19.50] | 8.00 [7.50–8.50] | **2.38×** | 2.50× |" in text
    assert "command: `python -m benchmarks.sim --v2e-command SRC`" in text
    with pytest.raises(InputError, match="kind 'gpu' unknown"):
        comparison_markdown({**rec, "kind": "gpu"})


@pytest.mark.skipif(not __import__("os").path.isdir("/proc/self/task"), reason="needs Linux /proc")
def test_thread_cpu_names_every_event_list_thread():
    """The pipeline's workers carry their names at the OS level (unnamed threads read as the
    process name, 'python'), so each one's CPU time is read by name; the stepping thread does
    measurable work (bikes: frames above stream.INLINE_PIXELS, which run on the workers)."""
    from benchmarks.sim import thread_cpu_seconds

    r = thread_cpu_seconds("bikes", n_frames=12)
    assert r["frames"] == 12 and r["events"] > 1000
    assert {"stepping (main)", "fsdvs-emit", "fsdvs-sort"} <= set(r["cpu"])
    assert r["cpu"]["stepping (main)"] > 0 and all(v >= 0 for v in r["cpu"].values())
    with pytest.raises(InputError, match="clip 'nope' unknown"):
        thread_cpu_seconds("nope")


def test_h5_filter_costs_cover_the_writer_and_read_every_file_back():
    """Each filter setting and the toolkit's threaded writer write the same events, read back
    equal (the function raises otherwise); the shuffle filter shrinks the file."""
    from benchmarks.sim import h5_filter_costs

    rows = h5_filter_costs("carphone", n_frames=6, repeats=1)
    names = [r["filters"] for r in rows]
    assert names == [
        "gzip 4",
        "gzip 1",
        "shuffle + gzip 4",
        "shuffle + gzip 1",
        "the writer (shuffle + ISA-L deflate 1, 2 threads)",
    ]
    assert len({r["events"] for r in rows}) == 1 and rows[0]["events"] > 1000
    by = {r["filters"]: r for r in rows}
    assert by["shuffle + gzip 1"]["size_mib"] < by["gzip 1"]["size_mib"]
    assert all(r["cpu_ns_per_event"] > 0 and r["wall_ns_per_event"] > 0 for r in rows)


def test_ab_child_runs_in_and_imports_the_checkout_asked_for(tmp_path):
    """An A/B child runs in the other checkout (``python -c`` puts its working directory ahead of
    PYTHONPATH) and stops when the fsdvs_hw it imported is not that checkout's."""
    import sys
    from pathlib import Path

    from benchmarks.sim import _run_child

    report = (
        "import json, os, fsdvs_hw; print(json.dumps({'package': fsdvs_hw.__file__, 'cwd': os.getcwd(), "
        "'walls': [1.0], 'cpus': [1.0], 'height': 1, 'width': 1, 'n_frames': 1}))"
    )
    here = str(Path(__file__).resolve().parents[1])
    r, rates, _ = _run_child([sys.executable, "-c", report], "this checkout", root=here)
    assert Path(r["package"]).resolve().is_relative_to(Path(here)) and Path(r["cwd"]).resolve() == Path(here)
    assert rates == [1e-6]
    other = tmp_path / "other"
    (other / "fsdvs_hw").mkdir(parents=True)  # a checkout whose package is not importable as such
    fake = report.replace("fsdvs_hw.__file__", "'/elsewhere/fsdvs_hw/__init__.py'")
    with pytest.raises(RuntimeError, match="imported fsdvs_hw from /elsewhere/fsdvs_hw/__init__.py, not from"):
        _run_child([sys.executable, "-c", fake], "other checkout", root=str(other))


def test_checkout_ab_gives_both_sides_the_default_chunks(tmp_path, monkeypatch):
    """The A/B runs both checkouts with the chunks the command and the v2e comparison use
    (chunk_frames_for of the frame size), not one-frame chunks; an explicit value wins."""
    import numpy as np

    from benchmarks import sim
    from fsdvs_hw.sensor.simulation.stream import chunk_frames_for

    other = tmp_path / "other"
    (other / "fsdvs_hw" / "sensor").mkdir(parents=True)
    (other / "fsdvs_hw" / "sensor" / "__init__.py").write_text("")
    monkeypatch.setattr(sim, "save_clip_frames", lambda clip, path, **kw: np.save(path, np.zeros((3, 144, 176), "f4")))
    seen = []

    def child(cmd, what, root=None):
        seen.append(int(cmd[-1]))
        r = {"n_frames": 3, "height": 144, "width": 176, "events": 0, "peak_rss_mb": 1.0}
        return r, [1.0], [1.0]

    monkeypatch.setattr(sim, "_run_child", child)
    rows = sim.compare_checkouts(str(other), clips=("carphone",), rounds=1)
    assert seen == [chunk_frames_for(144, 176)] * 2 == [rows[0]["chunk_frames"]] * 2 and seen[0] > 1
    seen.clear()
    sim.compare_checkouts(str(other), clips=("carphone",), rounds=1, chunk_frames=1)
    assert seen == [1, 1]
