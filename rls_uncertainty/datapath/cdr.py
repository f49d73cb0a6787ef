"""Fast CDR (XCDR1) for the few fixed message types the node and the replay touch.

The node receives thousands of standard input messages a second and the offline replay
reads thousands and writes tens of thousands; rclpy's and rosbags' generic (de)serializers
cost tens of microseconds per message, more than the estimation itself. These hand-written
codecs cover exactly:

* decoding ``sensor_msgs/Imu``, ``geometry_msgs/Vector3Stamped``, ``sensor_msgs/FluidPressure``,
  ``sensor_msgs/JointState``, ``geometry_msgs/WrenchStamped`` into light objects with the
  same field names (what :mod:`.inputs` reads), little- and big-endian, so node and replay
  have one decoding path (what is not read is built only on use: an IMU message's orientation
  and covariances; a JointState's names equal to the previous message's bytes are not parsed
  again); and ``std_msgs/Float64MultiArray``, the node's outputs as the
  dashboard reads them (live and from a replay's ``estimates.mcap``);
* encoding ``std_msgs/Header`` and ``std_msgs/Float64MultiArray`` (little endian), the latter
  with the vector layout of the estimates (:func:`encode_float64_multiarray`) or any layout
  (:func:`encode_float64_multiarray_dims`: the covariance matrices).

A payload that does not hold a whole message (truncated, a bad string length or terminator,
text that is not UTF-8, a sequence longer than the payload, an unknown encapsulation) raises
:class:`struct.error` whose text names the type and the problem, never a partial message.
Bytes after the message are ignored, as rclpy's deserializer does: rclpy's own serializer
leaves up to 8 of them (its size estimate pads empty sequences), where rosbags refuses more
than 3. ``test/test_cdr.py`` checks both directions against rosbags on thousands of random
messages, byte for byte and field for field.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import make_dataclass
from functools import lru_cache
from typing import Any

import numpy as np

__all__ = ["decode", "encode_header", "encode_string", "encode_diagnostic_array", "encode_float64_multiarray",
           "encode_float64_multiarray_dims", "multiarray_head", "multiarray_dim", "encode_float64_multiarray_tail",
           "DECODABLE", "FLOAT64_MULTIARRAY"]

_LE_HEADER = b"\x00\x01\x00\x00"
FLOAT64_MULTIARRAY = "std_msgs/msg/Float64MultiArray"
_TIME = struct.Struct("<iI")
_U32 = struct.Struct("<I")


# Light message objects with the ROS field names. Slotted, they are smaller than a
# SimpleNamespace and quicker to read: the IMU handler takes about 1.2 instead of 1.8 us.
def _message(name: str, fields: str) -> type:
    return make_dataclass(name, fields.split(), slots=True)


Time = _message("Time", "sec nanosec")
Header = _message("Header", "stamp frame_id")
Vector3 = _message("Vector3", "x y z")
Quaternion = _message("Quaternion", "x y z w")
Vector3Stamped = _message("Vector3Stamped", "header vector")
FluidPressure = _message("FluidPressure", "header fluid_pressure variance")
Wrench = _message("Wrench", "force torque")
WrenchStamped = _message("WrenchStamped", "header wrench")
JointState = _message("JointState", "header name position velocity effort")
MultiArrayDimension = _message("MultiArrayDimension", "label size stride")
MultiArrayLayout = _message("MultiArrayLayout", "dim data_offset")
Float64MultiArray = _message("Float64MultiArray", "layout data")


class Imu:
    """``sensor_msgs/Imu`` with the ROS field names (in ``__match_args__``, the ROS order).
    ``header``, ``angular_velocity`` and ``linear_acceleration`` (what :mod:`.inputs` reads)
    are built on decoding; ``orientation`` and the three covariances are unpacked from the
    payload on first use (read or assigned), so an IMU message decodes in five small
    objects instead of nine and six doubles instead of 37 (every field can be assigned)."""

    __slots__ = ("header", "angular_velocity", "linear_acceleration", "_buf", "_at", "_order", "_rest")
    __match_args__ = ("header", "orientation", "orientation_covariance", "angular_velocity",
                      "angular_velocity_covariance", "linear_acceleration", "linear_acceleration_covariance")

    def __init__(self, header: Any, angular_velocity: Any, linear_acceleration: Any, buf: bytes, at: int,
                 order: str) -> None:
        self.header, self.angular_velocity, self.linear_acceleration = header, angular_velocity, linear_acceleration
        self._buf, self._at, self._order = buf, at, order  # the 37 doubles at buf[at:]
        self._rest: list[Any] | None = None

    def _fields(self) -> list:
        """``[orientation, orientation_covariance, angular_velocity_covariance,
        linear_acceleration_covariance]``, unpacked once (the decoder checked the length)."""
        rest = self._rest
        if rest is None:
            v = _IMU_DOUBLES[self._order].unpack_from(self._buf, self._at)
            rest = self._rest = [Quaternion(v[0], v[1], v[2], v[3]), v[4:13], v[16:25], v[28:37]]
            self._buf = b""
        return rest

    def __repr__(self) -> str:
        return f"Imu({', '.join(f'{name}={getattr(self, name)!r}' for name in self.__match_args__)})"

    def __eq__(self, other: object) -> bool:
        if type(other) is not Imu:
            return NotImplemented
        return all(getattr(self, name) == getattr(other, name) for name in self.__match_args__)

    __hash__ = None  # type: ignore[assignment]  # (mutable, as the other messages)


def _imu_field(i: int, name: str) -> property:
    def get(self: Imu) -> Any:
        return self._fields()[i]

    def set_(self: Imu, value: Any) -> None:
        self._fields()[i] = value

    return property(get, set_, doc=f"``{name}``, unpacked on first use")


for _i, _name in enumerate(("orientation", "orientation_covariance", "angular_velocity_covariance",
                            "linear_acceleration_covariance")):
    setattr(Imu, _name, _imu_field(_i, _name))
_IMU_DOUBLES = {order: struct.Struct(f"{order}37d") for order in "<>"}


def _align(offset: int, size: int) -> int:
    return (offset + size - 1) & ~(size - 1)


def _bad_string(buf: bytes, o: int, n: int) -> struct.error:
    if n == 0 or o + 4 + n > len(buf):
        return struct.error(f"string at offset {o} declares {n} bytes with NUL, {len(buf) - o - 4} left")
    return struct.error(f"string at offset {o} is not NUL-terminated")


def _not_utf8(o: int, exc: UnicodeDecodeError) -> struct.error:
    return struct.error(f"string at offset {o} is not UTF-8 ({exc.reason} at byte {exc.start})")


def _read_string(buf: bytes, o: int, u32: struct.Struct) -> tuple[str, int]:
    """The CDR string at the 4-aligned offset ``o`` and the offset after it."""
    (n,) = u32.unpack_from(buf, o)
    end = o + 4 + n
    if n == 0 or end > len(buf) or buf[end - 1]:
        raise _bad_string(buf, o, n)
    try:
        return buf[o + 4 : end - 1].decode(), end
    except UnicodeDecodeError as exc:
        raise _not_utf8(o, exc) from None


def _too_long(buf: bytes, o: int, n: int, what: str) -> struct.error:
    return struct.error(f"{what} at offset {o} declares {n} elements, {len(buf) - o - 4} bytes left")


# The decoders of one byte order (``"<"`` or ``">"``). Each takes the payload after the 4-byte
# encapsulation header and returns the message. Offsets are aligned inline (they run for
# every input message). A CDR string at a 4-aligned offset o: its length n including the
# terminating NUL, then the bytes; n >= 1 and the last byte is NUL.
def _header_decoder(order: str) -> Callable[[bytes], tuple[Any, int]]:
    """``std_msgs/Header`` at the start of the payload: the header and the offset after it."""
    fixed = struct.Struct(order + "iII")  # the stamp and the frame_id's length, read at once

    def header(buf):
        sec, nanosec, n = fixed.unpack_from(buf, 0)
        end = 12 + n
        if n == 0 or end > len(buf) or buf[end - 1]:
            raise _bad_string(buf, 8, n)
        try:
            frame = buf[12 : end - 1].decode()
        except UnicodeDecodeError as exc:
            raise _not_utf8(8, exc) from None
        return Header(Time(sec, nanosec), frame), end

    return header


def _fixed_decoders(order: str, header: Callable[[bytes], tuple[Any, int]]) -> dict[str, Callable[[bytes], Any]]:
    """The types whose payload after the header is a fixed block of doubles."""
    d2, d3, d6 = (struct.Struct(f"{order}{n}d") for n in (2, 3, 6))
    rates = struct.Struct(f"{order}104x3d72x3d72x")  # 37 doubles' bytes

    def imu(buf):
        h, o = header(buf)
        o = (o + 7) & ~7
        # The rates and accelerations (doubles 13-15 and 25-27 of 37) in one unpack whose
        # padding spans the whole block: a short payload fails as unpacking all 37 would.
        wx, wy, wz, ax, ay, az = rates.unpack_from(buf, o)
        return Imu(h, Vector3(wx, wy, wz), Vector3(ax, ay, az), buf, o, order)

    def vector3_stamped(buf):
        h, o = header(buf)
        return Vector3Stamped(h, Vector3(*d3.unpack_from(buf, (o + 7) & ~7)))

    def fluid_pressure(buf):
        h, o = header(buf)
        p, var = d2.unpack_from(buf, (o + 7) & ~7)
        return FluidPressure(h, p, var)

    def wrench_stamped(buf):
        h, o = header(buf)
        v = d6.unpack_from(buf, (o + 7) & ~7)
        return WrenchStamped(h, Wrench(Vector3(v[0], v[1], v[2]), Vector3(v[3], v[4], v[5])))

    return {
        "sensor_msgs/msg/Imu": imu,
        "geometry_msgs/msg/Vector3Stamped": vector3_stamped,
        "sensor_msgs/msg/FluidPressure": fluid_pressure,
        "geometry_msgs/msg/WrenchStamped": wrench_stamped,
    }


def _joint_state_decoder(order: str, header: Callable[[bytes], tuple[Any, int]]) -> Callable[[bytes], Any]:
    """``sensor_msgs/JointState``: a sequence of strings and three sequences of doubles."""
    u32 = struct.Struct(order + "I")
    last_names: dict[int, tuple[bytes, tuple[str, ...]]] = {}  # by offset: the names' bytes, the names

    def doubles(buf, o, what):
        o = (o + 3) & ~3
        (n,) = u32.unpack_from(buf, o)
        if n == 0:
            return (), o + 4
        if 8 * n > len(buf) - o - 4:
            raise _too_long(buf, o, n, what)
        start = (o + 11) & ~7
        return struct.unpack_from(f"{order}{n}d", buf, start), start + 8 * n

    def joint_state(buf):
        h, o = header(buf)
        o = (o + 3) & ~3
        (count,) = u32.unpack_from(buf, o)
        size = len(buf)
        if 5 * count > size - o - 4:  # each name takes at least 5 bytes
            raise _too_long(buf, o, count, "name")
        # The names repeat from message to message: bytes equal to the last names' bytes at
        # the same offset are those names (parsing them again would give the same strings).
        known = last_names.get(o)
        if known is not None and buf.startswith(known[0], o):
            names, o = list(known[1]), o + len(known[0])
        else:
            start = o
            o += 4
            names = []
            for _ in range(count):
                name, o = _read_string(buf, (o + 3) & ~3, u32)
                names.append(name)
            if len(last_names) > 8:  # (a few header lengths at most in one stream)
                last_names.clear()
            last_names[start] = (buf[start:o], tuple(names))
        position, o = doubles(buf, o, "position")
        velocity, o = doubles(buf, o, "velocity")
        effort, _ = doubles(buf, o, "effort")
        return JointState(h, names, position, velocity, effort)

    return joint_state


def _multiarray_decoder(order: str) -> Callable[[bytes], Any]:
    """``std_msgs/Float64MultiArray``: a sequence of dims (a string, two uint32), the uint32
    ``data_offset`` and a sequence of doubles (``data``, a tuple)."""
    u32, dim_tail = struct.Struct(order + "I"), struct.Struct(order + "II")

    def multiarray(buf):
        size = len(buf)
        (count,) = u32.unpack_from(buf, 0)
        if 16 * count > size - 4:  # each dim takes at least 16 bytes (length, NUL, padding, size, stride)
            raise _too_long(buf, 0, count, "dim")
        o = 4
        dims = []
        for _ in range(count):
            label, o = _read_string(buf, (o + 3) & ~3, u32)
            o = (o + 3) & ~3
            dims.append(MultiArrayDimension(label, *dim_tail.unpack_from(buf, o)))
            o += 8
        o = (o + 3) & ~3
        data_offset, n = dim_tail.unpack_from(buf, o)
        if 8 * n > size - o - 8:
            raise _too_long(buf, o + 4, n, "data")
        data = struct.unpack_from(f"{order}{n}d", buf, (o + 15) & ~7) if n else ()
        return Float64MultiArray(MultiArrayLayout(dims, data_offset), data)

    return multiarray


def _decoders(order: str) -> dict[str, Callable[[bytes], Any]]:
    """Every decoder of one byte order (``"<"`` or ``">"``), by message type."""
    header = _header_decoder(order)
    return {**_fixed_decoders(order, header), "sensor_msgs/msg/JointState": _joint_state_decoder(order, header),
            FLOAT64_MULTIARRAY: _multiarray_decoder(order)}


_LITTLE = _decoders("<")
_BIG = _decoders(">")
DECODABLE = frozenset(_LITTLE)  # the inputs' types and FLOAT64_MULTIARRAY


def decode(msgtype: str, raw: bytes | memoryview) -> Any:
    """The message decoded from a serialized payload (``bytes`` or ``memoryview``, with its
    4-byte encapsulation header), or ``None`` when this module does not handle ``msgtype``.
    Raises :class:`struct.error` naming the type and the problem when the payload does not
    hold one valid message."""
    head = raw[:2]  # the encapsulation; the two option bytes after it are ignored (as DDS does)
    if head == b"\x00\x01":
        fn = _LITTLE.get(msgtype)
    elif head == b"\x00\x00":
        fn = _BIG.get(msgtype)
    elif msgtype in DECODABLE:
        raise struct.error(f"{msgtype}: not a CDR payload (encapsulation {bytes(raw[:4]).hex() or 'missing'})")
    else:
        return None
    if fn is None:
        return None
    if len(raw) < 4:
        raise struct.error(f"{msgtype}: not a CDR payload (encapsulation {bytes(raw).hex()})")
    buf = raw[4:]
    if type(buf) is not bytes:
        buf = bytes(buf)
    try:
        return fn(buf)
    except struct.error as exc:
        raise struct.error(f"{msgtype}: malformed {len(raw)}-byte payload: {exc}") from None


def _string(out: bytearray, text: str) -> None:
    data = text.encode() + b"\x00"
    out += b"\x00" * (_align(len(out), 4) - len(out))
    out += _U32.pack(len(data)) + data


def encode_header(sec: int, nanosec: int, frame_id: str) -> bytes:
    """CDR of ``std_msgs/Header``."""
    out = bytearray(_TIME.pack(sec, nanosec))
    _string(out, frame_id)
    return _LE_HEADER + bytes(out)


def encode_string(text: str) -> bytes:
    """CDR of ``std_msgs/String``."""
    out = bytearray()
    _string(out, text)
    return _LE_HEADER + bytes(out)


def encode_diagnostic_array(sec: int, nanosec: int,
                            statuses: Sequence[tuple[int, str, str, str, Sequence[tuple[str, str]]]]) -> bytes:
    """CDR of ``diagnostic_msgs/DiagnosticArray`` (header ``frame_id`` empty) of ``statuses``,
    each ``(level, name, message, hardware_id, key-values)``."""
    out = bytearray(_TIME.pack(sec, nanosec))
    _string(out, "")
    _sequence_length(out, len(statuses))
    for level, name, message, hardware_id, values in statuses:
        out.append(level)  # (a byte: no alignment)
        for text in (name, message, hardware_id):
            _string(out, text)
        _sequence_length(out, len(values))
        for key, value in values:
            _string(out, key)
            _string(out, value)
    return _LE_HEADER + bytes(out)


def _sequence_length(out: bytearray, n: int) -> None:
    out += b"\x00" * (_align(len(out), 4) - len(out))
    out += _U32.pack(n)


# A MultiArrayDimension starts 4-aligned and its bytes (label length, label, NUL, padding to 4,
# size, stride) are a multiple of 4 long, so each one's bytes do not depend on where it sits:
# they are built once per (label, size, stride). The parameter labels repeat for every sample
# and one sample's stamp label for each of its arrays.
@lru_cache(maxsize=512)
def _dim(text: str, size: int, stride: int) -> bytes:
    data = text.encode() + b"\x00"
    return _U32.pack(len(data)) + data + b"\x00" * (-len(data) % 4) + _U32.pack(size) + _U32.pack(stride)


@lru_cache(maxsize=64)
def _doubles(n: int) -> struct.Struct:
    return struct.Struct(f"<{n}d")


_COUNTS = tuple(_U32.pack(i) for i in range(8))
_LE_F64 = np.dtype("<f8")
_ZERO_AND_COUNT = struct.Struct("<II")
_PADDING = tuple(b"\x00" * i for i in range(8))


def _multiarray(dims: bytes, data_offset: int, data: Sequence[float] | np.ndarray) -> bytes:
    n = len(data)
    head = dims + _U32.pack(data_offset) + _U32.pack(n)
    if not n:
        return _LE_HEADER + head
    # A numpy array is copied out as little-endian doubles at once (the node's case).
    raw = data.astype(_LE_F64, copy=False).tobytes() if type(data) is np.ndarray else _doubles(n).pack(*data)
    return _LE_HEADER + head + b"\x00" * (-len(head) % 8) + raw


def encode_float64_multiarray(label: str, data: Sequence[float] | np.ndarray, second: str | None = None) -> bytes:
    """CDR of a ``std_msgs/Float64MultiArray`` with ``dim[0] = (label, n, n)`` and, when
    ``second`` is given, ``dim[1] = (second, 1, 1)``; ``data``: a sequence of floats or a
    one-dimensional numpy array."""
    n = len(data)
    if second is None:
        dims = _COUNTS[1] + _dim(label, n, n)
    else:
        dims = _COUNTS[2] + _dim(label, n, n) + _dim(second, 1, 1)
    return _multiarray(dims, 0, data)


def multiarray_head(dims: Sequence[tuple[str, int, int]], count: int) -> bytes:
    """The first bytes of a ``std_msgs/Float64MultiArray`` layout of ``count`` dims: the dim
    count and ``dims``, the leading ones (the caller adds the rest with
    :func:`encode_float64_multiarray_tail`)."""
    return _U32.pack(count) + b"".join(_dim(text, size, stride) for text, size, stride in dims)


def multiarray_dim(label: str, size: int, stride: int) -> bytes:
    """The bytes of one ``std_msgs/MultiArrayDimension`` as :func:`multiarray_head` lays it."""
    return _dim(label, size, stride)


def encode_float64_multiarray_tail(head: bytes, last: bytes, data: np.ndarray) -> bytes:
    """CDR of a ``std_msgs/Float64MultiArray`` whose layout is :func:`multiarray_head`'s
    ``head`` then the dim ``last`` (:func:`multiarray_dim`), ``data_offset`` 0 and the doubles
    of the numpy array ``data`` in row-major order: the bytes of
    :func:`encode_float64_multiarray_dims` with those dims and ``data``, built with the dims
    that repeat from sample to sample made once."""
    n = data.size
    dims = head + last + _ZERO_AND_COUNT.pack(0, n)  # data_offset 0, then the data's length
    if not n:
        return _LE_HEADER + dims
    raw = data.tobytes() if data.dtype == _LE_F64 else data.astype(_LE_F64).tobytes()  # row-major
    return b"".join((_LE_HEADER, dims, _PADDING[-len(dims) % 8], raw))


def encode_float64_multiarray_dims(dims: Sequence[tuple[str, int, int]], data: Sequence[float],
                                   data_offset: int = 0) -> bytes:
    """CDR of a ``std_msgs/Float64MultiArray`` with ``layout.dim`` = ``dims``, a sequence of
    ``(label, size, stride)``, ``layout.data_offset`` and ``data`` (a sequence of floats or a
    one-dimensional numpy array)."""
    head = _U32.pack(len(dims)) + b"".join(_dim(text, size, stride) for text, size, stride in dims)
    return _multiarray(head, data_offset, data)
