"""The flight so far: the node's maneuver history (``~/maneuvers``) as the page's ``flight`` message.

The estimator node publishes its maneuver history as JSON on ``~/maneuvers``
(:func:`..datapath.maneuvers.history_json`), and ``rls-uncertainty replay`` writes the same
messages into its ``estimates.mcap``; the live and the replay source hand each one here, so the
page shows the same thing from both. :class:`FlightHistory` turns a message into what the page
draws beside the current maneuver:

* per maneuver recorded, its name, span, verdict (against ``targets.percent``, empty without
  targets) and per parameter and method its final estimate with the conventional (Eq. 13) and
  corrected (Eq. 22) standard errors and its status (Fig. 12 draws the rows of status ``ok``);
* Table 4 over them, computed by the campaign's own :func:`..campaign.table4.table4` (the
  maneuvers of status ``ok``; the mean estimate, the scatter as the sample standard deviation
  of the estimates, the mean standard errors and each over the scatter), so the page's table
  is the campaign's ``table4.csv`` of the same rows.

What a message may hold is bounded (:data:`MAX_MANEUVERS` maneuvers, :data:`MAX_ROWS` rows
each, names of at most :data:`MAX_NAME` characters); a message that is not such a history is
refused, counted in :attr:`FlightHistory.refused` and changes nothing.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

from ..campaign.run import ManeuverResult, ParameterResult
from ..campaign.table4 import Table4Row, table4

__all__ = ["FlightHistory", "MAX_MANEUVERS", "MAX_ROWS", "MAX_NAME", "MAX_BYTES"]

MAX_MANEUVERS = 500  # the node keeps maneuvers.history (100 by default) of them
MAX_ROWS = 200  # rows of one maneuver: parameters times methods
MAX_NAME = 200
MAX_BYTES = 8 * 1024 * 1024  # of one history message
_NUMBERS = ("estimate", "se_conventional", "se_corrected", "se_corrected_all")


def _number(x: object) -> float:
    """A JSON number (``null``: NaN); anything else is a ValueError."""
    if x is None:
        return math.nan
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise ValueError(f"not a number: {x!r}")
    return float(x)


def _text(x: object, default: str = "") -> str:
    if x is None:
        return default
    if not isinstance(x, str) or len(x) > MAX_NAME * 4:
        raise ValueError(f"not a text: {x!r:.80}")
    return x


def _row(name: str, r: object) -> ParameterResult:
    if not isinstance(r, Mapping):
        raise ValueError("a row is not an object")
    est, se_conv, se_corr, se_all = (_number(r.get(k)) for k in _NUMBERS)
    samples = r.get("samples")
    n = int(samples) if isinstance(samples, int) and not isinstance(samples, bool) else 0
    return ParameterResult(name, _text(r.get("model"))[:MAX_NAME], _text(r.get("parameter"))[:MAX_NAME], est,
                           se_conv, se_corr, se_all, n,
                           _number(r.get("r_squared")), _text(r.get("status")), _text(r.get("method"), "time"),
                           _text(r.get("state")), _text(r.get("reason")), _text(r.get("verdict")))


def _maneuver(m: object) -> tuple[ManeuverResult, dict[str, Any]]:
    """One maneuver of the history: its campaign result and what the page is told of it."""
    if not isinstance(m, Mapping) or not isinstance(m.get("rows"), list) or len(m["rows"]) > MAX_ROWS:
        raise ValueError("a maneuver is not an object with at most MAX_ROWS rows")
    name = _text(m.get("name"))[:MAX_NAME]
    rows = tuple(_row(name, r) for r in m["rows"])
    start, end = _number(m.get("start")), _number(m.get("end"))
    page = {"name": name, "start": _finite(start), "end": _finite(end), "duration": _finite(end - start),
            "verdict": rows[0].verdict if rows else "",
            "rows": [{"model": r.model, "parameter": r.parameter, "method": r.method, "status": r.status,
                      **{k: _finite(getattr(r, k)) for k in ("estimate", "se_conventional", "se_corrected")}}
                     for r in rows]}
    return ManeuverResult(name, rows), page


def _finite(x: float) -> float | None:
    """``x``, or None (JSON null) when it is not finite: the page's JSON holds no NaN."""
    return x if math.isfinite(x) else None


def _table_row(r: Table4Row) -> dict[str, Any]:
    conventional, _all, corrected = r.ratios
    return {"model": r.model, "parameter": r.parameter, "method": r.method, "maneuvers": r.maneuvers,
            "mean": _finite(r.mean), "scatter": _finite(r.scatter), "se_conventional": _finite(r.se_conventional),
            "se_corrected": _finite(r.se_corrected), "conventional_over_scatter": _finite(conventional),
            "corrected_over_scatter": _finite(corrected)}


class FlightHistory:
    """The newest history message as the page's ``flight`` message (module docstring)."""

    def __init__(self) -> None:
        self.message: dict[str, Any] | None = None
        self.refused = 0

    def update(self, text: str) -> dict[str, Any] | None:
        """A ``~/maneuvers`` message: the ``flight`` message when it changed what the page
        shows; None when it did not, or when it was refused (counted)."""
        try:
            message = self._message(text)
        except (ValueError, TypeError, RecursionError):
            self.refused += 1
            return None
        if message == self.message:
            return None
        self.message = message
        return message

    @staticmethod
    def _message(text: str) -> dict[str, Any]:
        if len(text) > MAX_BYTES:
            raise ValueError("not a history message")
        doc = json.loads(text)
        if not isinstance(doc, Mapping) or not isinstance(doc.get("maneuvers"), list) \
                or len(doc["maneuvers"]) > MAX_MANEUVERS:
            raise ValueError("not a history message")
        results, pages = zip(*(_maneuver(m) for m in doc["maneuvers"]), strict=True) if doc["maneuvers"] else ((), ())
        recorded = doc.get("recorded")
        return {"type": "flight", "source": _text(doc.get("source"))[:MAX_NAME],
                "active": _text(doc.get("active"))[:MAX_NAME] or None,
                "recorded": recorded if isinstance(recorded, int) and not isinstance(recorded, bool) else len(pages),
                "maneuvers": list(pages), "table4": [_table_row(r) for r in table4(list(results))]}
