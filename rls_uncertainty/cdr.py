"""Fast CDR (XCDR1, little endian) for the few fixed message types the replay touches.

The offline replay reads thousands of standard input messages and writes tens of thousands
of output arrays; rosbags' generic (de)serializer costs tens of microseconds per message,
more than the estimation itself. These hand-written codecs cover exactly:

* decoding ``sensor_msgs/Imu``, ``geometry_msgs/Vector3Stamped``, ``sensor_msgs/FluidPressure``,
  ``sensor_msgs/JointState``, ``geometry_msgs/WrenchStamped`` into light objects with the
  same field names (what :mod:`.messages` reads);
* encoding ``std_msgs/Header`` and ``std_msgs/Float64MultiArray``.

``test/test_bags.py`` checks both directions against rosbags byte for byte / field for field.
Anything else (or a big-endian payload) returns ``None`` and the caller falls back to rosbags.
"""

from __future__ import annotations

import struct
from types import SimpleNamespace

__all__ = ["decode", "encode_header", "encode_float64_multiarray", "DECODABLE"]

_LE_HEADER = b"\x00\x01\x00\x00"
_TIME = struct.Struct("<iI")
_U32 = struct.Struct("<I")
_D = {n: struct.Struct(f"<{n}d") for n in (2, 3, 6, 37)}


def _align(offset: int, size: int) -> int:
    return (offset + size - 1) & ~(size - 1)


def _header(buf: bytes):
    sec, nanosec = _TIME.unpack_from(buf, 0)
    (n,) = _U32.unpack_from(buf, 8)
    frame = buf[12 : 12 + n - 1].decode() if n else ""
    return SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec), frame_id=frame), 12 + n


def _vec(values, i):
    return SimpleNamespace(x=values[i], y=values[i + 1], z=values[i + 2])


def _imu(buf):
    header, o = _header(buf)
    v = _D[37].unpack_from(buf, _align(o, 8))
    return SimpleNamespace(
        header=header,
        orientation=SimpleNamespace(x=v[0], y=v[1], z=v[2], w=v[3]),
        orientation_covariance=v[4:13],
        angular_velocity=_vec(v, 13),
        angular_velocity_covariance=v[16:25],
        linear_acceleration=_vec(v, 25),
        linear_acceleration_covariance=v[28:37],
    )


def _vector3_stamped(buf):
    header, o = _header(buf)
    return SimpleNamespace(header=header, vector=_vec(_D[3].unpack_from(buf, _align(o, 8)), 0))


def _fluid_pressure(buf):
    header, o = _header(buf)
    p, var = _D[2].unpack_from(buf, _align(o, 8))
    return SimpleNamespace(header=header, fluid_pressure=p, variance=var)


def _wrench_stamped(buf):
    header, o = _header(buf)
    v = _D[6].unpack_from(buf, _align(o, 8))
    return SimpleNamespace(header=header, wrench=SimpleNamespace(force=_vec(v, 0), torque=_vec(v, 3)))


def _doubles(buf, o):
    o = _align(o, 4)
    (n,) = _U32.unpack_from(buf, o)
    o += 4
    if n == 0:
        return (), o
    o = _align(o, 8)
    return struct.unpack_from(f"<{n}d", buf, o), o + 8 * n


def _joint_state(buf):
    header, o = _header(buf)
    o = _align(o, 4)
    (count,) = _U32.unpack_from(buf, o)
    o += 4
    names = []
    for _ in range(count):
        o = _align(o, 4)
        (n,) = _U32.unpack_from(buf, o)
        names.append(buf[o + 4 : o + 3 + n].decode())
        o += 4 + n
    position, o = _doubles(buf, o)
    velocity, o = _doubles(buf, o)
    effort, o = _doubles(buf, o)
    return SimpleNamespace(header=header, name=names, position=position, velocity=velocity, effort=effort)


_DECODERS = {
    "sensor_msgs/msg/Imu": _imu,
    "geometry_msgs/msg/Vector3Stamped": _vector3_stamped,
    "sensor_msgs/msg/FluidPressure": _fluid_pressure,
    "sensor_msgs/msg/JointState": _joint_state,
    "geometry_msgs/msg/WrenchStamped": _wrench_stamped,
}
DECODABLE = frozenset(_DECODERS)


def decode(msgtype: str, raw: bytes):
    """The message, or ``None`` when this module does not handle the type or encoding."""
    fn = _DECODERS.get(msgtype)
    if fn is None or raw[:4] != _LE_HEADER:
        return None
    return fn(memoryview(raw)[4:].tobytes())


def _string(out: bytearray, text: str) -> None:
    data = text.encode() + b"\x00"
    out += b"\x00" * (_align(len(out), 4) - len(out))
    out += _U32.pack(len(data)) + data


def encode_header(sec: int, nanosec: int, frame_id: str) -> bytes:
    """CDR of ``std_msgs/Header``."""
    out = bytearray(_TIME.pack(sec, nanosec))
    _string(out, frame_id)
    return _LE_HEADER + bytes(out)


def encode_float64_multiarray(label: str, data, second: str | None = None) -> bytes:
    """CDR of a ``std_msgs/Float64MultiArray`` with ``dim[0] = (label, n, n)`` and, when
    ``second`` is given, ``dim[1] = (second, 1, 1)``."""
    n = len(data)
    dims = [(label, n, n)] + ([(second, 1, 1)] if second is not None else [])
    out = bytearray(_U32.pack(len(dims)))
    for text, size, stride in dims:
        _string(out, text)
        out += b"\x00" * (_align(len(out), 4) - len(out))
        out += _U32.pack(size) + _U32.pack(stride)
    out += _U32.pack(0)  # data_offset
    out += _U32.pack(n)
    if n:
        out += b"\x00" * (_align(len(out), 8) - len(out))
        out += struct.pack(f"<{n}d", *data)
    return _LE_HEADER + bytes(out)
