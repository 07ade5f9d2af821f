"""The event-file writer's compiled message conversion: NumPy's values bit for bit, and every
problem left to NumPy's path, which words it (the same errors as before)."""

import re

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor import EventList
from fsdvs_hw.sensor.native import library as native
from fsdvs_hw.sensor.eventfiles import eventfile
from fsdvs_hw.sensor.eventfiles.eventfile import EventFileWriter, read_events

pytestmark = pytest.mark.skipif(not native.available(), reason="compiled kernels unavailable")

W, H = 40, 30


def _numpy_message(t, x, y, p):
    return np.rint(t * 1e6).astype(np.int64), x.astype(np.int16), y.astype(np.int16), (p > 0).astype(np.uint8)


def _events(t, x, y, p):
    n = len(t)
    return EventList(
        torch.zeros(1, dtype=torch.int64).expand(n),
        torch.as_tensor(x, dtype=torch.int64),
        torch.as_tensor(y, dtype=torch.int64),
        torch.as_tensor(t, dtype=torch.float64),
        torch.as_tensor(p, dtype=torch.int8),
    )


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.floats(0, 5000, allow_nan=False),
            st.integers(0, 5 * 10**9).map(lambda k: (k + 0.5) * 1e-6),  # halfway: rint's ties to even
        ),
        min_size=0,
        max_size=300,
    ),
    st.randoms(use_true_random=False),
)
def test_the_compiled_message_is_numpys_bit_for_bit(times, rnd):
    t = np.sort(np.array(times, dtype=np.float64))
    n = len(t)
    x = np.array([rnd.randrange(W) for _ in range(n)], dtype=np.int64)
    y = np.array([rnd.randrange(H) for _ in range(n)], dtype=np.int64)
    p = np.array([rnd.choice((-1, 1)) for _ in range(n)], dtype=np.int8)
    got = native.event_message(t, x, y, p, W, H, -1, 2**63 - 1)
    assert got is not None
    for a, b in zip(got, _numpy_message(t, x, y, p), strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def _good(n=5):
    t = np.linspace(0.001, 0.002, n)
    return t, np.arange(n, dtype=np.int64), np.arange(n, dtype=np.int64), np.ones(n, dtype=np.int8)


@pytest.mark.parametrize(
    "spoil",
    [
        lambda t, x, y, p: t.__setitem__(2, -1e-3),  # negative time
        lambda t, x, y, p: t.__setitem__(2, np.nan),
        lambda t, x, y, p: x.__setitem__(2, W),  # outside the sensor
        lambda t, x, y, p: y.__setitem__(2, -1),
        lambda t, x, y, p: p.__setitem__(2, 0),  # polarity
        lambda t, x, y, p: t.__setitem__(3, 0.0011),  # earlier than the one before
        lambda t, x, y, p: t.__setitem__(4, 5000.0),  # after max_t_us
    ],
)
def test_each_problem_is_left_to_numpy(spoil):
    t, x, y, p = _good()
    assert native.event_message(t, x, y, p, W, H, -1, 2**32 - 1) is not None
    spoil(t, x, y, p)
    assert native.event_message(t, x, y, p, W, H, -1, 2**32 - 1) is None


def test_times_before_the_last_written_are_left_to_numpy():
    t, x, y, p = _good()
    assert native.event_message(t, x, y, p, W, H, 1000, 2**32 - 1) is not None  # t[0] = 1000 µs
    assert native.event_message(t, x, y, p, W, H, 1001, 2**32 - 1) is None


@pytest.mark.parametrize(
    ("spoil", "message"),
    [
        (lambda t, x, y, p: p.__setitem__(2, 0), "polarity must be +1"),
        (lambda t, x, y, p: x.__setitem__(2, W), "pixel outside the 40x30 sensor"),
        (lambda t, x, y, p: t.__setitem__(3, 0.0011), "non-decreasing time"),
        (lambda t, x, y, p: t.__setitem__(4, 5000.0), "uint32 µs range"),
        (lambda t, x, y, p: t.__setitem__(0, -1.0), "negative time"),
    ],
)
def test_the_writer_still_words_each_problem(tmp_path, spoil, message):
    t, x, y, p = _good()
    spoil(t, x, y, p)
    with pytest.raises(InputError, match=re.escape(message)):
        with EventFileWriter(tmp_path / "e.h5", W, H) as w:
            w.write(_events(t, x, y, p))
    assert not (tmp_path / "e.h5").exists()


def test_a_streams_events_take_the_compiled_path_and_write_the_same_file(tmp_path, monkeypatch):
    rng = np.random.default_rng(3)
    n = 100_000
    t = np.sort(rng.uniform(0, 3, n))
    ev = _events(t, rng.integers(0, W, n), rng.integers(0, H, n), rng.choice(np.array([-1, 1], np.int8), n))
    calls = []
    real = native.event_message
    monkeypatch.setattr(native, "event_message", lambda *a: calls.append(1) or real(*a))
    with EventFileWriter(tmp_path / "fast.h5", W, H) as w:
        w.write(ev)
    assert calls  # the compiled path ran
    monkeypatch.setattr(eventfile, "_message_columns", lambda *a: None)
    with EventFileWriter(tmp_path / "numpy.h5", W, H) as w:
        w.write(ev)
    fast, slow = read_events(tmp_path / "fast.h5"), read_events(tmp_path / "numpy.h5")
    for col in ("t_us", "x", "y", "p"):
        assert np.array_equal(getattr(fast, col), getattr(slow, col))
    assert len(fast.t_us) == n


def test_columns_of_other_dtypes_take_numpys_path(tmp_path):
    t, x, y, p = _good()
    ev = EventList(
        torch.zeros(5, dtype=torch.int64),
        torch.as_tensor(x, dtype=torch.int32),
        torch.as_tensor(y),
        torch.as_tensor(t),
        torch.as_tensor(p),
    )
    assert eventfile._message_columns(ev, W, H, -1, 2**32 - 1) is None
    assert eventfile._message_columns(_events(t, x, y, p), W, H, -1, 2**32 - 1) is not None
    with EventFileWriter(tmp_path / "e.h5", W, H) as w:
        w.write(ev)
    assert np.array_equal(read_events(tmp_path / "e.h5").x, x)
