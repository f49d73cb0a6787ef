"""DDS playback of replay bags, and the live demo.

``rls-uncertainty play BAG`` publishes each message's recorded CDR bytes unchanged on its
topic at the bag's pace (times a rate factor), and ``/clock`` at every message's log time so
a node with ``use_sim_time`` follows the bag (rosbag2's player is not installable here).
``--loop N`` plays the bag N times: stamps and ``/clock`` restart with every pass, as a looped
``ros2 bag play`` does.

Reliable QoS by default, with flow control by acknowledgements (the player's writers ask for
them every 50 ms: :data:`PLAYER_PROFILE`, a Fast DDS profile used unless the caller names
one): a topic never has more than ``window`` messages that its reliable subscribers have not
all acknowledged (the writer keeps exactly ``window`` messages, so nothing unacknowledged is
ever overwritten). After the last message the player waits until
every reliable subscriber acknowledged everything, or ``ack_timeout``, and says what was not
delivered (exit status 1). What DDS lets a publisher know, and what it does not: an
acknowledgement means the message is in every matched reliable subscriber's DDS queue (per
publisher, for all its reliable subscribers together); not that the subscribing program took
it from the queue, nor anything about best-effort subscribers. How many messages a subscriber
processed only the subscriber can say (the estimator node: ``/diagnostics``,
``inputs.<stream>.received``).

``rls-uncertainty demo`` starts the estimator node in its own process, plays the bundled
T-2 bag to it over DDS, listens to its outputs and prints the final estimates beside the
offline replay of the same bag.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, MutableMapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from ..datapath.inputs import message_class
from ..datapath.outputs import ARRAY_OUTPUTS, NODE_NAME
from ..errors import BagError, ConfigError

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher

    from ..datapath.config import PipelineConfig
    from ..datapath.pipeline import SampleOutput

__all__ = ["play", "demo", "bundled_bag", "stop_process", "TopicStats", "DEFAULT_WINDOW"]

# Messages per topic that may wait for acknowledgement: the estimator node's default input
# queue depth (qos.depth), so a keep-last subscriber of that depth is never sent more at once.
DEFAULT_WINDOW = 100


# Fast DDS (the default RMW) sends a reliable writer's heartbeat, its request for
# acknowledgements, every 3 s by default: flow control that waits for a window's
# acknowledgements then waits up to 3 s per window, and a 200 Hz topic with a 100-message
# window plays 2.5-5x slower than real time. The player's own writers take a 50 ms heartbeat
# from this profile, shipped with the package.
PLAYER_PROFILE = Path(__file__).with_name("fastdds_player.xml")
_PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


@contextmanager
def _player_writer_profile(env: MutableMapping[str, str] = os.environ) -> Iterator[bool]:
    """While DDS starts (``rclpy.init`` and the first node), name :data:`PLAYER_PROFILE` as the
    Fast DDS profile file, unless the caller already named one (then theirs stands, and this
    yields False). The environment is restored afterwards, so processes started later (the
    demo's node, or anything a test starts) never inherit it."""
    if any(name in env for name in _PROFILE_VARIABLES):
        yield False
        return
    env[_PROFILE_VARIABLES[0]] = str(PLAYER_PROFILE)
    try:
        yield True
    finally:
        env.pop(_PROFILE_VARIABLES[0], None)


def _loopback_default() -> None:
    # DDS discovery stays on this machine unless the caller chose otherwise (the demo only).
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


@dataclass
class TopicStats:
    """What the player knows about one topic's delivery. ``unconfirmed``: messages published
    since every reliable subscriber last acknowledged everything (0 once all are)."""

    topic: str
    msgtype: str
    published: int = 0
    unconfirmed: int = 0
    ack_waits: int = 0
    ack_wait_s: float = 0.0
    subscribers_min: int | None = None
    subscribers_max: int = 0

    def saw(self, n: int) -> None:
        self.subscribers_min = n if self.subscribers_min is None else min(self.subscribers_min, n)
        self.subscribers_max = max(self.subscribers_max, n)


class _Dimension(Protocol):
    @property
    def label(self) -> str: ...


class _Layout(Protocol):
    @property
    def dim(self) -> Sequence[_Dimension]: ...


class _ArrayMessage(Protocol):
    """What the demo reads of a ``std_msgs/Float64MultiArray`` (rosidl's classes are untyped)."""

    @property
    def layout(self) -> _Layout: ...

    @property
    def data(self) -> Sequence[float]: ...


class NotAcknowledged(Exception):
    """A reliable subscriber did not acknowledge a topic's messages in time."""

    def __init__(self, topic: str, pending: int, timeout: float) -> None:
        super().__init__(f"{topic}: {pending} message(s) not acknowledged by every reliable subscriber "
                         f"within {timeout:g} s")
        self.topic, self.pending, self.timeout = topic, pending, timeout


class _Publisher:
    """Publishers for every topic of a bag (and /clock) on an existing rclpy node."""

    def __init__(self, node: Node, bag: Path, *, clock: bool, reliable: bool, window: int = DEFAULT_WINDOW) -> None:
        from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy  # noqa: PLC0415

        from ..offline.bags import _open_reader, typestore  # noqa: PLC0415

        self.path = Path(bag)
        self.node = node
        self.reliable = reliable
        self.window = int(window)
        self.reader = _open_reader(self.path, typestore())
        # The writer keeps `window` messages: flow control (run) never lets more than that
        # wait for acknowledgement, so keep-last never drops one that was not delivered.
        reliability = QoSReliabilityPolicy.RELIABLE if reliable else QoSReliabilityPolicy.BEST_EFFORT
        self.qos = QoSProfile(depth=self.window, history=QoSHistoryPolicy.KEEP_LAST, reliability=reliability)
        self.pubs: dict[str, Publisher] = {}
        self.stats: dict[str, TopicStats] = {}
        for conn in self.reader.connections:
            try:
                cls = message_class(conn.msgtype)
            except (ImportError, AttributeError, ValueError) as exc:
                self.reader.close()
                raise BagError(f"{self.path}: topic {conn.topic}: type {conn.msgtype} is not available in this "
                               "ROS install") from exc
            self.pubs[conn.topic] = node.create_publisher(cls, conn.topic, self.qos)
            self.stats[conn.topic] = TopicStats(conn.topic, conn.msgtype)
        clock_type = message_class("rosgraph_msgs/msg/Clock")
        # /clock: only the newest value matters (rclpy's time source subscribes best effort,
        # depth 1), so it takes no part in flow control.
        self.clock_pub = node.create_publisher(clock_type, "/clock", 10) if clock else None
        self._clock = clock_type()
        self.loops_done = 0

    def count_subscribers(self) -> None:
        for topic, pub in self.pubs.items():
            self.stats[topic].saw(pub.get_subscription_count())

    def check_types(self) -> None:
        """Refuse to play when a subscription the ROS graph shows on a bag topic takes another
        type than the bag's: DDS never matches them, so its node would receive nothing.
        Raises :class:`BagError` naming every such topic, the bag's type and the subscriber's."""
        deadline = time.monotonic() + 2.0  # DDS may list a subscription before its node's name
        while True:
            wrong, unnamed = [], False
            for topic, s in self.stats.items():
                for info in self.node.get_subscriptions_info_by_topic(topic):
                    if info.topic_type != s.msgtype:
                        known = not info.node_name.startswith("_NODE_NAME_UNKNOWN")
                        unnamed |= not known
                        who = f"{info.node_namespace.rstrip('/')}/{info.node_name}" if known else "a subscriber"
                        wrong.append(f"topic {topic}: the bag holds {s.msgtype}, {who} subscribes with "
                                     f"{info.topic_type}")
            if not (wrong and unnamed and time.monotonic() < deadline):
                break
            time.sleep(0.1)
        if wrong:
            raise BagError(f"{self.path}: {'; '.join(sorted(set(wrong)))} (a subscriber of another type never "
                           "receives a message); nothing was played")

    def wait_for_subscribers(self, n: int, timeout: float, spin: Callable[[], None] | None = None) -> None:
        deadline = time.monotonic() + timeout
        while n and any(p.get_subscription_count() < n for p in self.pubs.values()):
            self.check_types()  # a subscriber of another type never matches: say so, not "no subscriber"
            if time.monotonic() > deadline:
                missing = [t for t, p in self.pubs.items() if p.get_subscription_count() < n]
                raise BagError(f"{self.path}: no subscriber on {missing} after {timeout:g} s")
            if spin:
                spin()
            else:
                time.sleep(0.05)

    def confirm(self, topic: str, timeout: float) -> bool:
        """Wait until every reliable subscriber of ``topic`` acknowledged every message."""
        s = self.stats[topic]
        if s.unconfirmed == 0:
            return True
        t0 = time.monotonic()
        from rclpy.duration import Duration  # noqa: PLC0415

        ok = self.pubs[topic].wait_for_all_acked(Duration(nanoseconds=int(timeout * 1e9)))
        s.ack_waits += 1
        s.ack_wait_s += time.monotonic() - t0
        s.saw(self.pubs[topic].get_subscription_count())
        if ok:
            s.unconfirmed = 0
        return ok

    def confirm_all(self, timeout: float) -> list[str]:
        """Wait for every topic's acknowledgements, ``timeout`` in all; the topics that still
        wait for some."""
        deadline = time.monotonic() + timeout
        return [t for t in self.pubs if not self.confirm(t, max(0.0, deadline - time.monotonic()))]

    def run(self, rate: float, spin: Callable[[], None] | None = None, *, loops: int = 1,
            ack_timeout: float = 30.0) -> int:
        """Publish every message ``loops`` times; ``spin`` is called between messages when
        given. Raises :class:`NotAcknowledged` when a topic's window stays unacknowledged for
        ``ack_timeout`` (publishing on would overwrite undelivered messages)."""
        count = 0
        window = self.window
        stats, pubs = self.stats, self.pubs
        clock_pub, clock = self.clock_pub, self._clock
        for _ in range(loops):
            t_wall0, t_bag0 = time.monotonic(), None
            self.count_subscribers()
            for conn, t, raw in self.reader.messages():
                if t_bag0 is None:
                    t_bag0 = t
                if rate > 0:
                    delay = t_wall0 + (t - t_bag0) * 1e-9 / rate - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                topic = conn.topic
                s = stats[topic]
                if s.unconfirmed >= window and not self.confirm(topic, ack_timeout):
                    raise NotAcknowledged(topic, s.unconfirmed, ack_timeout)
                if clock_pub is not None:
                    clock.clock.sec, clock.clock.nanosec = divmod(t, 1_000_000_000)
                    clock_pub.publish(clock)
                pubs[topic].publish(bytes(raw))
                s.published += 1
                s.unconfirmed += 1
                count += 1
                if spin is not None and count % 50 == 0:
                    spin()
            # Each pass is delivered before the next one restarts the stamps.
            late = self.confirm_all(ack_timeout)
            if late:
                raise NotAcknowledged(late[0], stats[late[0]].unconfirmed, ack_timeout)
            self.loops_done += 1
        return count

    def report(self) -> str:
        """Per topic: messages published, whether every reliable subscriber acknowledged them,
        the subscriptions matched (fewest and most seen while playing) and the subscriptions
        DDS discovery lists (node and reliability: history depth is not part of discovery)."""
        from rclpy.qos import QoSReliabilityPolicy  # noqa: PLC0415

        me = f"{self.node.get_namespace().rstrip('/')}/{self.node.get_name()}"
        rows = [("topic", "published", "acknowledged", "matched", "subscriptions discovered (node: reliability)")]
        for topic, s in self.stats.items():
            subs = []
            for info in self.node.get_subscriptions_info_by_topic(topic):
                name = f"{info.node_namespace.rstrip('/')}/{info.node_name}"
                if name != me:
                    reliable = info.qos_profile.reliability == QoSReliabilityPolicy.RELIABLE
                    kind = "reliable" if reliable else "best effort"
                    subs.append(f"{name}: {kind}")
            if not self.reliable:
                acked = "unknown (best effort)"
            elif s.unconfirmed:
                acked = f"NO: up to the last {s.unconfirmed}"
            else:
                acked = "all" if s.subscribers_max else "none needed"
            lo, hi = s.subscribers_min or 0, s.subscribers_max
            rows.append((topic, str(s.published), acked, str(hi) if lo == hi else f"{lo}-{hi}",
                         ", ".join(sorted(subs)) or "none"))
        widths = [max(len(r[i]) for r in rows) for i in range(4)]
        lines = ["  ".join([*(r[i].ljust(widths[i]) for i in range(4)), r[4]]).rstrip() for r in rows]
        lines.append(
            "acknowledged: in the DDS queue of every matched reliable subscriber (DDS acknowledges per publisher, "
            "for all its reliable subscribers together); it does not say that a subscriber's program took the "
            "message, nor anything about best-effort subscribers. A subscription discovered but never matched "
            "has incompatible QoS. How many messages each subscriber processed only it can say (the estimator "
            "node: /diagnostics, inputs.<stream>.received).")
        return "\n".join(lines)

    def close(self) -> None:
        self.reader.close()


def _check_rate(rate: float) -> None:
    if not (math.isfinite(rate) and rate >= 0):
        raise ConfigError(f"rate must be a finite number >= 0 (0 = as fast as possible), got {rate!r}")


def play(bag: str | Path, *, rate: float = 1.0, clock: bool = True, reliable: bool = True,
         wait_for_subscribers: int = 0, start_delay: float = 0.5, wait_timeout: float = 30.0,
         loops: int = 1, window: int = DEFAULT_WINDOW, ack_timeout: float = 30.0, report: bool = False) -> int:
    """Publish ``bag`` ``loops`` times; ``rate`` is the speed factor (0 = as fast as the
    acknowledgements allow). Waits for ``wait_for_subscribers`` subscribers on every topic
    first. Returns a process exit code: 0 when every reliable subscriber acknowledged every
    message, 1 when not (what was not delivered is printed). Raises :class:`BagError` before
    anything is published when a subscriber on a bag topic takes another type than the bag
    holds (:meth:`_Publisher.check_types`, checked while waiting and before the first message)."""
    _check_rate(rate)
    # Checked at run time whatever the annotations say: callers from Python may pass anything.
    integers: tuple[tuple[str, object, int], ...] = (
        ("number of subscribers to wait for", wait_for_subscribers, 0), ("loop count", loops, 1), ("window", window, 1))
    for name, n, low in integers:
        if not (isinstance(n, int) and not isinstance(n, bool) and n >= low):
            raise ConfigError(f"the {name} must be an integer >= {low}, got {n!r}")
    for name, value in (("start delay", start_delay), ("wait timeout", wait_timeout), ("ack timeout", ack_timeout)):
        if not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"{name} must be a finite number of seconds >= 0, got {value!r}")
    import rclpy  # noqa: PLC0415

    with _player_writer_profile():
        rclpy.init()
        node = rclpy.create_node("rls_player")
    player = None
    try:
        player = _Publisher(node, Path(bag), clock=clock, reliable=reliable, window=window)
        player.wait_for_subscribers(wait_for_subscribers, wait_timeout)
        player.count_subscribers()
        lo, hi = (f(s.subscribers_max for s in player.stats.values()) for f in (min, max))
        player.check_types()
        print(f"playing {bag}: {lo if lo == hi else f'{lo}-{hi}'} subscription(s) matched per topic; first message "
              f"in {start_delay:g} s", file=sys.stderr, flush=True)
        time.sleep(start_delay)
        player.check_types()  # the subscribers discovered meanwhile
        t0 = time.monotonic()
        failure = None
        try:
            count = player.run(rate, loops=loops, ack_timeout=ack_timeout)
        except NotAcknowledged as exc:
            failure = exc
            count = sum(s.published for s in player.stats.values())
            # Whatever else is still in flight gets the same chance before the report.
            player.confirm_all(ack_timeout)
        player.count_subscribers()
        passes = f"{player.loops_done} pass(es)" if loops > 1 or failure else "once"
        print(f"published {count} messages from {bag} in {time.monotonic() - t0:.2f} s ({passes})", file=sys.stderr)
        if report:
            print(player.report(), file=sys.stderr)
        late = [s for s in player.stats.values() if s.unconfirmed]
        if failure is not None or late:
            what = ", ".join(f"{s.topic} (up to {s.unconfirmed} of {s.published})" for s in late) or str(failure)
            stopped = " - playback stopped: publishing on would overwrite them" if failure is not None else ""
            print(f"NOT DELIVERED: not acknowledged within {ack_timeout:g} s by every reliable subscriber: "
                  f"{what}{stopped}", file=sys.stderr)
            return 1
        return 0
    finally:
        if player is not None:
            player.close()
        node.destroy_node()
        rclpy.try_shutdown()


