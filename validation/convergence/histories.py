"""Scratch: per-sample theta / corrected SE histories of every run of the Table 3 Monte Carlo
(50 lags), saved to an npz per level for offline tuning of the convergence criterion.

    PYTHONPATH=$PWD python validation/convergence/histories.py --runs 100 --seed 7 --out /tmp/hist
"""
import argparse
import time
from pathlib import Path

import numpy as np

from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.montecarlo import LEVELS, level_inputs

ap = argparse.ArgumentParser()
ap.add_argument("--runs", type=int, default=100)
ap.add_argument("--seed", type=int, default=7)
ap.add_argument("--levels", type=float, nargs="+", default=[x * 100 for x in LEVELS])
ap.add_argument("--out", default="/tmp/conv_hist")
a = ap.parse_args()
out = Path(a.out)
out.mkdir(parents=True, exist_ok=True)
for lv in a.levels:
    t0 = time.perf_counter()
    t, _, sizes, X, Z = level_inputs(lv / 100, a.runs, seed=a.seed)
    bank = EstimatorBank(sizes, 50)
    N, M, n = X.shape
    th = np.full((N, M, n), np.nan)
    se = np.full((N, M, n), np.nan)
    for k in range(N):
        bank.update(X[k], Z[k])
        th[k] = bank.theta_all()
        se[k] = bank.standard_errors_all("corrected")
    np.savez(out / f"level{int(lv):02d}.npz", t=t, theta=th, se=se)
    print(lv, time.perf_counter() - t0, flush=True)
