"""The results table printed by ``simulate``, ``replay`` and ``demo``: one formatter, one look.

Columns: parameter, true value (only when some row knows it; ``-`` for a row that does not),
estimate, conventional standard error (Eq. 13), corrected standard error (Eqs. 20/22) and
their ratio; when the rows carry a state (``replay``), the percent error ``100 SE /
|estimate|`` of the corrected standard error and the parameter's state
(:mod:`rls_uncertainty.datapath.states`). Numbers have four decimals, more when a row's smallest standard error needs
them to show two significant digits (``0.000017`` rather than ``0.0000``); a ratio that is
not defined (zero or non-finite conventional error) shows ``-``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from ..datapath.states import se_percent, se_percent_text

__all__ = ["ResultRow", "results_table", "rows_from_arrays"]

_MIN_DECIMALS = 4
_MAX_DECIMALS = 10
_TRUE_DECIMALS = 3


@dataclass(frozen=True)
class ResultRow:
    """One parameter's line: its name, estimate, both standard errors and, when known, the
    true value."""

    parameter: str
    estimate: float
    se_conventional: float
    se_corrected: float
    true: float | None = None
    state: str | None = None


def rows_from_arrays(
    names: Sequence[str],
    estimates: Iterable[float],
    se_conventional: Iterable[float],
    se_corrected: Iterable[float],
    truth: Mapping[str, float] | None = None,
    states: Mapping[str, str] | None = None,
) -> list[ResultRow]:
    """Rows of one model from its parameter names and arrays (numpy arrays or sequences, all
    of the names' length); ``truth`` maps names to true values (names it lacks have none),
    ``states`` to their state's text."""
    truth = truth or {}
    return [
        ResultRow(name, float(a), float(b), float(c), truth.get(name),
                  None if states is None else states.get(name, "-"))
        for name, a, b, c in zip(names, estimates, se_conventional, se_corrected, strict=True)
    ]


def _decimals(row: ResultRow) -> int:
    """Four decimals, or as many as the row's smallest positive finite standard error needs
    for two significant digits."""
    ses = [s for s in (row.se_conventional, row.se_corrected) if math.isfinite(s) and s > 0]
    if not ses:
        return _MIN_DECIMALS
    needed = 1 - math.floor(math.log10(min(ses)))
    return max(_MIN_DECIMALS, min(_MAX_DECIMALS, needed))


def _true_text(value: float | None) -> str:
    """Three decimals, more when the value has them (up to six): never rounds a true value."""
    if value is None:
        return "-"
    for d in range(_TRUE_DECIMALS, 7):
        if round(value, d) == value:
            break
    return f"{value:.{d}f}"


def _ratio_text(row: ResultRow) -> str:
    c = row.se_conventional
    if not (math.isfinite(c) and c > 0 and math.isfinite(row.se_corrected)):
        return "-"
    return f"{row.se_corrected / c:.2f}"


def results_table(rows: Iterable[ResultRow], *, show_true: bool | None = None) -> str:
    """The table as text (header, rule, one line per row; no trailing newline).

    ``show_true``: include the true-value column; by default when any row has a true value.
    """
    rows = list(rows)
    if show_true is None:
        show_true = any(r.true is not None for r in rows)
    show_state = any(r.state is not None for r in rows)
    cells = []
    for r in rows:
        d = _decimals(r)
        line = [r.parameter]
        if show_true:
            line.append(_true_text(r.true))
        line += [f"{r.estimate:.{d}f}", f"{r.se_conventional:.{d}f}", f"{r.se_corrected:.{d}f}", _ratio_text(r)]
        if show_state:
            line += [se_percent_text(se_percent(r.estimate, r.se_corrected)), "  " + (r.state or "-")]
        cells.append(line)
    titles = ["parameter"] + (["true"] if show_true else []) + ["estimate", "SE conv.", "SE corr.", "corr/conv"]
    titles += ["SE %", "  state"] if show_state else []
    # Minimum widths: the demo's look (README); wider when a value needs it.
    minimum = [12] + ([9] if show_true else []) + [11, 10, 10, 10] + ([7, 0] if show_state else [])
    widths = [max([m, len(t) + 1] + [len(c[i]) + (2 if i == 0 else 1) for c in cells])
              for i, (m, t) in enumerate(zip(minimum, titles, strict=True))]

    last = len(titles) - 1 if show_state else -1  # the state: left-aligned, not padded

    def fmt(line: list[str]) -> str:
        return "".join(
            v if i == last else f"{v:<{w}}" if i == 0 else f"{v:>{w}}"
            for i, (v, w) in enumerate(zip(line, widths, strict=True))
        )

    header = fmt(titles)
    return "\n".join([header, "-" * len(header), *(fmt(c) for c in cells)])
