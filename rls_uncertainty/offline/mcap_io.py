"""MCAP files: the ones the package writes carry CRCs, and every one it reads is checked.

**Writing** (:class:`McapWriter`). The ``mcap`` library's writer (the format's reference
implementation) in rosbag2's layout: profile ``ros2``, one ``ros2msg`` schema per message type
(the typestore's definition), one ``cdr`` channel per topic with its ``offered_qos_profiles``,
messages in chunks of about 1 MiB, uncompressed (the message records and their indexes
packed here, each at once, into the library's chunk with the mcap versions in
:data:`CHECKED_MCAP_VERSIONS`, through its ``add_message`` with any other: its bytes either way),
and a ``rosbag2`` metadata record. Three
CRC-32s cover every byte but the two magics: each chunk's records (``uncompressed_crc``), the
whole data section (``DataEnd.data_section_crc``: the chunk headers, the message indexes, the
metadata) and the summary with the footer (``Footer.summary_crc``). For a bag directory,
:func:`write_metadata` writes the rosbag2 ``metadata.yaml`` (version 9) that rosbags and
``ros2 bag`` read. (rosbags' own MCAP writer writes every CRC as 0, "not computed".)

**Checking** (:func:`check_mcap_integrity`), before any reader trusts a file: the footer and
the summary (its CRC when it has one), then every record in one pass that holds one chunk at
a time: each chunk's CRC, its header against the summary's chunk index, the data section's
CRC, and the number of messages against the summary's statistics. A CRC of 0 means "not
computed" (the MCAP specification) and is not checked: files of other writers pass as far as
their CRCs go. A problem is one :class:`.errors.BagError` line naming the file and the part
that is damaged: a chunk by its number, byte offset and the topics it holds.
"""

from __future__ import annotations

import functools
import io
import struct
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from ..errors import BagError
from ..files import OutputWriter

if TYPE_CHECKING:  # annotations only: the mcap library is imported where it is used
    from mcap._chunk_builder import ChunkBuilder
    from mcap.data_stream import RecordBuilder
    from mcap.records import Chunk, ChunkIndex, MessageIndex, Statistics
    from mcap.summary import Summary
    from mcap.writer import Writer
    from rosbags.typesys.store import Typestore

__all__ = ["McapWriter", "write_metadata", "check_mcap_integrity", "CHUNK_SIZE", "LIBRARY"]

CHUNK_SIZE = 1 << 20  # bytes of records per chunk (as rosbag2 and rosbags write)
LIBRARY = "rls_uncertainty"  # the header's library field: no version, so a file does not change with one
ROS_DISTRO = "jazzy"  # the typestore the definitions and their hashes come from (bags.typestore)
_MAGIC = b"\x89MCAP0\r\n"
_FOOTER = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset_start, summary_crc
_DATA_END = 1 + 8 + 4  # opcode, length, data_section_crc
_RECORD_HEADER = struct.Struct("<BQ")  # a record's opcode and length
_MESSAGE = struct.Struct("<BQHIQQ")  # a Message record up to its data: opcode, length, channel, sequence, times
_OFFERED_QOS = "[]"  # rosbag2 version 9: the offered QoS profiles as YAML (none recorded)


