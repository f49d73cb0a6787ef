"""A model's fit and its parameters' identifiability as the page shows them, read back from the
node's ``~/M/fit`` and ``~/M/identifiability`` arrays (docs/node.md#fit-and-identifiability; no
ROS, no web server).

``~/M/fit`` is ``[r_squared, samples, bound_2sigma, rho_1 ... rho_L]``: R^2, the samples ``n``
since the estimator started, the white-noise bound ``2 / sqrt(n)`` and the residual
autocorrelation coefficients ``rho_i = R(i) / R(0)`` of Eq. 17 at the ``L`` lags in use: the
paper's Fig. 5.

``~/M/identifiability`` is one row per parameter: its estimate's correlation with each
parameter's (the corrected covariance, Eqs. 20/22), its regressor's standard deviation since the
start (``excitation``), the resolution it is tested against (both 0 for the bias, which is not
tested) and 1/0 identifiable. :func:`reasons` says in a few words why a parameter is not
identifiable, from those figures alone, as :mod:`..identifiability` decides it (most fundamental
first):

1. a slope whose regressor's standard deviation is at most its resolution is *not excited*;
2. when every parameter of the model is not identifiable and no regressor is flat, the model
   *explains nothing* (R^2 under ``identifiability.min_r_squared``, which only that test makes
   fail for every parameter at once);
3. otherwise a slope that is excited but not identifiable is *correlated* with another beyond
   ``identifiability.max_correlation``: the one its estimate is most correlated with is named;
4. the bias, when not identifiable but the model fits, is *confounded* with the flat regressors
   (their mean is off zero).

The arrays do not carry the thresholds, so one case is told from the node's words: every
parameter not identifiable *and* a flat regressor could be case 2 or cases 3-4; the model's
``/diagnostics`` text names ``identifiability.min_r_squared`` exactly when the fit is the reason.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..datapath.outputs import parse_stamp_label

__all__ = ["Fit", "Identifiability", "fit_of", "identifiability_of", "reasons", "quality_json", "NO_FIT_PARAMETER"]

NO_FIT_PARAMETER = "identifiability.min_r_squared"  # named by the node's text when the fit is the reason
_IDENTIFIABILITY_COLUMNS = ("excitation", "resolution", "identifiable")


def _finite(values: Sequence[float], what: str) -> tuple[float, ...]:
    out = tuple(float(x) for x in values)
    if not all(math.isfinite(x) for x in out):
        raise ValueError(f"{what}: non-finite values")
    return out


@dataclass(frozen=True)
class Fit:
    """One ``~/M/fit`` array (module docstring)."""

    stamp_ns: int
    r_squared: float
    samples: int
    bound_2sigma: float
    rho: tuple[float, ...]

    def as_json(self) -> dict:
        outside = sum(abs(r) > self.bound_2sigma for r in self.rho)
        return {"stamp": self.stamp_ns * 1e-9, "r_squared": self.r_squared, "samples": self.samples,
                "bound_2sigma": self.bound_2sigma, "rho": list(self.rho),
                "outside": outside / len(self.rho) if self.rho else 0.0}


def fit_of(msg: Any) -> Fit:
    """A :class:`Fit` from a ``Float64MultiArray`` (read by field name); ValueError when its
    layout is not the node's."""
    dims = msg.layout.dim
    data = _finite(msg.data, "fit")
    if len(dims) != 2 or not str(dims[0].label).startswith("r_squared,samples,bound_2sigma") or len(data) < 3:
        raise ValueError("fit: not the layout [r_squared, samples, bound_2sigma, rho_1..rho_L] + stamp")
    return Fit(parse_stamp_label(str(dims[-1].label)), data[0], int(data[1]), data[2], data[3:])


@dataclass(frozen=True)
class Identifiability:
    """One ``~/M/identifiability`` array (module docstring), by parameter."""

    stamp_ns: int
    names: tuple[str, ...]
    correlation: tuple[tuple[float, ...], ...]
    excitation: tuple[float, ...]
    resolution: tuple[float, ...]
    identifiable: tuple[bool, ...]


