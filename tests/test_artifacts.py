"""Buildable artifacts: each realisation's files checked by the real tool, and an exploration writing them all.

ngspice runs the written deck and must reproduce the written operating point; the written
testbench must pass bit-exact in Icarus Verilog and the written Verilog must lint clean under
``verilator -Wall``; the written phase profile, reloaded and propagated, must reproduce the written
PSF. Each check is also shown to fail when the data it checks is wrong.
"""

from __future__ import annotations

import csv
import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import require_tool
from scipy.signal import correlate2d

from fsdvs_hw.design import parse_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.realise.artifacts import Artifact, read_index
from fsdvs_hw.realise.registry import REALISATIONS, RealisationSpec, get_realisation, realisation_names

# ---------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def target():
    return parse_design({}).target  # the shipped 7x7 learned detection kernel


@pytest.fixture(scope="module")
def mesh_dir(tmp_path_factory, target):
    from fsdvs_hw.realise.mesh import fit_resistive_mesh

    d = fit_resistive_mesh(target)
    out = tmp_path_factory.mktemp("mesh")
    written = get_realisation("mesh").write_artifacts_of(d, out)
    return d, out, written


@pytest.fixture(scope="module")
def asic_dir(tmp_path_factory, target):
    from fsdvs_hw.realise.asic import fit_asic_taps

    d = fit_asic_taps(target, bits=8)
    out = tmp_path_factory.mktemp("asic")
    written = get_realisation("asic").write_artifacts_of(d, out, resolution=(20, 27))
    return d, out, written


@pytest.fixture(scope="module")
def metalens_dir(tmp_path_factory):
    from fsdvs_hw.realise.metalens import fit_metalens

    d = fit_metalens(reference_kernel("dog", 5), n_wavelengths=3, n_terms=2, n_starts=1, max_iter=20, guard_px=1)
    out = tmp_path_factory.mktemp("metalens")
    written = get_realisation("metalens").write_artifacts_of(d, out)
    return d, out, written


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


# ---------------------------------------------------------------------------- registry
def test_every_hardware_realisation_declares_a_writer_and_the_references_none():
    for name in realisation_names("hardware"):
        assert get_realisation(name).write_artifacts, name
    for name in realisation_names("reference"):
        assert get_realisation(name).write_artifacts_of(None, "/nonexistent") == ()  # writes nothing, no folder


def test_writer_reference_and_returned_names_are_checked(tmp_path):
    spec = REALISATIONS["learned"]
    with pytest.raises(InputError, match="write_artifacts must be 'module:name'"):
        RealisationSpec(name="x", fit=spec.fit, write_artifacts="no_colon_here")
    rogue = RealisationSpec(
        name="x", fit=spec.fit, artifacts={"a": "declared"}, write_artifacts=f"{__name__}:_undeclared_writer"
    )
    with pytest.raises(InputError, match="returned 'b'; declared artifacts: a"):
        rogue.write_artifacts_of(None, tmp_path)


def _undeclared_writer(record, out_dir, **_):
    return (Artifact("b", Path(out_dir) / "b.txt", "not declared"),)


def test_written_names_are_the_declared_ones(mesh_dir, asic_dir, metalens_dir):
    from fsdvs_hw.realise.asic.sky130_artifacts import SKY130_ARTIFACTS  # written only when built in sky130

    for name, (_, out, written) in (("mesh", mesh_dir), ("asic", asic_dir), ("metalens", metalens_dir)):
        assert {a.name for a in written} == set(get_realisation(name).artifacts) - set(SKY130_ARTIFACTS), name
        for a in written:
            assert a.path.is_file() and a.path.parent == out and a.path.stat().st_size > 0


