"""rls_uncertainty.datapath.cdr against rosbags (and rclpy): thousands of seeded random messages of every
type it decodes (the inputs' and Float64MultiArray, the outputs the dashboard reads), in both
byte orders, field for field with floats compared bit for bit; its
encoders byte for byte; truncated and garbage payloads refused exactly when rosbags refuses
them (bytes after the message aside); and the bundled bag decoded like rosbags decodes it."""

from __future__ import annotations

import copy
import dataclasses
import random
import struct
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore

from rls_uncertainty.datapath import cdr
from rls_uncertainty.datapath.inputs import MESSAGE_TYPES

ROOT = Path(__file__).resolve().parents[1]

STORE = get_typestore(Stores.ROS2_JAZZY)
T = STORE.types
BUNDLED = ROOT / "bags" / "t2_maneuver"
N_RANDOM = 1000  # random messages per type (each decoded in both byte orders, and padded)

INT32 = (-(2**31), 2**31 - 1)
UINT32_MAX = 2**32 - 1
SPECIAL_FLOATS = (
    0.0, -0.0, float("inf"), float("-inf"), float("nan"), -float("nan"),
    sys.float_info.max, -sys.float_info.max, sys.float_info.min, -sys.float_info.min,
    5e-324, -5e-324, 1e-300, -1e300, 1.0, -1.0,
)
# Code point ranges of valid UTF-8 text without NUL (ROS strings end at the first NUL) and
# without surrogates: ASCII, two-, three- and four-byte sequences.
CODE_POINTS = ((0x01, 0x7F), (0x80, 0x7FF), (0x800, 0xD7FF), (0xE000, 0xFFFF), (0x10000, 0x10FFFF))


# ------------------------------------------------------------------ random inputs
def rand_float(rng: random.Random) -> float:
    r = rng.random()
    if r < 0.25:
        return rng.choice(SPECIAL_FLOATS)
    if r < 0.5:  # any bit pattern: every exponent, subnormals, NaN payloads of both signs
        return struct.unpack("<d", rng.randbytes(8))[0]
    if r < 0.75:
        return rng.gauss(0.0, 10.0 ** rng.randint(-10, 10))
    return rng.uniform(-1e308, 1e308)


def rand_floats(rng: random.Random, n: int) -> np.ndarray:
    return np.array([rand_float(rng) for _ in range(n)], dtype=np.float64)


def rand_text(rng: random.Random, max_len: int = 24) -> str:
    r = rng.random()
    if r < 0.15:
        return ""
    if r < 0.3:
        return rng.choice(("base_link", "imu_link", "élevon_gauche", "舵面", "🛩️ wing", "a" * 300))
    chars = []
    for _ in range(rng.randint(1, max_len)):
        lo, hi = rng.choice(CODE_POINTS)
        chars.append(chr(rng.randint(lo, hi)))
    return "".join(chars)


def rand_length(rng: random.Random) -> int:
    r = rng.random()
    if r < 0.05:
        return rng.randint(65, 300)
    return rng.choice((0, 0, 1, 2, 3, 4, 5, 7, 8, 13, rng.randint(0, 64)))


def rand_header(rng: random.Random):
    sec = rng.choice((*INT32, 0, rng.randint(*INT32), rng.randint(0, 2**31 - 1)))
    nanosec = rng.choice((0, 999_999_999, UINT32_MAX, rng.randint(0, UINT32_MAX)))
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                    frame_id=rand_text(rng))


def rand_vector3(rng: random.Random):
    return T["geometry_msgs/msg/Vector3"](x=rand_float(rng), y=rand_float(rng), z=rand_float(rng))


