"""Validation of the frequency-domain estimator (docs/frequency.md) beside the time-domain one.

Uses public names of the package only:

* **Table 3 Monte Carlo** (the paper's T-2 simulation, ``montecarlo.level_inputs``: the runs
  and seeds of ``rls-uncertainty montecarlo``): per band-limited noise level, the
  frequency-domain :class:`~rls_uncertainty.frequency.FrequencyBank` (corrected and
  conventional standard errors) and the time-domain
  :class:`~rls_uncertainty.estimator.EstimatorBank` with the node's 50 lags, on the same
  regression rows, sample by sample. Mean estimate, mean standard errors and observed scatter
  1, 2, 3, 5 and 7 s after the elevator input starts and at the end of the maneuver; the time
  from which the mean SE over the scatter stays in [0.8, 1.25]; the convergence flags of
  :class:`~rls_uncertainty.datapath.convergence.ConvergenceMonitor` on both (``--grid``: the grid).
* **Grids** (``--grids``): candidate grids covering Table 2's multisines, and trims, for
  ``config/t2.yaml``.
* **Twin Otter** (``--flight``): the three recordings through the node's pipeline
  (``testing.replay_bag``) with ``estimator.method: both``: both methods' end estimates and
  standard errors and their first convergence flags.

The frequency-domain options are those the node takes from ``config/t2.yaml`` (grid 0.2-2.2 Hz
every 0.04 Hz, ``trim_span`` 0.5 s = 25 samples, 1 s = 50 lags; ``--trim-span`` another trim).
Prints the tables (Markdown) on stdout; REPORT.md beside this file holds them with how they
were run. From the worktree root, one process (the machine is shared)::

    .venv/bin/python docs/studies/frequency/study.py --flight            # 250 runs per level
    .venv/bin/python docs/studies/frequency/study.py --quick             # 20 runs, 0 % and 20 %
"""

from __future__ import annotations

import os

# Small matrices: one BLAS thread is faster than several on a shared 2-core machine.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT))

from rls_uncertainty.datapath.convergence import ConvergenceMonitor  # noqa: E402
from rls_uncertainty.estimator import EstimatorBank  # noqa: E402
from rls_uncertainty.frequency import FrequencyBank, FrequencyOptions  # noqa: E402
from rls_uncertainty.frequency.covariance import PairGeometry, middle  # noqa: E402
from rls_uncertainty.settings import load_parameters_file, pipeline_config  # noqa: E402
from rls_uncertainty.simulation.montecarlo import LEVELS, MONTE_CARLO_CONVERGENCE, level_inputs  # noqa: E402
from rls_uncertainty.simulation.t2 import T2_MODELS, T2_TRUE, SimulationConfig  # noqa: E402

RATE = SimulationConfig().rate
INPUT_START = SimulationConfig().input_start
AFTER_INPUT = (1.0, 2.0, 3.0, 5.0, 7.0)  # s after the elevator input starts; then the end
# The time-domain estimator the node takes from config/t2.yaml (estimator.lag_span 1 s: 50 lags).
T2_ESTIMATOR = pipeline_config(load_parameters_file("t2")).estimator
TD_LAGS = T2_ESTIMATOR.lags
HONEST = (0.8, 1.25)
# The five Table 3 parameters: (model index, column among the model's regressors incl. "1").
PARAMETERS = tuple(T2_TRUE)
CELLS = [(m, c) for m, model in enumerate(T2_MODELS) for c in range(1, len(model.regressors))]
TRUTH = np.array([T2_TRUE[p] for p in PARAMETERS])


def grid_options(grid: tuple[float, float, float], **kw: int) -> FrequencyOptions:
    f_min, f_max, step = grid
    return FrequencyOptions(rate_hz=RATE, f_min=f_min, f_max=f_max, f_step=step, **kw)


