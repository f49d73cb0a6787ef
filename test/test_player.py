"""`rls-uncertainty play` over real DDS (loopback) into the estimator node in its own process:
as fast as possible it loses nothing (the node publishes exactly the offline replay's
messages, byte for byte), it says what was not delivered when a subscriber stops
acknowledging, and a looped bag gives one result set per pass. Before the first message it
waits for the subscribers (started after it, they still get every message; none: it says so,
publishes nothing and exits 1), and the node fed the bag without /clock reports its inputs by
their arrival, not as months stale."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections import Counter

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray

from rls_uncertainty.datapath.diagnostics import outputs_discovered, outputs_subscribed
from rls_uncertainty.datapath.inputs import MESSAGE_TYPES, message_class
from rls_uncertainty.datapath.outputs import NODE_NAME, OutputLayout, output_topics
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, node_config, pipeline_config

from ros_harness import BUNDLED, RELIABLE, REPLAY_NODE, ROOT, T2, NodeProcess, spin_until

pytestmark = pytest.mark.usefixtures("ros")


@pytest.fixture(scope="module")
def expected():
    """Per output topic, the bytes the node must publish for the bundled bag (offline replay
    with the node's default configuration for config/t2.yaml)."""
    params = load_parameters_file("t2")
    offline = run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(params))
    frame = node_config(params).frame_id
    per_topic: dict[str, list[bytes]] = {f"/{NODE_NAME}/{t}": [] for t, _ in output_topics(["CZ", "Cm"])}
    layout = OutputLayout.of(offline.pipeline)
    for out in offline.outputs:
        for index, data in layout.encode(out, frame):
            per_topic[f"/{NODE_NAME}/{layout.topics[index][0]}"].append(data)
    assert len(per_topic[f"/{NODE_NAME}/sample_stamp"]) == 591
    return per_topic


class RawRecorder:
    """Every output topic of the node, recorded as the serialized bytes it publishes."""

    def __init__(self, models=("CZ", "Cm")) -> None:
        self.node = rclpy.create_node("raw_recorder")
        self.got: dict[str, list[bytes]] = {}
        self.subs = []
        for rel, msgtype in output_topics(models):
            topic = f"/{NODE_NAME}/{rel}"
            store = self.got.setdefault(topic, [])
            self.subs.append(self.node.create_subscription(message_class(msgtype), topic, store.append, RELIABLE,
                                                           raw=True))
        self.samples: dict[str, str] = {}  # the key-values of the node's newest samples status
        self._diagnostics = self.node.create_subscription(DiagnosticArray, "/diagnostics", self._report, 10)

    def spin_until(self, condition, timeout: float) -> bool:
        return spin_until(self.node, condition, timeout)

    def _report(self, msg, info) -> None:
        if info["source_timestamp"] < NodeProcess.last_start_ns:  # an earlier node's (RosTester._take_diagnostics)
            return
        for status in msg.status:
            if status.name == f"{NODE_NAME}: samples":
                self.samples = {kv.key: kv.value for kv in status.values}

    def wait_connected(self, timeout: float = 60.0) -> None:
        """Until these subscriptions matched the node's publishers and the node's report says it
        publishes on as many topics (it publishes only on those it saw a subscriber on at its
        last report: a sample sent before would be lost to this recorder)."""
        def matched() -> int:
            return sum(s.get_publisher_count() >= 1 for s in self.subs)

        assert self.spin_until(lambda: outputs_discovered(self.samples, matched(), len(self.subs)), timeout), (
            f"estimator node's outputs not discovered within {timeout:g} s: {matched()} of {len(self.subs)} "
            f"subscriptions matched its publishers, its report says it publishes on "
            f"{outputs_subscribed(self.samples)} (-1: no report)")

    def close(self) -> None:
        self.node.destroy_node()


@pytest.fixture
def recorder():
    r = RawRecorder()
    yield r
    r.close()


def _play(*args: str, bag=BUNDLED) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "rls_uncertainty.cli", "play", str(bag), "--wait", "120", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)


def _audience_line(bag=BUNDLED, pace="as fast as possible", nodes=f"/{NODE_NAME} (reliable)") -> str:
    return f"playing {bag} {pace}: 5 subscription(s) matched on each of the bag's 5 topics, of 1 node(s): {nodes}"


def _finish(player: subprocess.Popen, recorder: RawRecorder, timeout: float = 300.0) -> tuple[int, str]:
    """Spin the recorder while the player runs; its exit status and stderr."""
    deadline = time.monotonic() + timeout
    while player.poll() is None and time.monotonic() < deadline:
        rclpy.spin_once(recorder.node, timeout_sec=0.05)
    if player.poll() is None:
        player.kill()
    _out, err = player.communicate()
    return player.returncode, err