def rand_message(rng: random.Random, msgtype: str):
    h = rand_header(rng)
    if msgtype == "sensor_msgs/msg/Imu":
        q = T["geometry_msgs/msg/Quaternion"](
            x=rand_float(rng), y=rand_float(rng), z=rand_float(rng), w=rand_float(rng)
        )
        return T[msgtype](header=h, orientation=q, orientation_covariance=rand_floats(rng, 9),
                          angular_velocity=rand_vector3(rng), angular_velocity_covariance=rand_floats(rng, 9),
                          linear_acceleration=rand_vector3(rng), linear_acceleration_covariance=rand_floats(rng, 9))
    if msgtype == "geometry_msgs/msg/Vector3Stamped":
        return T[msgtype](header=h, vector=rand_vector3(rng))
    if msgtype == "sensor_msgs/msg/FluidPressure":
        return T[msgtype](header=h, fluid_pressure=rand_float(rng), variance=rand_float(rng))
    if msgtype == "sensor_msgs/msg/JointState":
        # Names and the three arrays of independent lengths: empty, equal, mismatched.
        return T[msgtype](header=h, name=[rand_text(rng, 12) for _ in range(rand_length(rng))],
                          position=rand_floats(rng, rand_length(rng)), velocity=rand_floats(rng, rand_length(rng)),
                          effort=rand_floats(rng, rand_length(rng)))
    if msgtype == "geometry_msgs/msg/WrenchStamped":
        return T[msgtype](header=h, wrench=T["geometry_msgs/msg/Wrench"](force=rand_vector3(rng),
                                                                         torque=rand_vector3(rng)))
    if msgtype == cdr.FLOAT64_MULTIARRAY:  # no header: any number of dims, any sizes, any data
        dims = [T["std_msgs/msg/MultiArrayDimension"](label=rand_text(rng), size=rng.randint(0, UINT32_MAX),
                                                      stride=rng.choice((0, 1, rng.randint(0, UINT32_MAX))))
                for _ in range(rng.choice((0, 1, 2, 3, rand_length(rng))))]
        layout = T["std_msgs/msg/MultiArrayLayout"](dim=dims, data_offset=rng.choice((0, rng.randint(0, UINT32_MAX))))
        return T[msgtype](layout=layout, data=rand_floats(rng, rand_length(rng)))
    raise AssertionError(msgtype)


# ------------------------------------------------------------------ comparison
def bits(x: float) -> bytes:
    return struct.pack("<d", x)


def assert_same(ours, ref, path: str = "msg") -> None:
    """Every field of rosbags' ``ref`` equals the one of ``ours``: the same field names,
    strings and integers equal, floats bit for bit (NaN payloads, negative zero)."""
    if dataclasses.is_dataclass(ref):
        names = [f.name for f in dataclasses.fields(ref) if not f.name.startswith("__")]
        assert [n for n in type(ours).__match_args__ if not n.startswith("__")] == names, path
        for name in names:
            assert_same(getattr(ours, name), getattr(ref, name), f"{path}.{name}")
    elif isinstance(ref, (str, int)) and not isinstance(ref, (bool, np.floating)):
        assert type(ours) is type(ref) and ours == ref, f"{path}: {ours!r} != {ref!r}"
    elif isinstance(ref, (float, np.floating)):
        assert isinstance(ours, float) and bits(ours) == bits(float(ref)), f"{path}: {ours!r} != {ref!r}"
    else:  # a sequence: numpy array of doubles or list of strings
        assert len(ours) == len(ref), f"{path}: length {len(ours)} != {len(ref)}"
        for i, (a, b) in enumerate(zip(ours, ref, strict=True)):
            assert_same(a, b.item() if isinstance(b, np.generic) else b, f"{path}[{i}]")


def serialize(msg, msgtype: str, little_endian: bool = True) -> bytes:
    return bytes(STORE.serialize_cdr(msg, msgtype, little_endian=little_endian))


