"""Keep freed memory in the process instead of handing it back to the OS (glibc ``mallopt``).

A streamed event list allocates and frees the same few frame-sized buffers at every sub-step
(torch tensors, NumPy work arrays of the event workers, decoded frames). glibc returns a freed
block to the kernel when the free memory at the top of the heap exceeds its trim threshold, or
when the block was mapped on its own; the next allocation of that size then faults every page in
again, zeroed by the kernel. On 1280×720 frames that made the ``simulate`` command spend 1.5–2 s
of its 5.6–6.6 s in the kernel (``/usr/bin/time``, bigbuckbunny.mp4, ``v2e-default``);
:func:`retain_freed_memory` cut that to 1.1 s (docs/speed.md). The peak resident memory does not
grow (the same buffers are reused), but memory freed at the end of a peak stays with the process,
up to the trim threshold, until it exits.

It is a process-wide setting, so only commands call it (``fsdvs-hw simulate``), never the library.

Example
-------
>>> from fsdvs_hw.allocator import retain_freed_memory
>>> isinstance(retain_freed_memory(), bool)
True
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

__all__ = ["MMAP_THRESHOLD_BYTES", "TRIM_THRESHOLD_BYTES", "retain_freed_memory"]

#: Free memory (bytes) at the top of the heap that glibc keeps before trimming it.
TRIM_THRESHOLD_BYTES = 256 << 20

#: Allocations below this size (bytes) come from the heap, not their own mapping (glibc's
#: largest: half of a 64 MiB heap).
MMAP_THRESHOLD_BYTES = 32 << 20

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


def retain_freed_memory() -> bool:
    """Set glibc's trim threshold to :data:`TRIM_THRESHOLD_BYTES` and its mapping threshold to
    :data:`MMAP_THRESHOLD_BYTES` for this process.

    Returns
    -------
    bool
        True if both were set; False where the C library is not glibc (macOS, musl, Windows) or
        refuses, and nothing changed.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)) and bool(
        mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
    )
