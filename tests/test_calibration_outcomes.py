"""calibrate_sensor says when it cannot be trusted: input checks in every form, outcomes, the model check."""

from __future__ import annotations

import math

import pytest
import torch

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import SensorConfig, event_list
from fsdvs_hw.sensor.cameras.calibrate import OUTCOMES, calibrate_sensor
from fsdvs_hw.sensor.cameras.calibration_check import TOLERANCES, which_conventions
from fsdvs_hw.sensor.cameras.calibration_scene import calibration_video
from fsdvs_hw.sensor.simulation.events import EventList


@pytest.fixture(scope="module")
def scene():
    return calibration_video(120, 10, 12)


def _truth(conventions="native", **kw):
    base = dict(threshold_off=0.3, threshold_sigma=0.02, seed=4, conventions=conventions)
    base.update(kw)
    return SensorConfig.ideal(0.25, **base)


def _events(video, ts, cfg):
    return event_list(video, config=cfg, timestamps_s=ts)


def test_matching_conventions_fit_and_print(scene):
    video, ts = scene
    cal = calibrate_sensor(
        _events(video, ts, _truth()), video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=40
    )
    assert cal.outcome == "fits" and cal.outcome in OUTCOMES
    assert cal.check.passed and {r.statistic for r in cal.check.rows} >= {"ON events", "pair spread"}
    text = str(cal)
    assert text.splitlines()[0].endswith(": fits") and "threshold_on" in text and "model check" in text
    assert cal.estimates["threshold_on"].contains(0.25) and cal.estimates["threshold_off"].contains(0.3)
    status = {r["parameter"]: r["status"] for r in cal.table()}
    assert status["threshold_on"] == "estimated" and status["refractory_s"] == "bounded"  # none swallowed


def test_v2e_conventions_recording_is_a_model_mismatch_naming_the_statistic(scene):
    """Events on the frame's time grid (v2e's rule): the native fit's pairs are not one threshold
    apart, and the check says so instead of returning a tight wrong interval."""
    video, ts = scene
    rec = _events(video, ts, _truth("v2e"))
    cal = calibrate_sensor(rec, video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=40)
    assert cal.outcome == "model mismatch"
    assert "pair spread" in cal.check.failed
    row = next(r for r in cal.check.rows if r.statistic == "pair spread")
    assert row.observed > row.expected + row.tolerance  # far outside, not at the edge
    assert "model mismatch: " in str(cal) and "pair spread" in str(cal).split("model mismatch: ")[1]
    checks = which_conventions(cal, rec, video, timestamps_s=ts)
    assert not checks["native"].passed and set(checks) == {"native", "v2e"}


def test_the_check_at_known_parameters_tells_the_conventions(scene):
    """At the parameters a recording was made with, the check passes under its own conventions
    and fails under the other: the statistic that tells them apart is the pair spread."""
    from fsdvs_hw.sensor.cameras.calibrate import recording_columns
    from fsdvs_hw.sensor.cameras.calibration_check import model_check

    video, ts = scene
    for made, other in (("v2e", "native"), ("native", "v2e")):
        truth = _truth(made)
        rec = recording_columns(_events(video, ts, truth), video)
        assert model_check(rec, video, ts, truth).passed, made
        assert "pair spread" in model_check(rec, video, ts, truth.replace(conventions=other)).failed, made
    with pytest.raises(InputError, match="the fit assumes the native conventions"):
        calibrate_sensor(rec, video, timestamps_s=ts, config=SensorConfig.ideal(0.2, conventions="v2e"))


def test_tolerances_are_stated_for_every_statistic():
    assert set(TOLERANCES) == {
        "ON events",
        "OFF events",
        "ON fraction",
        "pair spread",
        "static ON rate",
        "static OFF rate",
        "short intervals",
    }
    assert all(a >= 0 and r >= 0 for a, r in TOLERANCES.values())


def test_too_few_events_is_not_reported_as_a_still_video(scene):
    video, ts = scene
    ev = _events(video, ts, _truth())
    for n in (0, 1):
        few = EventList(ev.b[:n], ev.x[:n], ev.y[:n], ev.t[:n], ev.p[:n])
        with pytest.raises(InputError, match=f"has {n} event") as err:
            calibrate_sensor(few, video, timestamps_s=ts, check=False)
        assert "moves too little" not in str(err.value)
    few = EventList(ev.b[:12], ev.x[:12], ev.y[:12], ev.t[:12], ev.p[:12])
    with pytest.raises(InputError, match="too few events") as err:
        calibrate_sensor(few, video, timestamps_s=ts, check=False)
    assert "moves too little" not in str(err.value)


def test_non_finite_times_and_span_beyond_the_video_refused(scene):
    video, ts = scene
    ev = _events(video, ts, _truth())
    t = ev.t.clone()
    t[3] = float("nan")
    with pytest.raises(InputError, match=r"event 3 .*nan"):
        calibrate_sensor(EventList(ev.b, ev.x, ev.y, t, ev.p), video, timestamps_s=ts)
    late = EventList(ev.b, ev.x, ev.y, ev.t * 25.0, ev.p)  # a 3 s recording against a 0.12 s video
    with pytest.raises(InputError, match=r"spans .* the video 0 to 0.119 s"):
        calibrate_sensor(late, video, timestamps_s=ts)
    neg = EventList(ev.b, ev.x - int(ev.x.min()) - 1, ev.y, ev.t, ev.p)
    with pytest.raises(InputError, match=r"negative pixel|x of event \d+ is -\d+"):
        calibrate_sensor(neg, video, timestamps_s=ts)


