"""Ctrl-C on the node (rls_uncertainty/ros/interrupt.py): once rclpy is up, SIGINT ends the run
through rclpy's shutdown, never as a KeyboardInterrupt inside an executor callback (which rclpy
reports as a FATAL exception with a traceback, the callback cut short); before, it still stops
at once. Each case runs test/interrupt_probe.py in its own process on the session's domain."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

PROBE = Path(__file__).resolve().parent / "interrupt_probe.py"


def _probe(mode: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(PROBE), mode], capture_output=True, text=True, timeout=120)


def test_sigint_inside_a_callback_ends_the_spin_through_rclpy_and_the_callback_completes():
    run = _probe("guarded")
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == ["shutdown", "ticks 1", "handler restored True"], run.stdout
    assert "FATAL" not in run.stderr and "Traceback" not in run.stderr and "KeyboardInterrupt" not in run.stderr


def test_without_the_guard_python_raises_inside_the_callback():
    # What the guard prevents: the default handler interrupts the callback (it never completes)
    # and rclpy's executor reports a FATAL exception.
    run = _probe("plain")
    assert "FATAL" in run.stderr and "ticks 0" in run.stdout, (run.stdout, run.stderr)


def test_sigint_before_rclpy_is_up_still_stops_at_once():
    run = _probe("starting")
    assert (run.returncode, run.stdout) == (0, "interrupted while starting\n"), run.stderr


def test_a_timer_callback_cut_by_a_stop_ends_quietly_and_any_other_error_still_reaches_the_executor():
    # rclpy's signal handler shuts the context down from its own thread; a pass that was feeding
    # then finds its next publish failing ("publisher's context is invalid"), which the executor
    # reported as a FATAL exception with a traceback.
    import pytest

    from rls_uncertainty.ros.node import unless_stopped

    class Context:
        def __init__(self, ok):
            self._ok = ok

        def ok(self):
            return self._ok

    class Node:
        def __init__(self, ok):
            self.context = Context(ok)

    def publish():
        raise RuntimeError("Failed to publish: publisher's context is invalid")

    assert unless_stopped(Node(False), publish)() is None
    with pytest.raises(RuntimeError, match="context is invalid"):
        unless_stopped(Node(True), publish)()
    calls = []
    unless_stopped(Node(True), lambda: calls.append(1))()
    assert calls == [1]
