"""Bag I/O: read any recording with ``rosbags``, map its fields onto the node's standard
inputs, write deterministic ROS 2 MCAP replays with CRCs (:mod:`.mcap_io`).

* :func:`typestore` - the Jazzy types plus the project's ``msg_schemas/`` (``fti_msgs``) and
  any ``--schemas`` directory; schemas embedded in a bag take part automatically.
* :func:`convert` - a recording plus a mapping file (``msg_schemas/fti_msgs/mapping.yaml``
  is the one for the shared Twin Otter recordings) to a replay on the standard topics.
* :func:`write_t2_bag` - the bundled seeded T-2 maneuver on the standard topics.
* :func:`write_campaign_bags` - a simulated campaign: N seeded T-2 maneuvers in turbulence,
  one replay bag each (``make-bag --campaign N``).
* :class:`InputStream` - the standard-topic messages of a replay, read as a stream for the
  offline replay (:func:`read_inputs`: the same as a list, for small bags and tests).
* :class:`BagWriter` - a bag's MCAP file written record by record, with CRCs
  (:class:`.mcap_io.McapWriter`): :func:`write_replay`, :func:`convert`,
  :func:`write_sensor_streams` and the replay's ``estimates.mcap``.

Reading and writing stream: messages are read one MCAP chunk at a time in log-time order,
and written as they come, so memory does not grow with the recording (what a writer holds
back to keep its output ordered is said with each writer).

Replays are ROS 2 bags (storage version 9, MCAP with chunk, data and summary CRCs: a damaged
byte is refused by :func:`.mcap_io.check_mcap_integrity`, which every read runs first), every
message logged at its header stamp, ordered by stamp with a stable tie-break (topic, then
recorded order): converting the same input twice gives byte-identical files. Output is
written to a temporary directory that is renamed only when complete. Every problem raises
:class:`BagError` naming the file, the topic and what is wrong.
"""

from __future__ import annotations

import hashlib
import heapq
import math
import numbers
import struct
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from ..aero.coefficients import rep103_to_aircraft
from ..datapath import cdr
from ..datapath.inputs import MESSAGE_TYPES, Stamped, stamp_ns
from ..datapath.inputs import STREAMS as INPUTS
from ..datapath.maneuvers import EVENT, EVENT_TYPE
from ..errors import BagError, ConfigError
from ..files import OutputWriter, input_problem, output_directory
from ..progress import track
from ..settings import yaml_files
from ..settings.models import package_path
from .mcap_io import McapWriter, check_mcap_integrity, write_metadata

if TYPE_CHECKING:  # annotations only: rosbags itself is imported where it is used
    from hashlib import _Hash

    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import Typestore

    from ..simulation.t2 import SensorStreams
    from ..simulation.turbulence import DrydenVertical

__all__ = [
    "BagError",
    "typestore",
    "convert",
    "write_replay",
    "check_mcap_integrity",
    "check_bag",
    "write_t2_bag",
    "write_campaign_bags",
    "write_sensor_streams",
    "BagWriter",
    "InputStream",
    "read_inputs",
    "load_mapping",
    "schema_dir",
    "UNITS",
    "EXCITATION_TOPIC",
]


def schema_dir() -> Path:
    """The project's ``msg_schemas/`` directory (source tree or ROS install share)."""
    return package_path("msg_schemas")


