"""Progress bars for waits longer than a couple of seconds: one rule for when they show.

Every long loop of the toolkit (a sweep's design points, :func:`~fsdvs_hw.realise.metalens.fit_metalens`'s
L-BFGS iterations, the event simulator's frames, the notebooks' sweeps) draws its bar through
:func:`progress_bar`, a `tqdm <https://tqdm.github.io>`_ bar on stderr. A function's ``progress``
argument decides whether it shows:

- ``True``: always; ``False``: never;
- ``None`` (the default): only when stderr is a terminal and progress has not been switched off
  for the process (:func:`set_progress`; the CLI's ``--no-progress`` does that). So piped output,
  log files, the test suite and batch jobs get no bar, an interactive terminal does.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import Any

__all__ = ["progress_bar", "progress_enabled", "set_progress"]

_ENABLED: bool = True  # the process-wide switch (--no-progress sets it False)


def set_progress(enabled: bool) -> None:
    """Switch automatic progress bars on or off for this process (``progress=None`` everywhere).

    Parameters
    ----------
    enabled : bool
        False: no bar unless a call asks with ``progress=True`` (the CLI's ``--no-progress``).
    """
    global _ENABLED
    _ENABLED = bool(enabled)


def progress_enabled(progress: bool | None = None) -> bool:
    """Whether a bar shows: ``progress`` if given, else the process switch and stderr being a terminal.

    Parameters
    ----------
    progress : bool, optional
        An explicit choice; None: automatic (see the module docstring).

    Returns
    -------
    bool
    """
    if progress is not None:
        return bool(progress)
    if not _ENABLED:
        return False
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):  # replaced or closed stderr
        return False


def progress_bar(
    iterable: Iterable[Any] | None = None,
    *,
    total: float | None = None,
    desc: str | None = None,
    unit: str = "it",
    progress: bool | None = None,
    **kwargs: Any,
) -> Any:
    """A tqdm bar on stderr, shown per :func:`progress_enabled` (a disabled bar costs nothing).

    Parameters
    ----------
    iterable : iterable, optional
        Wrapped and iterated as with ``tqdm(iterable)``; or None and call ``update(n)``.
    total : float, optional
        Expected number of steps (default ``len(iterable)`` where it has one).
    desc, unit : str
        Label and unit of the bar.
    progress : bool, optional
        Show it (True), hide it (False) or decide automatically (None).
    **kwargs
        Passed to :class:`tqdm.tqdm` (e.g. ``initial``, ``leave``).

    Returns
    -------
    tqdm.tqdm
        Use as a context manager or close it.
    """
    from tqdm import tqdm

    kwargs.setdefault("dynamic_ncols", True)
    return tqdm(
        iterable, total=total, desc=desc, unit=unit, file=sys.stderr, disable=not progress_enabled(progress), **kwargs
    )
