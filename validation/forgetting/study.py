"""Monte Carlo study of the corrected covariance under exponential forgetting (issue 12 item 7).

Seeded. Constant true parameters, T-2-kind regressors (bias, an angle of attack driven by the
Table 2 elevator multisine through the T-2 short-period dynamics, the elevator itself),
repeated every 10 s so that a long run is a soak; colored equation-error noise of unit
variance (AR(1) with several correlation times, and band-limited noise: white noise through
the paper's fifth-order Chebyshev low-pass). All runs share the regressors (deterministic, as
in the paper), so the exact sampling covariance of the estimate is known:
``cov = D X'W Sigma W X D`` with the true noise autocovariance (``oracle_all``).

Each configuration runs ``runs`` models in one :class:`EstimatorBank` and, beside it, the
streams needed to take the gap apart (all use the bank's own ``D_k`` and ``Lambda_k(i)``):

==================  ==========================================================================
variant             autocovariance used in ``D [sum_i c_i R(i) Lambda(i)] D``
==================  ==========================================================================
``bank``            the bank as it is: its residuals (``residual=`` option), weights ``f``
``oracle_all``      the true ``gamma(i)``, all lags: the exact sampling covariance
``oracle_L``        the true ``gamma(i)``, lags ``0..n_lags`` with the lag window  -> (ii)
``noise_f``         ``R`` of the true noise ``eps`` (no fit), weights ``f``        -> (iii)
``noise_fR``        ``R`` of the true noise, weights ``f_R``                        -> (iii)
``batch_post``      weighted batch residuals ``z - X theta_k`` (a posteriori), weights ``f``
``df``              ``bank`` with ``R`` times ``n_eff / (n_eff - p_eff)``,
                    ``p_eff = tr(D_k Lambda_k(0))``                                 -> (i)
``bankres_fR``      the bank's residuals, weights ``f_R``                            -> (i)
``noisemodel_f``    residuals of the noise model (RLS with ``f_R``), weights ``f``
``fix``             residuals of the noise model, weights ``f_R`` (the proposed fix)
``fix_level``       ``fix`` rescaled by the ``f``-weighted mean square of the noise model's
                    residuals over its ``R(0)`` (level from the short memory; option)
==================  ==========================================================================

Usage (from the worktree root, PYTHONPATH=$PWD)::

    python validation/forgetting/study.py run  --f 0.98 --noise ar5      # one configuration
    python validation/forgetting/study.py grid [--only main|extra]      # all missing ones
    python validation/forgetting/study.py report                         # tables for REPORT.md

Results go to ``validation/forgetting/results/*.json`` (one file per configuration).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parent))

from prototype import (
    LagSums,
    NoiseModel,
    covariance_from_bank,
    default_noise_forgetting,
)

from rls_uncertainty.config import load_aircraft
from rls_uncertainty.estimator import EstimatorBank, lag_weights
from rls_uncertainty.multisine import T2_TABLE2
from rls_uncertainty.simulation import SimulationConfig, _state_space

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
RATE = 50.0
THETA = np.array([-0.2, -3.911, 0.215])  # C_Z model of T-2: bias, C_Z_alpha, C_Z_delta_e
PARAMS = ("bias", "alpha", "delta_e")
FORGETTING = (0.95, 0.98, 0.99, 0.995, 0.999)
NOISES = ("white", "ar2", "ar5", "ar10", "ar20", "bl2", "bl1", "ar50", "bl05")


# ----------------------------------------------------------------------------- data
def t2_regressors(n: int, rate: float = RATE, start: int = 0) -> np.ndarray:
    """``(n, 3)``: 1, alpha (rad), delta_e (rad); the elevator multisine repeats every 10 s and
    alpha is its periodic steady-state response through the T-2 short-period dynamics."""
    cfg = SimulationConfig()
    A, B, C, Dm = _state_space(cfg, load_aircraft("t2"))
    ms = T2_TABLE2["elevator"]
    per = int(round(ms.period * rate))
    Ad, Bd, *_ = signal.cont2discrete((A, B, C, Dm), 1.0 / rate)
    u = ms(np.arange(per) / rate)
    x = np.zeros(2)
    for _ in range(20):  # reach the periodic steady state
        al = np.empty(per)
        for k in range(per):
            al[k] = x[0]
            x = Ad @ x + Bd[:, 0] * u[k]
    idx = (np.arange(n) + start) % per
    return np.column_stack([np.ones(n), al[idx], u[idx]])


def noise_filter(name: str):
    """``(b, a)`` of the noise filter driven by white noise, or None for white noise."""
    if name == "white":
        return None
    if name.startswith("ar"):
        tau = float(name[2:])
        phi = np.exp(-1.0 / tau)
        return np.array([1.0]), np.array([1.0, -phi])
    if name.startswith("bl"):
        hz = {"bl2": 2.0, "bl1": 1.0, "bl05": 0.5}[name]
        return signal.cheby1(5, 0.5, hz, fs=RATE)
    raise ValueError(name)


def true_autocovariance(name: str, n: int = 20000) -> np.ndarray:
    """Autocovariance ``gamma(0..n-1)`` of the unit-variance noise."""
    ba = noise_filter(name)
    if ba is None:
        g = np.zeros(n)
        g[0] = 1.0
        return g
    b, a = ba
    imp = np.zeros(4 * n)
    imp[0] = 1.0
    h = signal.lfilter(b, a, imp)
    full = signal.fftconvolve(h, h[::-1])[len(h) - 1 :][:n]
    return full / full[0]


def make_noise(name: str, runs: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """``(runs, n)`` stationary unit-variance noise."""
    ba = noise_filter(name)
    if ba is None:
        return rng.standard_normal((runs, n))
    b, a = ba
    imp = np.zeros(20000)
    imp[0] = 1.0
    scale = np.sqrt(np.sum(signal.lfilter(b, a, imp) ** 2))
    warm = 3000
    e = rng.standard_normal((runs, n + warm))
    y = signal.lfilter(b, a, e, axis=1)[:, warm:]
    return y / scale


# ----------------------------------------------------------------------------- exact truth
def exact_covariance(X: np.ndarray, f: float, gamma: np.ndarray, k: int) -> np.ndarray:
    """``D X'W Sigma W X D`` of the weighted fit over samples ``1..k`` (weights ``f^(k-j)``)."""
    W = min(k, int(40.0 / (1.0 - f)) if f < 1 else k)
    Xk = X[k - W : k]
    w = f ** np.arange(W - 1, -1, -1.0)
    u = Xk * w[:, None]
    D = np.linalg.inv(Xk.T @ u)
    L = min(len(gamma), W)
    g2 = np.concatenate([gamma[1:L][::-1], gamma[:L]])  # lags -(L-1)..(L-1)
    Tu = np.column_stack([signal.fftconvolve(u[:, a], g2)[L - 1 : L - 1 + W] for a in range(u.shape[1])])
    M = u.T @ Tu
    M = 0.5 * (M + M.T)
    return D @ M @ D


