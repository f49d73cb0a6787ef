"""``rls-uncertainty replay BAG ... --compare DIR``: this replay's outputs against an earlier
replay's (a reference, "golden" output) sample by sample, within a tolerance that holds
across CPUs (docs/testing.md, "Comparing replays").

Two replays are *comparable* when they read the same input messages (the bag's input content
digest, :class:`.bags.InputStream`) over the same span and strictness, with the same models,
parameter names and sample rate: then their ``estimates.csv`` rows pair one to one by
sample time and parameter; and at least one estimation method in common (``estimator.method``:
a time-domain run and a frequency-domain one have no results file to pair). Anything else
raises :class:`.errors.NotComparable`, saying why.
Other configuration changes (a lag count, a forgetting factor) leave them comparable: the
comparison then shows what they changed, and the differing parameters are named.

Per sample and parameter, with ``s = |estimate| + std_error`` of the reference (the
parameter's magnitude plus its uncertainty at that sample), the values are equal when

* estimates: ``|a - b| <= atol + rtol * s``;
* standard errors, corrected and conventional, compared as variances (Eqs. 13, 20/22 compute
  variances; a standard error is their square root, which magnifies rounding where the
  variance is at rounding level, as at an exact fit): ``|a^2 - b^2| <= 2 s (atol + rtol * s)``,
  which is ``|a - b| <= (s / a)(atol + rtol * s)`` where the variance is resolved;
* convergence flags and lag counts: identical.

Both methods' results are compared (``estimator.method``): ``estimates.csv`` (time domain) and
``estimates_frequency.csv`` (frequency domain; its parameters listed as ``P [frequency]``), each
where the run wrote it; a file that only one of the runs has counts all its rows as found in
that run only. A value is within its tolerance only when the inequality holds with a finite
tolerance: a NaN on either side is a difference, never equality.

A reference is trusted only as far as it is checked (:func:`check_reference`, before the bag
is read; again as the comparison reads it): ``run.json``'s fields of the types a replay writes
(a sample period > 0, an ``estimator.method`` of :data:`.settings.config.METHODS`, as many
parameter lists as models, the results files its method writes present, each a regular file);
each results file's header exactly :data:`.replay_files.CSV_COLUMNS`, UTF-8 lines, every cell of
its type, the rows in order of sample and parameter, the models and parameters of its
``run.json``; every estimate and standard error finite, the standard errors >= 0. Anything else
is a :class:`.errors.NotComparable` naming the file, the line and the column (or the field).

The defaults (:data:`DEFAULT_RTOL`, :data:`DEFAULT_ATOL`) and their derivation are in
docs/testing.md. Memory: both files are read row by row.
"""

from __future__ import annotations

import csv
import heapq
import json
import math
import os
import re
import stat
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, NamedTuple

from ..datapath.config import METHODS
from ..errors import ConfigError, NotComparable
from ..files import file_kind
from .replay_files import CSV_COLUMNS, RUN_FORMAT

__all__ = ["DEFAULT_RTOL", "DEFAULT_ATOL", "Difference", "Comparison", "read_run", "check_reference", "comparable",
           "check_tolerance", "compare_replays"]

# Relative tolerance, of |estimate| + SE: rounding between BLAS kernels reaches 4e-9 on the
# bundled and Twin Otter replays, the smallest configuration change tried 5e-4
# (docs/testing.md, "Comparing replays").
DEFAULT_RTOL = 1e-6
# Absolute tolerance, in the units of each derivative: none beyond the relative one.
DEFAULT_ATOL = 0.0
_SHOWN = 10  # differences listed
# The files compared: per estimation method, its estimates file and how its parameters are listed.
RESULT_FILES = (("estimates.csv", "{}"), ("estimates_frequency.csv", "{} [frequency]"))
_MAX_RUN_BYTES = 16 << 20  # a run.json beyond this is not one (a replay's is a few kB)
_MAX_LINE = 1 << 16  # bytes in a line of a results file (a replay's are under 200)
_TIME = re.compile(r"[0-9]{1,11}\.[0-9]{9}")  # a stamp as .replay_files.stamp_text writes it
_LAGS = re.compile(r"[0-9]{1,9}")  # a lag count (empty where the run has none)
_MISSING = object()


