"""Issue 14 validation (run: PYTHONPATH=$PWD python validation/integration/table3_lags.py 250 OUT.json;
the a posteriori variant: residual="a_posteriori" in the three banks, W0S = ()): Table 3 Monte
Carlo, corrected SE / observed scatter for auto (cap 50),
50 lags and all lags (the package's banks), plus a burn-in prototype for Eq. 17 (residuals of
the first W0 samples after initialization left out of R), evaluated with batch_estimate on the
recursive residual history."""

import json
import sys
import time

import numpy as np

from rls_uncertainty.estimator import EstimatorBank, batch_estimate
from rls_uncertainty.estimator.lag_selection import flat_top_lags
from rls_uncertainty.montecarlo import _WHERE, LEVELS, PARAMETERS, T2_MODELS, level_inputs, parameter_cells

RUNS = int(sys.argv[1]) if len(sys.argv) > 1 else 250
W0S = (25, 50)
out = {}
for level in LEVELS:
    t0 = time.time()
    t, reductions, sizes, X, Z = level_inputs(level, RUNS)
    N = t.size
    nm = len(T2_MODELS)
    banks = {"auto": EstimatorBank(sizes, "auto"), "50": EstimatorBank(sizes, 50), "all": EstimatorBank(sizes, None)}
    for k in range(N):
        for b in banks.values():
            b.update(X[k], Z[k])
    ri, ci = parameter_cells(RUNS)
    theta = banks["50"].theta_all()[ri, ci]
    scatter = theta.std(axis=0, ddof=1)
    res = {"scatter": scatter.tolist()}
    for name, b in banks.items():
        res[name] = (b.standard_errors_all()[ri, ci].mean(axis=0) / scatter).tolist()
    res["conventional"] = (banks["50"].standard_errors_all("conventional")[ri, ci].mean(axis=0) / scatter).tolist()
    L = banks["auto"].lags_used.reshape(RUNS, nm)
    res["lags_q"] = np.percentile(L, [0, 10, 50, 90, 100], axis=0).tolist()
    res["at_cap"] = (L == 50).mean(axis=0).tolist()
    # burn-in prototype: R from residuals after k0 + W0 (both partners), normalised by N - k0 - W0
    allb = banks["all"]
    for W0 in W0S:
        se = {"auto": np.zeros((RUNS, 5)), "50": np.zeros((RUNS, 5))}
        Lb = np.zeros((RUNS, nm), dtype=int)
        for r, data in enumerate(reductions):
            per = {"auto": [], "50": []}
            for m, model in enumerate(T2_MODELS):
                j = r * nm + m
                Xm, zm = data[model.output]
                v = allb.residuals(j).copy()
                start = int(allb.ready_at[j]) + W0
                v[:start] = 0.0
                n = N - start
                R = np.array([v[i:] @ v[: N - i] for i in range(51)]) / n
                Lb[r, m] = flat_top_lags(R, n, cap=50)
                for key, lags in (("auto", int(Lb[r, m])), ("50", 50)):
                    cov = batch_estimate(Xm, zm, lags, residuals=v)[2] * (N / n)
                    per[key].append(np.sqrt(np.maximum(np.diag(cov), 0.0)))
            for key in per:
                se[key][r] = [per[key][_WHERE[p][0]][_WHERE[p][1]] for p in PARAMETERS]
        for key in se:
            res[f"{key}_burn{W0}"] = (se[key].mean(axis=0) / scatter).tolist()
        res[f"lags_burn{W0}_q"] = np.percentile(Lb, [0, 10, 50, 90, 100], axis=0).tolist()
    out[level] = res
    print(f"level {level}: {time.time() - t0:.0f} s", flush=True)
    with open(sys.argv[2] if len(sys.argv) > 2 else f"table3_lags_{RUNS}.json", "w") as fh:
        json.dump(out, fh, indent=1)
