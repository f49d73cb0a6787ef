"""Table 3 with the band-limited noise on all four measured signals (the default) or on the
measured responses only (alpha, q, a_z; not the measured elevator). Report: REPORT.md beside
this file.

The paper's Section IV.A Monte Carlo with the seeds and settings of ``rls-uncertainty
montecarlo`` (seed 2016, generator ``[seed, level in per mille, run]``, the 5-point
differentiator ``PAPER_DIFFERENTIATOR``, 50 lags): both variants draw the same random numbers
(``simulation.add_noise``), so they differ only by the band-limited noise on the elevator.
Every run's C_Z and C_m models go through one bank per variant and level; at the end of the
maneuver the mean estimate, the mean conventional and corrected standard errors and the
observed scatter (standard deviation of the final estimates) over the runs are compared with
Table 3. The distance of a variant from the paper: the RMS over the 25 means (5 parameters x 5
levels) of (our mean - the paper's mean) / the paper's observed scatter (the braces of Table
3, the same level and parameter).

    .venv/bin/python docs/studies/table3_noise_variant/study.py                # 250 runs per level
    .venv/bin/python docs/studies/table3_noise_variant/study.py --quick        # 20 runs, 0 % and 20 %
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Collection
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.estimator.options import EstimatorOptions
from rls_uncertainty.simulation.montecarlo import (
    LEVELS,
    PAPER_DIFFERENTIATOR,
    PAPER_TABLE3,
    PARAMETERS,
    level_inputs,
    parameter_cells,
)
from rls_uncertainty.simulation.t2 import (
    RESPONSES,
    SIGNALS,
    T2_MODELS,
    T2_TRUE,
    add_noise,
    reduce_short_period,
    simulate_short_period,
)

SEED = 2016  # montecarlo's
VARIANTS: dict[str, Collection[str]] = {"all four signals": SIGNALS, "responses only (default)": RESPONSES}
COLUMNS = ("mean", "se_conventional", "se_corrected", "scatter")  # PAPER_TABLE3's tuple order


def inputs(level: float, runs: int, band_limited_on: Collection[str]) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Model sizes, regressors (N, 2 runs, 4) and outputs (N, 2 runs) of every run, built as
    ``montecarlo.level_inputs`` builds them, with the variant's noise."""
    clean = simulate_short_period()
    data = []
    for run in range(runs):
        rng = np.random.default_rng([SEED, int(round(level * 1000)), run])
        noisy = add_noise(clean, level, rng, band_limited_on=band_limited_on)
        data.append(reduce_short_period(noisy, PAPER_DIFFERENTIATOR)[1])
    N = data[0]["CZ"][1].size
    n = len(T2_MODELS)
    X = np.zeros((N, n * runs, max(len(m.regressors) for m in T2_MODELS)))
    Z = np.zeros((N, n * runs))
    for r, d in enumerate(data):
        for m, model in enumerate(T2_MODELS):
            Xm, zm = d[model.output]
            X[:, r * n + m, : Xm.shape[1]], Z[:, r * n + m] = Xm, zm
    return [len(m.regressors) for m in T2_MODELS] * runs, X, Z


def level_table(level: float, runs: int, variant: str) -> np.ndarray:
    """(5 parameters, 4 columns): mean estimate, mean conventional SE, mean corrected SE
    (50 lags) and scatter at the end of the maneuver."""
    sizes, X, Z = inputs(level, runs, VARIANTS[variant])
    bank = EstimatorBank(sizes, EstimatorOptions(lags=50))
    for k in range(X.shape[0]):
        bank.update(X[k], Z[k])
    rows, cols = parameter_cells(runs)
    theta = bank.theta_all()[rows, cols]
    conventional = bank.standard_errors_all("conventional")[rows, cols]
    corrected = bank.standard_errors_all("corrected")[rows, cols]
    return np.column_stack([theta.mean(axis=0), conventional.mean(axis=0), corrected.mean(axis=0),
                            theta.std(axis=0, ddof=1)])


def check_default_is_the_monte_carlo(runs: int = 3) -> None:
    """Each variant's inputs are ``montecarlo.level_inputs``' with that variant exactly, and
    the default's are its default's."""
    for level in (0.0, 0.2):
        for name, on in VARIANTS.items():
            _t, _red, sizes, X, Z = level_inputs(level, runs, seed=SEED, band_limited_on=on)
            if name.endswith("(default)"):
                _t, _red, _s, X_default, _z = level_inputs(level, runs, seed=SEED)
                if not np.array_equal(X, X_default):
                    sys.exit(f"the default variant is not montecarlo's default at {level:.0%}")
            mine = inputs(level, runs, on)
            if mine[0] != sizes or not (np.array_equal(mine[1], X) and np.array_equal(mine[2], Z)):
                sys.exit(f"the {name} inputs differ from montecarlo.level_inputs at {level:.0%}")


