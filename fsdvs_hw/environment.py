"""Every environment variable fsdvs_hw reads, under one prefix: ``FSDVS_HW_``.

=================================  ============================================================
``FSDVS_HW_MAX_ALLOC_BYTES``       largest single array allocated (bytes; :mod:`fsdvs_hw.limits`)
``FSDVS_HW_WORKER_THREADS``        torch threads in each sweep, ablation and co-design worker
                                   process (the local pool sets 1)
``FSDVS_HW_REALISATION_PLUGINS``   modules that registered realisations at run time, imported by
                                   spawned workers (set by :func:`~fsdvs_hw.realise.registry.register_realisation`;
                                   installed plugins use the ``fsdvs_hw.realisations`` entry points)
``FSDVS_HW_CACHE``                 folder of the compiled event kernels (default ``$XDG_CACHE_HOME/fsdvs_hw``)
``FSDVS_HW_NO_NATIVE``             set: never build or load the compiled event kernels
=================================  ============================================================

The names read before (``FSDVS_MAX_ALLOC_BYTES``, ``FSDVS_SWEEP_THREADS``,
``FSDVS_CODESIGN_THREADS``, ``FSDVS_REALISATION_PLUGINS``) still work, with a
:class:`DeprecationWarning`, when the new name is not set.

Example
-------
>>> import os
>>> os.environ["FSDVS_HW_WORKER_THREADS"] = "1"
>>> env("FSDVS_HW_WORKER_THREADS")
'1'
>>> del os.environ["FSDVS_HW_WORKER_THREADS"]
"""

from __future__ import annotations

import os
import warnings

__all__ = ["ENVIRONMENT", "env", "set_env"]

#: name → (former names still read, what it sets)
ENVIRONMENT: dict[str, tuple[tuple[str, ...], str]] = {
    "FSDVS_HW_MAX_ALLOC_BYTES": (("FSDVS_MAX_ALLOC_BYTES",), "largest single array allocated (bytes)"),
    "FSDVS_HW_WORKER_THREADS": (
        ("FSDVS_SWEEP_THREADS", "FSDVS_CODESIGN_THREADS"),
        "torch threads per sweep, ablation and co-design worker process",
    ),
    "FSDVS_HW_REALISATION_PLUGINS": (
        ("FSDVS_REALISATION_PLUGINS",),
        "modules of realisations registered at run time (os.pathsep-separated)",
    ),
    "FSDVS_HW_CACHE": ((), "folder of the compiled event kernels"),
    "FSDVS_HW_NO_NATIVE": ((), "set: do not use the compiled event kernels"),
}


def env(name: str) -> str | None:
    """The value of one of :data:`ENVIRONMENT`'s variables (or of a former name, with a warning).

    Parameters
    ----------
    name : str
        A key of :data:`ENVIRONMENT`.

    Returns
    -------
    str or None
        None when neither the name nor a former name is set (or set to the empty string).

    Raises
    ------
    KeyError
        ``name`` is not one of fsdvs_hw's variables (a programming error, not user input).
    """
    former, _ = ENVIRONMENT[name]
    value = os.environ.get(name)
    if value:
        return value
    for old in former:
        value = os.environ.get(old)
        if value:
            warnings.warn(f"${old} is deprecated; set ${name} instead", DeprecationWarning, stacklevel=2)
            return value
    return None


def set_env(name: str, value: str | None, *, default: bool = False) -> None:
    """Set (``value``) or clear (None) one of :data:`ENVIRONMENT`'s variables for this process and
    the processes it spawns; ``default=True`` leaves a value already set alone."""
    ENVIRONMENT[name]  # noqa: B018 - only fsdvs_hw's own names
    if value is None:
        os.environ.pop(name, None)
    elif not (default and os.environ.get(name)):
        os.environ[name] = value
