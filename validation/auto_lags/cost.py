"""Cost of ``n_lags="auto"`` in the estimator benchmark's terms (issue 14).

The six models of Eq. 2 on ``benchmarks/estimator_benchmark.py``'s synthetic maneuver. For a
cap ``C`` the bank must keep the lag sums and lag products of every lag up to ``C`` (``L`` can
grow at any sample), so its update costs what ``n_lags=C`` costs today. On top of that, at
each published covariance: the rule (:func:`select_lags` on ``R_k(0..C)``, ``O(M C)``) and
Eq. 22 with the chosen ``L`` (no dearer than with ``C`` lags). Medians of per-sample times;
each figure is the smallest of three interleaved repetitions (the machine is shared).

Run: PYTHONPATH=$PWD .venv/bin/python validation/auto_lags/cost.py
"""

from __future__ import annotations

import gc
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from estimator_benchmark import SIZES, maneuver, per_sample  # noqa: E402

from rls_uncertainty.estimator import EstimatorBank  # noqa: E402
from rls_uncertainty.lag_selection import select_lags  # noqa: E402


def rule_cost(cap: int, n: int = 3000, warm: int = 300) -> float:
    """Median time of one rule evaluation for the six models (R from the bank's lag sums)."""
    X, z = maneuver(n)
    bank = EstimatorBank(SIZES, cap)
    for k in range(warm):
        bank.update(X[k], z[k])
    times = []
    gc.disable()
    for k in range(warm, n):
        bank.update(X[k], z[k])
        t0 = time.perf_counter()
        R = bank._S[:, : bank.n_window] / bank.n_eff
        select_lags(R, bank.k, "flat_top", cap=cap)
        times.append(time.perf_counter() - t0)
    gc.enable()
    return float(np.median(times) * 1e6)


def main(repeats: int = 3) -> None:
    caps = (50, 100, 200)
    best: dict[int, list[float]] = {cap: [np.inf] * 4 for cap in caps}
    for _ in range(repeats):
        for cap in caps:
            upd, full, p99 = per_sample(cap)
            rule = rule_cost(cap)
            best[cap] = [min(a, b) for a, b in zip(best[cap], (upd, full, p99, rule), strict=True)]
    print("cap | update us | update + outputs us | p99 us | rule us | state kB")
    for cap in caps:
        bank = EstimatorBank(SIZES, cap)
        X, z = maneuver(cap + 10)
        for k in range(cap + 10):
            bank.update(X[k], z[k])
        kb = sum(a.nbytes for a in bank.state()["arrays"].values()) / 1024
        upd, full, p99, rule = best[cap]
        print(f"{cap} | {upd:.1f} | {full:.1f} | {p99:.1f} | {rule:.1f} | {kb:.0f}")


if __name__ == "__main__":
    main()
