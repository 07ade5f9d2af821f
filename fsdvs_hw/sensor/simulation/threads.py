"""How many torch threads an event-list simulation should use on this machine, and the OS-level
names of its worker threads.

Example
-------
>>> from fsdvs_hw.sensor.simulation.threads import event_list_threads
>>> event_list_threads() >= 1
True
"""

from __future__ import annotations

import os
import sys
import threading

__all__ = ["event_list_threads", "name_os_thread"]


def event_list_threads() -> int:
    """torch intra-op threads for an event-list run: the CPU cores minus two, at least 1.

    The event pipeline (:class:`~fsdvs_hw.sensor.simulation.event_pipeline.EventPipeline`) keeps two worker threads
    busy (emit, sort) beside torch's stepping thread. On 2 cores this gives 1: measured with
    ``fsdvs-hw bench sim``, 2 torch threads made the bikes event list ~25 % slower, their OpenMP
    team competing with the workers.

    Returns
    -------
    int
        ``max(1, os.cpu_count() - 2)``.
    """
    return max(1, (os.cpu_count() or 1) - 2)


def name_os_thread() -> None:
    """Give the calling thread's OS-level name its Python name (its first 15 bytes; Linux, through
    ``prctl(PR_SET_NAME)``; elsewhere nothing).

    The event pipeline's workers call it when they start, so ``top -H``, ``ps -L``,
    ``/proc/PID/task/TID/comm`` and native profilers show ``fsdvs-emit_0``, ``fsdvs-sort_0`` and
    ``fsdvs-noise_0`` instead of ``python`` (``python -m benchmarks.sim --thread-cpu CLIP`` reads
    each one's CPU time that way).

    Examples
    --------
    >>> import sys, threading
    >>> def show(out):
    ...     name_os_thread()
    ...     if sys.platform.startswith("linux"):
    ...         tid = threading.get_native_id()
    ...         out.append(open(f"/proc/self/task/{tid}/comm").read().strip())
    ...     else:
    ...         out.append("fsdvs-demo")
    >>> out = []
    >>> t = threading.Thread(target=show, args=(out,), name="fsdvs-demo")
    >>> t.start(); t.join(); out
    ['fsdvs-demo']
    """
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        libc.prctl(15, threading.current_thread().name.encode()[:15], 0, 0, 0)  # 15: PR_SET_NAME
    except (OSError, AttributeError):  # no libc symbol: the name stays the process's
        pass
