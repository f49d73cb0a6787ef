"""How a parameter's history is shown, for every front end that draws it (the replay figures,
the control-room page): its unit and the y-range of its estimate and 2-sigma band.

Units (Eq. 2): a derivative with respect to a flow angle, a control surface or a
nondimensional rate (``q_hat = q cbar/2V``, in rad) is per radian (``1/rad``); the bias
(``CZ_0``) is dimensionless (``-``).

The y-range (:func:`band_limits`): the ``RANGE_QUANTILE`` and ``1 - RANGE_QUANTILE`` quantiles
(numpy's linear interpolation) of ``theta -/+ 2 SE`` (corrected standard error, Eq. 22) over the
samples after the start-up transient, widened to hold the newest sample's band, padded by
``RANGE_PAD`` of the span. The replay figures take the samples from the excitation onset; the
page, which has no regressors, drops the first ``TRANSIENT_FRACTION`` of the samples it shows.
numpy only.
"""

from __future__ import annotations

import numpy as np

__all__ = ["RANGE_QUANTILE", "RANGE_PAD", "TRANSIENT_FRACTION", "band_limits", "parameter_unit", "parameter_rate",
           "unit_table"]

RANGE_QUANTILE = 0.05  # quantile of the band's edges that sets the range (a short spike does not)
RANGE_PAD = 0.08  # fraction of the span added above and below
TRANSIENT_FRACTION = 0.2  # the page: the first fifth of the samples shown is the start-up transient

_PER_RADIAN = ("alpha", "beta", "delta_e", "delta_a", "delta_r", "p", "q", "r")
_RATE_REGRESSOR = {"p": "p b/2V", "q": "q cbar/2V", "r": "r b/2V"}


def band_limits(theta: np.ndarray, se: np.ndarray, *, quantile: float = RANGE_QUANTILE,
                pad: float = RANGE_PAD) -> tuple[float, float] | None:
    """y-limits holding ``theta -/+ 2 se`` of the given samples (see the module docstring);
    non-finite samples are ignored; None when fewer than two finite samples remain."""
    theta, se = np.asarray(theta, dtype=float), np.asarray(se, dtype=float)
    ok = np.isfinite(theta) & np.isfinite(se)
    if ok.sum() < 2:
        return None
    th, s = theta[ok], se[ok]
    lo = min(float(np.quantile(th - 2 * s, quantile)), float(th[-1] - 2 * s[-1]))
    hi = max(float(np.quantile(th + 2 * s, 1 - quantile)), float(th[-1] + 2 * s[-1]))
    span = hi - lo if hi > lo else max(abs(hi), 1e-12)
    return lo - pad * span, hi + pad * span


def _suffix(parameter: str) -> str:
    """``CZ_alpha`` -> ``alpha`` (outputs of Eq. 1 have no underscore)."""
    return parameter.split("_", 1)[1] if "_" in parameter else ""


def parameter_unit(parameter: str) -> str:
    """``1/rad`` or ``-`` (dimensionless), from the parameter's name (module docstring)."""
    return "1/rad" if _suffix(parameter) in _PER_RADIAN else "-"


def parameter_rate(parameter: str) -> str:
    """For a rate derivative, the nondimensional rate it is per (``q cbar/2V``); else empty."""
    return _RATE_REGRESSOR.get(_suffix(parameter), "")


def unit_table() -> dict[str, str]:
    """Per parameter suffix (``alpha``, ``q``, ``0``), the unit as the page writes it:
    ``1/rad``, ``1/rad (per q cbar/2V)``, ``dimensionless``."""
    out = {"0": "dimensionless"}
    for suffix in _PER_RADIAN:
        rate = _RATE_REGRESSOR.get(suffix)
        out[suffix] = "1/rad" + (f" (per {rate})" if rate else "")
    return out