class McapWriter(OutputWriter):
    """One MCAP file written as messages come, with CRCs (see the module docstring).

    ``path`` is created exclusively (an existing file is never replaced). Register a topic with
    :meth:`add_connection`, write serialized messages with :meth:`write`, and :meth:`close`
    (or leave the ``with`` block) to write the summary; :attr:`info` is then the rosbag2
    bag-file information, for :func:`write_metadata`. On an exception inside the block the
    file is closed and removed."""

    def __init__(self, path: str | Path, store: Typestore) -> None:
        from mcap.writer import CompressionType, Writer  # noqa: PLC0415 - the bag library only for bags

        self.path = Path(path)
        self._store = store
        self._fh: IO[bytes] = open(self.path, "xb")  # noqa: SIM115 - closed in close() or abort()
        self._writer = Writer(self._fh, chunk_size=CHUNK_SIZE, compression=CompressionType.NONE,
                              enable_crcs=True, enable_data_crcs=True)
        self._writer.start(profile="ros2", library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._topics: list[tuple[str, str, int]] = []  # (topic, type, channel), in registration order
        self.info: dict[str, Any] | None = None
        self._chunk: _Chunk | _LibraryChunk = _chunk(self._writer)

    def add_connection(self, topic: str, msgtype: str) -> int:
        """Register ``topic`` of ``msgtype`` (its schema once per type); the channel id."""
        self._chunk.hand_over()  # (the library writes the records of a registration into the chunk)
        schema = self._schemas.get(msgtype)
        if schema is None:
            text, _ = self._store.generate_msgdef(msgtype, ros_version=2)
            encoding = "ros2idl" if text.startswith("=" * 80 + "\nIDL: ") else "ros2msg"
            schema = self._schemas[msgtype] = self._writer.register_schema(msgtype, encoding, text.encode())
        channel: int = self._writer.register_channel(topic, "cdr", schema, {"offered_qos_profiles": _OFFERED_QOS})
        self._topics.append((topic, msgtype, channel))
        self._chunk.restart()  # (the messages that follow come after the channel record)
        return channel

    def write(self, channel: int, log_time: int, raw: bytes | memoryview) -> None:
        """One serialized message of ``channel`` logged (and published) at ``log_time`` ns."""
        self._chunk.add(channel, log_time, raw)

    def _information(self) -> dict[str, Any]:
        """rosbag2's bag-file information (version 9) of what was written (the library's
        statistics, every message handed over)."""
        self._chunk.hand_over()
        stats = self._chunk.statistics
        count = stats.message_count
        start = stats.message_start_time if count else 0
        span = stats.message_end_time - start if count else 0
        counts = stats.channel_message_counts  # (a defaultdict the summary writes: only read with get)
        return {
            "version": 9,
            "storage_identifier": "mcap",
            "relative_file_paths": [self.path.name],
            "duration": {"nanoseconds": span},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {"topic_metadata": {"name": topic, "type": msgtype, "serialization_format": "cdr",
                                    "offered_qos_profiles": [],
                                    "type_description_hash": self._store.hash_rihs01(msgtype)},
                 "message_count": counts.get(channel, 0)}
                for topic, msgtype, channel in self._topics
            ],
            "compression_format": "",
            "compression_mode": "",
            "files": [{"path": self.path.name, "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": span}, "message_count": count}],
            "custom_data": None,
            "ros_distro": ROS_DISTRO,
        }

    def close(self) -> dict[str, Any]:
        """Write the metadata record, the summary and the footer; close the file."""
        import yaml  # noqa: PLC0415

        info = self._information()  # (the library writes the last chunk after the metadata)
        self._writer.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(info, default_flow_style=False)})
        self._writer.finish()
        self._fh.close()
        self.info = info
        return info

    def abort(self) -> None:
        """Close and remove the unfinished file."""
        self._fh.close()
        self.path.unlink(missing_ok=True)


#: The ``mcap`` versions whose private chunk builder and statistics :class:`_Chunk` was checked
#: against (``test_mcap_io``: byte for byte the library's ``add_message``); any other version
#: writes through the library's public ``add_message`` (:class:`_LibraryChunk`), slower.
CHECKED_MCAP_VERSIONS = ("1.6.",)


def _checked_mcap() -> bool:
    """Whether the ``mcap`` module imported (its own version, whatever package metadata the path
    holds) is one of :data:`CHECKED_MCAP_VERSIONS`."""
    import mcap  # noqa: PLC0415

    return str(getattr(mcap, "__version__", "")).startswith(CHECKED_MCAP_VERSIONS)


