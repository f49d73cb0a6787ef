"""Issue 12 item 7, before/after (run: PYTHONPATH=$PWD python validation/integration/forgetting_before_after.py
0.95,0.98,0.99,0.995 white,ar1_rho0.8,ar1_tau10).

Part A before/after: in-package EstimatorBank, own residuals (noise_forgetting=f) vs default
noise model. Test regressors (bias + 2 multisines), 48 runs, 12 checkpoints after 12/(1-f) and 3/(1-f_R)."""

import sys

import numpy as np

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[2] / "test"))
import test_estimator_forgetting as T

from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.estimator.options import default_noise_forgetting

THETA = T.THETA


def noise(rng, kind, runs, n):
    e = rng.standard_normal((runs, n + 200))
    if kind == "white":
        return e[:, 200:], np.r_[1.0, np.zeros(400)]
    rho = {"ar1_tau5": np.exp(-1 / 5), "ar1_tau10": np.exp(-1 / 10), "ar1_rho0.8": 0.8}[kind]
    v = np.empty_like(e)
    v[:, 0] = e[:, 0] / np.sqrt(1 - rho**2)
    for k in range(1, e.shape[1]):
        v[:, k] = rho * v[:, k - 1] + e[:, k]
    return v[:, 200:], rho ** np.arange(401) / (1 - rho**2)


def exact_se(X, k, f, gam):
    W = min(k, int(35 / (1 - f)))
    Xk = X[k - W : k]
    u = Xk * (f ** np.arange(W - 1, -1, -1.0))[:, None]
    D = np.linalg.inv(Xk.T @ u)
    mid = u.T @ u * gam[0]
    for i in range(1, min(len(gam), W)):
        P = u[i:].T @ u[:-i] * gam[i]
        mid += P + P.T
    return np.sqrt(np.diag(D @ mid @ D))


def run(f, kind, runs=48, seed=1):
    fR = default_noise_forgetting(f, 50)
    start = int(max(12 / (1 - f), 3 / (1 - fR)))
    step = int(max(2.5 / (1 - f), 250))
    checks = start + step * np.arange(12)
    N = int(checks[-1])
    rng = np.random.default_rng(seed)
    X = T.regressors(N)
    e, gam = noise(rng, kind, runs, N)
    Z = (X @ THETA)[None, :] + e
    banks = {
        "own": EstimatorBank([3] * runs, 50, forgetting=f, noise_forgetting=f),
        "fix": EstimatorBank([3] * runs, 50, forgetting=f),
    }
    Xb = np.ascontiguousarray(np.broadcast_to(X[:, None, :], (N, runs, 3)))
    res = {name: ([], []) for name in banks}
    ex = []
    cs = set(checks.tolist())
    for k in range(N):
        z = np.ascontiguousarray(Z[:, k])
        for b in banks.values():
            b.update(Xb[k], z)
        if k + 1 in cs:
            ex.append(exact_se(X, k + 1, f, gam))
            for name, b in banks.items():
                res[name][0].append(b.theta_all() - THETA)
                res[name][1].append(b.standard_errors_all())
    ex = np.array(ex)
    out = {}
    for name, (err_list, se_list) in res.items():
        err, se = np.array(err_list), np.array(se_list)
        out[name] = dict(
            ratio=np.mean(se / ex[:, None], axis=(0, 1)).round(2).tolist(),
            cov=(100 * np.mean(np.abs(err) < 2 * se, axis=(0, 1))).round(0).tolist(),
            mc=np.sqrt(np.mean((err / ex[:, None]) ** 2, axis=(0, 1))).round(2).tolist(),
        )
    return out


if __name__ == "__main__":
    rows = []
    for f in [float(a) for a in sys.argv[1].split(",")]:
        for kind in sys.argv[2].split(","):
            o = run(f, kind)

            def fmt(d):
                return "/".join(f"{x:.2f}" for x in d["ratio"]) + " (" + "/".join(f"{x:.0f}" for x in d["cov"]) + ")"

            line = (
                f"| {f} | {kind} | {fmt(o['own'])} | {fmt(o['fix'])} | "
                + "/".join(f"{x:.2f}" for x in o["fix"]["mc"])
                + " |"
            )
            print(line, flush=True)
