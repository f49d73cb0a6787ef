"""Speed and memory of the recursive estimator.

Prints, in one run on this machine:
  1. per-sample time for the six models of Eq. 2 (3, 4, 3, 6, 4, 4 parameters) at
     lags = 0, 11, 50, 200 and all: the update alone (Eqs. 15-17, 21) and the update plus
     every output a node publishes (estimates, corrected and conventional standard errors);
  2. for lags = 50, the cost around k = 1e3, 1e4 and 1e5 (must stay flat) and the memory;
  2b. forgetting f = 0.98 at 50 lags: the estimator's own residuals (noise_forgetting = f)
     against the default noise model (f_R = 0.99951; docs/estimator.md);
  2c. lags = "auto" (max_lags 50, the lags chosen at every sample) beside lags = 50;
  2d. the lag window follows time (estimator.lag_span 1 s): 50 lags at 50 Hz, 200 at 200 Hz,
     1000 at 1 kHz: per-sample time, CPU share of one core at that rate, and state memory;
  3. the ratio against refitting batch OLS with a HAC covariance (statsmodels, uniform kernel,
     maxlags 50) at every sample of a 600-sample maneuver, six models;
  4. recursive instrumental variables (algorithm "iv") against the least squares per sample,
     six models, 50 lags, one maneuver (the two banks alternate sample by sample).

Run: .venv/bin/python benchmarks/estimator_benchmark.py
"""

from __future__ import annotations

import gc
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions

SIZES = (3, 4, 3, 6, 4, 4)
RATE = 50.0


