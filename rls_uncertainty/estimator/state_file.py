"""The estimator state file: a restarted node resumes the estimation where it stopped.

One ``.npz`` archive (numpy only, no pickle, entries stored uncompressed): the
:meth:`.EstimatorBank.state` arrays, plus a ``meta`` entry holding one JSON text with

* ``format``: :attr:`EstimatorBank.STATE_FORMAT` (a file of another layout is refused by name);
* ``fingerprint``: what the state must match to be resumed (aircraft, models, rate and the
  estimator settings; :meth:`.config.PipelineConfig.fingerprint`);
* ``sizes``, ``options``, ``bank_counters``: the rest of the bank's state (the options as
  :meth:`.options.EstimatorOptions.as_dict` writes them);
* ``samples_used``, ``zsum``, ``zsq``: the samples behind the estimates and the running sums
  of each model's output and its square (the R^2 of the model fit).

It is written with :func:`rls_uncertainty.files.atomic_file` (a fresh exclusive temporary file in the same
directory, fsync'ed, then renamed), so a crash never leaves half a file and a planted
temporary name or symlink is never written through.

**One user at a time.** A process that keeps a state file (the node) first claims it
(:func:`claim`): ``state_file`` must be a regular file or absent (a FIFO, a device, a directory or a socket
is refused without being opened: opening a FIFO blocks, and renaming a device aside would
take it from the system); the lock beside it (:class:`rls_uncertainty.files.FileLock`,
``.NAME.lock``) is taken without waiting, so a second process refuses the file instead of
renaming it aside or overwriting it; then, holding the lock, the temporaries of interrupted
saves (:func:`rls_uncertainty.files.temporaries`: ``.NAME.<16 hex digits>.tmp``) are removed:
no live process can be writing them.

**Reading never trusts the file.** :func:`load_state` checks, in this order and before
anything is allocated from the file's declarations: the archive (a regular file, a zip of at
most :data:`MAX_ENTRIES` ``.npy`` entries, none compressed or encrypted, their declared sizes
adding up to no more than the file holds: a small file cannot inflate); the ``meta`` entry
(a unicode scalar of at most :data:`MAX_META_BYTES`); every ``meta`` field (type, keys, value
range) and its agreement with the configuration the caller expects; then the array entries:
exactly the names the state layout has, each entry's declared size equal to what the
configuration and counters imply, each ``.npy`` header's dtype and shape as expected, every
float finite and every counter in range. Any failure is one :class:`StateFileError` whose
text names the file and the field. :meth:`EstimatorBank.from_state` checks shapes again (a
second line). :func:`set_aside` renames a refused (regular) file out of the way without
overwriting anything, so the node never replaces a file it could not use.
"""

from __future__ import annotations

import errno
import json
import math
import os
import stat
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, StateFileError
from ..files import FileLock, atomic_file, temporaries
from .bank import EstimatorBank
from .lag_storage import GROWTH_START
from .options import EstimatorOptions
from .state import COUNTERS

__all__ = [
    "EstimatorState",
    "StateFileClaim",
    "claim",
    "save_state",
    "load_state",
    "set_aside",
    "state_layout",
    "StateFileError",
    "MAX_ENTRIES",
    "MAX_META_BYTES",
]

MAX_ENTRIES = 32  # entries of a state archive (format 3 has 11 or 12)
MAX_META_BYTES = 1 << 20  # the meta entry's text as stored (4 bytes a character); a few kB in practice
_NPY_PREAMBLE = 12 + 10_000  # magic, version, header length and numpy's largest header text
_MAX_MODELS, _MAX_PARAMETERS = 64, 64
_MAX_LAGS = 10_000_000
_MAX_COUNT = 2**53  # samples: exact as a float
_GROWTH_START = GROWTH_START  # the lag capacity an all-lags bank starts with, doubled as samples arrive
_ANOTHER = "saved with another aircraft, model or estimator configuration"
_META_KEYS = ("format", "fingerprint", "sizes", "options", "bank_counters", "samples_used", "zsum", "zsq")
_F8, _I8, _B1 = np.dtype("<f8"), np.dtype("<i8"), np.dtype("|b1")


