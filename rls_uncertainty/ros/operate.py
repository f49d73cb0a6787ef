"""Operating a running estimator node without ros2cli (the pip route has no ``ros2`` command):

* ``rls-uncertainty status [--once] [--node NAME]``: the node's ``/diagnostics`` as a terminal
  table (streams with rate, age, counts and the reasons of recent rejections; samples;
  models, the parameters whose convergence flag is held back as not identifiable and why; which
  estimation methods' estimates the node publishes, from the ROS graph's topics), redrawn in
  place at each report until Ctrl-C or SIGTERM (exit status 0); it follows the node: a silence
  longer than ``--timeout`` (or three report intervals) is said, with whether the node is still
  on the ROS graph, and so is its return; ``--once`` prints one and exits;
* ``rls-uncertainty enable | disable | reset [--node NAME]``: calls ``~/enable``
  (``std_srvs/SetBool``) or ``~/reset`` (``std_srvs/Trigger``) of every node that answers to
  the name and prints each answer (:func:`call`).

Exit status 0 when the node answered (and the service succeeded), 1 when no node answered
within ``--timeout`` seconds (the message says which domain and discovery range were
searched), or when several nodes carry the name and not all of them answered the same success;
2 for a bad option. Only the service calls change anything; ``status`` reads.

**Several nodes of one name** (twins: two launches of one file) all serve ``NAME/enable``. A
DDS service client reaches every server it has matched when it sends, and each answers; but
rclpy's client hands back only the first answer, and a client is ready as soon as it has
matched *one* server, so a call made at once would reach whichever twin was discovered
first, and say that one's answer. Neither rclpy nor rmw in Jazzy can address one server
among several of a name (no endpoint GIDs for services, and a request goes to every matched
server), so :func:`call` makes sure a request reaches them all and collects every answer:

1. it counts the nodes that carry the name: the most of the ROS graph's nodes of that name,
   the graph's servers of the service, and ``nodes_with_this_name`` from the node's own
   ``/diagnostics`` (the node has run long enough to have discovered its twins, where this
   command's graph is a second old), waiting up to :data:`REPORT_WAIT_S` for a report;
2. it sends once the graph shows that many servers, and collects answers until as many
   arrived to one request. The graph can list a server before this client's request writer
   has matched it (a twin listed beside the other missed a call now and then), and a request
   sent before the match never reaches that server, so with fewer answers after
   :data:`RESEND_S` the call is sent again, at most :data:`SENDS` times: a node may then get
   it twice (harmless for ``enable`` and ``disable``; ``reset`` resets that node again, a
   second later), which the output says;
3. it prints the answers to the request that most nodes answered; with more than one node,
   a line says so first, and the exit status is 1 unless every node answered and all
   succeeded alike.

Answers carry no sender: they are numbered, not named (the twins' logs say which got what).
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any, TextIO

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.subscription import Subscription
from rclpy.task import Future
from std_srvs.srv import SetBool, Trigger

from ..datapath.outputs import METHODS, array_key
from .environment import split_node_name, where
from .health import LEVELS, HealthTracker, NodeHealth, parse_statuses, statuses_of

__all__ = ["call", "report", "status", "format_health", "published_methods", "SERVICES", "REPORT_WAIT_S", "RESEND_S",
           "SENDS"]

# command -> (service relative to the node, type, request data)
SERVICES: dict[str, tuple[str, Any, bool | None]] = {
    "enable": ("enable", SetBool, True),
    "disable": ("enable", SetBool, False),
    "reset": ("reset", Trigger, None),
}
_CLEAR = "\x1b[H\x1b[2J"
# How long enable/disable/reset wait, once a server of the service is ready, for a report of
# the node (its nodes_with_this_name) before counting the nodes from the ROS graph alone: the
# node reports every diagnostics_period (1 s by default).
REPORT_WAIT_S = 3.0
# A request reaches only the servers matched when it is sent, and the graph can list a server
# before the match: when fewer nodes answer than carry the name, the call is sent again after
# RESEND_S, at most SENDS times in all.
RESEND_S = 1.0
SENDS = 3
# How long `status` waits at least for the node to be discovered, whatever its --timeout (measured
# on one machine: 0.1-3 s for a process just started, sometimes more on a busy one).
DISCOVERY_S = 10.0
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


def _on_graph(node: Node, node_name: str) -> int:
    """How many nodes the ROS graph lists under ``node_name``."""
    key = split_node_name(node_name)[::-1]  # (name, namespace), as the graph lists nodes
    return sum(1 for n in node.get_node_names_and_namespaces() if tuple(n) == key)


class _Namesakes:
    """How many nodes carry ``node_name`` (module docstring, step 1), as seen so far."""

    def __init__(self, session: _Session, node_name: str, service: str) -> None:
        self.node, self.node_name, self.service = session.node, node_name, service
        self.reported = 0  # nodes_with_this_name of the newest report; 0: none yet
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        parsed = parse_statuses(statuses_of(msg), self.node_name)
        if parsed is not None:
            value = parsed.samples.get("nodes_with_this_name", "1")
            self.reported = max(self.reported, int(value) if value.isdigit() else 1)

    def servers(self) -> int:
        return self.node.count_services(self.service)

    def expected(self) -> int:
        return max(self.reported, _on_graph(self.node, self.node_name), self.servers(), 1)


def _spin_until(session: _Session, condition: Callable[[], bool], deadline: float) -> bool:
    while not condition():
        if time.monotonic() > deadline:
            return False
        session.executor.spin_once(timeout_sec=0.05)
    return True


def report(command: str, node_name: str, answers: list[tuple[bool, str]], nodes: int, timeout: float,
           sends: int = 1, out: TextIO = sys.stdout) -> int:
    """Print the ``answers`` (success, message) of the ``nodes`` that carry ``node_name`` to
    the request that most of them answered, of ``sends`` sent; the exit status (module
    docstring)."""
    nodes = max(nodes, len(answers))
    if not answers:
        return _fail(command, f"{node_name} did not answer within {timeout:g} s")
    if nodes == 1:
        success, message = answers[0]
        print(f"{node_name}: {message}", file=out)
        return 0 if success else 1
    again = (f"; sent {sends} times, as the earlier calls did not reach every node (a node may have had it more "
             "than once)") if sends > 1 else ""
    print(f"{node_name}: {nodes} nodes answer to this name, and each gets every call: give each its own name or "
          f"namespace (--ros-args -r __node:=NAME or -r __ns:=/NAMESPACE){again}", file=out)
    for i, (_success, message) in enumerate(answers, 1):
        print(f"{node_name} [answer {i} of {nodes}]: {message}", file=out)
    if len(answers) < nodes:
        return _fail(command, f"{nodes - len(answers)} of the {nodes} nodes named {node_name} did not answer within "
                              f"{timeout:g} s: whether the call reached them is not known")
    if len(set(answers)) > 1 or not answers[0][0]:
        return _fail(command, f"the {nodes} nodes named {node_name} did not all succeed alike")
    return 0


def call(command: str, node_name: str, timeout: float) -> int:
    """``enable``, ``disable`` or ``reset`` of every node named ``node_name`` (module
    docstring); each answer printed. Discovery and the answers each wait up to ``timeout``."""
    service, srv_type, data = SERVICES[command]
    name = f"{node_name.rstrip('/')}/{service}"
    answers: dict[int, list[tuple[bool, str]]] = {}  # by the request's sequence number

    def every_answer(sequence: int) -> Future:
        # rclpy's executor hands each response to the future of its sequence number, and a
        # plain client keeps only the first; this one keeps them all.
        future = Future()
        future.add_done_callback(lambda f: answers.setdefault(sequence, []).append(
            (bool(f.result().success), str(f.result().message))))
        return future

    def most() -> list[tuple[bool, str]]:
        return max(answers.values(), key=len, default=[])

    with _Session() as session:
        client = session.node.create_client(srv_type, name)
        client.get_pending_request = every_answer  # type: ignore[method-assign,assignment]
        namesakes = _Namesakes(session, node_name, name)
        deadline = time.monotonic() + timeout
        if not _spin_until(session, client.service_is_ready, deadline):
            return _fail(command, f"no node answers {name} within {timeout:g} s ({where()}): is {node_name} running, "
                                  "with the same domain and discovery range?")
        report_by = min(deadline, time.monotonic() + REPORT_WAIT_S)
        _spin_until(session, lambda: (namesakes.reported > 0 or time.monotonic() > report_by)
                    and namesakes.servers() >= namesakes.expected(), deadline)
        nodes = namesakes.expected()
        request = srv_type.Request()
        if data is not None:
            request.data = data
        deadline = time.monotonic() + timeout
        sends = 0
        while sends < SENDS and len(most()) < nodes and time.monotonic() < deadline:
            client.call_async(request)
            sends += 1
            last = sends == SENDS
            _spin_until(session, lambda: len(most()) >= nodes, deadline if last else time.monotonic() + RESEND_S)
        nodes = max(nodes, namesakes.expected())
    return report(command, node_name, most(), nodes, timeout, sends)


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
    mrows, prows = [], []
    for model, v in h.models.items():
        ready = v.get("ready") == "True"
        r2 = f"{float(v['r_squared']):.3f}" if ready and "r_squared" in v else "-"
        state = "ready" if ready else "initializing"
        if not ready and "publish_at_samples" in v:
            state += f" {v.get('publish_count', '?')}/{v['publish_at_samples']}"
        mrows.append([model, state, v.get("samples", ""), r2, v.get("lags", "-"),
                      v.get("converged_parameters", "") or ("all" if v.get("converged") == "True" else "-"),
                      v.get("held_back", "") or "-"])
        for key, text in v.items():  # per parameter and method: state.<p>, frequency.state.<p> (datapath.states)
            prefix, found, parameter = key.rpartition("state.")
            if found and parameter and prefix in ("", "frequency."):
                method = "frequency" if prefix else "time"
                prows.append([model, parameter, method, v.get(f"{prefix}se_percent.{parameter}", "-"), text])
    if mrows:
        lines += ["", *_table(["model", "state", "samples", "R^2", "lags", "converged", "held back"], mrows)]
    if prows:
        lines += ["", *_table(["model", "parameter", "method", "SE %", "state"], prows)]
    # Why a flag is held back, or a model cannot initialize: the node's own words.
    lines += [f"  {v['identifiability']}" for v in h.models.values() if v.get("identifiability")]
    return "\n".join(lines)


class _Presence:
    """Whether the node still reports, as ``status`` follows it: the node is taken as gone
    when no report came for :meth:`limit` seconds (``timeout``, or three of its report
    intervals when it reports more slowly than that), and back at its next report."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self.last: float | None = None  # when the newest report arrived
        self.interval = 0.0  # the newest interval between two reports
        self.gone_since: float | None = None  # the newest report's time while the node is said gone

    def limit(self) -> float:
        return max(self.timeout, 3.0 * self.interval)

    def report(self, now: float) -> float | None:
        """A report arrived at ``now``: the seconds without one if the node had been said gone."""
        silent = now - self.gone_since if self.gone_since is not None else None
        if self.last is not None and silent is None:
            self.interval = now - self.last
        self.last, self.gone_since = now, None
        return silent

    def went(self, now: float) -> bool:
        """Whether the node is to be said gone now (once per absence)."""
        if self.last is None or self.gone_since is not None or now - self.last <= self.limit():
            return False
        self.gone_since = self.last
        return True


