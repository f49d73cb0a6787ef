"""`rls-uncertainty play` over real DDS (loopback) into the estimator node in its own process:
as fast as possible it loses nothing (the node publishes exactly the offline replay's
messages, byte for byte), it says what was not delivered when a subscriber stops
acknowledging, and a looped bag gives one result set per pass."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest
import rclpy

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

    def spin_until(self, condition, timeout: float) -> bool:
        return spin_until(self.node, condition, timeout)

    def wait_connected(self, timeout: float = 30.0) -> None:
        assert self.spin_until(lambda: all(s.get_publisher_count() >= 1 for s in self.subs), timeout), \
            "estimator node's outputs not discovered"

    def close(self) -> None:
        self.node.destroy_node()


@pytest.fixture
def recorder():
    r = RawRecorder()
    yield r
    r.close()


def _play(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "rls_uncertainty.cli", "play", str(BUNDLED), "--wait", "1", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)


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
        player = _play("--rate", "0", "--delay", "2", "--window", "20", "--ack-timeout", "2", "--report")
        line = player.stderr.readline()  # the player found the node: freeze it before the first message
        assert "1 subscription(s) matched per topic" in line, line
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


def _swapped_bag(tmp_path):
    """The bundled bag with the IMU and airspeed messages on each other's topics: the right
    topic names with the wrong types."""
    from rosbags.highlevel import AnyReader

    from rls_uncertainty.offline.bags import typestore, write_replay

    swap = {"/imu": "/airspeed", "/airspeed": "/imu"}
    with AnyReader([BUNDLED], default_typestore=typestore()) as reader:
        records = [(t, swap.get(c.topic, c.topic), c.msgtype, bytes(raw)) for c, t, raw in reader.messages()]
    return write_replay(tmp_path / "swapped", records)


@pytest.mark.parametrize("wait", [False, True], ids=["no_wait", "wait_1"])
def test_play_refuses_a_bag_whose_types_differ_from_the_subscribers_and_exits_2(tmp_path, recorder, wait):
    bag = _swapped_bag(tmp_path)
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE)
    try:
        recorder.wait_connected()
        args = ["--wait", "1"] if wait else ["--delay", "5"]  # without waiting: time for discovery
        t0 = time.monotonic()
        player = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "play", str(bag), "--rate", "0", *args],
                                capture_output=True, text=True, cwd=ROOT, timeout=120)
        assert player.returncode == 2, player
        lines = player.stderr.splitlines()
        assert lines[-1] == (
            f"rls-uncertainty play: error: {bag}: topic /airspeed: the bag holds sensor_msgs/msg/Imu, /{NODE_NAME} "
            f"subscribes with geometry_msgs/msg/Vector3Stamped; topic /imu: the bag holds "
            f"geometry_msgs/msg/Vector3Stamped, /{NODE_NAME} subscribes with sensor_msgs/msg/Imu (a subscriber of "
            "another type never receives a message); nothing was played")
        # Before it, at most the line announcing the first message (discovery still under way).
        assert all(line.startswith(f"playing {bag}: ") for line in lines[:-1]) and len(lines) <= 2, lines
        assert time.monotonic() - t0 < 30  # said at once, not after --wait's 30 s timeout
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
    """The player publishes the bag's own topics: the bundled bag's are the node's inputs."""
    from rosbags.highlevel import AnyReader

    with AnyReader([BUNDLED]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
    assert topics == {f"/{k}": t for k, t in MESSAGE_TYPES.items()}


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
