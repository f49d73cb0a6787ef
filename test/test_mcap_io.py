"""MCAP files (rls_uncertainty/offline/mcap_io.py): what the package writes carries chunk, data and
summary CRCs that the mcap library and zlib agree on, reads back through rosbags as written,
and any damaged byte of it is refused with the damaged part named. No DDS."""

import struct

import pytest
from bag_samples import crcs
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from rls_uncertainty.datapath.cdr import encode_header
from rls_uncertainty.errors import BagError
from rls_uncertainty.offline import mcap_io
from rls_uncertainty.offline.bags import BagWriter, typestore, write_replay

HEADER = "std_msgs/msg/Header"


def _records(n=24):
    """``n`` header messages on /a and /b, stamps 10 ms apart, given out of order."""
    recs = [(10**18 + 10**7 * k, "/a" if k % 2 else "/b", HEADER, encode_header(10**9, k, f"f{k}")) for k in range(n)]
    return recs[::-1]


def write_mcap(path, records):
    """``records`` as one MCAP file at ``path``, through the package's writer (the one every
    bag, conversion and replay output goes through)."""
    with BagWriter(path, sorted({(topic, msgtype) for _, topic, msgtype, _ in records}), typestore()) as writer:
        for record in records:
            writer.add(*record)


@pytest.fixture
def small_chunks(monkeypatch):
    """Chunks of about 300 bytes: a small bag of several chunks."""
    monkeypatch.setattr(mcap_io, "CHUNK_SIZE", 300)


def test_written_files_carry_chunk_data_and_summary_crcs(tmp_path, small_chunks):
    write_mcap(tmp_path / "x.mcap", _records())
    chunk_crcs, data_crc, summary_crc = crcs(tmp_path / "x.mcap")
    assert len(chunk_crcs) > 2 and all(chunk_crcs) and data_crc and summary_crc
    mcap_io.check_mcap_integrity(tmp_path / "x.mcap")


def test_rosbags_reads_back_what_was_written_in_stamp_order(tmp_path, small_chunks):
    recs = _records()
    write_replay(tmp_path / "bag", recs)
    assert sorted(p.name for p in (tmp_path / "bag").iterdir()) == ["bag.mcap", "metadata.yaml"]
    want = sorted((t, topic, raw) for t, topic, _type, raw in recs)
    for source in (tmp_path / "bag", tmp_path / "bag" / "bag.mcap"):  # the directory, and the file alone
        with AnyReader([source], default_typestore=typestore()) as reader:
            got = [(t, c.topic, bytes(raw)) for c, t, raw in reader.messages()]
            assert {c.topic: c.msgcount for c in reader.connections} == {"/a": 12, "/b": 12}
            assert {c.msgtype for c in reader.connections} == {HEADER}
        assert got == want
    with open(tmp_path / "bag" / "bag.mcap", "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {(c.message_encoding, c.metadata["offered_qos_profiles"]) for c in summary.channels.values()} == {
            ("cdr", "[]")}
        assert [m.name for m in reader.iter_metadata()] == ["rosbag2"]


def test_every_bit_flip_of_a_written_bag_is_refused(tmp_path, small_chunks):
    """One flipped bit in each byte (bit = byte offset mod 8): header, chunks, message
    indexes, metadata, data end, summary, footer and both magics are all covered."""
    write_mcap(tmp_path / "x.mcap", _records(12))
    data = (tmp_path / "x.mcap").read_bytes()
    damaged = tmp_path / "damaged.mcap"
    passed = []
    for offset in range(len(data)):
        flipped = bytearray(data)
        flipped[offset] ^= 1 << (offset % 8)
        damaged.write_bytes(bytes(flipped))
        try:
            mcap_io.check_mcap_integrity(damaged)
        except BagError as exc:
            assert str(exc).startswith(f"{damaged}: ") and "\n" not in str(exc)
        else:
            passed.append(offset)
    assert passed == [], f"{len(passed)} of {len(data)} damaged copies passed, at bytes {passed[:20]}"


def test_a_damaged_chunk_is_named_by_number_offset_and_topics(tmp_path, small_chunks):
    write_mcap(tmp_path / "x.mcap", _records())
    data = bytearray((tmp_path / "x.mcap").read_bytes())
    with open(tmp_path / "x.mcap", "rb") as fh:
        index = make_reader(fh).get_summary().chunk_indexes
    second = index[1].chunk_start_offset
    data[second + index[1].chunk_length - 5] ^= 0x10  # inside the chunk's records
    (tmp_path / "x.mcap").write_bytes(bytes(data))
    with pytest.raises(BagError) as err:
        mcap_io.check_mcap_integrity(tmp_path / "x.mcap")
    assert str(err.value).startswith(f"{tmp_path / 'x.mcap'}: corrupt MCAP: chunk 2 of {len(index)} at byte "
                                     f"{second} (/a, /b) fails its CRC (stored ")


