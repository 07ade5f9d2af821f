"""The background prefetch of the simulate command's frames: order, errors, bounded lead, clean stop."""

import threading
import time

import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.prefetch import prefetch


def _wait_until(cond, timeout=10.0):
    t_end = time.monotonic() + timeout
    while not cond() and time.monotonic() < t_end:
        time.sleep(0.01)
    return cond()


def _endless(closed):
    """An endless source that sets ``closed`` when it is closed (its finally runs)."""
    try:
        yield from range(10**9)
    finally:
        closed.set()


def test_items_arrive_in_order_and_all_of_them():
    assert list(prefetch(iter(range(1000)), max_items=3)) == list(range(1000))
    assert list(prefetch([], max_items=1)) == []


def test_producer_runs_ahead_by_at_most_max_items_and_starts_before_the_first_next():
    produced = []

    def source():
        for i in range(100):
            produced.append(i)
            yield i

    gen = prefetch(source(), max_items=4)
    # the producer starts at once: 4 items queued, the 5th taken from the source and waiting to be put
    assert _wait_until(lambda: len(produced) == 5)
    time.sleep(0.2)
    assert len(produced) == 5
    assert next(gen) == 0
    assert _wait_until(lambda: len(produced) == 6)
    gen.close()


def test_error_of_the_source_is_raised_where_its_item_would_be():
    def source():
        yield 1
        yield 2
        raise InputError("frame 2 cannot be decoded")

    got = []
    with pytest.raises(InputError, match="frame 2 cannot be decoded"):
        for v in prefetch(source(), max_items=8):
            got.append(v)
    assert got == [1, 2]


def test_close_stops_the_producer_and_closes_the_source():
    closed = threading.Event()
    gen = prefetch(_endless(closed), max_items=2, name="test-prefetch")
    assert next(gen) == 0
    gen.close()
    assert closed.is_set()  # close() returns after the source's finally ran
    assert not any(t.name == "test-prefetch" for t in threading.enumerate())


def test_close_before_the_first_item_stops_the_producer_too():
    """The producer starts at once; closing before any next() (the simulate command does when
    loading the kernel fails) must stop it and close the source, not leave it polling."""
    closed = threading.Event()
    gen = prefetch(_endless(closed), max_items=2, name="test-prefetch-early")
    time.sleep(0.1)  # let it fill the queue and block
    gen.close()
    assert closed.is_set()
    assert not any(t.name == "test-prefetch-early" for t in threading.enumerate())
    with pytest.raises(StopIteration):
        next(gen)


def test_consumer_error_mid_loop_also_stops_the_producer():
    closed = threading.Event()
    with pytest.raises(ZeroDivisionError):
        for v in prefetch(_endless(closed), max_items=2):
            if v == 3:
                _ = 1 / 0
    assert _wait_until(closed.is_set)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "4"])
def test_bad_max_items_is_refused_by_name(bad):
    with pytest.raises(InputError, match="max_items"):
        prefetch(iter([1]), max_items=bad)


def test_the_producer_sees_the_callers_context_variables():
    """Items are made in a copy of the caller's context: an allocation_limit block holds there too."""
    from fsdvs_hw.limits import allocation_limit, max_alloc_bytes

    def limits():
        for _ in range(2):
            yield max_alloc_bytes()

    with allocation_limit(12345):
        seen = list(prefetch(limits(), max_items=1))
    assert seen == [12345, 12345]
