"""DDS playback of replay bags (``rls-uncertainty play``; the demo's player, :mod:`.demo`).

``rls-uncertainty play BAG`` publishes each message's recorded CDR bytes unchanged on its
topic at the bag's pace (times a rate factor), and ``/clock`` at every message's log time so
a node with ``use_sim_time`` follows the bag (rosbag2's player is not installable here).
``--loop N`` plays the bag N times: stamps and ``/clock`` restart with every pass, as a looped
``ros2 bag play`` does.

**Who listens** (:meth:`_Publisher.find_audience`). Before the first message the player waits,
at most ``--wait`` seconds (:data:`DEFAULT_WAIT_S`), until every subscription the ROS graph
lists on the bag's topics has matched its publishers, and at least one has (or
``--subscribers N`` on every topic), all of it holding for ``--delay`` seconds (a
subscriber's other topics and its side of the match catch up meanwhile); then it says how
many subscriptions matched, on which topics, of which nodes, and notes the best-effort ones
(the player cannot know what they lose). Nobody in time: it says so, publishes nothing and
exits 1. A message published before a subscriber matched would be lost to it: the ROS graph
learns of a new node within a second or two, later than its publishers do on a busy
machine.

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
``inputs.<stream>.received``). A subscriber that keeps the last N messages loses those it
has not taken when more arrive: lossless at any pace needs reliable subscriptions with
queues deeper than the backlog can grow (the estimator node: :data:`.demo.REPLAY_PARAMETERS`).
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, MutableMapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..datapath.inputs import message_class
from ..errors import BagError, ConfigError
from .environment import where

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher

__all__ = ["play", "bundled_bag", "stop_process", "TopicStats", "Audience", "Subscription", "NoAudience",
           "DEFAULT_WINDOW", "DEFAULT_WAIT_S"]

# Messages per topic that may wait for acknowledgement: the estimator node's default input
# queue depth (qos.depth), so a keep-last subscriber of that depth is never sent more at once.
DEFAULT_WINDOW = 100
# How long play waits for its subscribers to be discovered and matched before it gives up.
DEFAULT_WAIT_S = 10.0


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


@dataclass(frozen=True)
class Subscription:
    """A subscription the ROS graph lists on a bag topic: its node's name, whether it is
    reliable, and why its QoS can never match the player's (empty when it can)."""

    node: str
    reliable: bool
    incompatible: str = ""


@dataclass
class Audience:
    """Who listens on the bag's topics: per topic, the subscriptions matched with the player's
    publisher (DDS says how many, not whose) and those the ROS graph lists."""

    matched: dict[str, int]
    present: dict[str, list[Subscription]]

    def shortfall(self, subscribers: int | None) -> str:
        """Why playing may not start yet (empty when it may): a subscription listed and not
        matched (one whose QoS can never match is not waited for); fewer than ``subscribers``
        matched on a topic; with ``subscribers`` None, no subscription matched at all."""
        by_problem: dict[str, list[str]] = {}  # the same problem on several topics: said once
        for topic, subs in self.present.items():
            want = sum(1 for sub in subs if not sub.incompatible)
            if self.matched[topic] < want:
                by_problem.setdefault(f"{self.matched[topic]} of the {want} subscription(s) listed matched",
                                      []).append(topic)
            if subscribers and self.matched[topic] < subscribers:
                by_problem.setdefault(f"{self.matched[topic]} of the {subscribers} subscription(s) asked for matched",
                                      []).append(topic)
        problems = [f"{problem} on {', '.join(topics)}" for problem, topics in by_problem.items()]
        if subscribers is None and not any(self.matched.values()):
            problems.insert(0, f"no subscriber on any of the bag's {len(self.matched)} topics "
                               f"({', '.join(self.matched)})")
        if problems:  # and what may explain them
            problems += self.notes(incompatible_only=True)
        return "; ".join(problems)

    def nodes(self) -> dict[str, bool]:
        """The subscribing nodes the graph names (compatible subscriptions), and whether all
        their subscriptions are reliable."""
        out: dict[str, bool] = {}
        for subs in self.present.values():
            for sub in subs:
                if not sub.incompatible:
                    out[sub.node] = out.get(sub.node, True) and sub.reliable
        return dict(sorted(out.items()))

    def describe(self) -> str:
        """How many subscriptions matched, on how many topics, and whose."""
        total, topics = sum(self.matched.values()), [t for t, n in self.matched.items() if n]
        scope = (f"each of the bag's {len(self.matched)} topics" if len(topics) == len(self.matched)
                 else f"{len(topics)} of the bag's {len(self.matched)} topics (none on "
                      f"{', '.join(t for t in self.matched if t not in topics)})")
        nodes = self.nodes()
        whose = ", ".join(f"{n} ({'reliable' if r else 'best effort'})" for n, r in nodes.items())
        return (f"{total} subscription(s) matched on {scope}" + (f", of {len(nodes)} node(s): {whose}" if nodes else "")
                if total else "no subscriber")

    def notes(self, incompatible_only: bool = False) -> list[str]:
        """What the player cannot promise: subscriptions that never match, best-effort ones."""
        out = []
        for topic, subs in self.present.items():
            for sub in subs:
                if sub.incompatible:
                    out.append(f"{sub.node} on {topic} can never match: incompatible QoS ({sub.incompatible})")
        if not incompatible_only:
            out += [f"{node} subscribes best effort: a message it cannot take in time is lost, and play cannot know "
                    "(a lossless replay needs reliable subscriptions with deep queues: docs/tools.md, play)"
                    for node, reliable in self.nodes().items() if not reliable]
        return out


