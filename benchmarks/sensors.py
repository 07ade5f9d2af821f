"""``fsdvs-hw bench sensors``: calibration recovery — parameters fitted back from simulated recordings.

For two sensor presets and two recording lengths, the display-recapture test pattern
(:func:`fsdvs_hw.sensor.cameras.calibration_scene.calibration_video`, 40 x 40 pixels at 1 kHz) is
simulated with the preset's parameters, written as a Prophesee EVT 3.0 file (µs timestamps, as an
EVK4 records) and read back, then :func:`fsdvs_hw.sensor.cameras.calibrate.calibrate_sensor` fits it from
a neutral start (thresholds 0.2, bandwidth guess 100 Hz, fitted). Each row: the preset's value, the
value of this simulated sensor's own pixels (thresholds and their spread: the mean and SD of the
per-pixel draws over the pixels the fit uses; the interval is for the preset's population value),
the recovered value with its 95 % pixel-bootstrap interval, and whether the interval holds the
preset's value.

``python -m benchmarks.sensors docs/sensors.md`` runs it and writes the table into that page.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .harness import BenchRun, BenchSection, Column, kept_global_state

__all__ = ["bench_sensors", "write_docs"]

_FIELDS = (
    "threshold_on",
    "threshold_off",
    "threshold_sigma",
    "refractory_s",
    "cutoff_hz",
    "leak_rate_hz",
    "shot_noise_rate_hz",
)


def _own_pixels(config, height: int, width: int, like) -> dict[str, float]:
    """This sensor's own threshold mean/SD over the pixels the fit sees (the pattern's moving part)."""
    from fsdvs_hw.sensor.simulation.pixel import threshold_maps

    on, off = threshold_maps(config, (height, width), like)
    active = slice(int(0.25 * width), None)
    return {
        "threshold_on": float(on[:, active].mean()),
        "threshold_off": float(off[:, active].mean()),
        "threshold_sigma": float(np.sqrt(0.5 * (float(on[:, active].var()) + float(off[:, active].var())))),
    }


@kept_global_state()
def bench_sensors(*, quick: bool = False) -> BenchRun:
    """The recovery table: preset, recording length, parameter, true, own pixels, recovered [CI], covered.

    Returns
    -------
    BenchRun
        Markdown and records (one per printed number).
    """
    import tempfile

    from fsdvs_hw.sensor import event_list
    from fsdvs_hw.sensor.cameras.calibrate import calibrate_sensor
    from fsdvs_hw.sensor.cameras.calibration_scene import calibration_video
    from fsdvs_hw.sensor.cameras.presets import sensor_config
    from fsdvs_hw.sensor.eventfiles.prophesee import write_prophesee
    from fsdvs_hw.sensor.eventfiles.recordings import read_recording

    size = 16 if quick else 40
    presets = ["davis346"] if quick else ["davis346", "v2e-noisy"]
    lengths = [0.2] if quick else [0.5, 2.0]
    n_boot = 50 if quick else 200
    sec = BenchSection(
        "sensors",
        settings={
            "quick": quick,
            "pixels": f"{size}x{size}",
            "frame_rate_hz": 1000,
            "n_boot": n_boot,
            "level": 0.95,
            "fit_cutoff": not quick,
            "start": "thresholds 0.2, cutoff 100 Hz",
        },
    )
    sec.text(
        "### Calibration recovery (fsdvs-hw bench sensors)",
        "",
        f"{size} x {size} pixels, calibration_video at 1 kHz, EVT 3.0 round trip, 95 % pixel-bootstrap "
        f"intervals ({n_boot} resamples); `python -m benchmarks.sensors docs/sensors.md`.",
        "",
    )
    table = sec.table(
        Column.text("preset"),
        Column.text("length s"),
        Column.text("parameter"),
        Column.number("true (preset)", ".4g", unit="SensorConfig unit", metric="true value"),
        Column.number("this sensor's pixels", ".4g", unit="SensorConfig unit", metric="own-pixel value"),
        Column.numbers(
            "recovered [95 % CI]",
            "{0} [{1}, {2}]",
            ("recovered", "", ".4g"),
            ("ci low", "", ".4g"),
            ("ci high", "", ".4g"),
        ),
        Column.text("CI holds true"),
    )
    with tempfile.TemporaryDirectory() as tmp:
        for name in presets:
            truth = sensor_config(name, seed=7)
            for length in lengths:
                video, ts = calibration_video(int(round(length * 1000)), size, size)
                ev = event_list(video, config=truth, timestamps_s=ts)
                path = write_prophesee(Path(tmp) / f"{name}_{length}.raw", ev, width=size, height=size)
                start = truth.replace(
                    threshold_on=0.2, threshold_off=0.2, cutoff_hz=100.0 if not quick else truth.cutoff_hz
                )
                cal = calibrate_sensor(
                    read_recording(path),
                    video,
                    timestamps_s=ts,
                    config=start,
                    fit_cutoff=not quick and truth.cutoff_hz > 0,
                    n_boot=n_boot,
                )
                own = _own_pixels(truth, size, size, video[0, 0])
                for k in _FIELDS:
                    if k not in cal.estimates:
                        continue
                    e, tv = cal.estimates[k], float(getattr(truth, k))
                    table.row(
                        name,
                        f"{length:g}",
                        k,
                        tv,
                        own.get(k, tv),
                        (e.value, e.low, e.high),
                        "yes" if e.contains(tv) else "no",
                    )
    sec.text("")
    return sec.run()


def write_docs(path: str | Path = "docs/sensors.md", *, quick: bool = False) -> Path:
    """Run the bench and write its table into the calibration block of ``path`` (atomically)."""
    from fsdvs_hw.paths import write_output
    from fsdvs_hw.sensor.cameras.presets import splice_block

    p = Path(path)
    md = bench_sensors(quick=quick).markdown
    return write_output(p, splice_block(p.read_text(encoding="utf-8"), "calibration", md), flag="path")


if __name__ == "__main__":  # pragma: no cover - the page's regeneration command
    print(write_docs(sys.argv[1] if len(sys.argv) > 1 else "docs/sensors.md"))
