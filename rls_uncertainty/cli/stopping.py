"""Stopping signals raised as an exception where they arrive, and recognised however they come
back: the command line's start-up (:func:`rls_uncertainty.cli.main`) and its commands
(:func:`.commands.run`) each run under a :class:`Stopping`.

Light on purpose (the standard library's signal, thread and context modules only): the
console scripts load it first, so that a Ctrl-C while everything else loads is already one.
"""

from __future__ import annotations

import _thread
import signal
import sys
import threading
from contextlib import contextmanager

TYPE_CHECKING = False
if TYPE_CHECKING:  # (not loaded when the commands run: the less to load before the handler is in)
    from collections.abc import Callable, Iterable, Iterator
    from types import FrameType
    from typing import Any, NoReturn

__all__ = ["Stopped", "Stopping"]

# The handler each stopping signal has when nothing took it over (Python's, the system's):
# another one (ignored by nohup or a background job, a caller's own) is left alone.
_USUAL = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL, signal.SIGHUP: signal.SIG_DFL}


class Stopped(KeyboardInterrupt):
    """A stopping signal (SIGINT, SIGTERM, SIGHUP), raised in the main thread where it arrived,
    so that the command unwinds as for Ctrl-C. (Not KeyboardInterrupt itself for SIGINT: a
    Ctrl-C that reached a replay as it started, handled here, still made the interpreter end
    the process by SIGINT at exit instead of the status returned; CPython marks an unhandled
    interrupt by the exception's exact type, so a subclass is never marked.)"""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class _Resend:
    """A stop raised where Python cannot propagate it, raised again in the command's own code.

    The handler runs wherever the main thread is when the signal arrives; inside a weakref
    callback (the import system runs one as each module finishes loading) or a ``__del__`` its
    :class:`Stopped` cannot propagate (Python prints "Exception ignored" and goes on). Installed
    as ``sys.unraisablehook`` while the handlers are in, this says nothing about such a
    :class:`Stopped` and has a thread of its own simulate the signal again in the main thread
    (:func:`_thread.interrupt_main`), whose handler then runs in the command's code; one
    swallowed again comes back here. Every other unraisable exception goes to the hook before.
    :meth:`close`, before the handlers are put back, makes sure that no thread simulates a
    signal after it, and raises the stop that no thread had simulated yet."""

    def __init__(self, usual: Callable[[Any], object]) -> None:
        self.usual, self.open, self.lock = usual, True, threading.Lock()
        self.unsent: list[int] = []

    def __call__(self, unraisable: Any) -> None:
        if isinstance(unraisable.exc_value, Stopped):
            self.unsent.append(unraisable.exc_value.signum)
            _thread.start_new_thread(self._send, ())
        else:
            self.usual(unraisable)

    def _send(self) -> None:
        with self.lock:
            if self.open and self.unsent:
                _thread.interrupt_main(signal.Signals(self.unsent.pop()))

    def close(self) -> None:
        self.open = False
        with self.lock:  # a thread that found it open has sent its signal (handled by the handler)
            pass
        if self.unsent:
            raise Stopped(self.unsent.pop())


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


class Stopping:
    """The stopping signals of one stage (the start-up, a command) and what became of them:
    :meth:`signals` makes them raise :class:`Stopped`, :meth:`signal_of` tells a stop from
    whatever exception it came back as."""

    def __init__(self) -> None:
        self.received: int | None = None  # the last stopping signal its handler took

    def _raise(self, signum: int, _frame: FrameType | None) -> NoReturn:
        self.received = signum
        raise Stopped(signum)

    @contextmanager
    def signals(self, signums: Iterable[signal.Signals]) -> Iterator[None]:
        """While the block runs, ``signums`` raise :class:`Stopped` (raised again where it
        landed where Python cannot propagate it: :class:`_Resend`); a signal the process was
        started ignoring (``nohup``, a background job) stays ignored, and the handlers and the
        unraisable hook before are put back after (``main`` called from a program), also when
        a stop arrives while they are put in or back. Off the main thread, nothing changes."""
        before: dict[signal.Signals, Any] = {}
        hook = sys.unraisablehook
        resend = None
        try:
            if threading.current_thread() is threading.main_thread():
                for signum in signums:
                    if signal.getsignal(signum) is _USUAL[signum]:
                        before[signum] = _USUAL[signum]  # first: put back even if a stop lands next
                        signal.signal(signum, self._raise)
            if before:
                resend = _Resend(hook)
                sys.unraisablehook = resend
            yield
        finally:
            try:
                if resend is not None:
                    resend.close()
            finally:
                _put_back(before, hook)

    def signal_of(self, exc: BaseException) -> int | None:
        """The stopping signal behind ``exc``, or None: ``exc`` a stop itself (a
        KeyboardInterrupt is SIGINT's), one raised from a stop (Python 3.11 raises a
        RuntimeError from an exception raised in a ``__set_name__``, as the stop is when the
        signal lands while a class is made), or any exception once a stop was received here
        (code that caught the stop and raised another in its place: numpy, loading, turns one
        into an ImportError)."""
        seen = set()
        cause: BaseException | None = exc
        while cause is not None and id(cause) not in seen:
            if isinstance(cause, KeyboardInterrupt):
                return cause.signum if isinstance(cause, Stopped) else int(signal.SIGINT)
            seen.add(id(cause))
            cause = cause.__cause__
        return self.received