def _chunk(writer: Writer) -> _Chunk | _LibraryChunk:
    """The message writer for ``writer``: records packed at once with a checked ``mcap``
    version (the imported module's own, whatever package metadata the path holds), the
    library's ``add_message`` otherwise."""
    if _checked_mcap() and hasattr(writer, "_Writer__chunk_builder") and hasattr(writer, "_Writer__statistics"):
        return _Chunk(writer)
    return _LibraryChunk(writer)


class _LibraryStatistics:
    """What :meth:`McapWriter._information` reads of the library's statistics, counted here."""

    def __init__(self) -> None:
        self.message_count = self.message_start_time = self.message_end_time = 0
        self.channel_message_counts: dict[int, int] = {}


class _LibraryChunk:
    """:class:`_Chunk`'s interface over the library's public ``Writer.add_message`` (one record
    object and several writes per message)."""

    def __init__(self, writer: Writer) -> None:
        self._writer = writer
        self.statistics = _LibraryStatistics()

    def restart(self) -> None:
        """(Nothing held here.)"""

    def hand_over(self) -> None:
        """(Every message is the library's as soon as it is added.)"""

    def add(self, channel: int, log_time: int, raw: bytes | memoryview) -> None:
        """One message record, logged and published at ``log_time``."""
        self._writer.add_message(channel, log_time=log_time, data=bytes(raw), publish_time=log_time)
        stats = self.statistics
        counts = stats.channel_message_counts
        counts[channel] = counts.get(channel, 0) + 1
        if stats.message_count:
            stats.message_start_time = min(stats.message_start_time, log_time)
            stats.message_end_time = max(stats.message_end_time, log_time)
        else:
            stats.message_start_time = stats.message_end_time = log_time
        stats.message_count += 1


class _Chunk:
    """The messages of the chunk being built, as the ``mcap`` library's ``Writer.add_message``
    builds them, without its per-message record objects: each message record (opcode, length,
    channel, sequence 0, log and publish time, data) is packed at once into one buffer, and
    the message index kept per channel in the order of the channels' first messages.
    :meth:`hand_over` gives them to the library's chunk builder and statistics, which write
    the chunk, its message indexes and the summary themselves: the file is byte for byte the
    library's (``test_mcap_io`` compares them)."""

    def __init__(self, writer: Writer) -> None:
        # The library's chunk builder and statistics (its Writer keeps them private).
        self._builder: ChunkBuilder = writer._Writer__chunk_builder  # type: ignore[attr-defined]
        self.statistics: Statistics = writer._Writer__statistics  # type: ignore[attr-defined]
        self._writer = writer
        self.restart()

    def restart(self) -> None:
        """No message yet, after what the library's chunk builder holds (a registration's records)."""
        self._buffer = bytearray()
        self._base = self._builder.count  # where the buffer starts in the chunk's records
        self._index: dict[int, list[tuple[int, int]]] = {}
        self._first = self._last = self._count = 0

    def add(self, channel: int, log_time: int, raw: bytes | memoryview) -> None:
        """One message record (``Writer.add_message`` with ``publish_time = log_time``); the chunk
        is written once its records pass :data:`CHUNK_SIZE` bytes, as the library does."""
        buffer = self._buffer
        index = self._index.get(channel)
        if index is None:
            index = self._index[channel] = []
        index.append((log_time, self._base + len(buffer)))
        size = raw.nbytes if type(raw) is memoryview else len(raw)  # (a view's len counts its items)
        buffer += _MESSAGE.pack(0x05, 22 + size, channel, 0, log_time, log_time)  # 0x05: Message
        buffer += raw
        self._first = min(self._first, log_time) if self._count else log_time
        self._last = max(self._last, log_time)
        self._count += 1
        if self._base + len(buffer) > CHUNK_SIZE:
            self.hand_over()
            self._writer.flush()  # the chunk and its message indexes, as add_message writes them
            self.restart()

    def hand_over(self) -> None:
        """The buffered messages into the library's chunk builder and statistics (still unwritten)."""
        if not self._count:
            return
        builder, stats, count = self._builder, self.statistics, self._count
        builder.record_writer.write(self._buffer)
        first = min(builder.message_start_time, self._first) if builder.num_messages else self._first
        builder.message_start_time, builder.message_end_time = first, max(builder.message_end_time, self._last)
        builder.num_messages += count
        index_type = _message_index()
        for channel, records in self._index.items():
            index = builder.message_indices.get(channel)
            if index is None:
                builder.message_indices[channel] = index_type(channel, records)
            else:
                index.records += records
            stats.channel_message_counts[channel] += len(records)
        stats.message_start_time = min(stats.message_start_time, self._first) if stats.message_count else self._first
        stats.message_end_time = max(stats.message_end_time, self._last)
        stats.message_count += count
        self.restart()


