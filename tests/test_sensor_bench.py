"""`fsdvs-hw bench sim` (slow) and config round trips."""

from __future__ import annotations

import re

import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import SensorConfig


def test_config_dict_round_trip_and_unknown_fields():
    cfg = SensorConfig(threshold_on=0.3, placement="post_log", surround_lambda_px=2.0, seed=9)
    assert SensorConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(InputError, match="unknown sensor field"):
        SensorConfig.from_dict({"treshold_on": 0.2})
    ideal = SensorConfig.ideal()
    assert not ideal.has_photoreceptor and ideal.shot_noise_rate_hz == 0 and ideal.threshold_sigma == 0


@pytest.mark.slow
def test_bench_sim_quick_tables():
    from fsdvs_hw.bench import BENCHMARKS, run_benchmark

    assert BENCHMARKS["sim"] == "fsdvs_hw.sensor.bench:bench_sim"
    text = run_benchmark("sim", quick=True)
    assert "forward+backward" in text and "Mpixel-frames/s" in text
    # every plan row stays within its tolerance of the reference (frame L1 error column)
    rows = re.findall(r"\| plan_model tol ([0-9.]+) .*?\| \d+ \| ([0-9.]+) \| ([0-9.]+) \|", text)
    assert len(rows) == 3
    for tol, count_err, frame_err in rows:
        assert float(count_err) <= float(tol) and float(frame_err) <= float(tol)