def run_inputs(level: float, runs: int) -> tuple[np.ndarray, list[int], np.ndarray, np.ndarray, np.ndarray]:
    """``t``, time-domain sizes, regressors ``X`` (with the bias column), outputs ``Z`` and the
    frequency-domain regressors (without it)."""
    t, _red, sizes, X, Z = level_inputs(level, runs)
    Xf = X[:, :, 1:]  # every T-2 model has "1" first
    return t, sizes, X, Z, Xf


def pick(values: np.ndarray, runs: int, shift: int) -> np.ndarray:
    """``(runs, 5)`` Table 3 parameters from ``(M, n)`` model rows; ``shift`` 0 for rows with the
    bias column, 1 without."""
    n_models = len(T2_MODELS)
    return np.stack([values[np.arange(runs) * n_models + m, c - shift] for m, c in CELLS], axis=1)


def snapshot_indices(t: np.ndarray) -> dict[str, int]:
    out = {f"+{a:g} s": int(np.searchsorted(t, INPUT_START + a - 1e-9)) for a in AFTER_INPUT}
    out["end"] = t.size - 1
    return out


class Tracker:
    """Per-sample statistics of one method over the runs: snapshots, ensemble ratios, flags."""

    def __init__(self, sizes: list[int], runs: int, t: np.ndarray, shift: int) -> None:
        self.runs, self.t, self.shift = runs, t, shift
        self.monitor = ConvergenceMonitor(sizes, MONTE_CARLO_CONVERGENCE)
        self.stamps = np.round(t * 1e9).astype(np.int64)
        self.snap = {name: {} for name in snapshot_indices(t)}
        self.index = {k: name for name, k in snapshot_indices(t).items()}
        self.ratio = np.full((t.size, 5), np.nan)  # mean corrected SE / scatter
        self.flag = np.full((runs, 5), np.inf)
        self.flag_outside = np.zeros((runs, 5), bool)

    def update(self, k: int, theta: np.ndarray, se: np.ndarray, se_conv: np.ndarray, ready: np.ndarray) -> None:
        flags, _ = self.monitor.update(int(self.stamps[k]), theta, se, ready)
        th, s = pick(theta, self.runs, self.shift), pick(se, self.runs, self.shift)
        f = pick(flags, self.runs, self.shift)
        new = f & ~np.isfinite(self.flag)
        self.flag[new] = self.t[k]
        self.flag_outside[new] = (np.abs(th - TRUTH) > 2 * s)[new]
        if ready.all():
            self.ratio[k] = s.mean(axis=0) / th.std(axis=0, ddof=1)
        if k in self.index:
            self.snap[self.index[k]] = {
                "theta": th, "se": s, "se_conventional": pick(se_conv, self.runs, self.shift)}


def run_level(level: float, runs: int, options: FrequencyOptions) -> dict:
    """Both methods on every run of one level, sample by sample."""
    t, sizes, X, Z, Xf = run_inputs(level, runs)
    td = EstimatorBank(sizes, T2_ESTIMATOR)
    fd = FrequencyBank([s - 1 for s in sizes], options)
    tracks = {"time": Tracker(sizes, runs, t, 0), "frequency": Tracker([s - 1 for s in sizes], runs, t, 1)}
    cost = {"time": 0.0, "frequency": 0.0}
    for k in range(t.size):
        t0 = time.perf_counter()
        td.update(X[k], Z[k])
        out_td = (td.theta_all(), td.standard_errors_all("corrected"), td.standard_errors_all("conventional"),
                  td.ready)
        t1 = time.perf_counter()
        fd.update(Xf[k], Z[k])
        out_fd = (fd.theta_all(), fd.standard_errors_all("corrected"), fd.standard_errors_all("conventional"),
                  fd.ready)
        t2 = time.perf_counter()
        cost["time"] += t1 - t0
        cost["frequency"] += t2 - t1
        tracks["time"].update(k, *out_td)
        tracks["frequency"].update(k, *out_fd)
    return {"level": level, "runs": runs, "t": t, "tracks": tracks, "se_true_noise": true_noise_se(fd, X, Z, runs),
            "cost_per_model_sample_us": {m: c / t.size / len(sizes) * 1e6 for m, c in cost.items()}}