@functools.cache
def _message_index() -> type[MessageIndex]:
    """The library's message index record, written with one ``struct.pack`` (it packs each
    entry's two fields apart): the same bytes."""
    from mcap.records import MessageIndex  # noqa: PLC0415

    class PackedMessageIndex(MessageIndex):
        def write(self, stream: RecordBuilder) -> None:
            n = len(self.records)
            entries = [value for record in self.records for value in record]  # (log time, offset) each
            # 0x07: MessageIndex; its length, the channel, the entries' bytes, the entries.
            stream.write(struct.pack(f"<BQHI{2 * n}Q", 0x07, 6 + 16 * n, self.channel_id, 16 * n, *entries))

    return PackedMessageIndex


def write_metadata(directory: Path, info: Mapping[str, Any]) -> None:
    """The rosbag2 ``metadata.yaml`` of a bag directory holding one file (:attr:`McapWriter.info`)."""
    import yaml  # noqa: PLC0415

    text = yaml.safe_dump({"rosbag2_bagfile_information": dict(info)}, default_flow_style=False)
    with open(directory / "metadata.yaml", "x", encoding="utf-8") as fh:
        fh.write(text)


# ------------------------------------------------------------------------------ checking
def _footer(fh: IO[bytes], size: int, path: Path) -> tuple[int, int, int]:
    """``(summary_start, summary_offset_start, summary_crc)`` after both magics are checked."""
    fh.seek(0)
    if size < 2 * len(_MAGIC) + _FOOTER or fh.read(len(_MAGIC)) != _MAGIC:
        raise BagError(f"{path}: not an MCAP file (no MCAP magic at its start)")
    fh.seek(size - len(_MAGIC) - _FOOTER)
    tail = fh.read(_FOOTER + len(_MAGIC))
    if tail[_FOOTER:] != _MAGIC:
        raise BagError(f"{path}: corrupt or truncated MCAP: no MCAP magic at its end")
    opcode, length, start, offsets, crc = struct.unpack("<BQQQI", tail[:_FOOTER])
    if opcode != 0x02 or length != _FOOTER - 9:
        raise BagError(f"{path}: corrupt MCAP: the footer record is damaged")
    return start, offsets, crc


def _check_summary(fh: IO[bytes], size: int, path: Path) -> int:
    """The summary section's start, its CRC checked (when the writer computed one)."""
    start, _offsets, crc = _footer(fh, size, path)
    footer = size - len(_MAGIC) - _FOOTER
    if start == 0:
        raise BagError(f"{path}: MCAP file has no summary (truncated or still being written)")
    if not len(_MAGIC) <= start <= footer:
        raise BagError(f"{path}: corrupt MCAP: the footer points its summary outside the file")
    fh.seek(start - _DATA_END)
    if start < len(_MAGIC) + _DATA_END or fh.read(9) != struct.pack("<BQ", 0x0F, 4):
        # The data section ends with its DataEnd record (which holds the data section's CRC),
        # right before the summary: a reader that skipped a damaged one would check no CRC.
        raise BagError(f"{path}: corrupt MCAP: no data end record right before the summary (byte {start})")
    if crc:
        fh.seek(start)
        computed = zlib.crc32(fh.read(footer + _FOOTER - 4 - start))  # up to the footer's CRC field
        if computed != crc:
            raise BagError(f"{path}: corrupt MCAP: the summary (bytes {start} to {footer + _FOOTER}: chunk "
                           f"indexes, statistics) fails its CRC (stored {crc:08x}, computed {computed:08x})")
    return start


