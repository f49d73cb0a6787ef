"""Fig. 12 of the paper for a campaign, through :func:`.figures.figure12`: every maneuver's
end-of-maneuver estimate of each parameter of one model with its conventional (Eq. 13),
corrected (Eq. 22) and all-lags corrected (Eq. 20) 2-sigma bars, the mean over the maneuvers
and the band mean +- 2 scatter, both Table 4's. With the frequency-domain estimates too
(``estimator.method: both``) each maneuver's frequency-domain estimate with its corrected
2-sigma bar stands beside them, with its own mean; with those alone (``frequency``) the figure
is theirs: their conventional (F5) and corrected (F7-F10) bars, their mean and scatter.
Matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..progress import track
from .run import ManeuverResult
from .table4 import Table4Row

__all__ = ["campaign_figures"]


def _columns(rows: Sequence[Table4Row], results: Sequence[ManeuverResult], method: str = "time",
             names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """``(maneuvers, parameters)`` arrays of the ``method``'s estimates and three standard
    errors of the parameters ``names`` (default: those of ``rows``), NaN where a maneuver gave
    no value."""
    names = [r.parameter for r in rows] if names is None else names
    values = {(p.maneuver, p.parameter): p for res in results for p in res.rows if p.ok and p.method == method}
    out = {}
    for field in ("estimate", "se_conventional", "se_corrected", "se_corrected_all"):
        out[field] = np.array([[getattr(values[(res.name, n)], field) if (res.name, n) in values else np.nan
                                for n in names] for res in results], dtype=float).reshape(len(results), len(names))
    return out


def _frequency_beside(rows: Sequence[Table4Row], results: Sequence[ManeuverResult],
                      names: Sequence[str]) -> dict[str, Any]:
    """figure12's arguments for the frequency-domain values beside the time-domain ones of the
    parameters ``names`` (none when no frequency-domain row has an estimate)."""
    freq = [r for r in rows if r.method == "frequency"]
    if not any(r.maneuvers for r in freq):
        return {}
    c = _columns(freq, results, "frequency", names)
    means = {r.parameter: r.mean for r in freq}
    return {"frequency": (c["estimate"], c["se_corrected"]),
            "frequency_mean": [means.get(n, np.nan) for n in names]}


def campaign_figures(out: Path, rows: Sequence[Table4Row], results: Sequence[ManeuverResult], *,
                     formats: Sequence[str] = ("png",), dpi: int | None = None, lags: str = "configured lags",
                     frequency_lags: str = "configured lags", progress: bool | None = False) -> list[Path]:
    """``fig12_<model>.<fmt>`` for every model with an estimate in some maneuver: the
    time-domain values with the frequency-domain ones beside them when the campaign has both,
    the frequency-domain ones alone when it has only those (``frequency_lags``: how their
    corrected bars' lags are named). ``progress``: a bar per figure on stderr."""
    from ..offline.figures import DEFAULT_DPI, figure12  # noqa: PLC0415 - matplotlib only when drawing

    written: list[Path] = []
    models = [m for m in dict.fromkeys(r.model for r in rows) if any(r.maneuvers for r in rows if r.model == m)]
    for model in track(models, len(models), "figures", " figures", progress):
        mine = [r for r in rows if r.model == model]
        primary = [r for r in mine if r.method == "time"]
        if primary:
            method, extra = "time", _frequency_beside(mine, results, [r.parameter for r in primary])
            kw: dict[str, Any] = {"lags": lags, **extra}
        else:
            primary = [r for r in mine if r.method == "frequency"]
            method, kw = "frequency", {"lags": frequency_lags, "title": "frequency domain"}
        c = _columns(primary, results, method)
        written += figure12(model, [res.name for res in results], [r.parameter for r in primary], c["estimate"],
                            c["se_conventional"], c["se_corrected"], out,
                            se_corrected_all=c["se_corrected_all"] if method == "time" else None,
                            formats=formats, dpi=DEFAULT_DPI if dpi is None else dpi,
                            mean=[r.mean for r in primary], scatter=[r.scatter for r in primary],
                            stem=f"fig12_{model}", **kw)
    return written
