"""``rls-uncertainty``: the package's command line, one subcommand per job.

One module per group of commands: :mod:`.simulation` (``simulate``, ``montecarlo``,
``multisine``), :mod:`.bags` (``make-bag``, ``convert``), :mod:`.offline` (``replay``,
``campaign``, ``predict``) and :mod:`.ros` (``demo``, ``play``, ``dashboard``, ``status``, ``enable``,
``disable``, ``reset``). A setting's flag is made from its declaration on its options class
(:mod:`.flags`), so every command names, bounds and explains it the same way. Errors: a usage
error or one of the package's own errors (or a file-system error) is one line and exit status
2; anything else is a bug and keeps its traceback. Stopping: Ctrl-C (SIGINT), and for the
commands without ROS SIGTERM and SIGHUP too, unwind the command as an exception would (its
worker processes ended, its unfinished output directory removed, :mod:`..files`) and end it
with one line and exit status 128 + the signal's number (130 for Ctrl-C, 143 for SIGTERM). The
ROS commands handle their signals themselves (the node and rclpy, the dashboard's loop).
Ctrl-C while a command is still starting (loading its modules, about a second, or parsing its
command line) ends it the same way, in one line, before it has written anything.

This module is kept light so that it can catch that: :mod:`.commands` holds the commands.
"""

from __future__ import annotations

import importlib
import signal
import sys
from typing import Any

__all__ = ["main", "build_parser", "estimator_node"]

_COMMAND_MODULES = frozenset({"bags", "commands", "flags", "offline", "ros", "simulation"})


def _stopped_while_starting(program: str) -> int:
    print(f"{program}: stopped by SIGINT while starting; nothing written", file=sys.stderr)
    return 128 + int(signal.SIGINT)


def main(argv: list[str] | None = None) -> int:
    """``rls-uncertainty ARGV`` (:func:`.commands.run`); its exit status."""
    try:
        from .commands import parse, run

        args = parse(argv)
    except KeyboardInterrupt:
        return _stopped_while_starting("rls-uncertainty")
    return run(args)


def estimator_node() -> int:
    """The console script ``estimator_node``: :func:`..ros.node.main`, or one line naming the
    extra to install when the ROS stack is missing (exit status 2)."""
    try:
        from .commands import load_estimator_node

        node_main = load_estimator_node()
    except KeyboardInterrupt:
        return _stopped_while_starting("estimator_node")
    return 2 if node_main is None else node_main()


def __getattr__(name: str) -> Any:
    """``build_parser`` and the command modules (``cli.offline``, ...), loaded when first used."""
    if name == "build_parser":
        from .commands import build_parser

        return build_parser
    if name in _COMMAND_MODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
