"""Process-wide control of one streamed simulation run: stopping on signals, and the cycle collector.

A run to an event file must stop at once on SIGINT or SIGTERM and leave no file behind
(:func:`stop_on_signals` turns the signals into :class:`Stopped`; :func:`signals_deferred`
holds them back while torch loads, whose import cannot be interrupted safely). Its start-up
imports some 10⁵ long-lived objects that the cycle collector would otherwise scan again and again
(:func:`collector_spares_imports` imports with the collector off and freezes them;
:func:`frozen_objects_restored` undoes that freeze for an in-process caller).

Both are process-wide: only the ``simulate`` command uses them, never the simulator itself.
"""

from __future__ import annotations

import contextlib
import gc
import signal
import threading
from collections.abc import Iterator

__all__ = ["Stopped", "collector_spares_imports", "frozen_objects_restored", "signals_deferred", "stop_on_signals"]


class Stopped(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived; ``signum`` says which.

    Parameters
    ----------
    signum : int
        The signal's number.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


#: True while :func:`signals_deferred` holds: the handler records a signal without raising.
_defer_signals = [False]


@contextlib.contextmanager
def stop_on_signals() -> Iterator[list[int]]:
    """SIGINT and SIGTERM raise :class:`Stopped` in the main thread, except inside
    :func:`signals_deferred`.

    Yields
    ------
    list of int
        The signals received, in order: a library that swallows the exception cannot make the
        run succeed. Outside the main thread no handler is installed and the list stays empty.
    """
    got: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield got
        return

    def handler(signum: int, frame: object) -> None:
        got.append(signum)
        if not _defer_signals[0]:
            raise Stopped(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield got
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


@contextlib.contextmanager
def signals_deferred(stopped: list[int]) -> Iterator[None]:
    """Inside, SIGINT and SIGTERM are only recorded in ``stopped``; on the way out the first one
    raises :class:`Stopped`.

    For importing torch: its import runs Python called from C++ (pybind11), and an exception
    raised there by a signal handler cannot unwind through C++: the process aborted (SIGABRT)
    instead of stopping cleanly (``tests/test_eventfile_safety.py``, a signal sent during
    start-up).

    Parameters
    ----------
    stopped : list of int
        The list that :func:`stop_on_signals` yielded.
    """
    _defer_signals[0] = True
    try:
        yield
    finally:
        _defer_signals[0] = False
    if stopped:
        raise Stopped(stopped[0])


@contextlib.contextmanager
def collector_spares_imports() -> Iterator[None]:
    """Import inside without Python's cycle collector, then freeze what exists (``gc.freeze``).

    Importing torch creates some 10⁵ long-lived objects: the collector ran ~370 times during the
    command's imports (0.08–0.13 s) and one full collection during the run walked all of them
    again (0.09–0.11 s; bikes, ``gc.callbacks``, 2 runs each). Frozen objects are never scanned
    by later collections; the collector is back on for the run (the simulation's own cycles are
    still collected). Process-wide, so only the ``simulate`` command does it, never the
    simulator, and the run undoes the freeze when it returns (:func:`frozen_objects_restored`).
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        gc.freeze()
        if enabled:
            gc.enable()


@contextlib.contextmanager
def frozen_objects_restored() -> Iterator[None]:
    """Unfreeze (``gc.unfreeze``) on the way out what :func:`collector_spares_imports` froze
    inside, where nothing was frozen before: a caller of :func:`fsdvs_hw.cli.main` in its own
    process (a test, a notebook) gets its collector back as it was. The console script freezes
    again before the interpreter exits (:func:`fsdvs_hw.cli.console`)."""
    frozen_before = gc.get_freeze_count()
    try:
        yield
    finally:
        if frozen_before == 0:
            gc.unfreeze()
