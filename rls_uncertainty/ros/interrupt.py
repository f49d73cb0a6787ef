"""Ctrl-C on the node: through rclpy's shutdown, never as an exception inside a callback.

``rclpy.init`` installs a SIGINT handler that shuts the context down (the node's spin loop then
ends and the node saves its state) and then calls the handler that was there before. Python's
default one raises KeyboardInterrupt wherever the main thread happens to be: with the node busy,
often inside an executor callback (the intake timer), where rclpy's executor reports it as a
FATAL exception with a traceback before the node stops. :func:`sigint_through_rclpy` puts a
handler underneath that raises KeyboardInterrupt only until rclpy is up (Ctrl-C while the node
starts still stops it at once) and does nothing after: rclpy's shutdown alone ends the run.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["sigint_through_rclpy", "SigintWhileLoading"]


@contextmanager
def sigint_through_rclpy() -> Iterator[Callable[[], None]]:
    """While the block runs, SIGINT raises KeyboardInterrupt until the callable yielded is
    called (call it once ``rclpy.init`` has returned), and is left to rclpy after. Nothing
    changes off the main thread or when SIGINT is not Python's default handler (ignored by a
    background job, or a caller's own); the handler before is put back at the end."""
    up = False

    def handler(_signum: int, _frame: FrameType | None) -> None:
        if not up:
            raise KeyboardInterrupt

    def rclpy_is_up() -> None:
        nonlocal up
        up = True

    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield lambda: None
        return
    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield rclpy_is_up
    finally:
        signal.signal(signal.SIGINT, previous)


class SigintWhileLoading:
    """For ``python -m rls_uncertainty.ros.node`` while it loads the node's modules (the console
    script has :class:`..cli.stopping.Stopping`, a wing above): while ``with`` it, SIGINT raises
    KeyboardInterrupt and is remembered, so that :meth:`stopped` also tells the stops that came
    back as another exception (rclpy's C extension turns one into "ImportError: initialization
    failed") and those that the loading code swallowed (the standard library's XML module falls
    back from its C accelerator on that ImportError), after which the node would otherwise start
    as if no Ctrl-C had come. Nothing changes off the main thread or when SIGINT is not Python's
    default handler; the handler before is put back at the end."""

    def __init__(self) -> None:
        self.received = False
        self._previous: object = None

    def _raise(self, _signum: int, _frame: FrameType | None) -> None:
        self.received = True
        raise KeyboardInterrupt

    def __enter__(self) -> SigintWhileLoading:
        if threading.current_thread() is threading.main_thread() \
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._raise)
        return self

    def __exit__(self, *_exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)  # type: ignore[arg-type]

    def stopped(self, exc: BaseException | None = None) -> bool:
        """Whether a Ctrl-C came: ``exc`` a KeyboardInterrupt, or any exception (or none) once
        one was received."""
        return isinstance(exc, KeyboardInterrupt) or self.received