def true_noise_se(bank: FrequencyBank, X: np.ndarray, Z: np.ndarray, runs: int) -> np.ndarray:
    """The frequency-domain SE at the end of the record with the *true* equation-error
    autocovariance in F7-F8 instead of the estimated one, ``(runs, 5)``: the equation error of
    every run with the true parameters, less its mean over runs at each sample (the bias and
    the differentiator's error on the clean signals), averaged over runs and samples per lag."""
    n_models, N = len(T2_MODELS), X.shape[0]
    L = bank.options.n_lags
    truth = [np.array([T2_TRUE[p] for p, (mm, _c) in zip(PARAMETERS, CELLS, strict=True) if mm == m])
             for m in range(n_models)]
    R = np.zeros((runs * n_models, L + 1))
    for m in range(n_models):
        rows = np.arange(runs) * n_models + m
        e = Z[:, rows] - np.einsum("nra,a->nr", X[:, rows, 1 : 1 + truth[m].size], truth[m])
        e -= e.mean(axis=1, keepdims=True)
        R[rows] = [np.sum(e[i:] * e[: N - i]) / (runs * (N - i)) for i in range(L + 1)]
    _Z, Xf = bank.transforms()
    A = np.einsum("mka,mkb->mab", Xf.conj(), Xf).real
    pad = np.all(Xf == 0, axis=1)
    A[pad[:, :, None] & np.eye(A.shape[1], dtype=bool)] = 1.0
    A_inv = np.linalg.inv(A)
    geometry = PairGeometry(2 * np.pi * bank.frequencies / RATE).at(N)
    cov = A_inv @ (middle(R, Xf, geometry, min(N, bank.options.trim_samples)) / RATE**2) @ A_inv
    se = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0, None))
    return pick(se, runs, 1)


def honest_from(t: np.ndarray, ratio: np.ndarray) -> float:
    """First time from which on the ratio stays in [0.8, 1.25] (inf if the end is outside)."""
    bad = np.flatnonzero(~((ratio >= HONEST[0]) & (ratio <= HONEST[1])))
    if bad.size == 0:
        return float(t[0])
    return float(t[bad[-1] + 1]) if bad[-1] + 1 < t.size else math.inf


def summarise(res: dict) -> dict:
    out: dict = {"level": res["level"], "runs": res["runs"], "cost": res["cost_per_model_sample_us"], "methods": {},
                 "se_true_noise_end": res["se_true_noise"].mean(axis=0).tolist()}
    t = res["t"]
    for method, tr in res["tracks"].items():
        snaps = {}
        for name, s in tr.snap.items():
            scatter = s["theta"].std(axis=0, ddof=1)
            snaps[name] = {
                "mean": s["theta"].mean(axis=0).tolist(), "scatter": scatter.tolist(),
                "cover": (np.abs(s["theta"] - TRUTH) <= 2 * s["se"]).mean(axis=0).tolist(),
                "se": s["se"].mean(axis=0).tolist(), "se_conventional": s["se_conventional"].mean(axis=0).tolist(),
            }
        flagged = np.isfinite(tr.flag)
        out["methods"][method] = {
            "snapshots": snaps,
            "honest_from": [honest_from(t, tr.ratio[:, i]) - INPUT_START for i in range(5)],
            "flag_median": [float(np.median(tr.flag[:, i])) - INPUT_START for i in range(5)],
            "flagged": flagged.mean(axis=0).tolist(),
            "false_at_flag": [float(tr.flag_outside[flagged[:, i], i].mean()) if flagged[:, i].any() else math.nan
                              for i in range(5)],
        }
    return out


# ---------------------------------------------------------------------------- tables
def fmt(x: float, digits: int = 3) -> str:
    if math.isnan(x):
        return "-"
    return "never" if math.isinf(x) else f"{x:.{digits}f}"


def ratio_cell(se: float, scatter: float) -> str:
    r = se / scatter
    mark = "" if HONEST[0] <= r <= HONEST[1] else "*"
    return f"{r:.2f}{mark}"