class Difference(NamedTuple):
    """One value beyond the tolerance: ``excess`` is ``|difference| / tolerance`` (inf for a
    flag or lag count, and for a value of this run that is not finite)."""

    excess: float
    stamp_ns: int
    parameter: str
    quantity: str
    value: str  # this run's, as written
    reference: str  # the reference's


@dataclass
class Comparison:
    """The outcome: values compared (per sample and parameter: the estimate, both standard
    errors, the flag and the lag count), those beyond the tolerance (the largest numeric ones
    and the first differing flags or lag counts kept), rows found in only one of the runs, and
    notes on how the configurations differ."""

    rtol: float
    atol: float
    reference: Path
    compared: int = 0
    rows: int = 0
    beyond: int = 0
    largest: float = 0.0  # the largest |difference| / tolerance seen (numeric values)
    worst: list[Difference] = field(default_factory=list)  # a heap of the largest numeric ones
    categorical: list[Difference] = field(default_factory=list)  # the first differing flags, lag counts
    only_here: int = 0
    only_there: int = 0
    unmatched: list[str] = field(default_factory=list)
    first_ns: int | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def equal(self) -> bool:
        return not (self.beyond or self.only_here or self.only_there)

    def report(self) -> str:
        """What the command prints."""
        tol = f"rtol {self.rtol:g} of |estimate| + SE, atol {self.atol:g}"
        lines = [f"configuration differs from the reference's: {note}" for note in self.notes]
        counted = f"{self.compared} values ({self.rows} samples x parameters)"
        if self.equal:
            lines.append(f"--compare {self.reference}: equal: {counted} within {tol}; the largest difference is "
                         f"{self.largest:.2g} of its tolerance")
            return "\n".join(lines)
        lines.append(f"--compare {self.reference}: DIFFERENT: {self.beyond} of {counted} beyond {tol}; "
                     f"{self.only_here} rows only in this run, {self.only_there} only in the reference")
        lines += [f"  {u}" for u in self.unmatched]
        shown = sorted(self.worst, reverse=True) + self.categorical
        if shown:
            t0 = self.first_ns or 0
            table = [("parameter", "time (s)", "quantity", "this run", "reference", "|difference|/tolerance")]
            table += [(d.parameter, f"{(d.stamp_ns - t0) * 1e-9:.3f}", d.quantity, d.value, d.reference,
                       "differs" if math.isinf(d.excess) else f"{d.excess:.3g}") for d in shown]
            widths = [max(len(row[i]) for row in table) for i in range(len(table[0]))]
            lines += ["  " + "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
                      for row in table]
            lines.append(f"  (the {len(self.worst)} largest numeric differences, then the first "
                         f"{len(self.categorical)} differing flags, lag counts or values that are not finite; time "
                         "from this run's first sample)")
        return "\n".join(lines)

    def add(self, difference: Difference) -> None:
        self.beyond += 1
        if math.isinf(difference.excess):
            if len(self.categorical) < _SHOWN // 2:
                self.categorical.append(difference)
        elif len(self.worst) < _SHOWN:
            heapq.heappush(self.worst, difference)
        elif difference > self.worst[0]:
            heapq.heapreplace(self.worst, difference)


