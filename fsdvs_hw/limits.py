"""Size limits checked before a large allocation: refuse with the figure and the limit.

A typo (``n_bins = 1000000``) should cost an error message, not minutes of swapping and a killed
machine. Functions that allocate an array whose size follows from user input estimate it first
and call :func:`check_allocation`, which raises an :class:`~fsdvs_hw.errors.InputError` naming
what would be allocated, its size and the limit.

The limit is :data:`DEFAULT_MAX_ALLOC_BYTES` (1 GiB); override it for one process with the
environment variable ``FSDVS_HW_MAX_ALLOC_BYTES`` (bytes, e.g. ``FSDVS_HW_MAX_ALLOC_BYTES=34359738368``
for 32 GiB) or for one block of code with :func:`allocation_limit`.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator

from .errors import InputError

__all__ = [
    "DEFAULT_MAX_ALLOC_BYTES",
    "MAX_CLIPS",
    "MAX_EPOCHS",
    "MAX_POINTS",
    "MAX_SEED",
    "MAX_SUBSTEPS",
    "MAX_WORKERS",
    "allocation_limit",
    "check_allocation",
    "check_count",
    "max_alloc_bytes",
]

#: Most local worker processes (``--workers``, ``[run] workers``): far above any useful count, low
#: enough that a typo does not fork thousands of processes.
MAX_WORKERS: int = 256
#: Largest seed (``--seed``, ``--seeds``): numpy's and torch's generators accept 0 <= seed < 2**32.
MAX_SEED: int = 2**32 - 1
#: Most clips of a training or test set (``--n-train``, ``--n-test``, ``--pilot``, ``[tasks] n_test``).
MAX_CLIPS: int = 100_000
#: Most training epochs (``--epochs-*``, ``[tasks] finetune_epochs``, ``[codesign] epochs``).
MAX_EPOCHS: int = 1000
#: Most design points a sweep may be asked to allow (``--max-points``, ``[run] max_points``).
MAX_POINTS: int = 10**9

#: Most simulator sub-steps per frame interval (``SensorConfig.substeps`` and ``max_substeps``): the
#: work grows linearly with them, so a typo (``substeps=10**9``) is refused instead of running for days.
MAX_SUBSTEPS: int = 100_000

#: Largest single array allocated without an explicit override (bytes).
DEFAULT_MAX_ALLOC_BYTES: int = 2**30

_ENV = "FSDVS_HW_MAX_ALLOC_BYTES"
_override: contextvars.ContextVar[int | None] = contextvars.ContextVar("fsdvs_max_alloc_bytes", default=None)


def max_alloc_bytes() -> int:
    """The limit in force: :func:`allocation_limit` block, else ``$FSDVS_HW_MAX_ALLOC_BYTES``, else the default."""
    v = _override.get()
    if v is not None:
        return v
    from .environment import env as _env

    env = _env(_ENV)
    if env is None:
        return DEFAULT_MAX_ALLOC_BYTES
    try:
        n = int(float(env))
    except ValueError:
        raise InputError(f"${_ENV}={env[:40]!r}: must be a number of bytes") from None
    if n < 1:
        raise InputError(f"${_ENV}={env[:40]!r}: must be a positive number of bytes")
    return n


@contextlib.contextmanager
def allocation_limit(n_bytes: int) -> Iterator[None]:
    """Use ``n_bytes`` as the allocation limit inside the ``with`` block (this thread/task only)."""
    if isinstance(n_bytes, bool) or not isinstance(n_bytes, int) or n_bytes < 1:
        raise InputError(f"allocation_limit: n_bytes must be a positive integer, got {n_bytes!r}")
    token = _override.set(n_bytes)
    try:
        yield
    finally:
        _override.reset(token)


def check_allocation(what: str, n_bytes: int | float) -> None:
    """Raise :class:`InputError` when allocating ``n_bytes`` for ``what`` would exceed the limit.

    Parameters
    ----------
    what : str
        What would be allocated, with the sizes that decide it (``"voxel_grid (B=1, n_bins=1e6, ...)"``).
    n_bytes : int or float
        Estimated size in bytes.
    """
    limit = max_alloc_bytes()
    if n_bytes > limit:
        raise InputError(
            f"{what}: would allocate {n_bytes / 2**30:.3g} GiB, more than the limit of "
            f"{limit / 2**30:.3g} GiB (raise it with ${_ENV} or fsdvs_hw.limits.allocation_limit)"
        )


def check_count(what: str, value: object, lo: int, hi: int) -> int:
    """``value`` as an integer in ``[lo, hi]``, or an :class:`InputError` naming ``what``, the value and the range.

    Examples
    --------
    >>> check_count("--workers", 4, 1, MAX_WORKERS)
    4
    """
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise InputError(f"{what} {str(value)[:40]}: out of range; allowed: an integer in [{lo}, {hi}]")
    return value