# ----------------------------------------------------------------------------- one configuration
def run_config(
    f: float,
    noise: str,
    *,
    runs: int = 200,
    n_lags: int = 50,
    window: str = "truncated",
    residual: str = "standardized",
    f_R: float | None = None,
    f_R_sweep: tuple = (),
    checkpoints: int | None = None,
    seed: int = 12,
    batch: bool = True,
) -> dict:
    t0 = time.perf_counter()
    f_R = default_noise_forgetting(f, n_lags) if f_R is None else f_R
    mem = 1.0 / (1.0 - f) if f < 1 else 0.0
    mem_R = 1.0 / (1.0 - f_R) if f_R < 1 else 0.0
    warm = int(max(12 * mem, 3 * mem_R, 500))
    spacing = int(max(2.5 * mem, 250))
    C = checkpoints or (20 if f <= 0.99 else 10)
    N = warm + (C - 1) * spacing + 1
    checks = warm + spacing * np.arange(C)
    rng = np.random.default_rng([seed, int(round(f * 1e4)), sum(map(ord, noise)), runs])
    X = t2_regressors(N)
    eps = make_noise(noise, runs, N, rng)
    gamma = true_autocovariance(noise)
    sigma = 0.02  # equation-error standard deviation (C_Z units); ratios do not depend on it
    Z = (X @ THETA)[None, :] + sigma * eps
    n = X.shape[1]

    bank = EstimatorBank([n] * runs, n_lags, window, f, residual=residual)
    noise_models = {fr: NoiseModel([n] * runs, n_lags, fr, level_forgetting=f if fr == f_R else None)
                    for fr in sorted({f_R, *f_R_sweep})}
    sums = {
        "noise_f": LagSums(runs, n_lags, f),
        "noise_fR": LagSums(runs, n_lags, f_R),
        "bankres_fR": LagSums(runs, n_lags, f_R),
        "noisemodel_f": LagSums(runs, n_lags, f),
    }
    for fr in f_R_sweep:
        sums[f"sweep_{fr}"] = noise_models[fr].sums
    Xb = np.empty((runs, n))
    out: dict[str, list] = {}

    def add(key, val):
        out.setdefault(key, []).append(np.asarray(val, dtype=float))

    c = lag_weights(n_lags, window)
    for k in range(N):
        Xb[:] = X[k]
        zk = Z[:, k].copy()
        bank.update(Xb, zk)
        for nm in noise_models.values():
            nm.update(Xb, zk)
        sums["noise_f"].push(sigma * eps[:, k])
        sums["noise_fR"].push(sigma * eps[:, k])
        if bank.ready.all():
            sums["bankres_fR"].push(-bank._vbuf[:, bank._ptr])
        nmain = noise_models[f_R]
        if nmain.ready.all():
            sums["noisemodel_f"].push(nmain.sums.hist[:, 0])
        kk = k + 1
        if kk not in checks:
            continue
        th = bank.theta_all()
        err = th - THETA[None, :]
        true_cov = exact_covariance(X, f, gamma * sigma**2, kk)
        add("true_se", np.sqrt(np.diag(true_cov)))
        add("err", err)

        def se_of(R, kind="corrected"):
            cov = covariance_from_bank(bank, R, kind)
            return np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0))

        add("se_bank", bank.standard_errors_all("corrected"))
        add("se_bank_conv", bank.standard_errors_all("conventional"))
        Rt = np.tile(gamma[: n_lags + 1] * sigma**2, (runs, 1))
        add("se_oracle_L", se_of(Rt))
        add("se_oracle_all", np.tile(np.sqrt(np.diag(true_cov)), (runs, 1)))
        for key in ("noise_f", "noise_fR", "bankres_fR", "noisemodel_f"):
            add(f"se_{key}", se_of(sums[key].autocovariance()))
        add("se_fix", se_of(noise_models[f_R].autocovariance()))
        add("se_fix_conv", se_of(noise_models[f_R].autocovariance(), "conventional"))
        add("se_fix_level", se_of(noise_models[f_R].autocovariance(level=True)))
        for fr in f_R_sweep:
            add(f"se_sweep_{fr}", se_of(noise_models[fr].autocovariance()))
        # (i) degrees of freedom: p_eff = tr(D Lambda(0)), n_eff = sum f^(k-j)
        D = bank._aug[0, :n]
        lam0 = bank._Q[0, :n, 0, :n]  # Lambda(0) = sum f^(2(k-j)) x_j x_j' (one-sided storage)
        p_eff = float(np.trace(D @ lam0))
        add("p_eff", [p_eff])
        add("n_eff", [bank.n_eff])
        Rb = bank._S[:, : bank.n_window] / bank.n_eff
        add("se_df", se_of(Rb * bank.n_eff / (bank.n_eff - p_eff)))
        if batch:
            W = min(kk, int(30 * mem)) if f < 1 else kk
            w = f ** np.arange(W - 1, -1, -1.0)
            v = Z[:, kk - W : kk] - th @ X[kk - W : kk].T  # (runs, W) a posteriori, theta_k
            Rp = np.empty((runs, n_lags + 1))
            for i in range(n_lags + 1):
                Rp[:, i] = (v[:, i:] * v[:, : W - i]) @ w[i:] / w.sum()
            add("se_batch_post", se_of(Rp))
    res = {k: np.array(v).tolist() for k, v in out.items()}
    res["config"] = dict(
        f=f, noise=noise, runs=runs, n_lags=n_lags, window=window, residual=residual, f_R=f_R,
        f_R_sweep=list(f_R_sweep), checkpoints=checks.tolist(), N=N, seed=seed, sigma=sigma,
        lags_share=float(_lag_share(gamma, n_lags, c)),
        seconds=time.perf_counter() - t0,
    )
    return res


