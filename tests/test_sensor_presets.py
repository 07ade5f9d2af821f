"""Sensor presets: every value sourced, published anchors, configs, and the generated docs table."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import SensorConfig
from fsdvs_hw.sensor.cameras.presets import (
    DOC_BLOCKS,
    PRESET_FIELDS,
    SENSOR_PRESETS,
    STATUSES,
    SourcedValue,
    presets_markdown,
    sensor_config,
    sensor_preset,
)

_DOCS = Path(__file__).resolve().parents[1] / "docs" / "sensors.md"


def test_docs_table_is_generated_from_the_code():
    text = _DOCS.read_text(encoding="utf-8")
    begin, end = DOC_BLOCKS["presets"]
    block = text[text.index(begin) + len(begin) + 1 : text.index(end)]
    assert block == presets_markdown(), "regenerate: python -m fsdvs_hw.sensor.cameras.presets docs/sensors.md"


def test_every_value_has_a_source_and_status():
    for p in SENSOR_PRESETS.values():
        assert set(p.values) == set(PRESET_FIELDS)
        for k, v in p.values.items():
            assert v.status in STATUSES and len(v.source) > 10, (p.name, k)
            if v.status == "published" and v.value is not None and not p.name.startswith("v2e"):
                assert any(w in v.source for w in ("JSSC", "ISSCC", "datasheet")), (p.name, k, v.source)


@pytest.mark.parametrize(
    "name,width,height,pitch", [("dvs128", 128, 128, 40.0), ("davis346", 346, 260, 18.5), ("imx636", 1280, 720, 4.86)]
)
def test_published_anchors(name, width, height, pitch):
    v = sensor_preset(name).values
    assert (v["width_px"].value, v["height_px"].value, v["pitch_um"].value) == (width, height, pitch)
    assert all(v[k].status == "published" for k in ("width_px", "height_px", "pitch_um"))


def test_dvs128_mismatch_and_latency_from_lichtsteiner_2008():
    v = sensor_preset("dvs128").values
    assert v["threshold_sigma"].value == 0.021 and "2.1 %" in v["threshold_sigma"].source
    assert v["latency_s"].value == 15e-6
    assert math.isclose(sensor_config("dvs128").threshold_on, math.log(1.15), abs_tol=1e-4)


@pytest.mark.parametrize("name", ["v2e-clean", "v2e-default", "v2e-noisy"])
def test_v2e_presets_equal_sensorconfig_presets(name):
    assert sensor_config(name) == SensorConfig.preset(name)
    assert sensor_config(name, seed=3).seed == 3


def test_camera_configs_build_and_unknown_names_refused():
    for name in ("dvs128", "DAVIS346", "imx636", "ideal", "default"):
        assert isinstance(sensor_config(name), SensorConfig)
    assert sensor_config("davis346").threshold_off > sensor_config("davis346").threshold_on
    with pytest.raises(InputError, match="'evk5' unknown; allowed: dvs128"):
        sensor_config("evk5")
    with pytest.raises(InputError, match="status"):
        SourcedValue(1.0, "x", "guessed")
    with pytest.raises(InputError, match="source"):
        SourcedValue(1.0, " ")


def test_design_files_offer_every_preset_as_the_emulation_camera():
    """design.py lists the cameras without importing the simulator; the list must follow the presets,
    and a design that names one records it (a design that does not keeps its content unchanged)."""
    from fsdvs_hw.design import parse_design
    from fsdvs_hw.design.sections import EMULATION_CAMERAS
    from fsdvs_hw.sensor.cameras.presets import SENSOR_PRESETS

    assert set(EMULATION_CAMERAS) == {"design", *SENSOR_PRESETS}
    assert parse_design({"emulation": {"camera": "imx636"}}).data["emulation"]["camera"] == "imx636"
    assert "camera" not in parse_design({}).data["emulation"]