def rosbags_decode(raw: bytes, msgtype: str):
    """rosbags' ``deserialize_cdr`` without its refusal of more than 3 bytes after the message:
    rclpy's serializer leaves up to 8 (see test_messages_serialized_by_rclpy_...), and both
    rclpy's deserializer and cdr.decode ignore them."""
    if len(raw) < 4 or raw[:2] not in (b"\x00\x00", b"\x00\x01"):
        raise SerdeError("not CDR")
    msgdef = STORE.get_msgdef(msgtype)
    fn = msgdef.deserialize_cdr_le if raw[1] else msgdef.deserialize_cdr_be
    try:
        return fn(raw[4:], 0, msgdef.cls, STORE)[0]
    except (struct.error, UnicodeDecodeError, ValueError) as exc:
        raise SerdeError(str(exc)) from exc


def random_payloads(msgtype: str, seed: int, n: int):
    rng = random.Random(f"{seed}:{msgtype}")
    for _ in range(n):
        yield rand_message(rng, msgtype)


# ------------------------------------------------------------------ decoding
def test_every_input_type_and_the_output_arrays_are_decodable_and_others_are_left_to_rosbags():
    assert set(MESSAGE_TYPES.values()) | {cdr.FLOAT64_MULTIARRAY} == cdr.DECODABLE
    assert cdr.decode("std_msgs/msg/String", b"\x00\x01\x00\x00") is None
    assert cdr.decode("std_msgs/msg/String", b"garbage") is None


@pytest.mark.parametrize("msgtype", sorted(cdr.DECODABLE))
def test_random_messages_of_both_byte_orders_decode_like_rosbags(msgtype):
    for i, msg in enumerate(random_payloads(msgtype, 1, N_RANDOM)):
        little = serialize(msg, msgtype, True)
        big = serialize(msg, msgtype, False)
        assert little[:2] == b"\x00\x01" and big[:2] == b"\x00\x00"
        for raw in (little, big):
            ours = cdr.decode(msgtype, raw)
            assert_same(ours, msg, f"{msgtype}#{i}")
            assert_same(ours, STORE.deserialize_cdr(raw, msgtype), f"{msgtype}#{i}")
        # A memoryview, and up to 3 bytes of alignment padding after the message, decode the same.
        padding = bytes(i % 4)
        assert_same(cdr.decode(msgtype, memoryview(big + padding)), msg, f"{msgtype}#{i} padded")


@pytest.mark.parametrize("msgtype", sorted(cdr.DECODABLE))
def test_messages_serialized_by_rclpy_decode_to_the_same_fields(msgtype):
    """The node's input path: payloads serialized by rclpy, whose alignment padding is not
    zeroed (whatever the buffer held), so only the fields can be compared, and which may end
    with up to 8 bytes after the message (its size estimate pads empty sequences)."""
    from rclpy.serialization import deserialize_message, serialize_message

    from rls_uncertainty.datapath.inputs import message_class

    cls = message_class(msgtype)
    longer = 0
    for i, msg in enumerate(random_payloads(msgtype, 2, 200)):
        exact = serialize(msg, msgtype)
        raw = serialize_message(deserialize_message(exact, cls))
        longer += len(raw) > len(exact) + 3
        assert_same(cdr.decode(msgtype, raw), msg, f"{msgtype}#{i}")
    if msgtype == "sensor_msgs/msg/JointState":
        assert longer > 20  # rosbags' deserialize_cdr refuses these


def _refuses(msgtype: str, raw: bytes) -> str:
    with pytest.raises(struct.error) as info:
        cdr.decode(msgtype, raw)
    text = str(info.value)
    assert text.startswith(msgtype), text
    return text


