"""Scratch: evaluate convergence-criterion settings on saved Monte Carlo histories
(validation/convergence/histories.py). Prints, per level and parameter, the envelope-covers-
scatter time, the median first-flag time, and false-convergence rates.

    PYTHONPATH=$PWD python validation/convergence/tune.py /tmp/conv_hist7 --window 2 --band 1 --rate 0.15
"""
import argparse
import itertools
from pathlib import Path

import numpy as np

from rls_uncertainty.convergence import ConvergenceConfig, ConvergenceMonitor
from rls_uncertainty.simulation import T2_TRUE

W = {"CZ_alpha": (0, 1), "CZ_delta_e": (0, 2), "Cm_alpha": (1, 1), "Cm_q": (1, 2), "Cm_delta_e": (1, 3)}


def load(d):
    out = {}
    for f in sorted(Path(d).glob("level*.npz")):
        z = np.load(f)
        out[int(f.stem[5:])] = (z["t"], z["theta"], z["se"])
    return out


def flags_of(t, th, se, cfg):
    N, M, n = th.shape
    sizes = [3, 4] * (M // 2)
    mon = ConvergenceMonitor(sizes, cfg)
    stamps = np.round(t * 1e9).astype(np.int64)
    F = np.zeros((N, M, n), bool)
    for k in range(N):
        ready = np.isfinite(th[k]).any(axis=1)
        F[k] = mon.update(int(stamps[k]), th[k], se[k], ready)[0]
    return F


def cover_time(t, x, s, runs):
    ms = np.nanmean(s, axis=1)
    sc = np.nanstd(x, axis=1, ddof=1)
    out = []
    for tol in (0.0, 2 / np.sqrt(2 * (runs - 1))):
        ok = ms >= (1 - tol) * sc
        bad = np.flatnonzero(~ok)
        out.append(t[0] if not bad.size else (t[bad[-1] + 1] if bad[-1] + 1 < t.size else np.inf))
    return out


def evaluate(data, cfg, verbose=True):
    rows = []
    for lv, (t, th, se) in data.items():
        F = flags_of(t, th, se, cfg)
        runs = th.shape[1] // 2
        for name, (m, c) in W.items():
            x = th[:, m::2, c]
            s = se[:, m::2, c]
            f = F[:, m::2, c]
            has = f.any(axis=0)
            k = np.argmax(f, axis=0)
            tf = np.where(has, t[k], np.inf)
            r = np.arange(runs)
            xf, sf = x[k, r], s[k, r]
            mean_t = np.nanmean(x, axis=1)[k]
            false_truth = (np.abs(xf - T2_TRUE[name]) > 2 * sf)[has].mean() if has.any() else np.nan
            false_mean = (np.abs(xf - mean_t) > 2 * sf)[has].mean() if has.any() else np.nan
            floor = np.mean(np.abs(x[-1] - T2_TRUE[name]) > 2 * s[-1])
            tc, tct = cover_time(t, x, s, runs)
            rows.append((lv, name, tc, tct, np.median(tf), has.mean(), false_truth, false_mean, floor))
            if verbose:
                print(f"{lv:3d}% {name:11s} cover {tc:5.2f}/{tct:5.2f}  flag med {np.median(tf):5.2f} "
                      f"flagged {has.mean():4.2f}  false(truth) {false_truth:4.2f}  false(mean) {false_mean:4.2f}  "
                      f"floor(end) {floor:4.2f}")
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--window", type=float, nargs="+", default=[2.0])
    ap.add_argument("--band", type=float, nargs="+", default=[1.0])
    ap.add_argument("--rate", type=float, nargs="+", default=[0.15])
    a = ap.parse_args()
    data = load(a.dir)
    for T, k, r in itertools.product(a.window, a.band, a.rate):
        print(f"== window {T} band {k} rate {r}")
        rows = evaluate(data, ConvergenceConfig(window=T, band=k, max_se_rate=r, rate_hz=50.0))
        fm = np.array([x[7] for x in rows])
        d20 = [x[4] - x[3] for x in rows if x[0] == 20]
        print(f"   max false(mean) {np.nanmax(fm):.3f}; 20%: flag - cover(tol) {np.round(d20, 2)}")
