"""The publication rule: which models of a bank publish their estimates and standard errors.

A model publishes once its residual degrees of freedom ``k - n`` (``k - k0 - B - n`` after a
residual burn-in of ``B`` samples from its initialization at ``k0``) reach
``estimator.publish_lag_windows`` lag windows ``L`` of Eq. 22
(:meth:`.options.EstimatorOptions.publish_samples`). Below that the corrected standard error
of Eqs. 20-22 is an artefact of the window: at ``k = n`` the residuals are those of an exact
fit and ``R_k(i)`` is zero. numpy only.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .options import EstimatorOptions

__all__ = ["PublicationRule"]

_NEVER = 2**62  # (a judgement that holds until the next restart)


class PublicationRule:
    """The rule for models of ``sizes`` parameters under ``options``; once every model
    publishes it stays so until :meth:`restart` (a new initialization or a restored state).
    Between restarts the judgement depends on ``k`` alone and only ever adds models, so it is
    made again only at the next ``k`` at which a waiting model's count reaches its threshold."""

    def __init__(self, sizes: Sequence[int], options: EstimatorOptions) -> None:
        self.at = np.array([options.publish_samples(s) for s in sizes], dtype=np.int64)
        self._burn_in = options.burn_in
        self.all_published = False
        self._k = -1  # the sample count of the last judgement (-1: none since the last restart)
        self._until = 0  # the judgement of _k holds for every k in [_k, _until)
        self._last = np.zeros(len(self.at), dtype=bool)
        self.hidden = np.ones((len(self.at), 1), dtype=bool)  # not published, as a column (last judgement)

    def restart(self) -> None:
        """Readiness changed: judge afresh."""
        self.all_published = False
        self._k, self._until = -1, 0

    def count(self, k: int, initialized: np.ndarray, ready_at: np.ndarray) -> np.ndarray:
        """What the rule counts for each model at sample ``k``, ``(M,)``: ``k``, or after a
        residual burn-in the samples after it (``k - k0 - B``; negative before it, 0 for a
        model not initialized)."""
        if not self._burn_in:
            return np.full(len(self.at), k, dtype=np.int64)
        return np.where(initialized, k - ready_at - self._burn_in, 0)

    def published(self, k: int, initialized: np.ndarray, ready_at: np.ndarray) -> np.ndarray:
        """Boolean per model: initialized and past the rule (``initialized`` itself, not a
        copy, once every model is)."""
        if self.all_published:
            return initialized
        if self._k <= k < self._until:
            return self._last
        count = self.count(k, initialized, ready_at) if self._burn_in else k
        published: np.ndarray = initialized & (count >= self.at)
        if published.all():
            self.all_published = True
        self._k, self._last = k, published
        # The count grows with k (one per sample): the next change is at the first k at which
        # an initialized model still waiting reaches its threshold.
        waiting = initialized > published
        self._until = (k + int((self.at - count)[waiting].min())) if waiting.any() else _NEVER
        self.hidden = ~published[:, None]
        return published
