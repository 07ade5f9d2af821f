"""The command's handling of Python's cycle collector: imports without it, a freeze that the
``simulate`` verb undoes for in-process callers, and the console script's freeze before exit."""

import gc
import subprocess
import sys

import pytest

from fsdvs_hw import cli
from fsdvs_hw.cli import simulate as simulate_verb


@pytest.fixture
def unfrozen():
    """Each test starts and ends with nothing frozen and the collector on."""
    gc.unfreeze()
    gc.enable()
    yield
    gc.unfreeze()
    gc.enable()


def test_imports_run_without_the_collector_and_are_frozen_after(unfrozen):
    with simulate_verb._collector_spares_imports():
        assert not gc.isenabled()
        made_inside = [[] for _ in range(1000)]  # tracked containers created while importing
    assert gc.isenabled()
    assert gc.get_freeze_count() >= len(made_inside)


def test_a_disabled_collector_stays_disabled(unfrozen):
    gc.disable()
    with simulate_verb._collector_spares_imports():
        pass
    assert not gc.isenabled()


def test_the_verb_undoes_its_freeze_for_an_in_process_caller(tmp_path, unfrozen):
    rc = cli.main(
        ["simulate", "example:carphone", "--out", str(tmp_path / "e.npz"), "--frames", "3", "--size", "12x16"]
        + ["--no-progress"]
    )
    assert rc == 0
    assert gc.get_freeze_count() == 0 and gc.isenabled()


def test_the_verb_leaves_a_callers_own_freeze_alone(unfrozen):
    gc.freeze()
    before = gc.get_freeze_count()
    with simulate_verb._frozen_objects_restored():
        with simulate_verb._collector_spares_imports():
            pass
    assert gc.get_freeze_count() >= before > 0


def test_console_freezes_before_the_interpreter_exits(monkeypatch, capsys, unfrozen):
    monkeypatch.setattr(sys, "argv", ["fsdvs-hw"])
    assert cli.console() == 2  # no verb: the help, status 2
    assert gc.get_freeze_count() > 0
    assert "usage" in capsys.readouterr().out


def test_python_m_runs_the_console_entry():
    res = subprocess.run(
        [
            sys.executable,
            "-c",
            "import runpy, sys, gc; sys.argv = ['fsdvs-hw']\n"
            "try:\n    runpy.run_module('fsdvs_hw.cli', run_name='__main__')\n"
            "except SystemExit as e:\n    print('status', e.code, 'frozen', gc.get_freeze_count() > 0)",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "status 2 frozen True" in res.stdout