class NoAudience(Exception):
    """Playing did not start: the subscribers were not there, or not matched, in time."""


class NotAcknowledged(Exception):
    """A reliable subscriber did not acknowledge a topic's messages in time."""

    def __init__(self, topic: str, pending: int, timeout: float) -> None:
        super().__init__(f"{topic}: {pending} message(s) not acknowledged by every reliable subscriber "
                         f"within {timeout:g} s")
        self.topic, self.pending, self.timeout = topic, pending, timeout


class _Publisher:
    """Publishers for every topic of a bag (and /clock) on an existing rclpy node."""

    def __init__(self, node: Node, bag: Path, *, clock: bool, reliable: bool, window: int = DEFAULT_WINDOW,
                 namespace: str = "") -> None:
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
        # Publishers and stats by the topic published: the bag's, under ``namespace`` if given.
        self.pubs: dict[str, Publisher] = {}
        self.stats: dict[str, TopicStats] = {}
        self._published_as: dict[str, str] = {}
        for conn in self.reader.connections:
            try:
                cls = message_class(conn.msgtype)
            except (ImportError, AttributeError, ValueError) as exc:
                self.reader.close()
                raise BagError(f"{self.path}: topic {conn.topic}: type {conn.msgtype} is not available in this "
                               "ROS install") from exc
            topic = self._published_as[conn.topic] = namespace.rstrip("/") + conn.topic
            self.pubs[topic] = node.create_publisher(cls, topic, self.qos)
            self.stats[topic] = TopicStats(topic, conn.msgtype)
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

    def subscriptions(self) -> dict[str, list[Subscription]]:
        """Per bag topic, the subscriptions of other nodes the ROS graph lists."""
        from rclpy.qos import QoSDurabilityPolicy, QoSReliabilityPolicy  # noqa: PLC0415

        me = (self.node.get_name(), self.node.get_namespace())
        found: dict[str, list[Subscription]] = {}
        for topic, s in self.stats.items():
            found[topic] = []
            for info in self.node.get_subscriptions_info_by_topic(topic):
                if (info.node_name, info.node_namespace) == me or info.topic_type != s.msgtype:
                    continue  # another type is check_types' to refuse
                known = not info.node_name.startswith("_NODE_NAME_UNKNOWN")
                name = f"{info.node_namespace.rstrip('/')}/{info.node_name}" if known else "a subscriber"
                reliable = info.qos_profile.reliability == QoSReliabilityPolicy.RELIABLE
                # The player's writers are volatile, and best effort with --best-effort: what
                # a subscription may ask of them (the graph's deadline and liveliness values
                # are not comparable with a profile's defaults, so those are not judged here).
                why = [text for bad, text in (
                    (reliable and not self.reliable, "it is reliable, the player best effort (--best-effort)"),
                    (info.qos_profile.durability == QoSDurabilityPolicy.TRANSIENT_LOCAL,
                     "it asks for transient-local durability, the player's is volatile")) if bad]
                found[topic].append(Subscription(name, reliable, "; ".join(why)))
        return found

    def find_audience(self, wait: float, subscribers: int | None = None, settle: float = 0.5,
                      spin: Callable[[], None] | None = None) -> Audience:
        """Wait, at most ``wait`` seconds, until every subscription the ROS graph lists on the
        bag's topics has matched this player's publishers (their count, per topic, is at least
        the graph's), and: at least one has (``subscribers`` None), or at least
        ``subscribers`` on every topic (0: none needed); all of it holding for ``settle``
        seconds, so that a subscriber's later topics and the subscriber's side of the match
        catch up. Raises :class:`NoAudience` saying what was missing; :class:`BagError` from
        :meth:`check_types`."""
        deadline = time.monotonic() + wait
        ready_since: float | None = None
        while True:
            self.check_types()  # a subscriber of another type never matches: say so, not "no subscriber"
            present = self.subscriptions()
            matched = {t: p.get_subscription_count() for t, p in self.pubs.items()}
            audience = Audience(matched, present)
            short = audience.shortfall(subscribers)
            now = time.monotonic()
            if not short:
                ready_since = now if ready_since is None else ready_since
                if now - ready_since >= settle:
                    return audience
            else:
                ready_since = None
            if now > deadline:
                raise NoAudience(f"{short} within {wait:g} s ({where()}): nothing was played")
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
        published_as = self._published_as
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
                topic = published_as[conn.topic]
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
         subscribers: int | None = None, wait: float = DEFAULT_WAIT_S, start_delay: float = 0.5,
         loops: int = 1, window: int = DEFAULT_WINDOW, ack_timeout: float = 30.0, report: bool = False) -> int:
    """Publish ``bag`` ``loops`` times; ``rate`` is the speed factor (0 = as fast as the
    acknowledgements allow). First waits, at most ``wait`` seconds, for its audience
    (:meth:`_Publisher.find_audience`: every subscription listed on the bag's topics matched,
    and at least one, or ``subscribers`` on every topic; for ``start_delay`` seconds) and
    says who it is. Returns a process exit code: 0 when every reliable subscriber
    acknowledged every message, 1 when not (what was not delivered is printed) or when the
    audience was not there in time (nothing is published; the reason is printed). Raises
    :class:`BagError` before anything is published when a subscriber on a bag topic takes
    another type than the bag holds (:meth:`_Publisher.check_types`, checked while waiting and
    before the first message)."""
    _check_rate(rate)
    # Checked at run time whatever the annotations say: callers from Python may pass anything.
    integers: tuple[tuple[str, object, int], ...] = (
        ("number of subscribers to wait for", 0 if subscribers is None else subscribers, 0), ("loop count", loops, 1),
        ("window", window, 1))
    for name, n, low in integers:
        if not (isinstance(n, int) and not isinstance(n, bool) and n >= low):
            raise ConfigError(f"the {name} must be an integer >= {low}, got {n!r}")
    for name, value in (("start delay", start_delay), ("wait", wait), ("ack timeout", ack_timeout)):
        if not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"{name} must be a finite number of seconds >= 0, got {value!r}")
    import rclpy  # noqa: PLC0415
    from rclpy.signals import SignalHandlerOptions  # noqa: PLC0415

    with _player_writer_profile():
        # Without rclpy's signal handlers: a stop is the command line's exception in this
        # thread (:mod:`..cli.stopping`), which unwinds the playback; rclpy's would shut the
        # context down under it from another thread, and the next publish fail with an RCLError.
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node("rls_player")
    player = None
    try:
        player = _Publisher(node, Path(bag), clock=clock, reliable=reliable, window=window)
        try:
            audience = player.find_audience(wait, subscribers, start_delay)
        except NoAudience as exc:
            print(f"NOT PLAYED: {bag}: {exc}. Start the subscribers first, give them longer (--wait SECONDS), or "
                  "play to nobody (--subscribers 0)", file=sys.stderr)
            return 1
        player.check_types()  # the subscribers discovered meanwhile
        pace = f"at {rate:g}x" if rate > 0 else "as fast as possible"
        print(f"playing {bag} {pace}: {audience.describe()}", file=sys.stderr, flush=True)
        for note in audience.notes():
            print(f"note: {note}", file=sys.stderr, flush=True)
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