def _open_regular(path: Path) -> IO[bytes]:
    """``path`` opened for reading without waiting (a FIFO at its name cannot block), refused
    unless it is a regular file."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise NotComparable(f"{path}: cannot be read ({exc.strerror or exc})") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise NotComparable(f"{path}: {file_kind(mode)}, not a regular file")
    os.set_blocking(fd, True)
    return os.fdopen(fd, "rb")


def read_run(directory: str | Path) -> dict[str, Any]:
    """A replay output directory's ``run.json``, every field :func:`comparable` reads checked
    (:func:`_check_run`); :class:`.errors.NotComparable` naming the file and the field when
    there is none, it is not one, or it is inconsistent (a field missing or of another type, a
    period of 0, an unknown estimation method, a results file its method writes missing)."""
    path = Path(directory) / "run.json"
    if not path.exists() and not path.is_symlink():
        raise NotComparable(f"{directory}: no run.json: not the output of rls-uncertainty replay, or made before "
                            "replays recorded their run (replay again to make the reference)")
    with _open_regular(path) as fh:
        text = fh.read(_MAX_RUN_BYTES + 1)
    if len(text) > _MAX_RUN_BYTES:
        raise NotComparable(f"{path}: larger than {_MAX_RUN_BYTES >> 20} MiB: not a run record")
    try:
        run = json.loads(text.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise NotComparable(f"{path}: not UTF-8 text (byte {exc.start})") from None
    except (json.JSONDecodeError, RecursionError) as exc:
        raise NotComparable(f"{path}: not valid JSON: {' '.join(str(exc).split())[:120]}") from None
    if not isinstance(run, dict) or run.get("format") != RUN_FORMAT:
        raise NotComparable(f"{path}: not a run record of this version ({RUN_FORMAT!r} expected)")
    _check_run(run, path)
    for name in _methods(run):
        if not (Path(directory) / name).exists():
            raise NotComparable(f"{path}: estimator.method {_method(run)!r} writes {name}, which {directory} "
                                "does not hold")
    return run


def _finite_seconds(value: object) -> bool:
    return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool)
                             and math.isfinite(value) and value >= 0)


def _names(value: object) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, str) and v for v in value)


# The fields of run.json that a comparison reads: (path of keys, check, what is expected).
_RUN_FIELDS: tuple[tuple[tuple[str, ...], Callable[[Any], bool], str], ...] = (
    (("bag",), lambda v: isinstance(v, dict), "a mapping"),
    (("bag", "path"), lambda v: isinstance(v, str), "the bag's path (a string)"),
    (("bag", "input_sha256"), lambda v: isinstance(v, str) and re.fullmatch("[0-9a-f]{64}", v) is not None,
     "a SHA-256 digest (64 hexadecimal digits)"),
    (("bag", "messages_read"), lambda v: type(v) is int and v >= 0, "a whole number >= 0"),
    (("bag", "start"), _finite_seconds, "null or a finite number of seconds >= 0"),
    (("bag", "end"), _finite_seconds, "null or a finite number of seconds >= 0"),
    (("bag", "strict"), lambda v: isinstance(v, bool), "true or false"),
    (("parameters",), lambda v: isinstance(v, dict), "a mapping"),
    (("configuration",), lambda v: isinstance(v, dict), "a mapping"),
    (("configuration_sha256",), lambda v: isinstance(v, str), "a string"),
    (("models",), _names, "a non-empty list of model names"),
    (("parameter_names",), lambda v: isinstance(v, list) and all(_names(n) for n in v),
     "a list of non-empty lists of parameter names"),
    (("period_ns",), lambda v: type(v) is int and v > 0, "a whole number of nanoseconds > 0"),
)


def _check_run(run: dict[str, Any], path: Path) -> None:
    """Refuse a run record (:func:`.replay_files.run_record`) a comparison cannot trust, naming
    the field: missing, of another type or out of range; models and parameter lists of other
    lengths; an ``estimator.method`` that is not one of :data:`.settings.config.METHODS`."""
    for keys, ok, expected in _RUN_FIELDS:
        value: Any = run
        for key in keys:
            value = value.get(key, _MISSING) if isinstance(value, dict) else _MISSING
        where = f"{path}: {'.'.join(keys)}"
        if value is _MISSING:
            raise NotComparable(f"{where}: missing (expected {expected})")
        if not ok(value):
            raise NotComparable(f"{where}: {_shown(value)} is not {expected}")
    models, names = run["models"], run["parameter_names"]
    if len(models) != len(names):
        raise NotComparable(f"{path}: parameter_names: {len(names)} lists for {len(models)} models")
    method = run["parameters"].get("estimator.method", "time")
    if method not in METHODS:
        raise NotComparable(f"{path}: parameters.estimator.method: {_shown(method)} is not one of "
                            f"{', '.join(METHODS)}")


def _shown(value: object) -> str:
    text = json.dumps(value, default=repr)
    return text if len(text) <= 60 else text[:57] + "..."


def _flat(values: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(values, dict):
        out: dict[str, Any] = {}
        for key, value in values.items():
            out.update(_flat(value, f"{prefix}{key}."))
        return out
    return {prefix[:-1]: values}


def _differences(here: dict[str, Any], there: dict[str, Any]) -> list[str]:
    a, b = _flat(here), _flat(there)
    return [f"{k}: {a.get(k, '(absent)')!r} here, {b.get(k, '(absent)')!r} in the reference"
            for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]


def comparable(here: dict[str, Any], there: dict[str, Any], *, bag: bool = True) -> list[str]:
    """Raise :class:`.errors.NotComparable` unless two runs' outputs pair sample by sample
    (``bag``: their bags' input digests too, known once a run has read its bag); else the
    notes on how their configurations differ."""
    h, t = here.get("bag", {}), there.get("bag", {})
    if bag and h.get("input_sha256") != t.get("input_sha256"):
        raise NotComparable(f"another bag: its input messages differ (SHA-256 {str(h.get('input_sha256'))[:12]}..., "
                            f"{h.get('messages_read')} messages here; {str(t.get('input_sha256'))[:12]}..., "
                            f"{t.get('messages_read')} messages in the reference {t.get('path')})")
    span = [(k, h.get(k), t.get(k)) for k in ("start", "end", "strict") if h.get(k) != t.get(k)]
    if span:
        raise NotComparable("another span: " + ", ".join(f"{k} {a!r} here, {b!r} in the reference" for k, a, b in span))
    if (here["models"], here["parameter_names"]) != (there["models"], there["parameter_names"]):
        raise NotComparable(f"other models: {_models(here)} here; {_models(there)} in the reference")
    if here["period_ns"] != there["period_ns"]:
        raise NotComparable(f"another sample rate: rate {1e9 / here['period_ns']:g} Hz here, "
                            f"{1e9 / there['period_ns']:g} Hz in the reference: the samples fall at other times")
    methods = (_methods(here), _methods(there))
    if not methods[0] & methods[1]:
        raise NotComparable(f"no estimation method in common: estimator.method {_method(here)!r} here "
                            f"({', '.join(sorted(methods[0]))}), {_method(there)!r} in the reference "
                            f"({', '.join(sorted(methods[1]))}): no results file to compare")
    notes = _differences(here.get("parameters", {}), there.get("parameters", {}))
    if not notes and here.get("configuration_sha256") != there.get("configuration_sha256"):
        notes = _differences(here.get("configuration", {}), there.get("configuration", {}))
    return notes


def _method(run: dict[str, Any]) -> str:
    return str(run.get("parameters", {}).get("estimator.method", "time"))


def _methods(run: dict[str, Any]) -> set[str]:
    """The results files a run with its ``estimator.method`` writes (:data:`RESULT_FILES`)."""
    method = _method(run)
    return {name for name, _ in RESULT_FILES if method == "both" or (method == "frequency") == ("frequency" in name)}


def _models(run: dict[str, Any]) -> str:
    return ", ".join(f"{m} ({' '.join(names)})" for m, names in zip(run["models"], run["parameter_names"], strict=True))


class _Row(NamedTuple):
    """One row of a results file, checked: its key (sample stamp, parameter index), the
    parameter as listed (:data:`RESULT_FILES`), the numbers and the cells as written."""

    key: tuple[int, int]
    time: str
    parameter: str
    values: tuple[float, float, float]  # estimate, std_error, std_error_conventional
    cells: dict[str, str]


class _Reader:
    """The rows of one run's results file (``estimates.csv``, :data:`.replay_files.CSV_COLUMNS`)
    in the file's order, each checked against the run: read line by line (a line of at most
    :data:`_MAX_LINE` bytes, UTF-8), the header exactly the columns written, every cell of its
    type, the model and parameter of the run, the rows in order of sample and parameter (as a
    replay writes them: the pairing relies on it). With ``reference``, the numbers must be
    finite and the standard errors >= 0 (a reference that is not is refused: nothing can be
    within a tolerance of it); this run's numbers are taken as they are (a value that is not
    finite is a difference). Any problem is :class:`.errors.NotComparable` naming the file,
    the line and the column."""

    def __init__(self, path: Path, order: dict[tuple[str, str], int], label: str, *, reference: bool) -> None:
        self.path, self.order, self.label, self.reference = path, order, label, reference
        self.line = 0

    def _lines(self, fh: IO[bytes]) -> Iterator[str]:
        while raw := fh.readline(_MAX_LINE + 1):
            self.line += 1
            if len(raw) > _MAX_LINE:
                raise self._error(None, f"longer than {_MAX_LINE} bytes: not a results file")
            try:
                yield raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise self._error(None, f"not UTF-8 text (byte {exc.start + 1} of the line)") from None

    def _error(self, column: str | None, problem: str) -> NotComparable:
        at = f", column {column}" if column else ""
        return NotComparable(f"{self.path}: line {self.line}{at}: {problem}")

    def __iter__(self) -> Iterator[_Row]:
        with _open_regular(self.path) as fh:
            reader = csv.reader(self._lines(fh))
            try:
                header = next(reader, None)
                self._header(header)
                previous = None
                for cells in reader:
                    row = self._row(cells)
                    if previous is not None and row.key <= previous.key:
                        raise self._error(None, f"{row.parameter} at {row.time} after {previous.parameter} at "
                                                f"{previous.time}: rows out of order or repeated")
                    previous = row
                    yield row
            except csv.Error as exc:
                raise self._error(None, f"not CSV: {exc}") from None

    def _header(self, header: list[str] | None) -> None:
        if header is None:
            raise NotComparable(f"{self.path}: empty (no header line)")
        missing = [c for c in CSV_COLUMNS if c not in header]
        if missing or tuple(header) != CSV_COLUMNS:
            problem = f"no column {missing[0]}" if missing else "columns in another order or extra columns"
            raise self._error(None, f"{problem}: the header is {_shown(','.join(header))}, expected "
                                    f"{','.join(CSV_COLUMNS)}")

    def _row(self, cells: list[str]) -> _Row:
        if len(cells) != len(CSV_COLUMNS):
            raise self._error(None, f"{len(cells)} cells, expected {len(CSV_COLUMNS)} ({', '.join(CSV_COLUMNS)})")
        row = dict(zip(CSV_COLUMNS, cells, strict=True))
        if not _TIME.fullmatch(row["time"]):
            raise self._error("time", f"{_shown(row['time'])} is not a stamp SEC.NANOSEC (9 digits)")
        index = self.order.get((row["model"], row["parameter"]))
        if index is None:
            raise self._error("parameter", f"{_shown(row['parameter'])} of model {_shown(row['model'])} is not a "
                                           "parameter of the run's models (run.json)")
        values = (self._number(row, "estimate"), self._number(row, "std_error"),
                  self._number(row, "std_error_conventional"))
        if row["converged"] not in ("0", "1"):
            raise self._error("converged", f"{_shown(row['converged'])} is not 0 or 1")
        if row["lags"] and not _LAGS.fullmatch(row["lags"]):
            raise self._error("lags", f"{_shown(row['lags'])} is not a whole number of lags")
        sec, _, nanosec = row["time"].partition(".")
        return _Row((int(sec) * 1_000_000_000 + int(nanosec), index), row["time"],
                    self.label.format(row["parameter"]), values, row)

    def _number(self, row: dict[str, str], column: str) -> float:
        try:
            x = float(row[column])
        except ValueError:
            raise self._error(column, f"{_shown(row[column])} is not a number") from None
        if self.reference and not math.isfinite(x):
            raise self._error(column, f"{row[column]} is not finite: no value is within a tolerance of it")
        if self.reference and x < 0 and column != "estimate":
            raise self._error(column, f"{row[column]} is negative: not a standard error")
        return x


def _check(cmp: Comparison, here: _Row, there: _Row) -> None:
    """One sample and parameter of both runs (module docstring). A value is within its
    tolerance only when ``|difference| <= tolerance`` holds and the tolerance is finite: a NaN
    on either side, or an infinite tolerance, is a difference."""
    (a, x1, x2), (b, y1, y2) = here.values, there.values
    s = abs(b) + y1
    tol = cmp.atol + cmp.rtol * s
    checks = (("estimate", abs(a - b), tol), ("std_error", abs(x1 * x1 - y1 * y1), 2 * s * tol),
              ("std_error_conventional", abs(x2 * x2 - y2 * y2), 2 * s * tol))
    for quantity, diff, bound in checks:
        if diff <= bound < math.inf:
            cmp.largest = max(cmp.largest, diff / bound if bound > 0 else 0.0)
            continue
        excess = diff / bound if 0 < bound < math.inf and diff < math.inf else math.inf
        cmp.largest = max(cmp.largest, excess)
        cmp.add(Difference(excess, here.key[0], here.parameter, quantity, here.cells[quantity], there.cells[quantity]))
    for quantity in ("converged", "lags"):
        if here.cells[quantity] != there.cells[quantity]:
            cmp.add(Difference(math.inf, here.key[0], here.parameter, quantity, here.cells[quantity],
                               there.cells[quantity]))
    cmp.compared += len(checks) + 2
    cmp.rows += 1


def _one_side(cmp: Comparison, rows: _Reader, *, here: bool) -> None:
    """A results file only one of the runs wrote: every row of it is unmatched."""
    n = sum(1 for _ in rows)
    if here:
        cmp.only_here += n
    else:
        cmp.only_there += n
    if n:
        cmp.unmatched.append(f"{rows.path.name} ({n} rows) only in {'this run' if here else 'the reference'}")


def _compare_file(cmp: Comparison, here: _Reader, there: _Reader) -> None:
    """Pair the rows of two runs' results files by sample and parameter (:func:`_check`)."""
    rows_a, rows_b = iter(here), iter(there)
    a, b = next(rows_a, None), next(rows_b, None)
    while a is not None or b is not None:
        if a is not None and cmp.first_ns is None:
            cmp.first_ns = a.key[0]
        if b is None or (a is not None and a.key < b.key):
            assert a is not None
            cmp.only_here += 1
            if len(cmp.unmatched) < _SHOWN:
                cmp.unmatched.append(f"only in this run: {a.parameter} at {a.time}")
            a = next(rows_a, None)
        elif a is None or b.key < a.key:
            cmp.only_there += 1
            if len(cmp.unmatched) < _SHOWN:
                cmp.unmatched.append(f"only in the reference: {b.parameter} at {b.time}")
            b = next(rows_b, None)
        else:
            _check(cmp, a, b)
            a, b = next(rows_a, None), next(rows_b, None)