def test_a_chunk_header_that_disagrees_with_the_summary_is_named(tmp_path, small_chunks):
    write_mcap(tmp_path / "x.mcap", _records())
    data = bytearray((tmp_path / "x.mcap").read_bytes())
    with open(tmp_path / "x.mcap", "rb") as fh:
        first = make_reader(fh).get_summary().chunk_indexes[0]
    # The chunk record: opcode, length, then message_start_time (uint64).
    start = first.chunk_start_offset + 9
    data[start: start + 8] = struct.pack("<Q", first.message_start_time + 1)
    (tmp_path / "x.mcap").write_bytes(bytes(data))
    with pytest.raises(BagError, match=r"chunk 1 of \d+ at byte \d+ \(/[ab].*\): its start time \(\d+\) disagrees "
                                       r"with the summary's chunk index"):
        mcap_io.check_mcap_integrity(tmp_path / "x.mcap")


def test_files_of_writers_without_crcs_are_checked_as_far_as_they_go(tmp_path):
    """CRC 0 means "not computed" (the MCAP specification): such a file passes, and damage
    inside a chunk's payload goes unseen; its structure is still checked."""
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "other.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh, compression=CompressionType.NONE, enable_crcs=False)
        w.start(profile="ros2")
        channel = w.register_channel("/a", "cdr", w.register_schema(HEADER, "ros2msg", b"x"))
        for k in range(5):
            w.add_message(channel, log_time=k, data=encode_header(1, k, "payload"), publish_time=k)
        w.finish()
    mcap_io.check_mcap_integrity(path)
    data = path.read_bytes()
    at = data.index(b"payload")
    path.write_bytes(data[:at] + b"P" + data[at + 1:])
    mcap_io.check_mcap_integrity(path)
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError, match="no MCAP magic at its end"):
        mcap_io.check_mcap_integrity(path)


def test_the_writer_never_replaces_a_file_and_removes_an_unfinished_one(tmp_path):
    existing = tmp_path / "x.mcap"
    existing.write_bytes(b"precious")
    with pytest.raises(FileExistsError):
        write_mcap(existing, _records())
    assert existing.read_bytes() == b"precious"
    with pytest.raises(RuntimeError), mcap_io.McapWriter(tmp_path / "y.mcap", typestore()) as w:
        w.write(w.add_connection("/a", HEADER), 1, encode_header(0, 1, ""))
        raise RuntimeError("interrupted")
    assert not (tmp_path / "y.mcap").exists()


@pytest.mark.parametrize("checked", [True, False], ids=["checked-mcap-version", "other-mcap-version"])
def test_the_writer_writes_the_mcap_librarys_bytes(tmp_path, small_chunks, monkeypatch, checked):
    """Byte for byte what the mcap library's Writer.add_message writes with the same records, over
    many chunks, a channel registered after messages, and message data given as a memoryview:
    with the mcap version the packed records were checked against, and (through the library's
    add_message) with any other."""
    import yaml
    from mcap.writer import CompressionType, Writer

    if not checked:
        monkeypatch.setattr(mcap_io, "CHECKED_MCAP_VERSIONS", ("0.0.",))
    store = typestore()
    # (each payload padded to whole 4-byte words: some are given as a view of 4-byte items)
    recs = [(t, topic, msgtype, raw + bytes(-len(raw) % 4)) for t, topic, msgtype, raw in sorted(_records(60))]
    late = [(t + 1, "/late", HEADER, encode_header(10**9, k, "late")) for k, (t, *_rest) in enumerate(recs[30:])]
    ours = mcap_io.McapWriter(tmp_path / "ours.mcap", store)
    assert type(ours._chunk).__name__ == ("_Chunk" if checked else "_LibraryChunk")
    channels = {topic: ours.add_connection(topic, HEADER) for topic in ("/a", "/b", "/none")}
    for k, (t, topic, _type, raw) in enumerate(recs[:30]):
        ours.write(channels[topic], t, memoryview(raw).cast("I") if k % 2 else memoryview(raw))
    channels["/late"] = ours.add_connection("/late", HEADER)
    mixed = sorted(recs[30:] + late)
    for t, topic, _type, raw in mixed:
        ours.write(channels[topic], t, raw)
    info = ours.close()
    written = recs + late
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]} == {
        topic: sum(r[1] == topic for r in written) for topic in ("/a", "/b", "/none", "/late")}
    stamps = [r[0] for r in written]
    assert (info["message_count"], info["starting_time"]["nanoseconds_since_epoch"], info["duration"]["nanoseconds"]) \
        == (len(written), min(stamps), max(stamps) - min(stamps))

    with open(tmp_path / "library.mcap", "xb") as fh:
        writer = Writer(fh, chunk_size=300, compression=CompressionType.NONE, enable_crcs=True, enable_data_crcs=True)
        writer.start(profile="ros2", library=mcap_io.LIBRARY)
        schema = writer.register_schema(HEADER, "ros2msg", store.generate_msgdef(HEADER, ros_version=2)[0].encode())
        for topic in ("/a", "/b", "/none"):
            writer.register_channel(topic, "cdr", schema, {"offered_qos_profiles": "[]"})
        for t, topic, _type, raw in recs[:30]:
            writer.add_message(channels[topic], log_time=t, data=raw, publish_time=t)
        writer.register_channel("/late", "cdr", schema, {"offered_qos_profiles": "[]"})
        for t, topic, _type, raw in mixed:
            writer.add_message(channels[topic], log_time=t, data=raw, publish_time=t)
        writer.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(info, default_flow_style=False)})
        writer.finish()
    ours_bytes = (tmp_path / "ours.mcap").read_bytes()
    assert len(crcs(tmp_path / "ours.mcap")[0]) > 5  # several chunks
    assert ours_bytes == (tmp_path / "library.mcap").read_bytes()


