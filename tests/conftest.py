"""Shared pytest fixtures and helpers for the fsdvs_hw suite."""

from __future__ import annotations

import os
import shutil

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


def require_tool(name: str) -> str:
    """Return the path of an external program, or skip the test saying how to install it."""
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} not installed (make test installs it with apt-get when run as root)")
    return path


@pytest.fixture
def rng():
    """A seeded numpy Generator (seed 1234) for reproducible random inputs."""
    import numpy as np

    return np.random.default_rng(1234)
