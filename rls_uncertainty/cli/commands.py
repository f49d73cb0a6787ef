"""The commands of ``rls-uncertainty`` (:mod:`rls_uncertainty.cli` says how they behave):
the parser made of every command group's flags, running the command chosen with its errors
and stopping signals each said in one line, and the ``estimator_node`` console script's loader.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Callable
from typing import NoReturn
from xml.etree import ElementTree

from ..errors import MissingExtra, RlsUncertaintyError
from ..extras import optional
from .bags import add_convert, add_make_bag
from .offline import add_campaign, add_predict, add_replay
from .ros import add_demo, add_operator_commands, add_play
from .simulation import add_montecarlo, add_multisine, add_simulate
from .stopping import Stopped, Stopping

__all__ = ["parse", "run", "build_parser", "load_estimator_node"]

_SUBCOMMANDS = (add_demo, add_simulate, add_montecarlo, add_multisine, add_make_bag, add_convert, add_replay,
                add_campaign, add_predict, add_play, add_operator_commands)
# The commands that handle their signals themselves (rclpy's handlers, the dashboard's loop); play and demo
# take the command line's stops, with rclpy's handlers left out (..ros.player.play).
_OWN_SIGNALS = frozenset({"dashboard", "status", "enable", "disable", "reset"})
_NO_OUTPUT = _OWN_SIGNALS | {"demo", "play"}  # (a stop leaves no output of theirs to remove)
_STOPPING_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


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
    """The command ``args`` chose, run; its exit status. While it runs, SIGINT, SIGTERM and
    SIGHUP raise :class:`.stopping.Stopped` (:meth:`.stopping.Stopping.signals`), except for the
    commands that handle their signals themselves."""
    stopping = Stopping()
    try:
        with stopping.signals(() if args.command in _OWN_SIGNALS else _STOPPING_SIGNALS):
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
        signum = stopping.signal_of(exc)
        if signum is None:
            raise
        return _stopped(args.command, signum)


def _stopped(command: str, signum: int) -> int:
    """Ctrl-C or a stopping signal: everything in the way unwound (workers ended, unfinished
    outputs removed); one line, and the status a shell gives a command a signal ended."""
    removed = "" if command in _NO_OUTPUT else "; its unfinished output removed"
    print(f"rls-uncertainty {command}: stopped by {signal.Signals(signum).name}{removed}", file=sys.stderr)
    return 128 + int(signum)


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
