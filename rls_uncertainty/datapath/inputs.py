"""The node's inputs: topics, message types, the fields read, and :func:`feed`.

One standard ROS message type per input stream of the pipeline (:data:`.pipeline.STREAMS`),
subscribed on a topic named after the stream by default (``topics.<stream>``; relative, so a
replay bag has them under ``/``):

============================  ===================================  =========================================
stream (default topic)        message type                         fields read
============================  ===================================  =========================================
``imu``                       ``sensor_msgs/msg/Imu``              ``angular_velocity`` (rad/s),
                                                                   ``linear_acceleration`` (m/s^2)
``airspeed``                  ``geometry_msgs/msg/Vector3Stamped`` ``vector``: true airspeed (m/s)
``dynamic_pressure``          ``sensor_msgs/msg/FluidPressure``    ``fluid_pressure`` (Pa)
``control_surfaces``          ``sensor_msgs/msg/JointState``       ``name``, ``position`` (rad)
``thrust``                    ``geometry_msgs/msg/WrenchStamped``  ``wrench.force.x`` (N)
``excitation``                ``sensor_msgs/msg/JointState``       ``name``, ``position`` (rad): the injected
                                                                   input, read with ``estimator.algorithm iv``
============================  ===================================  =========================================

Every message also gives ``header.stamp`` (the sample time) and ``header.frame_id``: vectors
are in the REP-103 body frame, which the pipeline's ``inputs.frame_id`` names; a message in
another frame is rejected as ``frame_mismatch`` (:func:`feed`). No arithmetic happens here
beyond reading fields and the stamp, and no ROS import: the live node (messages decoded by
:mod:`.cdr`) and the offline replay (rosbags messages) hand every message to the pipeline
through :func:`feed`, the same code.
"""

from __future__ import annotations

import heapq
import importlib
from collections.abc import Mapping, Sequence
from typing import Any, Protocol, TypeVar

from .pipeline import STREAMS, Pipeline, SampleOutput

__all__ = ["STREAMS", "MESSAGE_TYPES", "DEFAULT_TOPICS", "Stamped", "message_class", "stamp_ns", "feed",
           "arrival_order"]

# The ROS message type of each input stream.
MESSAGE_TYPES = {
    "imu": "sensor_msgs/msg/Imu",
    "airspeed": "geometry_msgs/msg/Vector3Stamped",
    "dynamic_pressure": "sensor_msgs/msg/FluidPressure",
    "control_surfaces": "sensor_msgs/msg/JointState",
    "thrust": "geometry_msgs/msg/WrenchStamped",
    "excitation": "sensor_msgs/msg/JointState",
}
# The default topic of each stream (the ``topics.<stream>`` parameters): its name.
DEFAULT_TOPICS = {stream: stream for stream in STREAMS}


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


# The handlers inline stamp_ns (they run for every input message).
def _imu(p: Pipeline, m: Any) -> list[SampleOutput]:
    s = m.header.stamp
    w, a = m.angular_velocity, m.linear_acceleration
    return p.add_imu(int(s.sec) * 1_000_000_000 + int(s.nanosec), (w.x, w.y, w.z), (a.x, a.y, a.z))


def _airspeed(p: Pipeline, m: Any) -> list[SampleOutput]:
    s = m.header.stamp
    v = m.vector
    return p.add_airspeed(int(s.sec) * 1_000_000_000 + int(s.nanosec), (v.x, v.y, v.z))


def _dynamic_pressure(p: Pipeline, m: Any) -> list[SampleOutput]:
    s = m.header.stamp
    return p.add_dynamic_pressure(int(s.sec) * 1_000_000_000 + int(s.nanosec), m.fluid_pressure)


def _surfaces(p: Pipeline, m: Any) -> list[SampleOutput]:
    s = m.header.stamp
    return p.add_surfaces(int(s.sec) * 1_000_000_000 + int(s.nanosec), m.name, m.position)


def _thrust(p: Pipeline, m: Any) -> list[SampleOutput]:
    s = m.header.stamp
    return p.add_thrust(int(s.sec) * 1_000_000_000 + int(s.nanosec), m.wrench.force.x)


def _excitation(p: Pipeline, m: Any) -> list[SampleOutput]:
    s = m.header.stamp
    return p.add_excitation(int(s.sec) * 1_000_000_000 + int(s.nanosec), m.name, m.position)


_FEED = {
    "imu": _imu,
    "airspeed": _airspeed,
    "dynamic_pressure": _dynamic_pressure,
    "control_surfaces": _surfaces,
    "thrust": _thrust,
    "excitation": _excitation,
}


def feed(pipeline: Pipeline, kind: str, msg: Stamped) -> list[SampleOutput]:
    """Hand one message of input ``kind`` to ``pipeline``; returns the samples it completed.
    A message whose ``header.frame_id`` is not the pipeline's ``frame_id`` (when that is set)
    is counted as ``frame_mismatch`` instead (:meth:`.pipeline.Pipeline.reject_frame`)."""
    frame = pipeline.frame_id
    if frame and msg.header.frame_id != frame:
        return pipeline.reject_frame(kind, stamp_ns(msg), msg.header.frame_id)
    return _FEED[kind](pipeline, msg)


_T = TypeVar("_T")


def arrival_order(taken: Mapping[str, Sequence[tuple[int, _T]]]) -> list[tuple[str, _T]]:
    """The messages taken at once from each input's queue, ``{kind: [(arrival time, message),
    ...]}`` in each queue's order, as one list of ``(kind, message)`` in order of arrival: the
    order :func:`feed` sees them in, as if each had been handed over when it arrived. Each
    stream keeps its own order; equal arrival times keep the order of ``taken``."""
    queues = [[(t, kind, m) for t, m in queue] for kind, queue in taken.items() if queue]
    if len(queues) == 1:
        return [(kind, m) for _t, kind, m in queues[0]]
    return [(kind, m) for _t, kind, m in heapq.merge(*queues, key=lambda x: x[0])]
