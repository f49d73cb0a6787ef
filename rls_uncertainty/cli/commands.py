"""The commands of ``rls-uncertainty`` (:mod:`rls_uncertainty.cli` says how they behave):
the parser made of every command group's flags, running the command chosen with its errors
and stopping signals each said in one line, and the ``estimator_node`` console script's loader.
"""

from __future__ import annotations

import _thread
import argparse
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any, NoReturn
from xml.etree import ElementTree

from ..errors import MissingExtra, RlsUncertaintyError
from ..extras import optional
from .bags import add_convert, add_make_bag
from .offline import add_campaign, add_predict, add_replay
from .ros import add_demo, add_operator_commands, add_play
from .simulation import add_montecarlo, add_multisine, add_simulate

__all__ = ["parse", "run", "build_parser", "load_estimator_node", "Stopped"]

_SUBCOMMANDS = (add_demo, add_simulate, add_montecarlo, add_multisine, add_make_bag, add_convert, add_replay,
                add_campaign, add_predict, add_play, add_operator_commands)
# The commands that handle their signals themselves (rclpy's handlers, the dashboard's loop).
_OWN_SIGNALS = frozenset({"demo", "play", "dashboard", "status", "enable", "disable", "reset"})


class Stopped(KeyboardInterrupt):
    """A stopping signal (SIGINT, SIGTERM, SIGHUP), raised in the main thread where it arrived,
    so that the command unwinds as for Ctrl-C. (Not KeyboardInterrupt itself for SIGINT: a
    Ctrl-C that reached a replay as it started, handled here, still made the interpreter end
    the process by SIGINT at exit instead of the status returned; CPython marks an unhandled
    interrupt by the exception's exact type, so a subclass is never marked.)"""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _stop(signum: int, _frame: FrameType | None) -> None:
    raise Stopped(signum)


class _Resend:
    """A stop raised where Python cannot propagate it, raised again in the command's own code.

    The handler runs wherever the main thread is when the signal arrives; inside a weakref
    callback or a ``__del__`` its :class:`Stopped` cannot propagate (Python prints "Exception
    ignored" and goes on). Installed as ``sys.unraisablehook`` while the command's handlers are
    in, this says nothing about such a :class:`Stopped` and has a thread of its own simulate the
    signal again in the main thread (:func:`_thread.interrupt_main`), whose handler then runs in
    the command's code; one swallowed again comes back here. Every other unraisable exception
    goes to the hook before. :meth:`close`, before the handlers are put back, makes sure that no
    thread simulates a signal after it."""

    def __init__(self, usual: Callable[[Any], object]) -> None:
        self.usual, self.open, self.lock = usual, True, threading.Lock()

    def __call__(self, unraisable: Any) -> None:
        if isinstance(unraisable.exc_value, Stopped):
            _thread.start_new_thread(self._send, (unraisable.exc_value.signum,))
        else:
            self.usual(unraisable)

    def _send(self, signum: int) -> None:
        with self.lock:
            if self.open:
                _thread.interrupt_main(signal.Signals(signum))

    def close(self) -> None:
        self.open = False
        with self.lock:  # a thread that found it open has sent its signal (handled by _stop)
            pass


def _put_back(before: dict[signal.Signals, Any], hook: Callable[[Any], object]) -> None:
    """The handlers in ``before``, then the unraisable ``hook``, put back, every one even when a
    stop arrives meanwhile (``signal.signal`` runs a pending handler before it changes
    anything); that stop is raised once they are."""
    stopped: KeyboardInterrupt | None = None
    for signum, handler in before.items():
        while signal.getsignal(signum) is not handler:
            try:
                signal.signal(signum, handler)
            except KeyboardInterrupt as exc:
                stopped = exc
    sys.unraisablehook = hook
    if stopped is not None:
        raise stopped