class _Discovery:
    """How long ``status`` waits for the node's first report: until the node is on the graph
    with a matched ``/diagnostics`` publisher, at least :data:`DISCOVERY_S` (DDS discovery of
    a process just started takes up to a few seconds: its participant is announced every 3 s
    after a first burst), then ``--timeout`` from the match, as ``call`` counts it."""

    def __init__(self, node: Node, subscription: Subscription, node_name: str, timeout: float) -> None:
        self._node, self._subscription, self._node_name = node, subscription, node_name
        self._timeout = timeout
        self._since = time.monotonic()
        self._limit = max(timeout, DISCOVERY_S)

    def expired(self, now: float) -> float | None:
        """The seconds waited in vain, or None while the wait goes on."""
        if self._limit > self._timeout and self._subscription.get_publisher_count() > 0 and \
                _on_graph(self._node, self._node_name):
            self._since, self._limit = now, self._timeout  # discovered: the report has --timeout
        return now - self._since if now - self._since > self._limit else None


@contextmanager
def _sigterm_interrupts() -> Iterator[None]:
    """SIGTERM ends ``status`` as Ctrl-C does (a KeyboardInterrupt in the main thread); the
    previous handler is restored afterwards."""
    def interrupt(_signum: int, _frame: object) -> None:
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, interrupt)
    except ValueError:  # not the main thread: signals stay as they are
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _gone_line(node: Node, node_name: str, silent_s: float) -> str:
    where_now = "still on the ROS graph: busy, or its reports do not reach here" if _on_graph(node, node_name) else \
        "no longer on the ROS graph"
    return (f"{time.strftime('%H:%M:%S')}  {node_name}: no report for {silent_s:.0f} s ({where_now}); waiting for it "
            "to come back (Ctrl-C to stop)")