def _lag_share(gamma, n_lags, c):
    """Share of the long-run variance ``sum_all gamma`` kept by the lag window."""
    full = gamma[0] + 2 * gamma[1:].sum()
    kept = c[0] * gamma[0] + 2 * np.dot(c[1:], gamma[1 : n_lags + 1])
    return kept / full


# ----------------------------------------------------------------------------- summaries
def summarize(res: dict) -> dict:
    """Per variant and parameter: mean SE / exact SE (averaged over checkpoints), RMS SE /
    exact SE, coefficient of variation of the SE over runs, 2-SE coverage (pooled)."""
    true = np.array(res["true_se"])  # (C, n)
    err = np.array(res["err"])  # (C, runs, n)
    mc = err.std(axis=1, ddof=1)  # (C, n)
    out = {"mc_over_true": (mc / true).mean(axis=0).tolist(), "config": res["config"]}
    out["p_eff"] = float(np.mean(res["p_eff"]))  # tr(D_k Lambda_k(0)), Lambda(0) = sum f^(2(k-j)) x x'
    out["n_eff"] = float(np.mean(res["n_eff"]))
    for key, val in res.items():
        if not key.startswith("se_"):
            continue
        se = np.array(val)  # (C, runs, n)
        ratio = (se.mean(axis=1) / true).mean(axis=0)
        rms = (np.sqrt((se**2).mean(axis=1)) / true).mean(axis=0)
        cv = (se.std(axis=1) / se.mean(axis=1)).mean(axis=0)
        cover = (np.abs(err) < 2 * se).mean(axis=(0, 1))
        out[key[3:]] = dict(ratio=ratio.tolist(), rms=rms.tolist(), cv=cv.tolist(), coverage=cover.tolist())
    return out


