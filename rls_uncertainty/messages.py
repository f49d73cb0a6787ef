"""Standard input messages -> plain stamped numbers for the :class:`.pipeline.Pipeline`.

One function per input topic, duck-typed on the ROS message fields, so the live node (rclpy
messages) and the offline replay (rosbags messages) run exactly the same code. No arithmetic
happens here beyond reading fields and the header stamp; no ROS import. :func:`feed` also
checks ``header.frame_id`` against the pipeline's ``inputs.frame_id``, so node and replay
reject a message in another frame identically.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:  # annotations only: no import cycle with the pipeline
    from .pipeline import Pipeline, SampleOutput

__all__ = [
    "NODE_NAME",
    "INPUTS",
    "MESSAGE_TYPES",
    "ARRAY_OUTPUTS",
    "message_class",
    "stamp_ns",
    "feed",
    "stamp_label",
    "parse_stamp_label",
]

# The node's name: its private topics are /rls_estimator/..., its diagnostics "rls_estimator: ...".
NODE_NAME = "rls_estimator"

# Standard input topics (relative names; a replay bag uses them under "/") and their types.
MESSAGE_TYPES = {
    "imu": "sensor_msgs/msg/Imu",
    "airspeed": "geometry_msgs/msg/Vector3Stamped",
    "dynamic_pressure": "sensor_msgs/msg/FluidPressure",
    "control_surfaces": "sensor_msgs/msg/JointState",
    "thrust": "geometry_msgs/msg/WrenchStamped",
}
INPUTS = tuple(MESSAGE_TYPES)
# The arrays published per model M as ~/M/<suffix> (std_msgs/Float64MultiArray), in order.
ARRAY_OUTPUTS = ("estimates", "standard_errors", "standard_errors_conventional")


class _Time(Protocol):
    @property
    def sec(self) -> int: ...
    @property
    def nanosec(self) -> int: ...


class _Header(Protocol):
    @property
    def stamp(self) -> _Time: ...
    @property
    def frame_id(self) -> str: ...


class Stamped(Protocol):
    """What is read of every input message here: ``header.stamp.sec/nanosec`` and
    ``header.frame_id`` (rclpy's generated classes, :mod:`.cdr`'s light objects)."""

    @property
    def header(self) -> _Header: ...


def message_class(msgtype: str) -> type:
    """The generated ROS message class of a type name such as ``sensor_msgs/msg/Imu`` (imported
    on demand: this module itself imports no ROS package)."""
    pkg, _msg, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def stamp_ns(msg: Stamped) -> int:
    """``header.stamp`` in integer nanoseconds."""
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def stamp_label(stamp: int) -> str:
    """``layout.dim[1].label`` of every output array: the sample's time, so each array can be
    paired with its sample without a second topic (``stamp:SEC.NANOSEC``)."""
    sec, nanosec = divmod(int(stamp), 1_000_000_000)
    return f"stamp:{sec}.{nanosec:09d}"


def parse_stamp_label(label: str) -> int:
    """The sample time in nanoseconds from :func:`stamp_label`'s text."""
    if not label.startswith("stamp:"):
        raise ValueError(f"not a stamp label: {label!r}")
    sec, _, nanosec = label[6:].partition(".")
    return int(sec) * 1_000_000_000 + int(nanosec)


# The handlers inline stamp_ns (they run for every input message).
def _imu(p, m):
    s = m.header.stamp
    w, a = m.angular_velocity, m.linear_acceleration
    return p.add_imu(int(s.sec) * 1_000_000_000 + int(s.nanosec), (w.x, w.y, w.z), (a.x, a.y, a.z))


def _airspeed(p, m):
    s = m.header.stamp
    v = m.vector
    return p.add_airspeed(int(s.sec) * 1_000_000_000 + int(s.nanosec), (v.x, v.y, v.z))


def _dynamic_pressure(p, m):
    s = m.header.stamp
    return p.add_dynamic_pressure(int(s.sec) * 1_000_000_000 + int(s.nanosec), m.fluid_pressure)


def _surfaces(p, m):
    s = m.header.stamp
    return p.add_surfaces(int(s.sec) * 1_000_000_000 + int(s.nanosec), m.name, m.position)


def _thrust(p, m):
    s = m.header.stamp
    return p.add_thrust(int(s.sec) * 1_000_000_000 + int(s.nanosec), m.wrench.force.x)


_FEED = {
    "imu": _imu,
    "airspeed": _airspeed,
    "dynamic_pressure": _dynamic_pressure,
    "control_surfaces": _surfaces,
    "thrust": _thrust,
}


def feed(pipeline: Pipeline, kind: str, msg: Stamped) -> list[SampleOutput]:
    """Hand one message of input ``kind`` to ``pipeline``; returns the samples it completed.
    A message whose ``header.frame_id`` is not the pipeline's ``frame_id`` (when that is set)
    is counted as ``frame_mismatch`` instead (:meth:`.pipeline.Pipeline.reject_frame`)."""
    frame = pipeline.frame_id
    if frame and msg.header.frame_id != frame:
        return pipeline.reject_frame(kind, stamp_ns(msg))
    return _FEED[kind](pipeline, msg)
