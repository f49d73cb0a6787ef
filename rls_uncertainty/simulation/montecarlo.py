"""Table 3 Monte Carlo of the paper (Section IV.A), and Figs. 5-7.

For each band-limited noise level, ``runs`` noisy realisations of the T-2 maneuver go through
the same aero reduction and differentiator the node uses, and, in batches of
:data:`BATCH_RUNS` runs (one job of an :mod:`..executors` executor each), through one
:class:`~rls_uncertainty.estimator.EstimatorBank` holding the batch's C_Z and C_m models (so
its runs advance together, sample by sample) and, with the method ``"frequency"`` or
``"both"`` (:data:`..datapath.config.METHODS`), one
:class:`~rls_uncertainty.frequency.FrequencyBank` on the same rows without the bias, as the
node's frequency path takes them. The batches are joined in run order before the statistics
over runs are formed, so the numbers do not depend on who ran the batches. End-of-maneuver
estimates, conventional and corrected standard errors (means over runs) and the observed
scatter (standard deviation of the final estimates) are compared with the paper's Table 3.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable, Collection, Sequence
from dataclasses import KW_ONLY, dataclass, field, replace
from pathlib import Path

import numpy as np

from ..aero.differentiation import DifferentiatorConfig
from ..aero.models import BIAS_REGRESSOR, REGRESSOR_UNITS
from ..datapath.config import METHODS
from ..datapath.convergence import ConvergenceConfig, ConvergenceMonitor
from ..datapath.guard import withheld as unpublishable
from ..datapath.identifiability import IdentifiabilityConfig, IdentifiabilityMonitor
from ..errors import ConfigError, WorkerLost
from ..estimator import EstimatorBank, EstimatorOptions, Lags, batch_estimate
from ..executors import Executor, LocalProcesses, Lost
from ..frequency import FrequencyBank, FrequencyOptions
from .t2 import (
    BAND_LIMITED_ON,
    SIGNALS,
    T2_MODELS,
    T2_TRUE,
    SimulationConfig,
    add_noise,
    reduce_short_period,
    simulate_short_period,
)

__all__ = [
    "LEVELS",
    "PAPER_TABLE3",
    "PAPER_DIFFERENTIATOR",
    "MONTE_CARLO_CONVERGENCE",
    "BEST_FROM",
    "TABLE3_OPTIONS",
    "BATCH_RUNS",
    "LevelResult",
    "t2_frequency_options",
    "level_inputs",
    "run_level",
    "run_table3",
    "convergence_summary",
    "write_outputs",
]

# The paper does not give its real-time differentiator, only that it amplifies the C_m residual
# near 10 Hz (Section IV.A). A 5-point cubic fit with a 2-sample lag does that and reproduces
# Table 3's conventional C_m standard errors at every noise level (0%: 0.019 / 1.40 / 0.026
# against the paper's 0.021 / 1.58 / 0.029), where the node's smoother default (9 points,
# lag 4) gives less than half of them. Same differentiator code, another window.
PAPER_DIFFERENTIATOR = DifferentiatorConfig(window=5, order=3, lag=2)

LEVELS = (0.0, 0.05, 0.10, 0.15, 0.20)
PARAMETERS = ("CZ_alpha", "CZ_delta_e", "Cm_alpha", "Cm_q", "Cm_delta_e")
# Table 3: level -> parameter -> (mean, conventional SE, corrected SE, scatter)
PAPER_TABLE3 = {
    0.00: {"CZ_alpha": (-3.888, 0.013, 0.015, 0.012), "CZ_delta_e": (0.225, 0.011, 0.013, 0.012),
           "Cm_alpha": (-1.521, 0.021, 0.014, 0.007), "Cm_q": (-54.73, 1.581, 1.149, 0.598),
           "Cm_delta_e": (-1.912, 0.029, 0.021, 0.011)},
    0.05: {"CZ_alpha": (-3.870, 0.019, 0.049, 0.049), "CZ_delta_e": (0.227, 0.017, 0.042, 0.039),
           "Cm_alpha": (-1.515, 0.023, 0.027, 0.026), "Cm_q": (-54.28, 1.670, 2.230, 2.009),
           "Cm_delta_e": (-1.905, 0.030, 0.041, 0.038)},
    0.10: {"CZ_alpha": (-3.841, 0.029, 0.088, 0.085), "CZ_delta_e": (0.232, 0.025, 0.075, 0.075),
           "Cm_alpha": (-1.507, 0.025, 0.044, 0.041), "Cm_q": (-53.15, 1.863, 3.674, 3.447),
           "Cm_delta_e": (-1.885, 0.034, 0.067, 0.068)},
    0.15: {"CZ_alpha": (-3.774, 0.038, 0.123, 0.129), "CZ_delta_e": (0.243, 0.034, 0.106, 0.108),
           "Cm_alpha": (-1.486, 0.029, 0.060, 0.063), "Cm_q": (-51.94, 2.095, 5.052, 4.806),
           "Cm_delta_e": (-1.864, 0.039, 0.092, 0.090)},
    0.20: {"CZ_alpha": (-3.710, 0.048, 0.158, 0.146), "CZ_delta_e": (0.260, 0.043, 0.138, 0.138),
           "Cm_alpha": (-1.468, 0.033, 0.079, 0.074), "Cm_q": (-49.90, 2.349, 6.485, 6.478),
           "Cm_delta_e": (-1.834, 0.044, 0.119, 0.122)},
}
# (model index in T2_MODELS, column) of each Table 3 parameter
_WHERE = {
    "CZ_alpha": (0, 1), "CZ_delta_e": (0, 2), "Cm_alpha": (1, 1), "Cm_q": (1, 2), "Cm_delta_e": (1, 3),
}
LAG_SWEEP = (0, 1, 2, 3, 5, 8, 11, 15, 20, 30, 50, 75, 100, 150, 200, 300, 400, 591)
# The node's convergence criterion with its buffer sized for the simulation's 50 Hz.
MONTE_CARLO_CONVERGENCE = replace(ConvergenceConfig(), rate_hz=SimulationConfig().rate)
BEST_FROM = SimulationConfig().input_start + 0.5  # s: from here on, the floor of false convergence
# The node's identifiability tests of the flags (its defaults).
NODE_IDENTIFIABILITY = IdentifiabilityConfig()
# The estimator of Table 3: 50 lags, the paper's Eq. 17 (no residual burn-in).
TABLE3_OPTIONS = EstimatorOptions(lags=50)
# Runs per job of run_table3: a level's runs are cut into batches of this many (the last one
# shorter), whatever runs them, so the numbers do not depend on the workers.
BATCH_RUNS = 25


@dataclass
class LevelResult:
    level: float
    runs: int
    estimates: np.ndarray  # (runs, 5) final estimates, PARAMETERS order
    se_conventional: np.ndarray  # (runs, 5)
    se_corrected: np.ndarray  # (runs, 5), the options' lags
    se_corrected_all: np.ndarray  # (runs, 5), all lags
    se_batch: np.ndarray  # (runs, 5), batch formula (Eqs. 8-11), the same lags, batch residuals
    se_batch_all: np.ndarray  # (runs, 5), batch formula, all lags, batch residuals
    time: np.ndarray  # sample times
    history_mean: np.ndarray  # (N, 3): mean CZ_alpha, mean conventional SE, mean corrected SE
    history_scatter: np.ndarray  # (N,): scatter of CZ_alpha over runs
    last_run: dict  # residual autocorrelations and lag sweep of the last run (Figs. 5, 7)
    # Convergence flags, PARAMETERS order; times in s, inf where never flagged.
    # Keyword-only (KW_ONLY): the arrays after the configuration's default need no placeholder default.
    _: KW_ONLY
    convergence: ConvergenceConfig = field(default_factory=ConvergenceConfig)
    identifiability: IdentifiabilityConfig = field(default_factory=IdentifiabilityConfig)
    flag_time: np.ndarray  # (runs, 5) first time each parameter is flagged
    untested_flag_time: np.ndarray  # (runs, 5) the same without the identifiability tests
    untested_model_flag_time: np.ndarray  # (runs, 2)
    flag_theta: np.ndarray  # (runs, 5) estimate at that time (NaN if never)
    flag_se: np.ndarray  # (runs, 5) corrected SE at that time
    model_flag_time: np.ndarray  # (runs, 2) first time C_Z / C_m has every parameter flagged
    model_flag_theta: np.ndarray  # (runs, 5) estimates at their model's flag time
    model_flag_se: np.ndarray  # (runs, 5)
    ensemble_mean: np.ndarray  # (N, 5) mean estimate over runs, each sample
    ensemble_se: np.ndarray  # (N, 5) mean corrected SE over runs
    ensemble_scatter: np.ndarray  # (N, 5) standard deviation of the estimates over runs
    truth_outside: np.ndarray  # (N, 7) fraction of runs with the true value outside +-2 SE
    # (5 parameters, then any parameter of the C_Z / C_m model), each sample
    lags_used: np.ndarray | None = None  # (runs, 2) final L of C_Z / C_m (chosen with lags="auto")
    converged_end: np.ndarray | None = None  # (runs, 5) flagged converged at the last sample (identifiability tests on)
    identifiable_end: np.ndarray | None = None  # (runs, 5) identifiable at the last sample
    options: EstimatorOptions = TABLE3_OPTIONS  # of se_corrected and se_conventional (time domain)
    band_limited_on: tuple[str, ...] = BAND_LIMITED_ON  # the measured signals with band-limited noise (add_noise)
    # "time" (recursive least squares) or "frequency" (docs/frequency.md, with the options
    # ``frequency``): the method of the estimates, SEs and flags. A frequency-domain result has
    # no all-lags or batch SEs (NaN), no lags_used and no last_run.
    method: str = "time"
    frequency: FrequencyOptions | None = None

    @property
    def lags(self) -> Lags:
        """The retained lags of ``se_corrected``: an integer, "all" or "auto"."""
        return self.frequency.n_lags if self.frequency is not None else self.options.lags

    @property
    def residual_burn_in(self) -> int:
        """The residual burn-in of ``se_corrected`` and ``se_conventional`` (50 with "auto" by
        default; none in the frequency domain)."""
        return 0 if self.frequency is not None else self.options.burn_in

    def summary(self) -> dict[str, dict[str, float]]:
        out = {}
        for i, name in enumerate(PARAMETERS):
            out[name] = {
                "true": T2_TRUE[name],
                "mean": float(self.estimates[:, i].mean()),
                "se_conventional": float(self.se_conventional[:, i].mean()),
                "se_corrected": float(self.se_corrected[:, i].mean()),
                "se_corrected_all": float(self.se_corrected_all[:, i].mean()),
                "se_batch": float(self.se_batch[:, i].mean()),
                "se_batch_all": float(self.se_batch_all[:, i].mean()),
                "scatter": float(self.estimates[:, i].std(ddof=1)),
                "converged_end": math.nan if self.converged_end is None else float(self.converged_end[:, i].mean()),
                "identifiable_end": math.nan if self.identifiable_end is None
                else float(self.identifiable_end[:, i].mean()),
                "se_percent": float(np.mean(100.0 * self.se_corrected[:, i] / np.abs(self.estimates[:, i]))),
            }
        return out


def _pick(per_model: list[np.ndarray]) -> np.ndarray:
    return np.array([per_model[m][c] for m, c in (_WHERE[p] for p in PARAMETERS)])


def parameter_cells(runs: int) -> tuple[np.ndarray, np.ndarray]:
    """Where the Table 3 parameters of every run sit in a bank of ``runs`` x :data:`T2_MODELS`
    models: ``rows`` and ``cols``, both ``(runs, len(PARAMETERS))``; run ``r``'s parameter
    ``PARAMETERS[i]`` is ``bank.theta_all()[rows[r, i], cols[r, i]]``."""
    rows = np.arange(runs)[:, None] * len(T2_MODELS) + np.array([_WHERE[p][0] for p in PARAMETERS])
    cols = np.broadcast_to(np.array([_WHERE[p][1] for p in PARAMETERS]), rows.shape)
    return rows, cols


def level_inputs(
    level: float, runs: int, *, seed: int = 2016, band_limited_on: Collection[str] = BAND_LIMITED_ON, first: int = 0
) -> tuple[np.ndarray, list[dict[str, tuple[np.ndarray, np.ndarray]]], list[int], np.ndarray, np.ndarray]:
    """Regressors and outputs of every run of one noise level, as the bank takes them, with
    the band-limited noise on the signals ``band_limited_on`` (:func:`.simulation.add_noise`):
    runs ``first`` to ``first + runs - 1`` of the level (each run's noise is drawn from its own
    seed ``[seed, level in thousandths, run]``, whichever runs are drawn with it).

    Returns ``(t, reductions, sizes, X, Z)``: sample times (N,), each run's reduced data
    (``{"CZ": (X, z), "Cm": (X, z)}``), the model sizes (run ``r``'s C_Z model is bank row
    ``2 r``, its C_m model row ``2 r + 1``), regressors (N, 2 runs, n_max) and outputs (N, 2 runs).
    """
    clean = simulate_short_period()
    reductions = []
    for run in range(first, first + runs):
        rng = np.random.default_rng([seed, int(round(level * 1000)), run])
        t, data = reduce_short_period(add_noise(clean, level, rng, band_limited_on=band_limited_on),
                                      PAPER_DIFFERENTIATOR)
        reductions.append(data)
    sizes = [len(m.regressors) for m in T2_MODELS] * runs
    n_models = len(T2_MODELS)
    N = t.size
    n_max = max(sizes)
    X = np.zeros((N, n_models * runs, n_max))
    Z = np.zeros((N, n_models * runs))
    for r, data in enumerate(reductions):
        for m, model in enumerate(T2_MODELS):
            Xm, zm = data[model.output]
            X[:, r * n_models + m, : Xm.shape[1]] = Xm
            Z[:, r * n_models + m] = zm
    return t, reductions, sizes, X, Z


class _Tracker:
    """What one method records of every run of a batch at every sample, besides the
    end-of-maneuver results: the Table 3 parameters' estimates, corrected SEs, which runs have
    every model ready, C_Z_alpha's conventional SE (Fig. 6), and from one
    :class:`~rls_uncertainty.datapath.convergence.ConvergenceMonitor` over the batch's models,
    less what the node's identifiability tests take out
    (:class:`~rls_uncertainty.datapath.identifiability.IdentifiabilityMonitor`, judged on the
    time-domain fit, as the node judges both methods), the first flag of each parameter and
    model (estimate and corrected SE at that moment; and the first flag without the tests).
    ``cols``: the column of each Table 3 parameter in its model's row of this method's bank.
    The statistics over runs are formed once every batch is in (:func:`_ensemble`)."""

    def __init__(self, t: np.ndarray, runs: int, sizes: list[int], cols: np.ndarray,
                 convergence: ConvergenceConfig) -> None:
        n_models, N, P = len(T2_MODELS), t.size, len(PARAMETERS)
        self.t, self.runs = t, runs
        self.monitor = ConvergenceMonitor(sizes, convergence)
        self.untested_k = np.full((runs, P), -1)
        self.untested_model_k = np.full((runs, n_models), -1)
        self.stamps = np.round(t * 1e9).astype(np.int64)
        self.cz = np.arange(runs) * n_models  # CZ model of each run
        self.model_of = np.array([_WHERE[p][0] for p in PARAMETERS])
        self.p_row = parameter_cells(runs)[0]  # (runs, 5) bank row of each parameter
        self.p_col = np.broadcast_to(cols, self.p_row.shape)
        self.theta, self.se = np.full((N, runs, P), np.nan), np.full((N, runs, P), np.nan)
        self.conventional0 = np.full((N, runs), np.nan)  # conventional SE of C_Z_alpha
        self.ready = np.zeros((N, runs), dtype=bool)  # every model of the run ready
        self.cz_ready = np.zeros((N, runs), dtype=bool)
        self.flag_k = np.full((runs, P), -1)
        self.flag_theta, self.flag_se = np.full((runs, P), np.nan), np.full((runs, P), np.nan)
        self.model_k = np.full((runs, n_models), -1)
        self.model_theta, self.model_se = np.full((runs, P), np.nan), np.full((runs, P), np.nan)
        self.final_flags = np.zeros((runs, P), dtype=bool)
        self.identifiable = np.zeros((runs, P), dtype=bool)

    def sample(self, k: int, theta_k: np.ndarray, se_k: np.ndarray, conventional_k: np.ndarray,
               ready_k: np.ndarray, restrict: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
               identifiable: Callable[[], np.ndarray]) -> None:
        """Sample ``k`` of the bank's outputs; ``restrict``: the identifiability tests on its flags,
        ``identifiable``: the parameters they pass (both in this method's layout)."""
        runs, n_models = self.runs, len(T2_MODELS)
        self.cz_ready[k] = ready_k[self.cz]
        self.ready[k] = ready_k.reshape(runs, n_models).all(axis=1)
        self.conventional0[k] = conventional_k[self.cz, self.p_col[0, 0]]
        flags, model_flags = self.monitor.update(int(self.stamps[k]), theta_k, se_k, ready_k)
        untested = flags[self.p_row, self.p_col] & (self.untested_k < 0)
        self.untested_k[untested] = k
        self.untested_model_k[model_flags.reshape(runs, n_models) & (self.untested_model_k < 0)] = k
        # The node's tests: a parameter not identifiable is never flagged.
        flags, model_flags = restrict(flags, model_flags)
        self.final_flags = flags[self.p_row, self.p_col]
        th_p, se_p = theta_k[self.p_row, self.p_col], se_k[self.p_row, self.p_col]
        self.theta[k], self.se[k] = th_p, se_p
        new = flags[self.p_row, self.p_col] & (self.flag_k < 0)
        self.flag_k[new], self.flag_theta[new], self.flag_se[new] = k, th_p[new], se_p[new]
        new_model = model_flags.reshape(runs, n_models) & (self.model_k < 0)
        self.model_k[new_model] = k
        new = new_model[:, self.model_of]
        self.model_theta[new], self.model_se[new] = th_p[new], se_p[new]
        if k == self.t.size - 1:
            self.identifiable = identifiable()[self.p_row, self.p_col]

    def results(self) -> dict:
        """This batch's per-run records (:func:`_merge` joins the batches)."""
        t = self.t
        return dict(
            theta=self.theta, se=self.se, conventional0=self.conventional0, ready=self.ready, cz_ready=self.cz_ready,
            flag_time=np.where(self.flag_k >= 0, t[self.flag_k], np.inf),
            untested_flag_time=np.where(self.untested_k >= 0, t[self.untested_k], np.inf),
            untested_model_flag_time=np.where(self.untested_model_k >= 0, t[self.untested_model_k], np.inf),
            flag_theta=self.flag_theta, flag_se=self.flag_se,
            model_flag_time=np.where(self.model_k >= 0, t[self.model_k], np.inf),
            model_flag_theta=self.model_theta, model_flag_se=self.model_se,
            converged_end=self.final_flags, identifiable_end=self.identifiable,
        )


def _ensemble(t: np.ndarray, rec: dict) -> dict:
    """The :class:`LevelResult` fields over all runs of a level, each sample: the Fig. 6 history
    of C_Z_alpha (where every run's C_Z model is ready), and the ensemble mean, mean corrected
    SE, scatter and truth-outside rates of every Table 3 parameter (where every run's models
    are all ready)."""
    theta, se, runs, N, P = rec["theta"], rec["se"], rec["theta"].shape[1], t.size, len(PARAMETERS)
    model_of = np.array([_WHERE[p][0] for p in PARAMETERS])
    truth = np.array([T2_TRUE[p] for p in PARAMETERS])
    history, scatter = np.full((N, 3), np.nan), np.full(N, np.nan)
    ens = np.full((3, N, P), np.nan)  # mean estimate, mean SE, scatter
    outside = np.full((N, P + len(T2_MODELS)), np.nan)
    for k in range(N):
        if rec["cz_ready"][k].all():
            th = theta[k, :, 0].copy()
            history[k] = (th.mean(), rec["conventional0"][k].mean(), se[k, :, 0].copy().mean())
            scatter[k] = th.std(ddof=1) if runs > 1 else 0.0
        if rec["ready"][k].all():
            th_p, se_p = theta[k], se[k]
            ens[0, k], ens[1, k] = th_p.mean(axis=0), se_p.mean(axis=0)
            ens[2, k] = th_p.std(axis=0, ddof=1) if runs > 1 else 0.0
            out = np.abs(th_p - truth) > 2 * se_p
            outside[k, :P] = out.mean(axis=0)
            outside[k, P:] = [out[:, model_of == m].any(axis=1).mean() for m in range(len(T2_MODELS))]
    return dict(history_mean=history, history_scatter=scatter, ensemble_mean=ens[0], ensemble_se=ens[1],
                ensemble_scatter=ens[2], truth_outside=outside)


def _collect(bank: EstimatorBank | FrequencyBank, runs: int, kind: str | None, cols: np.ndarray) -> np.ndarray:
    """``(runs, 5)`` final estimates (``kind`` None) or standard errors of the Table 3 parameters
    (``cols``: their columns in the bank's rows)."""
    n_models = len(T2_MODELS)
    rows = []
    for r in range(runs):
        per = [bank.theta(r * n_models + m) if kind is None else bank.standard_errors(r * n_models + m, kind)
               for m in range(n_models)]
        rows.append(np.array([per[_WHERE[p][0]][c] for p, c in zip(PARAMETERS, cols, strict=True)]))
    return np.array(rows)


def _batch_standard_errors(
    reductions: list[dict[str, tuple[np.ndarray, np.ndarray]]], lags_used: np.ndarray, lags: Lags
) -> tuple[np.ndarray, np.ndarray]:
    """``(runs, 5)`` batch standard errors (Eqs. 8-11, batch residuals) with ``lags`` (each
    model's final choice with ``"auto"``) and with all lags."""
    batch: dict[Lags, list[np.ndarray]] = {lags: [], "all": []}
    for r, data in enumerate(reductions):
        for key, rows in batch.items():
            per = [
                np.sqrt(np.diag(batch_estimate(*data[m.output], lags_used[r, i] if key == "auto" else key)[2]))
                for i, m in enumerate(T2_MODELS)
            ]
            rows.append(_pick(per))
    return np.array(batch[lags]), np.array(batch["all"])


def _last_run(bank_all: EstimatorBank, reductions: list[dict[str, tuple[np.ndarray, np.ndarray]]]) -> dict:
    """Figs. 5 and 7 for the last run: recursive (all lags) against batch autocorrelation of
    the C_Z residual, and corrected SE of C_Z_alpha against the number of retained lags."""
    j = (len(reductions) - 1) * len(T2_MODELS)
    Xcz, zcz = reductions[-1]["CZ"]
    N = zcz.size
    residuals = bank_all.residuals(j)
    v_batch = zcz - Xcz @ np.linalg.lstsq(Xcz, zcz, rcond=None)[0]
    R_batch = np.array([v_batch[i:] @ v_batch[: N - i] for i in range(N)]) / N
    sweep = [(L, float(np.sqrt(batch_estimate(Xcz, zcz, L, residuals=residuals)[2][1, 1])))
             for L in LAG_SWEEP if L < N]
    return {"R_recursive": bank_all.autocorrelation(j), "R_batch": R_batch, "lag_sweep": sweep, "N": N}


@dataclass(frozen=True)
class _Job:
    """One batch of runs of one level: runs ``first`` to ``first + runs - 1`` of ``total``."""

    level: float
    first: int
    runs: int
    total: int
    methods: tuple[str, ...]
    options: EstimatorOptions
    frequency: FrequencyOptions | None
    seed: int
    convergence: ConvergenceConfig
    identifiability: IdentifiabilityConfig
    band_limited_on: tuple[str, ...]


def _frequency_layout(sizes: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where the frequency-domain regressors (Eq. 2 without the bias, as the node's
    :class:`~rls_uncertainty.datapath.frequency_path.FrequencyPath` takes them) sit in the
    time-domain rows ``(M, n_max)``, flattened (``take``), and in the frequency-domain rows
    ``(M, q)`` (``put``); ``real``: ``(M, q)`` not padding; ``cols``: each Table 3 parameter's
    frequency-domain column."""
    n_max, q = max(sizes), max(sizes) - 1
    rows = [m.regressors for m in T2_MODELS] * (len(sizes) // len(T2_MODELS))
    take = np.array([j * n_max + i for j, row in enumerate(rows) for i, r in enumerate(row) if r != BIAS_REGRESSOR])
    f_sizes = [sum(r != BIAS_REGRESSOR for r in row) for row in rows]
    put = np.array([j * q + k for j, size in enumerate(f_sizes) for k in range(size)])
    real = np.arange(q) < np.array(f_sizes)[:, None]
    cols = np.array([sum(r != BIAS_REGRESSOR for r in T2_MODELS[m].regressors[:c]) for m, c in
                     (_WHERE[p] for p in PARAMETERS)])
    return take, put, real, cols


def _run_batch(job: _Job) -> dict[str, dict]:
    """Every method of ``job.methods`` on one batch of runs, sample by sample (a picklable
    top-level function: the executors' job). The time-domain bank always runs: the
    identifiability tests of both methods judge its fit, as in the node."""
    t, reductions, sizes, X, Z = level_inputs(job.level, job.runs, seed=job.seed, first=job.first,
                                              band_limited_on=job.band_limited_on)
    n_models = len(T2_MODELS)
    time_cols = np.array([_WHERE[p][1] for p in PARAMETERS])
    bank = EstimatorBank(sizes, job.options)
    bank_all = EstimatorBank(sizes, EstimatorOptions(lags="all")) if "time" in job.methods else None
    rows = [m.regressors for m in T2_MODELS] * job.runs
    quality = IdentifiabilityMonitor(rows, [[REGRESSOR_UNITS[r] for r in row] for row in rows], job.identifiability)
    tracks = {"time": _Tracker(t, job.runs, sizes, time_cols, job.convergence)}
    if "frequency" in job.methods:
        assert job.frequency is not None
        take, put, real, f_cols = _frequency_layout(sizes)
        f_bank = FrequencyBank(real.sum(axis=1).tolist(), job.frequency)
        tracks["frequency"] = _Tracker(t, job.runs, real.sum(axis=1).tolist(), f_cols, job.convergence)
        Xf = np.zeros((len(sizes), real.shape[1]))

        def f_identifiable() -> np.ndarray:
            ok = np.zeros(real.shape, dtype=bool)
            ok.flat[put] = quality.identifiable.flat[take]
            return ok

        def f_restrict(flags: np.ndarray, model_flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            ok = f_identifiable()
            return flags & ok, model_flags & (ok | ~real).all(axis=1)

    for k in range(t.size):
        bank.update(X[k], Z[k])
        if bank_all is not None:
            bank_all.update(X[k], Z[k])
        quality.add(X[k], Z[k])
        ready = bank.ready

        def restrict(flags: np.ndarray, model_flags: np.ndarray, ready: np.ndarray = ready) -> tuple[np.ndarray,
                                                                                                    np.ndarray]:
            return quality.restrict(flags, model_flags, bank, ready)

        tracks["time"].sample(k, bank.theta_all(), bank.standard_errors_all("corrected"),
                              bank.standard_errors_all("conventional"), ready, restrict, lambda: quality.identifiable)
        if "frequency" in tracks:
            Xf.flat[put] = X[k].flat[take]
            f_bank.update(Xf, Z[k])
            theta, se = f_bank.theta_all(), f_bank.standard_errors_all("corrected")
            se_conv = f_bank.standard_errors_all("conventional")
            # The node's guard: a model with a value not finite, zero or rounding-level is not ready.
            f_ready = f_bank.ready & ~(unpublishable(f_bank.ready, real, theta, se, se_conv) | f_bank.withheld)
            tracks["frequency"].sample(k, theta, se, se_conv, f_ready, f_restrict, f_identifiable)
    out: dict[str, dict] = {}
    if "time" in job.methods:
        assert bank_all is not None
        lags_used = bank.lags_used.reshape(job.runs, n_models)
        se_batch, se_batch_all = _batch_standard_errors(reductions, lags_used, job.options.lags)
        out["time"] = dict(
            tracks["time"].results(), lags_used=lags_used, se_batch=se_batch, se_batch_all=se_batch_all,
            estimates=_collect(bank, job.runs, None, time_cols),
            se_conventional=_collect(bank, job.runs, "conventional", time_cols),
            se_corrected=_collect(bank, job.runs, "corrected", time_cols),
            se_corrected_all=_collect(bank_all, job.runs, "corrected", time_cols),
            last_run=_last_run(bank_all, reductions) if job.first + job.runs == job.total else None)
    if "frequency" in job.methods:
        nan = np.full((job.runs, len(PARAMETERS)), np.nan)
        out["frequency"] = dict(
            tracks["frequency"].results(), lags_used=None, se_batch=nan, se_batch_all=nan, se_corrected_all=nan,
            estimates=_collect(f_bank, job.runs, None, f_cols),
            se_conventional=_collect(f_bank, job.runs, "conventional", f_cols),
            se_corrected=_collect(f_bank, job.runs, "corrected", f_cols), last_run=None)
    out["t"] = {"t": t}
    return out


_PER_RUN = ("estimates", "se_conventional", "se_corrected", "se_corrected_all", "se_batch", "se_batch_all",
            "flag_time", "untested_flag_time", "untested_model_flag_time", "flag_theta", "flag_se", "model_flag_time",
            "model_flag_theta", "model_flag_se", "converged_end", "identifiable_end", "lags_used")
_PER_SAMPLE = ("theta", "se", "conventional0", "ready", "cz_ready")


def _merge(job: _Job, batches: list[dict[str, dict]]) -> list[LevelResult]:
    """One :class:`LevelResult` per method of the level of ``job`` from its batches, in the
    order of their runs."""
    t = batches[0]["t"]["t"]
    results = []
    for method in job.methods:
        parts = [b[method] for b in batches]
        rec: dict = {k: None if parts[0][k] is None else np.concatenate([p[k] for p in parts]) for k in _PER_RUN}
        rec.update({k: np.concatenate([p[k] for p in parts], axis=1) for k in _PER_SAMPLE})
        last = parts[-1]["last_run"]
        results.append(LevelResult(
            level=job.level, runs=job.total, time=t, last_run=last or {},
            convergence=job.convergence, identifiability=job.identifiability, options=job.options,
            band_limited_on=tuple(s for s in SIGNALS if s in set(job.band_limited_on)), method=method,
            frequency=job.frequency if method == "frequency" else None,
            **{k: rec[k] for k in _PER_RUN}, **_ensemble(t, rec),
        ))
    return results


def _jobs(levels: Sequence[float], runs: int, batch_runs: int, **common: object) -> list[_Job]:
    return [_Job(level=lv, first=first, runs=min(batch_runs, runs - first), total=runs, **common)  # type: ignore[arg-type]
            for lv in levels for first in range(0, runs, batch_runs)]


def _methods(method: str, frequency: FrequencyOptions | None) -> tuple[tuple[str, ...], FrequencyOptions | None]:
    """The methods :data:`.datapath.config.METHODS` ``method`` runs, and the frequency-domain
    options they use (default: :func:`t2_frequency_options`)."""
    if method not in METHODS:
        raise ConfigError(f"method must be one of {', '.join(METHODS)}, got {method!r} (--method)")
    methods = ("time", "frequency") if method == "both" else (method,)
    if "frequency" in methods and frequency is None:
        frequency = t2_frequency_options()
    return methods, frequency if "frequency" in methods else None


def t2_frequency_options(publish_lag_windows: float | None = None) -> FrequencyOptions:
    """The frequency-domain options the node takes from ``config/t2.yaml`` with ``estimator.method:
    both`` (the T-2 grid 0.2-2.2 Hz every 0.04 Hz, the half second before the input as trim, 50
    lags; docs/frequency.md), with the publication rule ``publish_lag_windows`` (default: the
    node's)."""
    from ..settings import load_parameters_file, pipeline_config  # noqa: PLC0415 - the parameter file, on demand

    params = {**load_parameters_file("t2"), "estimator.method": "both"}
    if publish_lag_windows is not None:
        params["estimator.publish_lag_windows"] = publish_lag_windows
    options = pipeline_config(params).frequency
    assert options is not None  # method both
    return options


def run_level(
    level: float,
    runs: int,
    *,
    options: EstimatorOptions = TABLE3_OPTIONS,
    seed: int = 2016,
    convergence: ConvergenceConfig = MONTE_CARLO_CONVERGENCE,
    identifiability: IdentifiabilityConfig = NODE_IDENTIFIABILITY,
    band_limited_on: Collection[str] = BAND_LIMITED_ON,
    method: str = "time",
    frequency: FrequencyOptions | None = None,
    batch_runs: int | None = None,
) -> LevelResult:
    """All runs of one band-limited noise level (fraction, e.g. 0.2) with one ``method``
    (``"time"``: the estimator ``options``, default 50 lags, the paper's; ``"frequency"``: the
    frequency-domain estimator with ``frequency``, default :func:`t2_frequency_options`), the
    band-limited noise on the signals ``band_limited_on`` (:func:`.simulation.add_noise`), in
    this process, in the batches of ``batch_runs`` runs :func:`run_table3` uses (the same
    numbers). With ``lags="auto"`` each run's models choose their lags and the batch formula uses
    each model's final choice. For the time domain a second bank with all lags and the paper's
    Eq. 17 gives the all-lags comparison and Figs. 5 and 7.

    Besides the end-of-maneuver results, the convergence flags and the ensemble statistics
    of every sample are recorded (:class:`_Tracker`).
    """
    if method == "both":
        raise ConfigError("run_level runs one method (time or frequency); run_table3 runs both")
    methods, frequency = _methods(method, frequency)
    jobs = _jobs([level], runs, batch_runs or BATCH_RUNS, methods=methods, options=options, frequency=frequency,
                 seed=seed, convergence=convergence, identifiability=identifiability,
                 band_limited_on=tuple(band_limited_on))
    return _merge(jobs[0], [_run_batch(job) for job in jobs])[0]


def run_table3(
    runs: int,
    levels: Sequence[float] = LEVELS,
    *,
    options: EstimatorOptions = TABLE3_OPTIONS,
    jobs: int | None = None,
    progress: Callable[[str], object] = print,
    convergence: ConvergenceConfig = MONTE_CARLO_CONVERGENCE,
    band_limited_on: Collection[str] = BAND_LIMITED_ON,
    executor: Executor | None = None,
    method: str = "time",
    frequency: FrequencyOptions | None = None,
    batch_runs: int = BATCH_RUNS,
) -> list[LevelResult]:
    """Run every level with ``method`` (:data:`.datapath.config.METHODS`: the time domain with the
    estimator ``options``, the frequency domain with ``frequency``, default
    :func:`t2_frequency_options`, or both on the same runs) and the band-limited noise on
    ``band_limited_on``. The runs of each level are cut into batches of ``batch_runs``, one job
    each, on ``executor`` (default: ``jobs`` local processes, every core by default; or a Dask
    cluster, :mod:`.executors`); the batches depend on ``runs`` and ``batch_runs`` only, so the
    numbers are the same bit for bit whatever runs them. Returns one :class:`LevelResult` per
    level and method, level by level (time before frequency). A batch no worker finished is a
    :class:`.errors.WorkerLost`."""
    if not (type(batch_runs) is int and batch_runs >= 1):
        raise ConfigError(f"batch_runs must be an integer >= 1, got {batch_runs!r}")
    methods, frequency = _methods(method, frequency)
    executor = executor or LocalProcesses(jobs)
    t0 = time.perf_counter()
    work = _jobs(levels, runs, batch_runs, methods=methods, options=options, frequency=frequency, seed=2016,
                 convergence=convergence, identifiability=NODE_IDENTIFIABILITY, band_limited_on=tuple(band_limited_on))
    step = max(1, len(work) // 10)

    def done(i: int, n: int) -> None:
        if i % step == 0 or i == n:
            progress(f"  [{i}/{n}] batches of up to {batch_runs} runs done ({time.perf_counter() - t0:5.1f} s)")

    results = executor.run(_run_batch, work, done)
    lost = {f"{job.level * 100:g}%: {r.why}": None for job, r in zip(work, results, strict=True) if isinstance(r, Lost)}
    if lost:
        raise WorkerLost(f"Monte Carlo level(s) not computed: {'; '.join(lost)}")
    per_level = len(work) // max(len(levels), 1)
    out: list[LevelResult] = []
    for i in range(0, len(work), per_level):
        out += _merge(work[i], [r for r in results[i : i + per_level] if not isinstance(r, Lost)])
    return out


def _cover_time(t: np.ndarray, ratio: np.ndarray, threshold: float) -> float:
    """First time from which on ``ratio >= threshold`` (NaN counts as below); inf if the last
    sample is below."""
    below = np.flatnonzero(~(ratio >= threshold))
    if below.size == 0:
        return float(t[0])
    return float(t[below[-1] + 1]) if below[-1] + 1 < t.size else math.inf


def convergence_summary(res: LevelResult) -> list[dict]:
    """Convergence flags of one level against the observed scatter and the true values.

    Per Table 3 parameter (and per model, ``"CZ model"``, ``"Cm model"``):

    - ``flagged``: fraction of runs flagged at some time; ``flag_time_median``: median over
      runs of the first flag time (never-flagged runs count as infinite);
    - ``cover_time``: the time at which the corrected 2-sigma envelope covers the observed
      scatter: the first time from which on the mean corrected SE over runs is at least
      ``(1 - d)`` times the standard deviation of the estimates over runs, with
      ``d = 2 / sqrt(2 (runs - 1))`` the two-sigma sampling error of a standard deviation
      from ``runs`` samples (9% for 250 runs); ``cover_time_strict``: the same with ``d = 0``;
      infinite if the end of the maneuver is below;
    - ``false_convergence``: fraction of the flagged runs whose true value lies outside
      ``theta +- 2 se`` (corrected) at the first flag time; ``false_vs_mean``: the same
      with the ensemble mean at that time in place of the true value (calibration alone,
      without the estimator's bias); ``truth_outside_end``: fraction of all runs with the
      true value outside ``+- 2 se`` at the end of the maneuver; ``truth_outside_min``: the
      smallest such fraction at any sample from ``BEST_FROM`` (1 s, half a second into the
      elevator input) on -- the false-convergence rate of the best time to flag every run
      at once, chosen in hindsight: a floor for any flag; ``bias_at_flag_se``: (mean
      estimate at the flag - true value) / mean SE at the flag; ``se_over_scatter_at_flag``:
      mean SE / scatter at the median flag time;
    - ``untested_flag_time_median``: the median first flag time without the identifiability tests
      (:mod:`.identifiability`); ``held_back``: the fraction of runs whose first flag the tests
      delayed or withheld.

    For a model the flag time is the first time all its parameters are flagged, and a false
    convergence is any of its Table 3 parameters outside. The statistics over runs (cover
    times, truth outside) exist at the samples where every model of every run is ready (the
    C_Z models, with fewer parameters, may publish a sample before the C_m models).
    """
    t, runs = res.time, res.runs
    d = 2.0 / math.sqrt(2.0 * (runs - 1)) if runs > 1 else 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = res.ensemble_se / res.ensemble_scatter
    truth = np.array([T2_TRUE[p] for p in PARAMETERS])
    rows = []
    for i, name in enumerate(PARAMETERS):
        ft = res.flag_time[:, i]
        hit, false_truth, false_mean = _flag_rates(res, truth, ft, res.flag_theta, res.flag_se, [i])
        median = float(np.median(ft))
        cover = _cover_time(t, ratio[:, i], 1.0 - d)
        at = np.searchsorted(t, median) if math.isfinite(median) else None
        rows.append({
            "level": res.level, "parameter": name, "flagged": float(hit.mean()),
            "flag_time_median": median, "cover_time": cover,
            "cover_time_strict": _cover_time(t, ratio[:, i], 1.0),
            "flag_minus_cover": median - cover,
            "false_convergence": false_truth, "false_vs_mean": false_mean,
            "truth_outside_end": float(np.mean(np.abs(res.estimates[:, i] - truth[i]) > 2 * res.se_corrected[:, i])),
            "truth_outside_min": float(np.nanmin(res.truth_outside[t >= BEST_FROM, i])),
            "bias_at_flag_se": float((res.flag_theta[hit, i].mean() - truth[i]) / res.flag_se[hit, i].mean())
            if hit.any() else math.nan,
            "se_over_scatter_at_flag": float(ratio[at, i]) if at is not None else math.nan,
            **_held(ft, res.untested_flag_time[:, i]),
        })
    return rows + _model_rows(res, truth)


def _flag_rates(res: LevelResult, truth: np.ndarray, ft: np.ndarray, theta: np.ndarray, se: np.ndarray,
                cols: list[int]) -> tuple[np.ndarray, float, float]:
    """Which runs were flagged (first flag times ``ft``), and the fractions of those whose
    true value, or whose ensemble mean at the flag time, lies outside ``theta +- 2 se`` in any
    of the Table 3 columns ``cols``."""
    t = res.time
    hit = np.isfinite(ft)
    k = np.searchsorted(t, np.where(hit, ft, t[0]))
    mean = res.ensemble_mean[k][:, cols]
    th, s = theta[:, cols], se[:, cols]
    out_truth = (np.abs(th - truth[cols]) > 2 * s).any(axis=1)
    out_mean = (np.abs(th - mean) > 2 * s).any(axis=1)
    if not hit.any():
        return hit, math.nan, math.nan
    return hit, float(out_truth[hit].mean()), float(out_mean[hit].mean())


def _held(ft: np.ndarray, untested: np.ndarray) -> dict[str, float]:
    """The median first flag time without the identifiability tests and the fraction of runs
    whose first flag they delayed or withheld."""
    return {"untested_flag_time_median": float(np.median(untested)), "held_back": float(np.mean(ft > untested))}


def _model_rows(res: LevelResult, truth: np.ndarray) -> list[dict]:
    """:func:`convergence_summary`'s rows of the models (``"CZ model"``, ``"Cm model"``)."""
    t, rows = res.time, []
    for m, model in enumerate(T2_MODELS):
        cols = [i for i, p in enumerate(PARAMETERS) if _WHERE[p][0] == m]
        ft = res.model_flag_time[:, m]
        hit, false_truth, false_mean = _flag_rates(res, truth, ft, res.model_flag_theta, res.model_flag_se, cols)
        outside = (np.abs(res.estimates[:, cols] - truth[cols]) > 2 * res.se_corrected[:, cols]).any(axis=1)
        rows.append({
            "level": res.level, "parameter": f"{model.output} model", "flagged": float(hit.mean()),
            "flag_time_median": float(np.median(ft)), "cover_time": math.nan, "cover_time_strict": math.nan,
            "flag_minus_cover": math.nan, "false_convergence": false_truth, "false_vs_mean": false_mean,
            "truth_outside_end": float(outside.mean()),
            "truth_outside_min": float(np.nanmin(res.truth_outside[t >= BEST_FROM, len(PARAMETERS) + m])),
            "bias_at_flag_se": math.nan,
            "se_over_scatter_at_flag": math.nan,
            **_held(ft, res.untested_model_flag_time[:, m]),
        })
    return rows


CONVERGENCE_COLUMNS = (
    "level", "parameter", "flagged", "flag_time_median", "cover_time", "cover_time_strict", "flag_minus_cover",
    "false_convergence", "false_vs_mean", "truth_outside_end", "truth_outside_min", "bias_at_flag_se",
    "se_over_scatter_at_flag", "untested_flag_time_median", "held_back",
)


def _convergence_lines(results: list[LevelResult], named: bool = False) -> list[str]:
    cfg, runs = results[0].convergence, results[0].runs
    d = 2.0 / math.sqrt(2.0 * (runs - 1)) if runs > 1 else 0.0

    def sec(x):
        return "never" if not math.isfinite(x) else f"{x:.2f}"

    def pct(x):
        return "-" if not math.isfinite(x) else f"{100 * x:.0f}%"

    lines = [
        "",
        "## Convergence flags",
        "",
        f"Criterion (`rls_uncertainty.datapath.convergence`): window T = {cfg.window:g} s, band k = {cfg.band:g} "
        f"corrected SE, SE rate r = {cfg.max_se_rate:g}/s. Flag: median over runs of the first time the "
        "parameter (model: all its parameters) is flagged. Cover: first time from which on the mean corrected "
        f"SE over runs is at least (1 - {d:.3f}) x the scatter ({d:.3f} = 2/sqrt(2(runs-1)), the two-sigma "
        "sampling error of the scatter); strict: at least the scatter. False: flagged runs with the true value "
        "outside +-2 corrected SE at the flag time; vs mean: the same against the ensemble mean at that time "
        "(calibration alone, no estimator bias). Outside at end: all runs, truth outside +-2 SE at the end of the "
        f"maneuver; best: the least such fraction at any time from {BEST_FROM:g} s on (flagging every run at the "
        "best time, chosen in hindsight: a floor for any flag). Bias: (mean estimate - true) / mean SE at the flag. "
        "Held back: runs whose first flag the identifiability tests delayed or withheld (in brackets: the median "
        "flag time without them).",
        "",
        f"| level | {'method | ' if named else ''}parameter | flagged | flag, s | cover, s (strict) | flag - cover, s "
        "| false | false vs mean | truth outside: end / best | bias at flag, SE | SE/scatter at flag | held back |",
        "| --- |" + (" --- |" if named else "") + " --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for res in results:
        for row in convergence_summary(res):
            model = row["parameter"].endswith("model")
            lines.append(
                f"| {res.level * 100:.0f}% | {res.method + ' | ' if named else ''}{row['parameter']} | "
                f"{pct(row['flagged'])} | "
                f"{sec(row['flag_time_median'])} | "
                + ("- | - | " if model else
                   f"{sec(row['cover_time'])} ({sec(row['cover_time_strict'])}) | "
                   + ("-" if not math.isfinite(row["flag_minus_cover"]) else format(row["flag_minus_cover"], "+.2f"))
                   + " | ")
                + f"{pct(row['false_convergence'])} | {pct(row['false_vs_mean'])} | "
                + f"{pct(row['truth_outside_end'])} / {pct(row['truth_outside_min'])} | "
                + ("- | - |" if model else
                   f"{row['bias_at_flag_se']:+.2f} | {row['se_over_scatter_at_flag']:.2f} |")
                + f" {pct(row['held_back'])} ({sec(row['untested_flag_time_median'])}) |"
            )
    return lines


def write_outputs(results: list[LevelResult], out: Path, *, figures: bool = True) -> dict[str, Path]:
    """``table3.csv``, ``table3.md`` (beside the paper's values, then the convergence flags),
    ``convergence.csv`` (:func:`convergence_summary` of every level) and Figs. 5-7 as PNG."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / "table3.csv", "md": out / "table3.md", "convergence": out / "convergence.csv"}
    named = _method_column(results)
    method = ["method"] if named else []
    with open(paths["csv"], "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["level", *method, "parameter", "true", "mean", "se_conventional", "se_corrected", "scatter"])
        for res in results:
            for name, row in res.summary().items():
                w.writerow([f"{res.level:.2f}", *([res.method] if named else []), name, row["true"],
                            f"{row['mean']:.6g}", f"{row['se_conventional']:.6g}", f"{row['se_corrected']:.6g}",
                            f"{row['scatter']:.6g}"])
    time_results = [r for r in results if r.method == "time"]
    lags = results[0].lags
    burn_in = time_results[0].residual_burn_in if time_results else 0
    lines = [
        "# Table 3 reproduction",
        "",
        *(_methods_lines(results) if named else []),
        f"{results[0].runs} runs per level; end-of-maneuver values. Each cell: ours / paper. "
        "SE = mean standard error over runs; scatter = standard deviation of the estimates. Converged, "
        "identifiable at end: the runs whose parameter is flagged converged (the node's criterion and "
        "identifiability tests), identifiable, at the last sample; SE %: mean over runs of 100 corrected SE / "
        "|estimate|. "
        f"Band-limited noise on {', '.join(results[0].band_limited_on)} (docs/validation.md)."
        + (f" Residual burn-in {burn_in} samples: R(i) of Eq. 17 from the residuals after each model's "
           f"initialization + {burn_in} (both SE columns)." if burn_in else ""),
        "",
        f"| level | {'method | ' if named else ''}parameter | true | mean | SE conventional | SE corrected"
        f"{'' if named else f' ({lags} lags)'} | scatter | "
        "corrected/scatter | conventional/scatter | converged at end | identifiable at end | SE % |",
        "| --- |" + (" --- |" if named else "") + " --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for res in results:
        paper = PAPER_TABLE3.get(round(res.level, 2), {})
        for name, row in res.summary().items():
            p = paper.get(name, (np.nan,) * 4)
            lines.append(
                f"| {res.level * 100:.0f}% | {res.method + ' | ' if named else ''}{name} | {row['true']:g} | "
                f"{row['mean']:.3f} / {p[0]:.3f} | "
                f"{row['se_conventional']:.3f} / {p[1]:.3f} | {row['se_corrected']:.3f} / {p[2]:.3f} | "
                f"{row['scatter']:.3f} / {p[3]:.3f} | {row['se_corrected'] / row['scatter']:.2f} | "
                f"{row['se_conventional'] / row['scatter']:.2f} | {100 * row['converged_end']:.0f}% | "
                f"{100 * row['identifiable_end']:.0f}% | {row['se_percent']:.1f} |"
            )
    lines += _time_domain_lines(time_results, named)
    lines += _convergence_lines(results, named)
    paths["md"].write_text("\n".join(lines) + "\n")
    with open(paths["convergence"], "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([CONVERGENCE_COLUMNS[0], *method, *CONVERGENCE_COLUMNS[1:]])
        for res in results:
            for row in convergence_summary(res):
                w.writerow([f"{row['level']:.2f}", *([res.method] if named else []), row["parameter"]]
                           + [f"{row[c]:.6g}" for c in CONVERGENCE_COLUMNS[2:]])
    if figures and time_results:
        paths.update(_figures(time_results, out))
    return paths


def _method_column(results: list[LevelResult]) -> bool:
    """Whether the outputs name each row's method: unless every result is the time domain's
    (the outputs of ``--method time`` are the time domain's alone, without the column)."""
    return any(r.method != "time" for r in results)


def _methods_lines(results: list[LevelResult]) -> list[str]:
    """What each method of ``results`` is, with its settings (table3.md)."""
    lines = []
    for res in {r.method: r for r in results}.values():
        if res.method == "time":
            lines.append(f"Method time: recursive least squares, corrected SE with {res.options.lags} lags "
                         "(Eqs. 17-22).")
        else:
            f = res.frequency
            assert f is not None
            lines.append(f"Method frequency: equation error on a recursive Fourier transform, grid {f.f_min:g}-"
                         f"{f.f_max:g} Hz every {f.f_step:g} Hz, trim {f.trim_samples} samples, corrected SE with "
                         f"{f.n_lags} lags (docs/frequency.md, F7-F10); no bias parameter.")
    return [*lines, ""]


def _time_domain_lines(results: list[LevelResult], named: bool) -> list[str]:
    """table3.md's sections of the time domain alone: recursive against batch SEs, the lags chosen
    with ``auto`` (``named``: say so in the titles)."""
    if not results:
        return []
    lags = results[0].lags
    which = " (time domain)" if named else ""
    lines = [
        "",
        f"## Recursive against batch corrected standard errors{which} (end of maneuver, means over runs)",
        "",
        "Recursive: Eqs. 17-22 as the node runs them. Batch: Eqs. 8-11 with the final batch residuals.",
        "",
        "| level | parameter | recursive / batch, retained lags | recursive / batch, all lags "
        "| retained / all lags (recursive) |",
        "| --- | --- | --- | --- | --- |",
    ]
    for res in results:
        for name, row in res.summary().items():
            lines.append(
                f"| {res.level * 100:.0f}% | {name} | {row['se_corrected'] / row['se_batch']:.3f} | "
                f"{row['se_corrected_all'] / row['se_batch_all']:.3f} | "
                f"{row['se_corrected'] / row['se_corrected_all']:.3f} |"
            )
    if lags == "auto":
        lines += ["", f"## Chosen lags (auto){which}, end of maneuver: median [10%-90%] over runs", "",
                  "| level | " + " | ".join(m.output for m in T2_MODELS) + " |",
                  "| --- |" + " --- |" * len(T2_MODELS)]
        for res in results:
            q = np.percentile(res.lags_used, [50, 10, 90], axis=0)  # type: ignore[arg-type]  # run_level sets it
            lines.append(f"| {res.level * 100:.0f}% | " + " | ".join(
                f"{q[0, i]:.0f} [{q[1, i]:.0f}-{q[2, i]:.0f}]" for i in range(len(T2_MODELS))) + " |")
    return lines


def _figures(results: list[LevelResult], out: Path) -> dict[str, Path]:
    import matplotlib  # noqa: PLC0415 - plots only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    res = max(results, key=lambda r: r.level)
    last = res.last_run
    paths = {}
    fig, ax = plt.subplots(figsize=(7, 4))
    lags = np.arange(len(last["R_recursive"]))
    ax.plot(lags, last["R_recursive"], label="recursive (Eq. 17)")
    ax.plot(lags, last["R_batch"][: len(lags)], "--", label="batch (Eq. 10)")
    bound = 2 * last["R_batch"][0] / np.sqrt(last["N"])
    ax.axhline(bound, color="k", lw=0.8, ls=":", label=r"$\pm 2\sigma$, $\sigma = R(0)/\sqrt{N}$")
    ax.axhline(-bound, color="k", lw=0.8, ls=":")
    ax.set(xlabel="lag index", ylabel="autocorrelation of C_Z residual",
           title=f"Fig. 5: C_Z residual autocorrelation ({res.level * 100:.0f}% noise, last run)")
    ax.legend()
    paths["fig5"] = out / "fig5_autocorrelation.png"
    fig.tight_layout()
    fig.savefig(paths["fig5"], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    h, s, t = res.history_mean, res.history_scatter, res.time
    ax.plot(t, h[:, 0], "k", label="mean estimate")
    ax.fill_between(t, h[:, 0] - 2 * h[:, 2], h[:, 0] + 2 * h[:, 2], alpha=0.25, label=r"corrected $2\sigma$")
    ax.fill_between(t, h[:, 0] - 2 * h[:, 1], h[:, 0] + 2 * h[:, 1], alpha=0.5, label=r"conventional $2\sigma$")
    ax.plot(t, h[:, 0] - 2 * s, "r:", t, h[:, 0] + 2 * s, "r:", lw=1)
    ax.axhline(T2_TRUE["CZ_alpha"], color="g", lw=0.8, label="true")
    ax.set(xlabel="time, s", ylabel="C_Z_alpha", ylim=(-4.6, -3.0),
           title=f"Fig. 6: mean C_Z_alpha ({res.level * 100:.0f}% noise); red dotted: 2x observed scatter")
    ax.legend(loc="lower right", fontsize=8)
    paths["fig6"] = out / "fig6_czalpha_history.png"
    fig.tight_layout()
    fig.savefig(paths["fig6"], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    L, se = zip(*last["lag_sweep"], strict=True)
    ax.semilogx(np.asarray(L) + 1, se, "o-")
    ax.set(xlabel="number of retained lags + 1", ylabel="corrected SE of C_Z_alpha",
           title="Fig. 7: corrected standard error against retained lags (last run)")
    paths["fig7"] = out / "fig7_lags.png"
    fig.tight_layout()
    fig.savefig(paths["fig7"], dpi=110)
    plt.close(fig)
    return paths
