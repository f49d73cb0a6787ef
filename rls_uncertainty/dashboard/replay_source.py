"""The dashboard's replay source: a finished ``rls-uncertainty replay`` output directory, read
as a stream in its own thread and handed to the server's event loop in batches, like the live
source's items (memory bounded by the hub's histories whatever the flight's length).

* ``estimates.mcap`` (the node's own messages, byte for byte, with its ``/diagnostics`` and the
  per-period ``~/M/fit`` and ``~/M/identifiability``; see :mod:`..replay_files`) is read one
  chunk at a time in log order (``rosbags``), the arrays decoded by :mod:`..cdr`;
  The frequency-domain arrays (``~/M/frequency/...``, ``estimator.method`` ``frequency`` or
  ``both``) are in it too, and kept apart by :func:`.model.array_key`;
* a directory with ``estimates.csv`` and/or ``estimates_frequency.csv`` only (an older replay,
  or its MCAP removed) is read row by row, both files merged in time order: the estimates,
  standard errors and flags, without the fit, identifiability or input health that only the
  MCAP holds (the page says so).

:func:`open_replay` checks what can be checked before the server starts (the directory, the
MCAP's integrity and topics, the CSV's header) and raises :class:`..errors.BagError` naming the
file and the problem; a problem met while reading (a malformed CSV row) ends the reading, and
the page and the log say where.
"""

from __future__ import annotations

import contextlib
import csv
import heapq
import math
import struct
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..datapath.cdr import FLOAT64_MULTIARRAY, decode
from ..datapath.maneuvers import HISTORY_TOPIC
from ..datapath.outputs import FREQUENCY_DOMAIN, TIME_DOMAIN, ArrayKey, split_topic
from ..errors import BagError
from ..offline.bags import check_mcap_integrity, typestore
from ..offline.replay_files import CSV_COLUMNS
from ..ros.health import statuses_of
from .model import MAX_MODELS, MAX_PARAMETERS, MAX_STAMP_NS, Sample

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader

__all__ = ["ReplaySource", "open_replay", "BATCH"]

BATCH = 2000  # items handed to the event loop at once
# The replay's CSV of each method (rls_uncertainty.offline.replay_files), in the order they are named.
CSV_FILES = {TIME_DOMAIN: "estimates.csv", FREQUENCY_DOMAIN: "estimates_frequency.csv"}
IN_FLIGHT = 2  # batches handed over and not yet handled: the reader waits beyond


class ReplaySource:
    """A replay directory being read: :attr:`node` (the node whose topics it holds; empty for
    a CSV), :attr:`file` (``estimates.mcap``, or the CSV files read). :meth:`start` reads it in a
    thread and calls ``deliver(items)`` on the event loop; the last item is ``("replay_done",
    error)`` (error empty when read to the end)."""

    def __init__(self, directory: Path, file: str, node: str, items: Callable[[], Iterator[tuple]]) -> None:
        self.directory, self.file, self.node = directory, file, node
        self._items = items
        self._stop = threading.Event()
        self._slots = threading.Semaphore(IN_FLIGHT)
        self._thread: threading.Thread | None = None

    def start(self, call_soon_threadsafe: Callable[..., Any], deliver: Callable[[list[tuple]], None]) -> None:
        failed: list[str] = []

        def handle(batch: list[tuple]) -> None:
            try:
                if not failed:
                    deliver(batch)
            except Exception as exc:  # noqa: BLE001 - whatever a file's content provokes ends the reading, said
                failed.append(f"{self.file}: cannot be shown ({type(exc).__name__}: {exc})")
                self._stop.set()
                deliver([("replay_done", failed[0])])
            finally:
                self._slots.release()

        def hand(batch: list[tuple]) -> bool:
            while not self._slots.acquire(timeout=0.2):
                if self._stop.is_set():
                    return False
            try:
                call_soon_threadsafe(handle, batch)
            except RuntimeError:  # the loop closed: the server stopped
                return False
            return True

        def run() -> None:
            batch: list[tuple] = []
            error = ""
            try:
                for item in self._items():
                    if self._stop.is_set():
                        return
                    batch.append(item)
                    if len(batch) >= BATCH:
                        if not hand(batch):
                            return
                        batch = []
            except BagError as exc:
                error = str(exc)
            hand([*batch, ("replay_done", error)])

        self._thread = threading.Thread(target=run, name="rls_dashboard_replay", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)