def maneuver(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Smooth multisine-like regressors and colored outputs for the six models."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    X = np.zeros((n, len(SIZES), max(SIZES)))
    for j, s in enumerate(SIZES):
        X[:, j, 0] = 1.0
        for c in range(1, s):
            f = 0.2 + 0.17 * c + 0.05 * j
            X[:, j, c] = np.sin(2 * np.pi * f * t + c + j) + 0.02 * rng.standard_normal(n)
    noise = np.zeros((n, len(SIZES)))
    e = rng.standard_normal((n, len(SIZES)))
    for k in range(1, n):
        noise[k] = 0.9 * noise[k - 1] + e[k]
    z = np.einsum("kjc,jc->kj", X, rng.standard_normal((len(SIZES), max(SIZES)))) + 0.01 * noise
    return X, z


def outputs(bank: EstimatorBank) -> None:
    bank.theta_all()
    bank.standard_errors_all("corrected")
    bank.standard_errors_all("conventional")


def per_sample(lags, n: int = 3000, warm: int = 300, **options) -> tuple[float, float, float]:
    X, z = maneuver(n)
    bank = EstimatorBank(SIZES, EstimatorOptions(lags=lags, **options))
    for k in range(warm):
        bank.update(X[k], z[k])
    t_upd, t_all = [], []
    gc.disable()
    for k in range(warm, n):
        t0 = time.perf_counter()
        bank.update(X[k], z[k])
        t1 = time.perf_counter()
        outputs(bank)
        t2 = time.perf_counter()
        t_upd.append(t1 - t0)
        t_all.append(t2 - t0)
    gc.enable()
    return float(np.median(t_upd) * 1e6), float(np.median(t_all) * 1e6), float(np.percentile(t_all, 99) * 1e6)


def iv_ratio(n: int = 3000, warm: int = 300) -> tuple[float, float, float, float]:
    """Median microseconds per sample of the least squares and of instrumental variables (the
    regressors one sample earlier as instruments), update and update + outputs, the banks
    alternating sample by sample on one maneuver: ``(rls update, rls total, iv update, iv total)``."""
    X, z = maneuver(n)
    Z = np.roll(X, 1, axis=0)
    banks = (EstimatorBank(SIZES, EstimatorOptions(lags=50)),
             EstimatorBank(SIZES, EstimatorOptions(lags=50, algorithm="iv")))
    times = np.zeros((2, 2, n - warm))
    gc.disable()
    for k in range(n):
        for b, bank in enumerate(banks):
            t0 = time.perf_counter()
            if b:
                bank.update(X[k], z[k], Z[k])
            else:
                bank.update(X[k], z[k])
            t1 = time.perf_counter()
            outputs(bank)
            t2 = time.perf_counter()
            if k >= warm:
                times[b, :, k - warm] = (t1 - t0, t2 - t0)
    gc.enable()
    rls_upd, rls_all, iv_upd, iv_all = (float(np.median(t) * 1e6) for t in times.reshape(4, -1))
    return rls_upd, rls_all, iv_upd, iv_all


def _filled(lags: int) -> EstimatorBank:
    """A bank of ``lags`` lags that holds all of them (its state at full size)."""
    X, z = maneuver(lags + 100)
    bank = EstimatorBank(SIZES, EstimatorOptions(lags=lags))
    for k in range(lags + 100):
        bank.update(X[k], z[k])
    return bank


def flat_cost(lags: int = 50, total: int = 100_000) -> list[tuple[int, float]]:
    X, z = maneuver(2000)
    bank = EstimatorBank(SIZES, EstimatorOptions(lags=lags))
    marks = {1_000, 10_000, 100_000}
    out = []
    times = []
    gc.disable()
    for k in range(1, total + 1):
        i = k % 2000
        t0 = time.perf_counter()
        bank.update(X[i], z[i])
        outputs(bank)
        times.append(time.perf_counter() - t0)
        if k in marks:
            out.append((k, float(np.median(times[-500:]) * 1e6)))
    gc.enable()
    state_bytes = sum(a.nbytes for a in bank.state()["arrays"].values())
    return out, state_bytes


def hac_ratio(n: int = 600, maxlags: int = 50) -> tuple[float, float]:
    import statsmodels.api as sm  # benchmark-only dependency

    X, z = maneuver(n)
    t0 = time.perf_counter()
    bank = EstimatorBank(SIZES, EstimatorOptions(lags=maxlags))
    for k in range(n):
        bank.update(X[k], z[k])
        if bank.ready.all():
            outputs(bank)
    t_rls = time.perf_counter() - t0
    t0 = time.perf_counter()
    for k in range(1, n + 1):
        for j, s in enumerate(SIZES):
            if k <= s + 1:
                continue
            fit = sm.OLS(z[:k, j], X[:k, j, :s]).fit(
                cov_type="HAC", cov_kwds={"maxlags": min(maxlags, k - 1), "kernel": "uniform"}
            )
            fit.bse  # noqa: B018 - force the covariance
    t_hac = time.perf_counter() - t0
    return t_rls, t_hac


def main() -> None:
    print(f"rls_uncertainty estimator benchmark  (numpy {np.__version__}, {os.cpu_count()} cores, "
          f"OPENBLAS_CORETYPE={os.environ.get('OPENBLAS_CORETYPE', '-')})")
    print("\n1. Six models of Eq. 2 (3,4,3,6,4,4 parameters), median microseconds per sample")
    print(f"   {'lags':>8}{'update':>10}{'update+outputs':>17}{'p99':>9}")
    for lags in (0, 11, 50, 200, "all"):
        upd, total, p99 = per_sample(lags)
        print(f"   {lags!s:>8}{upd:10.1f}{total:17.1f}{p99:9.1f}")
    print("   (target: 50 lags, six models, at most 30 us; the paper: ~800 us per sample for two "
          "models in MATLAB)")

    print("\n2. lags = 50: median microseconds per sample (update + outputs) around k")
    marks, state_bytes = flat_cost()
    for k, us in marks:
        print(f"   k = {k:>7,}: {us:6.1f} us")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"   estimator state {state_bytes / 1024:.1f} KiB; process max RSS {rss:.1f} MiB")

    print("\n2b. Forgetting f = 0.98, 50 lags, median microseconds per sample (state KiB)")
    print(f"   {'R_k(i) from':>26}{'update':>10}{'update+outputs':>17}{'p99':>9}{'state':>8}")
    for label, g in (("own residuals (f_R = f)", 0.98), ("noise model (default f_R)", None)):
        upd, total, p99 = per_sample(50, forgetting=0.98, noise_forgetting=g)
        options = EstimatorOptions(lags=50, forgetting=0.98, noise_forgetting=g, p0=1.0)
        kib = sum(a.nbytes for a in EstimatorBank(SIZES, options).state()["arrays"].values()) / 1024
        print(f"   {label:>26}{upd:10.1f}{total:17.1f}{p99:9.1f}{kib:8.1f}")

    print("\n2c. Automatic lags, median microseconds per sample")
    print(f"   {'lags':>26}{'update':>10}{'update+outputs':>17}{'p99':>9}")
    for label, lags in (("50", 50), ("auto (max_lags 50)", "auto")):
        upd, total, p99 = per_sample(lags)
        print(f"   {label:>26}{upd:10.1f}{total:17.1f}{p99:9.1f}")

    print("\n2d. estimator.lag_span 1 s at the estimator rate: median microseconds per sample, share of one core")
    print(f"   {'rate, lags':>14}{'update':>10}{'update+outputs':>17}{'p99':>9}{'core':>8}{'state':>11}")
    for rate in (50, 200, 1000):
        upd, total, p99 = per_sample(rate, n=2 * rate + 1500, warm=rate + 100)
        kib = sum(a.nbytes for a in _filled(rate).state()["arrays"].values()) / 1024
        print(f"   {f'{rate} Hz, {rate}':>14}{upd:10.1f}{total:17.1f}{p99:9.1f}{total * rate / 1e4:7.1f}%"
              f"{kib:8.0f} KiB")

    print("\n3. 600-sample maneuver, six models, 50 lags: recursive vs refitting batch OLS + HAC "
          "(statsmodels, uniform kernel) at every sample")
    t_rls, t_hac = hac_ratio()
    print(f"   recursive {t_rls * 1e3:.1f} ms, batch refits {t_hac * 1e3:.0f} ms: "
          f"{t_hac / t_rls:.0f}x faster")

    print("\n4. Instrumental variables against least squares, six models, 50 lags, one maneuver, median "
          "microseconds per sample")
    rls_upd, rls_all, iv_upd, iv_all = iv_ratio()
    print(f"   {'':>8}{'update':>10}{'update+outputs':>17}")
    print(f"   {'rls':>8}{rls_upd:10.1f}{rls_all:17.1f}")
    print(f"   {'iv':>8}{iv_upd:10.1f}{iv_all:17.1f}")
    print(f"   iv / rls: update {iv_upd / rls_upd:.2f}x, update + outputs {iv_all / rls_all:.2f}x")


if __name__ == "__main__":
    main()
