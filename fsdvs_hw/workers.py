"""Local worker processes that die with their parent (no orphans after a kill).

:class:`concurrent.futures.ProcessPoolExecutor` workers wait on a queue whose other end every
sibling also holds, so when the main process is killed (``SIGKILL``, out of memory, a closed
terminal) they never see end-of-file: an idle worker waits forever and a busy one finishes its
fit first, each holding memory and CPU. :func:`process_pool` starts its workers with an
initializer that ties their lifetime to the parent's:

* on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (the kernel kills the worker when the parent
  dies, even while the worker is inside C code that holds the GIL);
* everywhere, a daemon thread that polls the parent's pid every
  :data:`PARENT_POLL_S` seconds and exits the worker when it changes (reparented to init).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from typing import Any

__all__ = ["PARENT_POLL_S", "process_pool"]

#: Seconds between checks of the parent's pid in each worker.
PARENT_POLL_S = 0.5


def process_pool(max_workers: int, *, initializer: Any = None, initargs: tuple[Any, ...] = ()) -> Any:
    """A spawn-context :class:`~concurrent.futures.ProcessPoolExecutor` whose workers die with this process.

    Parameters
    ----------
    max_workers : int
        Number of worker processes.
    initializer, initargs
        Optional extra initializer run in each worker after the lifetime tie.
    """
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    ctx = mp.get_context("spawn")  # fork after torch/BLAS threads started can deadlock
    return ProcessPoolExecutor(
        max_workers=max_workers, mp_context=ctx, initializer=_init_worker, initargs=(os.getpid(), initializer, initargs)
    )


def _init_worker(parent_pid: int, initializer: Any, initargs: tuple[Any, ...]) -> None:
    _die_with_parent(parent_pid)
    if initializer is not None:
        initializer(*initargs)


def _die_with_parent(parent_pid: int) -> None:
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # pragma: no cover - no prctl: the watchdog below still works
            pass
    if os.getppid() != parent_pid:  # the parent died before the tie was made
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent_pid,), name="fsdvs-parent-watch", daemon=True).start()


def _watch_parent(parent_pid: int) -> None:
    while True:
        time.sleep(PARENT_POLL_S)
        if os.getppid() != parent_pid:
            os._exit(1)
