"""Bag I/O (rls_uncertainty/bags.py): the bundled T-2 bag, `convert` with the fti_msgs
mapping, reading replay bags, and every bad bag or mapping ending in a one-line error with
no output left behind. No DDS."""

import filecmp
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from bag_samples import SMALL_MAPPING, fails, fti_bag, read_all, write_mapping
from conftest import FLIGHT_DATA

from rls_uncertainty import cli
from rls_uncertainty.bags import _standard_message, convert, read_inputs, typestore, write_replay

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"
MAPPING = ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml"


def test_bundled_bag_is_what_make_bag_writes(tmp_path):
    assert cli.main(["make-bag", "--out", str(tmp_path / "t2_maneuver")]) == 0
    assert filecmp.cmp(tmp_path / "t2_maneuver" / "t2_maneuver.mcap", BUNDLED / "t2_maneuver.mcap", shallow=False)
    assert (BUNDLED / "t2_maneuver.mcap").stat().st_size < 2_000_000
    messages, _t0 = read_inputs(BUNDLED)
    counts = {}
    for kind, _stamp, _msg in messages:
        counts[kind] = counts.get(kind, 0) + 1
    # 12 s at realistic rates: IMU faster than air data and surfaces.
    assert counts == {"imu": 2400, "airspeed": 600, "dynamic_pressure": 600, "control_surfaces": 1200, "thrust": 120}


def test_bag_log_time_is_the_header_stamp_in_order(tmp_path):
    from rosbags.highlevel import AnyReader

    with AnyReader([BUNDLED], default_typestore=typestore()) as reader:
        last = -1
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            assert t == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert t >= last
            last = t


def test_convert_maps_the_fti_fields_and_is_byte_identical(tmp_path):
    src = FLIGHT_DATA / "totter_f1_017"
    a, b = tmp_path / "a", tmp_path / "b"
    convert(src, MAPPING, a)
    assert cli.main(["convert", str(src), "--mapping", str(MAPPING), "--out", str(b)]) == 0
    c = tmp_path / "c" / "a"
    convert(src, MAPPING, c)
    assert (a / "a.mcap").read_bytes() == (c / "a.mcap").read_bytes()
    original = read_all(src)
    replayed = read_all(a)
    air = original["/fcc/air_data"]
    vel = replayed["/airspeed"]
    assert len(vel) == len(air) == 1001
    for (t0, m0), (t1, m1) in zip(air[::97], vel[::97]):
        v = m1.vector
        assert t0 == t1
        assert math.hypot(v.x, v.y, v.z) == pytest.approx(m0.true_airspeed, rel=1e-12)
        # REP-103 to aircraft axes: (x, -y, -z); alpha = atan2(w, u), beta = asin(v / V).
        assert math.atan2(-v.z, v.x) == pytest.approx(m0.angle_of_attack, abs=1e-12)
        assert math.asin(-v.y / m0.true_airspeed) == pytest.approx(m0.angle_of_sideslip, abs=1e-12)
    for (_, m0), (_, m1) in zip(original["/fcc/thrust"][::101], replayed["/thrust"][::101]):
        assert m1.wrench.force.x == pytest.approx(float(np.sum(m0.thrust)))
    for (_, m0), (_, m1) in zip(original["/fcc/surfaces"][::101], replayed["/control_surfaces"][::101]):
        assert list(m1.name) == ["elevator", "aileron", "rudder"]
        assert list(m1.position) == [m0.elevator, m0.aileron, m0.rudder]
    for (_, m0), (_, m1) in zip(original["/fcc/imu"][::101], replayed["/imu"][::101]):
        for f in ("angular_velocity", "linear_acceleration"):
            a0, a1 = getattr(m0, f), getattr(m1, f)
            assert (a1.x, a1.y, a1.z) == (a0.x, a0.y, a0.z)


# ----------------------------------------------------------------------------- bad bags
def test_small_recording_converts(tmp_path):
    out = tmp_path / "out"
    counts = convert(fti_bag(tmp_path, "rec"), write_mapping(tmp_path), out)
    assert counts == {"/imu": 50, "/airspeed": 50}