def open_replay(directory: str | Path) -> ReplaySource:
    """The :class:`ReplaySource` of a replay output directory (module docstring)."""
    directory = Path(directory)
    mcap = directory / "estimates.mcap"
    if mcap.is_file():
        return _open_mcap(directory, mcap)
    tables = {method: directory / name for method, name in CSV_FILES.items() if (directory / name).is_file()}
    if tables:
        return _open_csv(directory, tables)
    raise BagError(f"{directory}: no estimates.mcap, estimates.csv or estimates_frequency.csv (the output directory "
                   "of rls-uncertainty replay)")


# ------------------------------------------------------------------ estimates.mcap
def _open_reader(path: Path) -> AnyReader:
    from rosbags.highlevel import AnyReader  # noqa: PLC0415 - the bag library only for replays

    check_mcap_integrity(path)
    try:
        reader = AnyReader([path], default_typestore=typestore())
        reader.open()
    except Exception as exc:  # rosbags raises many types for a corrupt file
        raise BagError(f"{path}: cannot read: {exc}") from exc
    return reader


def _shown(reader: AnyReader) -> tuple[str, dict[int, ArrayKey]]:
    """The node and the connections of the arrays the dashboard shows (by connection id)."""
    found = [(split, c.id) for c in reader.connections
             if c.msgtype == FLOAT64_MULTIARRAY and (split := split_topic(c.topic)) is not None]
    nodes = [node for (node, key), _ in found if key.suffix == "estimates"]
    node = nodes[0] if nodes else ""  # one node's outputs in a replay's estimates.mcap
    return node, {cid: key for (n, key), cid in found if n == node}


def _open_mcap(directory: Path, path: Path) -> ReplaySource:
    reader = _open_reader(path)
    try:
        node, keys = _shown(reader)
    finally:
        reader.close()
    if not node:
        raise BagError(f"{path}: holds no estimates (no ~/M/estimates or ~/M/frequency/estimates topic)")
    history = f"{node.rstrip('/')}/{HISTORY_TOPIC}"

    def items() -> Iterator[tuple]:
        reader = _open_reader(path)
        try:
            wanted = [c for c in reader.connections if c.id in keys or c.topic in ("/diagnostics", history)]
            for conn, _t, raw in reader.messages(connections=wanted):
                key = keys.get(conn.id)
                if key is None:
                    msg = reader.deserialize(raw, conn.msgtype)
                    history_item = ("maneuvers", getattr(msg, "data", ""))
                    yield history_item if conn.topic == history else ("diagnostics", statuses_of(msg))
                    continue
                try:
                    msg = decode(FLOAT64_MULTIARRAY, raw)
                except struct.error:
                    msg = None
                yield ("array", key, msg, None)
        except BagError:
            raise
        except Exception as exc:  # rosbags raises many types for a corrupt file
            raise BagError(f"{path}: cannot read: {exc}") from exc
        finally:
            with contextlib.suppress(Exception):
                reader.close()

    return ReplaySource(directory, path.name, node, items)


# ------------------------------------------------------------------ estimates.csv
def _check_header(path: Path) -> None:
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            header = next(csv.reader(fh), [])
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise BagError(f"{path}: cannot read: {exc}") from exc
    if tuple(header[: len(CSV_COLUMNS)]) != CSV_COLUMNS:
        raise BagError(f"{path}: not the {path.name} of rls-uncertainty replay (columns {', '.join(CSV_COLUMNS)})")


def _csv_items(path: Path, method: str) -> Iterator[tuple]:
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = csv.reader(fh)
            next(rows)
            yield from _csv_samples(path, rows, method)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise BagError(f"{path}: cannot read: {exc}") from exc


