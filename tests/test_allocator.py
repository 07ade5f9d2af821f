"""The simulate command's allocator setting: freed frame-sized buffers stay in the process."""

import subprocess
import sys

import pytest

_PROBE = """
import sys
import numpy as np
from fsdvs_hw.allocator import retain_freed_memory
ok = retain_freed_memory() if sys.argv[1] == "retain" else None
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096
base = rss()
arrays = [np.ones(1 << 19) for _ in range(40)]  # 40 buffers of 4 MiB, touched
peak = rss()
del arrays
print(ok, (peak - base) >> 20, (rss() - base) >> 20)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_buffers_stay_resident_only_with_the_setting():
    """160 MiB of 4 MiB buffers, freed: glibc hands them back to the kernel by default (and the
    next allocation faults them in again); after retain_freed_memory() they stay (below the 256 MiB
    trim threshold), ready for reuse."""

    def run(mode):
        out = subprocess.run([sys.executable, "-c", _PROBE, mode], capture_output=True, text=True, check=True)
        ok, grown, kept = out.stdout.split()
        return ok, int(grown), int(kept)

    ok, grown, kept = run("retain")
    assert ok == "True" and grown >= 150 and kept >= 150
    ok, grown, kept = run("default")
    assert grown >= 150 and kept <= 20
