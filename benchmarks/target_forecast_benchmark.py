"""The time-to-target forecast (rls_uncertainty.datapath.targets) against the time actually taken,
over the Table 3 Monte Carlo.

Each run of one band-limited noise level (the Table 3 simulation: the T-2 maneuver, the paper's
differentiator, 50 lags) goes through an :class:`EstimatorBank` sample by sample, and its five
Table 3 parameters' estimates and corrected standard errors through a
:class:`.targets.TargetTracker`. Each parameter's target is its median percent error over the
runs at ``--target-at`` seconds. At each forecast time the tracker's time left gives a forecast
of when the target is reached; the run's own percent-error history gives when it actually was
(the first sample at or after the forecast with ``pe <= target``). Printed per parameter and
pooled: the forecasts made, those whose target was never reached in the recording (left out),
and the median and 90th percentile of the absolute error ``|forecast - actual|`` in seconds,
with the median signed error (positive: the forecast was late, i.e. pessimistic).

    .venv/bin/python benchmarks/target_forecast_benchmark.py [--runs 100] [--level 0.1]
        [--times 4 5 6 7 8] [--target-at 10] [--window 2]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from rls_uncertainty.datapath.targets import TargetOptions, TargetTracker, percent_errors
from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.simulation.montecarlo import PARAMETERS, TABLE3_OPTIONS, level_inputs, parameter_cells


def histories(level: float, runs: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t (N,), estimates (N, runs, 5), corrected SEs (N, runs, 5))`` of the Table 3 runs."""
    t, _, sizes, X, Z = level_inputs(level, runs)
    bank = EstimatorBank(sizes, TABLE3_OPTIONS)
    rows, cols = parameter_cells(runs)
    theta = np.full((t.size, runs, len(PARAMETERS)), np.nan)
    se = np.full_like(theta, np.nan)
    for k in range(t.size):
        bank.update(X[k], Z[k])
        if bank.ready.all():
            theta[k] = bank.theta_all()[rows, cols]
            se[k] = bank.standard_errors_all("corrected")[rows, cols]
    return t, theta, se


def forecast_errors(t: np.ndarray, theta: np.ndarray, se: np.ndarray, targets: np.ndarray, times: list[float],
                    window: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per (run, forecast time, parameter): the forecast reach time, the actual one (NaN: never
    in the recording; forecasts are made only where the target is not met yet and can be made)."""
    runs, n_par = theta.shape[1], theta.shape[2]
    options = TargetOptions(targets=tuple(f"{p}={float(g)!r}" for p, g in zip(PARAMETERS, targets, strict=True)),
                            window=window)
    pe = percent_errors(theta, se)  # (N, runs, 5)
    at = [int(np.searchsorted(t, s)) for s in times]
    forecast = np.full((runs, len(times), n_par), np.nan)
    actual = np.full_like(forecast, np.nan)
    for r in range(runs):
        tracker = TargetTracker(PARAMETERS, options)
        for k in range(t.size):
            if not np.isfinite(se[k, r]).all():
                continue
            progress = tracker.update(float(t[k]), theta[k, r], se[k, r], np.zeros(n_par, dtype=bool))
            if k not in at:
                continue
            i = at.index(k)
            for j, p in enumerate(progress):
                if p.met or not math.isfinite(p.time_left):
                    continue
                forecast[r, i, j] = t[k] + p.time_left
                reached = np.flatnonzero(pe[k:, r, j] <= targets[j])
                if reached.size:
                    actual[r, i, j] = t[k + reached[0]]
    return forecast, actual, pe


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--level", type=float, default=0.1)
    ap.add_argument("--times", type=float, nargs="+", default=[4.0, 5.0, 6.0, 7.0, 8.0])
    ap.add_argument("--target-at", type=float, default=10.0)
    ap.add_argument("--window", type=float, default=2.0)
    args = ap.parse_args()
    t, theta, se = histories(args.level, args.runs)
    k_target = int(np.searchsorted(t, args.target_at))
    targets = np.nanmedian(percent_errors(theta[k_target], se[k_target]), axis=0)
    forecast, actual, _ = forecast_errors(t, theta, se, targets, args.times, args.window)
    print(f"level {args.level:g}, {args.runs} runs, {t[-1] - t[0] + t[1] - t[0]:.1f} s each; targets: each "
          f"parameter's median percent error at {args.target_at:g} s; forecasts at {args.times} s, window "
          f"{args.window:g} s")
    print(f"{'parameter':<12}{'target %':>9}{'made':>6}{'never':>6}{'median |e| s':>14}{'p90 |e| s':>11}"
          f"{'median e s':>12}")

    def line(name: str, target: str, f: np.ndarray, a: np.ndarray) -> None:
        made = np.isfinite(f)
        ok = made & np.isfinite(a)
        e = (f - a)[ok]
        ae = np.abs(e)
        print(f"{name:<12}{target:>9}{int(made.sum()):>6}{int((made & ~ok).sum()):>6}"
              f"{np.median(ae) if e.size else math.nan:>14.2f}{np.percentile(ae, 90) if e.size else math.nan:>11.2f}"
              f"{np.median(e) if e.size else math.nan:>12.2f}")

    for j, p in enumerate(PARAMETERS):
        line(p, f"{targets[j]:.2f}", forecast[:, :, j], actual[:, :, j])
    line("all", "", forecast, actual)
    for i, s in enumerate(args.times):
        line(f"at {s:g} s", "", forecast[:, i], actual[:, i])


if __name__ == "__main__":
    main()