def identifiability_of(msg: Any) -> Identifiability:
    """An :class:`Identifiability` from a ``Float64MultiArray`` (read by field name);
    ValueError when its layout is not the node's ``n x (n + 3)`` table."""
    dims = msg.layout.dim
    if len(dims) != 3:
        raise ValueError(f"identifiability: {len(dims)} dims, expected parameters, columns and stamp")
    names = tuple(str(dims[0].label).split(","))
    n = len(names)
    columns = tuple(str(dims[1].label).split(","))
    data = _finite(msg.data, "identifiability")
    if columns != (*names, *_IDENTIFIABILITY_COLUMNS) or len(data) != n * (n + 3):
        raise ValueError("identifiability: not the n x (n + 3) table of the parameters")
    rows = [data[i * (n + 3) : (i + 1) * (n + 3)] for i in range(n)]
    return Identifiability(parse_stamp_label(str(dims[-1].label)), names, tuple(tuple(r[:n]) for r in rows),
                           tuple(r[n] for r in rows), tuple(r[n + 1] for r in rows),
                           tuple(r[n + 2] == 1.0 for r in rows))


def _bias(name: str) -> bool:
    return name.endswith("_0")  # the regressor "1" (config: the output, then the regressor, bias as 0)


def _partner(t: Identifiability, i: int) -> tuple[str, float] | None:
    """The slope ``i``'s estimate is most correlated with (magnitude), and the correlation."""
    best = None
    for k, name in enumerate(t.names):
        if k != i and not _bias(name) and (best is None or abs(t.correlation[i][k]) > abs(best[1])):
            best = (name, t.correlation[i][k])
    return best


def reasons(t: Identifiability, r_squared: float | None, node_text: str = "") -> dict[str, dict]:
    """Per parameter: ``identifiable``, ``reason`` (empty when identifiable; module docstring),
    ``partner`` and ``correlation`` (the parameter its estimate is most correlated with; none
    for the bias), ``excitation`` and ``resolution``. ``r_squared`` from ``~/M/fit``;
    ``node_text``: the model's ``identifiability`` value in ``/diagnostics`` (or empty)."""
    n = len(t.names)
    flat = [i for i in range(n) if not _bias(t.names[i]) and 0 < t.resolution[i] and t.excitation[i] <= t.resolution[i]]
    none = not any(t.identifiable)
    no_fit = none and (not flat or NO_FIT_PARAMETER in node_text)
    fit = f" (R^2 {r_squared:.3f})" if r_squared is not None else ""
    out = {}
    for i, name in enumerate(t.names):
        partner = None if _bias(name) else _partner(t, i)
        if t.identifiable[i]:
            reason = ""
        elif i in flat:
            reason = f"not excited (std {t.excitation[i]:.2g}, resolution {t.resolution[i]:.2g})"
        elif no_fit:
            reason = f"model explains nothing{fit}"
        elif _bias(name) and flat:
            reason = "confounded with " + ", ".join(t.names[k] for k in flat) + " (not excited, off zero)"
        elif partner is not None:
            reason = f"correlated {partner[1]:.4f} with {partner[0]}"
        else:
            reason = "not identifiable"
        out[name] = {"identifiable": t.identifiable[i], "reason": reason, "excitation": t.excitation[i],
                     "resolution": t.resolution[i], "partner": partner[0] if partner else None,
                     "correlation": partner[1] if partner else None}
    return out


def quality_json(method: str, model: str, fit: Fit | None, table: Identifiability | None,
                 diagnostics: Mapping[str, str] | None) -> dict:
    """The page's ``quality`` message of one model: the fit, the parameters' identifiability
    (:func:`reasons`) and the node's own text about it."""
    node_text = (diagnostics or {}).get("identifiability", "")
    return {"type": "quality", "method": method, "model": model,
            "fit": fit.as_json() if fit is not None else None,
            "parameters": reasons(table, fit.r_squared if fit else None, node_text) if table is not None else None,
            "stamp": table.stamp_ns * 1e-9 if table is not None else None, "node_text": node_text}