@dataclass
class EstimatorState:
    """What a state file holds: the estimator bank, the samples it has used, and the sums of
    each model's output ``z`` and ``z^2`` over them (one entry per model)."""

    bank: EstimatorBank
    samples_used: int
    output_sum: np.ndarray
    output_sum_squares: np.ndarray


def save_state(path: str | Path, state: EstimatorState, fingerprint: Mapping[str, Any]) -> None:
    """Write ``state`` (atomically) with the configuration ``fingerprint`` it belongs to."""
    bank = state.bank.state()
    meta = {
        "format": EstimatorBank.STATE_FORMAT,
        "fingerprint": fingerprint,
        "sizes": bank["sizes"],
        "options": bank["options"],
        "bank_counters": bank["counters"],
        "samples_used": int(state.samples_used),
        "zsum": np.asarray(state.output_sum, dtype=float).tolist(),
        "zsq": np.asarray(state.output_sum_squares, dtype=float).tolist(),
    }
    with atomic_file(Path(path)) as fh:
        np.savez(fh, meta=np.array(json.dumps(meta)), **bank["arrays"])


class _Invalid(Exception):
    """One problem with one field; :func:`load_state` adds the path."""


def _fail(field: str, problem: str) -> _Invalid:
    return _Invalid(f"field '{field}' {problem}")


# ---------------------------------------------------------------------------------------------
# The array layout of each state format, from the validated configuration and counters.


def _all_lags_capacity(k: int) -> int:
    """The lag capacity of an all-lags bank after ``k`` samples: 64, doubled until it holds k."""
    cap = _GROWTH_START
    while cap < k:
        cap *= 2
    return cap


Layout = dict[str, tuple[tuple[int, ...], np.dtype]]


def state_layout(
    sizes: tuple[int, ...], options: EstimatorOptions, counters: Mapping[str, Any], waiting: bool
) -> Layout:
    """``{entry name: (shape, dtype)}`` of the arrays of a state of a bank of ``sizes`` and
    ``options`` at ``counters`` (``waiting``: some model still waits for initialization), as
    :meth:`EstimatorBank.state` writes them: the estimator's own layout
    (:meth:`EstimatorBank.state_layout`), nothing read from the file. The caller bounds the
    size first (:func:`_implied_bytes`)."""
    return EstimatorBank.state_layout(sizes, options, counters, waiting)


def _implied_bytes(sizes: tuple[int, ...], counters: Mapping[str, Any]) -> int:
    """An upper bound of the memory an empty bank of ``sizes`` takes at ``counters``' lag
    capacity (histories, lag sums and products of y = (x, z))."""
    m, n1, cap = len(sizes), max(sizes) + 1, int(counters["cap"])
    return 8 * m * cap * (2 * n1 * n1 + 4 * 3 * n1 + 4)

# ---------------------------------------------------------------------------------------------
# meta


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _int(value: Any, field: str, low: int, high: int) -> int:
    if not _is_int(value):
        raise _fail(field, f"must be an integer, found {_kind(value)}")
    if not low <= value <= high:
        raise _fail(field, f"must be in [{low}, {high}], found {value}")
    checked: int = value  # (an int: _is_int)
    return checked