def distance(tables: dict[float, np.ndarray], levels: Collection[float]) -> tuple[float, np.ndarray]:
    """RMS over levels and parameters of (mean - paper's mean) / paper's scatter, and the
    per-cell values (levels, 5)."""
    d = np.array([[(tables[lv][i, 0] - PAPER_TABLE3[lv][p][0]) / PAPER_TABLE3[lv][p][3]
                   for i, p in enumerate(PARAMETERS)] for lv in levels])
    return float(np.sqrt(np.mean(d**2))), d


def _span(levels: tuple[float, ...]) -> str:
    lo, hi = min(levels) * 100, max(levels) * 100
    return f"{hi:.0f} %" if lo == hi else f"{lo:.0f}-{hi:.0f} %"


def report(results: dict[str, dict[float, np.ndarray]], levels: tuple[float, ...], runs: int) -> None:
    names = list(VARIANTS)
    print(f"## Means and standard errors, {runs} runs per level (ours: {' / '.join(names)}; then the paper)\n")
    print("| level | parameter | true | mean | SE conventional | SE corrected (50 lags) | scatter | "
          "(mean - paper) / paper's scatter |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for lv in levels:
        for i, p in enumerate(PARAMETERS):
            paper = PAPER_TABLE3[lv][p]
            cells = [" / ".join(f"{results[n][lv][i, c]:.3f}" for n in names) + f" / {paper[c]:.3f}"
                     for c in range(len(COLUMNS))]
            dev = " / ".join(f"{(results[n][lv][i, 0] - paper[0]) / paper[3]:+.2f}" for n in names)
            print(f"| {lv * 100:.0f}% | {p} | {T2_TRUE[p]:g} | " + " | ".join(cells) + f" | {dev} |")
    print("\n## Distance from Table 3: RMS of (mean - paper's mean) / paper's scatter\n")
    subsets = {_span(levels): levels}
    noisy = tuple(lv for lv in levels if lv > 0)
    if noisy and len(noisy) < len(levels):
        subsets[_span(noisy)] = noisy
    print("| variant | " + " | ".join(f"{k} ({len(v) * len(PARAMETERS)} means)" for k, v in subsets.items())
          + " | " + " | ".join(PARAMETERS) + " (all levels) |")
    print("| --- |" + " --- |" * (len(subsets) + len(PARAMETERS)))
    for n in names:
        rms = [distance(results[n], lv)[0] for lv in subsets.values()]
        d = distance(results[n], levels)[1]
        per = np.sqrt(np.mean(d**2, axis=0))
        print(f"| {n} | " + " | ".join(f"{x:.2f}" for x in rms) + " | " + " | ".join(f"{x:.2f}" for x in per) + " |")
    print(f"\nsampling error of a mean from {runs} runs: its scatter / sqrt({runs}), {1 / np.sqrt(runs):.2f} "
          "of the unit above where our scatter equals the paper's")
    print("\n## Standard errors and scatter against Table 3: RMS of (ours / paper - 1), percent\n")
    print("| variant | levels | " + " | ".join(COLUMNS[1:]) + " | C_m only: " + " | ".join(COLUMNS[1:]) + " |")
    print("| --- | --- |" + " --- |" * 2 * (len(COLUMNS) - 1))
    cm = [i for i, p in enumerate(PARAMETERS) if p.startswith("Cm")]
    for n in names:
        for label, lvs in subsets.items():
            rel = np.array([[results[n][lv][i, 1:] / PAPER_TABLE3[lv][p][1:] - 1 for i, p in enumerate(PARAMETERS)]
                            for lv in lvs])  # (levels, parameters, 3)
            every = np.sqrt(np.mean(rel**2, axis=(0, 1))) * 100
            only_cm = np.sqrt(np.mean(rel[:, cm] ** 2, axis=(0, 1))) * 100
            print(f"| {n} | {label} | " + " | ".join(f"{x:.0f}" for x in every) + " | "
                  + " | ".join(f"{x:.0f}" for x in only_cm) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="20 runs at 0 %% and 20 %%")
    ap.add_argument("--runs", type=int, default=250, help="runs per noise level (default 250)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    args = ap.parse_args()
    levels, runs = ((0.0, 0.2), 20) if args.quick else (LEVELS, args.runs)
    check_default_is_the_monte_carlo()
    t0 = time.perf_counter()
    tasks = [(lv, runs, n) for n in VARIANTS for lv in levels]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        tables = list(pool.map(level_table, *zip(*tasks, strict=True)))
    results: dict[str, dict[float, np.ndarray]] = {n: {} for n in VARIANTS}
    for (lv, _runs, n), table in zip(tasks, tables, strict=True):
        results[n][lv] = table
    print(f"{len(tasks)} variant-levels of {runs} runs: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    report(results, levels, runs)


if __name__ == "__main__":
    main()
