"""Small bags and mapping files for the bag-tool tests, the CLI's one-line-error check, a
directory snapshot, an MCAP file's CRCs checked against zlib, and a guard against a call that
blocks."""

import copy
import os
import signal
import zlib
from contextlib import contextmanager
from pathlib import Path

import yaml

from rls_uncertainty import cli
from rls_uncertainty.offline.bags import _standard_message, typestore


def read_all(path):
    from rosbags.highlevel import AnyReader

    out = {}
    with AnyReader([Path(path)], default_typestore=typestore()) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    return out


def fti_bag(tmp_path, name, *, imu_stamps_ns=None, n=50, empty=False):
    """A small recording with fti_msgs types, optionally with bad IMU stamps."""
    store = typestore()
    T = store.types
    records = []
    stamps = imu_stamps_ns if imu_stamps_ns is not None else [10**18 + k * 20 * 10**6 for k in range(n)]
    for k, s in enumerate(stamps):
        records.append((s, "/fcc/imu", "sensor_msgs/msg/Imu",
                        _standard_message(store, "imu", s, (0.0, 0.01 * k, 0.0, 0.0, 0.0, 9.8))))
        hdr = _standard_message(store, "airspeed", s, (1.0, 0.0, 0.0)).header
        records.append((s, "/fcc/air_data", "fti_msgs/msg/AirData", T["fti_msgs/msg/AirData"](
            header=hdr, true_airspeed=50.0, angle_of_attack=0.05, angle_of_sideslip=0.0,
            dynamic_pressure=1500.0, air_density=1.2, mach=0.15)))
    path = tmp_path / name
    if empty:
        from rosbags.rosbag2 import StoragePlugin, Writer

        with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            w.add_connection("/fcc/imu", "sensor_msgs/msg/Imu", typestore=store)
            w.add_connection("/fcc/air_data", "fti_msgs/msg/AirData", typestore=store)
        return path
    # Like a recorder: log time is the arrival order, header stamps are what the sensor said.
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for k, (_stamp, topic, msgtype, msg) in enumerate(records):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=store)
            w.write(conns[topic], 10**18 + k * 10**6, store.serialize_cdr(msg, msgtype))
    return path


SMALL_MAPPING = {
    "imu": {"topic": "/fcc/imu"},
    "airspeed": {"topic": "/fcc/air_data", "frame": "aircraft",
                 "polar": {"speed": "true_airspeed", "alpha": "angle_of_attack", "beta": "angle_of_sideslip"}},
}


def write_mapping(tmp_path, spec=None):
    path = tmp_path / "mapping.yaml"
    path.write_text(yaml.safe_dump(spec or SMALL_MAPPING))
    return path


def fails(capsys, args, *needles):
    """Run the command: it must end with exit status 2 and one line on stderr, the command's
    own error line (no traceback, no usage text), containing every needle."""
    try:
        code = cli.main(args)
    except SystemExit as exc:  # argparse's usage errors
        code = exc.code
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert code == 2, captured
    assert len(lines) == 1 and lines[0].startswith(f"rls-uncertainty {args[0]}: error: "), captured.err
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def tree(root: Path) -> dict:
    """Every entry under ``root``, not following symlinks: relative path -> file bytes,
    ``"dir"`` or ``("link", target)``; compares a directory before and after a command."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            rel = str(p.relative_to(root))
            if p.is_symlink():
                out[rel] = ("link", os.readlink(p))
            elif p.is_dir():
                out[rel] = "dir"
            else:
                out[rel] = p.read_bytes()
    return out


def crcs(path):
    """Every CRC of an MCAP file, each checked against zlib over the bytes it covers:
    ``(chunk CRCs, data section CRC, summary CRC)``; asserts that each is valid."""
    from mcap.records import Chunk, DataEnd, Footer
    from mcap.stream_reader import StreamReader, get_chunk_data_stream

    data = Path(path).read_bytes()
    chunk_crcs, data_crc, summary_crc = [], None, None
    with open(path, "rb") as fh:
        for record in StreamReader(fh, emit_chunks=True, validate_crcs=True).records:
            if isinstance(record, Chunk):
                stream, size = get_chunk_data_stream(record)
                assert zlib.crc32(stream.read(size)) == record.uncompressed_crc
                chunk_crcs.append(record.uncompressed_crc)
            elif isinstance(record, DataEnd):
                data_crc = record.data_section_crc
            elif isinstance(record, Footer):
                summary_crc = record.summary_crc
                start = record.summary_start
    assert zlib.crc32(data[: start - 13]) == data_crc  # the data section: up to its DataEnd record
    assert zlib.crc32(data[start: len(data) - 8 - 4]) == summary_crc  # summary and footer up to its CRC
    return chunk_crcs, data_crc, summary_crc


@contextmanager
def no_hang(seconds: float):
    """Turn a call that blocks for more than ``seconds`` into a TimeoutError (SIGALRM: main
    thread only), so a regression that blocks fails the test instead of hanging the run."""

    def expired(_signum, _frame):
        raise TimeoutError(f"blocked for more than {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def changed_messages(messages, kind, change):
    """``(kind, stamp, msg)`` messages with ``change(k, copy)`` applied to a copy of the k-th
    message of ``kind`` (it returns False to keep the original): hostile inputs made from a
    real recording."""
    out, k = [], 0
    for msg_kind, stamp, msg in messages:
        chosen = msg
        if msg_kind == kind:
            new = copy.deepcopy(msg)
            if change(k, new) is not False:
                chosen = new
            k += 1
        out.append((msg_kind, stamp, chosen))
    return out
