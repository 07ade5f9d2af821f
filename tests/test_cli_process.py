"""The command's process settings: Python's cycle collector (imports without it, a freeze that the
``simulate`` verb undoes for in-process callers, the console script's freeze before exit) and
OpenBLAS's threads (one for ``simulate`` and its writer process)."""

import gc
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from fsdvs_hw import cli
from fsdvs_hw.cli import simulate as simulate_verb
from fsdvs_hw.sensor.eventfiles import run_control
from fsdvs_hw.sensor.eventfiles.eventfile import EventFileWriter


@pytest.fixture
def unfrozen():
    """Each test starts and ends with nothing frozen and the collector on."""
    gc.unfreeze()
    gc.enable()
    yield
    gc.unfreeze()
    gc.enable()


def test_imports_run_without_the_collector_and_are_frozen_after(unfrozen):
    with run_control.collector_spares_imports():
        assert not gc.isenabled()
        made_inside = [[] for _ in range(1000)]  # tracked containers created while importing
    assert gc.isenabled()
    assert gc.get_freeze_count() >= len(made_inside)


def test_a_disabled_collector_stays_disabled(unfrozen):
    gc.disable()
    with run_control.collector_spares_imports():
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
    with run_control.frozen_objects_restored():
        with run_control.collector_spares_imports():
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


def test_simulate_gets_one_openblas_thread_unless_the_user_chose(monkeypatch, capsys, unfrozen):
    for preset_value, want in ((None, "1"), ("3", "3")):
        if preset_value is None:
            monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
        else:
            monkeypatch.setenv("OPENBLAS_NUM_THREADS", preset_value)
        monkeypatch.setattr(sys, "argv", ["fsdvs-hw", "simulate"])  # no video: argparse's error, status 2
        with pytest.raises(SystemExit):
            cli.console()
        assert os.environ["OPENBLAS_NUM_THREADS"] == want
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    monkeypatch.setattr(sys, "argv", ["fsdvs-hw"])
    cli.console()
    assert "OPENBLAS_NUM_THREADS" not in os.environ  # other verbs: untouched
    capsys.readouterr()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_h5_writer_process_runs_with_one_openblas_thread(tmp_path, monkeypatch):
    pytest.importorskip("h5py")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "8")
    with EventFileWriter(tmp_path / "e.h5", 4, 4) as w:
        env = (Path("/proc") / str(w._child.pid) / "environ").read_bytes().split(b"\0")
    assert b"OPENBLAS_NUM_THREADS=1" in env
    assert (tmp_path / "e.h5").exists()


_QUICK_EXIT_CHILD = """
import atexit, sys
atexit.register(lambda: print("exit handler ran", flush=True))
sys.argv = ["fsdvs-hw"] + sys.argv[1:]
from fsdvs_hw.cli import console
print("status", console())  # a quick-exit verb never gets here
"""


def test_simulate_ends_its_process_without_teardown_after_committing_the_file(tmp_path):
    out = tmp_path / "e.h5"
    args = ["simulate", "example:carphone", "--out", str(out), "--frames", "3", "--size", "12x16", "--no-progress"]
    res = subprocess.run([sys.executable, "-c", _QUICK_EXIT_CHILD, *args], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "exit handler ran" in res.stdout and f"{out}: " in res.stdout  # handlers ran, the summary flushed
    assert "status" not in res.stdout  # the process ended inside console()
    assert out.exists()
    # a failing run keeps its status; another verb returns to the caller and tears down as usual
    bad = subprocess.run(
        [sys.executable, "-c", _QUICK_EXIT_CHILD, "simulate", str(tmp_path / "missing.mp4"), "--out", str(out)],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and "missing.mp4" in bad.stderr
    other = subprocess.run([sys.executable, "-c", _QUICK_EXIT_CHILD], capture_output=True, text=True)
    assert "status 2" in other.stdout and "exit handler ran" in other.stdout


def test_a_missing_video_is_reported_before_torch_loads(tmp_path):
    code = (
        "import sys\nfrom fsdvs_hw.cli import main\n"
        f"rc = main(['simulate', {str(tmp_path / 'missing.mp4')!r}, '--out', {str(tmp_path / 'e.h5')!r}])\n"
        "print('status', rc, 'torch loaded', 'torch' in sys.modules)"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "status 2 torch loaded False" in res.stdout
    assert "missing.mp4" in res.stderr and "does not exist" in res.stderr


def test_an_undecodable_video_found_by_the_probe_thread_is_one_line_and_leaves_no_file(tmp_path, capsys):
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video")
    out = tmp_path / "e.h5"
    assert cli.main(["simulate", str(bad), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "bad.mp4" in err and "cannot be decoded" in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == [bad]


def test_a_signal_while_torch_loads_stops_the_run_after_the_import(unfrozen):
    """Inside ``signals_deferred`` a SIGTERM is only recorded (an exception raised inside
    torch's import, from Python called by C++, aborted the process); it stops the run on the way
    out. Outside, a signal raises at once."""
    reached = False
    with run_control.stop_on_signals() as stopped:
        with pytest.raises(run_control.Stopped) as info:
            with run_control.signals_deferred(stopped):
                os.kill(os.getpid(), signal.SIGTERM)
                for _ in range(1000):  # the handler runs between bytecodes: recorded, not raised
                    pass
                reached = True
        assert reached and info.value.signum == signal.SIGTERM
        with pytest.raises(run_control.Stopped) as info:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):
                pass
        assert info.value.signum == signal.SIGINT
    assert stopped == [signal.SIGTERM, signal.SIGINT]


def test_a_closed_stdout_ends_quietly_after_the_file_is_written(tmp_path):
    """``fsdvs-hw simulate … | head -0``: the summary line meets a closed pipe after the file is
    committed. The file stays, nothing is printed on stderr, the status is SIGPIPE's 141."""
    out = tmp_path / "e.npz"
    cmd = [sys.executable, "-m", "fsdvs_hw.cli", "simulate", "example:carphone", "--frames", "3"]
    cmd += ["--size", "12x16", "--out", str(out), "--no-progress"]
    with open(tmp_path / "err.txt", "wb") as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err)
        proc.stdout.close()  # the reader is gone before the command prints
        rc = proc.wait(timeout=120)
    assert rc == 141
    assert (tmp_path / "err.txt").read_text().strip() == ""
    assert out.exists()


def test_a_broken_pipe_elsewhere_is_reported_as_an_error(monkeypatch, capsys):
    """A BrokenPipeError that is not our stdout's (a child process's pipe) is not mistaken for a
    reader that went away: the usual one-line error and status 2."""

    def broken(args):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(simulate_verb, "run", broken)
    assert cli.main(["simulate", "example:carphone", "--out", "e.h5"]) == 2
    assert "fsdvs-hw simulate: error: Broken pipe" in capsys.readouterr().err
