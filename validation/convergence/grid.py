"""Scratch: grid over (window, band, max_se_rate) on saved histories; one summary line each."""
import itertools
import sys

import numpy as np

sys.path.insert(0, "validation/convergence")
from tune import evaluate, load

from rls_uncertainty.convergence import ConvergenceConfig

data = load(sys.argv[1])
grid = (
    [float(x) for x in sys.argv[2].split(",")],
    [float(x) for x in sys.argv[3].split(",")],
    [float(x) for x in sys.argv[4].split(",")],
)
print("T     k     r    | med flag per level (mean over params) | max false(mean) | mean false(mean) "
      "| 20% flag-cover(tol) per param")
for T, k, r in itertools.product(*grid):
    rows = evaluate(data, ConvergenceConfig(window=T, band=k, max_se_rate=r, rate_hz=50.0), verbose=False)
    rows = np.array([(x[0], x[2], x[3], x[4], x[5], x[6], x[7]) for x in rows], dtype=float)
    meds = [rows[rows[:, 0] == lv, 3].mean() for lv in (0, 5, 10, 15, 20)]
    fm = rows[:, 6]
    d20 = rows[rows[:, 0] == 20, 3] - rows[rows[:, 0] == 20, 2]
    print(f"{T:4.1f} {k:4.2f} {r:5.2f} | " + " ".join(f"{m:5.2f}" for m in meds) +
          f" | {np.nanmax(fm):.3f} | {np.nanmean(fm):.3f} | " + " ".join(f"{d:+5.2f}" for d in d20) +
          f" | flagged min {rows[:, 4].min():.2f}", flush=True)
