"""Fig. 12 of the paper for a campaign, through :func:`.figures.figure12`: every maneuver's
end-of-maneuver estimate of each parameter of one model with its conventional (Eq. 13),
corrected (Eq. 22) and all-lags corrected (Eq. 20) 2-sigma bars, the mean over the maneuvers
and the band mean +- 2 scatter, both Table 4's. Matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .run import ManeuverResult
from .table4 import Table4Row

__all__ = ["campaign_figures"]


def _columns(rows: Sequence[Table4Row], results: Sequence[ManeuverResult]) -> dict[str, np.ndarray]:
    """``(maneuvers, parameters)`` arrays of the estimates and the three standard errors of the
    parameters ``rows``, NaN where a maneuver gave no value."""
    names = [r.parameter for r in rows]
    values = {(p.maneuver, p.parameter): p for res in results for p in res.rows if p.ok}
    out = {}
    for field in ("estimate", "se_conventional", "se_corrected", "se_corrected_all"):
        out[field] = np.array([[getattr(values[(res.name, n)], field) if (res.name, n) in values else np.nan
                                for n in names] for res in results])
    return out


def campaign_figures(out: Path, rows: Sequence[Table4Row], results: Sequence[ManeuverResult], *,
                     formats: Sequence[str] = ("png",), dpi: int | None = None, lags: str = "configured lags",
                     ) -> list[Path]:
    """``fig12_<model>.<fmt>`` for every model with an estimate in some maneuver."""
    from ..figures import DEFAULT_DPI, figure12  # noqa: PLC0415 - matplotlib only when drawing

    written: list[Path] = []
    for model in dict.fromkeys(r.model for r in rows):
        mine = [r for r in rows if r.model == model]
        if not any(r.maneuvers for r in mine):
            continue
        c = _columns(mine, results)
        written += figure12(model, [res.name for res in results], [r.parameter for r in mine], c["estimate"],
                            c["se_conventional"], c["se_corrected"], out, se_corrected_all=c["se_corrected_all"],
                            formats=formats, dpi=DEFAULT_DPI if dpi is None else dpi, lags=lags,
                            mean=[r.mean for r in mine], scatter=[r.scatter for r in mine], stem=f"fig12_{model}")
    return written
