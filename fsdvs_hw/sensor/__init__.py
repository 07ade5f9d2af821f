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

from .calibrate import SensorCalibration, calibrate_sensor
from .compare import EventComparison, compare_events
from .config import PLACEMENTS, POSITIVITY_MODES, SURROGATES, SensorConfig
from .events import EventList, EventSimulator, SimulationInfo, event_frames, event_list, voxel_grid
from .filtering import mesh_surround_steady_state
from .pixel import linlog
from .plan import ModelPlan, PlanDecision, SceneStats, plan_model
from .presets import SensorPreset, sensor_config, sensor_preset
from .recordings import read_recording
from .stream import EventChunk, collect, simulate
from .upsampling import upsample_frames

__all__ = [
    "PLACEMENTS",
    "POSITIVITY_MODES",
    "SURROGATES",
    "EventChunk",
    "EventComparison",
    "EventList",
    "EventSimulator",
    "ModelPlan",
    "PlanDecision",
    "SceneStats",
    "SensorCalibration",
    "SensorConfig",
    "SensorPreset",
    "SimulationInfo",
    "calibrate_sensor",
    "collect",
    "compare_events",
    "event_frames",
    "event_list",
    "linlog",
    "mesh_surround_steady_state",
    "plan_model",
    "read_recording",
    "sensor_config",
    "sensor_preset",
    "simulate",
    "upsample_frames",
    "voxel_grid",
]
