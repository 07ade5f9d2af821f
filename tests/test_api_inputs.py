"""The Python API refuses what the CLI refuses, with the same kind of message (issue 23).

Every public function of ``fsdvs_hw.sensor``, ``fsdvs_hw.scenes.synthetic`` and ``fsdvs_hw.tasks``
checks its arguments before any work: a wrong type, rank, dtype or value is an
:class:`~fsdvs_hw.errors.InputError` naming the argument, never a TypeError / AttributeError /
RuntimeError from inside torch or numpy. Huge-but-finite videos saturate (finite events), sizes are
checked against the allocation limit before anything is allocated, and a design whose sizes cannot
work together is refused at load.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fsdvs_hw import sensor
from fsdvs_hw.errors import InputError
from fsdvs_hw.limits import MAX_SUBSTEPS, allocation_limit
from fsdvs_hw.scenes import synthetic as scenes
from fsdvs_hw.sensor.simulation.config import SATURATION_INTENSITY

V = torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(0))
CLEAN = sensor.SensorConfig.ideal()


def _tasks():
    from fsdvs_hw import tasks

    return tasks


def _scene_batch():
    return scenes.make_scenes(scenes.SceneConfig(height_px=16, width_px=16, radius_px=(3, 4)), 2, seed=0)


# (function, expected substring naming the argument); each call is wrong in exactly one argument
BAD_CALLS = {
    "event_frames video None": (lambda: sensor.event_frames(None), "video"),
    "event_frames video int": (lambda: sensor.event_frames(3), "video"),
    "event_frames video str": (lambda: sensor.event_frames("video.mp4"), "video"),
    "event_frames video str array": (lambda: sensor.event_frames(np.array([[["a"]]])), "video"),
    "event_frames video complex": (lambda: sensor.event_frames(V.to(torch.complex64)), "video"),
    "event_frames video 3-D": (lambda: sensor.event_frames(V[0]), "video"),
    "event_frames negative": (lambda: sensor.event_frames(-V), "video"),
    "event_frames NaN": (lambda: sensor.event_frames(V * float("nan")), "video"),
    "event_frames config str": (lambda: sensor.event_frames(V, config="ideal"), "config"),
    "event_frames kernel str": (lambda: sensor.event_frames(V, "abc"), "kernel"),
    "event_frames kernel even": (lambda: sensor.event_frames(V, torch.ones(2, 2)), "kernel"),
    "event_frames timestamps str": (lambda: sensor.event_frames(V, timestamps_s="abc"), "timestamps_s"),
    "event_frames timestamps equal": (lambda: sensor.event_frames(V, timestamps_s=[0.0, 0.0, 1.0]), "timestamps_s"),
    "event_frames timestamps inf": (lambda: sensor.event_frames(V, timestamps_s=[0.0, 1.0, np.inf]), "timestamps_s"),
    "event_frames generator str": (lambda: sensor.event_frames(V, generator="g"), "generator"),
    "event_frames plan str": (lambda: sensor.event_frames(V, plan="p"), "plan"),
    "event_frames return_info str": (lambda: sensor.event_frames(V, return_info="yes"), "return_info"),
    "event_list video list": (lambda: sensor.event_list([1.0, 2.0]), "video"),
    "event_list config int": (lambda: sensor.event_list(V, config=3), "config"),
    "event_list progress str": (lambda: sensor.event_list(V, progress="no"), "progress"),
    "voxel_grid n_bins str": (lambda: sensor.voxel_grid(torch.ones(1, 2, 2, 4, 4), "3"), "n_bins"),
    "voxel_grid timestamps str": (
        lambda: sensor.voxel_grid(torch.ones(1, 2, 2, 4, 4), 3, timestamps_s="abc"),
        "timestamps_s",
    ),
    "voxel_grid signed str": (lambda: sensor.voxel_grid(torch.ones(1, 2, 2, 4, 4), 3, signed="no"), "signed"),
    "voxel_grid frames numpy int": (
        lambda: sensor.voxel_grid(torch.ones(1, 2, 2, 4, 4, dtype=torch.int64), 3),
        "frames",
    ),
    "voxel_grid height str": (
        lambda: sensor.voxel_grid(sensor.event_list(V, config=CLEAN), 3, timestamps_s=[0, 1, 2], height="8", width=8),
        "height",
    ),
    "voxel_grid height negative": (
        lambda: sensor.voxel_grid(sensor.event_list(V, config=CLEAN), 3, timestamps_s=[0, 1, 2], height=-8, width=8),
        "height",
    ),
    "SensorConfig threshold str": (lambda: sensor.SensorConfig(threshold_on="abc"), "threshold_on"),
    "SensorConfig threshold 0": (lambda: sensor.SensorConfig(threshold_off=0.0), "threshold_off"),
    "SensorConfig placement list": (lambda: sensor.SensorConfig(placement=["pre_log"]), "placement"),
    "SensorConfig placement array": (lambda: sensor.SensorConfig(placement=np.array(["a", "b"])), "placement"),
    "SensorConfig substeps 1e9": (lambda: sensor.SensorConfig(substeps=10**9), "substeps"),
    "SensorConfig substeps 0": (lambda: sensor.SensorConfig(substeps=0), "substeps"),
    "SensorConfig phase str": (lambda: sensor.SensorConfig(random_reference_phase="yes"), "random_reference_phase"),
    "SensorConfig seed str": (lambda: sensor.SensorConfig(seed="1"), "seed"),
    "plan_model str": (lambda: sensor.plan_model("video"), "video"),
    "plan_model tolerance str": (lambda: sensor.plan_model(V, "x"), "tolerance"),
    "simulate None": (lambda: sensor.simulate(None), "frames"),
    "simulate events str": (lambda: sensor.simulate(V[0], events="yes"), "events"),
    "simulate generator str": (lambda: sensor.simulate(V[0], generator=1), "generator"),
    "simulate timestamps int": (lambda: sensor.simulate(V[0], timestamps_s=3), "timestamps_s"),
    "simulate timestamps equal": (lambda: list(sensor.simulate(V[0], timestamps_s=[0.0, 0.0, 1.0])), "timestamps_s"),
    "collect str": (lambda: sensor.collect("abc"), "chunks"),
    "collect None": (lambda: sensor.collect(None), "chunks"),
    "linlog list": (lambda: sensor.linlog([1.0, 2.0], 0.1), "intensity"),
    "linlog knee str": (lambda: sensor.linlog(torch.ones(3), "x"), "knee"),
    "linlog knee 0": (lambda: sensor.linlog(torch.ones(3), 0.0), "knee"),
    "mesh numpy": (lambda: sensor.mesh_surround_steady_state(np.ones((4, 4)), 1.0), "signal"),
    "mesh lambda str": (lambda: sensor.mesh_surround_steady_state(torch.ones(4, 4), "x"), "lambda_px"),
    "EventSimulator config str": (lambda: sensor.EventSimulator(config="x"), "config"),
    "SceneConfig n_objects int": (lambda: scenes.SceneConfig(n_objects=5), "n_objects"),
    "SceneConfig radius str": (lambda: scenes.SceneConfig(radius_px=("a", "b")), "radius_px"),
    "SceneConfig height str": (lambda: scenes.SceneConfig(height_px="32"), "height_px"),
    "SceneConfig from_dict None": (lambda: scenes.SceneConfig.from_dict(None), "from_dict"),
    "SceneConfig with_ unknown": (lambda: scenes.SceneConfig().with_(foo=1), "foo"),
    "make_scenes config str": (lambda: scenes.make_scenes("cfg", 1), "config"),
    "make_scenes n_clips str": (lambda: scenes.make_scenes(scenes.SceneConfig(), "1"), "n_clips"),
    "is_sub_threshold str": (lambda: scenes.is_sub_threshold("a", 0.2), "edge_contrast"),
    "is_sub_threshold None": (lambda: scenes.is_sub_threshold(0.1, None), "threshold"),
    "scene_regime list": (lambda: scenes.scene_regime(["clutter"]), "scene regime"),
    "scene_regime unknown field": (lambda: scenes.scene_regime("clutter", foo=3), "foo"),
    "SceneBatch.subset str": (lambda: _scene_batch().subset("x"), "index"),
    "SceneBatch.subset out of range": (lambda: _scene_batch().subset([5]), "index"),
    "get_evaluator list": (lambda: _tasks().get_evaluator(["detection"]), "task"),
    "learn_kernel scene str": (lambda: _tasks().learn_kernel("detection", 3, scene="big"), "scene"),
    "learn_kernel sensor str": (lambda: _tasks().learn_kernel("detection", 3, sensor="ideal"), "sensor"),
    "learn_kernel learn_filter str": (lambda: _tasks().learn_kernel("detection", 3, learn_filter="no"), "learn_filter"),
    "learn_kernel size float": (lambda: _tasks().learn_kernel("detection", 3.0), "size"),
    "evaluate_kernel checkpoint int": (lambda: _tasks().evaluate_kernel(None, "detection", 3), "checkpoint"),
    "evaluate_kernel sensor str": (lambda: _tasks().evaluate_kernel(None, "detection", "c", sensor="x"), "sensor"),
    "evaluate_kernel lr str": (
        lambda: _tasks().evaluate_kernel(None, "detection", "c", finetune_lr="x"),
        "finetune_lr",
    ),
    "evaluate_kernel events_fn int": (
        lambda: _tasks().evaluate_kernel(None, "detection", "c", events_fn=3),
        "events_fn",
    ),
    "event_representation numpy": (
        lambda: __import__("fsdvs_hw.tasks.networks", fromlist=["x"]).event_representation(np.zeros((1, 2, 2, 4, 4))),
        "frames",
    ),
}


@pytest.mark.parametrize("case", list(BAD_CALLS), ids=list(BAD_CALLS))
def test_bad_argument_is_an_input_error_naming_it(case):
    fn, expected = BAD_CALLS[case]
    try:
        fn()
    except InputError as exc:
        msg = str(exc)
        assert expected in msg, msg
        assert "\n" not in msg and len(msg) < 400, msg  # one clear line, not a dump
        assert "Traceback" not in msg
    except Exception as exc:  # noqa: BLE001 - any other type is the leak this test is about
        pytest.fail(f"{case}: {type(exc).__name__} leaked from inside: {exc}")
    else:
        pytest.fail(f"{case}: accepted")


def test_numpy_float64_and_lists_are_accepted_and_agree_with_tensors():
    ref = sensor.event_frames(V.double(), config=CLEAN)
    assert torch.equal(sensor.event_frames(V.double().numpy(), config=CLEAN), ref)
    assert torch.equal(sensor.event_frames(V.double().tolist(), config=CLEAN).double(), ref)


@pytest.mark.parametrize("bad_ts", [[0.0, 0.0, 1.0], [2.0, 1.0, 0.0], [0.0, np.nan, 1.0]])
def test_voxel_grid_refuses_times_that_would_give_nan(bad_ts):
    frames = torch.ones(1, 2, 2, 4, 4)
    # the unchecked formula divides by the zero bin width: prove the case is the NaN one
    assert sensor.voxel_grid(frames, 3, timestamps_s=[0.0, 0.5, 1.0]).isfinite().all()
    with pytest.raises(InputError, match="timestamps_s"):
        sensor.voxel_grid(frames, 3, timestamps_s=bad_ts)
    ev = sensor.event_list(V * 3, config=CLEAN)
    assert len(ev) > 0
    with pytest.raises(InputError, match="timestamps_s"):
        sensor.voxel_grid(ev, 3, timestamps_s=bad_ts, height=8, width=8)


def _bright_dark_video(value: float, size: int = 64) -> torch.Tensor:
    v = torch.full((1, 3, size, size), 1.0)
    v[:, 1] = value
    v[:, 2, : size // 2] = value
    return v


@pytest.mark.parametrize("value", [3e38, 0.0])
@pytest.mark.parametrize("setting", ["plain", "fft 7x7", "dog pedestal", "differential", "post_log"])
def test_extreme_finite_videos_give_finite_frames_and_events(value, setting):
    k7 = torch.full((7, 7), 1 / 49)
    dog = -torch.full((7, 7), 1 / 49)
    dog[3, 3] = 2.0
    cfg, kernel = {
        "plain": (sensor.SensorConfig(), None),
        "fft 7x7": (sensor.SensorConfig(convolution="fft"), k7),
        "dog pedestal": (sensor.SensorConfig(positivity="pedestal"), dog),
        "differential": (sensor.SensorConfig(positivity="differential"), dog),
        "post_log": (sensor.SensorConfig(placement="post_log", surround_lambda_px=2.0, surround_weight=0.5), k7),
    }[setting]
    video = _bright_dark_video(value)
    frames, info = sensor.event_frames(video, kernel, config=cfg, return_info=True)
    assert torch.isfinite(frames).all() and frames.min() >= 0
    expected_saturated = int((video > SATURATION_INTENSITY).sum())
    assert info.saturated == expected_saturated
    assert (expected_saturated > 0) == (value > SATURATION_INTENSITY)
    ev = sensor.event_list(video, kernel, config=cfg)
    assert torch.isfinite(ev.t).all()
    # counting the events per interval reproduces the frames, as for any valid video
    counts = torch.zeros_like(frames).double()
    k = torch.bucketize(ev.t, torch.arange(3, dtype=torch.float64) / cfg.frame_rate_hz, right=False) - 1
    counts.index_put_(
        (ev.b, k, (ev.p < 0).long(), ev.y, ev.x), torch.ones(len(ev), dtype=torch.float64), accumulate=True
    )
    assert torch.equal(counts, frames.double())


def test_saturated_video_is_the_video_clipped_at_the_saturation_intensity():
    video = _bright_dark_video(3e38, 16)
    clipped = video.clamp(max=SATURATION_INTENSITY)
    assert torch.equal(sensor.event_frames(video), sensor.event_frames(clipped))
    chunks = list(sensor.simulate(video[0], event_frames=True, chunk_frames=1))
    f, _, info = sensor.collect(chunks)
    assert torch.equal(f, sensor.event_frames(video)) and info.saturated == int((video > SATURATION_INTENSITY).sum())


def test_valid_video_is_not_saturated_and_runs_unchanged():
    frames, info = sensor.event_frames(V * 5, config=CLEAN, return_info=True)
    assert info.saturated == 0
    from fsdvs_hw.sensor.simulation.events import saturate

    assert saturate(V)[0] is V  # no copy, no rounding: bit-identical results


def test_huge_video_is_refused_before_allocation():
    # a 100000 x 100000 expanded view: 4e10 bytes of frames; the check reads the shape only
    view = torch.zeros(1, 1, 1, 1).expand(1, 2, 100_000, 100_000)
    with pytest.raises(InputError, match=r"event frames .*H=100000, W=100000"):
        sensor.event_frames(view)
    # the limit decides, not the machine: a tiny limit refuses a tiny video, a larger one runs it
    with allocation_limit(1000), pytest.raises(InputError, match="allocation limit|more than the limit"):
        sensor.event_frames(V)
    with allocation_limit(1 << 20):
        assert sensor.event_frames(V, config=CLEAN).shape == (1, 2, 2, 8, 8)


def test_make_scenes_size_is_refused_before_allocation(monkeypatch):
    allocated = []
    real_empty = np.empty
    monkeypatch.setattr(scenes.np, "empty", lambda *a, **k: allocated.append(a) or real_empty(*a, **k))
    cfg = scenes.SceneConfig(height_px=2048, width_px=2048, n_frames=1000)
    with pytest.raises(InputError, match=r"make_scenes .*n_clips=100000"):
        scenes.make_scenes(cfg, 100_000)
    assert allocated == []  # refused before the video array was asked for
    with allocation_limit(1000), pytest.raises(InputError, match="make_scenes"):
        scenes.make_scenes(scenes.SceneConfig(), 1)


def test_substeps_bound_comes_from_limits():
    assert sensor.SensorConfig(substeps=MAX_SUBSTEPS).substeps == MAX_SUBSTEPS
    with pytest.raises(InputError, match=f"\\[1, {MAX_SUBSTEPS}\\]"):
        sensor.SensorConfig(max_substeps=MAX_SUBSTEPS + 1)


# ---------------------------------------------------------------------------- design cross-field sizes
def _fake_checkpoint(path, height: int, width: int) -> None:
    from safetensors.numpy import save_file

    prov = {"scene": {"height_px": height, "width_px": width}}
    save_file({"kernel": np.ones((1, 1))}, str(path), metadata={"provenance": json.dumps(prov)})


def test_design_refuses_a_kernel_larger_than_a_checkpoints_clips(tmp_path):
    from fsdvs_hw.design import DesignError, parse_design

    _fake_checkpoint(tmp_path / "small.safetensors", 8, 8)
    _fake_checkpoint(tmp_path / "big.safetensors", 32, 32)
    raw = {
        "kernel": {"source": "reference", "family": "dog", "size": 9},
        "tasks": {"checkpoints": {"detection": ["big.safetensors", "small.safetensors"]}},
        "emulation": {"enabled": False},
    }
    with pytest.raises(DesignError) as err:
        parse_design(raw, base_dir=tmp_path)
    msg = str(err.value)
    assert "tasks.checkpoints.detection[1]" in msg and "8x8" in msg and "9x9" in msg
    assert "detection[0]" not in msg  # the 32x32 checkpoint fits
    raw["tasks"]["checkpoints"]["detection"] = ["big.safetensors"]
    assert parse_design(raw, base_dir=tmp_path).target.size == 9


def test_design_refuses_an_emulation_that_cannot_render_its_clips():
    from fsdvs_hw.design import DesignError, parse_design

    small = {"kernel": {"size": 3}, "sensor": {"resolution": [12, 64]}}
    with pytest.raises(DesignError, match=r"sensor\.resolution.*emulation"):
        parse_design(small)
    parse_design({**small, "emulation": {"enabled": False}})  # no emulation: the size is fine
    with pytest.raises(DesignError, match=r"sensor\.resolution.*2048"):
        parse_design({"sensor": {"resolution": [48, 4096]}})
    with allocation_limit(1 << 20), pytest.raises(DesignError, match=r"emulation\.n_clips.*upsample_factor"):
        parse_design({"emulation": {"n_clips": 100}})
    assert parse_design({}).data["sensor"]["resolution"] == [48, 64]


# ---------------------------------------------------------------------------- property
_values = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 5),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=3),
    st.lists(st.floats(0, 2), max_size=3),
    st.sampled_from(
        [
            np.zeros((1, 2, 3, 3)),
            np.full((1, 2, 3, 3), 3e38),
            np.ones((1, 3, 2, 2), dtype=np.int64),
            np.array(["a"]),
            torch.rand(1, 2, 3, 3),
            torch.rand(2, 3, 4),
            torch.zeros(1, 2, 2, 2) - 1,
        ]
    ),
)
_kwargs = st.fixed_dictionaries(
    {},
    optional={
        "kernel": st.one_of(
            st.none(),
            st.integers(-2, 2),
            st.text(max_size=2),
            st.sampled_from([np.ones((3, 3)), np.ones((2, 2)), torch.zeros(3, 3), [[1.0]]]),
        ),
        "timestamps_s": _values,
        "config": st.one_of(st.none(), st.text(max_size=2), st.sampled_from([CLEAN, sensor.SensorConfig()])),
        "generator": st.one_of(st.none(), st.integers(0, 2)),
    },
)


@settings(max_examples=50, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck))
@given(video=_values, kwargs=_kwargs, which=st.sampled_from(["event_frames", "event_list"]))
def test_random_arguments_work_with_finite_outputs_or_raise_input_error(video, kwargs, which):
    try:
        out = getattr(sensor, which)(video, **kwargs)
    except InputError:
        return
    if which == "event_frames":
        assert torch.isfinite(out).all() and out.min() >= 0
    else:
        assert torch.isfinite(out.t).all() and len(out.x) == len(out)
