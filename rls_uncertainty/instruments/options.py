"""The instruments' settings (``instruments.*`` parameters), declared once (:mod:`..schema`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..aero.models import ModelConfig
from ..errors import ConfigError
from ..schema import check, option
from .layout import InstrumentLayout
from .strength import WEAK_BELOW

__all__ = ["SOURCES", "InstrumentOptions"]

# Where the instruments come from: the short-period auxiliary model driven by the injected
# excitation (:mod:`.auxiliary`) or the surfaces and delayed regressors (:mod:`.delayed`);
# ``auto``: the first when it serves the models, else the second.
SOURCES = ("auto", "excitation", "delayed")


@dataclass(frozen=True)
class InstrumentOptions:
    """How ``estimator.algorithm iv`` builds its instruments (:class:`.auxiliary.ShortPeriodAuxiliary`
    or :class:`.delayed.DelayedRegressors`) and when it calls them weak
    (:class:`.strength.InstrumentStrength`)."""

    source: str = option(
        "auto", "estimator.algorithm iv: where the instruments come from: excitation (the injected input on "
        "topics.excitation through an auxiliary short-period model; CZ and Cm models only), delayed (the measured "
        "surfaces for themselves and every other regressor delayed by instruments.delay_span; any model, no "
        "excitation needed) or auto (excitation when the models are the short-period ones, else delayed)",
        choices=SOURCES, ros="instruments.source")
    delay_span: float = option(
        0.5, "estimator.algorithm iv with instruments.source delayed: how far back the regressors that are not "
        "surfaces are taken as instruments; longer than the residual stays correlated, short enough that the "
        "delayed motion still moves with the present one (the weak-instrument test says when not)", unit="s",
        low=0.001, high=10.0, ros="instruments.delay_span")

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

    def resolved_source(self, models: Sequence[ModelConfig]) -> str:
        """``excitation`` or ``delayed`` for ``models``; with ``excitation`` chosen, models the
        auxiliary model cannot serve are refused (:class:`ConfigError`, one line)."""
        if self.source == "delayed":
            return "delayed"
        if self.source == "excitation":
            InstrumentLayout(models)
            return "excitation"
        try:
            InstrumentLayout(models)
        except ConfigError:
            return "delayed"
        return "excitation"
