"""Design files: defaults, validation errors (file, key, value, allowed), overrides and point keys."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.design import DesignError, load_design, parse_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.explore.sweep import expand_points
from fsdvs_hw.kernels import Kernel, load_kernel, reference_kernel

REPO = Path(__file__).resolve().parents[1]


def _write(tmp_path: Path, text: str, name: str = "d.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_default_design_loads_with_its_documented_target():
    d = load_design(REPO / "designs" / "default.toml")
    assert d.name == "default"
    shipped = load_kernel(REPO / "designs" / "kernels" / "learned_detection_7x7.json")
    assert d.target.allclose(shipped)
    assert d.target.pitch_m == pytest.approx(4.86e-6)
    assert d.data["sensor"]["placement"] == "pre_log"
    assert d.realisations == ["learned", "delta", "mesh", "asic", "metalens", "metalens_layout"]
    assert set(d.checkpoints()) >= {"detection", "recognition"}
    assert all(p.is_file() for paths in d.checkpoints().values() for p in paths)


@pytest.mark.parametrize("path", sorted((REPO / "designs").glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_design_file_is_valid(path):
    d = load_design(path)
    assert expand_points(d)


def test_empty_design_gets_every_default():
    d = parse_design({})
    assert d.data["sensor"]["threshold_on"] == 0.2
    assert d.data["optics"]["focal_length_m"] == 4.0e-3
    assert d.target.size == 7
    assert d.data["tasks"]["checkpoints"] == {}


def test_kernel_file_is_resolved_relative_to_the_design(tmp_path):
    k = Kernel(np.array([[0, -1, 0], [-1, 5, -1], [0, -1, 0]], float), name="sharpen")
    (tmp_path / "k").mkdir()
    k.save(tmp_path / "k" / "sharp.json")
    p = _write(tmp_path, '[kernel]\nsource = "file"\npath = "k/sharp.json"\n[sensor]\npitch_m = 3e-6\n')
    d = load_design(p)
    assert d.target.allclose(k)
    assert d.target.pitch_m == 3e-6  # the design's pitch overrides the file's


# ---------------------------------------------------------------------- one clear error each
BAD = {
    "unknown key": (
        "[sensor]\npitch_m = 4.86e-6\nthreshhold_on = 0.2\n",
        ["sensor.threshhold_on", "unknown key", "threshold_on"],
    ),
    "unknown section": ("[sensors]\npitch_m = 4.86e-6\n", ["'sensors'", "unknown section", "sensor"]),
    "wrong type": ('[sensor]\npitch_m = "4.86um"\n', ["sensor.pitch_m", '"4.86um"', "wrong type string", "number"]),
    "wrong type in list": ('[sensor]\nresolution = [48, "64"]\n', ["sensor.resolution[1]", "wrong type", "integer"]),
    "out of range": (
        "[sensor]\npitch_m = 4.86\n",
        ["sensor.pitch_m", "4.86", "out of range", "[1e-07, 0.001]", "metres"],
    ),
    "even kernel size": ("[kernel]\nsize = 6\n", ["kernel.size", "6", "out of range", "odd"]),
    "bad choice": ('[sensor]\nplacement = "after_log"\n', ["sensor.placement", "after_log", "'pre_log', 'post_log'"]),
    "missing kernel file": (
        '[kernel]\nsource = "file"\npath = "nope.npy"\n',
        ["kernel.path", "nope.npy", "kernel file not found"],
    ),
    "bad realisation": (
        '[realisations]\ninclude = ["learned", "fpga"]\n',
        ["realisations.include[1]", "fpga", "'mesh', 'mesh_process', 'asic', 'metalens'"],
    ),
    "bad sweep value": ('[sweep]\naxes = { "asic.bits" = [4, 0] }\n', ["sweep.axes.asic.bits", "0", "out of range"]),
    "sweep axis on unknown key": (
        '[sweep]\naxes = { "sensor.gain" = [1, 2] }\n',
        ["sweep.axes.sensor.gain", "unknown key"],
    ),
    "unknown CSF": (
        '[analysis]\ncsf_methods = ["mannos_sakrison_1974", "kelly_1979"]\n',
        ["analysis.csf_methods[1]", "kelly_1979", "barten_1999"],
    ),
    "bad reference parameter": (
        '[kernel]\nfamily = "dog"\nparams = { sigma_centre_px = 3.0, sigma_surround_px = 1.0 }\n',
        ["kernel.params", "sigma_surround_px", "must exceed"],
    ),
    "sensor smaller than the kernel": (
        "[kernel]\nsize = 15\n[sensor]\nresolution = [12, 64]\n",
        ["sensor.resolution", "smaller than the 15x15 kernel"],
    ),
    "missing checkpoint": (
        '[tasks]\ncheckpoints = { detection = "nowhere/learned_detection" }\n',
        ["tasks.checkpoints.detection", "checkpoint file not found"],
    ),
    "missing checkpoint in a seed list": (
        f'[tasks]\ncheckpoints = {{ detection = ["ck.safetensors", "nowhere/seed1"] }}\n',
        ["tasks.checkpoints.detection[1]", "nowhere/seed1", "checkpoint file not found"],
    ),
    "empty seed list": ("[tasks]\ncheckpoints = { detection = [] }\n", ["tasks.checkpoints.detection", "empty list"]),
    "task weight for a task not scored": (
        f'[tasks]\ncheckpoints = {{ detection = "ck.safetensors" }}\n[scoring]\ntask_weights = {{ recognition = 1 }}\n',
        ["scoring.task_weights.recognition", "not a task"],
    ),
    "negative task weight": (
        f'[tasks]\ncheckpoints = {{ detection = "ck.safetensors" }}\n[scoring]\ntask_weights = {{ detection = -1 }}\n',
        ["scoring.task_weights.detection", ">= 0"],
    ),
    "per-task n_test out of range": (
        f'[tasks]\ncheckpoints = {{ detection = "ck.safetensors" }}\nn_test = {{ detection = -5 }}\n',
        ["tasks.n_test.detection", "[0, 100000]"],
    ),
    "bad confidence": ("[scoring]\nconfidence = 1.5\n", ["scoring.confidence", "out of range"]),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_each_bad_design_gives_one_clear_error(tmp_path, case):
    text, needles = BAD[case]
    # a real checkpoint beside the design (paths in a design file must stay inside its folder)
    shutil.copy(REPO / "designs" / "kernels" / "learned_detection_7x7.safetensors", tmp_path / "ck.safetensors")
    p = _write(tmp_path, text)
    with pytest.raises(DesignError) as info:
        load_design(p)
    msg = str(info.value)
    assert isinstance(info.value, InputError)
    assert str(p) in msg
    assert "(1 problem)" in msg, msg
    for n in needles:
        assert n in msg, f"{n!r} not in {msg!r}"


def test_unknown_fit_option_is_named_with_the_fit_functions_options(tmp_path):
    p = _write(tmp_path, "[realisations.asic]\nbits = 6\nbitz = 4\n")
    with pytest.raises(DesignError, match=r"realisations\.asic\.bitz.*unknown option of fit_asic_taps.*symmetry"):
        load_design(p)


def test_fit_option_type_follows_the_fit_functions_default(tmp_path):
    p = _write(tmp_path, '[realisations.asic]\npre_add = "yes"\n')
    with pytest.raises(DesignError, match=r"realisations\.asic\.pre_add.*wrong type string.*boolean"):
        load_design(p)


def test_all_problems_of_one_file_are_listed_together(tmp_path):
    p = _write(tmp_path, '[sensor]\npitch_m = -1.0\nthreshold_on = "x"\n[optics]\nfocal = 1\n')
    with pytest.raises(DesignError) as info:
        load_design(p)
    msg = str(info.value)
    assert "(3 problems)" in msg
    assert "sensor.pitch_m" in msg and "sensor.threshold_on" in msg and "optics.focal" in msg


def test_missing_and_unparsable_files(tmp_path):
    with pytest.raises(DesignError, match="design file not found"):
        load_design(tmp_path / "absent.toml")
    p = _write(tmp_path, "[sensor\npitch_m = 1\n")
    with pytest.raises(DesignError, match="not valid TOML"):
        load_design(p)


def test_cli_rejects_a_bad_design_before_any_work(tmp_path):
    p = _write(tmp_path, "[sensor]\npitch_m = 4.86\n")
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "fsdvs_hw.cli", "explore", str(p), "--out", str(out)],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )
    assert r.returncode == 2
    assert "sensor.pitch_m" in r.stderr and "out of range" in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()  # nothing was started


# ---------------------------------------------------------------------- overrides and points
def test_overrides_are_revalidated():
    d = parse_design({})
    assert d.with_overrides({"asic.bits": 4}).data["realisations"]["asic"]["bits"] == 4
    with pytest.raises(DesignError, match="realisations.asic.bits"):
        d.with_overrides({"asic.bits": 0})


def test_points_grid_per_realisation_and_global_axes():
    d = parse_design(
        {
            "realisations": {"include": ["learned", "delta", "asic"]},
            "sweep": {"axes": {"asic.bits": [2, 4, 8], "optics.focal_length_m": [2e-3, 4e-3]}},
        }
    )
    pts = expand_points(d)
    # (learned + delta + 3 asic) for each of 2 focal lengths
    assert len(pts) == 2 * (1 + 1 + 3)
    assert len({p.key for p in pts}) == len(pts)
    asic = [p for p in pts if p.realisation == "asic"]
    assert sorted({p.params["asic.bits"] for p in asic}) == [2, 4, 8]
    assert all(p.data["realisations"]["asic"]["bits"] == p.params["asic.bits"] for p in asic)


def test_point_key_depends_only_on_what_decides_the_result():
    base = parse_design({"realisations": {"include": ["learned", "asic"]}})
    other_mesh = parse_design(
        {
            "realisations": {"include": ["learned", "asic"], "mesh": {}},
            "run": {"workers": 7},
            "design": {"description": "x"},
        }
    )
    keys = {p.realisation: p.key for p in expand_points(base)}
    assert keys == {p.realisation: p.key for p in expand_points(other_mesh)}
    moved = parse_design({"realisations": {"include": ["learned", "asic"]}, "sensor": {"threshold_on": 0.3}})
    assert all(keys[p.realisation] != p.key for p in expand_points(moved))
    bits = parse_design({"realisations": {"include": ["learned", "asic"], "asic": {"bits": 5}}})
    kb = {p.realisation: p.key for p in expand_points(bits)}
    assert kb["learned"] == keys["learned"] and kb["asic"] != keys["asic"]


def test_checkpoint_glob_lists_networks_in_natural_order_and_an_empty_match_is_named(tmp_path):
    import shutil

    from fsdvs_hw.design import parse_design

    src = (
        Path(__file__).parents[1]
        / "designs"
        / "kernels"
        / "networks"
        / "recognition_with_learned_detection_7x7_s0.safetensors"
    )
    (tmp_path / "nets").mkdir()
    for s in (0, 2, 10, 1):
        shutil.copy(src, tmp_path / "nets" / f"rec_s{s}.safetensors")
    d = parse_design({"tasks": {"checkpoints": {"recognition": "nets/rec_s*.safetensors"}}}, base_dir=tmp_path)
    assert d.data["tasks"]["checkpoints"]["recognition"] == [f"nets/rec_s{s}.safetensors" for s in (0, 1, 2, 10)]
    assert [p.name for p in d.checkpoints()["recognition"]] == [f"rec_s{s}.safetensors" for s in (0, 1, 2, 10)]
    assert d.data["tasks"]["test_clips"] == "per_network"
    with pytest.raises(DesignError, match=r"tasks\.checkpoints\.recognition.*matches no file"):
        parse_design({"tasks": {"checkpoints": {"recognition": "nets/none_*.safetensors"}}}, base_dir=tmp_path)
    with pytest.raises(DesignError, match=r"tasks\.test_clips"):
        parse_design({"tasks": {"test_clips": "nested"}}, base_dir=tmp_path)
