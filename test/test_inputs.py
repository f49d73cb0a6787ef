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


# ------------------------------------------------------------------ batched intake
def _bag():
    from pathlib import Path

    from rls_uncertainty.offline.bags import read_inputs

    messages, _ = read_inputs(Path(__file__).resolve().parents[1] / "bags" / "t2_maneuver")
    return messages


def _samples(outputs):
    return [(o.stamp_ns, o.ready.tolist(), o.theta.tobytes(), o.se.tobytes(), o.se_conventional.tobytes())
            for o in outputs]


def test_batched_intake_gives_the_samples_of_per_message_intake():
    """The node takes every queued message each intake period and feeds them in order of
    arrival (arrival_order). Whatever the batch boundaries, the samples are bit for bit those
    of the messages fed one by one as they arrived (the replay's order)."""
    import pytest

    from rls_uncertainty.datapath.inputs import arrival_order
    from rls_uncertainty.datapath.pipeline import Pipeline
    from rls_uncertainty.settings import load_parameters_file, pipeline_config

    config = pipeline_config(load_parameters_file("t2"))
    bag = _bag()
    one_by_one = Pipeline(config)
    want = _samples([o for kind, _s, m in bag for o in feed(one_by_one, kind, m)])
    assert len(want) > 100
    for size in (1, 7, 64, 1000, len(bag)):
        pipe, got = Pipeline(config), []
        for start in range(0, len(bag), size):
            taken: dict[str, list] = {kind: [] for kind in STREAMS}
            for arrival, (kind, _s, m) in enumerate(bag[start:start + size], start):
                taken[kind].append((arrival, m))
            got += [o for kind, m in arrival_order(taken) for o in feed(pipe, kind, m)]
        assert _samples(got) == want, size
        assert pipe.counters() == one_by_one.counters()
    with pytest.raises(AssertionError):  # the check can fail: another order changes the samples
        shuffled = Pipeline(config)
        late = [x for x in bag if x[0] == "imu"] + [x for x in bag if x[0] != "imu"]
        assert _samples([o for kind, _s, m in late for o in feed(shuffled, kind, m)]) == want


def test_arrival_order_keeps_each_streams_order_and_breaks_ties_by_stream():
    from rls_uncertainty.datapath.inputs import arrival_order

    taken = {"imu": [(5, "i0"), (3, "i1"), (9, "i2")], "airspeed": [(4, "a0"), (9, "a1")], "thrust": []}
    order = arrival_order(taken)
    assert [m for k, m in order if k == "imu"] == ["i0", "i1", "i2"]
    assert order == [("airspeed", "a0"), ("imu", "i0"), ("imu", "i1"), ("imu", "i2"), ("airspeed", "a1")]
    assert arrival_order({"imu": [(2, "x"), (1, "y")]}) == [("imu", "x"), ("imu", "y")]
