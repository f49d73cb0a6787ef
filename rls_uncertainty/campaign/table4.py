"""The paper's Table 4 from a campaign's per-maneuver results (Section IV.B). numpy only.

Per parameter, over the maneuvers whose model was estimated (status ``ok``: not ``too_short``,
not ``no estimate``), in the order of
the maneuvers: the mean estimate, the means of the conventional (Eq. 13), corrected all-lags
(Eq. 20) and corrected configured-lags (Eq. 22) standard errors, and the observed scatter, the
sample standard deviation of the estimates (``ddof=1``; NaN with fewer than two maneuvers). Each
predicted standard error over the scatter says how well it predicts the spread: 1 is the
ideal, and the paper finds about 1/4 for the conventional and 1/2 to 1 for the corrected ones
on 14 flight-test maneuvers in turbulence (Table 4).

With the frequency-domain estimates (``estimator.method`` ``frequency`` or ``both``) each
method has its own rows, the frequency domain's after the time domain's of the same parameter:
its mean, the means of its conventional (F5) and corrected (F7-F10) standard errors (no all-lags
one) and the scatter of its estimates, so the two predictions of the same spread sit side by
side.

The sums run over the maneuvers in their campaign order, whatever process computed them, so
the table is the same from every executor.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .run import MANEUVER_COLUMNS, ManeuverResult, ParameterResult

__all__ = ["Table4Row", "TABLE4_COLUMNS", "table4", "maneuvers_csv", "table4_csv", "table4_markdown", "summary_text"]


@dataclass(frozen=True)
class Table4Row:
    """One parameter's line of Table 4 for one ``method`` (module docstring); ``maneuvers``
    counts those used, ``converged`` those of them whose parameter was flagged converged at
    their end."""

    model: str
    parameter: str
    maneuvers: int
    mean: float
    se_conventional: float
    se_corrected_all: float
    se_corrected: float
    scatter: float
    method: str = "time"
    converged: int = 0

    def over_scatter(self, se: float) -> float:
        """``se`` / the scatter (NaN when the scatter is zero or not defined)."""
        return se / self.scatter if self.scatter > 0 else math.nan

    @property
    def ratios(self) -> tuple[float, float, float]:
        """Conventional, corrected all-lags and corrected configured-lags SE over the scatter."""
        return (self.over_scatter(self.se_conventional), self.over_scatter(self.se_corrected_all),
                self.over_scatter(self.se_corrected))


RATIO_COLUMNS = ("conventional_over_scatter", "corrected_all_over_scatter", "corrected_over_scatter")
# table4.csv's columns: every field of Table4Row, the method beside the parameter, then the ratios.
_VALUES = ("maneuvers", "converged", "mean", "se_conventional", "se_corrected_all", "se_corrected", "scatter")
TABLE4_COLUMNS = ("model", "parameter", "method", *_VALUES, *RATIO_COLUMNS)


def table4(results: Sequence[ManeuverResult]) -> list[Table4Row]:
    """Table 4 over ``results`` (the campaign's maneuvers, in order), one row per parameter and
    method in the order they first appear (per parameter: time, then frequency domain)."""
    by_parameter: dict[tuple[str, str, str], list[ParameterResult]] = {}
    for res in results:
        for row in res.rows:
            by_parameter.setdefault((row.model, row.parameter, row.method), []).append(row)
    out = []
    for (model, parameter, method), rows in by_parameter.items():
        used = [r for r in rows if r.ok]
        v = np.array([(r.estimate, r.se_conventional, r.se_corrected_all, r.se_corrected) for r in used],
                     dtype=float).reshape(-1, 4)
        n = len(used)
        mean = v.mean(axis=0) if n else np.full(4, math.nan)
        scatter = float(np.std(v[:, 0], ddof=1)) if n > 1 else math.nan
        converged = sum(r.state == "converged" for r in used)
        out.append(Table4Row(model, parameter, n, float(mean[0]), float(mean[1]), float(mean[2]), float(mean[3]),
                             scatter, method, converged))
    return out


def _cell(x: object) -> str:
    if isinstance(x, float):
        return "" if math.isnan(x) else repr(float(x))
    return str(x)


def maneuvers_csv(results: Sequence[ManeuverResult]) -> str:
    """``maneuvers.csv``: :data:`.run.MANEUVER_COLUMNS`, one row per maneuver, parameter and
    method (full precision; empty cells where a maneuver gave no value), and ``start`` and
    ``end`` (s from the recording's start) when the maneuvers were cut from one recording by
    their boundaries (:mod:`.split`)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    spans = bool(results) and all(res.start is not None for res in results)
    w.writerow((*MANEUVER_COLUMNS, "start", "end") if spans else MANEUVER_COLUMNS)
    for res in results:
        span = [_cell(res.start), _cell(res.end)] if spans else []
        for row in res.rows:
            w.writerow([_cell(getattr(row, c)) for c in MANEUVER_COLUMNS] + span)
    return buf.getvalue()


def table4_csv(rows: Sequence[Table4Row]) -> str:
    """``table4.csv``: :data:`TABLE4_COLUMNS` (full precision)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TABLE4_COLUMNS)
    for row in rows:
        w.writerow([_cell(x) for x in (row.model, row.parameter, row.method, *(getattr(row, c) for c in _VALUES),
                                       *row.ratios)])
    return buf.getvalue()


def _num(x: float, digits: int = 4) -> str:
    return "-" if not math.isfinite(x) else f"{x:.{digits}g}"


def _failures(results: Sequence[ManeuverResult]) -> list[str]:
    """One line per maneuver with a model not estimated: its name, the model (and the method,
    when not the time domain) and why."""
    lines = []
    for res in results:
        bad = {(r.model if r.method == "time" else f"{r.model} ({r.method} domain)", r.status)
               for r in res.rows if not r.ok}
        if res.problem is not None:
            lines.append(f"{res.name}: {res.problem}")
        else:
            lines += [f"{res.name}: {model}: {status}" for model, status in sorted(bad)]
    return lines


def _by_method(rows: Sequence[Table4Row]) -> bool:
    """Whether the table has rows of another method than the time domain's (then a method
    column says which; a time-domain table is as it always was)."""
    return any(r.method != "time" for r in rows)


def table4_markdown(rows: Sequence[Table4Row], results: Sequence[ManeuverResult], lags: object) -> str:
    """``table4.md``: Table 4 with the ratios to the scatter, and the maneuvers not used."""
    n = len(results)
    method = _by_method(rows)
    lines = [
        "# Table 4: mean estimation results over the campaign's maneuvers",
        "",
        f"{n} maneuver{'s' if n != 1 else ''}; end-of-maneuver values. SE: mean standard error over the maneuvers "
        "used; scatter: sample standard deviation of their estimates (Section IV.B). "
        + ("A scatter from few maneuvers is itself uncertain: its relative standard error is about "
           "1/sqrt(2 (n - 1)) for n maneuvers." if n < 30 else ""),
    ]
    if method:
        lines += ["", "Method `frequency`: the frequency-domain estimates (docs/frequency.md), their conventional "
                  "(F5) and corrected (F7-F10, frequency.lag_span) standard errors; all lags is time-domain only."]
    lines += [
        "",
        f"| model | parameter |{' method |' * method} maneuvers | converged at end | mean | SE conventional | "
        f"SE corrected, all lags | SE corrected, {lags} lags | scatter | conventional / scatter | corrected all / "
        "scatter | corrected / scatter |",
        "| --- | --- |" + " --- |" * (10 + method),
    ]
    for r in rows:
        ratios = " | ".join(_num(x, 3) for x in r.ratios)
        lines.append(f"| {r.model} | {r.parameter} |{f' {r.method} |' * method} {r.maneuvers} | "
                     f"{r.converged} of {r.maneuvers} | {_num(r.mean)} | "
                     f"{_num(r.se_conventional, 3)} | {_num(r.se_corrected_all, 3)} | {_num(r.se_corrected, 3)} | "
                     f"{_num(r.scatter, 3)} | {ratios} |")
    failures = _failures(results)
    if failures:
        lines += ["", "Maneuvers (or models) not used:", ""] + [f"- {line}" for line in failures]
    return "\n".join(lines) + "\n"


def summary_text(rows: Sequence[Table4Row], results: Sequence[ManeuverResult], lags: object) -> str:
    """The printed summary (also ``summary.txt``): Table 4 as aligned text (with a method
    column when the frequency domain has rows), then the maneuvers not used and why."""
    method = _by_method(rows)
    head = ("parameter", *("method",) * method, "n", "converged", "mean", "SE conv", "SE all", f"SE {lags}",
            "scatter", "conv/sc", "all/sc", f"{lags}/sc")
    body = [(r.parameter, *(r.method,) * method, str(r.maneuvers), f"{r.converged}/{r.maneuvers}", _num(r.mean),
             _num(r.se_conventional, 3),
             _num(r.se_corrected_all, 3), _num(r.se_corrected, 3), _num(r.scatter, 3), *(_num(x, 3) for x in r.ratios))
            for r in rows]
    widths = [max(len(str(c)) for c in col) for col in zip(head, *body, strict=True)]
    fmt = "  ".join(f"{{:<{w}}}" if i <= method else f"{{:>{w}}}" for i, w in enumerate(widths))
    lines = [fmt.format(*head), fmt.format(*("-" * w for w in widths))] + [fmt.format(*b) for b in body]
    used = sum(1 for res in results if res.problem is None)
    lines += ["", f"{used} of {len(results)} maneuvers used (SE: mean over them; scatter: standard deviation of "
              "their estimates; x/sc: the SE over the scatter, 1 is ideal; converged: of them, flagged converged at "
              "their end)"]
    failures = _failures(results)
    if failures:
        lines += ["not used:"] + [f"  {line}" for line in failures]
    return "\n".join(lines) + "\n"
