"""The shipped data: design files, learned kernels, network checkpoints and README figures.

They live in one folder, ``designs/``, found by :func:`designs_dir` through
:mod:`importlib.resources`:

* **installed wheel**: package data at ``fsdvs_hw/designs/`` (``setup.py`` copies the repository's
  top-level ``designs/`` into the wheel);
* **source checkout or editable install** (``make demo``, ``pip install -e .``): the top-level
  ``designs/`` folder beside the package, where users edit it.

Every module that reads shipped data goes through this resolver (never
``Path(__file__).parents[N]``). The folder is read-only to the toolkit: benchmarks, training and
explorations write to ``out/`` or to the folder the user names, never here.
"""

from __future__ import annotations

import functools
from importlib import resources
from pathlib import Path

from .errors import InputError

__all__ = ["DEFAULT_DESIGN", "designs_dir", "resolve_design", "shipped_designs", "shipped_path"]

#: File name of the embedded default design (``fsdvs-hw explore`` with no design argument).
DEFAULT_DESIGN = "default.toml"


@functools.cache
def designs_dir() -> Path:
    """The folder of shipped designs, kernels and checkpoints (absolute).

    Returns
    -------
    Path
        ``fsdvs_hw/designs`` inside an installed wheel, else the checkout's top-level ``designs/``.

    Raises
    ------
    FileNotFoundError
        Neither exists (a wheel built without its data), or the package is imported from a zip
        archive, whose data cannot be read as files.
    """
    package = resources.files("fsdvs_hw")
    embedded = package.joinpath("designs")
    if embedded.is_dir():
        if not isinstance(embedded, Path):
            raise FileNotFoundError(
                f"fsdvs_hw's shipped designs are inside an archive ({embedded}); "
                "install the wheel (pip install) instead of importing it from a zip"
            )
        return embedded.resolve()
    checkout = Path(str(package)).resolve().parent / "designs"
    if (checkout / DEFAULT_DESIGN).is_file():
        return checkout
    raise FileNotFoundError(
        f"fsdvs_hw: no shipped designs folder (looked in {embedded} and {checkout}); "
        "reinstall the package from its wheel or run from a full checkout"
    )


def shipped_path(*parts: str) -> Path:
    """A path inside the shipped designs folder, e.g. ``shipped_path("kernels", "dog_7x7.json")``.

    The path is returned whether or not it exists (callers check and report what is missing).
    """
    return designs_dir().joinpath(*parts)


def shipped_designs() -> list[str]:
    """File names of the shipped design files (``default.toml``, ``sweep_*.toml``), sorted."""
    return sorted(p.name for p in designs_dir().glob("*.toml"))


def resolve_design(arg: str | Path | None) -> Path:
    """The design file a command-line argument names.

    Parameters
    ----------
    arg : str, Path or None
        ``None``: the embedded default design. An existing file: itself (the user's own design;
        its relative paths resolve against its own folder). Otherwise the name of a shipped
        design, with or without ``.toml`` (``sweep_asic_bits``), so installed users can run the
        shipped designs from any folder.

    Raises
    ------
    InputError
        ``arg`` is neither an existing file nor a shipped design; the message lists the shipped ones.
    """
    if arg is None:
        return shipped_path(DEFAULT_DESIGN)
    path = Path(arg)
    if path.is_file():
        return path
    name = path.name if path.suffix == ".toml" else f"{path.name}.toml"
    if path.parent == Path(".") or path.parent.name == "designs":
        candidate = shipped_path(name)
        if candidate.is_file():
            return candidate
    raise InputError(
        f"design {str(arg)!r}: no such file, and not a shipped design (shipped: {', '.join(shipped_designs())})"
    )