# ---------------------------------------------------------------------------- mesh
def _deck_nodal_solve(deck: str, prefix: str, i_in: float) -> dict[str, float]:
    """Node voltages of one mesh from the deck's own resistor values (an independent dense solve)."""
    nodes: dict[str, int] = {}
    elems = []
    for line in deck.splitlines():
        m = re.match(rf"^R\w+ ({prefix}\d+_\d+) (\S+) (\S+)$", line)
        if m:
            a, b, r = m.group(1), m.group(2), float(m.group(3))
            for n in (a, b):
                if n != "0":
                    nodes.setdefault(n, len(nodes))
            elems.append((a, b, 1.0 / r))
    g = np.zeros((len(nodes), len(nodes)))
    for a, b, cond in elems:
        ia, ib = nodes[a], nodes.get(b)
        g[ia, ia] += cond
        if ib is not None:
            g[ib, ib] += cond
            g[ia, ib] -= cond
            g[ib, ia] -= cond
    src = re.search(rf"^IIN\w 0 ({prefix}\d+_\d+) DC (\S+)$", deck, re.M)
    assert src and float(src.group(2)) == i_in
    rhs = np.zeros(len(nodes))
    rhs[nodes[src.group(1)]] = i_in
    v = np.linalg.solve(g, rhs)
    return {n: v[i] for n, i in nodes.items()}


def _op_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_mesh_operating_point_is_the_decks_own_circuit(mesh_dir):
    """The CSV's voltages solve the deck's resistor network (parsed from the file, dense solve)."""
    d, out, _ = mesh_dir
    deck = (out / "mesh.cir").read_text()
    assert deck.splitlines()[0].startswith("* run: ngspice -b mesh.cir -r mesh.raw")
    rows = _op_rows(out / "operating_point.csv")
    for prefix, col in (("n", "v_narrow_V"), ("w", "v_wide_V")):
        v = _deck_nodal_solve(deck, prefix, 1e-9)
        key = "node_narrow" if prefix == "n" else "node_wide"
        got = np.array([float(r[col]) for r in rows])
        ref = np.array([v[r[key]] for r in rows])
        assert np.abs(got - ref).max() <= 1e-12 * np.abs(ref).max()
    # the kernel taps the operating point implies are the design's kernel, up to the patch truncation
    n = math.isqrt(len(rows))
    k = np.array([float(r["kernel_tap_1"]) for r in rows]).reshape(n, n)
    h = n // 2
    assert np.abs(k[h - 3 : h + 4, h - 3 : h + 4] - d.kernel_taps(7)).max() < 1e-3 * np.abs(d.kernel_taps(7)).max()
    i_n = np.array([float(r["i_narrow_A"]) for r in rows])
    assert np.allclose(i_n, d.g_vertical_narrow_s * np.array([float(r["v_narrow_V"]) for r in rows]), rtol=1e-15)


