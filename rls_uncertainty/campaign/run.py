"""One maneuver of a campaign through the replay's pipeline, with the configured and with all lags.

:func:`run_maneuver` reads the maneuver's bag (or its span of a recording) as a stream into
:func:`..replay.run_pipeline`, the same pipeline as ``rls-uncertainty replay`` and the node,
which keeps the regression rows it hands to its estimator. The same rows, sample by sample,
then go into a second :class:`..estimator.EstimatorBank` with every lag (Eq. 20,
``lags="all"``; otherwise the configured options): the data is read once and both corrected
standard errors belong to the same estimates. The rows since the pipeline's last restart are
the ones its estimator saw, so the two banks agree sample for sample.

With ``estimator.method`` ``frequency`` or ``both`` the same run also carries the
frequency-domain estimator (:mod:`..frequency_path`): its last published estimates and
standard errors become rows of their own (``method`` ``frequency``, over the parameters
without the bias), bit for bit the last rows of the replay's ``estimates_frequency.csv``.
The all-lags bank belongs to the time domain: it runs only when the time-domain estimates are
published (``time``, ``both``).

A maneuver's end-of-maneuver values become :class:`ParameterResult` rows (``maneuvers.csv``),
one per parameter of every configured model and published method (per parameter the
time-domain row, then the frequency-domain one): ``status`` ``ok``, ``too_short: <span>`` (less
data than ``--min-span``: its parameters could not be flagged converged; left out of Table 4),
``no estimate: <why>`` (the model never published: too few samples for the publication rule,
not excited) or ``failed: <why>`` (the bag could not be read); with each parameter's state at
the end (:mod:`..datapath.states`: ``converged``, ``settling``, ``held back`` with the reason)
and its percent error; with ``targets.percent`` set, each row of the maneuver carries its
verdict at the end (:mod:`..datapath.targets`). The failure of one maneuver is its own rows' status, never the
campaign's.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from ..datapath.config import PipelineConfig
from ..datapath.feasibility import record_checks
from ..datapath.inputs import Stamped
from ..datapath.maneuvers import MANEUVER_COLUMNS, OK, ParameterResult, verdict_of
from ..datapath.pipeline import all_lags_bank
from ..datapath.states import ParameterState
from ..errors import RlsUncertaintyError
from ..estimator import EstimatorBank
from ..offline.bags import InputStream
from ..offline.model_file import FittedModel, run_models
from ..offline.replay import run_pipeline
from ..offline.results import ReplayResult
from .maneuvers import MIN_SPAN, CampaignSettings, Maneuver

__all__ = ["CampaignSettings", "ParameterResult", "ManeuverResult", "MANEUVER_COLUMNS", "run_maneuver",
           "failed_result", "MIN_SPAN", "TOO_SHORT"]

TOO_SHORT = "too_short"


@dataclass(frozen=True)
class ManeuverResult:
    """A maneuver's rows, and where its time went (s): ``seconds["read"]`` reading and
    decoding the bag, ``["pipeline"]`` the pipeline with the configured lags, ``["all_lags"]``
    the all-lags bank; ``data_seconds`` the span of data read; ``models`` the models identified
    at its end (:mod:`..offline.model_file`; none for a maneuver too short or failed)."""

    name: str
    rows: tuple[ParameterResult, ...]
    data_seconds: float = 0.0
    seconds: Mapping[str, float] = field(default_factory=dict)
    models: tuple[FittedModel, ...] = field(default=(), compare=False)  # (numpy arrays: not compared)
    # A maneuver cut from one recording by its boundaries (:mod:`.split`): start and end, s
    # from the recording's start; None otherwise.
    start: float | None = None
    end: float | None = None

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
    """Rows of a maneuver that produced nothing: every parameter and method with ``status``."""
    nan = math.nan
    rows = tuple(ParameterResult(maneuver, m.output, p, nan, nan, nan, nan, 0, nan, status, method)
                 for m in config.models for p in m.parameter_names for method in config.row_methods(m, p))
    return ManeuverResult(maneuver, rows)


def _no_estimate(result: ReplayResult, model: str, method: str) -> str:
    """Why ``model`` has no ``method``-domain estimate: the run's explanation (its
    ``(frequency domain)`` line with both methods, :func:`.replay.unestimated`), else a
    general line."""
    why = {line.split(":", 1)[0]: line.split(":", 1)[1].strip() for line in result.explanations}
    own = why.get(f"{model} (frequency domain)") if method == "frequency" else None
    reason = own or why.get(model) or why.get("no estimates")
    if reason is None:
        what = "its model" if method == "time" else "its frequency-domain estimator"
        return f"no estimate: {what} never became ready"
    return reason if reason.startswith("no estimate") else f"no estimate: {reason}"


def _states(result: ReplayResult) -> dict[tuple[str, str], ParameterState]:
    return {(s.method, s.parameter): s for s in result.states}


def _frequency_row(name: str, result: ReplayResult, model: str, parameter: str, samples: int) -> ParameterResult:
    """``parameter``'s last published frequency-domain values (as ``estimates_frequency.csv``
    wrote them last)."""
    nan = math.nan
    state = _states(result).get(("frequency", parameter))
    st, why = ("", "") if state is None else (state.state, state.reason)
    try:
        final = result.final(parameter, "frequency")
    except RlsUncertaintyError:
        return ParameterResult(name, model, parameter, nan, nan, nan, nan, samples, nan,
                               _no_estimate(result, model, "frequency"), "frequency", st, why)
    return ParameterResult(name, model, parameter, final.estimate, final.std_error_conventional, final.std_error, nan,
                           samples, nan, OK, "frequency", st, why)


def _rows(name: str, result: ReplayResult, bank_all: EstimatorBank | None) -> tuple[ParameterResult, ...]:
    """The maneuver's rows: per model and parameter, its time-domain row (with ``bank_all``)
    and its frequency-domain one (when the run published them)."""
    pipe = result.pipeline
    assert pipe is not None
    # (A bank that saw no sample has no standard errors to evaluate.)
    se_all = bank_all.standard_errors_all("corrected") if bank_all is not None and bank_all.ready.any() else None
    last_row = pipe.regression[-1][0] if pipe.regression else None
    freq_samples = pipe.frequency.bank.evaluated_at if pipe.frequency is not None else 0
    states = _states(result)
    rows = []
    for j, m in enumerate(pipe.models):
        fit = pipe.model_fit(j)
        samples = int(fit.get("samples", 0))
        r2 = float(fit.get("r_squared", math.nan))
        for i, p in enumerate(pipe.parameter_names[j]):
            for method in pipe.config.row_methods(m, p):
                if method == "frequency":
                    rows.append(_frequency_row(name, result, m.output, p, freq_samples))
                    continue
                state = states.get(("time", p))
                st, why = ("", "") if state is None else (state.state, state.reason)
                try:
                    final = result.final(p)
                except RlsUncertaintyError:
                    rows.append(ParameterResult(name, m.output, p, math.nan, math.nan, math.nan, math.nan, samples,
                                                r2, _no_estimate(result, m.output, "time"), "time", st, why))
                    continue
                # All lags at the sample of the final estimates (the last row, unless the model's
                # last outputs were withheld as non-finite).
                s_all = float(se_all[j, i]) if se_all is not None and final.stamp_ns == last_row else math.nan
                rows.append(ParameterResult(name, m.output, p, final.estimate, final.std_error_conventional,
                                            final.std_error, s_all, samples, r2, OK, "time", st, why))
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
            if stream.span_seconds >= settings.min_span:  # (shorter: too_short rows, below, not a refusal)
                record_checks(config, stream.span_seconds)  # (a refusal: the maneuver's failed rows)
            timed = _TimedStream(stream)
            result = run_pipeline(timed, config, record=True, keep_outputs=False)
        t1 = time.perf_counter()
        pipe = result.pipeline
        bank_all = all_lags_bank(pipe) if config.publishes_time and pipe is not None else None
    except (RlsUncertaintyError, OSError) as exc:
        return failed_result(maneuver.name, config, f"failed: {' '.join(str(exc).split())}")
    rows = _rows(maneuver.name, result, bank_all)
    models = tuple(run_models(result.pipeline)) if result.pipeline is not None else ()
    verdict = verdict_of(result.pipeline) if result.pipeline is not None else ""
    if verdict:
        rows = tuple(replace(r, verdict=verdict) for r in rows)
    if result.data_seconds < settings.min_span:  # every row too_short: out of Table 4
        short = (f"{TOO_SHORT}: {result.data_seconds:.2f} s of data, fewer than --min-span "
                 f"{settings.min_span:g} s")
        rows = tuple(replace(r, status=short) for r in rows)
        models = ()
    t2 = time.perf_counter()
    read = opened - t0 + timed.seconds
    seconds: dict[str, Any] = {"read": read, "pipeline": t1 - t0 - read, "all_lags": t2 - t1}
    return ManeuverResult(maneuver.name, rows, result.data_seconds, seconds, models)