def _chunk_name(i: int, summary: Summary) -> str:
    """``chunk I of N at byte OFFSET (topics)`` from the summary's chunk index."""
    n = len(summary.chunk_indexes)
    if i >= n:
        return f"chunk {i + 1} (the summary lists {n})"
    index = summary.chunk_indexes[i]
    topics = sorted(summary.channels[c].topic for c in index.message_index_offsets if c in summary.channels)
    return f"chunk {i + 1} of {n} at byte {index.chunk_start_offset} ({', '.join(topics) or 'no messages'})"


def _chunk_header_problem(chunk: Chunk, index: ChunkIndex) -> str | None:
    """The first field of a chunk's header that disagrees with its index in the summary."""
    for field, found, listed in (
        ("start time", chunk.message_start_time, index.message_start_time),
        ("end time", chunk.message_end_time, index.message_end_time),
        ("uncompressed size", chunk.uncompressed_size, index.uncompressed_size),
        ("compression", chunk.compression, index.compression),
        ("size", len(chunk.data), index.compressed_size),
    ):
        if found != listed:
            return f"its {field} ({found}) disagrees with the summary's chunk index ({listed})"
    return None


def _count_chunk(chunk: Chunk, path: Path, name: str) -> int:
    """The messages in a chunk, its CRC checked; its records walked without decoding them."""
    from mcap.data_stream import ReadDataStream  # noqa: PLC0415
    from mcap.stream_reader import CRCValidationError, get_chunk_data_stream  # noqa: PLC0415

    try:
        stream, size = get_chunk_data_stream(chunk, validate_crc=True)
    except CRCValidationError as exc:
        raise BagError(f"{path}: corrupt MCAP: {name} fails its CRC (stored {exc.expected:08x}, computed "
                       f"{exc.actual:08x})") from None
    data = stream.read(size)  # (the whole chunk, once: its records are walked in place)
    count = pos = 0
    header = _RECORD_HEADER.unpack_from
    while pos + _RECORD_HEADER.size <= size:
        opcode, length = header(data, pos)
        pos += _RECORD_HEADER.size
        if pos + length > size:
            raise BagError(f"{path}: corrupt MCAP: {name}: a record runs past the chunk's end")
        pos += length
        count += opcode == 0x05  # MCAP "Message" record
    if pos < size:  # a record header cut short: the library's reader fails on it as on any other
        tail = ReadDataStream(io.BytesIO(data[pos:]))
        tail.read1()
        tail.read8()
    return count


