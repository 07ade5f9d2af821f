"""How many torch threads an event-list simulation should use on this machine.

Example
-------
>>> from fsdvs_hw.sensor.threads import event_list_threads
>>> event_list_threads() >= 1
True
"""

from __future__ import annotations

import os

__all__ = ["event_list_threads"]


def event_list_threads() -> int:
    """torch intra-op threads for an event-list run: the CPU cores minus two, at least 1.

    The event pipeline (:class:`~fsdvs_hw.sensor.events._EventPipeline`) keeps two worker threads
    busy (emit, sort) beside torch's stepping thread. On 2 cores this gives 1: measured with
    ``fsdvs-hw bench sim``, 2 torch threads made the bikes event list ~25 % slower, their OpenMP
    team competing with the workers.

    Returns
    -------
    int
        ``max(1, os.cpu_count() - 2)``.
    """
    return max(1, (os.cpu_count() or 1) - 2)