def _same_message(got: bytes, want: bytes) -> bool:
    """The bytes the node published, as received: DDS pads a serialized payload with up to 3
    zero bytes to a multiple of 4, which a CDR reader ignores."""
    pad = got[len(want):]
    return got[:len(want)] == want and len(pad) < 4 and not any(pad)


def _equal(got: dict, want: dict) -> bool:
    return set(got) == set(want) and all(
        len(got[t]) == len(want[t]) and all(map(_same_message, got[t], want[t])) for t in want)


def _diff(got: dict, want: dict) -> str:
    """Where two per-topic message lists first differ (for an assertion message)."""
    for topic in want:
        g, w = got.get(topic, []), want[topic]
        # Over the shorter list only: a missing or extra message is a difference at its end.
        i = next((k for k, (a, b) in enumerate(zip(g, w, strict=False)) if not _same_message(a, b)),
                 min(len(g), len(w)))
        if i < max(len(g), len(w)):
            return f"{topic}: {len(g)} messages, expected {len(w)}; first difference at #{i}"
    return "equal"


def test_play_as_fast_as_possible_to_a_reliable_node_gives_exactly_the_offline_replay(tmp_path, recorder, expected):
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE)
    try:
        recorder.wait_connected()
        code, err = _finish(_play("--rate", "0", "--report"), recorder)
        assert code == 0, err
        assert "published 4920 messages" in err
        report = {line.split()[0]: line.split() for line in err.splitlines() if line.startswith("/")}
        for topic, n in (("/imu", "2400"), ("/airspeed", "600"), ("/thrust", "120")):
            # published, acknowledged by every reliable subscriber, 1 matched, who it is
            assert report[topic][1:5] == [n, "all", "1", f"/{NODE_NAME}:"], err
        assert "acknowledged: in the DDS queue" in err
        want = sum(len(v) for v in expected.values())
        assert recorder.spin_until(lambda: sum(len(v) for v in recorder.got.values()) >= want, 120), \
            _diff(recorder.got, expected)
        recorder.spin_until(lambda: False, 0.5)  # nothing more may come
        assert _equal(recorder.got, expected), _diff(recorder.got, expected)
    finally:
        assert node.stop() == 0, node.text()


def test_play_says_what_a_stopped_subscriber_did_not_acknowledge_and_exits_1(tmp_path, recorder):
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE)
    player = None
    try:
        recorder.wait_connected()
        # In real time the bag lasts 12 s: the node is frozen long before its end.
        player = _play("--rate", "1", "--window", "20", "--ack-timeout", "2", "--report")
        line = player.stderr.readline()  # the player found the node and starts: freeze the node
        assert line == _audience_line(pace="at 1x") + "\n", line
        node.proc.send_signal(signal.SIGSTOP)
        try:
            code, err = _finish(player, recorder, timeout=120)
        finally:
            node.proc.send_signal(signal.SIGCONT)
        assert code == 1, err
        assert "NOT DELIVERED: not acknowledged within 2 s by every reliable subscriber" in err
        assert "playback stopped" in err
        report = {row.split()[0]: row for row in err.splitlines() if row.startswith("/")}
        assert "NO: up to the last 20" in report["/imu"], err
    finally:
        if player is not None and player.poll() is None:
            player.kill()
        assert node.stop() == 0, node.text()


