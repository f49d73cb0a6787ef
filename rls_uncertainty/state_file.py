"""The estimator state file: a restarted node resumes the estimation where it stopped.

The file side of :mod:`.estimator.state` (which maps a bank to plain data and checks each
field of a saved one): locks, the atomic write, the archive read without trusting it, and the
renaming of a refused file. The pipeline saves and loads through it, the node claims and sets
aside through it; it sits beside :mod:`.files`, whose write-then-rename and lock it uses, so
that the numerical core opens no file.

One ``.npz`` archive (numpy only, no pickle, entries stored uncompressed): the
:meth:`.EstimatorBank.state` arrays, plus a ``meta`` entry holding one JSON text with

* ``format``: :attr:`EstimatorBank.STATE_FORMAT` (a file of another layout is refused by name);
* ``fingerprint``: what the state must match to be resumed (aircraft, models, rate, the
  estimator settings, with iv the instruments' and with the frequency domain the ``frequency``
  settings; :meth:`.config.PipelineConfig.fingerprint`);
* ``sizes``, ``options``, ``bank_counters``: the rest of the bank's state (the options as
  :meth:`.options.EstimatorOptions.as_dict` writes them);
* ``samples_used``, ``zsum``, ``zsq``: the samples behind the estimates and the running sums
  of each model's output and its square (the R^2 of the model fit);
* ``instruments`` (``estimator.algorithm iv`` only): the counters of the instrument path
  (:meth:`.datapath.instrument_path.InstrumentPath.snapshot`), whose arrays are the ``iv_``
  entries: the auxiliary model, its bare least-squares fit and the rows waiting for it, or the
  delayed regressors held, and the weak-instrument sums. Without iv the file has neither;
* ``frequency`` (``estimator.method`` ``frequency`` or ``both`` only): the counters of the
  frequency-domain estimator's record (:meth:`.datapath.frequency_path.FrequencyPath.snapshot`,
  :mod:`.frequency.state`: the samples in it, the last evaluation's sample, the repairs
  counted, whether an evaluation is due), whose arrays are the ``fq_`` entries: the recursive
  Fourier transforms, the first sample and the trim's sum, the lag-product sums and the window
  of the last samples, with iv the instruments' cross sums, and the last evaluation's results
  (estimates, covariances, standard errors, residual autocovariance, output variance, the
  models ready, solved and withheld). With ``estimator.method time`` the file has neither.

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
range; the estimator's fields by :mod:`.estimator.state`) and its agreement with the
configuration the caller expects; then the array entries: exactly the names the state layout
has, each entry's declared size equal to what the configuration and counters imply, each
``.npy`` header's dtype and shape as expected, every float finite and every counter in range.
Any failure is one :class:`StateFileError` whose text names the file and the field.
:meth:`EstimatorBank.from_state` checks shapes again (a second line). :func:`set_aside`
renames a refused (regular) file out of the way without overwriting anything, so the node
never replaces a file it could not use.
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
from typing import Any, Protocol

import numpy as np

from .errors import StateFileError
from .estimator.bank import EstimatorBank
from .estimator.options import EstimatorOptions
from .estimator.state import (
    ANOTHER_CONFIGURATION,
    MAX_COUNT,
    check_counters,
    check_expected,
    check_format,
    check_options,
    check_sizes,
    check_values,
    describe,
    implied_bytes,
    integer,
    invalid,
    json_object,
    number,
)
from .files import FileLock, atomic_file, temporaries

__all__ = [
    "EstimatorState",
    "StateFileClaim",
    "claim",
    "save_state",
    "load_state",
    "set_aside",
    "StateFileError",
    "MAX_ENTRIES",
    "MAX_META_BYTES",
]

MAX_ENTRIES = 48  # entries of a state archive (the meta, a bank's 11 to 14 arrays, the instruments' 6 or 16,
# the frequency-domain record's 12 or 13)
MAX_META_BYTES = 1 << 20  # the meta entry's text as stored (4 bytes a character); a few kB in practice
_NPY_PREAMBLE = 12 + 10_000  # magic, version, header length and numpy's largest header text
_META_KEYS = ("format", "fingerprint", "sizes", "options", "bank_counters", "samples_used", "zsum", "zsq")


@dataclass
class EstimatorState:
    """What a state file holds: the estimator bank, the samples it has used, and the sums of
    each model's output ``z`` and ``z^2`` over them (one entry per model)."""

    bank: EstimatorBank
    samples_used: int
    output_sum: np.ndarray
    output_sum_squares: np.ndarray
    instruments: dict[str, Any] | None = None  # estimator.algorithm iv: InstrumentPath.snapshot()
    frequency: dict[str, Any] | None = None  # estimator.method frequency or both: FrequencyPath.snapshot()