def status(node_name: str, once: bool, timeout: float, out: TextIO = sys.stdout,
           until: Callable[[], bool] | None = None) -> int:
    """Print the node's reports as they come (in place on a terminal) until Ctrl-C or SIGTERM
    (or ``until()``); with ``once`` the first one. Discovery of the node and then its first
    report each wait up to ``timeout``, discovery at least :data:`DISCOVERY_S`
    (:class:`_Discovery`); no first report: exit status 1.
    Afterwards the node is followed: a silence longer than :meth:`_Presence.limit`
    is said (with whether the node is still on the ROS graph), and so is its return."""
    presence = _Presence(timeout)
    tracker = HealthTracker()
    reports: list[NodeHealth] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        nonlocal tracker
        parsed = parse_statuses(statuses_of(msg), node_name)
        if parsed is not None:
            if presence.gone_since is not None:
                tracker = HealthTracker()  # a restarted node counts from zero
            reports.append(tracker.update(parsed))

    live = out.isatty()
    shown, text = 0, ""

    def write(block: str) -> None:
        out.write(block + "\n")
        out.flush()

    with _Session() as session, _sigterm_interrupts():
        subscription = session.node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 50)
        first = _Discovery(session.node, subscription, node_name, timeout)
        try:
            while until is None or not until():
                session.executor.spin_once(timeout_sec=0.2)
                now = time.monotonic()
                if not reports:
                    waited = first.expired(now) if presence.last is None else None
                    if waited is not None:
                        return _fail("status", f"no /diagnostics from {node_name} within {waited:.0f} s ({where()}): "
                                               "is the node running, with the same domain and discovery range?")
                    if presence.went(now):
                        line = _gone_line(session.node, node_name, now - (presence.last or now))
                        write(f"{_CLEAR}{text}\n\n{line}" if live else f"\n{line}")
                    continue
                silent = presence.report(now)
                topics = [t for t, _types in session.node.get_topic_names_and_types()]
                text = format_health(node_name, reports[-1], published_methods(topics, node_name))
                reports.clear()
                shown += 1
                back = "" if silent is None else \
                    f"{time.strftime('%H:%M:%S')}  {node_name} is back after {silent:.0f} s without a report"
                if live:
                    write(_CLEAR + text + (f"\n\n{back}" if back else ""))
                else:
                    write(("\n" if shown > 1 else "") + "\n".join(filter(None, (back, text))))
                if once:
                    return 0
        except KeyboardInterrupt:
            pass
    return 0
