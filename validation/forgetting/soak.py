"""The issue's soak, as one long run: forgetting 0.98, 50 lags, T-2-kind regressors repeating
every 500 samples, four models with different colored noises in one bank, corrected standard
errors of the current bank and of the prototype fix at every 250th sample.

The true sampling std at a checkpoint depends only on the regressor phase (two phases here),
and is computed exactly (``D X'W Sigma W X D``); the time average over the soak checks it.

Run: ``PYTHONPATH=$PWD python validation/forgetting/soak.py [n_samples]`` (200 000 samples by
default, about three minutes; the issue's million samples give the same numbers with
narrower confidence intervals).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from prototype import HonestForgettingBank
from study import (
    RESULTS,
    THETA,
    exact_covariance,
    make_noise,
    t2_regressors,
    true_autocovariance,
)

NOISES = ("ar5", "ar10", "bl2", "bl1")


def soak(n_samples: int = 300_000, f: float = 0.98, n_lags: int = 50, seed: int = 1_000_000) -> dict:
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    X = t2_regressors(n_samples)
    sigma = 0.02
    eps = np.vstack([make_noise(nz, 1, n_samples, rng) for nz in NOISES]) * sigma
    Z = (X @ THETA)[None, :] + eps
    m = len(NOISES)
    hb = HonestForgettingBank([3] * m, n_lags, forgetting=f)
    warm = 10_000
    truth = {}
    Xt = t2_regressors(21_000)
    for phase in (0, 250):
        k = 20_000 + phase  # any k >> 1/(1-f) with this phase (regressors repeat every 500)
        truth[phase] = np.array([np.sqrt(np.diag(exact_covariance(Xt, f, sigma**2 * true_autocovariance(nz), k)))
                                 for nz in NOISES])
    err, se_cur, se_fix, true = [], [], [], []
    Xb = np.empty((m, 3))
    for k in range(n_samples):
        Xb[:] = X[k]
        hb.update(Xb, Z[:, k].copy())
        kk = k + 1
        if kk >= warm and kk % 250 == 0:
            err.append(hb.theta_all() - THETA)
            se_cur.append(hb.bank.standard_errors_all())
            se_fix.append(hb.standard_errors_all())
            true.append(truth[kk % 500])
    err, se_cur, se_fix, true = map(np.array, (err, se_cur, se_fix, true))
    out = {"n_samples": n_samples, "f": f, "n_lags": n_lags, "f_R": hb.noise_forgetting,
           "checkpoints": len(err), "noises": {}}
    for i, nz in enumerate(NOISES):
        out["noises"][nz] = {
            "time_std_over_true": (err[:, i].std(axis=0) / true[:, i].mean(axis=0)).tolist(),
            "current_ratio": (se_cur[:, i] / true[:, i]).mean(axis=0).tolist(),
            "current_coverage": (np.abs(err[:, i]) < 2 * se_cur[:, i]).mean(axis=0).tolist(),
            "fix_ratio": (se_fix[:, i] / true[:, i]).mean(axis=0).tolist(),
            "fix_coverage": (np.abs(err[:, i]) < 2 * se_fix[:, i]).mean(axis=0).tolist(),
        }
    out["seconds"] = time.perf_counter() - t0
    return out


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 200_000
    res = soak(n)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "soak.json").write_text(json.dumps(res, indent=1))
    print(f"{res['n_samples']} samples, f={res['f']}, f_R={res['f_R']:.6f}, {res['checkpoints']} checkpoints, "
          f"{res['seconds']:.0f} s")
    print("| noise | time std / exact | current SE/true (coverage %) | fix SE/true (coverage %) |")
    print("| --- | --- | --- | --- |")
    for nz, r in res["noises"].items():
        def cell(a, c):
            return "/".join(f"{x:.2f}" for x in a) + " (" + "/".join(f"{100 * x:.0f}" for x in c) + ")"
        print(f"| {nz} | {'/'.join(f'{x:.2f}' for x in r['time_std_over_true'])} | "
              f"{cell(r['current_ratio'], r['current_coverage'])} | {cell(r['fix_ratio'], r['fix_coverage'])} |")