def check_tolerance(rtol: float, atol: float) -> None:
    """Refuse a tolerance that is not a finite number >= 0 (an infinite one would pass
    anything): :class:`.errors.ConfigError`."""
    for name, value in (("rtol", rtol), ("atol", atol)):
        given: object = value  # (whatever a script passed: checked here)
        if isinstance(given, bool) or not isinstance(given, (int, float)) or not math.isfinite(given) or given < 0:
            raise ConfigError(f"--compare's {name} must be a finite number >= 0, got {value!r} (--{name})")


def _order(run: dict[str, Any]) -> dict[tuple[str, str], int]:
    """Each (model, parameter) of a run and its place in the rows of a sample."""
    pairs = [(m, p) for m, names in zip(run["models"], run["parameter_names"], strict=True) for p in names]
    return {pair: i for i, pair in enumerate(pairs)}


def check_reference(directory: str | Path) -> dict[str, Any]:
    """A reference replay's ``run.json`` (:func:`read_run`) with every row of its results files
    checked (:class:`_Reader`), as a comparison will read them: what a replay with ``--compare``
    checks before it reads its bag, so that a damaged reference is refused at once."""
    run = read_run(directory)
    for name, label in RESULT_FILES:
        if name in _methods(run):
            for _ in _Reader(Path(directory) / name, _order(run), label, reference=True):
                pass
    return run


def compare_replays(here_dir: str | Path, there_dir: str | Path, *, rtol: float = DEFAULT_RTOL,
                    atol: float = DEFAULT_ATOL) -> Comparison:
    """This replay's outputs (``here_dir``) against a reference replay's (``there_dir``), the
    results files each run's ``estimator.method`` writes (:data:`RESULT_FILES`):
    :class:`Comparison`, or :class:`.errors.NotComparable` saying why they cannot be (the
    reference's files checked as they are read, :class:`_Reader`)."""
    check_tolerance(rtol, atol)
    here, there = read_run(here_dir), read_run(there_dir)
    cmp = Comparison(rtol, atol, Path(there_dir), notes=comparable(here, there))
    order = _order(here)
    written = _methods(here), _methods(there)
    for name, label in RESULT_FILES:
        a = _Reader(Path(here_dir) / name, order, label, reference=False) if name in written[0] else None
        b = _Reader(Path(there_dir) / name, order, label, reference=True) if name in written[1] else None
        if a is not None and b is not None:
            _compare_file(cmp, a, b)
        elif a is not None:
            _one_side(cmp, a, here=True)
        elif b is not None:
            _one_side(cmp, b, here=False)
    return cmp
