"""Shared pytest fixtures and helpers for the fsdvs_hw suite."""

from __future__ import annotations

import os
import shutil

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

# Property tests: `make test` (and CI) draws the same examples every run, so a run passes or fails
# on the code alone, never on the luck of the draw; `make fuzz` (HYPOTHESIS_PROFILE=fuzz) draws new
# random examples, many more of them, to look for inputs the fixed draw misses.
from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile(
    "fuzz",
    max_examples=1000,
    derandomize=False,
    database=None,
    print_blob=True,
    deadline=None,
    suppress_health_check=list(HealthCheck),
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def require_tool(name: str) -> str:
    """Return the path of an external program, or skip the test saying how to install it."""
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} not installed (make test installs it with apt-get when run as root)")
    return path


def cheap_design(name: str = "cheap") -> str:
    """A design file's text whose points are cheap: the ideal references only, one CSF model, no
    emulation, one worker (each point ~0.1-0.5 s). Append sections to extend it."""
    return f"""[design]
name = {name!r}
[realisations]
include = ["learned", "delta"]
[analysis]
csf_methods = ["mannos_sakrison_1974"]
[emulation]
enabled = false
[run]
workers = 1
"""


@pytest.fixture
def rng():
    """A seeded numpy Generator (seed 1234) for reproducible random inputs."""
    import numpy as np

    return np.random.default_rng(1234)
