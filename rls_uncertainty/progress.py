"""Progress of the long commands (``replay``, ``campaign``, ``make-bag --campaign``, figure
drawing): a tqdm bar on stderr with the count, the rate and the time left, never on stdout (a
pipe reading a command's results gets only them).

``mode`` says when a bar is drawn: ``None`` (the default of the commands) on a terminal only,
so a log file or a pipe gets no carriage-return frames; ``True`` always (``--progress``);
``False`` never (``--quiet``).
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

__all__ = ["Progress", "bar", "track"]

T = TypeVar("T")


class Progress:
    """A bar of ``total`` steps named ``desc`` (``unit`` per step) drawn per ``mode`` (module
    docstring); :meth:`update` by a number of steps, :meth:`close` when done (also as a context
    manager). A bar that is not drawn costs nothing but the calls."""

    def __init__(self, total: int | None, desc: str, unit: str, mode: bool | None = None) -> None:
        # tqdm's own rule for disable=None: drawn only when the stream is a terminal.
        disable = None if mode is None else not mode
        self._bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=disable, dynamic_ncols=True,
                         mininterval=0.2, leave=True)

    @property
    def drawn(self) -> bool:
        return not self._bar.disable

    def update(self, steps: int = 1) -> None:
        self._bar.update(steps)

    def set_to(self, done: int) -> None:
        """Move the bar to ``done`` steps (a callback that reports the count so far)."""
        self._bar.update(done - self._bar.n)

    def close(self) -> None:
        self._bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def bar(total: int | None, desc: str, unit: str, mode: bool | None = None) -> Progress:
    """A :class:`Progress` bar (module docstring)."""
    return Progress(total, desc, unit, mode)


def track(items: Iterable[T], total: int, desc: str, unit: str, mode: bool | None = None) -> Iterator[T]:
    """``items``, one step of a :class:`Progress` bar per item."""
    with Progress(total, desc, unit, mode) as progress:
        for item in items:
            yield item
            progress.update()
