"""The per-stage cost of a user clip on a GPU (benchmarks/user_data_stages.py), where CUDA exists.

Skipped on a machine without CUDA: no GPU figure is estimated from CPU ones. Where a GPU is
present it times simulate and network on CUDA for two 320 x 240 videos at both frame sizes and
checks that each stage ran over every clip with a positive, finite time (that CUDA gives the CPU's
events for a noise-free sensor is tests/test_user_data_explore.py's).
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (none on this machine)")


def test_stage_times_on_cuda(tmp_path: Path):
    from benchmarks.user_data_stages import SIZES, stage_times, write_videos

    write_videos(tmp_path, 2)
    for size in SIZES:
        times = stage_times(tmp_path, size, repeats=2, device="cuda")
        assert times["n_clips"] == 2
        for stage in ("simulate", "network"):
            walls, _ = times[stage]
            assert len(walls) == 2 and all(0 < t < math.inf for t in walls)
