"""The emulation track's recapturing camera can be a sensor preset (the paper's EVK4: imx636)."""

from __future__ import annotations

import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import reference_kernel


def test_camera_preset_changes_the_recapture_only():
    pytest.importorskip("torch")
    from fsdvs_hw.design import parse_design
    from fsdvs_hw.explore.emulation import camera_config, emulation_scores
    from fsdvs_hw.sensor import SensorConfig
    from fsdvs_hw.sensor.cameras.presets import sensor_config

    d = parse_design({"sensor": {"resolution": [24, 32]}, "emulation": {"n_clips": 1, "n_frames": 4}})
    sensor, emu = d.data["sensor"], d.data["emulation"]
    dog = reference_kernel("dog", 7)
    design = emulation_scores(dog, sensor=sensor, emulation=emu)
    assert emulation_scores(dog, sensor=sensor, emulation=emu, camera="design") == {
        **design,
        "wall_s": pytest.approx(design["wall_s"], abs=1e9),
    }
    dvs128 = emulation_scores(dog, sensor=sensor, emulation=emu, camera="dvs128")
    assert dvs128["events_in_sensor"] == design["events_in_sensor"]  # the in-sensor reference is unchanged
    assert dvs128["events_recaptured"] != design["events_recaptured"]  # a 0.14 threshold camera recaptures more
    assert dvs128["events_recaptured"] > design["events_recaptured"]
    cfg = camera_config("imx636", SensorConfig(frame_rate_hz=30.0, seed=4))
    assert cfg == sensor_config("imx636", frame_rate_hz=30.0, seed=4)
    with pytest.raises(InputError, match="'evk9' unknown"):
        emulation_scores(dog, sensor=sensor, emulation=emu, camera="evk9")
