"""The instruments' settings (``instruments.*`` parameters), declared once (:mod:`..schema`)."""

from __future__ import annotations

from dataclasses import dataclass

from ..schema import check, option
from .strength import WEAK_BELOW

__all__ = ["InstrumentOptions"]


@dataclass(frozen=True)
class InstrumentOptions:
    """How ``estimator.algorithm iv`` builds its instruments (:class:`.auxiliary.ShortPeriodAuxiliary`)
    and when it calls them weak (:class:`.strength.InstrumentStrength`)."""

    refresh_span: float = option(
        0.5, "estimator.algorithm iv: time between rebuilds of the auxiliary short-period model that turns the "
        "injected excitation into instruments, from the current estimates", unit="s", low=0.02, high=60.0,
        ros="instruments.refresh_span")
    weak_below: float = option(
        WEAK_BELOW, "estimator.algorithm iv: instruments whose smallest canonical correlation with the regressors "
        "is below this are weak: said once per model, and the model's parameters are never flagged converged",
        low=0.0, high=0.99, ros="instruments.weak_below")
    max_backlog_span: float = option(
        30.0, "estimator.algorithm iv: longest time the samples wait for the first auxiliary model (older ones are "
        "rejected as instruments_not_ready)", unit="s", low=1.0, high=600.0, ros="instruments.max_backlog_span")

    def __post_init__(self) -> None:
        check(self, "instruments")
