"""A node whose timer callback sends SIGINT to its own process, then goes on running Python
(test_node_interrupt.py). ``guarded``: under :func:`rls_uncertainty.ros.interrupt.sigint_through_rclpy`,
as the node's main runs; ``plain``: Python's default handler; ``starting``: SIGINT before
rclpy is up, under the guard. Prints how the spin ended and how many callbacks completed."""
import contextlib
import os
import signal
import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor

from rls_uncertainty.ros.interrupt import sigint_through_rclpy

mode = sys.argv[1]
with (contextlib.nullcontext(lambda: None) if mode == "plain" else sigint_through_rclpy()) as up:
    if mode == "starting":
        try:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):
                pass
        except KeyboardInterrupt:
            print("interrupted while starting")
            sys.exit(0)
    rclpy.init()
    up()
    node = rclpy.create_node("interrupt_probe")
    ticks = []
    def tick():
        # One tick only, however late the shutdown lands on a busy machine: "ticks 1" says the
        # callback completed after its own SIGINT, "ticks 0" that it was cut short.
        timer.cancel()
        os.kill(os.getpid(), signal.SIGINT)
        ticks.append(sum(range(1000)))
    timer = node.create_timer(0.01, tick)
    ex = EventsExecutor()
    ex.add_node(node)
    try:
        while rclpy.ok():
            ex.spin_once(timeout_sec=1.0)
        print("ended")
    except ExternalShutdownException:
        print("shutdown")
    except KeyboardInterrupt:
        print("interrupted")
    print("ticks", len(ticks))
    ex.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
print("handler restored", signal.getsignal(signal.SIGINT) is signal.default_int_handler)