def main_table(summaries: list[dict], o: FrequencyOptions) -> list[str]:
    lines = [
        f"## Table 3 Monte Carlo: both methods on the same runs (frequency grid {o.f_min:g}-{o.f_max:g} Hz "
        f"every {o.f_step:g} Hz, trim {o.trim_samples} sample(s), {o.n_lags} lags; time domain {TD_LAGS} lags)",
        "",
        "Times after the elevator input starts (0.5 s); `end` = 12 s. Per method: mean estimate; "
        "corrected SE / conventional SE (means over runs); observed scatter (standard deviation of the "
        "estimates over runs); SE over scatter, corrected / conventional (`*` outside [0.8, 1.25]).",
        "",
        "| level | time | parameter | true | FD mean | FD SE corr / conv | FD scatter | FD ratio corr / conv "
        "| TD mean | TD SE corr / conv | TD scatter | TD ratio corr / conv |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for s in summaries:
        for name in s["methods"]["frequency"]["snapshots"]:
            for i, p in enumerate(PARAMETERS):
                row = [f"{s['level'] * 100:.0f}%", name, p, f"{TRUTH[i]:g}"]
                for method in ("frequency", "time"):
                    d = s["methods"][method]["snapshots"][name]
                    sc = d["scatter"][i]
                    row += [fmt(d["mean"][i]), f"{fmt(d['se'][i])} / {fmt(d['se_conventional'][i])}", fmt(sc),
                            f"{ratio_cell(d['se'][i], sc)} / {ratio_cell(d['se_conventional'][i], sc)}"]
                lines.append("| " + " | ".join(row) + " |")
    return lines


def ratio_table(summaries: list[dict]) -> list[str]:
    lines = ["## SE over scatter, range over the five parameters", "",
             "| level | time | FD corrected | FD conventional | TD corrected | TD conventional |",
             "| --- | --- | --- | --- | --- | --- |"]
    for s in summaries:
        for name in s["methods"]["frequency"]["snapshots"]:
            row = [f"{s['level'] * 100:.0f}%", name]
            for method in ("frequency", "time"):
                d = s["methods"][method]["snapshots"][name]
                for key in ("se", "se_conventional"):
                    r = np.array(d[key]) / np.array(d["scatter"])
                    row.append(f"{r.min():.2f}-{r.max():.2f}")
            lines.append("| " + " | ".join(row) + " |")
    return lines


def coverage_table(summaries: list[dict]) -> list[str]:
    lines = ["## Coverage: runs whose +-2 corrected SE interval holds the true value", "",
             "Range over the five parameters (95 % for an honest SE and an unbiased estimate). Unlike the ratio to "
             "the scatter it counts the bias too: at 10-20 % the errors-in-variables bias of C_m_q (both methods) "
             "lowers it at the end.", "",
             "| level | time | FD corrected | TD corrected |", "| --- | --- | --- | --- |"]
    for s in summaries:
        for name in s["methods"]["frequency"]["snapshots"]:
            cells = [s["methods"][m]["snapshots"][name]["cover"] for m in ("frequency", "time")]
            lines.append(f"| {s['level'] * 100:.0f}% | {name} | " + " | ".join(
                f"{min(c) * 100:.0f}-{max(c) * 100:.0f}%" for c in cells) + " |")
    return lines


def true_noise_table(summaries: list[dict]) -> list[str]:
    lines = ["## End of the maneuver: the frequency-domain SE with the estimated and with the true noise "
             "autocovariance", "",
             "SE over scatter. True: F7-F8 with the autocovariance of the runs' true equation error (their "
             "equation error with the true parameters, less its mean over the runs at each sample). "
             "Where this is off too, the sandwich itself misses something (errors in variables).", "",
             "| level | " + " | ".join(PARAMETERS) + " |", "| --- |" + " --- |" * 5]
    for s in summaries:
        d = s["methods"]["frequency"]["snapshots"]["end"]
        cells = [f"{d['se'][i] / d['scatter'][i]:.2f} / {s['se_true_noise_end'][i] / d['scatter'][i]:.2f}"
                 for i in range(5)]
        lines.append(f"| {s['level'] * 100:.0f}% | " + " | ".join(cells) + " |")
    return lines


def convergence_table(summaries: list[dict]) -> list[str]:
    lines = [
        "## When each method can be trusted",
        "",
        "Honest from: the time after the input start from which the mean corrected SE over the scatter "
        "stays in [0.8, 1.25] to the end. Flag: median time (after the input start) of the first "
        "convergence flag of `rls_uncertainty.datapath.convergence` (the node's criterion, 50 Hz buffer); "
        "flagged: runs flagged at some time; false: flagged runs whose true value lies outside "
        "+-2 corrected SE at the flag.",
        "",
        "| level | parameter | FD honest from, s | TD honest from, s | FD flag, s | TD flag, s "
        "| FD flagged / false | TD flagged / false |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for s in summaries:
        f, d = s["methods"]["frequency"], s["methods"]["time"]
        for i, p in enumerate(PARAMETERS):
            lines.append(
                f"| {s['level'] * 100:.0f}% | {p} | {fmt(f['honest_from'][i], 2)} | {fmt(d['honest_from'][i], 2)} | "
                f"{fmt(f['flag_median'][i], 2)} | {fmt(d['flag_median'][i], 2)} | "
                f"{f['flagged'][i] * 100:.0f}% / {f['false_at_flag'][i] * 100:.0f}% | "
                f"{d['flagged'][i] * 100:.0f}% / {d['false_at_flag'][i] * 100:.0f}% |")
    return lines


# ---------------------------------------------------------------------------- grids
# (grid (f_min, f_max, step), trim_samples): candidates for config/t2.yaml. Table 2's multisines
# excite 0.2 to 2.2 Hz (the elevator 0.3 to 2.1 Hz); the T-2's input starts after 25 samples.
CANDIDATES = (
    ((0.1, 1.5, 0.04), 1),  # the default (SIDPAC's demo): misses the 1.8 and 2.1 Hz elevator harmonics
    ((0.1, 2.2, 0.04), 1),
    ((0.2, 2.2, 0.04), 1),
    ((0.1, 2.2, 0.02), 1),
    ((0.1, 2.2, 0.1), 1),  # exactly Table 2's harmonics, 0.1 to 2.2 Hz
    ((0.1, 3.0, 0.04), 1),
    ((0.1, 1.5, 0.04), 25),
    ((0.2, 2.2, 0.04), 25),
)


def grid_study(runs: int, levels: tuple[float, ...]) -> list[dict]:
    """Frequency-domain results of every candidate at the snapshot times (evaluated there only)."""
    rows = []
    for level in levels:
        t, sizes, _X, Z, Xf = run_inputs(level, runs)
        at = {k: name for name, k in snapshot_indices(t).items()}
        banks = {c: FrequencyBank([s - 1 for s in sizes], grid_options(c[0], trim_samples=c[1])) for c in CANDIDATES}
        for k in range(t.size):
            for c, bank in banks.items():
                bank.update(Xf[k], Z[k])
                if k in at:
                    th, se = pick(bank.theta_all(), runs, 1), pick(bank.standard_errors_all(), runs, 1)
                    conv = pick(bank.standard_errors_all("conventional"), runs, 1)
                    scatter = th.std(axis=0, ddof=1)
                    rmse = np.sqrt(((th - TRUTH) ** 2).mean(axis=0))
                    rows.append({"level": level, "grid": c[0], "trim": c[1], "time": at[k],
                                 "mean": th.mean(axis=0).tolist(), "scatter": scatter.tolist(), "rmse": rmse.tolist(),
                                 "ratio": (se.mean(axis=0) / scatter).tolist(),
                                 "ratio_conventional": (conv.mean(axis=0) / scatter).tolist()})
        print(f"  candidates: level {level * 100:.0f}% done", file=sys.stderr)
    return rows


def grid_table(rows: list[dict], runs: int) -> list[str]:
    lines = [
        f"## Candidate grids and trims ({runs} runs per level; frequency domain only)", "",
        "Scatter and RMS error (about the true value) relative to the default's (0.1-1.5 Hz every 0.04 Hz, "
        "the first sample as trim) at the same level and time, averaged over the five parameters and the "
        "five levels; SE over scatter: range over parameters and levels (`*`: outside [0.8, 1.25]).", "",
        "| grid, Hz | trim, samples | time | scatter / default | RMSE / default | corrected SE/scatter "
        "| conventional SE/scatter |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    base = {(r["level"], r["time"]): r for r in rows if (tuple(r["grid"]), r["trim"]) == CANDIDATES[0]}
    for grid, trim in CANDIDATES:
        mine = [r for r in rows if (tuple(r["grid"]), r["trim"]) == (grid, trim)]
        for time_name in dict.fromkeys(r["time"] for r in mine):
            sel = [r for r in mine if r["time"] == time_name]
            sc = np.mean([np.array(r["scatter"]) / np.array(base[(r["level"], time_name)]["scatter"]) for r in sel])
            rm = np.mean([np.array(r["rmse"]) / np.array(base[(r["level"], time_name)]["rmse"]) for r in sel])
            ratio = np.array([r["ratio"] for r in sel])
            conv = np.array([r["ratio_conventional"] for r in sel])

            def span(a: np.ndarray) -> str:
                ok = (a.min() >= HONEST[0]) and (a.max() <= HONEST[1])
                return f"{a.min():.2f}-{a.max():.2f}" + ("" if ok else "*")

            lines.append(f"| {grid[0]:g}-{grid[1]:g} / {grid[2]:g} | {trim} | {time_name} | {sc:.2f} | {rm:.2f} | "
                         f"{span(ratio)} | {span(conv)} |")
    return lines


# ---------------------------------------------------------------------------- Twin Otter
RECORDINGS = {
    "totter_f1_017": ("twin_otter_lateral", {}),
    "totter_f1_014": ("twin_otter_lateral", {"aircraft": "twin_otter_f1_014"}),
    "totter_9752ed20": ("twin_otter_longitudinal", {}),
}


def first_flag(series: object) -> float:
    """Seconds from the first published estimate to the first convergence flag (inf: none)."""
    t, flags = series.stamps_ns, series.converged  # type: ignore[attr-defined]
    return float((t[np.argmax(flags)] - t[0]) * 1e-9) if flags.any() else math.inf


def flight(name: str, data: Path, work: Path) -> dict:
    """Both methods through the real replay (``estimator.method: both``, the recording's
    parameter file): each parameter's last published estimate and SEs, and when it was first
    flagged converged."""
    from rls_uncertainty.offline.bags import convert  # noqa: PLC0415 - flight part only
    from rls_uncertainty.testing import replay_bag  # noqa: PLC0415

    config_name, extra = RECORDINGS[name]
    bag = work / name
    convert(data / name, ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml", bag)
    result = replay_bag(bag, config_name, **{"estimator__method": "both", **extra})
    config = result.pipeline.config
    rows = []
    for names in result.frequency_parameter_names:
        for p in names:
            td, fd = result.final(p), result.final(p, method="frequency")
            rows.append({"parameter": p, "td": [td.estimate, td.std_error, td.std_error_conventional],
                         "fd": [fd.estimate, fd.std_error, fd.std_error_conventional],
                         "td_flag": first_flag(result.series(p)),
                         "fd_flag": first_flag(result.series(p, method="frequency"))})
    counters = result.counters()
    return {"recording": name, "rate": config.rate, "samples": counters["samples_used"],
            "rejected": counters["samples_rejected"], "grid": config.frequency, "rows": rows}


def flight_table(results: list[dict]) -> list[str]:
    lines = ["## Twin Otter recordings: end of the maneuver, both methods through the replay", "",
             "`rls_uncertainty.testing.replay_bag` (the node's pipeline) with `config/twin_otter_*.yaml` and "
             "`estimator.method: both`: the last published estimate and SE corrected / conventional of each "
             "parameter, and the time from the first published estimate to the first convergence flag. The "
             "biases are not estimated in the frequency domain.", ""]
    for r in results:
        g = r["grid"]
        lines += [f"### {r['recording']} ({r['samples']} samples used at {r['rate']:g} Hz; rejected: "
                  f"{r['rejected'] or 0}; grid {g.f_min:g}-{g.f_max:g} Hz every {g.f_step:g} Hz, "
                  f"{g.n_lags} lags)", "",
                  "| parameter | TD estimate | TD SE corr / conv | FD estimate | FD SE corr / conv "
                  "| difference / larger corr. SE | TD flag, s | FD flag, s |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for row in r["rows"]:
            td, fd = row["td"], row["fd"]
            gap = abs(td[0] - fd[0]) / max(td[1], fd[1])
            lines.append(f"| {row['parameter']} | {td[0]:.4g} | {td[1]:.3g} / {td[2]:.3g} | {fd[0]:.4g} | "
                         f"{fd[1]:.3g} / {fd[2]:.3g} | {gap:.2f} | {fmt(row['td_flag'], 1)} | "
                         f"{fmt(row['fd_flag'], 1)} |")
        lines.append("")
    return lines


# ---------------------------------------------------------------------------- main
def t2_options(trim_span: float | None) -> FrequencyOptions:
    """The frequency-domain options the node takes from config/t2.yaml with ``estimator.method:
    both`` (``trim_span``: another ``frequency.trim_span``, s)."""
    params = {**load_parameters_file("t2"), "estimator.method": "both"}
    if trim_span is not None:
        params["frequency.trim_span"] = trim_span
    options = pipeline_config(params).frequency
    assert options is not None
    return options


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=250)
    ap.add_argument("--levels", type=float, nargs="*", default=list(LEVELS))
    ap.add_argument("--trim-span", type=float, default=None,
                    help="frequency.trim_span of the Monte Carlo, s (default: config/t2.yaml's; 0: the first sample)")
    ap.add_argument("--grids", action="store_true", help="also compare the candidate grids and trims")
    ap.add_argument("--grid-runs", type=int, default=150)
    ap.add_argument("--flight", action="store_true", help="also the Twin Otter recordings")
    ap.add_argument("--skip-montecarlo", action="store_true")
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "flight_data")
    ap.add_argument("--quick", action="store_true", help="20 runs at 0 %% and 20 %%, no grids, no flight data")
    args = ap.parse_args(argv)
    if args.quick:
        args.runs, args.levels, args.grids, args.flight = 20, [0.0, 0.2], False, False
    options = t2_options(args.trim_span)
    print(f"<!-- docs/studies/frequency/study.py {' '.join(sys.argv[1:])} -->\n")
    if not args.skip_montecarlo:
        summaries = []
        for level in args.levels:
            t0 = time.perf_counter()
            summaries.append(summarise(run_level(level, args.runs, options)))
            print(f"level {level * 100:.0f}%: {args.runs} runs in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        cost = {m: float(np.mean([s["cost"][m] for s in summaries])) for m in ("time", "frequency")}
        lines = [*ratio_table(summaries), "", *coverage_table(summaries), "", *true_noise_table(summaries), "",
                 *convergence_table(summaries), "",
                 *main_table(summaries, options)]
        lines += ["", f"Study loop cost per model and sample (update and all outputs, {2 * args.runs} models at once): "
                  f"time domain {cost['time']:.1f} us, frequency domain {cost['frequency']:.1f} us "
                  "(the node's bank of a few models: benchmarks/frequency_benchmark.py).", ""]
        print("\n".join(lines))
    if args.grids:
        print("\n".join(grid_table(grid_study(args.grid_runs, tuple(args.levels)), args.grid_runs)) + "\n")
    if args.flight:
        with tempfile.TemporaryDirectory(prefix="freq_study_") as work:
            results = [flight(name, args.data, Path(work)) for name in RECORDINGS]
        print("\n".join(flight_table(results)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