@contextmanager
def _stopping_signals(command: str) -> Iterator[None]:
    """While the command runs, SIGINT, SIGTERM and SIGHUP raise :class:`Stopped` (raised again
    where it landed where Python cannot propagate it: :class:`_Resend`); a signal the process was
    started ignoring (``nohup``, a background job) stays ignored, and the handlers and the
    unraisable hook before are put back after (``main`` called from a program)."""
    before = {}
    if command not in _OWN_SIGNALS and threading.current_thread() is threading.main_thread():
        for signum, usual in ((signal.SIGINT, signal.default_int_handler), (signal.SIGTERM, signal.SIG_DFL),
                              (signal.SIGHUP, signal.SIG_DFL)):
            if signal.getsignal(signum) is usual:
                before[signum] = signal.signal(signum, _stop)
    hook = sys.unraisablehook
    resend = _Resend(hook) if before else None
    if resend is not None:
        sys.unraisablehook = resend
    try:
        yield
    finally:
        try:
            if resend is not None:
                resend.close()
        finally:
            _put_back(before, hook)


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line, like every other error of the command (exit status 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _version() -> str:
    """The installed package's version, which setup.py reads from package.xml (the one place it
    is written); from package.xml itself in a source tree that was never installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("rls_uncertainty")
    except PackageNotFoundError:
        from ..settings.models import package_path

        return ElementTree.parse(package_path("package.xml")).getroot().findtext("version", "unknown")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="rls-uncertainty",
        description="Recursive least squares with colored-residual parameter uncertainty.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line ``argv`` (``sys.argv[1:]`` when None) parsed; a usage error exits 2."""
    return build_parser().parse_args(argv)


def run(args: argparse.Namespace) -> int:
    """The command ``args`` chose, run; its exit status."""
    try:
        with _stopping_signals(args.command):
            code = int(args.func(args) or 0)
        sys.stdout.flush()  # here, so that a reader gone (below) is seen here
        return code
    except BrokenPipeError:
        # Whatever read the output stopped reading (`| head`): the command's files are
        # written; nothing more to say, and nothing more can be printed. Python's own exit
        # flush must not fail again on the closed pipe.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except (RlsUncertaintyError, OSError) as exc:
        # The package's own errors and file-system problems are the user's to fix; anything
        # else is a bug and shows its traceback. One line, whatever the message holds.
        message = " ".join(str(exc).split())
        print(f"rls-uncertainty {args.command}: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        return _stopped(args.command, exc.signum if isinstance(exc, Stopped) else signal.SIGINT)
    except Exception as exc:
        stop = _stop_inside(exc)
        if stop is None:
            raise
        return _stopped(args.command, stop.signum)


def _stopped(command: str, signum: int) -> int:
    """Ctrl-C or a stopping signal: everything in the way unwound (workers ended, unfinished
    outputs removed); one line, and the status a shell gives a command a signal ended."""
    removed = "" if command in _OWN_SIGNALS else "; its unfinished output removed"
    print(f"rls-uncertainty {command}: stopped by {signal.Signals(signum).name}{removed}", file=sys.stderr)
    return 128 + int(signum)


def _stop_inside(exc: BaseException) -> Stopped | None:
    """The :class:`Stopped` that ``exc`` was raised from, if any: Python 3.11 raises a
    RuntimeError from an exception raised in a ``__set_name__``, as the stop is when the signal
    lands while a class is made (a module loaded in the middle of the command)."""
    seen = set()
    cause = exc.__cause__
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, Stopped):
            return cause
        seen.add(id(cause))
        cause = cause.__cause__
    return None


def load_estimator_node() -> Callable[[], int] | None:
    """:func:`..ros.node.main`, or None after one line naming the extra to install when the ROS
    stack is missing."""
    try:
        with optional("ros"):
            from ..ros.node import main as node_main
    except MissingExtra as exc:
        print(f"estimator_node: error: {exc}", file=sys.stderr)
        return None
    return node_main