def _number(value: Any, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(field, f"must be a number, found {_kind(value)}")
    number = float(value)
    if not math.isfinite(number):
        raise _fail(field, f"must be finite, found {number}")
    return number


def _kind(value: Any) -> str:
    """A short description of a JSON value for a message (never the whole value)."""
    if isinstance(value, (dict, list)):
        return f"a {'JSON object' if isinstance(value, dict) else 'list'} of {len(value)} items"
    text = repr(value)
    return f"{type(value).__name__} {text[:40]}{'...' if len(text) > 40 else ''}"


def _short(value: Any) -> str:
    text = repr(list(value) if isinstance(value, tuple) else value)
    return text if len(text) <= 60 else text[:57] + "..."


def _object(value: Any, field: str, keys: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _fail(field, f"must be a JSON object, found {_kind(value)}")
    missing = [k for k in keys if k not in value]
    if missing:
        raise _fail(f"{field}.{missing[0]}" if field else missing[0], "is missing")
    extra = sorted(str(k) for k in value if k not in keys)
    if extra:
        raise _fail(f"{field}.{extra[0]}" if field else extra[0][:40], "is not part of a state file")
    checked: dict[str, Any] = value  # (a JSON object: string keys)
    return checked


def _check_format(meta: Any) -> None:
    if not isinstance(meta, dict):
        raise _fail("meta", f"must be a JSON object, found {_kind(meta)}")
    if "format" not in meta:
        raise _fail("format", "is missing")
    found = meta["format"]
    if found != EstimatorBank.STATE_FORMAT or not _is_int(found):
        raise _Invalid(
            f"state format {_kind(found) if not _is_int(found) else found}, this version reads "
            f"{EstimatorBank.STATE_FORMAT} (saved by another version; delete it to start afresh)"
        )


def _check_sizes(raw: Any) -> tuple[int, ...]:
    if not isinstance(raw, list) or not 1 <= len(raw) <= _MAX_MODELS:
        raise _fail("sizes", f"must be a list of 1 to {_MAX_MODELS} sizes, found {_kind(raw)}")
    return tuple(_int(s, f"sizes[{i}]", 1, _MAX_PARAMETERS) for i, s in enumerate(raw))


def _check_options(raw: Any) -> EstimatorOptions:
    try:
        options = EstimatorOptions.from_dict(raw)
    except ConfigError as exc:
        raise _fail("options", f"is not valid ({str(exc)[:160]})") from None
    if (options.held or 0) > _MAX_LAGS:
        raise _fail("options.lags", f"holds {options.held} lags, more than a state file may ({_MAX_LAGS})")
    return options


def _check_expected(
    sizes: tuple[int, ...], options: EstimatorOptions, expect: tuple[tuple[int, ...], EstimatorOptions] | None
) -> None:
    """The file's sizes and options are those of the configuration the caller continues with."""
    if expect is None:
        return
    want_sizes, want_options = expect
    if list(sizes) != list(want_sizes):
        raise _Invalid(f"{_ANOTHER}: field 'sizes' is {_short(sizes)}, the configuration has {_short(want_sizes)}")
    found, want = options.resolved().as_dict(), want_options.resolved().as_dict()
    for key in want:
        if found[key] != want[key]:
            raise _Invalid(f"{_ANOTHER}: field 'options.{key}' is {_short(found[key])}, the configuration has "
                           f"{_short(want[key])}")


def _check_counters(raw: Any, options: EstimatorOptions) -> dict[str, Any]:
    c = _object(raw, "bank_counters", COUNTERS)
    k = _int(c["k"], "bank_counters.k", 0, _MAX_COUNT)
    n_eff = _number(c["n_eff"], "bank_counters.n_eff")
    if not 0.0 <= n_eff <= k * (1.0 + 1e-9):
        raise _fail("bank_counters.n_eff", f"must be in [0, k = {k}], found {n_eff}")
    n_noise = _number(c["n_noise"], "bank_counters.n_noise")
    if not 0.0 <= n_noise <= k * (1.0 + 1e-9):
        raise _fail("bank_counters.n_noise", f"must be in [0, k = {k}], found {n_noise}")
    held = options.held
    want = _all_lags_capacity(k) if held is None else held + 1
    cap = _int(c["cap"], "bank_counters.cap", 1, 2 * _MAX_COUNT)
    if cap != want:
        lags = "all lags" if held is None else f"{held} lags"
        raise _fail("bank_counters.cap", f"is {cap}; {lags} after {k} samples hold {want}")
    return c


def _check_sums(meta: dict[str, Any], m: int) -> tuple[np.ndarray, np.ndarray]:
    out = []
    for key in ("zsum", "zsq"):
        values = meta[key]
        if not isinstance(values, list) or len(values) != m:
            raise _fail(key, f"must be a list of {m} numbers (one per model), found {_kind(values)}")
        out.append(np.array([_number(v, f"{key}[{i}]") for i, v in enumerate(values)]))
    if np.any(out[1] < 0):
        raise _fail("zsq", "must not be negative (sums of squares)")
    return out[0], out[1]


# ---------------------------------------------------------------------------------------------
# the archive


def _entries(zf: zipfile.ZipFile, file_size: int) -> dict[str, zipfile.ZipInfo]:
    """The archive's entries by array name, checked before any is read."""
    infos = zf.infolist()
    if len(infos) > MAX_ENTRIES:
        raise _Invalid(f"not a state file: {len(infos)} entries (a state has at most {MAX_ENTRIES})")
    entries: dict[str, zipfile.ZipInfo] = {}
    declared = 0
    for info in infos:
        name = info.filename
        shown = name[:40]
        if not name.endswith(".npy") or not name[:-4].isidentifier():
            raise _Invalid(f"not a state file: entry '{shown}' is not a numpy array of a state")
        if name[:-4] in entries:
            raise _Invalid(f"not a state file: entry '{shown}' appears twice")
        if info.flag_bits & 0x1:
            raise _Invalid(f"not a state file: entry '{shown}' is encrypted")
        if info.compress_type != zipfile.ZIP_STORED:
            raise _Invalid(f"not a state file: entry '{shown}' is compressed (state files are written "
                           "uncompressed; it is not inflated)")
        declared += info.file_size
        entries[name[:-4]] = info
    if declared > file_size:
        raise _Invalid(f"not a state file: its entries declare {declared} bytes, the file holds {file_size}")
    if "meta" not in entries:
        raise _fail("meta", "is missing (not a state file)")
    return entries


def _read_array(zf: zipfile.ZipFile, info: zipfile.ZipInfo, field: str, shape: tuple[int, ...] | None,
                dtype: np.dtype | None) -> np.ndarray:
    """One ``.npy`` entry. Its header must declare ``dtype`` (kind and size, either byte
    order) and ``shape`` (``None``: any, checked by the caller from the header's values before
    the data is read), and the entry must hold exactly that many bytes after the header."""
    with zf.open(info) as fp:
        try:
            version = np.lib.format.read_magic(fp)
            if version == (1, 0):
                found_shape, fortran, found = np.lib.format.read_array_header_1_0(fp)
            elif version == (2, 0):
                found_shape, fortran, found = np.lib.format.read_array_header_2_0(fp)
            else:
                raise ValueError(f"npy format version {version}")
        except (ValueError, SyntaxError, EOFError, TypeError) as exc:
            raise _fail(field, f"is not a readable numpy array ({str(exc)[:80]})") from None
        if found.hasobject or found.fields is not None or found.subdtype is not None:
            raise _fail(field, f"has dtype {found.str}, not plain numbers")
        if dtype is not None and (found.kind, found.itemsize) != (dtype.kind, dtype.itemsize):
            raise _fail(field, f"has dtype {found.str}, expected {dtype.str}")
        if shape is not None and tuple(found_shape) != shape:
            raise _fail(field, f"has shape {tuple(found_shape)}, the configuration implies {shape}")
        nbytes = math.prod(found_shape) * found.itemsize
        if fp.tell() + nbytes != info.file_size:
            raise _fail(field, f"holds {info.file_size - fp.tell()} bytes of data, its shape needs {nbytes}")
        data = fp.read(nbytes)
    if len(data) != nbytes:  # pragma: no cover - zipfile checks the size and CRC
        raise _fail(field, "is truncated")
    native = found.newbyteorder("=") if found.byteorder in "<>" else found
    arr = np.frombuffer(data, dtype=found).astype(native, copy=True)
    return arr.reshape(found_shape, order="F" if fortran else "C")


def _read_meta(zf: zipfile.ZipFile, info: zipfile.ZipInfo) -> Any:
    if info.file_size > MAX_META_BYTES + _NPY_PREAMBLE:
        raise _fail("meta", f"declares {info.file_size} bytes (at most {MAX_META_BYTES})")
    arr = _read_array(zf, info, "meta", (), None)
    if arr.dtype.kind != "U":
        raise _fail("meta", f"must be a JSON text, found an array of dtype {arr.dtype.str}")
    try:
        return json.loads(str(arr[()]))
    except (ValueError, RecursionError) as exc:
        raise _fail("meta", f"is not valid JSON ({str(exc)[:80]})") from None


def _check_values(arrays: dict[str, np.ndarray], k: int) -> None:
    for name, arr in arrays.items():
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise _fail(f"arrays.{name}", "holds NaN or infinite values (a bank's state never does)")
    for name, low, high in (("ready_at", 0, k), ("repairs", 0, _MAX_COUNT)):
        counts = arrays.get(name)
        if counts is not None and counts.size > 0 and not (counts.min() >= low and counts.max() <= high):
            raise _fail(f"arrays.{name}", f"must hold counts in [{low}, {high}]")


Expected = tuple[tuple[int, ...], EstimatorOptions] | None


def _load(path: Path, fingerprint: Mapping[str, Any], expect: Expected) -> EstimatorState:
    try:
        # Without waiting: a FIFO put here after the caller's claim cannot block the read.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise _Invalid("no such state file") from None
    except OSError as exc:
        raise _Invalid(f"not a readable state file ({exc.strerror or exc})") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise _Invalid(f"not a readable state file ({_file_kind(st.st_mode)}, not a regular file)")
    with os.fdopen(fd, "rb") as fh:
        try:
            zf = zipfile.ZipFile(fh)
        except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, OSError, EOFError) as exc:
            raise _Invalid(f"not a readable state file (not a zip archive: {str(exc)[:80]})") from None
        with zf:
            try:
                return _load_archive(zf, st.st_size, fingerprint, expect)
            except (zipfile.BadZipFile, OSError, EOFError) as exc:  # a CRC or size mismatch while reading
                raise _Invalid(f"not a readable state file ({str(exc)[:80]})") from None


def _load_archive(
    zf: zipfile.ZipFile, file_size: int, fingerprint: Mapping[str, Any], expect: Expected
) -> EstimatorState:
    entries = _entries(zf, file_size)
    meta = _read_meta(zf, entries["meta"])
    _check_format(meta)
    meta = _object(meta, "", _META_KEYS)
    sizes, options = _check_sizes(meta["sizes"]), _check_options(meta["options"])
    _check_expected(sizes, options, expect)
    # Compare as JSON would store it (tuples become lists).
    if meta["fingerprint"] != json.loads(json.dumps(fingerprint)):
        raise _Invalid(_ANOTHER)
    counters = _check_counters(meta["bank_counters"], options)
    samples_used = _int(meta["samples_used"], "samples_used", 0, _MAX_COUNT)
    zsum, zsq = _check_sums(meta, len(sizes))
    implied = _implied_bytes(sizes, counters)
    if implied > 64 * file_size + (16 << 20):  # the arrays of such a state would be in the file
        raise _fail(
            "bank_counters.cap", f"implies about {implied} bytes of estimator state; the file holds {file_size}"
        )
    arrays = _read_arrays(zf, entries, sizes, options, counters)
    try:
        bank = EstimatorBank.from_state(
            {"format": meta["format"], "sizes": list(sizes), "options": meta["options"], "counters": counters,
             "arrays": arrays}
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:  # the second line: the bank's own checks
        raise _Invalid(f"inconsistent estimator state ({str(exc)[:120]})") from None
    return EstimatorState(bank=bank, samples_used=samples_used, output_sum=zsum, output_sum_squares=zsq)


def _read_arrays(
    zf: zipfile.ZipFile, entries: dict[str, zipfile.ZipInfo], sizes: tuple[int, ...], options: EstimatorOptions,
    counters: dict[str, Any],
) -> dict[str, np.ndarray]:
    """The state's arrays: exactly the entries of the configuration's layout, each declared
    size checked before anything is read, then each header and every value."""
    names = set(entries) - {"meta"}
    if "ready" not in entries:
        raise _fail("arrays.ready", "is missing")
    ready = _read_array(zf, entries["ready"], "arrays.ready", (len(sizes),), np.dtype(bool))
    layout = state_layout(sizes, options, counters, waiting=not bool(ready.all()))
    missing, extra = sorted(set(layout) - names), sorted(names - set(layout))
    if missing:
        raise _fail(f"arrays.{missing[0]}", "is missing")
    if extra:
        raise _fail(f"arrays.{extra[0]}", "is not part of this configuration's state")
    for name, (want_shape, want_dtype) in layout.items():  # declared sizes, before reading anything
        nbytes = math.prod(want_shape) * want_dtype.itemsize
        declared = entries[name].file_size
        if not nbytes < declared <= nbytes + _NPY_PREAMBLE:
            raise _fail(f"arrays.{name}", f"declares {declared} bytes; the configuration implies an array "
                        f"{want_shape} of {nbytes} bytes")
    arrays = {name: _read_array(zf, entries[name], f"arrays.{name}", *layout[name]) for name in sorted(names)}
    _check_values(arrays, counters["k"])
    return arrays


def load_state(
    path: str | Path, fingerprint: Mapping[str, Any], *, expect: Expected = None
) -> EstimatorState:
    """The state saved in ``path``. Raises :class:`StateFileError` naming the file and the
    field when the file is missing, unreadable, not a state file, of another format, saved with
    other sizes or options than ``expect`` or another configuration than ``fingerprint``, or
    inconsistent (see the module docstring).

    ``expect``: ``(sizes, options)`` of the bank the caller will continue with; the file's
    must be the same (the options with their defaults resolved)."""
    path = Path(path)
    try:
        return _load(path, fingerprint, expect)
    except _Invalid as exc:
        raise StateFileError(f"{path}: {exc}") from None


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _file_kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


@dataclass
class StateFileClaim:
    """A process's hold on its state file (:func:`claim`): the lock, and the temporaries of
    interrupted saves it removed."""

    path: Path
    lock: FileLock
    removed: list[Path]

    def release(self) -> None:
        """Free the lock (after the last save)."""
        self.lock.release()


def claim(path: str | Path) -> StateFileClaim:
    """Take ``path`` for this process (see the module docstring): a regular file or none
    (never opened here), its lock taken, stale temporaries removed. Raises
    :class:`StateFileError`, one line naming the file, when it is not a regular file, when
    another process holds it, or when its lock file cannot be made (a missing or read-only
    directory): nothing is renamed, removed or written then."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        pass  # absent (or a dangling link): the load says so
    except OSError as exc:
        raise StateFileError(f"{path}: cannot be examined ({exc.strerror or exc})") from None
    else:
        if not stat.S_ISREG(st.st_mode):
            raise StateFileError(f"{path}: is {_file_kind(st.st_mode)}, not a regular file (it is not opened, "
                                 "renamed or replaced); set state_file to a file's path")
    try:
        lock = FileLock(path)
    except BlockingIOError as exc:
        raise StateFileError(f"{path}: in use: its lock {exc.filename} is {exc.strerror} (another node "
                             "estimating with it); give each node its own state_file") from None
    except OSError as exc:
        where = exc.filename or path
        raise StateFileError(f"{path}: cannot take its lock {where} ({exc.strerror or exc})") from None
    removed = []
    for tmp in temporaries(path):
        try:
            tmp.unlink()
        except OSError:
            continue  # gone already, or not ours to remove: it stays, harmless
        removed.append(tmp)
    return StateFileClaim(path, lock, removed)


def set_aside(path: str | Path, now: datetime | None = None) -> Path:
    """Rename ``path`` to ``PATH.rejected-YYYYmmddTHHMMSSZ`` (UTC; ``-1``, ``-2``, ... appended
    while that name is taken) and return the new path. An existing file is never replaced: the
    new name is made with a hard link (which fails if the name exists) and the old one removed;
    where the file system has no hard links, a rename to a name checked to be free. A symlink
    is moved as the link itself. Raises :class:`OSError` when it cannot."""
    path = Path(path)
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%dT%H%M%SZ")
    base = f"{path.name}.rejected-{stamp}"
    for i in range(1000):
        target = path.with_name(base if i == 0 else f"{base}-{i}")
        try:
            os.link(path, target, follow_symlinks=False)
        except FileExistsError:
            continue
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.EXDEV, errno.ENOTSUP, errno.EOPNOTSUPP, errno.ENOSYS,
                                 errno.EMLINK, errno.EACCES):
                raise
            if os.path.lexists(target):
                continue
            os.rename(path, target)  # no hard links here (or a directory): the name was free just now
            return target
        os.unlink(path)
        return target
    raise OSError(errno.EEXIST, f"no free name for {path} after 1000 tries")
