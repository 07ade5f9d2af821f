"""The one schema (fsdvs_hw.schema, issue 28): the JSON Schema editors get, the typed design, the
messages generated from a field's schema, and the strict rules shared by design files and fits."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.design import DesignError, design_json_schema, load_design, parse_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.realise.asic.options import AsicOptions
from fsdvs_hw.schema import validate

jsonschema = pytest.importorskip("jsonschema")

REPO = Path(__file__).resolve().parents[1]
DESIGNS = sorted((REPO / "designs").glob("*.toml"))


@pytest.fixture(scope="module")
def validator():
    schema = design_json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.mark.parametrize("path", DESIGNS, ids=lambda p: p.stem)
def test_shipped_designs_validate_against_the_generated_json_schema(path, validator):
    errors = list(validator.iter_errors(tomllib.loads(path.read_text())))
    assert errors == [], [e.message for e in errors]


@pytest.mark.parametrize(
    "patch,where",
    [
        ({"sensor": {"pitch_m": 4.86}}, "pitch_m"),  # out of range
        ({"sensor": {"threshold_on": True}}, "threshold_on"),  # a boolean is not a number
        ({"sensor": {"placement": "after_log"}}, "placement"),  # not a choice
        ({"sensor": {"threshhold_on": 0.2}}, "threshhold_on"),  # unknown key
        ({"realisations": {"asic": {"bits": 7.5}}}, "bits"),  # an integer option
        ({"realisations": {"include": ["learned", "fpga"]}}, "fpga"),  # not a registered realisation
        ({"sensors": {}}, "sensors"),  # unknown section
    ],
)
def test_a_bad_value_fails_the_json_schema(patch, where, validator):
    errors = list(validator.iter_errors(patch))
    assert errors, patch
    assert any(where in (e.message + " " + "/".join(map(str, e.absolute_path))) for e in errors)


def test_the_json_schema_carries_units_descriptions_and_defaults():
    schema = design_json_schema()
    pitch = schema["$defs"]["SensorSection"]["properties"]["pitch_m"]
    assert pitch["unit"] == "m" and "metres" in pitch["description"] and pitch["default"] == 4.86e-6
    assert (pitch["minimum"], pitch["maximum"]) == (1e-7, 1e-3)
    bits = schema["$defs"]["AsicOptions"]["properties"]["bits"]
    assert bits["unit"] == "bit" and bits["type"] == "integer" and bits["default"] == 8
    assert schema["$defs"]["KernelSection"]["properties"]["size"]["odd"] is True


def test_cli_writes_the_json_schema(tmp_path, capsys):
    out = tmp_path / "design.schema.json"
    assert main(["schema", "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == json.loads(json.dumps(design_json_schema()))


def test_the_typed_design_reads_the_same_values_as_its_dict():
    d = load_design(REPO / "designs" / "default.toml")
    data = d.to_dict()
    assert d.spec.sensor.threshold_on == data["sensor"]["threshold_on"]
    assert d.spec.sensor.resolution == data["sensor"]["resolution"]
    assert d.spec.tasks.checkpoints == data["tasks"]["checkpoints"]
    assert d.spec.run.seed == data["run"]["seed"] and d.spec.codesign.enabled == data["codesign"]["enabled"]
    # every option has its value (its default where unset); the dict keeps only the options set
    e = parse_design({"realisations": {"asic": {"bits": 5}}})
    assert e.spec.realisations.asic.bits == 5 and e.spec.realisations.asic.symmetry == "auto"
    assert e.to_dict()["realisations"]["asic"] == {"bits": 5}


def test_messages_are_generated_from_the_fields_schema():
    with pytest.raises(DesignError) as info:
        parse_design({"sensor": {"pitch_m": 4.86}, "realisations": {"asic": {"scale": -1.0}, "mesh": {"fit_size": 4}}})
    msg = str(info.value)
    assert (
        "key 'sensor.pitch_m' = 4.86: out of range; allowed: a number in [1e-07, 0.001] m (pixel pitch in metres)"
    ) in msg
    # a union: the value's own alternative explains the problem; an open bound is a round bracket
    assert (
        "key 'realisations.asic.scale' = -1.0: out of range; allowed: a number in (0, inf] or one of "
        "'free', 'pow2' (tap scale: 'free', 'pow2' or a fixed positive number)"
    ) in msg
    assert (
        "key 'realisations.mesh.fit_size' = 4: out of range (even); allowed: an odd integer in [1, 63] px or None"
        in msg
    )
    assert "(3 problems)" in msg


@pytest.mark.parametrize(
    "value,why",
    [
        (True, "wrong type boolean"),
        (7.0, "wrong type number"),
        ("8", "wrong type string"),
        (None, "None is not allowed"),
        (1, "out of range"),
    ],
)
def test_strict_rules_of_an_integer_option(value, why):
    with pytest.raises(InputError, match=f"key 'bits' = .*: {why}; allowed: an integer in \\[2, 24\\] bit"):
        validate(AsicOptions, {"bits": value})


def test_numbers_are_normalised_and_numpy_scalars_accepted():
    m = validate(AsicOptions, {"adder_weight": 1, "bits": np.int64(4), "pre_add": np.bool_(False)})
    assert isinstance(m.adder_weight, float) and m.adder_weight == 1.0
    assert m.bits == 4 and type(m.bits) is int and m.pre_add is False
    for bad in (math.nan, math.inf):
        with pytest.raises(InputError, match="not a finite number"):
            validate(AsicOptions, {"adder_weight": bad})
    with pytest.raises(InputError, match="wrong type boolean"):
        validate(AsicOptions, {"adder_weight": np.bool_(True)})