@pytest.mark.parametrize("msgtype", sorted(cdr.DECODABLE))
def test_truncated_payloads_are_refused_with_the_type_and_problem(msgtype):
    rng = random.Random(f"truncated:{msgtype}")
    for i, msg in enumerate(random_payloads(msgtype, 3, 100)):
        raw = serialize(msg, msgtype, i % 2 == 0)
        # Every cut in the header and the last bytes, and a sample of the others.
        cuts = {*range(min(len(raw), 48)), *range(max(0, len(raw) - 16), len(raw)),
                *rng.sample(range(len(raw)), min(len(raw), 24))}
        for cut in sorted(cuts):
            text = _refuses(msgtype, raw[:cut])
            assert ("not a CDR payload" in text) if cut < 4 else ("malformed" in text), text
            if cut % 5 == 0:
                with pytest.raises(SerdeError):
                    rosbags_decode(raw[:cut], msgtype)


def _mutations(rng: random.Random, raw: bytes):
    """Damaged copies of a valid payload: random bytes overwritten, a length field changed,
    bytes appended, the whole body replaced by random bytes."""
    body = bytearray(raw)
    for _ in range(rng.randint(1, 4)):
        body[rng.randrange(4, len(body))] = rng.randrange(256)
    yield bytes(body)
    body = bytearray(raw)
    at = rng.randrange(4, len(body) - 3)
    body[at:at + 4] = struct.pack("<I", rng.choice((0, 1, 2**31, UINT32_MAX, rng.randrange(2**32))))
    yield bytes(body)
    yield raw + rng.randbytes(rng.randint(4, 40))
    yield raw[:4] + rng.randbytes(rng.randint(0, 2 * len(raw)))


@pytest.mark.parametrize("msgtype", sorted(cdr.DECODABLE))
def test_garbage_is_refused_exactly_when_rosbags_refuses_it(msgtype):
    rng = random.Random(f"garbage:{msgtype}")
    refused = decoded = 0
    for i, msg in enumerate(random_payloads(msgtype, 4, 400)):
        for raw in _mutations(rng, serialize(msg, msgtype, i % 2 == 0)):
            try:
                ref = rosbags_decode(raw, msgtype)
            except SerdeError:
                _refuses(msgtype, raw)
                refused += 1
            else:
                assert_same(cdr.decode(msgtype, raw), ref, f"{msgtype}#{i}")
                decoded += 1
    assert refused > 400 and decoded > 100  # both outcomes were exercised


def rng_bytes(seed: str, n: int) -> bytes:
    return random.Random(seed).randbytes(n)


@pytest.mark.parametrize("msgtype", sorted(cdr.DECODABLE))
def test_payloads_that_are_not_cdr_are_refused_and_bytes_after_the_message_ignored(msgtype):
    good = serialize(rand_message(random.Random(5), msgtype), msgtype)
    for raw in (b"", b"\x00", b"\x00\x01", b"\x00\x01\x00", b"\x00\x02\x00\x00" + good[4:],
                b"\x01\x00\x00\x00" + good[4:], b"\x00\x06\x00\x00" + good[4:]):
        assert "not a CDR payload" in _refuses(msgtype, raw)
    assert_same(cdr.decode(msgtype, good + rng_bytes(msgtype, 9)), STORE.deserialize_cdr(good, msgtype))
    # The option bytes of the encapsulation header are ignored (as rosbags and DDS do).
    assert_same(cdr.decode(msgtype, good[:2] + b"\x00\x03" + good[4:]), STORE.deserialize_cdr(good, msgtype))


def test_string_problems_are_named():
    h = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="ab")
    msg = T["geometry_msgs/msg/Vector3Stamped"](header=h, vector=T["geometry_msgs/msg/Vector3"](x=1.0, y=2.0, z=3.0))
    t = "geometry_msgs/msg/Vector3Stamped"
    raw = bytearray(serialize(msg, t))
    assert raw[12:19] == b"\x03\x00\x00\x00ab\x00"
    bad = bytearray(raw)
    bad[18] = ord("c")  # no NUL terminator
    assert "not NUL-terminated" in _refuses(t, bytes(bad))
    bad = bytearray(raw)
    bad[16] = 0xFF  # not UTF-8
    assert "not UTF-8" in _refuses(t, bytes(bad))
    bad = bytearray(raw)
    bad[12:16] = struct.pack("<I", 0)  # an empty CDR string has length 1 (the NUL)
    assert "declares 0 bytes" in _refuses(t, bytes(bad))
    bad[12:16] = struct.pack("<I", UINT32_MAX)
    assert f"declares {UINT32_MAX} bytes" in _refuses(t, bytes(bad))