def typestore(extra_schemas: list[Path] | None = None) -> Typestore:
    """Jazzy typestore with the ``.msg`` files of ``msg_schemas/`` and ``extra_schemas``
    (directories laid out as ``PKG/msg/NAME.msg``)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: PLC0415

    store = get_typestore(Stores.ROS2_JAZZY)
    dirs = [schema_dir(), *(Path(d) for d in (extra_schemas or []))]
    types = {}
    for d in dirs:
        if not d.is_dir():
            raise BagError(f"{d}: schema directory does not exist")
        for msg in sorted(d.rglob("*.msg")):
            name = f"{msg.parent.parent.name}/msg/{msg.stem}"
            try:
                types.update(get_types_from_msg(msg.read_text(), name))
            except Exception as exc:  # the parser raises several types
                raise BagError(f"{msg}: cannot parse message schema: {exc}") from exc
    store.register(types)
    return store


# The files of a rosbag2 directory a reader opens: its metadata and its storage files.
_BAG_FILES = ("metadata.yaml", "*.mcap", "*.db3", "*.zstd")


def check_bag(path: str | Path) -> Path:
    """``path`` if it can be a bag: an MCAP file, or a rosbag2 directory whose metadata and
    storage files are regular files; else :class:`BagError` in one line, before anything is
    opened (a FIFO or a device would block a reader or feed it without end; a symbolic link
    loop has no file at its end)."""
    path = Path(path)
    problem = input_problem(path)
    if problem == "no such file or directory":
        raise BagError(f"{path}: no such bag")
    if problem is not None:
        raise BagError(f"{path}: {problem}; a bag is an MCAP file or a rosbag2 directory")
    if path.is_dir():
        for pattern in _BAG_FILES:
            for item in sorted(path.glob(pattern)):
                problem = input_problem(item, directory=False)
                if problem is not None:
                    raise BagError(f"{item}: {problem}; the files of a bag are regular files")
    return path


def _open_reader(path: Path, store: Typestore) -> AnyReader:
    from rosbags.highlevel import AnyReader  # noqa: PLC0415

    check_bag(path)
    mcaps = [path] if path.suffix == ".mcap" else sorted(path.glob("*.mcap")) if path.is_dir() else []
    for f in mcaps:
        check_mcap_integrity(f)
    try:
        reader = AnyReader([path], default_typestore=store)
        reader.open()
    except Exception as exc:  # rosbags raises several types for corrupt files
        raise BagError(f"{path}: cannot open bag: {exc}") from exc
    return reader


def _has_schema(msgtype: str, store: Typestore, reader: AnyReader) -> bool:
    """A definition with fields, from msg_schemas/ / --schemas or embedded in the bag."""
    if msgtype in store.fielddefs:
        return True
    fields_ = getattr(reader, "typestore", store).fielddefs.get(msgtype)
    if not fields_:
        return False
    return not (len(fields_[1]) == 1 and fields_[1][0][0] == "structure_needs_at_least_one_member")


def content_digest_update(digest: _Hash, topic: str, log_time: int, raw: bytes | memoryview) -> None:
    """Add one message to a bag's content digest: its topic, log time and serialized bytes,
    each delimited, so that two bags holding the same messages have the same digest whatever
    their storage, chunking, compression or other topics."""
    digest.update(f"{topic}\0{log_time}\0{len(raw)}\0".encode())
    digest.update(raw)


def _iter_messages(
    path: Path, reader: AnyReader, connections: Sequence[Connection], store: Typestore | None = None,
    fast: bool = False, digest: _Hash | None = None,
) -> Generator[tuple[Connection, int, object], None, None]:
    """Messages of ``connections`` in log order, deserialized as they are read (``rosbags``
    reads an MCAP one chunk at a time); corruption names the file. ``fast`` decodes the
    standard input types of a ROS 2 bag with :mod:`.cdr`; ``digest`` is updated with every
    message read (:func:`content_digest_update`)."""
    it = reader.messages(connections=connections)
    fast = fast and getattr(reader, "is2", False)
    update = None if digest is None else digest.update
    plans: dict[int, tuple[bytes, bool]] = {}  # per connection: its topic's bytes, decoded by cdr
    while True:
        try:
            conn, t, raw = next(it)
        except StopIteration:
            return
        except Exception as exc:  # a corrupt bag raises many types
            raise BagError(f"{path}: corrupt or truncated bag: {exc}") from exc
        plan = plans.get(id(conn))
        if plan is None:
            plan = plans[id(conn)] = (conn.topic.encode(), fast and conn.msgtype in cdr.DECODABLE)
        if update is not None:  # content_digest_update, inline
            update(b"%s\0%d\0%d\0" % (plan[0], t, len(raw)))
            update(raw)
        if plan[1]:
            try:
                msg = cdr.decode(conn.msgtype, raw)
            except (struct.error, UnicodeDecodeError, IndexError) as exc:
                raise BagError(f"{path}: topic {conn.topic}: cannot decode {conn.msgtype}: {exc}") from exc
            if msg is not None:
                yield conn, t, msg
                continue
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as exc:  # re-raised as BagError unless the fallback below decodes it
            # An empty or broken embedded schema: the msg_schemas/ or --schemas type decides.
            if store is not None and conn.msgtype in store.types:
                try:
                    yield conn, t, store.deserialize_cdr(raw, conn.msgtype)
                    continue
                except Exception:  # noqa: BLE001, S110
                    pass
            raise BagError(
                f"{path}: topic {conn.topic}: cannot decode {conn.msgtype} (no schema in the bag or in "
                f"msg_schemas/?): {exc}"
            ) from exc
        yield conn, t, msg


# ------------------------------------------------------------------------------ writing
_TOPIC_RANK = {kind: i for i, kind in enumerate(INPUTS)}


def _rank(topic: str) -> int:
    """Where a topic's messages go among those of one stamp: the standard inputs in the
    order of :data:`.inputs.STREAMS`, then every other topic (by name)."""
    return _TOPIC_RANK.get(topic.strip("/"), len(_TOPIC_RANK))


def _check_log_time(path: Path, stamp: int, topic: str) -> None:
    if not 0 <= stamp < 2**64:
        raise BagError(f"{path}: topic {topic}: stamp {stamp} ns cannot be a log time (0 to 2^64 - 1 ns)")


class BagWriter(OutputWriter):
    """One MCAP file of a ROS 2 bag (storage version 9) written as its records arrive, at
    ``path`` (a new file, :class:`.mcap_io.McapWriter`: with CRCs; callers make it atomic with
    :func:`.files.output_directory`, and :func:`_bag_directory` adds ``metadata.yaml``).

    ``topics``: every ``(topic, msgtype)`` the bag holds, its connections in the order of
    :func:`_rank`, then name. :meth:`add` queues a record (``msg`` a message, serialized
    now, or its CDR bytes); :meth:`release` writes the queued records stamped before a time
    that the caller knows no later record precedes, and :meth:`close` the rest. The file is
    ordered by stamp, then topic rank, then topic, then the order of :meth:`add`: exactly what
    one sort of all the records gives (:func:`write_replay`), in memory bounded by what the
    caller holds back (and the one chunk :class:`.mcap_io.McapWriter` builds). Log time =
    stamp. :attr:`info` (once closed) is the rosbag2 bag-file information."""

    def __init__(self, path: Path, topics: Sequence[tuple[str, str]], store: Typestore) -> None:
        self.path, self.store = Path(path), store
        self._types = dict(topics)
        self._writer = McapWriter(self.path, store)
        self._ranks = {topic: _rank(topic) for topic in self._types}
        self._conns = {topic: self._writer.add_connection(topic, self._types[topic])
                       for topic in sorted(self._types, key=lambda t: (self._ranks[t], t))}
        self._queue: list[tuple[int, int, str, int, bytes | memoryview]] = []
        self._added = 0
        self.written = 0
        self.info: dict[str, Any] | None = None

    def add(self, stamp: int, topic: str, msgtype: str, msg: object) -> None:
        """Queue one record; a stamp that cannot be a log time is a :class:`BagError`."""
        if not 0 <= stamp < 2**64:
            _check_log_time(self.path, stamp, topic)
        raw = msg if isinstance(msg, (bytes, memoryview)) else self.store.serialize_cdr(msg, msgtype)
        rank = self._ranks.get(topic)
        heapq.heappush(self._queue, (stamp, _rank(topic) if rank is None else rank, topic, self._added, raw))
        self._added += 1

    def release(self, before_ns: int | None = None) -> None:
        """Write every queued record stamped before ``before_ns`` (all of them: None)."""
        queue, write, conns = self._queue, self._writer.write, self._conns
        while queue and (before_ns is None or queue[0][0] < before_ns):
            stamp, _, topic, _, raw = heapq.heappop(queue)
            write(conns[topic], stamp, raw)
            self.written += 1

    @property
    def queued(self) -> int:
        """Records added and not written yet."""
        return len(self._queue)

    def close(self) -> None:
        """Write what is queued and finish the file (its summary, CRCs and :attr:`info`)."""
        self.release()
        self.info = self._writer.close()

    def abort(self) -> None:
        """Remove the unfinished file (the caller's output directory is discarded)."""
        self._writer.abort()


@contextmanager
def _bag_directory(path: Path, topics: Sequence[tuple[str, str]], store: Typestore, *, force: bool,
                   inputs: tuple[str | Path, ...] = (), files: Mapping[str, str] | None = None) -> Iterator[BagWriter]:
    """A ROS 2 bag directory at ``path``, atomic (:func:`.files.output_directory`: complete or
    absent; an existing non-empty ``path`` only with ``force``, never over ``inputs``):
    ``NAME.mcap`` written by the :class:`BagWriter` this yields, then rosbag2's
    ``metadata.yaml`` (:func:`.mcap_io.write_metadata`) and the text ``files`` (name: text)."""
    with output_directory(path, force=force, inputs=inputs) as tmp:
        with BagWriter(tmp / f"{path.resolve().name}.mcap", topics, store) as writer:
            yield writer
        assert writer.info is not None  # (set by close)
        write_metadata(tmp, writer.info)
        for name, text in (files or {}).items():
            (tmp / name).write_text(text)


def _mk(
    store: Typestore,
) -> tuple[Mapping[str, Callable[..., object]], Callable[[int], object], Callable[[float, float, float], object]]:
    T = store.types

    def header(stamp: int, frame: str = "base_link") -> object:
        return T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=int(stamp // 10**9), nanosec=int(stamp % 10**9)),
            frame_id=frame,
        )

    def vec(x: float, y: float, z: float) -> object:
        return T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    return T, header, vec


def _standard_message(
    store: Typestore, kind: str, stamp: int, values: npt.ArrayLike, names: Sequence[str] | None = None
) -> object:
    """A standard input message from plain values (REP-103, SI): a number (dynamic pressure,
    thrust) or a sequence of them."""
    T, header, vec = _mk(store)
    values = np.asarray(values, dtype=float)
    if kind == "imu":
        cov = np.zeros(9)
        unknown = np.zeros(9)
        unknown[0] = -1.0  # orientation not provided
        return T["sensor_msgs/msg/Imu"](
            header=header(stamp),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=unknown,
            angular_velocity=vec(*values[:3]),
            angular_velocity_covariance=cov,
            linear_acceleration=vec(*values[3:6]),
            linear_acceleration_covariance=cov.copy(),
        )
    if kind == "airspeed":
        return T["geometry_msgs/msg/Vector3Stamped"](header=header(stamp), vector=vec(*values))
    if kind == "dynamic_pressure":
        return T["sensor_msgs/msg/FluidPressure"](header=header(stamp), fluid_pressure=float(values), variance=0.0)
    if kind in ("control_surfaces", "excitation"):  # (the excitation: the surfaces' type and joints)
        if names is None:
            raise ValueError(f"{kind} needs the joint names")
        return T["sensor_msgs/msg/JointState"](
            header=header(stamp),
            name=list(names),
            position=values,
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
    if kind == "thrust":
        return T["geometry_msgs/msg/WrenchStamped"](
            header=header(stamp),
            wrench=T["geometry_msgs/msg/Wrench"](force=vec(float(values), 0.0, 0.0), torque=vec(0.0, 0.0, 0.0)),
        )
    raise ValueError(kind)


def write_replay(path: str | Path, records: Iterable[tuple[int, str, str, object]], store: Typestore | None = None,
                 *, force: bool = False, inputs: tuple[str | Path, ...] = ()) -> Path:
    """Write ``records`` (``(stamp_ns, topic, msgtype, msg)``, ``msg`` a message or its CDR
    bytes) as a ROS 2 MCAP bag at ``path`` (a directory: ``NAME.mcap`` with CRCs and
    ``metadata.yaml``), log time = stamp, ordered by stamp with a stable tie-break
    (:class:`BagWriter`; the records are all held, for the sort). Atomic
    (:func:`_bag_directory`): the bag appears under ``path`` only when complete; an existing
    non-empty ``path`` is refused unless ``force``, and ``inputs`` are never overwritten."""
    store = store or typestore()
    path = Path(path)
    recs = list(records)
    if not recs:
        raise BagError(f"{path}: nothing to write (no messages)")
    topics: dict[str, str] = {}
    for stamp, topic, msgtype, _msg in recs:
        _check_log_time(path, int(stamp), topic)
        topics.setdefault(topic, msgtype)
    with _bag_directory(path, list(topics.items()), store, force=force, inputs=inputs) as writer:
        for stamp, topic, msgtype, msg in recs:
            writer.add(int(stamp), topic, msgtype, msg)
    return path


def write_sensor_streams(path: str | Path, streams: SensorStreams, *, force: bool = False,
                         excitation: bool = False, events: Sequence[tuple[int, str, str, object]] = (),
                         files: Mapping[str, str] | None = None) -> Path:
    """A :class:`.simulation.SensorStreams` as a bag on the standard topics at ``path``
    (atomic, as :func:`write_replay`), written message by message in stamp order: a long
    recording never sits in memory as messages. With ``excitation``, the designed excitation
    the streams carry goes on :data:`EXCITATION_TOPIC` with the surfaces' message type, names
    and stamps; ``events``: more records ``(stamp_ns, topic, msgtype, msg)`` in stamp order (an
    event topic), merged in; ``files``: text files (name: text) written beside the bag's."""
    store = typestore()
    path = Path(path)
    sources = {f"/{kind}": (kind, getattr(streams, kind)) for kind in INPUTS if kind != "excitation"}
    if excitation and streams.excitation is not None:
        sources[EXCITATION_TOPIC] = ("control_surfaces", streams.excitation)

    def records(topic: str) -> Iterator[tuple[int, int, str, int]]:
        stamps = sources[topic][1][0]
        return ((int(stamps[k]), _rank(topic), topic, k) for k in range(stamps.size))

    extra = ((int(e[0]), _rank(e[1]), e[1], k) for k, e in enumerate(events))
    topics = [(topic, MESSAGE_TYPES[kind]) for topic, (kind, _) in sources.items()]
    topics += sorted({(topic, msgtype) for _, topic, msgtype, _ in events} - set(topics))
    with _bag_directory(path, topics, store, force=force, files=files) as writer:
        for stamp, _, topic, k in heapq.merge(*(records(topic) for topic in sources), extra):
            if topic not in sources:  # an event
                writer.add(stamp, topic, events[k][2], events[k][3])
            else:
                kind, (_, values) = sources[topic]
                msg = _standard_message(store, kind, stamp, values[k], streams.surface_names)
                writer.add(stamp, topic, MESSAGE_TYPES[kind], msg)
            writer.release()  # the merge gives the records in the bag's order
    return path


# The topic of the designed excitation in a simulated bag: the multisine injected on each
# surface (rad, from trim, before any feedback), as a flight-control computer would publish it.
EXCITATION_TOPIC = "/fcc/excitation"

# The bundled bag's band-limited noise is on all four measured signals, as it was recorded:
# the demo and the measured figures of the docs are its replay. The simulation's default moved
# to the responses only for the Table 3 means (docs/validation.md); one maneuver is no mean.
BUNDLED_BAG_NOISE_ON = ("delta_e", "alpha", "q", "az")


def write_t2_bag(path: str | Path, band_level: float = 0.2, seed: int = 250, *, force: bool = False,
                 band_limited_on: Sequence[str] = BUNDLED_BAG_NOISE_ON, input_amplitude: float = 1.0) -> Path:
    """The bundled bag: one seeded T-2 maneuver (Section IV.A) on the standard topics, IMU at
    200 Hz, air data at 50 Hz, surfaces at 100 Hz, thrust at 10 Hz
    (:func:`.simulation.simulate_sensor_streams`), the band-limited noise on
    ``band_limited_on`` (the bundled bag's: all four signals), the elevator multisine at
    ``input_amplitude`` x Table 2's amplitude (the sensor noise at the nominal one's scale)."""
    from ..simulation.t2 import simulate_sensor_streams  # noqa: PLC0415

    streams = simulate_sensor_streams(band_level, seed, band_limited_on=band_limited_on,
                                      input_amplitude=input_amplitude)
    return write_sensor_streams(path, streams, force=force)


def write_campaign_bags(path: str | Path, maneuvers: int, gust: DrydenVertical, *, band_level: float = 0.2,
                        band_limited_on: Sequence[str] | None = None, seed: int = 250,
                        force: bool = False, input_amplitude: float = 1.0, pitch_gust: bool = True,
                        progress: bool | None = False) -> list[Path]:
    """A simulated flight-test campaign (Section IV.B, simulated): ``maneuvers`` T-2 maneuvers
    flown in the Dryden vertical ``gust`` (:func:`.simulation.simulate_campaign`, each with
    its own gust and noise sequences from ``seed``), each a replay bag ``mNNN`` in the
    directory ``path`` with the designed excitation on :data:`EXCITATION_TOPIC`, and
    ``campaign.yaml`` recording the settings. Atomic as
    :func:`write_replay`; one maneuver is in memory at a time. ``band_limited_on``: the
    signals carrying the band-limited noise (None: the simulation's default); ``input_amplitude``:
    the elevator multisine's fraction of Table 2's amplitude; ``pitch_gust``: the gust's pitch
    gust acts on the aircraft too (:mod:`..simulation.t2`); ``progress``: a bar of the
    maneuvers written on stderr (:mod:`..progress`)."""
    import yaml  # noqa: PLC0415 - the manifest only

    from ..simulation.t2 import BAND_LIMITED_ON, simulate_campaign  # noqa: PLC0415 - scipy only when simulating

    if not (type(maneuvers) is int and maneuvers >= 1):
        raise ConfigError(f"a campaign needs an integer number of maneuvers >= 1, got {maneuvers!r} (--campaign)")
    on = tuple(BAND_LIMITED_ON if band_limited_on is None else band_limited_on)
    width = max(3, len(str(maneuvers)))
    names = [f"m{i:0{width}d}" for i in range(1, maneuvers + 1)]
    path = Path(path)
    with output_directory(path, force=force) as tmp:
        manifest = {"maneuvers": maneuvers, "seed": seed, "gust_sigma_w_m_s": gust.sigma,
                    "gust_scale_length_m": gust.scale_length, "pitch_gust": bool(pitch_gust),
                    "band_limited_noise": band_level,
                    "band_limited_on": list(on), "input_amplitude": float(input_amplitude), "bags": names,
                    "simulation": "rls_uncertainty.simulation.t2.simulate_campaign (Section IV.A T-2 maneuver, "
                                  "Dryden vertical gust on alpha, with pitch_gust its MIL-F-8785C pitch gust on q, "
                                  "seeds SeedSequence(seed).spawn(maneuvers))"}
        (tmp / "campaign.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
        streams = simulate_campaign(maneuvers, gust, seed=seed, band_level=band_level, band_limited_on=on,
                                    input_amplitude=input_amplitude, pitch_gust=bool(pitch_gust))
        for name, maneuver in track(zip(names, streams, strict=True), maneuvers, "make-bag", " maneuvers", progress):
            write_sensor_streams(tmp / name, maneuver, excitation=True)
    return [path / name for name in names]


# ------------------------------------------------------------------------------ reading
def input_topics(topics: Mapping[str, str] | None = None) -> dict[str, str]:
    """Bag topic of each standard input: ``topics.*`` parameters, absolute (``/imu``...)."""
    topics = topics or {}
    out = {}
    for kind in INPUTS:
        name = topics.get(kind, kind)
        out[kind] = name if name.startswith("/") else f"/{name}"
    return out


class InputStream:
    """The standard-input messages of a replay bag, ``(kind, stamp_ns, msg)`` in log order,
    read from the file while they are iterated (``rosbags`` decompresses an MCAP chunk when the
    log-time order reaches it): memory does not grow with the bag. Opening checks what the bag's index tells: the input
    topics (``topics.*`` parameters, :func:`input_topics`) and their types, and the span
    ``start``/``end`` (s from the bag start; finite, at least 0, ``end`` after ``start``, within
    the bag; else :class:`ConfigError`). Iterating checks each message: a negative header
    stamp, and with ``strict`` a topic whose header stamps do not increase, is a
    :class:`BagError`; messages outside the span are read and skipped; a bag with no input
    message in the span is a :class:`BagError` at the end.

    Iterable once; the bag is closed at the end of the iteration, by :meth:`close` or by
    ``with``. With ``events`` (``maneuvers.topic``), the test-point events of that topic
    (``diagnostic_msgs/msg/KeyValue``, no header) come too, as ``("event", log time, msg)`` in
    their place (:mod:`..datapath.maneuvers`). :attr:`t0` is the bag's start (ns), :attr:`total`
    the input messages its index lists (the span aside), :attr:`digest` (once iterated) the SHA-256 of every input-topic
    message of the bag (:func:`content_digest_update`), and :attr:`read` the messages read."""

    def __init__(self, path: str | Path, topics: Mapping[str, str] | None = None, *, strict: bool = True,
                 start: float | None = None, end: float | None = None, events: str | None = None) -> None:
        self.path = path = Path(path)
        _check_span(start, end)
        self.strict = strict
        self.store = store = typestore()
        wanted = input_topics(topics)
        kinds: dict[str, tuple[str, ...]] = {}  # topic -> the inputs it feeds (the excitation may be the surfaces')
        for kind, topic in wanted.items():
            kinds[topic] = (*kinds.get(topic, ()), kind)
        self._kinds = kinds
        # The test-point events (maneuvers.topic), yielded as ("event", log time, msg) when given.
        self._events = None if events is None else (events if events.startswith("/") else f"/{events}")
        self._reader = reader = _open_reader(path, store)
        self._open = True
        try:
            self._conns = self._input_connections()
            self.t0 = t0 = reader.start_time
            self.end_ns = reader.end_time
            _check_span_in_bag(path, start, end, reader.end_time - 1 - t0)
        except BaseException:
            self.close()
            raise
        self.start, self.end = start, end
        self._lo = None if start is None else t0 + int(round(start * 1e9))
        self._hi = None if end is None else t0 + int(round(end * 1e9))
        self.total = sum(int(getattr(c, "msgcount", 0) or 0) for c in self._conns)
        # The span read, s: the bag's, or --start/--end's within it.
        self.span_seconds = ((self.end_ns if self._hi is None else min(self._hi, self.end_ns))
                             - (t0 if self._lo is None else self._lo)) * 1e-9
        self._digest = hashlib.sha256()
        self.read = 0
        self._used = False

    def _input_connections(self) -> list[Connection]:
        """The bag's connections on input topics, each of its input's type."""
        path, reader, kinds = self.path, self._reader, self._kinds
        conns = [c for c in reader.connections if c.topic in kinds]
        if not conns:
            raise BagError(
                f"{path}: none of the input topics {sorted(kinds)} is in the bag "
                f"(it has {sorted({c.topic for c in reader.connections}) or 'no topics'})"
            )
        for c in conns:
            for kind in kinds[c.topic]:
                expected = MESSAGE_TYPES[kind]
                if c.msgtype != expected:
                    raise BagError(f"{path}: topic {c.topic} has type {c.msgtype}, expected {expected}")
        events = [c for c in reader.connections if c.topic == self._events]
        for c in events:
            if c.msgtype != EVENT_TYPE:
                raise BagError(f"{path}: topic {c.topic} (maneuvers.topic) has type {c.msgtype}, expected {EVENT_TYPE}")
        return conns + events

    @property
    def digest(self) -> str:
        """Hex SHA-256 of the input-topic messages read so far (all of them once iterated)."""
        return self._digest.hexdigest()

    def __iter__(self) -> Iterator[tuple[str, int, Stamped]]:
        if self._used:
            raise BagError(f"{self.path}: an input stream is read once; open the bag again")
        self._used = True
        try:
            yield from self._messages()
        finally:
            self.close()

    def _messages(self) -> Iterator[tuple[str, int, Stamped]]:
        path, kinds, lo, hi, strict = self.path, self._kinds, self._lo, self._hi, self.strict
        last: dict[str, int] = {}
        used = 0
        for conn, t, raw_msg in _iter_messages(path, self._reader, self._conns, self.store, fast=True,
                                                digest=self._digest):
            self.read += 1
            if conn.topic == self._events:  # no header: the log time places it
                if (lo is None or t >= lo) and (hi is None or t <= hi):
                    yield EVENT, t, cast(Stamped, raw_msg)
                continue
            msg = cast(Stamped, raw_msg)  # the input types (checked on opening) all carry a header
            stamp = stamp_ns(msg)
            if stamp < 0:
                raise BagError(f"{path}: topic {conn.topic}: negative header stamp ({stamp} ns, before 1970)")
            if strict:
                prev = last.get(conn.topic)
                if prev is not None and stamp <= prev:
                    what = "duplicate" if stamp == prev else "non-monotonic"
                    raise BagError(f"{path}: topic {conn.topic}: {what} header stamps ({prev} then {stamp} ns)")
                last[conn.topic] = stamp
            if (lo is not None and stamp < lo) or (hi is not None and stamp > hi):
                continue
            used += 1
            for kind in kinds[conn.topic]:
                yield kind, stamp, msg
        if not used:
            if self.read:
                raise BagError(f"{path}: no input messages from {self.start or 0:g} s to "
                               f"{'the end' if self.end is None else f'{self.end:g} s'} (the bag holds "
                               f"{(self.end_ns - self.t0) * 1e-9:.1f} s)")
            raise BagError(f"{path}: no input messages (empty bag)")

    def close(self) -> None:
        """Close the bag (once; again does nothing)."""
        if self._open:
            self._open = False
            self._reader.close()

    def __enter__(self) -> InputStream:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def read_inputs(path: str | Path, topics: Mapping[str, str] | None = None, *, strict: bool = True,
                start: float | None = None, end: float | None = None,
                events: str | None = None) -> tuple[list[tuple[str, int, Stamped]], int]:
    """The messages of :class:`InputStream` as a list, and the bag's start time: every
    message in memory at once, for small bags and tests (the replay streams)."""
    with InputStream(path, topics, strict=strict, start=start, end=end, events=events) as stream:
        return list(stream), stream.t0


def _check_span_in_bag(path: Path, start: float | None, end: float | None, last_ns: int) -> None:
    """``start`` and ``end`` (s from the bag start, compared in ns as the messages are cut) within
    the bag, whose last message is ``last_ns`` after its first; else a :class:`ConfigError`
    giving the bag's span."""
    for name, value in (("start", start), ("end", end)):
        if value is not None and int(round(value * 1e9)) > last_ns:
            raise ConfigError(f"{path}: {name} {value:g} s is after the bag's last message: the bag spans 0 to "
                              f"{last_ns * 1e-9:.9g} s from its start")


def _check_span(start: float | None, end: float | None) -> None:
    """``start`` and ``end``: None or finite seconds >= 0 from the bag start, end after start."""
    # Checked as any object: callers pass what the command line or a script gave.
    given: tuple[tuple[str, object], ...] = (("start", start), ("end", end))
    for name, value in given:
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
            raise ConfigError(f"{name} must be a finite number of seconds >= 0 from the bag start, got {value!r}")
    if start is not None and end is not None and end <= start:
        raise ConfigError(f"end ({end:g} s) must be after start ({start:g} s)")


# ------------------------------------------------------------------------------ convert
# Unit names accepted in mapping files and their factors to SI.
UNITS = {
    "rad/s": 1.0, "deg/s": math.pi / 180.0,
    "m/s^2": 1.0, "g": 9.80665, "ft/s^2": 0.3048,
    "m/s": 1.0, "ft/s": 0.3048, "kt": 1852.0 / 3600.0, "km/h": 1.0 / 3.6,
    "rad": 1.0, "deg": math.pi / 180.0,
    "Pa": 1.0, "hPa": 100.0, "psf": 47.88025898, "psi": 6894.757293,
    "N": 1.0, "lbf": 4.448221615, "kN": 1000.0,
}
FRAMES = ("rep103", "aircraft")
_QUANTITY_UNITS = {
    "angular rate": ("rad/s", "deg/s"),
    "acceleration": ("m/s^2", "g", "ft/s^2"),
    "speed": ("m/s", "ft/s", "kt", "km/h"),
    "angle": ("rad", "deg"),
    "pressure": ("Pa", "hPa", "psf", "psi"),
    "force": ("N", "lbf", "kN"),
}
# Per standard input, every key a mapping may give: what it holds (a field list of three,
# one field, a unit of a quantity, ...). Anything else is refused, so a misspelt key is an
# error instead of a silently ignored setting.
_MAPPING_KEYS = {
    "imu": {"topic": "topic", "frame": "frame",
            "angular_velocity": "fields3", "angular_velocity_units": "angular rate",
            "linear_acceleration": "fields3", "linear_acceleration_units": "acceleration"},
    "airspeed": {"topic": "topic", "frame": "frame", "vector": "fields3", "units": "speed",
                 "polar": "polar", "speed_units": "speed", "angle_units": "angle"},
    "dynamic_pressure": {"topic": "topic", "field": "field", "units": "pressure"},
    "control_surfaces": {"topic": "topic", "joints": "joints", "units": "angle"},
    "thrust": {"topic": "topic", "field": "field", "units": "force"},
}
_MAPPING_KEYS["excitation"] = _MAPPING_KEYS["control_surfaces"]  # the injected input: surfaces' joints
_JOINTS = ("control_surfaces", "excitation")  # the inputs mapped joint by joint
_POLAR_KEYS = ("speed", "alpha", "beta")
_REDUCTIONS = ("sum", "mean")


def _unit(spec: dict, key: str, default: str, where: str) -> float:
    name = spec.get(key, default)
    if name not in UNITS:
        raise BagError(f"{where}: unknown unit {name!r}; known: {sorted(UNITS)}")
    return UNITS[name]


def _check_field(value: object, where: str) -> None:
    """A field: a dotted path (``-`` prefix flips the sign), or ``{field: PATH, reduce: sum|mean}``."""
    if isinstance(value, dict):
        extra = sorted(map(str, set(value) - {"field", "reduce"}))
        if extra:
            raise BagError(f"{where}: unknown key(s) {extra}; a field is PATH or {{field: PATH, reduce: sum|mean}}")
        if "field" not in value:
            raise BagError(f"{where}: needs 'field: PATH'")
        if value.get("reduce", "sum") not in _REDUCTIONS:
            raise BagError(f"{where}: reduce must be one of {list(_REDUCTIONS)}, got {value['reduce']!r}")
        value = value["field"]
    if not isinstance(value, str) or not value.lstrip("-"):
        raise BagError(f"{where}: expected a field name (a dotted path such as vector.x), got {value!r}")


def _check_input(kind: str, spec: object, where: str) -> None:
    keys = _MAPPING_KEYS[kind]
    if not isinstance(spec, dict):
        raise BagError(f"{where}: expected a mapping with at least 'topic', got {spec!r}")
    extra = sorted(map(str, set(spec) - set(keys)))
    if extra:
        raise BagError(f"{where}: unknown key(s) {extra}; known: {list(keys)}")
    if "topic" not in spec:
        raise BagError(f"{where}: needs a 'topic'")
    if kind in _JOINTS and "joints" not in spec:
        raise BagError(f"{where}: needs 'joints: {{joint_name: field, ...}}'")
    if kind == "airspeed":
        given = "polar" if "polar" in spec else "vector"
        other = ("vector", "units") if given == "polar" else ("polar", "speed_units", "angle_units")
        clash = [k for k in other if k in spec]
        if clash:
            raise BagError(f"{where}: {clash} do not go with the {given} form; give the airspeed either as "
                           "'vector' (with 'units') or as 'polar' (with 'speed_units', 'angle_units')")
    for key, value in spec.items():
        what, at = keys[key], f"{where}: {key}"
        if what == "topic":
            if not isinstance(value, str) or not value:
                raise BagError(f"{at}: expected a topic name, got {value!r}")
        elif what == "frame":
            if not isinstance(value, str) or value not in FRAMES:
                raise BagError(f"{at}: must be one of {list(FRAMES)}, got {value!r}")
        elif what == "fields3":
            if not isinstance(value, list) or len(value) != 3:
                raise BagError(f"{at}: expected a list of three fields (x, y, z), got {value!r}")
            for i, f in enumerate(value):
                _check_field(f, f"{at}[{i}]")
        elif what == "field":
            _check_field(value, at)
        elif what == "polar":
            if not isinstance(value, dict):
                raise BagError(f"{at}: expected {{speed: FIELD, alpha: FIELD, beta: FIELD}}, got {value!r}")
            extra = sorted(map(str, set(value) - set(_POLAR_KEYS)))
            missing = [k for k in ("speed", "alpha") if k not in value]
            if extra or missing:
                raise BagError(f"{at}: " + (f"unknown key(s) {extra}" if extra else f"needs {missing}")
                               + f"; known: {list(_POLAR_KEYS)} (beta optional)")
            for k, f in value.items():
                _check_field(f, f"{at}.{k}")
        elif what == "joints":
            if not isinstance(value, dict) or not value:
                raise BagError(f"{at}: expected {{joint_name: field, ...}}, got {value!r}")
            for name, f in value.items():
                if not isinstance(name, str) or not name:
                    raise BagError(f"{at}: joint names must be text, got {name!r}")
                _check_field(f, f"{at}.{name}")
        else:  # a unit of the quantity ``what``
            allowed = _QUANTITY_UNITS[what]
            if not isinstance(value, str) or value not in UNITS:
                raise BagError(f"{at}: unknown unit {value!r}; {what} units: {list(allowed)}")
            if value not in allowed:
                raise BagError(f"{at}: {value!r} is not a unit of {what}; {what} units: {list(allowed)}")


def load_mapping(path: str | Path) -> dict:
    """A mapping file: for each standard input, the recorded topic, fields, units and frame.
    Every key and value is checked here, before any bag is read: a problem is a
    :class:`BagError` naming the file, the input and the key."""
    path = Path(path)
    data = yaml_files.load_mapping(path, "mapping file", BagError)
    unknown = sorted(map(str, set(data) - set(INPUTS)))
    if unknown:
        raise BagError(f"{path}: unknown input(s) {unknown}; known: {list(INPUTS)}")
    for kind in ("imu", "airspeed"):
        if kind not in data:
            raise BagError(f"{path}: the mapping must give {kind!r}")
    for kind, spec in data.items():
        _check_input(kind, spec, f"{path}: input {kind!r}")
    return data


def _field(msg: object, dotted: str, where: str) -> Any:  # a message field: any type
    value = msg
    for part in dotted.split("."):
        if not hasattr(value, part):
            raise BagError(f"{where}: message has no field {dotted!r}")
        value = getattr(value, part)
    return value


def _scalar(msg: object, spec: str | Mapping[str, str], where: str) -> float:
    """A field with an optional leading '-' (sign flip); arrays reduce by sum or mean."""
    name = spec if isinstance(spec, str) else spec["field"]
    sign = -1.0 if name.startswith("-") else 1.0
    value = _field(msg, name.lstrip("-"), where)
    try:
        if isinstance(value, (list, tuple, np.ndarray)):
            reduce = "sum" if isinstance(spec, str) else spec.get("reduce", "sum")
            value = np.sum(value) if reduce == "sum" else np.mean(value)
        return sign * float(value)
    except (TypeError, ValueError) as exc:
        raise BagError(f"{where}: field {name!r} is not a number") from exc


def _to_rep103(vec: Sequence[float], frame: str) -> tuple[float, ...]:
    # The aircraft-to-REP-103 rotation (pi about x) is its own inverse.
    return tuple(float(x) for x in rep103_to_aircraft(vec)) if frame == "aircraft" else tuple(vec)


def _mapped_values(kind: str, spec: dict, msg: object, where: str) -> float | Sequence[float]:
    """Plain REP-103 SI values of one standard input from a recorded message."""
    frame = spec.get("frame", "rep103")
    if kind == "imu":
        w = [_scalar(msg, f, where) * _unit(spec, "angular_velocity_units", "rad/s", where)
             for f in spec.get("angular_velocity", ["angular_velocity.x", "angular_velocity.y", "angular_velocity.z"])]
        a = [_scalar(msg, f, where) * _unit(spec, "linear_acceleration_units", "m/s^2", where)
             for f in spec.get("linear_acceleration",
                               ["linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z"])]
        if len(w) != 3 or len(a) != 3:
            raise BagError(f"{where}: angular_velocity and linear_acceleration need three fields each")
        return _to_rep103(w, frame) + _to_rep103(a, frame)
    if kind == "airspeed":
        if "polar" in spec:
            p = spec["polar"]
            V = _scalar(msg, p["speed"], where) * _unit(spec, "speed_units", "m/s", where)
            ang = _unit(spec, "angle_units", "rad", where)
            alpha = _scalar(msg, p["alpha"], where) * ang
            beta = _scalar(msg, p["beta"], where) * ang if "beta" in p else 0.0
            # Aircraft body axes: u = V cos a cos b, v = V sin b, w = V sin a cos b.
            vec = (V * math.cos(alpha) * math.cos(beta), V * math.sin(beta), V * math.sin(alpha) * math.cos(beta))
            return _to_rep103(vec, "aircraft") if frame == "aircraft" else vec
        fields_ = spec.get("vector", ["vector.x", "vector.y", "vector.z"])
        v = [_scalar(msg, f, where) * _unit(spec, "units", "m/s", where) for f in fields_]
        return _to_rep103(v, frame)
    if kind == "dynamic_pressure":
        return _scalar(msg, spec.get("field", "fluid_pressure"), where) * _unit(spec, "units", "Pa", where)
    if kind == "thrust":
        return _scalar(msg, spec.get("field", "wrench.force.x"), where) * _unit(spec, "units", "N", where)
    if kind in _JOINTS:
        joints = spec.get("joints")
        if not isinstance(joints, dict) or not joints:
            raise BagError(f"{where}: {kind} needs 'joints: {{joint_name: field}}'")
        scale = _unit(spec, "units", "rad", where)
        return [_scalar(msg, f, where) * scale for f in joints.values()]
    raise ValueError(kind)


class _StampBounds:
    """While a recording is read in log order: the least header stamp any message still to
    come can carry. Each topic's header stamps increase (:func:`_header_stamp` refuses the
    rest), so a topic's next stamp exceeds its last; a topic not seen yet starts at its first
    message's stamp (read ahead once per topic); a topic whose every message was read (the
    bag's index counts them) bounds nothing. Records stamped below the bound can be written:
    the writer holds back only what the topics' stamp skew spans."""

    def __init__(self, src: Path, reader: AnyReader, conns: Sequence[Connection], store: Typestore) -> None:
        self.left: dict[str, int | None] = {}
        self.bound: dict[str, int] = {}
        for topic in sorted({c.topic for c in conns}):
            mine = [c for c in conns if c.topic == topic]
            counts = [int(getattr(c, "msgcount", 0) or 0) for c in mine]
            self.left[topic] = sum(counts) if all(counts) else None  # None: not indexed, never done
            self.bound[topic] = self._first_stamp(src, reader, mine, store)

    @staticmethod
    def _first_stamp(src: Path, reader: AnyReader, conns: Sequence[Connection], store: Typestore) -> int:
        """The header stamp of the first message of ``conns``; 0 (no bound) when there is none
        or it cannot be read (the reading proper then says why)."""
        it = _iter_messages(src, reader, conns, store)
        try:
            return stamp_ns(cast(Stamped, next(it)[2]))
        except (StopIteration, AttributeError, TypeError, BagError):
            return 0
        finally:
            it.close()

    def after(self, topic: str, stamp: int) -> int | None:
        """The bound once ``topic``'s message stamped ``stamp`` is read (None: no message left)."""
        left = self.left[topic]
        if left is not None:
            self.left[topic] = left = left - 1
        if left is not None and left <= 0:
            self.bound.pop(topic, None)
        else:
            self.bound[topic] = stamp + 1
        return min(self.bound.values()) if self.bound else None


def _header_stamp(src: Path, topic: str, msg: object, last: dict[str, int]) -> int:
    """A recorded message's header stamp, refused when missing, negative or not after the
    previous one of its topic (``last``, updated)."""
    try:
        stamp = stamp_ns(cast(Stamped, msg))  # any type: one without a header raises below
    except AttributeError as exc:
        raise BagError(f"{src}: topic {topic}: message has no header stamp") from exc
    if stamp < 0:
        raise BagError(f"{src}: topic {topic}: negative header stamp ({stamp} ns, before 1970); "
                       "a replay bag logs every message at its stamp")
    prev = last.get(topic)
    if prev is not None and stamp <= prev:
        what = "duplicate" if stamp == prev else "non-monotonic"
        raise BagError(f"{src}: topic {topic}: {what} header stamps ({prev} then {stamp} ns)")
    last[topic] = stamp
    return stamp


def _mapped_connections(src: Path, mapping: str | Path, spec: dict, reader: AnyReader,
                        store: Typestore) -> list[Connection]:
    """The recording's connections on the mapped topics; a mapped topic missing from the
    recording, or a type without a schema, is a :class:`BagError`."""
    topics = {c.topic: c for c in reader.connections}
    for kind, s in spec.items():
        if s["topic"] not in topics:
            raise BagError(
                f"{src}: topic {s['topic']} (mapped to {kind} in {mapping}) is not in the bag; "
                f"it has {sorted(topics)}"
            )
    wanted = sorted({s["topic"] for s in spec.values()})
    conns = [c for c in reader.connections if c.topic in wanted]
    for c in conns:
        if not _has_schema(c.msgtype, store, reader):
            raise BagError(f"{src}: topic {c.topic}: type {c.msgtype} has no schema (not embedded in the bag, "
                           "not in msg_schemas/ or --schemas)")
    return conns


def _convert_messages(src: Path, spec: dict, reader: AnyReader, conns: Sequence[Connection], store: Typestore,
                      writer: BagWriter) -> dict[str, int]:
    """Every mapped message as standard inputs into ``writer``, released as the stamps allow
    (:class:`_StampBounds`); the messages per standard topic."""
    kinds_of = {c.topic: [k for k, s in spec.items() if s["topic"] == c.topic] for c in conns}
    bounds = _StampBounds(src, reader, conns, store)
    last: dict[str, int] = {}
    counts: dict[str, int] = {}
    for conn, _t, msg in _iter_messages(src, reader, conns, store):
        stamp = _header_stamp(src, conn.topic, msg, last)
        for kind in kinds_of[conn.topic]:
            values = _mapped_values(kind, spec[kind], msg, f"{src}: topic {conn.topic} ({kind})")
            names = list(spec[kind]["joints"]) if kind in _JOINTS else None
            topic = f"/{kind}"
            writer.add(stamp, topic, MESSAGE_TYPES[kind], _standard_message(store, kind, stamp, values, names))
            counts[topic] = counts.get(topic, 0) + 1
        writer.release(bounds.after(conn.topic, stamp))
    if not counts:
        raise BagError(f"{src}: the mapped topics hold no messages (empty bag)")
    return counts


def convert(src: str | Path, mapping: str | Path, out: str | Path, schemas: list[Path] | None = None, *,
            force: bool = False) -> dict:
    """Recording + mapping file -> replay bag on the standard topics, read and written as a
    stream (:class:`BagWriter`, :class:`_StampBounds`). Returns message counts per standard
    topic. Raises :class:`BagError` on any problem, leaving no output."""
    src, out = Path(src), Path(out)
    spec = load_mapping(mapping)
    store = typestore(schemas)
    reader = _open_reader(src, store)
    try:
        conns = _mapped_connections(src, mapping, spec, reader, store)
        with _bag_directory(out, [(f"/{kind}", MESSAGE_TYPES[kind]) for kind in spec], store, force=force,
                            inputs=(src, mapping)) as writer:
            counts = _convert_messages(src, spec, reader, conns, store, writer)
    finally:
        reader.close()
    return counts