def bundled_bag() -> Path:
    """``bags/t2_maneuver`` in the source tree or the ROS install's share directory."""
    from ..settings.models import package_path  # noqa: PLC0415

    return package_path("bags", "t2_maneuver")


# Input queue depth for the node in a reliable replay: deeper than any topic of the bundled
# bag, so a node that falls behind (a busy machine) delays messages instead of overwriting them.
_REPLAY_DEPTH = 10_000
# And a long input buffer: a node that falls behind takes about one message per topic per
# executor round, so its slow streams run seconds ahead of the IMU; with the default 2 s their
# messages would expire (docs/tools.md, play).
_REPLAY_BUFFER_S = 60.0


def _start_node(params_path: str) -> tuple[subprocess.Popen[str], str]:
    """The estimator node for a reliable replay, in a process of its own; and its log file's
    name. The node writes its log through its own copy of the file descriptor: ours is closed
    once the node is started; the file stays (delete=False) until the demo succeeds."""
    import tempfile  # noqa: PLC0415

    with tempfile.NamedTemporaryFile("w+", prefix="rls_demo_node_", suffix=".log", delete=False) as node_log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "rls_uncertainty.ros.node", "--ros-args", "--params-file", params_path,
             "-p", "qos.reliable:=true", "-p", f"qos.depth:={_REPLAY_DEPTH}",
             "-p", f"inputs.buffer_duration:={_REPLAY_BUFFER_S}"],
            stdout=node_log, stderr=subprocess.STDOUT, text=True,
        )
    return proc, node_log.name