def test_huge_sequence_counts_are_refused_without_allocating():
    js = T["sensor_msgs/msg/JointState"](header=rand_header(random.Random(6)), name=[], position=np.zeros(0),
                                         velocity=np.zeros(0), effort=np.zeros(0))
    t = "sensor_msgs/msg/JointState"
    raw = serialize(js, t)
    for tail_from_end, what in ((16, "name"), (12, "position"), (8, "velocity"), (4, "effort")):
        bad = bytearray(raw)
        at = len(raw) - tail_from_end
        assert bad[at:at + 4] == bytes(4)
        bad[at:at + 4] = struct.pack("<I", UINT32_MAX)
        assert f"{what} at offset" in _refuses(t, bytes(bad))


def test_the_bundled_bag_decodes_like_rosbags():
    from rosbags.highlevel import AnyReader

    seen = set()
    with AnyReader([BUNDLED], default_typestore=STORE) as reader:
        for conn, _t, raw in reader.messages():
            seen.add(conn.msgtype)
            assert_same(cdr.decode(conn.msgtype, raw), reader.deserialize(raw, conn.msgtype), conn.topic)
    assert seen == set(MESSAGE_TYPES.values())


# ------------------------------------------------------------------ encoding
def _multiarray(label: str, data, second: str | None):
    Dim = T["std_msgs/msg/MultiArrayDimension"]
    dims = [Dim(label=label, size=len(data), stride=len(data))]
    dims += [Dim(label=second, size=1, stride=1)] if second is not None else []
    return T["std_msgs/msg/Float64MultiArray"](layout=T["std_msgs/msg/MultiArrayLayout"](dim=dims, data_offset=0),
                                               data=np.array(data, dtype=np.float64))


def test_encoders_equal_rosbags_and_rclpy_on_fixed_cases():
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64MultiArray, Header

    cases = (("CZ_0,CZ_alpha,CZ_delta_e", [1.5, -2.25, 1e-300], "stamp:1767225600.140000000"),
             ("x", [], None), ("ab", [3.0], "s"), ("abc", [1.0, 2.0], None), ("", [], ""))
    for label, data, second in cases:
        want = serialize(_multiarray(label, data, second), "std_msgs/msg/Float64MultiArray")
        got = cdr.encode_float64_multiarray(label, data, second)
        assert got == want
        back = deserialize_message(got, Float64MultiArray)  # what a subscriber of the node gets
        assert [(d.label, d.size, d.stride) for d in back.layout.dim] == [(d.label, d.size, d.stride) for d in
                                                                         _multiarray(label, data, second).layout.dim]
        assert back.layout.data_offset == 0 and list(back.data) == data
    for frame in ("base_link", "", "abc"):
        ref = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=17, nanosec=99), frame_id=frame)
        got = cdr.encode_header(17, 99, frame)
        assert got == serialize(ref, "std_msgs/msg/Header")
        back = deserialize_message(got, Header)
        assert (back.stamp.sec, back.stamp.nanosec, back.frame_id) == (17, 99, frame)


def test_random_headers_encode_byte_identical_to_rosbags():
    rng = random.Random(7)
    for _ in range(N_RANDOM):
        h = rand_header(rng)
        got = cdr.encode_header(h.stamp.sec, h.stamp.nanosec, h.frame_id)
        assert got == serialize(h, "std_msgs/msg/Header"), h
        assert_same(STORE.deserialize_cdr(got, "std_msgs/msg/Header"), h)


