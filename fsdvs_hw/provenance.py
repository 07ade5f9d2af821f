"""Provenance: the versions of every numerical dependency a result was computed with.

A fit, a task metric or a benchmark timing depends on more than fsdvs_hw: IPOPT (bundled in casadi)
stops elsewhere in another release, scipy's bootstrap and nlopt's optimisers change between
versions, torch's kernels change the last bits of every activation. Every stored result (explore
points, ``scores.json``, the report, benchmark records, learned checkpoints) therefore carries
:func:`library_versions`, and ``requirements-lock.txt`` at the top of the repository pins the set
that CI tested.

Example
-------
>>> from fsdvs_hw.provenance import library_versions
>>> v = library_versions()
>>> sorted(k for k in ("numpy", "scipy", "casadi", "ipopt", "torch") if k in v)
['casadi', 'ipopt', 'numpy', 'scipy', 'torch']
"""

from __future__ import annotations

import functools
import platform
import re
from importlib.metadata import PackageNotFoundError, version
from importlib.util import find_spec
from pathlib import Path

__all__ = ["NUMERICAL_PACKAGES", "ipopt_version", "library_versions"]

#: Distributions whose arithmetic reaches a result (PyPI names), in the order they are listed.
NUMERICAL_PACKAGES: tuple[str, ...] = (
    "fsdvs_hw",
    "numpy",
    "scipy",
    "torch",
    "casadi",
    "nlopt",
    "colour-science",
    "scikit-image",
    "torchmetrics",
    "pycocotools",
    "h5py",
    "imageio-ffmpeg",
)


def ipopt_version() -> str | None:
    """The IPOPT release bundled with the installed casadi (from its shared library's name).

    Returns
    -------
    str or None
        ``"3.14.19"`` for casadi 3.8.2's wheel; None when casadi is not installed or ships no
        versioned ``libipopt``.
    """
    spec = find_spec("casadi")
    if spec is None or not spec.submodule_search_locations:
        return None
    found = []
    for folder in spec.submodule_search_locations:
        for lib in Path(folder).glob("*ipopt*"):
            m = re.search(r"libipopt[^/]*?\.(\d+\.\d+\.\d+)", lib.name) or re.search(
                r"ipopt[-_.](\d+\.\d+\.\d+)", lib.name
            )
            if m and not lib.name.startswith("libsipopt"):
                found.append(m.group(1))
    return max(found, key=lambda v: tuple(int(p) for p in v.split("."))) if found else None


def library_versions() -> dict[str, str | None]:
    """Versions of Python and of every package in :data:`NUMERICAL_PACKAGES`, plus IPOPT.

    Read from the installed distributions' metadata (no package is imported); a package that is
    not installed maps to None. Cached: the environment does not change within a process.

    Returns
    -------
    dict of str to str or None
        ``{"python": "3.11.7", "fsdvs_hw": "0.1.0", "numpy": "2.4.6", ..., "ipopt": "3.14.19"}``.
    """
    return dict(_versions())


@functools.lru_cache(maxsize=1)
def _versions() -> tuple[tuple[str, str | None], ...]:
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in NUMERICAL_PACKAGES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    out["ipopt"] = ipopt_version()
    return tuple(out.items())
