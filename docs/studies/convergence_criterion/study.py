"""The defaults of the convergence flags (``convergence.window``, ``convergence.band``,
``convergence.max_se_rate``): a grid of settings on a tuning set of the Table 3 Monte Carlo.
Report: REPORT.md beside this file.

The tuning set is the paper's Section IV.A simulation with seed 7; the Monte Carlo that
docs/validation.md reports (``rls-uncertainty montecarlo``) uses seed 2016, so the defaults
are judged there on runs they were not chosen on. For each setting, every level is run with
the package's own Monte Carlo (``montecarlo.run_level``, 50 lags) and summarized by
``montecarlo.convergence_summary`` (its docstring defines every column):

* median flag time per level (mean over the five Table 3 parameters);
* false convergence against the ensemble mean (calibration alone: flagged while the ensemble
  mean lies outside +-2 corrected SE), largest and mean over levels and parameters;
* flag time minus cover time at 20 % per parameter (cover: the mean corrected SE reaches the
  observed scatter within its two-sigma sampling error); the goal was within 2 s;
* the smallest fraction of runs ever flagged.

    .venv/bin/python docs/studies/convergence_criterion/study.py           # the report's grid, 250 runs
    .venv/bin/python docs/studies/convergence_criterion/study.py --quick   # two settings, 0 % and 20 %, 30 runs
    .venv/bin/python docs/studies/convergence_criterion/study.py --cost    # CPU time of one update

``--cost``: the CPU time of one ``ConvergenceMonitor.update`` for 6 models x 6 parameters at
50 Hz with converging estimates (flags up most of the time), the best and median of 300
batches, beside one ``np.add`` of two 6 x 6 arrays measured the same way as a yardstick for
the machine's load.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace

import numpy as np

from rls_uncertainty.datapath.convergence import ConvergenceConfig, ConvergenceMonitor
from rls_uncertainty.simulation.montecarlo import LEVELS, MONTE_CARLO_CONVERGENCE, convergence_summary, run_level

SEED = 7
# (window T in s, band k in corrected SE, max_se_rate r in 1/s); the first is the default
GRID = (
    (2.0, 1.0, 0.25),
    (1.5, 1.0, 0.15), (1.5, 1.0, 0.30),
    (2.0, 1.0, 0.15), (2.0, 1.0, 0.20), (2.0, 1.0, 0.30),
    (2.5, 1.0, 0.25),
    (2.0, 0.5, 0.25), (2.0, 2.0, 0.25),
)


def evaluate(setting: tuple[float, float, float], levels: tuple[float, ...], runs: int) -> dict[float, list[dict]]:
    """convergence_summary's parameter rows of every level for one setting."""
    T, k, r = setting
    config = replace(MONTE_CARLO_CONVERGENCE, window=T, band=k, max_se_rate=r)
    rows = {}
    for level in levels:
        res = run_level(level, runs, seed=SEED, convergence=config)
        rows[level] = [row for row in convergence_summary(res) if not row["parameter"].endswith("model")]
    return rows


def line(setting: tuple[float, float, float], rows: dict[float, list[dict]]) -> str:
    T, k, r = setting
    flag = " ".join(f"{np.mean([x['flag_time_median'] for x in rows[lv]]):.2f}" for lv in rows)
    false = np.array([x["false_vs_mean"] for lv in rows for x in rows[lv]])
    last = rows[max(rows)]
    minus = " ".join(f"{x['flag_minus_cover']:+.2f}" for x in last)
    flagged = min(x["flagged"] for lv in rows for x in rows[lv])
    return (f"| {T:g} | {k:g} | {r:g} | {flag} | {np.nanmax(false):.3f} / {np.nanmean(false):.3f} | {minus} "
            f"| {100 * flagged:.0f}% |")


def cost(models: int = 6, n: int = 6, batch: int = 200, repeats: int = 300) -> None:
    """CPU time of one monitor update per sample (thread time, so other processes do not count)."""
    rng = np.random.default_rng(0)
    se = 0.1 / np.sqrt(np.arange(2 * batch) + 50.0)[:, None, None] * np.ones((1, models, n))
    theta = 1.0 + 0.3 * se * rng.normal(size=se.shape)
    ready = np.ones(models, bool)
    monitor = ConvergenceMonitor([n] * models, ConvergenceConfig())
    a, b, c = np.ones((6, 6)), np.ones((6, 6)), np.ones((6, 6))
    update, yardstick, step = [], [], 0
    for _ in range(repeats):
        t0 = time.thread_time()
        for _ in range(batch):
            j = step % (2 * batch)
            monitor.update(step * 20_000_000, theta[j], se[j], ready)
            step += 1
        update.append((time.thread_time() - t0) / batch * 1e6)
        t0 = time.thread_time()
        for _ in range(batch):
            np.add(a, b, out=c)
        yardstick.append((time.thread_time() - t0) / batch * 1e6)
    u, y = np.array(update), np.array(yardstick)
    print(f"update: best {u.min():.2f} us, median {np.median(u):.2f} us per sample ({models} models x {n} "
          f"parameters); one np.add (6 x 6): best {y.min():.3f} us, median {np.median(y):.3f} us; "
          f"update = {np.median(u / y):.0f} np.add; load average {os.getloadavg()[0]:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the default and one other setting, 0 %% and 20 %%, 30 runs")
    ap.add_argument("--runs", type=int, default=250, help="runs per noise level (default 250)")
    ap.add_argument("--cost", action="store_true", help="only the CPU time of one monitor update")
    args = ap.parse_args()
    if args.cost:
        cost()
        return
    grid, levels, runs = GRID, LEVELS, args.runs
    if args.quick:
        grid, levels, runs = GRID[:2], (0.0, 0.2), 30
    print(f"Tuning set: seed {SEED}, {runs} runs per level, levels "
          + " ".join(f"{lv * 100:.0f}%" for lv in levels) + f"; flag - cover at {max(levels) * 100:.0f}% for "
          "CZ_alpha, CZ_delta_e, Cm_alpha, Cm_q, Cm_delta_e\n")
    print("| T, s | k | r, 1/s | median flag time per level, s | false vs mean: max / mean "
          "| flag - cover, s | least flagged |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    default_rows = None
    for setting in grid:
        t0 = time.perf_counter()
        rows = evaluate(setting, levels, runs)
        default_rows = default_rows or rows
        print(line(setting, rows), flush=True)
        print(f"{setting}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    print("\nThe default setting per level and parameter (cover with tolerance / strict):\n")
    print("| level | parameter | flag, s | cover, s | flag - cover, s | false vs truth | false vs mean |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for lv, rows in (default_rows or {}).items():
        for x in rows:
            print(f"| {lv * 100:.0f}% | {x['parameter']} | {x['flag_time_median']:.2f} | {x['cover_time']:.2f} "
                  f"({x['cover_time_strict']:.2f}) | {x['flag_minus_cover']:+.2f} | "
                  f"{100 * x['false_convergence']:.0f}% | {100 * x['false_vs_mean']:.0f}% |")


if __name__ == "__main__":
    main()