def test_random_multiarrays_encode_byte_identical_to_rosbags():
    rng = random.Random(8)
    for _ in range(N_RANDOM):
        data = [rand_float(rng) for _ in range(rng.choice((0, 1, 2, 3, 4, 6, 9, rng.randint(0, 80))))]
        label, second = rand_text(rng, 60), rng.choice((None, rand_text(rng, 30)))
        got = cdr.encode_float64_multiarray(label, data, second)
        assert got == serialize(_multiarray(label, data, second), "std_msgs/msg/Float64MultiArray")
        assert cdr.encode_float64_multiarray(label, np.array(data, dtype=np.float64), second) == got
        back = STORE.deserialize_cdr(got, "std_msgs/msg/Float64MultiArray")
        assert [bits(x) for x in back.data] == [bits(x) for x in data]


def _layout_array(dims, data, data_offset=0):
    Dim = T["std_msgs/msg/MultiArrayDimension"]
    return T["std_msgs/msg/Float64MultiArray"](
        layout=T["std_msgs/msg/MultiArrayLayout"](dim=[Dim(label=lb, size=sz, stride=st) for lb, sz, st in dims],
                                                  data_offset=data_offset),
        data=np.array(data, dtype=np.float64))


def test_the_layout_encoder_equals_rosbags_and_rclpy_on_a_covariance():
    """The node's n x n covariance layout: dims (names, n, n*n), (names, n, n), (stamp, 1, 1)."""
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64MultiArray

    names = "Cm_0,Cm_alpha,Cm_q,Cm_delta_e"
    dims = [(names, 4, 16), (names, 4, 4), ("stamp:1767225600.140000000", 1, 1)]
    data = [float(i) * 1e-3 - 0.002 for i in range(16)]
    got = cdr.encode_float64_multiarray_dims(dims, data)
    assert got == serialize(_layout_array(dims, data), "std_msgs/msg/Float64MultiArray")
    back = deserialize_message(got, Float64MultiArray)
    assert [(d.label, d.size, d.stride) for d in back.layout.dim] == dims
    assert back.layout.data_offset == 0 and list(back.data) == data
    # The vector layout through either encoder is the same bytes.
    assert cdr.encode_float64_multiarray_dims([("a,b", 2, 2), ("s", 1, 1)], [1.0, 2.0]) == \
        cdr.encode_float64_multiarray("a,b", [1.0, 2.0], "s")


def test_random_layouts_encode_byte_identical_to_rosbags():
    rng = random.Random(9)
    for _ in range(N_RANDOM):
        dims = [(rand_text(rng, 40), rng.randint(0, UINT32_MAX), rng.randint(0, UINT32_MAX))
                for _ in range(rng.choice((0, 1, 2, 3, rng.randint(0, 8))))]
        data = [rand_float(rng) for _ in range(rng.choice((0, 1, 4, 9, rng.randint(0, 40))))]
        offset = rng.choice((0, rng.randint(0, UINT32_MAX)))
        got = cdr.encode_float64_multiarray_dims(dims, data, offset)
        assert got == serialize(_layout_array(dims, data, offset), "std_msgs/msg/Float64MultiArray")
        # numpy arrays (the node passes them) give the same bytes, also as strided views.
        assert cdr.encode_float64_multiarray_dims(dims, np.array(data), offset) == got
        assert cdr.encode_float64_multiarray_dims(dims, np.repeat(np.array(data), 2)[::2], offset) == got
        back = STORE.deserialize_cdr(got, "std_msgs/msg/Float64MultiArray")
        assert [(d.label, d.size, d.stride) for d in back.layout.dim] == dims and back.layout.data_offset == offset
        assert [bits(x) for x in back.data] == [bits(x) for x in data]