def test_truncated_mcap_names_the_file_and_leaves_nothing(tmp_path, capsys):
    src = tmp_path / "cut.mcap"
    data = (FLIGHT_DATA / "totter_f1_017" / "totter_f1_017.mcap").read_bytes()
    src.write_bytes(data[: len(data) // 2])
    out = tmp_path / "out"
    fails(capsys, ["convert", str(src), "--mapping", str(MAPPING), "--out", str(out)], str(src))
    assert not out.exists() and not (tmp_path / "out.partial").exists()


def test_corrupt_chunk_names_the_file(tmp_path, capsys):
    data = bytearray((FLIGHT_DATA / "totter_f1_017" / "totter_f1_017.mcap").read_bytes())
    for k in range(len(data) // 3, len(data) // 3 + 4000):
        data[k] ^= 0x5A
    src = tmp_path / "corrupt.mcap"
    src.write_bytes(bytes(data))
    out = tmp_path / "out"
    fails(capsys, ["convert", str(src), "--mapping", str(MAPPING), "--out", str(out)], str(src))
    assert not out.exists()


def test_type_without_schema_is_named_and_schemas_dir_supplies_it(tmp_path, capsys):
    from mcap.writer import Writer

    src = tmp_path / "noschema.mcap"
    with open(src, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(name="acme_msgs/msg/Thing", encoding="ros2msg", data=b"")
        cid = w.register_channel(topic="/thing", message_encoding="cdr", schema_id=sid)
        w.add_message(channel_id=cid, log_time=1, publish_time=1, data=b"\x00\x01\x00\x00" + struct.pack("<d", 1.0))
        w.finish()
    mapping = write_mapping(tmp_path, {"imu": {"topic": "/thing"}, "airspeed": {"topic": "/thing"}})
    fails(capsys, ["convert", str(src), "--mapping", str(mapping), "--out", str(tmp_path / "o")],
           str(src), "/thing", "acme_msgs/msg/Thing", "no schema")
    schemas = tmp_path / "schemas" / "acme_msgs" / "msg"
    schemas.mkdir(parents=True)
    (schemas / "Thing.msg").write_text("float64 value\n")
    # With the schema the type is known: the error is no longer about a missing schema.
    err = fails(capsys, ["convert", str(src), "--mapping", str(mapping), "--out", str(tmp_path / "o"),
                          "--schemas", str(tmp_path / "schemas")], "/thing")
    assert "no schema" not in err


def test_mapping_with_missing_topic_or_field(tmp_path, capsys):
    src = fti_bag(tmp_path, "rec")
    spec = dict(SMALL_MAPPING, airspeed=dict(SMALL_MAPPING["airspeed"], topic="/fcc/adc"))
    fails(capsys, ["convert", str(src), "--mapping", str(write_mapping(tmp_path, spec)), "--out", str(tmp_path / "o")],
           str(src), "/fcc/adc", "not in the bag")
    spec = dict(SMALL_MAPPING, dynamic_pressure={"topic": "/fcc/air_data", "field": "qbar"})
    fails(capsys, ["convert", str(src), "--mapping", str(write_mapping(tmp_path, spec)), "--out", str(tmp_path / "o")],
           str(src), "/fcc/air_data", "'qbar'")
    spec = dict(SMALL_MAPPING, dynamic_pressure={"topic": "/fcc/air_data", "field": "dynamic_pressure", "units": "bar"})
    fails(capsys, ["convert", str(src), "--mapping", str(write_mapping(tmp_path, spec)), "--out", str(tmp_path / "o")],
           "unknown unit 'bar'")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("problem,stamps", [
    ("non-monotonic", [10**18 + k * 10**7 for k in (0, 1, 2, 4, 3, 5)]),
    ("duplicate", [10**18 + k * 10**7 for k in (0, 1, 2, 2, 3, 4)]),
])
def test_bad_stamps_are_refused_by_convert_and_replay(tmp_path, capsys, problem, stamps):
    src = fti_bag(tmp_path, "rec", imu_stamps_ns=stamps)
    fails(capsys, ["convert", str(src), "--mapping", str(write_mapping(tmp_path)), "--out", str(tmp_path / "o")],
           str(src), "/fcc/imu", problem)
    assert not (tmp_path / "o").exists()
    # A replay bag with the same problem (written on the standard topics without checks).
    store = typestore()
    bad = tmp_path / "replay"
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(bad, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        for k, s in enumerate(stamps):
            w.write(conn, 10**18 + k * 10**6, store.serialize_cdr(_standard_message(store, "imu", s, (0, 0, 0, 0, 0, 9.8)),
                                                 "sensor_msgs/msg/Imu"))
    fails(capsys, ["replay", str(bad), "--out", str(tmp_path / "r"), "--quiet"], str(bad), "/imu", problem)
    assert not (tmp_path / "r").exists()


def test_empty_bag_is_an_error(tmp_path, capsys):
    src = fti_bag(tmp_path, "empty", empty=True)
    fails(capsys, ["convert", str(src), "--mapping", str(write_mapping(tmp_path)), "--out", str(tmp_path / "o")],
           str(src), "no messages")
    fails(capsys, ["replay", str(src), "--out", str(tmp_path / "r"), "--quiet"], str(src))
    assert not (tmp_path / "o").exists() and not (tmp_path / "r").exists()


def test_write_replay_orders_by_stamp_with_a_stable_tie_break(tmp_path):
    store = typestore()
    recs = [(s, "/imu", "sensor_msgs/msg/Imu", _standard_message(store, "imu", s, (k, 0, 0, 0, 0, 9.8)))
            for k, s in enumerate([30, 10, 20, 10])]
    recs.append((10, "/airspeed", "geometry_msgs/msg/Vector3Stamped",
                 _standard_message(store, "airspeed", 10, (1, 0, 0))))
    write_replay(tmp_path / "o", recs, store)
    got = [(t, topic, m.angular_velocity.x if topic == "/imu" else None)
           for topic, ms in read_all(tmp_path / "o").items() for t, m in ms]
    imu = [g for g in got if g[1] == "/imu"]
    assert [(t, x) for t, _, x in imu] == [(10, 1.0), (10, 3.0), (20, 2.0), (30, 0.0)]


def _recorded_messages(store, n=60):
    """Imu and fti_msgs/AirData messages of a small recording, built with ``store``'s types."""
    T = store.types
    out = []
    for k in range(n):
        s = 10**18 + k * 20 * 10**6
        stamp = T["builtin_interfaces/msg/Time"](sec=s // 10**9, nanosec=s % 10**9)
        hdr_kw = {"stamp": stamp, "frame_id": "base_link"}
        if "seq" in [f[0] for f in store.fielddefs["std_msgs/msg/Header"][1]]:
            hdr_kw["seq"] = k
        hdr = T["std_msgs/msg/Header"](**hdr_kw)
        vec = T["geometry_msgs/msg/Vector3"]
        imu = T["sensor_msgs/msg/Imu"](
            header=hdr, orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9), angular_velocity=vec(x=0.0, y=0.01 * k, z=0.0),
            angular_velocity_covariance=np.zeros(9), linear_acceleration=vec(x=0.0, y=0.0, z=9.8),
            linear_acceleration_covariance=np.zeros(9))
        air = T["fti_msgs/msg/AirData"](header=hdr, true_airspeed=50.0, angle_of_attack=0.001 * k,
                                        angle_of_sideslip=0.0, dynamic_pressure=1500.0, air_density=1.2, mach=0.15)
        out += [(s, "/fcc/imu", "sensor_msgs/msg/Imu", imu), (s, "/fcc/air_data", "fti_msgs/msg/AirData", air)]
    return out


def test_convert_reads_sqlite3_and_ros1_bags(tmp_path):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    fti = (ROOT / "msg_schemas" / "fti_msgs" / "msg" / "AirData.msg").read_text()
    # ROS 2 sqlite3 storage.
    store2 = typestore()
    sqlite_bag = tmp_path / "sqlite_bag"
    with Writer(sqlite_bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns = {}
        for s, topic, msgtype, msg in _recorded_messages(store2):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=store2)
            w.write(conns[topic], s, store2.serialize_cdr(msg, msgtype))
    # ROS 1 bag with its own (noetic) types and the fti schema.
    store1 = get_typestore(Stores.ROS1_NOETIC)
    store1.register(get_types_from_msg(fti, "fti_msgs/msg/AirData"))
    ros1_bag = tmp_path / "flight.bag"
    with Writer1(ros1_bag) as w:
        conns = {}
        for s, topic, msgtype, msg in _recorded_messages(store1):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=store1)
            w.write(conns[topic], s, store1.serialize_ros1(msg, msgtype))
    mapping = write_mapping(tmp_path)
    results = []
    for src in (sqlite_bag, ros1_bag):
        out = tmp_path / f"out_{src.stem}"
        assert convert(src, mapping, out) == {"/imu": 60, "/airspeed": 60}
        results.append(read_all(out))
    for r in results:
        alphas = [math.atan2(-m.vector.z, m.vector.x) for _t, m in r["/airspeed"]]
        np.testing.assert_allclose(alphas, 0.001 * np.arange(60), atol=1e-12)
        assert [m.angular_velocity.y for _t, m in r["/imu"]] == [0.01 * k for k in range(60)]
