"""The ``fsdvs-hw`` command: the only place that parses arguments (one thin module per verb).

Errors a user can cause (bad input, a bad or missing argument, a missing tool, a file or folder
that cannot be read or written) print one line naming the file and the problem and exit with
status 2, never a traceback. Every verb takes ``--no-progress`` (progress bars, on stderr, show
only when stderr is a terminal anyway; :mod:`fsdvs_hw.progress`), and its ``--help`` shows each
option's default.

Each verb is a module of this package, registered in :data:`COMMANDS` as a dotted module path. A
verb module defines ``HELP`` (one line), optionally ``DESCRIPTION``, ``add_arguments(parser)``
and ``run(args) -> int``: it turns the parsed arguments into the typed options of one library
function, calls it and prints. It imports heavy dependencies inside ``run`` so that ``--help``
is fast. ``python -m fsdvs_hw.cli`` is the same command (:func:`console`).
"""

from __future__ import annotations

import argparse
import atexit
import gc
import importlib
import os
import select
import sys
import threading
from collections.abc import Sequence
from typing import NoReturn

from ..errors import InputError, ToolMissingError

__all__ = ["COMMANDS", "QUICK_EXIT_VERBS", "VERB_ENVIRONMENT", "console", "main"]

#: sub-command name -> module implementing it
COMMANDS: dict[str, str] = {
    "analyse": "fsdvs_hw.cli.analyse",
    "bench": "fsdvs_hw.cli.bench",
    "learn": "fsdvs_hw.cli.learn",
    "codesign-pilot": "fsdvs_hw.cli.codesign_pilot",
    "ablation": "fsdvs_hw.cli.ablation",
    "rate": "fsdvs_hw.cli.rate",
    "process-cells": "fsdvs_hw.cli.process_cells",
    "recording": "fsdvs_hw.cli.recording",
    "information": "fsdvs_hw.cli.information",
    "explore": "fsdvs_hw.cli.explore",
    "report": "fsdvs_hw.cli.report",
    "schema": "fsdvs_hw.cli.schema",
    "sweep": "fsdvs_hw.cli.sweep",
    "simulate": "fsdvs_hw.cli.simulate",
    "sizing": "fsdvs_hw.cli.sizing",
}


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions kept as written; every option's default appended unless its help states it.

    Like :class:`argparse.ArgumentDefaultsHelpFormatter`, but a default of ``None`` or ``False``
    (an unset option, an off switch) is not printed, nor a default the help text already names.
    """

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if (
            "default" in text
            or action.default in (None, False, argparse.SUPPRESS)
            or not (action.option_strings or action.nargs in (argparse.OPTIONAL, argparse.ZERO_OR_MORE))
        ):
            return text
        return text + " (default: %(default)s)"


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (``fsdvs-hw VERB: error: ...``), exit 2.

    argparse prints the whole usage block before the message; the usage is one ``--help`` away.
    """

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _parser(verb: str | None = None) -> argparse.ArgumentParser:
    """The parser of every verb, or of ``verb`` alone (a known verb named on the command line:
    the other verbs' modules, and what their options import, are then not loaded; ~0.5 s)."""
    parser = _Parser(
        prog="fsdvs-hw",
        description=(
            "Design frequency-selective event cameras: analyse a learned spatial kernel against "
            "the human contrast sensitivity function, fit it to hardware (resistive mesh, ASIC "
            "taps, metalens) and score what building it costs."
        ),
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_path in COMMANDS.items():
        if verb is not None and name != verb:
            continue
        module = importlib.import_module(module_path)
        # argparse %-formats help strings: a literal "95 % CI" must reach it as "95 %% CI"
        p = sub.add_parser(
            name,
            help=module.HELP.replace("%", "%%"),
            description=getattr(module, "DESCRIPTION", module.HELP),
            formatter_class=_HelpFormatter,
        )
        module.add_arguments(p)
        if "--no-progress" not in p._option_string_actions:
            p.add_argument(
                "--no-progress",
                action="store_true",
                help="no progress bars (none either when stderr is not a terminal)",
            )
        p.set_defaults(_module=module, _parser=p)
    return parser


def _version() -> str:
    from .. import __version__

    return f"fsdvs-hw {__version__}"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fsdvs-hw`` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = _parser(argv[0] if argv and argv[0] in COMMANDS else None)
    args, extra = parser.parse_known_args(argv)
    if extra:  # named by the verb's parser, so the message points at the verb's --help
        getattr(args, "_parser", parser).error(f"unrecognized arguments: {' '.join(extra)}")
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    from ..progress import set_progress

    set_progress(not args.no_progress)
    try:
        return int(args._module.run(args) or 0)
    except (InputError, ToolMissingError) as exc:
        print(f"fsdvs-hw {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a file or folder named on the command line: missing, unreadable, full disk
        if isinstance(exc, BrokenPipeError) and _stdout_closed():  # our reader went away (`| head`)
            _silence_stdout()
            return 128 + 13  # as a process ended by SIGPIPE (13), the status shells expect
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"fsdvs-hw {args.command}: error: {where}{exc.strerror or type(exc).__name__}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fsdvs-hw {args.command}: interrupted", file=sys.stderr)
        return 130


#: Environment defaults that :func:`console` gives a verb's process before NumPy loads (a value
#: the user set wins). ``simulate`` makes no NumPy linear algebra (torch has its own threads), and
#: OpenBLAS's idle worker thread spun for 0.13 of the 0.23 CPU s a bare ``import numpy`` took (2-core
#: machine, 3 runs each; ``perf stat``): CPU that the command's start-up, on both cores, needs.
VERB_ENVIRONMENT: dict[str, dict[str, str]] = {"simulate": {"OPENBLAS_NUM_THREADS": "1"}}


#: Verbs whose process, once the verb has returned, ends without the interpreter's teardown: exit
#: handlers (``atexit``) run and stdout/stderr are flushed, then ``os._exit``. Such a verb leaves
#: nothing for teardown to do: ``simulate`` has committed its file (written, ``fsync``'ed and
#: renamed) before it returns. The teardown it skips frees torch's objects one by one and runs
#: libtorch's destructors: 0.15–0.19 s of a 2.9–3.4 s bikes command (2-core machine, 3 runs).
QUICK_EXIT_VERBS = frozenset({"simulate"})


def console() -> int:
    """The ``fsdvs-hw`` console script and ``python -m fsdvs_hw.cli``: the verb's
    :data:`VERB_ENVIRONMENT`, :func:`main` on ``sys.argv``, then every live object frozen
    (``gc.freeze``) before the interpreter exits.

    The interpreter's last cycle collection at exit walks every object alive, torch's ~10⁵
    included: 0.4 s of a 1.6 s process that only imports torch (2-core machine, 3 runs each:
    1.63–1.71 s plain, 1.21–1.28 s frozen at the end). Frozen objects are skipped. Only for a
    process of its own, so :func:`main` (called in-process by tests and notebooks) does not.

    A verb of :data:`QUICK_EXIT_VERBS` that returns ends the process here (:func:`_quick_exit`);
    one that raises (``SystemExit`` from a bad argument included) goes the usual way.

    Returns
    -------
    int
        The exit status.
    """
    verb = sys.argv[1] if len(sys.argv) > 1 else ""
    for name, value in VERB_ENVIRONMENT.get(verb, {}).items():
        os.environ.setdefault(name, value)
    try:
        status = main()
    finally:
        gc.freeze()
    if verb in QUICK_EXIT_VERBS:
        _quick_exit(status)
    return status


def _stdout_closed() -> bool:
    """Whether stdout is a pipe whose reader has closed it (``poll`` reports ``POLLERR``); False
    where that cannot be asked (no ``poll``, no file descriptor), so a broken pipe elsewhere (a
    child process's) is reported as the error it is."""
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):
        return False


def _silence_stdout() -> None:
    """Point stdout at the null device, so that the interpreter's final flush of a closed pipe
    does not print a second error (Python's documented recipe for SIGPIPE)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # no real stdout (a test's capture): nothing to flush
        pass


def _quick_exit(status: int) -> None:
    """Wait for the threads a normal exit waits for (non-daemon), run the exit handlers, flush
    stdout and stderr, and end the process with ``status``."""
    for thread in threading.enumerate():
        if thread is not threading.main_thread() and not thread.daemon:
            thread.join()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing left to deliver
            pass
    os._exit(status)