class InstrumentPath(Protocol):
    """What a state's instruments are checked against: the instrument path the caller
    continues with (:class:`.datapath.instrument_path.InstrumentPath`)."""

    def state_spec(self) -> dict[str, Any]:
        """The source, the counters' ranges and flags, the counter of the rows held, the span."""

    def state_layout(self, rows: int) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
        """``{name: (shape, dtype)}`` of the arrays with ``rows`` rows held."""


class FrequencyPath(Protocol):
    """What a state's frequency-domain record is checked against: the frequency path the
    caller continues with (:class:`.datapath.frequency_path.FrequencyPath`)."""

    def state_spec(self) -> dict[str, Any]:
        """The arrays' name prefix, the counters' ranges and flags, the results' names."""

    def state_layout(self, evaluated_at: int) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
        """``{name: (shape, dtype)}`` of the record's arrays, last evaluated at ``evaluated_at``."""


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
    arrays = dict(bank["arrays"])
    if state.instruments is not None:
        meta["instruments"] = state.instruments["counters"]
        arrays.update(state.instruments["arrays"])
    if state.frequency is not None:
        meta["frequency"] = state.frequency["counters"]
        arrays.update(state.frequency["arrays"])
    with atomic_file(Path(path)) as fh:
        np.savez(fh, meta=np.array(json.dumps(meta)), **arrays)


def _check_sums(meta: dict[str, Any], m: int) -> tuple[np.ndarray, np.ndarray]:
    out = []
    for key in ("zsum", "zsq"):
        values = meta[key]
        if not isinstance(values, list) or len(values) != m:
            raise invalid(key, f"must be a list of {m} numbers (one per model), found {describe(values)}")
        out.append(np.array([number(v, f"{key}[{i}]") for i, v in enumerate(values)]))
    if np.any(out[1] < 0):
        raise invalid("zsq", "must not be negative (sums of squares)")
    return out[0], out[1]



# ---------------------------------------------------------------------------------------------
# the archive