def test_layouts_built_from_a_head_and_a_last_dim_encode_byte_identical_to_rosbags():
    """encode_float64_multiarray_tail (the node's arrays: dims made once, the stamp's dim per
    sample, the data a numpy array, strided or 2-D as a covariance slice) is rosbags' bytes."""
    rng = random.Random(10)
    for _ in range(N_RANDOM):
        dims = [(rand_text(rng, 40), rng.randint(0, UINT32_MAX), rng.randint(0, UINT32_MAX))
                for _ in range(rng.randint(1, 4))]
        rows, cols = rng.choice(((1, 0), (1, 1), (1, rng.randint(1, 12)), (rng.randint(1, 6), rng.randint(1, 6))))
        block = np.array([[rand_float(rng) for _ in range(cols + 2)] for _ in range(rows + 1)])
        data = block[:rows, 1 : cols + 1]  # not contiguous
        head = cdr.multiarray_head(dims[:-1], len(dims))
        got = cdr.encode_float64_multiarray_tail(head, cdr.multiarray_dim(*dims[-1]), data if rows > 1 else data[0])
        assert got == serialize(_layout_array(dims, data.ravel().tolist(), 0), "std_msgs/msg/Float64MultiArray")
        # Row-major whatever the array's memory order.
        assert cdr.encode_float64_multiarray_tail(head, cdr.multiarray_dim(*dims[-1]), np.asfortranarray(data)) == \
            cdr.encode_float64_multiarray_tail(head, cdr.multiarray_dim(*dims[-1]), data)


def test_imu_fields_unpacked_on_first_use_can_be_assigned_and_copied():
    """The IMU fields the pipeline does not read are unpacked when first read or assigned;
    assigning one keeps the others as decoded, and a copy decodes the same."""
    rng = random.Random(11)
    msgtype = "sensor_msgs/msg/Imu"
    for i in range(50):
        ref = rand_message(rng, msgtype)
        raw = serialize(ref, msgtype, little_endian=bool(i % 2))
        assert_same(copy.deepcopy(cdr.decode(msgtype, raw)), ref, f"copy#{i}")
        ours = cdr.decode(msgtype, raw)
        ours.angular_velocity_covariance = (1.0,) * 9
        assert ours.angular_velocity_covariance == (1.0,) * 9
        ref.angular_velocity_covariance = np.ones(9)
        assert_same(ours, ref, f"assigned#{i}")
    v3, quaternion = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    plain = T[msgtype](header=rand_header(rng), orientation=quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                       orientation_covariance=np.arange(9.0), angular_velocity=v3(x=1.0, y=2.0, z=3.0),
                       angular_velocity_covariance=np.zeros(9), linear_acceleration=v3(x=4.0, y=5.0, z=6.0),
                       linear_acceleration_covariance=np.ones(9))
    first, second = (cdr.decode(msgtype, serialize(plain, msgtype)) for _ in range(2))
    assert first == second and first.orientation_covariance == tuple(np.arange(9.0))
    first.orientation.w = 0.5
    assert first != second


def test_joint_states_with_repeated_and_changed_names_decode_like_rosbags():
    """JointState names equal to the previous message's bytes are taken as decoded before;
    any other names (one letter changed, another count, a longer frame) are parsed again."""
    rng = random.Random(5)
    msgtype = "sensor_msgs/msg/JointState"
    for i in range(200):
        names = rng.choice((["elevator", "aileron", "rudder"], ["elevator", "aileron", "ruddes"],
                            ["elevator", "aileron"], [], ["élevon"]))
        header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=i, nanosec=0),
                                          frame_id=rng.choice(("base_link", "base_lin", "b")))
        ref = T[msgtype](header=header, name=names, position=rand_floats(rng, len(names)),
                         velocity=np.zeros(0), effort=np.zeros(0))
        ours = cdr.decode(msgtype, serialize(ref, msgtype, little_endian=bool(i % 3)))
        assert_same(ours, ref, f"#{i}")
        ours.name.append("x")  # (each message its own list)
        assert_same(cdr.decode(msgtype, serialize(ref, msgtype, little_endian=bool(i % 3))), ref, f"#{i} again")
