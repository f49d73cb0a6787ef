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
that run only.

The defaults (:data:`DEFAULT_RTOL`, :data:`DEFAULT_ATOL`) and their derivation are in
docs/testing.md. Memory: both files are read row by row.
"""

from __future__ import annotations

import csv
import heapq
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, NamedTuple

from ..errors import NotComparable
from .replay_files import RUN_FORMAT

__all__ = ["DEFAULT_RTOL", "DEFAULT_ATOL", "Difference", "Comparison", "read_run", "comparable", "compare_replays"]

# Relative tolerance, of |estimate| + SE: rounding between BLAS kernels reaches 4e-9 on the
# bundled and Twin Otter replays, the smallest configuration change tried 5e-4
# (docs/testing.md, "Comparing replays").
DEFAULT_RTOL = 1e-6
# Absolute tolerance, in the units of each derivative: none beyond the relative one.
DEFAULT_ATOL = 0.0
_SHOWN = 10  # differences listed
# The files compared: per estimation method, its estimates file and how its parameters are listed.
RESULT_FILES = (("estimates.csv", "{}"), ("estimates_frequency.csv", "{} [frequency]"))


class Difference(NamedTuple):
    """One value beyond the tolerance: ``excess`` is ``|difference| / tolerance`` (inf for a
    flag or lag count)."""

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
                         f"{len(self.categorical)} differing flags or lag counts; time from this run's first sample)")
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


def read_run(directory: str | Path) -> dict[str, Any]:
    """A replay output directory's ``run.json``; :class:`.errors.NotComparable` when there is
    none, or it is not one."""
    path = Path(directory) / "run.json"
    try:
        run = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise NotComparable(f"{directory}: no run.json: not the output of rls-uncertainty replay, or made before "
                            "replays recorded their run (replay again to make the reference)") from exc
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise NotComparable(f"{path}: unreadable: {exc}") from exc
    if not isinstance(run, dict) or run.get("format") != RUN_FORMAT:
        raise NotComparable(f"{path}: not a run record of this version ({RUN_FORMAT!r} expected)")
    if not any((Path(directory) / name).is_file() for name, _ in RESULT_FILES):
        raise NotComparable(f"{directory}: no {' or '.join(name for name, _ in RESULT_FILES)}")
    return run


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


def _stamp(text: str) -> int:
    sec, _, nanosec = text.partition(".")
    return int(sec) * 1_000_000_000 + int(nanosec.ljust(9, "0"))


def _rows(fh: IO[str], order: dict[str, int], label: str) -> Iterator[tuple[tuple[int, int], dict[str, str]]]:
    """``((stamp, parameter index), row)`` of an ``estimates.csv``, in the file's order, the
    parameter named by ``label`` (:data:`RESULT_FILES`)."""
    for row in csv.DictReader(fh):
        key = (_stamp(row["time"]), order.get(row["parameter"], -1))
        row["parameter"] = label.format(row["parameter"])
        yield key, row


def _check(cmp: Comparison, key: tuple[int, int], here: dict[str, str], there: dict[str, str]) -> None:
    """One sample and parameter of both runs (module docstring)."""
    a, b = float(here["estimate"]), float(there["estimate"])
    s = abs(b) + float(there["std_error"])
    tol = cmp.atol + cmp.rtol * s
    checks = [("estimate", abs(a - b), tol)]
    for q in ("std_error", "std_error_conventional"):
        x, y = float(here[q]), float(there[q])
        checks.append((q, abs(x * x - y * y), 2 * s * tol))
    for quantity, diff, bound in checks:
        excess = diff / bound if bound > 0 else (math.inf if diff else 0.0)
        cmp.largest = max(cmp.largest, excess)
        if diff > bound:
            cmp.add(Difference(excess, key[0], here["parameter"], quantity, here[quantity], there[quantity]))
    for quantity in ("converged", "lags"):
        if here[quantity] != there[quantity]:
            cmp.add(Difference(math.inf, key[0], here["parameter"], quantity, here[quantity], there[quantity]))
    cmp.compared += len(checks) + 2
    cmp.rows += 1


def _one_side(cmp: Comparison, path: Path, order: dict[str, int], label: str, *, here: bool) -> None:
    """A results file only one of the runs wrote: every row of it is unmatched."""
    with open(path, newline="") as fh:
        rows = sum(1 for _ in _rows(fh, order, label))
    if here:
        cmp.only_here += rows
    else:
        cmp.only_there += rows
    if rows:
        cmp.unmatched.append(f"{path.name} ({rows} rows) only in {'this run' if here else 'the reference'}")


def _compare_file(cmp: Comparison, path_a: Path, path_b: Path, order: dict[str, int], label: str) -> None:
    """Pair the rows of two runs' results files by sample and parameter (:func:`_check`)."""
    with open(path_a, newline="") as fh_a, open(path_b, newline="") as fh_b:
        rows_a, rows_b = _rows(fh_a, order, label), _rows(fh_b, order, label)
        a, b = next(rows_a, None), next(rows_b, None)
        while a is not None or b is not None:
            if a is not None and cmp.first_ns is None:
                cmp.first_ns = a[0][0]
            if b is None or (a is not None and a[0] < b[0]):
                assert a is not None
                cmp.only_here += 1
                if len(cmp.unmatched) < _SHOWN:
                    cmp.unmatched.append(f"only in this run: {a[1]['parameter']} at {a[1]['time']}")
                a = next(rows_a, None)
            elif a is None or b[0] < a[0]:
                cmp.only_there += 1
                if len(cmp.unmatched) < _SHOWN:
                    cmp.unmatched.append(f"only in the reference: {b[1]['parameter']} at {b[1]['time']}")
                b = next(rows_b, None)
            else:
                _check(cmp, a[0], a[1], b[1])
                a, b = next(rows_a, None), next(rows_b, None)


def compare_replays(here_dir: str | Path, there_dir: str | Path, *, rtol: float = DEFAULT_RTOL,
                    atol: float = DEFAULT_ATOL) -> Comparison:
    """This replay's outputs (``here_dir``) against a reference replay's (``there_dir``), both
    methods' results files (:data:`RESULT_FILES`): :class:`Comparison`, or
    :class:`.errors.NotComparable` saying why they cannot be."""
    here, there = read_run(here_dir), read_run(there_dir)
    cmp = Comparison(rtol, atol, Path(there_dir), notes=comparable(here, there))
    order = {p: i for i, p in enumerate(p for names in here["parameter_names"] for p in names)}
    for name, label in RESULT_FILES:
        path_a, path_b = Path(here_dir) / name, Path(there_dir) / name
        if path_a.is_file() and path_b.is_file():
            _compare_file(cmp, path_a, path_b, order, label)
        elif path_a.is_file() or path_b.is_file():
            _one_side(cmp, path_a if path_a.is_file() else path_b, order, label, here=path_a.is_file())
    return cmp
