"""One maneuver of a campaign through the replay's pipeline, with the configured and with all lags.

:func:`run_maneuver` reads the maneuver's bag (or its span of a recording) as a stream into
:func:`..replay.run_pipeline`, the same pipeline as ``rls-uncertainty replay`` and the node,
which keeps the regression rows it hands to its estimator. The same rows, sample by sample,
then go into a second :class:`..estimator.EstimatorBank` with every lag (Eq. 20,
``lags="all"``; otherwise the configured options): the data is read once and both corrected
standard errors belong to the same estimates. The rows since the pipeline's last restart are
the ones its estimator saw, so the two banks agree sample for sample.

A maneuver's end-of-maneuver values become :class:`ParameterResult` rows (``maneuvers.csv``),
one per parameter of every configured model: ``status`` ``ok``, ``no estimate: <why>`` (the
model never became identifiable: too short, not excited) or ``failed: <why>`` (the bag could not
be read). The failure of one maneuver is its own rows' status, never the campaign's.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from ..bags import InputStream
from ..config import PipelineConfig
from ..errors import RlsUncertaintyError
from ..estimator import EstimatorBank
from ..inputs import Stamped
from ..replay import run_pipeline
from ..results import ReplayResult
from .maneuvers import Maneuver

__all__ = ["CampaignSettings", "ParameterResult", "ManeuverResult", "MANEUVER_COLUMNS", "run_maneuver",
           "failed_result"]

OK = "ok"


@dataclass(frozen=True)
class CampaignSettings:
    """What every maneuver is run with: the pipeline's configuration, the input topics
    (``topics.*``) and ``strict`` (``replay``'s default; False is ``--lenient``)."""

    config: PipelineConfig
    topics: Mapping[str, str] = field(default_factory=dict)
    strict: bool = True


@dataclass(frozen=True)
class ParameterResult:
    """A row of ``maneuvers.csv``: one parameter's end-of-maneuver values. ``se_corrected``
    is the corrected standard error with the configured lags (Eq. 22), ``se_corrected_all``
    with all lags (Eq. 20), ``se_conventional`` Eq. 13; ``samples`` those the model's
    estimator used, ``r_squared`` its fit; NaN where the maneuver gave none."""

    maneuver: str
    model: str
    parameter: str
    estimate: float
    se_conventional: float
    se_corrected: float
    se_corrected_all: float
    samples: int
    r_squared: float
    status: str

    @property
    def ok(self) -> bool:
        return self.status == OK


MANEUVER_COLUMNS = tuple(f.name for f in fields(ParameterResult))


@dataclass(frozen=True)
class ManeuverResult:
    """A maneuver's rows, and where its time went (s): ``seconds["read"]`` reading and
    decoding the bag, ``["pipeline"]`` the pipeline with the configured lags, ``["all_lags"]``
    the all-lags bank; ``data_seconds`` the span of data read."""

    name: str
    rows: tuple[ParameterResult, ...]
    data_seconds: float = 0.0
    seconds: Mapping[str, float] = field(default_factory=dict)

    @property
    def problem(self) -> str | None:
        """The maneuver's failure (its rows' status), None when some model was estimated."""
        return None if any(r.ok for r in self.rows) or not self.rows else self.rows[0].status


class _TimedStream:
    """Iterates a message stream, adding the time spent inside it (reading, decoding) to
    :attr:`seconds`."""

    def __init__(self, messages: Iterable[tuple[str, int, Stamped]]) -> None:
        self._it: Iterator[tuple[str, int, Stamped]] = iter(messages)
        self.seconds = 0.0

    def __iter__(self) -> _TimedStream:
        return self

    def __next__(self) -> tuple[str, int, Stamped]:
        t0 = time.perf_counter()
        try:
            return next(self._it)
        finally:
            self.seconds += time.perf_counter() - t0


def failed_result(maneuver: str, config: PipelineConfig, status: str) -> ManeuverResult:
    """Rows of a maneuver that produced nothing: every parameter with ``status``."""
    nan = math.nan
    rows = tuple(ParameterResult(maneuver, m.output, p, nan, nan, nan, nan, 0, nan, status)
                 for m in config.models for p in m.parameter_names)
    return ManeuverResult(maneuver, rows)


def all_lags_bank(result: ReplayResult) -> EstimatorBank:
    """A bank with every lag (Eq. 20) fed the regression rows the run's estimator used, in
    order; the other options are the run's (the residual burn-in resolved as configured)."""
    pipe = result.pipeline
    assert pipe is not None  # run_pipeline keeps its pipeline
    o = pipe.config.estimator
    bank = EstimatorBank(pipe.sizes, replace(o, lags="all", residual_burn_in=o.burn_in, noise_forgetting=None))
    for _t, X, z in pipe.regression:
        bank.update(X, z)
    return bank


def _rows(name: str, result: ReplayResult, bank_all: EstimatorBank) -> tuple[ParameterResult, ...]:
    pipe = result.pipeline
    assert pipe is not None
    # (A bank that saw no sample has no standard errors to evaluate.)
    se_all = bank_all.standard_errors_all("corrected") if bank_all.ready.any() else None
    last_row = pipe.regression[-1][0] if pipe.regression else None
    why = {line.split(":", 1)[0]: line.split(":", 1)[1].strip() for line in result.explanations}
    rows = []
    for j, m in enumerate(pipe.models):
        fit = pipe.model_fit(j)
        samples = int(fit.get("samples", 0))
        r2 = float(fit.get("r_squared", math.nan))
        for i, p in enumerate(pipe.parameter_names[j]):
            try:
                final = result.final(p)
            except RlsUncertaintyError:
                reason = why.get(m.output) or why.get("no estimates") or "no estimate: its model never became ready"
                status = reason if reason.startswith("no estimate") else f"no estimate: {reason}"
                rows.append(ParameterResult(name, m.output, p, math.nan, math.nan, math.nan, math.nan, samples,
                                            r2, status))
                continue
            # All lags at the sample of the final estimates (the last row, unless the model's
            # last outputs were withheld as non-finite).
            s_all = float(se_all[j, i]) if se_all is not None and final.stamp_ns == last_row else math.nan
            rows.append(ParameterResult(name, m.output, p, final.estimate, final.std_error_conventional,
                                        final.std_error, s_all, samples, r2, OK))
    return tuple(rows)


def run_maneuver(job: tuple[Maneuver, CampaignSettings]) -> ManeuverResult:
    """One maneuver (``job``: the maneuver and the campaign's settings) through the pipeline
    and the all-lags bank (module docstring). A bag that cannot be read, or a span outside it,
    gives ``failed: <why>`` rows; nothing is raised for the user's data."""
    maneuver, settings = job
    config = settings.config
    t0 = time.perf_counter()
    try:
        with InputStream(maneuver.bag, dict(settings.topics), strict=settings.strict, start=maneuver.start,
                         end=maneuver.end) as stream:
            opened = time.perf_counter()
            timed = _TimedStream(stream)
            result = run_pipeline(timed, config, record=True, keep_outputs=False)
        t1 = time.perf_counter()
        bank_all = all_lags_bank(result)
    except (RlsUncertaintyError, OSError) as exc:
        return failed_result(maneuver.name, config, f"failed: {' '.join(str(exc).split())}")
    rows = _rows(maneuver.name, result, bank_all)
    t2 = time.perf_counter()
    read = opened - t0 + timed.seconds
    seconds: dict[str, Any] = {"read": read, "pipeline": t1 - t0 - read, "all_lags": t2 - t1}
    return ManeuverResult(maneuver.name, rows, result.data_seconds, seconds)
