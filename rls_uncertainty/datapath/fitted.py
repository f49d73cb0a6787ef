"""The models a pipeline has identified, taken out of it: :class:`FittedModel` (numpy only).

Per model that published time-domain estimates at the pipeline's newest sample: its names,
the recursive estimates (Eqs. 15-16), their corrected covariance (Eq. 20 with all lags, Eq. 22
with the configured window; repaired to the nearest positive semi-definite matrix when
needed, as published) and conventional covariance (Eq. 13), the residual variance ``R(0)``
(Eq. 16) and the samples used. ``models.json`` (:mod:`..offline.model_file`) writes them, and
the maneuver history (:mod:`.maneuvers`) keeps them per maneuver.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # annotations only
    from .pipeline import Pipeline

__all__ = ["FittedModel", "run_models"]


@dataclass(frozen=True)
class FittedModel:
    """One model identified on one maneuver (module docstring): ``estimate`` ``(n,)``,
    ``covariance`` and ``covariance_conventional`` ``(n, n)``."""

    model: str
    regressors: tuple[str, ...]
    parameters: tuple[str, ...]
    estimate: np.ndarray
    covariance: np.ndarray
    covariance_conventional: np.ndarray
    residual_variance: float
    samples: int

    def as_json(self) -> dict[str, Any]:
        return {"model": self.model, "regressors": list(self.regressors), "parameters": list(self.parameters),
                "estimate": self.estimate.tolist(), "covariance": self.covariance.tolist(),
                "covariance_conventional": self.covariance_conventional.tolist(),
                "residual_variance": self.residual_variance, "samples": self.samples}


def run_models(pipe: Pipeline) -> list[FittedModel]:
    """Every model of ``pipe`` that published at its last sample (:attr:`.pipeline.Pipeline.last`),
    with its estimates, both covariances and its residual variance from the estimator's state
    at the end of the run (the last sample's)."""
    last = pipe.last
    if last is None or not pipe.config.publishes_time:
        return []
    bank = pipe.bank
    cov = bank.covariance_all()
    variances = bank.residual_variances()
    out = []
    for j, m in enumerate(pipe.models):
        n = pipe.sizes[j]
        if not last.ready[j]:
            continue
        out.append(FittedModel(m.output, tuple(m.regressors), tuple(m.parameter_names), last.theta[j, :n].copy(),
                               _symmetric(cov[0, j, :n, :n]), _symmetric(cov[1, j, :n, :n]), float(variances[j]),
                               int(bank.k)))
    return out


def _symmetric(c: np.ndarray) -> np.ndarray:
    out: np.ndarray = 0.5 * (c + c.T)
    return out