def stop_process(proc: subprocess.Popen, timeout: float = 15.0) -> bool:
    """End a child process (a node, the dashboard) as Ctrl-C does: SIGINT, then SIGKILL if it
    has not ended within ``timeout`` seconds. Whether it ended by itself (then its exit status
    is ``proc.returncode``)."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            return False
    return True


class _Outputs:
    """What the demo's listener keeps of the node's outputs: the number of samples published
    and the latest array of each topic."""

    def __init__(self, node: Node, models: Sequence[str]) -> None:
        from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy  # noqa: PLC0415

        self.samples = 0
        self.latest: dict[str, _ArrayMessage] = {}
        qos = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)
        self.subs = [node.create_subscription(message_class("std_msgs/msg/Header"), f"/{NODE_NAME}/sample_stamp",
                                              self._count, qos)]
        array_type = message_class("std_msgs/msg/Float64MultiArray")
        for model in models:
            for suffix in ARRAY_OUTPUTS:
                topic = f"/{NODE_NAME}/{model}/{suffix}"

                def keep(msg: _ArrayMessage, t: str = topic) -> None:
                    self.latest[t] = msg

                self.subs.append(node.create_subscription(array_type, topic, keep, qos))

    def _count(self, _msg: object) -> None:
        self.samples += 1

    def arrays(self, model: str) -> list[_ArrayMessage | None]:
        """The latest estimates, corrected and conventional standard errors of ``model``."""
        return [self.latest.get(f"/{NODE_NAME}/{model}/{suffix}") for suffix in ARRAY_OUTPUTS]


def _spin_for(spin: Callable[[], object], seconds: float, until: Callable[[], bool] = lambda: False) -> None:
    """Spin for ``seconds`` or until ``until()`` holds."""
    deadline = time.monotonic() + seconds
    while not until() and time.monotonic() < deadline:
        spin()


def demo(rate: float = 4.0, params_file: str = "t2") -> int:
    """The live node on the bundled bag: estimates over DDS beside the offline replay."""
    _check_rate(rate)
    _loopback_default()
    import rclpy  # noqa: PLC0415

    from ..offline.bags import InputStream  # noqa: PLC0415
    from ..offline.replay import run_pipeline  # noqa: PLC0415
    from ..settings.models import config_dir  # noqa: PLC0415
    from ..settings.parameters import pipeline_config  # noqa: PLC0415
    from ..settings.sources import load_parameters_file  # noqa: PLC0415

    bag = bundled_bag()
    params_path = str(config_dir() / f"{params_file}.yaml")
    params = {**load_parameters_file(params_path), "inputs.buffer_duration": _REPLAY_BUFFER_S}
    config = pipeline_config(params)
    print(f"starting the estimator node ({params_path}) and playing {bag} over DDS at {rate:g}x ...")
    node_proc, node_log = _start_node(params_path)
    with _player_writer_profile():
        rclpy.init()
        node = rclpy.create_node("rls_demo")
    outputs = _Outputs(node, [m.output for m in config.models])
    player = None
    try:
        player = _Publisher(node, bag, clock=False, reliable=True)
        spin = lambda: rclpy.spin_once(node, timeout_sec=0.01)  # noqa: E731
        player.wait_for_subscribers(1, 30.0, spin)
        _spin_for(spin, 30, lambda: all(s.get_publisher_count() >= 1 for s in outputs.subs))
        _spin_for(spin, 1.0)  # discovery is not symmetric: let both sides match
        player.run(rate, spin)
        with InputStream(bag) as stream:
            offline = run_pipeline(stream, config, record=False)
        want = len(offline.outputs)
        _spin_for(spin, 20, lambda: outputs.samples >= want)
        _spin_for(spin, 0.5)
    finally:
        if player is not None:
            player.close()
        node.destroy_node()
        rclpy.try_shutdown()
        stop_process(node_proc)
    print(f"\nlive node: {outputs.samples} samples published (offline replay: {want})\n")
    worst = _compare(config, outputs, offline.outputs[-1], node_log)
    if worst is None:
        return 1
    os.unlink(node_log)
    print("Conventional standard errors assume white residuals (Eq. 13); the corrected ones use the recursive\n"
          "residual autocorrelation (Eqs. 17-22) and cover the real scatter of the estimates (Table 3).")
    return 0 if worst < 1e-9 and outputs.samples == want else 1


def _compare(config: PipelineConfig, outputs: _Outputs, last: SampleOutput, node_log: str) -> float | None:
    """Print the live node's last estimates beside the true values and the largest relative
    difference from the offline replay's last sample (returned; None if a model sent nothing)."""
    import numpy as np  # noqa: PLC0415

    from ..offline.report import results_table, rows_from_arrays  # noqa: PLC0415
    from ..simulation.t2 import T2_TRUE  # noqa: PLC0415

    rows = []
    worst = 0.0
    for j, m in enumerate(config.models):
        est, se, sc = outputs.arrays(m.output)
        if est is None or se is None or sc is None:
            print(f"{m.output}: no estimate received from the node; its log: {node_log}")
            return None
        names = est.layout.dim[0].label.split(",")
        rows += rows_from_arrays(names, est.data, sc.data, se.data, T2_TRUE)
        n = len(names)
        pairs = ((est.data, last.theta[j, :n]), (se.data, last.se[j, :n]), (sc.data, last.se_conventional[j, :n]))
        for live, off in pairs:
            worst = max(worst, float(np.max(np.abs(np.array(live) - off) / np.abs(off))))
    print(results_table(rows))
    print(f"\nlargest relative difference between the live node and the offline replay: {worst:.1e}")
    return worst
