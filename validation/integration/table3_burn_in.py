"""Residual burn-in in the package (run: PYTHONPATH=$PWD python validation/integration/table3_burn_in.py
250 validation/integration/table3_burn_in_250.json): the Table 3 Monte Carlo of table3_lags.py,
corrected SE / observed scatter at the end of the maneuver, with every bank an EstimatorBank:

* "auto": n_lags="auto" (max_lags 50) with its default residual_burn_in (50 samples);
* "50", "all": 50 lags and all lags with their default, burn-in 0 (the paper's Eq. 17;
  bit-identical to the "50" and "all" banks of table3_lags.py);
* "50_burn50": 50 lags with residual_burn_in=50.

Also the conventional SE of "auto" (its R(0) is the burned one) and of "50" (the paper's), the
chosen lags of "auto" (percentiles over runs, fraction at the cap) and each model's
initialization sample. The burn-in prototype of table3_lags.py (batch formula on the "all"
bank's residual history) gave the same definition; its numbers are in table3_lags_250.json."""

import json
import sys
import time

import numpy as np

from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.montecarlo import LEVELS, T2_MODELS, level_inputs, parameter_cells

RUNS = int(sys.argv[1]) if len(sys.argv) > 1 else 250
OUT = sys.argv[2] if len(sys.argv) > 2 else f"table3_burn_in_{RUNS}.json"
out = {}
for level in LEVELS:
    t0 = time.time()
    t, _reductions, sizes, X, Z = level_inputs(level, RUNS)
    N = t.size
    nm = len(T2_MODELS)
    banks = {
        "auto": EstimatorBank(sizes, "auto"),
        "50": EstimatorBank(sizes, 50),
        "all": EstimatorBank(sizes, None),
        "50_burn50": EstimatorBank(sizes, 50, residual_burn_in=50),
    }
    assert [b.residual_burn_in for b in banks.values()] == [50, 0, 0, 50]
    for k in range(N):
        for b in banks.values():
            b.update(X[k], Z[k])
    ri, ci = parameter_cells(RUNS)
    theta = banks["50"].theta_all()[ri, ci]
    scatter = theta.std(axis=0, ddof=1)
    res = {"N": N, "scatter": scatter.tolist()}
    for name, b in banks.items():
        assert np.array_equal(b.theta_all()[ri, ci], theta)  # the lags and burn-in change the SE only
        res[name] = (b.standard_errors_all()[ri, ci].mean(axis=0) / scatter).tolist()
    for name in ("auto", "50"):
        res[f"{name}_conventional"] = (
            banks[name].standard_errors_all("conventional")[ri, ci].mean(axis=0) / scatter
        ).tolist()
    L = banks["auto"].lags_used.reshape(RUNS, nm)
    res["lags_q"] = np.percentile(L, [0, 10, 50, 90, 100], axis=0).tolist()
    res["at_cap"] = (L == 50).mean(axis=0).tolist()
    ready_at = banks["auto"].ready_at.reshape(RUNS, nm)
    res["ready_at_range"] = [ready_at.min(axis=0).tolist(), ready_at.max(axis=0).tolist()]
    out[str(level)] = res
    print(f"level {level}: {time.time() - t0:.0f} s", flush=True)
    with open(OUT, "w") as fh:
        json.dump(out, fh, indent=1)