def _entries(zf: zipfile.ZipFile, file_size: int) -> dict[str, zipfile.ZipInfo]:
    """The archive's entries by array name, checked before any is read."""
    infos = zf.infolist()
    if len(infos) > MAX_ENTRIES:
        raise StateFileError(f"not a state file: {len(infos)} entries (a state has at most {MAX_ENTRIES})")
    entries: dict[str, zipfile.ZipInfo] = {}
    declared = 0
    for info in infos:
        name = info.filename
        shown = name[:40]
        if not name.endswith(".npy") or not name[:-4].isidentifier():
            raise StateFileError(f"not a state file: entry '{shown}' is not a numpy array of a state")
        if name[:-4] in entries:
            raise StateFileError(f"not a state file: entry '{shown}' appears twice")
        if info.flag_bits & 0x1:
            raise StateFileError(f"not a state file: entry '{shown}' is encrypted")
        if info.compress_type != zipfile.ZIP_STORED:
            raise StateFileError(f"not a state file: entry '{shown}' is compressed (state files are written "
                           "uncompressed; it is not inflated)")
        declared += info.file_size
        entries[name[:-4]] = info
    if declared > file_size:
        raise StateFileError(f"not a state file: its entries declare {declared} bytes, the file holds {file_size}")
    if "meta" not in entries:
        raise invalid("meta", "is missing (not a state file)")
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
            raise invalid(field, f"is not a readable numpy array ({str(exc)[:80]})") from None
        if found.hasobject or found.fields is not None or found.subdtype is not None:
            raise invalid(field, f"has dtype {found.str}, not plain numbers")
        if dtype is not None and (found.kind, found.itemsize) != (dtype.kind, dtype.itemsize):
            raise invalid(field, f"has dtype {found.str}, expected {dtype.str}")
        if shape is not None and tuple(found_shape) != shape:
            raise invalid(field, f"has shape {tuple(found_shape)}, the configuration implies {shape}")
        nbytes = math.prod(found_shape) * found.itemsize
        if fp.tell() + nbytes != info.file_size:
            raise invalid(field, f"holds {info.file_size - fp.tell()} bytes of data, its shape needs {nbytes}")
        data = fp.read(nbytes)
    if len(data) != nbytes:  # pragma: no cover - zipfile checks the size and CRC
        raise invalid(field, "is truncated")
    native = found.newbyteorder("=") if found.byteorder in "<>" else found
    arr = np.frombuffer(data, dtype=found).astype(native, copy=True)
    return arr.reshape(found_shape, order="F" if fortran else "C")


def _read_meta(zf: zipfile.ZipFile, info: zipfile.ZipInfo) -> Any:
    if info.file_size > MAX_META_BYTES + _NPY_PREAMBLE:
        raise invalid("meta", f"declares {info.file_size} bytes (at most {MAX_META_BYTES})")
    arr = _read_array(zf, info, "meta", (), None)
    if arr.dtype.kind != "U":
        raise invalid("meta", f"must be a JSON text, found an array of dtype {arr.dtype.str}")
    try:
        return json.loads(str(arr[()]))
    except (ValueError, RecursionError) as exc:
        raise invalid("meta", f"is not valid JSON ({str(exc)[:80]})") from None


Expected = tuple[tuple[int, ...], EstimatorOptions] | None


def _load(path: Path, fingerprint: Mapping[str, Any], expect: Expected,
          paths: tuple[InstrumentPath | None, FrequencyPath | None]) -> EstimatorState:
    try:
        # Without waiting: a FIFO put here after the caller's claim cannot block the read.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise StateFileError("no such state file") from None
    except OSError as exc:
        raise StateFileError(f"not a readable state file ({exc.strerror or exc})") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise StateFileError(f"not a readable state file ({_file_kind(st.st_mode)}, not a regular file)")
    with os.fdopen(fd, "rb") as fh:
        try:
            zf = zipfile.ZipFile(fh)
        except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, OSError, EOFError) as exc:
            raise StateFileError(f"not a readable state file (not a zip archive: {str(exc)[:80]})") from None
        with zf:
            try:
                return _load_archive(zf, st.st_size, fingerprint, expect, *paths)
            except (zipfile.BadZipFile, OSError, EOFError) as exc:  # a CRC or size mismatch while reading
                raise StateFileError(f"not a readable state file ({str(exc)[:80]})") from None