@pytest.mark.tools
def test_ngspice_runs_the_written_deck_and_reproduces_the_operating_point(mesh_dir, tmp_path):
    require_tool("ngspice")
    from fsdvs_hw.realise.mesh.artifacts import OP_RTOL, check_mesh_artifacts

    _, out, _ = mesh_dir
    res = check_mesh_artifacts(_copy(out, tmp_path / "ok"))
    assert res["max_rel_error"] <= OP_RTOL and res["nodes"] == 2 * len(_op_rows(out / "operating_point.csv"))
    # a wrong operating point (one node 1e-6 off) is caught
    bad = _copy(out, tmp_path / "bad")
    rows = _op_rows(bad / "operating_point.csv")
    rows[len(rows) // 2]["v_narrow_V"] = repr(float(rows[len(rows) // 2]["v_narrow_V"]) * (1 + 1e-6))
    with open(bad / "operating_point.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with pytest.raises(InputError, match="differ from operating_point.csv"):
        check_mesh_artifacts(bad)


# ---------------------------------------------------------------------------- asic
def _read_hex(path: Path, bits: int, signed: bool) -> np.ndarray:
    v = np.array([int(x, 16) for x in path.read_text().split()], dtype=np.int64)
    return np.where(v >= 1 << (bits - 1), v - (1 << bits), v) if signed else v


def test_expected_vectors_are_the_correlation_of_the_stimulus(asic_dir):
    """expected.hex = valid-mode correlation of stimulus.hex with the taps (scipy, not our integer model)."""
    from fsdvs_hw.realise.asic.arith import output_bits

    d, out, _ = asic_dir
    x = _read_hex(out / "stimulus.hex", d.input_bits, signed=False).reshape(2, 20, 27)
    assert x.max() == 255 and x.min() == 0 and set(np.unique(x[1])) == {0, 255}
    ob = output_bits(d.taps, d.input_bits)
    got = _read_hex(out / "expected.hex", ob, signed=True)
    ref = np.concatenate([correlate2d(f, d.taps, mode="valid").ravel() for f in x])
    assert np.array_equal(got, ref)
    taps = {(int(r["y_px"]), int(r["x_px"])): int(r["tap_int"]) for r in _op_rows(out / "taps.csv")}
    assert all(taps[(y, xx)] == d.taps[y, xx] for y in range(7) for xx in range(7))


@pytest.mark.tools
def test_written_testbench_passes_bit_exact_and_fails_on_a_wrong_vector(asic_dir, tmp_path):
    for tool in ("iverilog", "vvp", "verilator"):
        require_tool(tool)
    from fsdvs_hw.realise.asic.artifacts import check_asic_artifacts

    _, out, _ = asic_dir
    n_expected = len((out / "expected.hex").read_text().split())
    res = check_asic_artifacts(_copy(out, tmp_path / "ok"))
    assert res["pass_line"] == f"PASS: {n_expected} outputs bit-exact" and res["lint_warnings"] == 0
    bad = _copy(out, tmp_path / "bad")
    lines = (bad / "expected.hex").read_text().split()
    lines[3] = format(int(lines[3], 16) ^ 1, f"0{len(lines[3])}x")  # one bit flipped in one expected output
    (bad / "expected.hex").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="FAIL: 1 of"):
        check_asic_artifacts(bad)


@pytest.mark.tools
@pytest.mark.parametrize("bits,symmetry,out_shift,k", [(8, "8-fold", 0, 7), (4, "quadrant", 2, 5), (6, "none", 5, 3)])
def test_verilator_reports_no_warning_on_the_generated_verilog(tmp_path, bits, symmetry, out_shift, k):
    """Widths are explicit in the generator (no lint_off): the streaming filter and the synthesis datapath."""
    import subprocess

    verilator = require_tool("verilator")
    from fsdvs_hw.realise.asic import fit_asic_taps
    from fsdvs_hw.realise.asic.rtl import generate_datapath_verilog, generate_verilog

    q = fit_asic_taps(reference_kernel("dog", k), bits=bits, symmetry=symmetry).taps
    for name, src in (
        (
            "fsdvs_conv",
            generate_verilog(q, input_bits=8, image_width=33, image_height=9, out_shift=out_shift, symmetry=symmetry),
        ),
        ("fsdvs_datapath", generate_datapath_verilog(q, input_bits=8, out_shift=out_shift, symmetry=symmetry)),
    ):
        assert "lint_off" not in src
        (tmp_path / f"{name}.v").write_text(src)
        r = subprocess.run(
            [verilator, "--lint-only", "-Wall", f"{name}.v"], cwd=tmp_path, capture_output=True, text=True, timeout=120
        )
        assert r.returncode == 0 and "%Warning" not in r.stderr + r.stdout, r.stderr[-1500:]


# ---------------------------------------------------------------------------- metalens
def test_phase_profile_files_hold_the_lens_in_si_units(metalens_dir):
    from fsdvs_hw.realise.metalens.artifacts import read_phase_profile_csv

    d, out, _ = metalens_dir
    g = d.geometry
    with np.load(out / "phase_profile.npz") as z:
        data = dict(z)
    assert data["radius_m"][0] == 0 and data["radius_m"][-1] == pytest.approx(g.aperture_m / 2, rel=1e-15)
    assert float(data["focal_length_m"]) == g.focal_length_m
    assert float(data["numerical_aperture"]) == pytest.approx(
        (g.aperture_m / 2) / math.hypot(g.aperture_m / 2, g.focal_length_m)
    )
    assert np.array_equal(data["wavelengths_m"], d.spectral.wavelengths_m)
    assert float(data["wavelength_weights"].sum()) == pytest.approx(1.0)
    assert float(data["pixel_pitch_m"]) == d.target.pitch_m
    # phase 0 on the axis; the hyperbolic term dominates at the rim: -2π/λ0 (√(a²+f²) − f) plus the polynomial
    a, f, lam0 = g.aperture_m / 2, g.focal_length_m, g.design_wavelength_m
    rim = -2 * math.pi / lam0 * (math.hypot(a, f) - f) + sum(d.coefficients[0])
    assert data["phase_rad"][0, 0] == 0 and data["phase_rad"][0, -1] == pytest.approx(rim, rel=1e-12)
    r, ph = read_phase_profile_csv(out / "phase_profile.csv")
    assert np.array_equal(r, data["radius_m"]) and np.array_equal(ph, data["phase_rad"])
    with open(out / "phase_profile.csv") as fh:
        rows = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    wrapped = np.array([float(row["phase_wrapped_rad"]) for row in rows])
    assert wrapped.min() >= 0 and wrapped.max() < 2 * math.pi
    with np.load(out / "psf.npz") as z:
        assert np.array_equal(z["psf"][0], d.psfs[0]) and np.allclose(z["kernel"], d.kernel().taps, rtol=0, atol=0)
    import matplotlib.image as mpimg

    img = mpimg.imread(out / "phase_psf.png")
    assert img.shape[1] > 500 and float(np.std(img[..., :3])) > 0.02


def test_reloaded_phase_profile_reproduces_the_written_psf(metalens_dir, tmp_path):
    """NPZ and CSV reloaded, spline-interpolated onto the pupil nodes and propagated: the written PSF."""
    from fsdvs_hw.realise.metalens.artifacts import PSF_RTOL, check_metalens_artifacts, psf_from_phase_profile

    _, out, _ = metalens_dir
    res = check_metalens_artifacts(out)
    assert res["rel_error_npz"] <= PSF_RTOL and res["rel_error_csv"] <= PSF_RTOL
    assert res["phase_error_rad"] < 1e-7  # the interpolation error that the tolerance is built on
    # a 10 mrad quadratic phase error, a wrong wavelength or sensor distance: each is caught
    with np.load(out / "phase_profile.npz") as z:
        data = dict(z)
    written = np.load(out / "psf.npz")["psf"]
    rho2 = (data["radius_m"] / data["radius_m"][-1]) ** 2
    for change in (
        {"phase_rad": data["phase_rad"] + 1e-2 * rho2},
        {"wavelengths_m": data["wavelengths_m"] * 1.001},
        {"sensor_distance_m": data["sensor_distance_m"] + 1e-7},
    ):
        psf = psf_from_phase_profile({**data, **change})["psf"]
        assert np.linalg.norm(psf - written) / np.linalg.norm(written) > 100 * PSF_RTOL, list(change)


# ---------------------------------------------------------------------------- an exploration writes them all
def test_swept_points_get_their_own_folders_and_a_failing_writer_is_recorded(tmp_path, monkeypatch):
    from fsdvs_hw.explore.point_artifacts import point_folder_name, write_exploration_artifacts
    from fsdvs_hw.realise import registry

    assert point_folder_name("asic", {}) == "asic"
    assert point_folder_name("asic", {"asic.bits": 4, "sensor.threshold_on": 0.2}) == "asic__bits-4__threshold_on-0.2"
    assert "/" not in point_folder_name("asic", {"asic.x": "../../etc"})
    import dataclasses

    monkeypatch.setitem(
        registry._REGISTRY,
        "mesh",
        dataclasses.replace(registry.get_realisation("mesh"), write_artifacts=f"{__name__}:_failing_writer"),
    )
    from fsdvs_hw.records import Score, ScoredPoint

    record = {"kind": "reference", "kernel": reference_kernel("delta", 3).to_dict(), "label": "x"}
    score = Score("reference", "x", "", reference_kernel("delta", 3), 0.0, 0.0, 1.0, 0.0, realisation=record)
    pts = [
        ScoredPoint("m", "mesh", {}, "ok", score=score),
        ScoredPoint("l", "learned", {}, "ok", score=score),
        ScoredPoint("a", "asic", {}, "error", failure={"reason": "x"}),
    ]
    path, entries = write_exploration_artifacts(pts, tmp_path)
    assert [(e["point"], e["error"]) for e in entries] == [("mesh", "RuntimeError: disk full")]
    assert read_index(path) == entries


def _failing_writer(record, out_dir, **_):
    raise RuntimeError("disk full")


_SMALL = """
[realisations]
include = ["learned", "delta", "mesh", "asic", "metalens", "metalens_layout"]
[realisations.asic]
bits = 6
[realisations.metalens_layout]
aperture_m = 20e-6
focal_length_m = 60e-6
illuminant = 555e-9
n_wavelengths = 1
n_terms = 1
n_starts = 1
max_iter = 8
guard_px = 1
library_wavelengths_m = [555e-9]
n_radii = 12
fourier_orders = 2
check_orders = 1
[realisations.metalens]
illuminant = 555e-9
n_wavelengths = 1
n_terms = 1
n_starts = 1
max_iter = 8
guard_px = 1
n_sub = 6
[analysis]
csf_methods = ["mannos_sakrison_1974"]
[sensor]
resolution = [16, 24]
[emulation]
enabled = false
[run]
workers = 1
"""


def test_explore_writes_every_hardware_realisations_artifacts_and_the_report_links_them(tmp_path):
    from fsdvs_hw.explore.explore import run_exploration

    p = tmp_path / "small.toml"
    p.write_text(_SMALL)
    res = run_exploration(p, tmp_path / "out", progress=False)
    index = read_index(res.artifacts_index)
    assert res.artifacts_index == tmp_path / "out" / "artifacts" / "index.json"
    assert not any("error" in e for e in index)
    by_real: dict[str, set[str]] = {}
    for e in index:
        by_real.setdefault(e["realisation"], set()).add(e["name"])
        assert set(e) >= {"point", "realisation", "name", "file", "what", "checked_by"}
        assert (res.artifacts_index.parent / e["file"]).is_file() and e["what"]
    hardware = set(realisation_names("hardware")) - {"mesh_process"}  # scored only with [process]: test_process_*
    from fsdvs_hw.realise.asic.sky130_artifacts import SKY130_ARTIFACTS  # written only when built in sky130

    optional = {"asic": set(SKY130_ARTIFACTS)}
    assert by_real == {name: set(get_realisation(name).artifacts) - optional.get(name, set()) for name in hardware}
    assert {e["point"] for e in index} == hardware  # one folder per point, named by the realisation
    # the ASIC's RTL is for the design's sensor frame (24 px lines, rows wrap after 16)
    rtl = (res.artifacts_index.parent / "asic" / "fsdvs_conv.v").read_text()
    assert "reg [7:0] lb0 [0:23];" in rtl and "row == 4'd15" in rtl
    html = (tmp_path / "out" / "report.html").read_text()
    assert "<h2>Buildable artifacts</h2>" in html
    for e in index:
        assert f'href="artifacts/{e["file"]}"' in html
    assert all(not pt.artifacts for pt in res.points if pt.realisation in ("learned", "delta"))
    json.loads((tmp_path / "out" / "scores.json").read_text())  # still valid JSON with the entries attached


def test_report_fragment_links_escape_and_show_a_failed_writer():
    from fsdvs_hw.records import ScoredPoint
    from fsdvs_hw.report.artifact_links import artifacts_html

    def point(data):
        return ScoredPoint.from_dict({"key": data["realisation"], "status": "error", **data})

    assert artifacts_html([point({"realisation": "learned"})]) == ""
    frag = artifacts_html(
        [
            point(d)
            for d in (
                {
                    "realisation": "asic",
                    "artifacts": [
                        {
                            "point": "asic",
                            "name": "verilog",
                            "file": "artifacts/asic/f v.v",
                            "what": "RTL <8-bit>",
                            "checked_by": "verilator -Wall f.v",
                        }
                    ],
                },
                {"realisation": "mesh", "artifacts": [{"point": "mesh", "error": "RuntimeError: <disk> full"}]},
            )
        ]
    )
    assert 'href="artifacts/asic/f%20v.v"' in frag and "RTL &lt;8-bit&gt;" in frag
    assert "<code>verilator -Wall f.v</code>" in frag and "not written: RuntimeError: &lt;disk&gt; full" in frag
