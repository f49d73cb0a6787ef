"""``rls-uncertainty``: the package's command line, one subcommand per job.

One module per group of commands: :mod:`.simulation` (``simulate``, ``montecarlo``,
``multisine``), :mod:`.bags` (``make-bag``, ``convert``), :mod:`.offline` (``replay``,
``campaign``, ``predict``) and :mod:`.ros` (``demo``, ``play``, ``dashboard``, ``status``, ``enable``,
``disable``, ``reset``). A setting's flag is made from its declaration on its options class
(:mod:`.flags`), so every command names, bounds and explains it the same way. Errors: a usage
error or one of the package's own errors (or a file-system error) is one line and exit status
2; anything else is a bug and keeps its traceback. Stopping: Ctrl-C (SIGINT), and for the
commands without ROS and ``play`` and ``demo`` SIGTERM and SIGHUP too, unwind the command as an
exception would (its worker processes ended, its unfinished output directory removed,
:mod:`..files`) and end it with one line and exit status 128 + the signal's number (130 for
Ctrl-C, 143 for SIGTERM). The other ROS commands handle their signals themselves (the node and
rclpy, the dashboard's loop).
Ctrl-C while a command is still starting (loading its modules, about a second, or parsing its
command line) ends it the same way, in one line, before it has written anything: from the
first line of :func:`main` (of :func:`estimator_node`) on, SIGINT raises a stop
(:mod:`.stopping`), recognised also where it lands in a ``__del__`` or a weakref callback or
comes back as another exception.

Before that, a Ctrl-C is the interpreter's, and no code of this package can change what it
does: while the interpreter itself starts, until it has put in its own SIGINT handler (20 to
35 ms on a busy two-core machine), the process ends by the signal; while it then sets up its
streams and runs its ``site`` module with the environment's ``.pth`` files, it ends with a
fatal error and its traceback (exit status 1). The ROS wheels' bootstrap ``.pth`` file starts
the interpreter a second time, so both happen twice: a tenth of a second or more in all on such
a machine. Last, the console script's own first lines, up to this module's loading, end in a
traceback; this module imports nothing but ``sys``, so that :func:`main` starts as soon as the
script has it. :mod:`.commands` holds the commands.
"""

from __future__ import annotations

import sys

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable
    from typing import Any

    from .stopping import Stopping

__all__ = ["main", "build_parser", "estimator_node"]

_STARTING_STOPPED = 128 + 2  # the status of a command that SIGINT (2) stopped
_COMMAND_MODULES = frozenset({"bags", "commands", "flags", "offline", "ros", "simulation", "stopping"})


def _stopped(program: str, exc: BaseException, stopping: Stopping | None, started: bool) -> bool:
    """Whether ``exc`` is a stop (a Ctrl-C; one that came back as another exception:
    :meth:`.stopping.Stopping.signal_of`); if so, its one line. ``started``: the command had
    begun (a stop that escaped its own handling, a second Ctrl-C say), so what it wrote is not
    known."""
    if not isinstance(exc, KeyboardInterrupt) and (stopping is None or stopping.signal_of(exc) is None):
        return False
    said = "" if started else " while starting; nothing written"
    print(f"{program}: stopped by SIGINT{said}", file=sys.stderr)
    return True


def _started(program: str, load: Callable[[], Callable[[], int]]) -> int:
    """``load()`` (the modules and the command line) with SIGINT a stop, then the command it
    returns called; a stop at any point is :func:`_stopped`'s one line and status 130."""
    stopping, started = None, False
    try:
        import signal

        from .stopping import Stopped, Stopping

        stopping = Stopping()
        with stopping.signals((signal.SIGINT,)):
            command = load()
        if stopping.received is not None:
            # A stop that the loading code swallowed: the standard library's XML module, for
            # one, falls back from its C accelerator on the ImportError that a Ctrl-C landing in
            # that accelerator's import becomes. The command would start as if none had come.
            raise Stopped(stopping.received)
        # Still under this try: a Ctrl-C before the command's own handling starts is one line too.
        started = True
        return command()
    except (KeyboardInterrupt, Exception) as exc:
        if not _stopped(program, exc, stopping, started):
            raise
        return _STARTING_STOPPED


def main(argv: list[str] | None = None) -> int:
    """``rls-uncertainty ARGV`` (:func:`.commands.run`); its exit status."""

    def load() -> Callable[[], int]:
        from .commands import parse, run

        args = parse(argv)
        return lambda: run(args)

    return _started("rls-uncertainty", load)


def estimator_node() -> int:
    """The console script ``estimator_node``: :func:`..ros.node.main`, or one line naming the
    extra to install when the ROS stack is missing (exit status 2)."""

    def load() -> Callable[[], int]:
        from .commands import load_estimator_node

        node_main = load_estimator_node()
        return (lambda: 2) if node_main is None else node_main

    return _started("estimator_node", load)


def __getattr__(name: str) -> Any:
    """``build_parser`` and the command modules (``cli.offline``, ...), loaded when first used."""
    if name == "build_parser":
        from .commands import build_parser

        return build_parser
    if name in _COMMAND_MODULES:
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