def result_path(f, noise, tag=""):
    return RESULTS / f"f{f}_{noise}{('_' + tag) if tag else ''}.json"


def save(res, path):
    RESULTS.mkdir(exist_ok=True)
    summ = summarize(res)
    path.write_text(json.dumps(summ, indent=1))
    return summ


def fmt_row(s: dict, key: str) -> str:
    v = s[key]
    r = "/".join(f"{x:.2f}" for x in v["ratio"])
    c = "/".join(f"{100 * x:.0f}" for x in v["coverage"])
    return f"{r} ({c}%)"


GRID_MAIN = [(f, nz) for f in FORGETTING for nz in ("white", "ar2", "ar5", "ar10", "ar20", "bl2", "bl1")]
GRID_EXTRA = [
    # (f, noise, tag, kwargs)
    (0.98, "ar50", "", {}),
    (0.99, "ar50", "", {}),
    (0.999, "ar50", "", {}),
    (0.98, "bl05", "", {}),
    (0.999, "bl05", "", {}),
    (0.98, "ar5", "bartlett", {"window": "bartlett"}),
    (0.98, "bl2", "bartlett", {"window": "bartlett"}),
    (0.99, "ar10", "bartlett", {"window": "bartlett"}),
    (0.98, "ar5", "a_posteriori", {"residual": "a_posteriori"}),
    (0.98, "ar5", "a_priori", {"residual": "a_priori"}),
    (0.98, "bl2", "a_posteriori", {"residual": "a_posteriori"}),
    (0.98, "bl2", "a_priori", {"residual": "a_priori"}),
    (0.98, "ar5", "sweep", {"f_R_sweep": (0.995, 0.998, 0.999, 0.9995, 0.9998, 0.9999)}),
    (0.98, "bl2", "sweep", {"f_R_sweep": (0.995, 0.998, 0.999, 0.9995, 0.9998, 0.9999)}),
    (0.995, "ar10", "sweep", {"f_R_sweep": (0.998, 0.999, 0.9995, 0.9998, 0.9999)}),
    (1.0, "ar5", "", {}),
    (1.0, "bl2", "", {}),
    # the attribution table: these runs also have the level-adaptive variant
    (0.95, "white", "level", {}),
    (0.98, "white", "level", {}),
    (0.98, "ar5", "level", {}),
    (0.98, "bl2", "level", {}),
    (0.99, "ar10", "level", {}),
    (0.995, "bl2", "level", {}),
    (0.999, "ar5", "level", {}),
    (0.999, "bl1", "level", {}),
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--f", type=float, required=True)
    r.add_argument("--noise", required=True)
    r.add_argument("--runs", type=int, default=200)
    r.add_argument("--window", default="truncated")
    r.add_argument("--residual", default="standardized")
    r.add_argument("--tag", default="")
    g = sub.add_parser("grid")
    g.add_argument("--only", choices=("main", "extra"), default=None)
    g.add_argument("--runs", type=int, default=200)
    sub.add_parser("report")
    a = ap.parse_args(argv)
    if a.cmd == "run":
        res = run_config(a.f, a.noise, runs=a.runs, window=a.window, residual=a.residual)
        s = save(res, result_path(a.f, a.noise, a.tag))
        _print(s)
    elif a.cmd == "grid":
        jobs = []
        if a.only in (None, "main"):
            jobs += [(f, nz, "", {}) for f, nz in GRID_MAIN]
        if a.only in (None, "extra"):
            jobs += GRID_EXTRA
        for f, nz, tag, kw in jobs:
            p = result_path(f, nz, tag)
            if p.exists():
                continue
            res = run_config(f, nz, runs=a.runs, **kw)
            s = save(res, p)
            print(f"{p.name}: {s['config']['seconds']:.0f} s", flush=True)
            _print(s)
    else:
        from report_tables import write_tables  # noqa: PLC0415 - report_tables imports this module

        write_tables(RESULTS, HERE / "tables.md")


def _print(s):
    cfg = s["config"]
    print(f"f={cfg['f']} noise={cfg['noise']} f_R={cfg['f_R']:.6f} lags_share={cfg['lags_share']:.3f} "
          f"p_eff={s['p_eff']:.2f} n_eff={s['n_eff']:.1f} mc/true={np.round(s['mc_over_true'], 3)}")
    for key in s:
        if isinstance(s[key], dict) and "ratio" in s[key]:
            print(f"  {key:>14}: {fmt_row(s, key)}  cv={'/'.join(f'{x:.2f}' for x in s[key]['cv'])}")


if __name__ == "__main__":
    main()