def _load_archive(
    zf: zipfile.ZipFile, file_size: int, fingerprint: Mapping[str, Any], expect: Expected,
    instruments: InstrumentPath | None, frequency: FrequencyPath | None,
) -> EstimatorState:
    entries = _entries(zf, file_size)
    meta = _read_meta(zf, entries["meta"])
    check_format(meta)
    optional = (() if instruments is None else ("instruments",)) + (() if frequency is None else ("frequency",))
    meta = json_object(meta, "", _META_KEYS + optional)
    sizes, options = check_sizes(meta["sizes"]), check_options(meta["options"])
    check_expected(sizes, options, expect)
    # Compare as JSON would store it (tuples become lists).
    if meta["fingerprint"] != json.loads(json.dumps(fingerprint)):
        raise StateFileError(ANOTHER_CONFIGURATION)
    counters = check_counters(meta["bank_counters"], options)
    samples_used = integer(meta["samples_used"], "samples_used", 0, MAX_COUNT)
    zsum, zsq = _check_sums(meta, len(sizes))
    implied = implied_bytes(sizes, counters)
    if implied > 64 * file_size + (16 << 20):  # the arrays of such a state would be in the file
        raise invalid(
            "bank_counters.cap", f"implies about {implied} bytes of estimator state; the file holds {file_size}"
        )
    saved_instruments = None
    if instruments is not None:
        saved_instruments = _read_instruments(zf, entries, meta["instruments"], instruments)
        entries = {k: v for k, v in entries.items() if k not in saved_instruments["arrays"]}
    saved_frequency = None
    if frequency is not None:
        saved_frequency = _read_frequency(zf, entries, meta["frequency"], frequency)
        entries = {k: v for k, v in entries.items() if k not in saved_frequency["arrays"]}
    arrays = _read_arrays(zf, entries, sizes, options, counters)
    try:
        bank = EstimatorBank.from_state(
            {"format": meta["format"], "sizes": list(sizes), "options": meta["options"], "counters": counters,
             "arrays": arrays}
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:  # the second line: the bank's own checks
        raise StateFileError(f"inconsistent estimator state ({str(exc)[:120]})") from None
    return EstimatorState(bank=bank, samples_used=samples_used, output_sum=zsum, output_sum_squares=zsq,
                          instruments=saved_instruments, frequency=saved_frequency)


def _read_arrays(
    zf: zipfile.ZipFile, entries: dict[str, zipfile.ZipInfo], sizes: tuple[int, ...], options: EstimatorOptions,
    counters: dict[str, Any],
) -> dict[str, np.ndarray]:
    """The state's arrays: exactly the entries of the configuration's layout, each declared
    size checked before anything is read, then each header and every value."""
    names = set(entries) - {"meta"}
    if "ready" not in entries:
        raise invalid("arrays.ready", "is missing")
    ready = _read_array(zf, entries["ready"], "arrays.ready", (len(sizes),), np.dtype(bool))
    layout = EstimatorBank.state_layout(sizes, options, counters, waiting=not bool(ready.all()))
    arrays = _read_layout(zf, entries, names, layout)
    check_values(arrays, counters["k"])
    return arrays


Layout = dict[str, tuple[tuple[int, ...], np.dtype]]


def _read_layout(zf: zipfile.ZipFile, entries: dict[str, zipfile.ZipInfo], names: set[str],
                 layout: Layout) -> dict[str, np.ndarray]:
    """The entries ``names``, which must be exactly those of ``layout``: each declared size
    checked before anything is read, then each header."""
    missing, extra = sorted(set(layout) - names), sorted(names - set(layout))
    if missing:
        raise invalid(f"arrays.{missing[0]}", "is missing")
    if extra:
        raise invalid(f"arrays.{extra[0]}", "is not part of this configuration's state")
    for name, (want_shape, want_dtype) in layout.items():  # declared sizes, before reading anything
        nbytes = math.prod(want_shape) * want_dtype.itemsize
        declared = entries[name].file_size
        if not nbytes < declared <= nbytes + _NPY_PREAMBLE:
            raise invalid(f"arrays.{name}", f"declares {declared} bytes; the configuration implies an array "
                        f"{want_shape} of {nbytes} bytes")
    return {name: _read_array(zf, entries[name], f"arrays.{name}", *layout[name]) for name in sorted(names)}


# ---------------------------------------------------------------------------------------------
# the instruments (estimator.algorithm iv)


def _read_instruments(zf: zipfile.ZipFile, entries: dict[str, zipfile.ZipInfo], raw: Any,
                      path: InstrumentPath) -> dict[str, Any]:
    """The instruments' state (:meth:`.InstrumentPath.snapshot`) checked against ``path``,
    the one the caller continues with: the counters of ``meta.instruments`` by type and range,
    the ``iv_`` entries by layout, then their values."""
    spec = path.state_spec()
    counters = _instrument_counters(raw, spec)
    layout = path.state_layout(counters[spec["rows"]])
    names = {k for k in entries if k.startswith("iv_")}
    arrays = _read_layout(zf, entries, names, layout)
    _check_instrument_values(arrays, counters, spec["span_ns"])
    return {"counters": counters, "arrays": arrays}


def _typed_counters(c: Mapping[str, Any], spec: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    """The ``integers`` of ``spec`` (name: (low, high)) and its ``flags`` (booleans) read from
    ``c``, each checked; an error names ``prefix.name``."""
    out: dict[str, Any] = {}
    for name, (low, high) in spec["integers"].items():
        out[name] = integer(c[name], f"{prefix}.{name}", low, high)
    for name in spec["flags"]:
        if not isinstance(c[name], bool):
            raise invalid(f"{prefix}.{name}", f"must be true or false, found {describe(c[name])}")
        out[name] = c[name]
    return out


def _instrument_counters(raw: Any, spec: Mapping[str, Any]) -> dict[str, Any]:
    c = json_object(raw, "instruments", ("source", *spec["integers"], *spec["flags"]))
    if c["source"] != spec["source"]:
        raise StateFileError(f"{ANOTHER_CONFIGURATION}: field 'instruments.source' is {describe(c['source'])}, "
                             f"the configuration has {spec['source']}")
    out: dict[str, Any] = {"source": spec["source"], **_typed_counters(c, spec, "instruments")}
    if "has_model" in out and not out["has_model"] and out["since_refresh"]:
        raise invalid("instruments.since_refresh", "must be 0 while there is no auxiliary model")
    if out.get("has_model") and out["waiting"]:
        raise invalid("instruments.waiting", "must be 0 once the auxiliary model exists")
    return out


def _check_instrument_values(arrays: Mapping[str, np.ndarray], counters: Mapping[str, Any],
                             span_ns: int | None) -> None:
    """Every float finite (``rho_min``: in [0, 1], or NaN before the first judgement), the
    stamps increasing (and within ``span_ns``), the auxiliary model stable (all zeros before
    it exists), the bare fit's ``D`` and ``theta`` zero before it starts."""
    for name, arr in arrays.items():
        if name == "iv_rho_min":
            if not np.all(np.isnan(arr) | ((arr >= 0.0) & (arr <= 1.0))):
                raise invalid("arrays.iv_rho_min", "must hold correlations in [0, 1] (NaN before the first)")
        elif arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise invalid(f"arrays.{name}", "holds NaN or infinite values (the instruments' state never does)")
    for name in ("iv_backlog_tag", "iv_history_stamp"):
        t = arrays.get(name)
        if t is not None and t.size > 1 and not np.all(t[1:] > t[:-1]):
            raise invalid(f"arrays.{name}", "must hold increasing stamps")
        if t is not None and t.size and span_ns is not None and int(t[-1]) - int(t[0]) > span_ns:
            raise invalid(f"arrays.{name}", f"spans more than the delay of {span_ns} ns")
    if "has_model" in counters:
        model = [arrays[f"iv_{k}"] for k in ("state", "Phi", "Gamma")]
        if not counters["has_model"] and any(a.any() for a in model):
            raise invalid("arrays.iv_Phi", "must be zero (with the state and Gamma) while there is no model")
        if counters["has_model"] and not np.abs(np.linalg.eigvals(arrays["iv_Phi"])).max() < 1.0:
            raise invalid("arrays.iv_Phi", "is not the discrete model of a stable aircraft (an eigenvalue "
                          "outside the unit circle)")
        if not counters["bare_ready"] and (arrays["iv_bare_D"].any() or arrays["iv_bare_theta"].any()):
            raise invalid("arrays.iv_bare_D", "must be zero (with bare_theta) before the bare fit starts")


# ---------------------------------------------------------------------------------------------
# the frequency-domain record (estimator.method frequency or both)


def _read_frequency(zf: zipfile.ZipFile, entries: dict[str, zipfile.ZipInfo], raw: Any,
                    path: FrequencyPath) -> dict[str, Any]:
    """The frequency-domain record (:meth:`.FrequencyPath.snapshot`) checked against ``path``,
    the one the caller continues with: the counters of ``meta.frequency`` by type and range,
    the ``fq_`` entries by layout, then their values (finite; zeros before the first sample)."""
    spec = path.state_spec()
    c = json_object(raw, "frequency", (*spec["integers"], *spec["flags"]))
    counters = _typed_counters(c, spec, "frequency")
    n = counters["n"]
    if counters["evaluated_at"] > n:
        raise invalid("frequency.evaluated_at", f"must be at most the record's {n} samples")
    if counters["due"] and (n == 0 or counters["evaluated_at"] == n):
        raise invalid("frequency.due", "must be false before the first sample and at the sample evaluated")
    names = {k for k in entries if k.startswith(spec["prefix"])}
    arrays = _read_layout(zf, entries, names, path.state_layout(counters["evaluated_at"]))
    _check_frequency_values(arrays, spec["results"], n, counters["evaluated_at"])
    return {"counters": counters, "arrays": arrays}


def _check_frequency_values(arrays: Mapping[str, np.ndarray], results: tuple[str, ...], n: int,
                            evaluated_at: int) -> None:
    """The record finite (all zeros before the first sample); the last evaluation's results
    without infinities (NaN where none), standard errors not negative, ready
    models solved and not withheld, and nothing before the first evaluation."""
    for name, arr in arrays.items():
        if name in results:
            if np.isinf(arr).any():
                raise invalid(f"arrays.{name}", "holds infinite values (results are finite or NaN)")
            if evaluated_at == 0 and not (np.isnan(arr).all() if arr.dtype.kind == "f" else not arr.any()):
                raise invalid(f"arrays.{name}", "must be NaN (flags false) before the first evaluation")
        elif not np.isfinite(arr).all():
            raise invalid(f"arrays.{name}", "holds NaN or infinite values (the frequency-domain record never does)")
        elif n == 0 and arr.any():
            raise invalid(f"arrays.{name}", "must be zero before the first sample (frequency.n is 0)")
    for name in ("se", "published_se"):
        if (arrays[f"fq_{name}"] < 0).any():
            raise invalid(f"arrays.fq_{name}", "must not be negative")
    ready, solved, withheld = arrays["fq_flags"]
    if (ready & ~solved).any() or (ready & withheld).any():
        raise invalid("arrays.fq_flags", "has a model ready that is not solved or is withheld")


def load_state(
    path: str | Path, fingerprint: Mapping[str, Any], *, expect: Expected = None,
    instruments: InstrumentPath | None = None, frequency: FrequencyPath | None = None,
) -> EstimatorState:
    """The state saved in ``path``. Raises :class:`StateFileError` naming the file and the
    field when the file is missing, unreadable, not a state file, of another format, saved with
    other sizes or options than ``expect`` or another configuration than ``fingerprint``, or
    inconsistent (see the module docstring).

    ``expect``: ``(sizes, options)`` of the bank the caller will continue with; the file's
    must be the same (the options with their defaults resolved). ``instruments``: the
    instrument path the caller will continue with (``estimator.algorithm iv``): the file must
    hold its state (:meth:`.InstrumentPath.snapshot`), checked against it, returned in
    :attr:`EstimatorState.instruments`; without it, a file holding instruments is refused.
    ``frequency``: the frequency path the caller will continue with (``estimator.method``
    frequency or both): the file must hold its record (:meth:`.FrequencyPath.snapshot`),
    checked against it, returned in :attr:`EstimatorState.frequency`; without it, a file
    holding one is refused."""
    path = Path(path)
    try:
        return _load(path, fingerprint, expect, (instruments, frequency))
    except StateFileError as exc:
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