def test_play_with_no_subscriber_says_so_publishes_nothing_and_exits_1():
    """Nobody on the bag's topics within --wait: one line saying so and where it looked, exit
    status 1, nothing published (no 'published' line)."""
    run = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "play", str(BUNDLED), "--wait", "2"],
                         capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert run.returncode == 1, run
    where = (f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}, "
             f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}")
    assert run.stderr == (
        f"NOT PLAYED: {BUNDLED}: no subscriber on any of the bag's 5 topics (/imu, /airspeed, /dynamic_pressure, "
        f"/control_surfaces, /thrust) within 2 s ({where}): nothing was played. Start the subscribers first, give "
        "them longer (--wait SECONDS), or play to nobody (--subscribers 0)\n"), run.stderr
    # --subscribers 0: nobody is needed, and the bag is played to nobody.
    run = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "play", str(BUNDLED), "--rate", "0",
                          "--subscribers", "0"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert run.returncode == 0, run
    assert run.stderr.splitlines()[0] == f"playing {BUNDLED} as fast as possible: no subscriber", run.stderr
    assert "published 4920 messages" in run.stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stopped_play_ends_in_one_line_with_the_signals_status(sig):
    """Ctrl-C or SIGTERM while the bag plays (to nobody, slowly): the playback unwinds, one line,
    exit status 128 + the signal's number; rclpy does not shut its context down under the
    player, whose next publish then failed with an RCLError traceback and exit status 1."""
    proc = subprocess.Popen([sys.executable, "-m", "rls_uncertainty.cli", "play", str(BUNDLED), "--subscribers", "0",
                             "--loop", "20"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            start_new_session=True)
    try:
        first = proc.stderr.readline()  # said once it has started publishing
        assert first == f"playing {BUNDLED} at 1x: no subscriber\n", first
        proc.send_signal(sig)
        _out, rest = proc.communicate(timeout=120)
        assert (proc.returncode, rest) == (128 + sig, f"rls-uncertainty play: stopped by {sig.name}\n")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


class _Diagnostics:
    """The estimator node's ``inputs`` and ``samples`` statuses, as ``{key: value}`` per report."""

    def __init__(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        self.node = rclpy.create_node("diagnostics_listener")
        self.reports: list[dict[str, str]] = []
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._keep, 100)

    def _keep(self, msg) -> None:
        values = {}
        for status in msg.status:
            if status.name in (f"{NODE_NAME}: inputs", f"{NODE_NAME}: samples"):
                values.update({kv.key: kv.value for kv in status.values})
                values[status.name.split(": ")[1]] = status.message
        if values:
            self.reports.append(values)

    def close(self) -> None:
        self.node.destroy_node()


def test_a_player_started_before_the_node_waits_for_it_and_the_node_uses_every_sample(tmp_path):
    """The tour: the player started first waits for the node (started after it) to match, says
    who it plays to, and paces the bag at 2x; the node, without /clock, receives every message
    and forms and uses the offline replay's samples, and while the bag plays its inputs are
    reported by their arrival (fresh), not by their stamps (months behind the node's clock)."""
    messages = read_inputs(BUNDLED)[0]
    per_topic = dict(Counter(kind for kind, _stamp, _msg in messages))
    offline = run_pipeline(messages, pipeline_config(load_parameters_file("t2"))).pipeline.counters()
    listener = _Diagnostics()
    player = _play("--rate", "2")
    node = None
    try:
        node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE, "-p", "diagnostics_period:=0.2")
        deadline = time.monotonic() + 300
        while player.poll() is None and time.monotonic() < deadline:
            rclpy.spin_once(listener.node, timeout_sec=0.05)
        _out, err = player.communicate(timeout=60)
        assert player.returncode == 0, err
        assert err.splitlines()[0] == _audience_line(pace="at 2x"), err
        assert "published 4920 messages" in err

        keys = ("samples_formed", "samples_used")

        def done() -> bool:
            last = listener.reports[-1] if listener.reports else {}
            return all(last.get(k) == str(offline[k]) for k in keys)

        assert spin_until(listener.node, done, 300), {k: v for k, v in listener.reports[-1].items()
                                                      if k.startswith("samples") or k.endswith(".received")}
        last = listener.reports[-1]
        assert {k: int(last[f"{k}.received"]) for k in per_topic} == per_topic, last
        # The samples the offline replay drops at the end of the data the live node still
        # holds, waiting for data that does not come.
        assert int(last["samples_pending"]) == offline["samples_rejected"]["end_of_data"] > 0, last
        playing = [r for r in listener.reports if 0 < int(r["imu.received"]) < per_topic["imu"]]
        assert playing, "no report while the bag played"
        ages = [float(r[f"{k}.age_s"]) for r in playing for k in per_topic if r[f"{k}.age_s"] != "never received"]
        assert max(ages) < 60, max(ages)  # by stamp: about 1e7 s (the bag is months old)
    finally:
        if player.poll() is None:
            player.kill()
            player.communicate()
        listener.close()
        if node is not None:
            assert node.stop() == 0, node.text()


def _swapped_bag(tmp_path):
    """The bundled bag with the IMU and airspeed messages on each other's topics: the right
    topic names with the wrong types."""
    from rosbags.highlevel import AnyReader

    from rls_uncertainty.offline.bags import typestore, write_replay

    swap = {"/imu": "/airspeed", "/airspeed": "/imu"}
    with AnyReader([BUNDLED], default_typestore=typestore()) as reader:
        records = [(t, swap.get(c.topic, c.topic), c.msgtype, bytes(raw)) for c, t, raw in reader.messages()]
    return write_replay(tmp_path / "swapped", records)


@pytest.mark.parametrize("args", [["--wait", "120"], ["--subscribers", "0", "--delay", "5"]],
                         ids=["waiting_for_subscribers", "for_nobody"])
