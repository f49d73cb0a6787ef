"""Every counter of a :class:`.pipeline.Pipeline`, what the refused inputs carried, and the fit
statistics it reports (numpy only).

:class:`Bookkeeping` outlives a reconfiguration (a reconfigured pipeline takes over the same
object): the messages of each input stream (:class:`.sampling.StreamCounts`), samples formed,
used and rejected by reason, estimator resets, JointState joints that no surface uses, model
outputs withheld as non-finite, and :attr:`Bookkeeping.evidence`: per stream and reason,
what the newest refused input carried (the joint names, the frame, the value beyond a
limit), so that a misconfiguration can be reported in the user's terms (:mod:`.alerts`).
Every table keyed by what arrives keeps a bounded number of keys.

:func:`model_fit` is the fit of one model that ``/diagnostics`` and the replay report: R^2
(:mod:`.identifiability`) and the residual whiteness from the autocorrelation of Eq. 17.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .streams import StreamCounts

if TYPE_CHECKING:  # annotations only
    from ..estimator import EstimatorBank

__all__ = [
    "Bookkeeping", "count_bounded", "model_fit", "SAMPLES", "KEYS_KEPT", "KEY_CHARS", "OTHER_JOINTS",
    "OTHER_REASONS", "EVIDENCE_ITEMS",
]

# Bounds of the tables keyed by what arrives: a flood of distinct JointState names or
# caller-given reasons adds one overflow key, not a key each.
KEYS_KEPT = 32  # distinct keys per table, the overflow key aside
KEY_CHARS = 64  # longer keys (a JointState name is any string) are cut to this length
OTHER_JOINTS = "<others>"  # unknown joints beyond the first KEYS_KEPT names
OTHER_REASONS = "other"  # rejection reasons beyond the first KEYS_KEPT of a stream
SAMPLES = "samples"  # the evidence key of the formed samples (beside the input streams)
EVIDENCE_ITEMS = 8  # names kept of a refused JointState (the rest is counted)
_EVIDENCE_KEYS = 256  # (stream, reason) pairs with evidence, at most


def count_bounded(counter: Counter, key: str, other: str, n: int = 1) -> None:
    """``counter[key] += n`` for at most :data:`KEYS_KEPT` distinct keys (cut to
    :data:`KEY_CHARS` characters); once the table is full, new keys count under ``other``."""
    key = key[:KEY_CHARS]
    if key not in counter and len(counter) - (other in counter) >= KEYS_KEPT:
        key = other
    counter[key] += n


@dataclass
class Bookkeeping:
    """Every counter of a pipeline, kept across reconfigurations: the messages of each input
    stream, samples formed, used and rejected (by reason), estimator resets (by reason),
    JointState joints that no surface uses (by name, at most :data:`KEYS_KEPT`, the rest as
    :data:`OTHER_JOINTS`), model outputs withheld because they were not finite (by model),
    and the evidence of the newest refusal per ``(stream, reason)`` (:meth:`note`)."""

    streams: dict[str, StreamCounts]
    samples_formed: int = 0
    samples_used: int = 0
    samples_rejected: Counter = field(default_factory=Counter)
    resets: Counter = field(default_factory=Counter)
    unknown_joints: Counter = field(default_factory=Counter)
    outputs_withheld: Counter = field(default_factory=Counter)
    evidence: dict[tuple[str, str], Any] = field(default_factory=dict)

    @classmethod
    def for_streams(cls, names: tuple[str, ...]) -> Bookkeeping:
        return cls({name: StreamCounts() for name in names})

    def note(self, stream: str, reason: str, what: Any) -> None:
        """Keep ``what`` (small: a tuple of a few names or numbers, a short string) as the
        evidence of the newest input of ``stream`` (or :data:`SAMPLES`) refused for ``reason``.
        At most a fixed number of pairs are kept; later new pairs are not."""
        key = (stream, reason)
        if key in self.evidence or len(self.evidence) < _EVIDENCE_KEYS:
            self.evidence[key] = what

    def report(self, pending: int) -> dict:
        """The counters as plain values (``/diagnostics``, the replay's summary); ``pending``:
        samples waiting in the differentiator's delay line."""
        return {
            "streams": {name: counts.report() for name, counts in self.streams.items()},
            "samples_formed": self.samples_formed,
            "samples_used": self.samples_used,
            "samples_rejected": dict(self.samples_rejected),
            "samples_pending": pending,
            "resets": dict(self.resets),
            "unknown_joints": dict(self.unknown_joints),
            "outputs_withheld": dict(self.outputs_withheld),
        }


def model_fit(bank: EstimatorBank, j: int, r2: float, withheld_now: bool, withheld: int) -> dict:
    """Model ``j`` of ``bank``'s fit: ``r2``, its R^2 (:meth:`.identifiability.
    IdentifiabilityMonitor.fit`: 1 - residual variance / output variance, both since the
    estimator started) and the residual whiteness: the lag-1 autocorrelation coefficient and
    the fraction of lags whose coefficient lies outside the 2-sigma white-noise bound 2/sqrt(n)
    (Eq. 17's R). ``ready`` is false, with a ``problem``, when R^2 is undefined (NaN: a constant
    output) or the model's outputs were withheld as non-finite (``withheld_now``: the newest
    sample's; ``withheld``: how many so far)."""
    if not bank.ready[j]:
        return {"ready": False, "samples": bank.k}
    n = bank.k  # samples since the estimator (re)started
    R = bank.autocorrelation(j)
    # A constant output (variance at rounding level) leaves R^2 undefined; a non-finite
    # estimator state (withheld outputs) leaves it NaN: either way the fit is reported as
    # not ready, with the problem, never as an OK "nan".
    if not math.isfinite(r2) or withheld_now:
        problem = "outputs not finite, withheld" if withheld_now or not np.isfinite(R).all() else \
            "output constant: R^2 undefined"
        return {"ready": False, "samples": bank.k, "problem": problem, "outputs_withheld": withheld}
    rho = R[1:] / R[0] if R[0] > 0 else np.zeros(0)
    bound = 2.0 / math.sqrt(max(n, 1))
    return {
        "ready": True,
        "samples": bank.k,
        # The largest lag of Eq. 22 the corrected covariance uses now (at most
        # the lag span times the rate; chosen per model with automatic lags).
        "lags": int(bank.lags_used[j]),
        "r_squared": float(r2),
        "residual_rho1": float(rho[0]) if rho.size else float("nan"),
        "lags_outside_2sigma": float(np.mean(np.abs(rho) > bound)) if rho.size else float("nan"),
        "repairs": int(bank.repairs[j]),
        "outputs_withheld": withheld,
    }
