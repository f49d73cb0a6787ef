"""The commands that talk DDS: ``demo``, ``play``, ``dashboard``, ``status``, ``enable``,
``disable`` and ``reset`` (rclpy imported only when one runs)."""

from __future__ import annotations

import argparse
from typing import Any

from ..dashboard.settings import ServerOptions
from ..extras import optional
from .flags import add_option_flags, integer, option_values, real

__all__ = ["add_demo", "add_play", "add_operator_commands"]


def _demo(args: argparse.Namespace) -> int:
    """The live node on the bundled bag over DDS, beside the offline replay."""
    with optional("ros"):
        from ..ros.demo import demo

        return demo(rate=args.rate)


def _play(args: argparse.Namespace) -> int:
    with optional("ros"):
        from ..ros.player import play

        return play(args.bag, rate=args.rate, clock=not args.no_clock, reliable=not args.best_effort,
                    subscribers=args.subscribers, wait=args.wait, start_delay=args.delay, loops=args.loop,
                    window=args.window, ack_timeout=args.ack_timeout, report=args.report)


def _dashboard(args: argparse.Namespace) -> int:
    with optional("dashboard", "ros"):
        from ..dashboard.app import dashboard_options, run

        return run(dashboard_options(option_values(args, ServerOptions), args.node, args.replay, args.reference))


def _status(args: argparse.Namespace) -> int:
    from ..dashboard.settings import full_node_name

    with optional("ros"):
        from ..ros.operate import status

        return status(full_node_name(args.node), args.once, args.timeout)


def _service(args: argparse.Namespace) -> int:
    from ..dashboard.settings import full_node_name

    with optional("ros"):
        from ..ros.operate import call

        return call(args.command, full_node_name(args.node), args.timeout)


def add_demo(sub: Any) -> None:
    demo = sub.add_parser("demo", help="the live estimator node on the bundled T-2 bag over DDS")
    demo.add_argument("--rate", type=real(0.0), default=4.0,
                      help="playback speed factor (default 4; 0 = as fast as possible)")
    demo.set_defaults(func=_demo)


def add_play(sub: Any) -> None:
    from ..ros.player import DEFAULT_WAIT_S, DEFAULT_WINDOW  # no ROS import at module level

    pl = sub.add_parser("play", help="publish a replay bag over DDS with /clock",
                        description="Publish a replay bag over DDS with /clock, once the subscribers present have "
                                    "matched (it says how many). Exit status 0 when every reliable subscriber "
                                    "acknowledged every message, 1 when not (what was not delivered is printed) or "
                                    "when no subscriber matched within --wait (nothing is published), 2 on bad "
                                    "input.")
    pl.add_argument("bag")
    pl.add_argument("--rate", type=real(0.0), default=1.0,
                    help="rate factor (default 1 = real time; 0 = as fast as the acknowledgements allow)")
    pl.add_argument("--loop", type=integer(1), default=1, metavar="N",
                    help="play the bag N times; stamps and /clock restart with every pass (default 1)")
    pl.add_argument("--window", type=integer(1), default=DEFAULT_WINDOW,
                    help="messages per topic that may await acknowledgement; the publishers keep this many "
                         f"(default {DEFAULT_WINDOW}, the node's default qos.depth)")
    pl.add_argument("--ack-timeout", type=real(0.0), default=30.0, metavar="SECONDS",
                    help="how long to wait for the acknowledgements of a window and at the end (default 30)")
    pl.add_argument("--report", action="store_true",
                    help="print per topic the messages published, acknowledged, and the discovered subscriptions")
    pl.add_argument("--no-clock", action="store_true", help="do not publish /clock")
    pl.add_argument("--best-effort", action="store_true", help="best-effort QoS (default reliable)")
    pl.add_argument("--wait", type=real(0.0), default=DEFAULT_WAIT_S, metavar="SECONDS",
                    help="wait at most this long for the subscribers to be discovered and matched; none by then: "
                         f"nothing is played, exit status 1 (default {DEFAULT_WAIT_S:g})")
    pl.add_argument("--subscribers", type=integer(0), default=None, metavar="N",
                    help="wait for N matched subscriptions on every topic of the bag (default: every subscription "
                         "listed on the bag's topics, at least one; 0: play even to nobody)")
    pl.add_argument("--delay", type=real(0.0), default=0.5, metavar="SECONDS",
                    help="how long the subscriptions must stay matched before the first message (default 0.5)")
    pl.set_defaults(func=_play)


def add_operator_commands(sub: Any) -> None:
    """dashboard, status, enable, disable, reset (docs/dashboard.md)."""
    node_help = "the estimator node's full name (default /rls_estimator; e.g. /ns/rls_estimator)"
    db = sub.add_parser("dashboard", help="control-room web page of a running node's estimates (or of a replay)")
    add_option_flags(db, ServerOptions)
    db.add_argument("--node", default="/rls_estimator", help=node_help)
    db.add_argument("--replay", metavar="DIR",
                    help="show a finished replay's outputs (the --out DIR of rls-uncertainty replay)")
    db.add_argument("--reference", metavar="FILE", help="YAML of reference values by parameter name (CZ_alpha: -3.9)")
    db.set_defaults(func=_dashboard)
    st = sub.add_parser("status", help="the node's inputs, samples and models from /diagnostics, followed until "
                                       "Ctrl-C")
    st.add_argument("--once", action="store_true", help="print one report and exit")
    st.add_argument("--node", default="/rls_estimator", help=node_help)
    st.add_argument("--timeout", type=real(0.0, low_open=True), default=5.0,
                    help="seconds to wait for the node to be discovered (at least 10) and then for its first report "
                         "(exit status 1 without one), and of silence "
                         "after which the node is said gone while status waits for its return (default 5)")
    st.set_defaults(func=_status)
    for name, text in (("enable", "start estimating (~/enable true)"),
                       ("disable", "stop estimating; samples still counted (~/enable false)"),
                       ("reset", "restart the estimator and every input state (~/reset)")):
        sp = sub.add_parser(name, help=text)
        sp.add_argument("--node", default="/rls_estimator", help=node_help)
        sp.add_argument("--timeout", type=real(0.0, low_open=True), default=5.0,
                        help="seconds to wait for the node to answer (default 5)")
        sp.set_defaults(func=_service)