def test_the_version_checked_is_that_of_the_mcap_library_imported(tmp_path, monkeypatch):
    """The packed records only with the version of the module the writer uses (not whatever
    package metadata is found first on the path, nor none at all)."""
    import importlib.metadata

    import mcap

    def unknown(name):
        raise importlib.metadata.PackageNotFoundError(name)

    with monkeypatch.context() as patched:
        patched.setattr(mcap, "__version__", "0.0.1")
        with mcap_io.McapWriter(tmp_path / "other.mcap", typestore()) as writer:
            assert type(writer._chunk).__name__ == "_LibraryChunk"
    monkeypatch.setattr(importlib.metadata, "version", unknown)
    with mcap_io.McapWriter(tmp_path / "no_metadata.mcap", typestore()) as writer:
        assert type(writer._chunk).__name__ == ("_Chunk" if mcap.__version__.startswith(mcap_io.CHECKED_MCAP_VERSIONS)
                                               else "_LibraryChunk")
        writer.write(writer.add_connection("/a", HEADER), 1, encode_header(0, 1, ""))
    assert crcs(tmp_path / "no_metadata.mcap")[0]  # written


def _walk_outcome(reader_type, data):
    """Every record a stream reader gives for ``data`` (message indexes by channel alone), then
    how it ended: what the integrity pass sees of a file."""
    import io

    from mcap.records import MessageIndex

    seen = []
    try:
        for record in reader_type(io.BytesIO(data), emit_chunks=True, validate_crcs=True,
                                  record_size_limit=len(data)).records:
            seen.append(("index", record.channel_id) if isinstance(record, MessageIndex) else repr(record))
    except Exception as exc:  # noqa: BLE001  (the outcome compared, whatever it is)
        seen.append((type(exc).__name__, str(exc)))
    return seen


def test_message_indexes_are_skipped_exactly_as_the_library_reads_them(tmp_path, small_chunks, monkeypatch):
    """The integrity pass reads message index records without decoding their entries: for any
    damage to one (its entries' length, the file cut inside it) the records read, the bytes
    consumed and the error are the library's; so is check_mcap_integrity's message."""
    import mcap
    from mcap.stream_reader import StreamReader

    write_mcap(tmp_path / "x.mcap", _records())
    data = (tmp_path / "x.mcap").read_bytes()
    if mcap.__version__.startswith(mcap_io.CHECKED_MCAP_VERSIONS):
        assert mcap_io._stream_reader() is not StreamReader
    starts, pos = [], 8  # the top-level records after the magic, up to the footer
    while data[pos] != 0x02:
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if data[pos] == 0x07:
            starts.append((pos, length))
        pos += 9 + length
    assert len(starts) > 4
    damaged = tmp_path / "damaged.mcap"
    cases = 0
    for at, length in starts[:3] + starts[-2:]:
        entries = at + 9 + 2  # the u32 byte length of the entries
        variants = [data[:cut] for cut in (at + 5, entries + 2, entries + 4, entries + 9, entries + 20,
                                           at + 9 + length - 3)]
        for value in (0, 1, 15, 16, 17, 31, length - 6, length - 5, length + 10, 2**32 - 16, 2**32 - 1):
            variants.append(data[:entries] + struct.pack("<I", value) + data[entries + 4:])
        for variant in variants:
            assert _walk_outcome(mcap_io._stream_reader(), variant) == _walk_outcome(StreamReader, variant)
            damaged.write_bytes(variant)
            outcomes = []
            for reader in (mcap_io._stream_reader(), StreamReader):
                monkeypatch.setattr(mcap_io, "_stream_reader", lambda reader=reader: reader)
                try:
                    mcap_io.check_mcap_integrity(damaged)
                    outcomes.append(None)
                except BagError as exc:
                    outcomes.append(str(exc))
                monkeypatch.undo()
                monkeypatch.setattr(mcap_io, "CHUNK_SIZE", 300)
            assert outcomes[0] == outcomes[1] and (outcomes[0] is None) == (variant == data)
            cases += 1
    assert cases == 5 * 17