def _skip_index(stream: Any, length: int) -> MessageIndex:
    """A message index record read as the ``mcap`` library's ``MessageIndex.read`` reads it (its
    channel id, the byte length of its entries, then the entries 16 bytes at a time up to that
    length), the same bytes consumed, CRC'd and failing the same way, but its entries left
    undecoded (the integrity pass never uses them): one read when they lie within the record."""
    from mcap.exceptions import EndOfFile  # noqa: PLC0415
    from mcap.records import MessageIndex  # noqa: PLC0415

    channel_id = stream.read2()
    records_length = stream.read4()
    whole = -(-records_length // 16) * 16  # what the library's loop reads: whole entries
    if whole > length - 6:  # damaged: the library's loop itself, 8 bytes at a time
        records_end = stream.count + records_length
        while stream.count < records_end:
            stream.read8()
            stream.read8()
    elif whole:
        got = len(stream.read(whole))  # (nothing read: EndOfFile, as the loop's first read)
        if got < whole:  # the file ends inside: what the loop's first short read raises
            if got % 8:
                raise struct.error("unpack requires a buffer of 8 bytes")
            raise EndOfFile()
    return MessageIndex(channel_id, [])


@functools.cache
def _stream_reader() -> type:
    """The ``mcap`` library's ``StreamReader``; with a version in :data:`CHECKED_MCAP_VERSIONS`,
    one that reads message index records with :func:`_skip_index` (the library's parser
    decodes each entry in Python)."""
    from mcap.opcode import Opcode  # noqa: PLC0415
    from mcap.stream_reader import StreamReader  # noqa: PLC0415

    if not (_checked_mcap() and hasattr(StreamReader, "_read_record")):
        return StreamReader

    class _Reader(StreamReader):
        def _read_record(self, opcode: int, length: int) -> Any:
            if opcode == Opcode.MESSAGE_INDEX:
                return _skip_index(self._stream, length)
            return super()._read_record(opcode, length)

    return _Reader


def _walk(fh: IO[bytes], size: int, path: Path, summary: Summary) -> int:
    """One pass over every record: chunks checked, the data section's CRC checked; the number
    of messages. No record is read beyond the file's ``size`` (a damaged length is refused
    before anything is allocated for it)."""
    from mcap.records import Chunk, DataEnd, Message  # noqa: PLC0415
    from mcap.stream_reader import CRCValidationError  # noqa: PLC0415

    chunks = count = 0
    data_end = False
    fh.seek(0)
    try:
        for record in _stream_reader()(fh, emit_chunks=True, validate_crcs=True, record_size_limit=size).records:
            if isinstance(record, Message):
                count += 1
            elif isinstance(record, Chunk):
                name = _chunk_name(chunks, summary)
                if chunks < len(summary.chunk_indexes):  # the header first: its sizes are used next
                    problem = _chunk_header_problem(record, summary.chunk_indexes[chunks])
                    if problem:
                        raise BagError(f"{path}: corrupt MCAP: {name}: {problem}")
                count += _count_chunk(record, path, name)
                chunks += 1
            elif isinstance(record, DataEnd):
                data_end = True
    except CRCValidationError as exc:
        if isinstance(exc.record, DataEnd):
            raise BagError(f"{path}: corrupt MCAP: the data section fails its CRC (stored {exc.expected:08x}, "
                           f"computed {exc.actual:08x}) while every chunk passes its own: the damage is outside "
                           "the messages (a message index, a chunk's record header, the header or metadata "
                           "record)") from None
        raise BagError(f"{path}: corrupt MCAP: {exc}") from None
    except BagError:
        raise
    except Exception as exc:  # the mcap library raises many types
        after = f" (after {_chunk_name(chunks - 1, summary)})" if chunks else ""
        raise BagError(f"{path}: corrupt or truncated MCAP{after}: {type(exc).__name__}: {exc}") from exc
    if not data_end:
        raise BagError(f"{path}: corrupt MCAP: no data end record (its CRC could not be checked)")
    return count


def check_mcap_integrity(path: str | Path) -> None:
    """Check an MCAP file before it is read (see the module docstring): every CRC the writer
    computed, each chunk's header against the summary and the number of messages. Raises
    :class:`.errors.BagError` naming the file and the damaged part (a chunk: its number, byte
    offset and topics); reads one chunk at a time."""
    from mcap.reader import make_reader  # noqa: PLC0415

    path = Path(path)
    try:
        with open(path, "rb") as fh:
            size = fh.seek(0, 2)
            _check_summary(fh, size, path)
            fh.seek(0)
            try:
                summary = make_reader(fh).get_summary()
            except Exception as exc:  # the mcap library raises many types
                raise BagError(f"{path}: corrupt MCAP: the summary cannot be read: {exc}") from exc
            if summary is None or summary.statistics is None:
                raise BagError(f"{path}: MCAP file has no summary (truncated or still being written)")
            count = _walk(fh, size, path, summary)
    except OSError as exc:
        raise BagError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    expected = summary.statistics.message_count
    if count != expected:
        raise BagError(f"{path}: corrupt MCAP: read {count} of the {expected} messages its summary lists")

