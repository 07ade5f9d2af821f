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
"""

from .config import PLACEMENTS, POSITIVITY_MODES, SURROGATES, SensorConfig
from .events import EventList, EventSimulator, SimulationInfo, event_frames, event_list, voxel_grid
from .filtering import mesh_surround_steady_state
from .pixel import linlog
from .plan import ModelPlan, PlanDecision, SceneStats, plan_model
from .stream import EventChunk, collect, simulate

__all__ = [
    "PLACEMENTS",
    "POSITIVITY_MODES",
    "SURROGATES",
    "EventChunk",
    "EventList",
    "EventSimulator",
    "ModelPlan",
    "PlanDecision",
    "SceneStats",
    "SensorConfig",
    "SimulationInfo",
    "collect",
    "event_frames",
    "event_list",
    "linlog",
    "mesh_surround_steady_state",
    "plan_model",
    "simulate",
    "voxel_grid",
]
