"""Differentiable FS-DVS event simulator (torch; CPU by default, the input's device otherwise).

Pipeline: linear-intensity video → spatial kernel (pre-log FS-DVS or post-log centre-surround,
with explicit positivity handling) → linear-log photoreceptor with intensity-dependent low-pass →
ON/OFF comparators with per-pixel mismatch, refractory period, leak and shot noise → event frames
(differentiable, straight-through surrogate), voxel grids, or an exact event list.

Public API
----------
SensorConfig          every parameter, documented defaults (v2e where v2e has one); ``.ideal()``
event_frames          (B, T, H, W) video → (B, T-1, 2, H, W) differentiable ON/OFF counts
event_list            exact events (b, x, y, t, p) with interpolated timestamps
voxel_grid            time-binned events (from an EventList or, differentiably, from frames)
EventSimulator        nn.Module wrapper; kernel as Parameter or buffer, swappable per call
plan_model / ModelPlan  the scene decides which effects run; every decision with its numbers
simulate / collect    streaming: any iterable of frames chunk by chunk, state carried (bit-exact)
upsample_frames       new frames between a video's (linear in log, or optical flow with occlusions)
sensor_preset / sensor_config   named cameras (DVS128, DAVIS346, IMX636, v2e sets), every value sourced
read_recording        a camera's file (Prophesee RAW EVT2/EVT3, DAT, DSEC h5, v2e h5, AEDAT4, npz)
compare_events        simulation vs recording: rates, alignment, polarity, pixel maps, intervals, noise
calibrate_sensor      thresholds, spread, refractory, noise, bandwidth fitted to a recording, with CIs
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# public name -> module that defines it. Loaded on first use, so that reading a preset, its input
# mapping or the config's field names (the ``simulate`` command's parser) does not import torch:
# the command decodes the video while torch loads (docs/speed.md).
_LAZY: dict[str, str] = {
    "PLACEMENTS": "fsdvs_hw.sensor.simulation.config",
    "POSITIVITY_MODES": "fsdvs_hw.sensor.simulation.config",
    "SURROGATES": "fsdvs_hw.sensor.simulation.config",
    "EventChunk": "fsdvs_hw.sensor.simulation.stream",
    "EventComparison": "fsdvs_hw.sensor.cameras.compare",
    "EventList": "fsdvs_hw.sensor.simulation.events",
    "EventSimulator": "fsdvs_hw.sensor.simulation.events",
    "ModelPlan": "fsdvs_hw.sensor.simulation.plan",
    "PlanDecision": "fsdvs_hw.sensor.simulation.plan",
    "SceneStats": "fsdvs_hw.sensor.simulation.plan",
    "SensorCalibration": "fsdvs_hw.sensor.cameras.calibrate",
    "SensorConfig": "fsdvs_hw.sensor.simulation.config",
    "SensorPreset": "fsdvs_hw.sensor.cameras.presets",
    "SimulationInfo": "fsdvs_hw.sensor.simulation.events",
    "calibrate_sensor": "fsdvs_hw.sensor.cameras.calibrate",
    "collect": "fsdvs_hw.sensor.simulation.stream",
    "compare_events": "fsdvs_hw.sensor.cameras.compare",
    "event_frames": "fsdvs_hw.sensor.simulation.events",
    "event_list": "fsdvs_hw.sensor.simulation.events",
    "linlog": "fsdvs_hw.sensor.simulation.pixel",
    "mesh_surround_steady_state": "fsdvs_hw.sensor.simulation.filtering",
    "plan_model": "fsdvs_hw.sensor.simulation.plan",
    "read_recording": "fsdvs_hw.sensor.eventfiles.recordings",
    "sensor_config": "fsdvs_hw.sensor.cameras.presets",
    "sensor_preset": "fsdvs_hw.sensor.cameras.presets",
    "simulate": "fsdvs_hw.sensor.simulation.stream",
    "upsample_frames": "fsdvs_hw.sensor.simulation.upsampling",
    "voxel_grid": "fsdvs_hw.sensor.simulation.voxels",
}

__all__, __getattr__, __dir__ = lazy_exports("fsdvs_hw.sensor", _LAZY, globals())

if TYPE_CHECKING:  # the same names, visible to IDEs and type checkers
    from .cameras.calibrate import SensorCalibration, calibrate_sensor
    from .cameras.compare import EventComparison, compare_events
    from .cameras.presets import SensorPreset, sensor_config, sensor_preset
    from .eventfiles.recordings import read_recording
    from .simulation.config import PLACEMENTS, POSITIVITY_MODES, SURROGATES, SensorConfig
    from .simulation.events import EventList, EventSimulator, SimulationInfo, event_frames, event_list
    from .simulation.filtering import mesh_surround_steady_state
    from .simulation.pixel import linlog
    from .simulation.plan import ModelPlan, PlanDecision, SceneStats, plan_model
    from .simulation.stream import EventChunk, collect, simulate
    from .simulation.upsampling import upsample_frames
    from .simulation.voxels import voxel_grid