def _open_csv(directory: Path, tables: dict[str, Path]) -> ReplaySource:
    """The CSV files of ``tables`` (method -> path), merged in time order (each is in time
    order), so both methods' histories grow together while the page reads."""
    for path in tables.values():
        _check_header(path)

    def items() -> Iterator[tuple]:
        yield from heapq.merge(*(_csv_items(path, method) for method, path in tables.items()),
                               key=lambda item: item[1].stamp_ns)

    return ReplaySource(directory, " and ".join(p.name for p in tables.values()), "", items)


def _csv_samples(path: Path, rows: Iterator[list[str]], method: str) -> Iterator[tuple]:
    """``("sample", Sample)`` of consecutive rows of one time and model (one row per parameter).
    What rls-uncertainty replay never writes ends the reading (BagError naming the line): a
    row that does not parse, more than :data:`.model.MAX_MODELS` models or
    :data:`.model.MAX_PARAMETERS` parameters in a sample, a sample whose parameters are not
    those of its model's first sample (a row missing or repeated)."""
    group: list[tuple[int, str, str, tuple[float, ...]]] = []
    first: dict[str, tuple[tuple[str, ...], int]] = {}  # per model: its first sample's names and line
    start = 2

    def sample() -> tuple:
        names = tuple(r[2] for r in group)
        model = group[0][1]
        known = first.setdefault(model, (names, start))
        if names != known[0] or len(set(names)) != len(names):
            raise BagError(f"{path}: line {start}: {model} at {_time(group[0][0])} has the parameters "
                           f"{', '.join(names)}, its first sample (line {known[1]}) {', '.join(known[0])}: not a "
                           f"sample of {path.name} as rls-uncertainty replay writes it")
        return ("sample", _csv_sample(group, method))

    for line, row in enumerate(rows, start=2):
        try:
            parsed = _csv_row(row)
        except (ValueError, IndexError) as exc:
            raise BagError(f"{path}: line {line}: not a row of {path.name} ({exc})") from exc
        if group and parsed[:2] != group[0][:2]:
            yield sample()
            group, start = [], line
        if not group and parsed[1] not in first and len(first) == MAX_MODELS:
            raise BagError(f"{path}: line {line}: a model more ({parsed[1]!r}) than the {MAX_MODELS} of Eq. 2 "
                           f"({', '.join(first)} before it): not a file of rls-uncertainty replay")
        group.append(parsed)
        if len(group) > MAX_PARAMETERS:
            raise BagError(f"{path}: line {line}: {parsed[1]} at {_time(parsed[0])} has more than {MAX_PARAMETERS} "
                           "parameters (Eq. 2's regressors): not a file of rls-uncertainty replay")
    if group:
        yield sample()


def _time(stamp_ns: int) -> str:
    return f"{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d} s"


def _csv_row(row: list[str]) -> tuple[int, str, str, tuple[float, ...]]:
    """``(stamp_ns, model, parameter, (estimate, std_error, std_error_conventional, converged))``;
    ValueError naming what is wrong (a time after 2262, a value that is not finite, no name)."""
    sec, dot, nanosec = row[0].partition(".")
    if not sec.isdigit() or (dot and not nanosec.isdigit()) or len(nanosec) > 9:
        raise ValueError(f"time {row[0][:60]!r}")
    stamp = int(sec) * 1_000_000_000 + int(nanosec.ljust(9, "0")) if len(sec) <= 19 else MAX_STAMP_NS + 1
    if stamp > MAX_STAMP_NS:
        raise ValueError(f"time {row[0][:60]!r} s is after the year 2262")
    values = tuple(float(x) for x in row[3:7])
    if len(values) != 4 or not all(math.isfinite(x) for x in values):
        raise ValueError(f"values {row[3:7]!r}")
    if not row[1] or not row[2]:
        raise ValueError("no model or parameter name")
    return stamp, row[1], row[2], values


def _csv_sample(rows: list[tuple[int, str, str, tuple[float, ...]]], method: str) -> Sample:
    stamp, model = rows[0][:2]
    estimate, se, se_conventional, converged = (tuple(r[3][i] for r in rows) for i in range(4))
    return Sample(model, stamp, tuple(r[2] for r in rows), estimate, se, se_conventional, converged, None,
                  method)
