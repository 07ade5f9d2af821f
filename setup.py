"""Build hook: ship the top-level ``designs/`` folder inside the wheel as ``fsdvs_hw/designs``.

Everything else about the package is declared in ``pyproject.toml``. ``designs/`` (design files,
learned kernels, network checkpoints, README figures) stays at the top of the repository, where
users edit it; a wheel carries a copy as package data, read through :mod:`importlib.resources`
(:func:`fsdvs_hw.resources.designs_dir`). Editable installs (``pip install -e .``) copy nothing:
they read the checkout's ``designs/`` directly.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

_DESIGNS = Path(__file__).resolve().parent / "designs"


class BuildPyWithDesigns(build_py):
    """``build_py`` that also copies ``designs/`` to ``<build_lib>/fsdvs_hw/designs``."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        if not (_DESIGNS / "default.toml").is_file():
            raise FileNotFoundError(f"{_DESIGNS}: the shipped designs folder is missing; build from a full checkout")
        target = Path(self.build_lib) / "fsdvs_hw" / "designs"
        if target.exists():
            shutil.rmtree(target)
        shutil.copytree(_DESIGNS, target, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", ".*"))


setup(cmdclass={"build_py": BuildPyWithDesigns})
