"""The prediction check: a model identified on one maneuver applied to another
(``rls-uncertainty predict RUN_DIR BAG --config CFG --out DIR``).

``RUN_DIR`` is the output of a ``replay`` or a ``campaign``; its ``models.json``
(:mod:`.model_file`) holds each model's final estimates ``theta``, their corrected covariance
``P`` (Eq. 20, or Eq. 22 with the configured window) and the residual variance ``s^2 = R(0)``
(Eq. 16). ``BAG`` goes through the replay's own pipeline (:func:`.replay.run_pipeline`, the
one data path: the same sampling, differentiation and Eq. 1/2 reduction under ``CFG``), whose
regression rows ``(x_k, z_k)`` (Eq. 2: regressors and measured coefficient per sample) are the
ones its estimator would use. Per model and sample:

* the prediction ``y_k = x_k' theta`` (Eq. 2 with the identified parameters);
* its variance as a prediction of a new measurement, ``V_k = x_k' P x_k + s^2``: the
  uncertainty of the parameters (``x' P x``) and the measurement's own fit error, independent
  of it (the prediction data were not used in the fit);
* the interval ``y_k -/+ q sqrt(V_k)``, ``q`` the normal quantile of the nominal ``level``
  (1.960 at 95 %).

Per model it reports the fit error (:class:`FitError`: the RMS of ``z - y``, R^2 = 1 - SS_res
/ SS_tot about the measured mean, Theil's inequality coefficient U = RMS(z - y) / (RMS(z) +
RMS(y)), 0 for a perfect prediction, 1 for none), the coverage: the fraction of measured
coefficients inside their interval, to be read against ``level``, and the median of
``x' P x / s^2``: how much of the interval is the parameters' uncertainty (when small, the
coverage checks ``s^2`` and the model's structure more than ``P``). The coverage is a marginal,
per-sample figure: colored residuals make neighbouring samples fall out together, so its
scatter between maneuvers is wider than a binomial's.

Which model: a replay's ``RUN_DIR`` holds one maneuver. A campaign's holds one per maneuver:
``maneuver`` (``--maneuver NAME``) picks one; by default the mean over the maneuvers that
identified the model, ``theta = mean(theta_i)``, ``P = sum(P_i) / N^2`` (the covariance of
the mean of independent estimates), ``s^2 = mean(s_i^2)``.

Written to ``DIR``: ``prediction.csv`` (``time`` and per model ``M``: ``M_measured``,
``M_predicted``, ``M_lower``, ``M_upper``; one row per sample of the prediction data; cells
empty for a model not applied) and ``summary.txt`` (what the command prints).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from statistics import NormalDist
from typing import Any

import numpy as np

from ..datapath.config import PipelineConfig
from ..errors import ConfigError
from ..files import output_directory
from ..schema import check, option
from ..settings.parameters import node_config, pipeline_config
from .bags import InputStream, check_bag
from .model_file import FittedModel, read_models
from .replay import run_pipeline
from .replay_files import stamp_text

__all__ = ["PredictOptions", "FitError", "ModelPrediction", "PredictionResult", "applied_models", "prediction",
           "fit_error", "regression_rows", "predict", "prediction_csv"]


@dataclass(frozen=True)
class PredictOptions:
    """``level``: the nominal coverage of the prediction intervals; ``maneuver``: with a
    campaign's ``RUN_DIR``, the maneuver whose models are applied (empty: their mean)."""

    level: float = option(0.95, "prediction intervals: their nominal coverage", low=0.5, high=0.9999,
                          cli="--level")
    maneuver: str = option("", "with a campaign's RUN_DIR: the maneuver whose models are applied (default: the "
                           "mean over the maneuvers that identified each model)", cli="--maneuver")

    def __post_init__(self) -> None:
        check(self, "predict")

    @property
    def quantile(self) -> float:
        """The two-sided normal quantile of :attr:`level` (1.960 at 0.95)."""
        return NormalDist().inv_cdf(0.5 + 0.5 * self.level)


@dataclass(frozen=True)
class FitError:
    """A model's prediction against the measurements: ``rms`` of ``z - y``, ``r_squared``,
    ``theil_u``, ``coverage`` (fraction inside the interval), over ``samples``; ``parameter_share``
    the median over the samples of ``x' P x / s^2``, the parameters' uncertainty against the
    residual variance in the interval (NaN when not computed)."""

    rms: float
    r_squared: float
    theil_u: float
    coverage: float
    samples: int
    parameter_share: float = math.nan


@dataclass(frozen=True)
class ModelPrediction:
    """One model's prediction over the prediction data: ``measured``, ``predicted``, ``lower``,
    ``upper`` per sample, its :class:`FitError` and the model applied."""

    model: FittedModel
    measured: np.ndarray
    predicted: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    error: FitError


