"""Run an iterator ahead of its consumer in a background thread (bounded memory).

The ``simulate`` command's frames come from a video decoder: ffmpeg in its own process, then a
little Python per frame (imageio's read, v2e's BGR-to-gray or the display transfer). In the
consumer's thread that work is serial with the simulation's stepping; in a prefetch thread it
overlaps it, and it starts while the main thread is still importing torch (docs/speed.md). Pipe
reads, OpenCV and most NumPy loops release the GIL, so the thread costs the consumer little.

Example
-------
>>> from fsdvs_hw.prefetch import prefetch
>>> list(prefetch(iter(range(5)), max_items=2))
[0, 1, 2, 3, 4]
"""

from __future__ import annotations

import contextvars
import queue
import threading
from collections.abc import Iterable, Iterator
from typing import Any, Generic, TypeVar

from .errors import InputError

__all__ = ["Prefetched", "prefetch"]

T = TypeVar("T")

#: Seconds between the producer's checks that the consumer has gone away while the queue is full.
_POLL_S = 0.05

_ITEM, _END, _ERROR = 0, 1, 2


def _produce(items: Iterator[Any], q: queue.Queue, stop: threading.Event) -> None:
    """Put each item of ``items`` on ``q`` until it ends, fails or ``stop`` is set; then close it."""
    try:
        for item in items:
            while True:
                if stop.is_set():
                    return
                try:
                    q.put((_ITEM, item), timeout=_POLL_S)
                    break
                except queue.Full:
                    continue
        q.put((_END, None))  # blocks until the consumer takes an item or drains the queue
    except BaseException as exc:  # noqa: BLE001  handed to the consumer, raised in its thread
        q.put((_ERROR, exc))
    finally:
        close = getattr(items, "close", None)
        if close is not None:
            close()  # a generator's finally (the decoder's reader) runs here, in its own thread


def prefetch(items: Iterable[T], *, max_items: int = 8, name: str = "fsdvs-prefetch") -> Prefetched[T]:
    """The items of ``items``, produced up to ``max_items`` ahead in a background thread.

    The producer thread starts at once (not on the first ``next()``), so work such as decoding
    overlaps whatever the caller does before it consumes. Items arrive in order; an exception of
    the source is raised in the consumer at the point where its next item would have been, with
    its traceback. Closing the returned iterator (before or after its first item), dropping it,
    or an exception in the consumer's loop stops the producer after the item it is producing and
    closes the source.

    Parameters
    ----------
    items : iterable
        The source; iterated only in the producer thread.
    max_items : int
        Items held ahead of the consumer (>= 1): the memory bound, ``max_items`` items.
    name : str
        The producer thread's name.

    Returns
    -------
    Prefetched
        An iterator over the same items; its ``close()`` stops the producer.

    Raises
    ------
    InputError
        ``max_items`` is not an integer >= 1.

    Example
    -------
    >>> from fsdvs_hw.prefetch import prefetch
    >>> sum(prefetch((i * i for i in range(4)), max_items=1))
    14
    """
    if not isinstance(max_items, int) or isinstance(max_items, bool) or max_items < 1:
        raise InputError(f"prefetch: max_items must be an integer >= 1, got {max_items!r}")
    q: queue.Queue = queue.Queue(maxsize=max_items)
    stop = threading.Event()
    # in a copy of the caller's context: the items see its context variables (an allocation_limit)
    run_in = contextvars.copy_context().run
    thread = threading.Thread(target=run_in, args=(_produce, iter(items), q, stop), name=name, daemon=True)
    thread.start()
    return Prefetched(q, stop, thread)


class Prefetched(Generic[T]):
    """The consumer's side of :func:`prefetch`: an iterator with ``close()``."""

    def __init__(self, q: queue.Queue, stop: threading.Event, thread: threading.Thread) -> None:
        self._q, self._stop, self._thread = q, stop, thread
        self._done = False

    def __iter__(self) -> Prefetched[T]:
        return self

    def __next__(self) -> T:
        if self._done:
            raise StopIteration
        kind, value = self._q.get()
        if kind == _ITEM:
            return value
        self.close()
        if kind == _END:
            raise StopIteration
        raise value

    def close(self) -> None:
        """Stop the producer and wait until it has closed the source (idempotent)."""
        if self._done:
            return
        self._done = True
        self._stop.set()
        while self._thread.is_alive():  # drain, so a producer blocked on a full queue sees the stop
            try:
                self._q.get(timeout=_POLL_S)
            except queue.Empty:
                pass
        self._thread.join()

    def __del__(self) -> None:  # dropped without close(): the producer must not run on
        if not getattr(self, "_done", True):
            self.close()
