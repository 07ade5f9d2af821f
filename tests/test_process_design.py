"""The ``[process]`` design section: absent, nothing changes; present, the mesh is also built in the process."""

from __future__ import annotations

import numpy as np
import pytest

from fsdvs_hw.design import DesignError, load_design, parse_design


def test_without_process_a_design_keeps_its_content():
    d = parse_design({"realisations": {"include": ["learned", "mesh"]}})
    assert "process" not in d.data
    assert "mesh_process" not in d.realisations and "mesh_process" not in d.data["realisations"]


def test_process_adds_the_transistor_mesh_with_the_section_as_defaults():
    d = parse_design(
        {
            "process": {"pdk": "sky130", "corners": ["ss", "tt"], "mismatch_samples": 5},
            "realisations": {"include": ["learned", "mesh"], "mesh_process": {"mismatch_samples": 2}},
        }
    )
    assert d.realisations == ["learned", "mesh", "mesh_process"]
    opts = d.realisation_options("mesh_process")
    assert opts["corners"] == ["ss", "tt"] and opts["pdk"] == "sky130"
    assert opts["mismatch_samples"] == 2  # the realisation's own table wins over [process]
    assert d.realisation_options("mesh") == {}  # the ideal mesh does not build in a process
    # a sweep or --set over a [process] key reaches the fit
    assert d.with_overrides({"process.temperatures_c": [0.0]}).realisation_options("mesh_process")[
        "temperatures_c"
    ] == [0.0]


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ({"pdk": "gf180"}, "unknown process"),
        ({"corners": ["xx"]}, "process.corners"),
        ({"temperatures_c": [200.0]}, "process.temperatures_c"),
        ({"mismatch_samples": -1}, "process.mismatch_samples"),
    ],
)
def test_bad_process_keys_are_refused_by_name(table, words):
    with pytest.raises(DesignError, match=words):
        parse_design({"process": table})


def test_the_shipped_sky130_design_builds_the_mesh_in_sky130():
    d = load_design("designs/sky130.toml")
    assert "mesh_process" in d.realisations
    opts = d.realisation_options("mesh_process")
    assert opts["pdk"] == "sky130" and opts["mismatch_samples"] >= 30
    assert len(opts["corners"]) * len(opts["temperatures_c"]) == 6 and opts["scored"] == "worst"


def test_process_pdk_builds_the_asic_taps_in_the_process_and_nothing_without_it():
    d = parse_design({"process": {"pdk": "sky130"}, "realisations": {"include": ["asic"], "asic": {"bits": 6}}})
    # only the keys the taps declare: pdk and the corners they are timed at (temperatures, mismatch: the mesh's)
    assert d.realisation_options("asic") == {"bits": 6, "pdk": "sky130", "corners": ["tt", "ff", "ss"]}
    d = parse_design({"process": {"pdk": "sky130"}, "realisations": {"include": ["asic"], "asic": {"corners": ["tt"]}}})
    assert d.realisation_options("asic") == {"pdk": "sky130", "corners": ["tt"]}  # its own table wins
    with pytest.raises(DesignError, match=r"realisations\.asic\.corners.*process-cells --corners sf"):
        parse_design({"process": {"pdk": "sky130", "corners": ["tt", "sf"]}, "realisations": {"include": ["asic"]}})
    assert parse_design({"realisations": {"include": ["asic"]}}).realisation_options("asic") == {}


def test_a_taps_frame_too_large_to_simulate_is_refused_when_the_design_is_read():
    from fsdvs_hw import fit_asic_taps
    from fsdvs_hw.errors import InputError
    from fsdvs_hw.realise.asic.options import MAX_PDK_FRAME_WORK

    raw = {"process": {"pdk": "sky130"}, "realisations": {"include": ["asic"], "asic": {"pdk_frame": [480, 640]}}}
    with pytest.raises(DesignError, match=r"realisations\.asic\.pdk_frame.*H·W² = 196608000"):
        parse_design(raw)  # [process] gives the taps their pdk: the bound applies at load, not after a 10-hour run
    raw["realisations"]["asic"]["pdk_frame"] = [128, 128]  # 128 * 128**2 = 2,097,152: allowed
    assert MAX_PDK_FRAME_WORK >= 128**3 and parse_design(raw).realisation_options("asic")["pdk_frame"] == [128, 128]
    del raw["process"]  # without a process nothing is simulated: any frame in range
    raw["realisations"]["asic"]["pdk_frame"] = [480, 640]
    assert parse_design(raw).realisation_options("asic") == {"pdk_frame": [480, 640]}
    with pytest.raises(InputError, match="pdk_frame"):
        fit_asic_taps(np.eye(3), bits=4, pdk="sky130", pdk_frame=(1024, 1024))