@dataclass(frozen=True)
class PredictionResult:
    """The prediction check: what was applied (``source``: the maneuver, or the mean over
    several), the samples' stamps and each model's :class:`ModelPrediction`."""

    source: str
    stamps_ns: np.ndarray
    models: list[ModelPrediction]
    level: float

    def summary(self) -> str:
        lines = [f"models of {self.source} applied to {self.stamps_ns.size} samples; "
                 f"prediction intervals at {100 * self.level:g} % nominal (x' P_corrected x + s^2)",
                 f"{'model':<8}{'RMS':>11}{'R^2':>8}{'Theil U':>9}{'inside':>9}{'xPx/s^2':>9}"]
        for p in self.models:
            e = p.error
            lines.append(f"{p.model.model:<8}{_cell(e.rms, 11, '.4g')}{_cell(e.r_squared, 8, '.3f')}"
                         f"{_cell(e.theil_u, 9, '.3f')}{_cell(100 * e.coverage, 8, '.1f')}%"
                         f"{_cell(e.parameter_share, 9, '.3f')}")
        return "\n".join(lines)


def _cell(value: float, width: int, spec: str) -> str:
    """``value`` right-aligned in ``width``; ``-`` for a figure that is not defined (NaN: R^2 of a
    constant measurement, the share with a zero residual variance)."""
    return f"{value:>{width}{spec}}" if math.isfinite(value) else f"{'-':>{width}}"


def _mean_model(fits: Sequence[FittedModel]) -> FittedModel:
    """The mean of one model's fits on several maneuvers (module docstring)."""
    first, n = fits[0], len(fits)
    for f in fits[1:]:
        if f.regressors != first.regressors:
            raise ConfigError(f"model {first.model} has regressors {list(first.regressors)} on one maneuver and "
                              f"{list(f.regressors)} on another; pick one with --maneuver")
    return FittedModel(first.model, first.regressors, first.parameters,
                       np.mean([f.estimate for f in fits], axis=0),
                       np.sum([f.covariance for f in fits], axis=0) / n**2,
                       np.sum([f.covariance_conventional for f in fits], axis=0) / n**2,
                       float(np.mean([f.residual_variance for f in fits])), sum(f.samples for f in fits))


def applied_models(maneuvers: Sequence[tuple[str, Sequence[FittedModel]]], maneuver: str = "") -> \
        tuple[str, list[FittedModel]]:
    """``(source, models)``: the models of ``maneuver``, of the only maneuver, or the mean over
    the maneuvers (module docstring). An unknown name, or no model at all, is a
    :class:`.errors.ConfigError`."""
    names = [name for name, _ in maneuvers]
    if maneuver:
        if maneuver not in names:
            raise ConfigError(f"--maneuver {maneuver}: not in the run; its maneuvers: {', '.join(names)}")
        chosen = [(n, m) for n, m in maneuvers if n == maneuver]
    else:
        chosen = list(maneuvers)
    with_models = [(n, list(m)) for n, m in chosen if m]
    if not with_models:
        which = f"--maneuver {maneuver}" if maneuver else "the run"
        raise ConfigError(f"{which} identified no model in models.json (no estimates: nothing to apply)")
    if len(with_models) == 1:
        return with_models[0][0], with_models[0][1]
    order = list(dict.fromkeys(f.model for _, models in with_models for f in models))
    mean = [_mean_model([f for _, models in with_models for f in models if f.model == name]) for name in order]
    return f"the mean over {len(with_models)} maneuvers", mean


