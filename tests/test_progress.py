"""Progress bars: shown on a terminal, never in pipes or when switched off; they count real work."""

from __future__ import annotations

import io

import numpy as np
import pytest

from fsdvs_hw import progress as prog
from fsdvs_hw.progress import progress_bar, progress_enabled, set_progress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture
def restore_switch():
    set_progress(True)  # a CLI test run earlier in this worker may have left --no-progress's switch off
    yield
    set_progress(True)


def test_auto_shows_only_on_a_terminal_and_only_while_switched_on(monkeypatch, restore_switch):
    monkeypatch.setattr(prog.sys, "stderr", io.StringIO())
    assert progress_enabled() is False  # a pipe or file: no bar
    assert progress_enabled(True) is True  # an explicit request wins
    monkeypatch.setattr(prog.sys, "stderr", _Tty())
    assert progress_enabled() is True
    set_progress(False)  # the CLI's --no-progress
    assert progress_enabled() is False and progress_enabled(True) is True
    assert progress_enabled(False) is False


def test_a_bar_writes_to_stderr_only_when_enabled(monkeypatch, restore_switch):
    err = _Tty()
    monkeypatch.setattr(prog.sys, "stderr", err)
    assert list(progress_bar(range(3), desc="work", mininterval=0)) == [0, 1, 2]
    assert "work" in err.getvalue() and "3/3" in err.getvalue()
    quiet = io.StringIO()
    monkeypatch.setattr(prog.sys, "stderr", quiet)
    assert list(progress_bar(range(3), desc="work")) == [0, 1, 2]
    assert quiet.getvalue() == ""


def _spy_bars(monkeypatch) -> list:
    """Record every bar made (drawn into a string, so it counts as a shown bar does)."""
    monkeypatch.setattr(prog.sys, "stderr", io.StringIO())
    seen = []
    real = prog.progress_bar

    def spy(*a, **kw):
        bar = real(*a, **kw)
        seen.append(bar)
        return bar

    monkeypatch.setattr(prog, "progress_bar", spy)
    return seen


def test_event_list_bar_counts_frame_intervals_and_leaves_events_unchanged(monkeypatch):
    torch = pytest.importorskip("torch")
    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.sensor import event_list

    seen = _spy_bars(monkeypatch)
    video = torch.rand(1, 6, 12, 12, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    k = reference_kernel("dog", 5)
    ev = event_list(video, k, progress=True)
    assert len(seen) == 1 and seen[0].total == 5 and seen[0].n == 5  # 6 frames: 5 intervals stepped
    ev_quiet = event_list(video, k, progress=False)
    assert torch.equal(ev.t, ev_quiet.t) and torch.equal(ev.x, ev_quiet.x)


def test_fit_metalens_bar_reaches_its_iteration_budget_without_changing_the_fit(monkeypatch):
    pytest.importorskip("torch")
    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.realise.metalens import fit_metalens

    seen = _spy_bars(monkeypatch)
    k = reference_kernel("dog", 5)
    opts = dict(n_wavelengths=1, illuminant=555e-9, n_terms=1, n_starts=2, max_iter=12, guard_px=1, n_sub=6)
    a = fit_metalens(k, progress=True, **opts)
    # budget: 2 starts x max(10, 12 // 6) + 12 refinement (+ max(10, 12 // 4) polish when the models differ)
    assert len(seen) == 1 and seen[0].n == seen[0].total and seen[0].total in (2 * 10 + 12, 2 * 10 + 12 + 10)
    assert seen[0].total >= a.fit_info["iterations"]
    b = fit_metalens(k, progress=False, **opts)
    assert np.allclose(a.psfs[0], b.psfs[0], rtol=0, atol=0)
