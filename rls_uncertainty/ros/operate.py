"""Operating a running estimator node without ros2cli (the pip route has no ``ros2`` command):

* ``rls-uncertainty status [--once] [--node NAME]``: the node's ``/diagnostics`` as a terminal
  table (streams with rate, age, counts and the reasons of recent rejections; samples;
  models, the parameters whose convergence flag is held back as not identifiable and why; which
  estimation methods' estimates the node publishes, from the ROS graph's topics), redrawn in
  place at each report; ``--once`` prints one and exits;
* ``rls-uncertainty enable | disable | reset [--node NAME]``: calls ``~/enable``
  (``std_srvs/SetBool``) or ``~/reset`` (``std_srvs/Trigger``) and prints the node's answer.

Exit status 0 when the node answered (and the service succeeded), 1 when no node answered
within ``--timeout`` seconds (the message says which domain and discovery range were
searched), 2 for a bad option. Only the service calls change anything; ``status`` reads.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable
from typing import Any, TextIO

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_srvs.srv import SetBool, Trigger

from ..datapath.outputs import METHODS, array_key
from .environment import where
from .health import LEVELS, HealthTracker, NodeHealth, parse_statuses, statuses_of

__all__ = ["call", "status", "format_health", "published_methods", "SERVICES"]

# command -> (service relative to the node, type, request data)
SERVICES: dict[str, tuple[str, Any, bool | None]] = {
    "enable": ("enable", SetBool, True),
    "disable": ("enable", SetBool, False),
    "reset": ("reset", Trigger, None),
}
_CLEAR = "\x1b[H\x1b[2J"
# How the status names each estimation method (rls_uncertainty.datapath.outputs.METHODS).
METHOD_TEXT = {"time": "time domain (RLS, ~/M/estimates)", "frequency": "frequency domain (~/M/frequency/estimates)"}


def _fail(command: str, text: str) -> int:
    print(f"rls-uncertainty {command}: error: {text}", file=sys.stderr)
    return 1


class _Session:
    """An rclpy context, node and executor of their own for one command (so a caller that
    uses rclpy itself is not disturbed), shut down on exit."""

    def __enter__(self) -> _Session:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node: Node = rclpy.create_node("rls_uncertainty_cli", context=self.context,
                                            start_parameter_services=False, enable_rosout=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        return self

    def __exit__(self, *exc: object) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def call(command: str, node_name: str, timeout: float) -> int:
    """``enable``, ``disable`` or ``reset``: call the service, print the answer."""
    service, srv_type, data = SERVICES[command]
    name = f"{node_name.rstrip('/')}/{service}"
    with _Session() as session:
        client = session.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            return _fail(command, f"no node answers {name} within {timeout:g} s ({where()}): is {node_name} running, "
                                  "with the same domain and discovery range?")
        request = srv_type.Request()
        if data is not None:
            request.data = data
        future = client.call_async(request)
        session.executor.spin_until_future_complete(future, timeout_sec=timeout)
        response = future.result() if future.done() else None
    if response is None:
        return _fail(command, f"{name} did not answer within {timeout:g} s")
    print(f"{node_name}: {response.message}")
    return 0 if response.success else 1


# ------------------------------------------------------------------ status
def _row(cells: list[str], widths: list[int]) -> str:
    cells = [c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths, strict=True))]
    return "  ".join(cells).rstrip()


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    return [_row(header, widths), *(_row(r, widths) for r in rows)]


def published_methods(topics: Iterable[str], node_name: str) -> list[str]:
    """The estimation methods (:data:`rls_uncertainty.datapath.outputs.METHODS`) whose ``estimates`` topic
    ``node_name`` has among ``topics`` (the graph's topic names; the node creates its
    publishers at start, before any sample)."""
    prefix = node_name.rstrip("/") + "/"
    found = {key.method for t in topics if t.startswith(prefix)
             and (key := array_key(t[len(prefix):])) is not None and key.suffix == "estimates"}
    return [m for m in METHODS if m in found]


def format_health(node_name: str, h: NodeHealth, methods: Iterable[str] = ()) -> str:
    """The status table of one report; ``methods``: the estimation methods the node publishes
    (:func:`published_methods`; none: not said)."""
    lines = [f"{node_name}  ({where()})  {time.strftime('%H:%M:%S')}",
             f"inputs: {LEVELS.get(h.inputs_level, h.inputs_level)}  {h.inputs_message}", ""]
    rows = []
    for s in h.streams:
        reasons = ", ".join(f"{r} {n}" for r, n in sorted(s.recent_reasons.items()))
        rows.append([s.name + ("" if s.get("required") == "True" else " (optional)"), s.get("rate_hz"),
                     s.get("age_s"), s.get("publishers"), s.get("received"), s.get("accepted"),
                     s.get("recent.rejected"), s.get("recent.missing"), s.get("recent.expired"), reasons])
    header = ["stream", "rate Hz", "age s", "pubs", "received", "accepted", "rejected*", "missing*", "expired*",
              "recent rejections by reason"]
    lines += _table(header, rows)
    lines.append(f"* in the last {h.window_s:g} s")
    rejected = ", ".join(f"{k[17:]} {v}" for k, v in h.samples.items() if k.startswith("samples_rejected.")) or "none"
    pending = h.samples.get("samples_pending", "0")
    lines += ["", f"samples: {h.samples_message}; pending {pending}; rejected: {rejected}"]
    methods = list(methods)
    if methods:
        lines.append("estimates published: " + ", ".join(METHOD_TEXT.get(m, m) for m in methods))
    mrows = []
    for model, v in h.models.items():
        ready = v.get("ready") == "True"
        r2 = f"{float(v['r_squared']):.3f}" if ready and "r_squared" in v else "-"
        mrows.append([model, "ready" if ready else "initializing", v.get("samples", ""), r2, v.get("lags", "-"),
                      v.get("converged_parameters", "") or ("all" if v.get("converged") == "True" else "-"),
                      v.get("held_back", "") or "-"])
    if mrows:
        lines += ["", *_table(["model", "state", "samples", "R^2", "lags", "converged", "held back"], mrows)]
    # Why a flag is held back, or a model cannot initialize: the node's own words.
    lines += [f"  {v['identifiability']}" for v in h.models.values() if v.get("identifiability")]
    return "\n".join(lines)


def status(node_name: str, once: bool, timeout: float, out: TextIO = sys.stdout,
           until: Callable[[], bool] | None = None) -> int:
    """Print the node's reports as they come (in place on a terminal) until Ctrl-C (or
    ``until()``); with ``once`` the first one."""
    tracker = HealthTracker()
    reports: list[NodeHealth] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        parsed = parse_statuses(statuses_of(msg), node_name)
        if parsed is not None:
            reports.append(tracker.update(parsed))

    live = out.isatty()
    shown = 0
    with _Session() as session:
        session.node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 50)
        deadline = time.monotonic() + timeout
        try:
            while until is None or not until():
                session.executor.spin_once(timeout_sec=0.2)
                if not reports:
                    if time.monotonic() > deadline:
                        return _fail("status", f"no /diagnostics from {node_name} within {timeout:g} s ({where()}): "
                                               "is the node running, with the same domain and discovery range?")
                    continue
                topics = [t for t, _types in session.node.get_topic_names_and_types()]
                text = format_health(node_name, reports[-1], published_methods(topics, node_name))
                reports.clear()
                shown += 1
                out.write((_CLEAR if live else ("\n" if shown > 1 else "")) + text + "\n")
                out.flush()
                if once:
                    return 0
        except KeyboardInterrupt:
            pass
    return 0