def prediction(model: FittedModel, X: np.ndarray, quantile: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(y, lower, upper)`` of ``model`` on the regressor rows ``X`` ``(K, n)``: ``y = X theta``
    and ``y -/+ quantile sqrt(x' P x + s^2)`` (module docstring); a value that is not finite (a
    model whose numbers overflow) is a :class:`.errors.ConfigError`."""
    with np.errstate(over="ignore", invalid="ignore"):  # a model too large for floats: refused below
        y = X @ model.estimate
        variance = np.einsum("ki,ij,kj->k", X, model.covariance, X) + model.residual_variance
        half = quantile * np.sqrt(np.maximum(variance, 0.0))
        lower, upper = y - half, y + half
    if not (np.isfinite(y).all() and np.isfinite(lower).all() and np.isfinite(upper).all()):
        raise ConfigError(f"model {model.model}: its prediction or interval is not a finite number (estimates or "
                          "covariance too large for the regressors)")
    return y, lower, upper


def fit_error(z: np.ndarray, y: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> FitError:
    """:class:`FitError` of the measured ``z`` against the prediction ``y`` and its interval."""
    with np.errstate(over="ignore", invalid="ignore"):  # (a prediction whose square overflows: rms inf)
        e = z - y
        rms = float(np.sqrt(np.mean(e**2)))
        total = float(np.sum((z - z.mean()) ** 2))
        r2 = 1.0 - float(np.sum(e**2)) / total if total > 0 else math.nan
        scale = float(np.sqrt(np.mean(z**2)) + np.sqrt(np.mean(y**2)))
        u = rms / scale if 0 < scale < math.inf else math.nan
    inside = float(np.mean((z >= lower) & (z <= upper)))
    return FitError(rms, r2, u, inside, int(z.size))


def regression_rows(bag: str | Path, config: PipelineConfig, topics: Mapping[str, str], *, strict: bool = True,
                    progress: bool | None = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The regression rows the replay's pipeline forms from ``bag`` under ``config``:
    ``(stamps_ns (K,), X (K, M, n_max), z (K, M))``, models in the order of ``config.models``
    (the rows since the pipeline's last restart: those its estimator saw)."""
    with InputStream(bag, topics, strict=strict) as stream:
        result = run_pipeline(stream, config, record=True, keep_outputs=False, progress=progress)
    pipe = result.pipeline
    assert pipe is not None  # run_pipeline keeps its pipeline
    rows = pipe.regression
    if not rows:
        why = "; ".join(result.explanations) or "no sample reached the estimator"
        raise ConfigError(f"{bag}: no regression rows to predict ({why})")
    stamps = np.array([t for t, _, _ in rows], dtype=np.int64)
    return stamps, np.stack([X for _, X, _ in rows]), np.stack([z for _, _, z in rows])


def _columns(config: PipelineConfig, models: Sequence[FittedModel]) -> list[tuple[FittedModel, int]]:
    """Each model with its index in ``config``; a model not in the configuration, or with
    other regressors, is a :class:`.errors.ConfigError`."""
    where = {m.output: j for j, m in enumerate(config.models)}
    out = []
    for f in models:
        if f.model not in where:
            raise ConfigError(f"model {f.model} of the run is not in --config's models "
                              f"({', '.join(where) or 'none'}): enable it (models.enabled) to predict it")
        j = where[f.model]
        if tuple(config.models[j].regressors) != f.regressors:
            raise ConfigError(f"model {f.model}: the run's regressors {list(f.regressors)} are not --config's "
                              f"{list(config.models[j].regressors)}")
        out.append((f, j))
    return out


def prediction_csv(result: PredictionResult) -> str:
    """``prediction.csv``'s text (module docstring)."""
    header = ["time"] + [f"{p.model.model}_{q}" for p in result.models
                         for q in ("measured", "predicted", "lower", "upper")]
    columns = [np.column_stack([p.measured, p.predicted, p.lower, p.upper]) for p in result.models]
    table = np.hstack(columns).tolist() if columns else [[] for _ in result.stamps_ns]
    lines = [",".join(header)]
    for stamp, row in zip(result.stamps_ns.tolist(), table, strict=True):
        lines.append(",".join([stamp_text(stamp), *map(repr, row)]))
    return "\n".join(lines) + "\n"


def predict(run_dir: str | Path, bag: str | Path, params: dict[str, Any], out: str | Path,
            options: PredictOptions = PredictOptions(), *, strict: bool = True, progress: bool | None = False,
            force: bool = False, inputs: Sequence[str | Path] = ()) -> PredictionResult:
    """The prediction check (module docstring) of ``run_dir``'s models on ``bag`` under the
    parameters ``params``, written to ``out`` (:func:`.files.output_directory`: complete or
    absent, an existing non-empty ``out`` only with ``force``, never over an input)."""
    source, models = applied_models(read_models(run_dir), options.maneuver)
    config = pipeline_config(params)
    columns = _columns(config, models)
    check_bag(bag)
    with output_directory(out, force=force, inputs=(bag, run_dir, *inputs)) as tmp:
        stamps, X, z = regression_rows(bag, config, node_config(params).topics, strict=strict, progress=progress)
        predicted = []
        for f, j in columns:
            Xj, zj = X[:, j, : len(f.regressors)], z[:, j]
            y, lo, hi = prediction(f, Xj, options.quantile)
            error = fit_error(zj, y, lo, hi)
            if not math.isfinite(error.rms):
                raise ConfigError(f"model {f.model}: its prediction error is not a finite number (estimates too "
                                  "large for the regressors)")
            if f.residual_variance > 0:
                share = float(np.median(np.einsum("ki,ij,kj->k", Xj, f.covariance, Xj))) / f.residual_variance
                error = replace(error, parameter_share=share)
            predicted.append(ModelPrediction(f, zj, y, lo, hi, error))
        result = PredictionResult(source, stamps, predicted, options.level)
        (tmp / "prediction.csv").write_text(prediction_csv(result))
        (tmp / "summary.txt").write_text(result.summary() + "\n")
    return result
