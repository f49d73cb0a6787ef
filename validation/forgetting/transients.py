"""Where the fix is slow: a step in the noise level and a step in a parameter.

f = 0.98, 50 lags, band-limited 2 Hz noise, T-2-kind regressors, 200 runs. At sample K0 either
(a) the noise standard deviation doubles, or (b) C_Z_alpha changes by 10 %. Printed against
time since the step: mean corrected SE (current bank and the fix) over the true sampling std
of the estimate, and 2-SE coverage of the error (for (b) the error includes the tracking lag,
the part of the error forgetting is there to shrink and no noise covariance describes). Also
the level-adaptive variant: ``R^N(i)`` rescaled by the f-weighted mean square of the noise
model's residuals over ``R^N(0)`` (shape from the noise memory, level from the short one).

Run: ``PYTHONPATH=$PWD python validation/forgetting/transients.py`` (about two minutes).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parent))

from prototype import HonestForgettingBank, NoiseModel, covariance_from_bank
from study import RESULTS, THETA, make_noise, t2_regressors, true_autocovariance

F, LAGS, RUNS, K0 = 0.98, 50, 200, 8000
OFFSETS = (-250, 25, 50, 100, 200, 500, 1000, 2000, 3000, 4000, 6000)


def exact_se_scaled(X, scale, gamma, k, f=F):
    """SE of the f-weighted fit at k when the noise is scale_j * (stationary noise of acf gamma)."""
    W = min(k, int(40 / (1 - f)))
    Xk = X[k - W : k]
    w = f ** np.arange(W - 1, -1, -1.0)
    D = np.linalg.inv(Xk.T @ (Xk * w[:, None]))
    u = Xk * (w * scale[k - W : k])[:, None]
    L = min(len(gamma), W)
    g2 = np.concatenate([gamma[1:L][::-1], gamma[:L]])
    Tu = np.column_stack([signal.fftconvolve(u[:, a], g2)[L - 1 : L - 1 + W] for a in range(3)])
    M = u.T @ Tu
    return np.sqrt(np.diag(D @ (0.5 * (M + M.T)) @ D))


def run(kind: str, seed: int = 77) -> dict:
    rng = np.random.default_rng([seed, len(kind)])
    N = K0 + OFFSETS[-1] + 1
    X = t2_regressors(N)
    sigma = 0.02
    eps = make_noise("bl2", RUNS, N, rng)
    gamma = true_autocovariance("bl2")
    scale = np.full(N, sigma)
    theta_t = np.tile(THETA, (N, 1))
    if kind == "noise_step":
        scale[K0:] *= 2.0
    else:  # bias and C_Z_alpha jump by 4 of their standard errors
        theta_t[K0:, :2] += 4.0 * exact_se_scaled(X, scale, gamma, K0)[:2]
    Z = np.einsum("ka,ka->k", X, theta_t)[None, :] + scale[None, :] * eps
    hb = HonestForgettingBank([3] * RUNS, LAGS, forgetting=F)
    hb.noise = NoiseModel([3] * RUNS, LAGS, hb.noise_forgetting, level_forgetting=F)  # + level variant
    checks = {K0 + o: o for o in OFFSETS}
    rows = []
    Xb = np.empty((RUNS, 3))
    for k in range(N):
        Xb[:] = X[k]
        hb.update(Xb, Z[:, k].copy())
        kk = k + 1
        if kk in checks:
            err = hb.theta_all() - theta_t[k]
            true = exact_se_scaled(X, scale, gamma, kk)
            cur, fix = hb.bank.standard_errors_all(), hb.standard_errors_all()
            cov = covariance_from_bank(hb.bank, hb.noise.autocovariance(level=True))
            lev = np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0))
            rows.append({
                "offset": checks[kk],
                "rms_err_over_true": (np.sqrt((err**2).mean(0)) / true).tolist(),
                "current_ratio": (cur.mean(0) / true).tolist(),
                "fix_ratio": (fix.mean(0) / true).tolist(),
                "current_coverage": (np.abs(err) < 2 * cur).mean(0).tolist(),
                "fix_coverage": (np.abs(err) < 2 * fix).mean(0).tolist(),
                "level_ratio": (lev.mean(0) / true).tolist(),
                "level_coverage": (np.abs(err) < 2 * lev).mean(0).tolist(),
            })
    return {"kind": kind, "f": F, "f_R": hb.noise_forgetting, "K0": K0, "rows": rows}


def table(res: dict) -> list[str]:
    def c(v):
        return "/".join(f"{x:.2f}" for x in v)

    def p(v):
        return "/".join(f"{100 * x:.0f}" for x in v)

    out = [f"{res['kind']} at k = {res['K0']} (f = {res['f']}, f_R = {res['f_R']:.5f})", "",
           "| samples after step | RMS error / true SE | current SE/true (coverage %) | fix SE/true (coverage %) | "
           "level-adaptive fix |",
           "| --- | --- | --- | --- | --- |"]
    for r in res["rows"]:
        out.append(f"| {r['offset']} | {c(r['rms_err_over_true'])} | "
                   f"{c(r['current_ratio'])} ({p(r['current_coverage'])}) | "
                   f"{c(r['fix_ratio'])} ({p(r['fix_coverage'])}) | {c(r['level_ratio'])} ({p(r['level_coverage'])}) |")
    return out


if __name__ == "__main__":
    RESULTS.mkdir(exist_ok=True)
    for kind in ("noise_step", "parameter_step"):
        res = run(kind)
        (RESULTS / f"transient_{kind}.json").write_text(json.dumps(res, indent=1))
        print("\n".join(table(res)) + "\n", flush=True)
