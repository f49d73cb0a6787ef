"""Corrected standard errors under exponential forgetting: the estimator's own residuals
against the noise model (the default ``noise_forgetting``). Report: REPORT.md beside this file.

Every run shares the same deterministic regressors (a bias and two multisines at 50 Hz), so
the sampling covariance of the f-weighted estimate is known exactly: ``D X'W Sigma W X D``
with the true noise autocovariance ``Sigma`` (the sandwich of Eqs. 8-11 with weights
``W = diag(f^(k-j))``). For each forgetting factor ``f`` and noise, two banks of ``--runs``
models see the same data, both with 50 lags:

* ``own residuals``: ``noise_forgetting = f``, Eq. 17 on the estimator's own residuals;
* ``noise model``: the default ``noise_forgetting`` (a second fit with a longer memory supplies
  ``R(i)``; docs/estimator.md).

At 12 checkpoints after both memories have filled, each parameter's mean corrected SE over
runs is divided by the exact SE and the share of runs with ``|theta_hat - theta| < 2 SE`` is
counted; the last column is the Monte Carlo scatter over the exact SE, a check of the exact
reference itself. Cells list the three parameters: bias / multisine a / multisine b.

    .venv/bin/python docs/studies/noise_model_under_forgetting/study.py           # the report's table
    .venv/bin/python docs/studies/noise_model_under_forgetting/study.py --quick   # f = 0.98, two noises, 16 runs
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.estimator.options import EstimatorOptions

LAGS = 50
THETA = np.array([0.5, -2.0, 1.0])
FORGETTING = (0.95, 0.98, 0.99, 0.995)
# AR(1) coefficient of each noise (0: white). "ar1_tau50" is correlated beyond the 50 lags.
NOISES = {"white": 0.0, "ar1_rho0.8": 0.8, "ar1_tau10": np.exp(-1 / 10), "ar1_tau50": np.exp(-1 / 50)}
CHECKPOINTS = 12
WARM_UP = 200  # samples of noise generated and dropped before the record


def regressors(n: int) -> np.ndarray:
    """A bias and two multisines (0.3-1.7 Hz) sampled at 50 Hz."""
    t = np.arange(n) / 50.0
    a = np.sin(2 * np.pi * 0.3 * t) + 0.6 * np.sin(2 * np.pi * 0.9 * t + 1.0) + 0.4 * np.sin(2 * np.pi * 1.7 * t + 2.0)
    b = np.cos(2 * np.pi * 0.5 * t + 0.3) + 0.5 * np.sin(2 * np.pi * 1.3 * t + 0.7)
    return np.column_stack([np.ones(n), a, b])


def noise(rng: np.random.Generator, rho: float, runs: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Stationary AR(1) noise with unit innovation variance, and its autocovariance
    ``gamma(i) = rho^i / (1 - rho^2)`` up to the lag where it falls below 1e-12."""
    e = rng.standard_normal((runs, n + WARM_UP))
    if rho == 0.0:
        return e[:, WARM_UP:], np.array([1.0])
    v = np.empty_like(e)
    v[:, 0] = e[:, 0] / np.sqrt(1 - rho**2)
    for k in range(1, e.shape[1]):
        v[:, k] = rho * v[:, k - 1] + e[:, k]
    lags = int(np.ceil(np.log(1e-12) / np.log(rho)))
    return v[:, WARM_UP:], rho ** np.arange(lags + 1) / (1 - rho**2)


def exact_se(X: np.ndarray, k: int, f: float, gamma: np.ndarray) -> np.ndarray:
    """Standard errors of the f-weighted least squares of samples 1..k under noise with
    autocovariance ``gamma`` (samples older than ``35 / (1 - f)`` weigh less than 1e-15)."""
    W = min(k, int(35 / (1 - f)))
    Xk = X[k - W : k]
    u = Xk * (f ** np.arange(W - 1, -1, -1.0))[:, None]
    D = np.linalg.inv(Xk.T @ u)
    middle = u.T @ u * gamma[0]
    for i in range(1, min(len(gamma), W)):
        P = u[i:].T @ u[:-i] * gamma[i]
        middle += P + P.T
    return np.sqrt(np.diag(D @ middle @ D))


def run(f: float, rho: float, runs: int, seed: int = 1) -> dict[str, np.ndarray]:
    """Both banks on one forgetting factor and noise: per bank (SE / exact, coverage), and
    the Monte Carlo scatter / exact SE."""
    options = {
        "own": EstimatorOptions(lags=LAGS, forgetting=f, noise_forgetting=f),
        "noise_model": EstimatorOptions(lags=LAGS, forgetting=f),
    }
    f_noise = options["noise_model"].noise_forgetting_used
    start = int(max(12 / (1 - f), 3 / (1 - f_noise)))
    step = int(max(2.5 / (1 - f), 250))
    checks = set((start + step * np.arange(CHECKPOINTS)).tolist())
    N = max(checks)
    rng = np.random.default_rng(seed)
    X = regressors(N)
    e, gamma = noise(rng, rho, runs, N)
    Z = (X @ THETA)[None, :] + e
    banks = {name: EstimatorBank([3] * runs, o) for name, o in options.items()}
    Xb = np.ascontiguousarray(np.broadcast_to(X[:, None, :], (N, runs, 3)))
    err: dict[str, list[np.ndarray]] = {name: [] for name in banks}
    se: dict[str, list[np.ndarray]] = {name: [] for name in banks}
    exact = []
    for k in range(N):
        z = np.ascontiguousarray(Z[:, k])
        for b in banks.values():
            b.update(Xb[k], z)
        if k + 1 in checks:
            exact.append(exact_se(X, k + 1, f, gamma))
            for name, b in banks.items():
                err[name].append(b.theta_all() - THETA)
                se[name].append(b.standard_errors_all("corrected"))
    ex = np.array(exact)[:, None, :]  # (checkpoints, 1, 3)
    out = {}
    for name in banks:
        e_, s_ = np.array(err[name]), np.array(se[name])
        out[name] = np.array([np.mean(s_ / ex, axis=(0, 1)), np.mean(np.abs(e_) < 2 * s_, axis=(0, 1))])
    out["scatter"] = np.sqrt(np.mean((np.array(err["own"]) / ex) ** 2, axis=(0, 1)))
    return out


def cell(ratio_coverage: np.ndarray) -> str:
    ratio, coverage = ratio_coverage
    return "/".join(f"{x:.2f}" for x in ratio) + " (" + "/".join(f"{100 * x:.0f}" for x in coverage) + ")"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="f = 0.98, white and AR(1) rho 0.8 noise, 16 runs")
    ap.add_argument("--runs", type=int, default=48, help="runs per configuration (default 48)")
    args = ap.parse_args()
    forgetting, noises, runs = FORGETTING, list(NOISES), args.runs
    if args.quick:
        forgetting, noises, runs = (0.98,), ["white", "ar1_rho0.8"], 16
    print(f"{runs} runs, {LAGS} lags, {CHECKPOINTS} checkpoints; cells: bias / multisine a / multisine b, "
          "mean corrected SE / exact SE (2-SE coverage %)\n")
    print("| f | noise | own residuals (noise_forgetting = f) | noise model (default) | scatter / exact SE |")
    print("| --- | --- | --- | --- | --- |")
    t0 = time.perf_counter()
    for f in forgetting:
        for name in noises:
            o = run(f, NOISES[name], runs)
            scatter = "/".join(f"{x:.2f}" for x in o["scatter"])
            print(f"| {f} | {name} | {cell(o['own'])} | {cell(o['noise_model'])} | {scatter} |", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
