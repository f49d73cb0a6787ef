"""The node's input contract (rls_uncertainty.datapath.inputs): one message type and default topic per
pipeline stream, the defaults the configuration uses, and feed(): the fields read, the
frame check. No ROS."""

from __future__ import annotations

from types import SimpleNamespace as NS

from rls_uncertainty.datapath.inputs import DEFAULT_TOPICS, MESSAGE_TYPES, feed, stamp_ns
from rls_uncertainty.datapath.pipeline import STREAMS
from rls_uncertainty.settings import node_config


class Recorder:
    """Stands in for the pipeline: records what feed() hands to each add_* method."""

    frame_id = "base_link"

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def __getattr__(self, name):
        return lambda *args: self.calls.append((name, *args)) or []


def header(sec, nanosec, frame="base_link"):
    return NS(stamp=NS(sec=sec, nanosec=nanosec), frame_id=frame)


def test_one_message_type_and_topic_per_stream_and_the_configuration_defaults_to_them():
    assert tuple(MESSAGE_TYPES) == tuple(DEFAULT_TOPICS) == STREAMS
    assert node_config({}).topics == DEFAULT_TOPICS


def test_feed_reads_the_documented_fields_of_each_type():
    vec = NS(x=1.0, y=2.0, z=3.0)
    h = header(7, 5)
    p = Recorder()
    feed(p, "imu", NS(header=h, angular_velocity=vec, linear_acceleration=NS(x=4.0, y=5.0, z=6.0)))
    feed(p, "airspeed", NS(header=h, vector=vec))
    feed(p, "dynamic_pressure", NS(header=h, fluid_pressure=900.0))
    feed(p, "control_surfaces", NS(header=h, name=["a", "b"], position=[0.1, 0.2]))
    feed(p, "thrust", NS(header=h, wrench=NS(force=NS(x=123.0, y=0.0, z=0.0))))
    t = 7_000_000_005
    assert stamp_ns(NS(header=h)) == t
    assert p.calls == [
        ("add_imu", t, (1.0, 2.0, 3.0), (4.0, 5.0, 6.0)),
        ("add_airspeed", t, (1.0, 2.0, 3.0)),
        ("add_dynamic_pressure", t, 900.0),
        ("add_surfaces", t, ["a", "b"], [0.1, 0.2]),
        ("add_thrust", t, 123.0),
    ]


def test_a_message_in_another_frame_is_rejected_with_the_frame_it_carries():
    p = Recorder()
    feed(p, "airspeed", NS(header=header(1, 0, "wind_frame"), vector=NS(x=1.0, y=0.0, z=0.0)))
    assert p.calls == [("reject_frame", "airspeed", 1_000_000_000, "wind_frame")]
    p.frame_id = ""  # empty: not checked
    feed(p, "airspeed", NS(header=header(1, 0, "wind_frame"), vector=NS(x=1.0, y=0.0, z=0.0)))
    assert p.calls[-1] == ("add_airspeed", 1_000_000_000, (1.0, 0.0, 0.0))