def test_play_refuses_a_bag_whose_types_differ_from_the_subscribers_and_exits_2(tmp_path, recorder, args):
    """Refused at once (not after --wait: exit status 2, not 1), and also when playing to
    nobody would not wait for subscribers at all (the ROS graph is looked at for --delay)."""
    bag = _swapped_bag(tmp_path)
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE)
    try:
        recorder.wait_connected()
        player = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "play", str(bag), "--rate", "0", *args],
                                capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert player.returncode == 2, player
        lines = player.stderr.splitlines()
        assert lines[-1] == (
            f"rls-uncertainty play: error: {bag}: topic /airspeed: the bag holds sensor_msgs/msg/Imu, /{NODE_NAME} "
            f"subscribes with geometry_msgs/msg/Vector3Stamped; topic /imu: the bag holds "
            f"geometry_msgs/msg/Vector3Stamped, /{NODE_NAME} subscribes with sensor_msgs/msg/Imu (a subscriber of "
            "another type never receives a message); nothing was played")
        assert len(lines) == 1, lines  # nothing announced, nothing played
        recorder.spin_until(lambda: False, 1.0)
        assert not any(recorder.got.values())  # nothing was published, so the node published nothing
    finally:
        assert node.stop() == 0, node.text()


@pytest.mark.parametrize("sim_time", [True, False], ids=["use_sim_time+clock", "wall_time-no_clock"])
def test_a_bag_played_three_times_gives_three_result_sets_equal_to_the_offline_replay(tmp_path, recorder, expected,
                                                                                       sim_time):
    """`play --loop 3`: stamps (and /clock) restart with every pass, as a looped rosbag2 play.
    The node must restart its data path at each backwards jump and give the offline replay's
    messages once per pass."""
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE, "-p", f"use_sim_time:={str(sim_time).lower()}")
    try:
        recorder.wait_connected()
        code, err = _finish(_play("--rate", "0", "--loop", "3", *([] if sim_time else ["--no-clock"])), recorder)
        assert code == 0, err
        assert "published 14760 messages" in err and "3 pass(es)" in err
        thrice = {topic: msgs * 3 for topic, msgs in expected.items()}
        want = sum(len(v) for v in thrice.values())
        recorder.spin_until(lambda: sum(len(v) for v in recorder.got.values()) >= want, 120)
        recorder.spin_until(lambda: False, 0.5)
        assert _equal(recorder.got, thrice), _diff(recorder.got, thrice) + "\n" + node.text()[-2000:]
    finally:
        assert node.stop() == 0, node.text()


def test_the_bundled_bag_holds_only_the_standard_inputs():
    """The player publishes the bag's own topics: the bundled bag's are the node's sensor
    inputs (every input but the excitation, which only instrumental variables read)."""
    from rosbags.highlevel import AnyReader

    with AnyReader([BUNDLED]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
    assert topics == {f"/{k}": t for k, t in MESSAGE_TYPES.items() if k != "excitation"}


# ------------------------------------------------------------------ the player's writer profile
def test_the_player_names_its_fast_heartbeat_profile_only_while_dds_starts_and_only_if_none_is_named():
    """Fast DDS's writers ask for acknowledgements every 3 s by default, which made a
    real-time play of the bundled bag take 30-73 s for 12 s of data. The player names its own
    profile (a 50 ms heartbeat) while DDS starts, restores the environment, and never
    replaces a profile file the caller named."""
    import xml.etree.ElementTree as ET

    from rls_uncertainty.ros.player import PLAYER_PROFILE, _player_writer_profile

    env: dict[str, str] = {"OTHER": "1"}
    with _player_writer_profile(env) as used:
        assert used and env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(PLAYER_PROFILE)
    assert env == {"OTHER": "1"}  # nothing leaks into processes started later
    for name in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        theirs = {name: "/site/profiles.xml"}
        with _player_writer_profile(theirs) as used:
            assert not used and theirs == {name: "/site/profiles.xml"}
        assert theirs == {name: "/site/profiles.xml"}
    ns = {"p": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    writer = ET.parse(PLAYER_PROFILE).getroot().find("p:publisher", ns)
    assert writer is not None and writer.get("is_default_profile") == "true"
    period = writer.find("p:times/p:heartbeatPeriod", ns)
    assert int(period.find("p:sec", ns).text) + int(period.find("p:nanosec", ns).text) * 1e-9 == 0.05
    # Installed with the package (setup.py package_data), next to player.py.
    assert '"ros/fastdds_player.xml"' in (ROOT / "setup.py").read_text()
