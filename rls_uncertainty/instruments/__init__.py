"""Instruments for the recursive instrumental-variables estimator (numerical core: numpy only).

An instrument moves with a model's regressors and carries neither their sensor noise nor the
gusts. :class:`.auxiliary.ShortPeriodAuxiliary` builds one per sample for each short-period
model from the injected elevator excitation and an auxiliary model of the aircraft
(:mod:`.layout` places it like the model's regressor vector, :mod:`.discrete` discretizes the
auxiliary model, :mod:`.bootstrap` fits it before the estimator has estimates);
:mod:`.strength` says when the instruments are too weak to use.
"""

from .auxiliary import InstrumentedSample, ShortPeriodAuxiliary
from .bootstrap import BareRls
from .delayed import DelayedRegressors
from .discrete import discretize, is_stable, short_period_matrices
from .layout import InstrumentLayout
from .strength import WEAK_BELOW, InstrumentStrength, canonical_correlations

__all__ = [
    "InstrumentedSample",
    "ShortPeriodAuxiliary",
    "BareRls",
    "DelayedRegressors",
    "discretize",
    "is_stable",
    "short_period_matrices",
    "InstrumentLayout",
    "WEAK_BELOW",
    "InstrumentStrength",
    "canonical_correlations",
]