def test_geometry_checked_for_a_path_as_for_an_object(scene, tmp_path):
    from fsdvs_hw.sensor.eventfiles.eventfile import write_events
    from fsdvs_hw.sensor.eventfiles.recordings import read_recording

    video, ts = scene
    ev = _events(video, ts, _truth())
    path = tmp_path / "rec.npz"
    write_events(path, ev, 20, 10)  # declared 20 wide, the video 12
    for form in (path, str(path), read_recording(path)):
        with pytest.raises(InputError, match="20x10 sensor, the video is 12x10"):
            calibrate_sensor(form, video, timestamps_s=ts)


def test_cutoff_without_a_filter_is_not_identifiable(scene):
    video, ts = scene
    ev = _events(video, ts, _truth())  # no photoreceptor low-pass
    cal = calibrate_sensor(
        ev, video, timestamps_s=ts, config=SensorConfig.ideal(0.2, cutoff_hz=300.0), fit_cutoff=True, n_boot=40
    )
    e = cal.estimates["cutoff_hz"]
    assert e.status == "not identifiable" and e.value == math.inf and e.low == pytest.approx(2400.0)
    assert cal.config.cutoff_hz == 0.0 and "above the scan" in str(cal)


def test_low_frame_rate_warns_with_upsampling_advice():
    video, ts = calibration_video(40, 10, 12, frame_rate_hz=25.0)
    ev = _events(video, ts, _truth())
    cal = calibrate_sensor(ev, video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=40, check=False)
    assert len(cal.warnings) == 1 and "upsample" in cal.warnings[0] and "25 fps" in cal.warnings[0]
    video, ts = calibration_video(120, 10, 12)  # 1000 fps
    cal = calibrate_sensor(_events(video, ts, _truth()), video, timestamps_s=ts, n_boot=40, check=False)
    assert cal.warnings == [] and cal.outcome == "unchecked"


def test_leak_without_a_steady_state(scene):
    """The reference starts at the first frame: a 0.5 Hz leak fires no event in the 0.12 s static
    border, so the static counts only bound it (their interval still holds it); the moving pixels'
    pair slope (the reference's drift) measures it, and the threshold fit undoes that drift."""
    video, ts = scene
    ev = _events(video, ts, _truth(leak_rate_hz=0.5, shot_noise_rate_hz=1.0))
    cal = calibrate_sensor(ev, video, timestamps_s=ts, config=SensorConfig.ideal(0.2), n_boot=40, check=False)
    e = cal.estimates["leak_rate_hz"]
    assert e.status == "bounded" and e.contains(0.5) and "(bounded)" in e.line("leak_rate_hz")
    drift = next(n for n in cal.notes if n.startswith("reference drift in the moving pixels"))
    value = float(drift.split("leak ")[1].split(" ")[0])
    assert value == pytest.approx(0.5, abs=0.03)
    assert cal.estimates["threshold_off"].contains(0.3) and cal.estimates["threshold_on"].contains(0.25)
    static = event_list(
        torch.full((1, 2, 16, 16), 0.5),
        config=SensorConfig.ideal(0.2, leak_rate_hz=0.5, shot_noise_rate_hz=1.0, seed=1),
        timestamps_s=[0.0, 1.0],
    )
    cal = calibrate_sensor(static, None, duration_s=1.0, n_boot=40)
    e = cal.estimates["leak_rate_hz"]
    assert e.status == "bounded" and e.contains(0.5)


def test_bad_options_refused(scene):
    video, ts = scene
    ev = _events(video, ts, _truth())
    with pytest.raises(InputError, match="error_recordings"):
        calibrate_sensor(ev, video, timestamps_s=ts, error_recordings=-1)
    with pytest.raises(InputError, match="check must be True or False"):
        calibrate_sensor(ev, video, timestamps_s=ts, check="yes")
    with pytest.raises(InputError, match="duration_s"):
        calibrate_sensor(ev, None, duration_s=float("nan"))
    with pytest.raises(InputError, match="longer than duration_s"):
        calibrate_sensor(ev, None, duration_s=0.01)


def test_static_scene_path_reads_the_file(tmp_path):
    from fsdvs_hw.sensor.eventfiles.eventfile import write_events

    truth = SensorConfig.ideal(0.2, shot_noise_rate_hz=4.0, seed=2)
    ev = event_list(torch.full((1, 2, 16, 16), 0.5), config=truth, timestamps_s=[0.0, 5.0])
    path = tmp_path / "static.npz"
    write_events(path, ev, 16, 16)
    cal = calibrate_sensor(path, None, duration_s=5.0, n_boot=50)
    assert cal.estimates["shot_noise_rate_hz"].contains(4.0)
