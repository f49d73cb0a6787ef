"""Issue 14 study: automatic lag selection for the corrected covariance (Eq. 22).

A prototype of ``n_lags="auto"`` around today's :class:`~rls_uncertainty.estimator.EstimatorBank`
(the estimator itself is not changed). What it does:

* One bank keeps all lags (``n_lags=None``). Its lag sums ``_S[:, i] = n_eff R_k(i)`` (Eq. 17)
  and one-sided lag products ``_U[m, b, i, a]`` (Eq. 21, ``Lambda(i) = U(i) + U(i)'``) for
  lags ``0..cap`` are exactly those a bank with ``n_lags=cap`` holds (the sums do not depend
  on the capacity), so they are what an integrated ``auto`` bank with that cap would see.
* At an evaluation, :func:`rls_uncertainty.lag_selection.select_lags` picks ``L`` per model
  from ``R_k(0..cap)`` (and optionally the diagonals of ``Lambda_k(i)``), and
  :func:`corrected_se` evaluates Eq. 22 with per-model lag weights from the same arrays
  (the bank's own formula: ``D [N + N'] D / n_eff`` with ``N' = sum_i c_i S(i) U(i)``, lag 0
  halved, column scaling undone, a negative diagonal repaired by the nearest positive
  semi-definite matrix). :func:`check_against_bank` shows that with ``L = 50`` and with all
  lags this reproduces banks run with ``n_lags=50`` and ``n_lags=None`` (relative
  differences ~1e-15).
* Table 3 Monte Carlo: the paper's T-2 simulation through ``montecarlo``'s machinery
  (``simulate_short_period``, ``add_noise``, ``reduce_short_period`` with
  ``PAPER_DIFFERENTIATOR``, ``T2_MODELS``, the five Table 3 parameters, the same seeds as
  ``montecarlo.run_level``); end-of-maneuver standard errors, averaged over runs, over the
  observed scatter of the final estimates.
* Twin Otter lateral recordings: the regression rows the node's pipeline hands its estimator
  (``Pipeline(record=True)``) for ``totter_f1_017`` and ``totter_f1_014``, replayed into the
  banks sample by sample; ``L`` is chosen at every sample (its history is summarised).

Usage (from the worktree root)::

    PYTHONPATH=$PWD .venv/bin/python validation/auto_lags/study.py --runs 250 \
        --bags /tmp/autolags --out validation/auto_lags/results

``--bags`` holds the converted recordings (``rls-uncertainty convert
../shared/flight_data/totter_f1_017 --mapping msg_schemas/fti_msgs/mapping.yaml --out
BAGS/f1_017``, same for ``f1_014``); without it the flight part converts them into a
temporary directory.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rls_uncertainty.estimator import EstimatorBank, nearest_psd
from rls_uncertainty.lag_selection import flat_top_lags, select_lags
from rls_uncertainty.montecarlo import _WHERE, LEVELS, PAPER_DIFFERENTIATOR, PARAMETERS
from rls_uncertainty.simulation import T2_MODELS, add_noise, reduce_short_period, simulate_short_period

ROOT = Path(__file__).resolve().parents[2]
FIXED = 50
CAP = 50


# ---------------------------------------------------------------------------- Eq. 22 per model
def lag_inputs(bank: EstimatorBank, cap: int) -> tuple[np.ndarray, np.ndarray]:
    """What the rule sees: ``R_k(0..W-1)`` ``(M, W)`` and the diagonals ``Lambda_aa(i)``
    ``(M, W, n_max)`` in the paper's convention (``Lambda(0) = sum x x'``, ``Lambda(i) = U(i) +
    U(i)'`` so its diagonal is ``2 U_aa(i)``), ``W = min(k, cap + 1)``. Scaled units: the rule
    only uses ratios."""
    w = min(bank.n_window, cap + 1)
    R = bank._S[:, :w] / bank.n_eff
    idx = np.arange(bank.n_max)
    lam = np.moveaxis(bank._U[:, idx, :w, idx], 0, -1).copy()  # (M, w, n): U_aa(i)
    lam[:, 1:] *= 2.0
    return R, lam


def window_weights(L, window: str, w: int) -> np.ndarray:
    """Per-model lag weights ``(M, w)``: ``truncated`` (Eq. 22), ``bartlett`` (``1 -
    i/(L+1)``, the estimator's) or ``trapezoid`` (Politis' flat-top window with ``M = L``:
    1 up to ``L/2``, then ``2 (1 - i/L)``)."""
    L = np.asarray(L, dtype=float)[:, None]
    i = np.arange(w, dtype=float)[None, :]
    if window == "truncated":
        return (i <= L).astype(float)
    if window == "bartlett":
        return np.where(i <= L, 1.0 - i / (L + 1.0), 0.0)
    if window == "trapezoid":
        x = i / np.maximum(L, 1.0)
        c = np.where(x <= 0.5, 1.0, np.where(x <= 1.0, 2.0 * (1.0 - x), 0.0))
        return np.where(L > 0, c, (i == 0).astype(float))
    raise ValueError(window)


def corrected_se(bank: EstimatorBank, weights: np.ndarray, S: np.ndarray | None = None,
                 n_eff: float | None = None) -> np.ndarray:
    """Corrected standard errors ``(M, n_max)`` of every model with its own lag weights
    (``weights[m, i]``, Eq. 22 / Eq. 20), from the bank's dispersion, lag sums and lag
    products. ``S``/``n_eff`` replace the bank's lag sums (used for the warm-up diagnosis)."""
    M, n = bank.n_models, bank.n_max
    w = weights.shape[1]
    c = weights.copy()
    c[:, 0] *= 0.5  # U(0) + U(0)' counts lag 0 twice
    S = bank._S if S is None else S
    n_eff = bank.n_eff if n_eff is None else n_eff
    cS = S[:, :w] * c
    N = np.einsum("mi,mbia->mba", cS, bank._U[:, :, :w])
    D = bank._aug[:, :n]
    cov = D @ (N + N.swapaxes(1, 2)) @ D / n_eff
    cov *= bank._inv_s[:, :, None] * bank._inv_s[:, None, :]
    out = np.full((M, n), np.nan)
    for j in np.flatnonzero(bank.ready):
        s = bank.sizes[j]
        cj = cov[j, :s, :s]
        if np.any(np.diag(cj) < 0.0):
            cj = nearest_psd(cj)
        out[j, :s] = np.sqrt(np.maximum(np.diag(cj), 0.0))
    return out


def auto_se(bank: EstimatorBank, cap: int, rule: str = "flat_top", *, window: str | None = None,
            score: bool = False, min_lags: int = 0, **flat_top) -> tuple[np.ndarray, np.ndarray]:
    """``(se, L)``: lags chosen by ``rule`` from lags ``0..cap``, then Eq. 22 with them.
    ``flat_top`` keywords (``c``, ``factor``) call :func:`flat_top_lags` with other tuning."""
    R, lam = lag_inputs(bank, cap)
    lam = lam if score else None
    if flat_top:
        lags = flat_top_lags(R, bank.k, cap=cap, lambda_diag=lam, min_lags=min_lags, **flat_top)
        window = window or "truncated"
    else:
        choice = select_lags(R, bank.k, rule, cap=cap, lambda_diag=lam, min_lags=min_lags)
        lags, window = choice.lags, window or choice.window
    weights = window_weights(lags, window, R.shape[1])
    return corrected_se(bank, weights), lags


def fixed_se(bank: EstimatorBank, L: int | None, window: str = "truncated") -> np.ndarray:
    w = bank.n_window
    L = w - 1 if L is None else L
    return corrected_se(bank, window_weights(np.full(bank.n_models, L), window, min(w, L + 1)))


def check_against_bank(bank_all: EstimatorBank, bank_fixed: EstimatorBank) -> float:
    """Largest relative difference of :func:`fixed_se` from the banks' own corrected SEs."""
    worst = 0.0
    for ours, theirs in ((fixed_se(bank_all, bank_fixed.n_lags), bank_fixed.standard_errors_all("corrected")),
                         (fixed_se(bank_all, None), bank_all.standard_errors_all("corrected"))):
        ok = np.isfinite(theirs)
        worst = max(worst, float(np.max(np.abs(ours[ok] - theirs[ok]) / np.abs(theirs[ok]))))
    return worst


def warmup_sums(bank: EstimatorBank, start: int, w: int) -> tuple[np.ndarray, float]:
    """Lag sums of the residuals from sample ``start`` on (earlier residuals set to zero),
    from the all-lags bank's residual history: the diagnosis of the 0% C_m excess."""
    V = -bank._recent(bank._vbuf)[:, ::-1]  # (M, k) residuals, oldest first
    V = V.copy()
    V[:, :start] = 0.0
    k = V.shape[1]
    S = np.stack([np.einsum("mj,mj->m", V[:, i:], V[:, : k - i]) for i in range(w)], axis=1)
    return S, float(k - start)


# ---------------------------------------------------------------------------- Table 3
def simulate_level(level: float, runs: int, seed: int = 2016):
    """The regression rows of ``runs`` T-2 maneuvers, laid out as ``montecarlo.run_level``
    does (model ``r * 2 + m``), with its seeds."""
    clean = simulate_short_period()
    nm = len(T2_MODELS)
    rows = []
    for run in range(runs):
        rng = np.random.default_rng([seed, int(round(level * 1000)), run])
        _t, data = reduce_short_period(add_noise(clean, level, rng), PAPER_DIFFERENTIATOR)
        rows.append(data)
    sizes = [len(m.regressors) for m in T2_MODELS] * runs
    N = rows[0][T2_MODELS[0].output][1].size
    X = np.zeros((N, nm * runs, max(sizes)))
    Z = np.zeros((N, nm * runs))
    for r, data in enumerate(rows):
        for m, model in enumerate(T2_MODELS):
            Xm, zm = data[model.output]
            X[:, r * nm + m, : Xm.shape[1]] = Xm
            Z[:, r * nm + m] = zm
    return sizes, X, Z


def pick(arr: np.ndarray, runs: int) -> np.ndarray:
    """``(runs, 5)``: the Table 3 parameters out of an ``(M, n_max)`` array."""
    nm = len(T2_MODELS)
    return np.array([[arr[r * nm + m, c] for m, c in (_WHERE[p] for p in PARAMETERS)] for r in range(runs)])


MC_VARIANTS = {
    # name: (rule, window override, score, min_lags, cap, residual)
    "auto": ("flat_top", None, False, 0, CAP, "standardized"),
    "auto_score": ("flat_top", None, True, 0, CAP, "standardized"),
    "auto_cap100": ("flat_top", None, False, 0, 100, "standardized"),
    "auto_trapezoid": ("flat_top", "trapezoid", False, 0, CAP, "standardized"),
    "newey_west": ("newey_west", None, False, 0, CAP, "standardized"),
    "newey_west_truncated": ("newey_west", "truncated", False, 0, CAP, "standardized"),
    "andrews_truncated": ("andrews", None, False, 0, CAP, "standardized"),
    "andrews_bartlett": ("andrews_bartlett", None, False, 0, CAP, "standardized"),
    "andrews_truncated_min4": ("andrews", None, False, 4, CAP, "standardized"),
    "auto_a_posteriori": ("flat_top", None, False, 0, CAP, "a_posteriori"),
    "flat_top_factor1": ("flat_top", None, False, 0, CAP, "standardized", {"factor": 1}),
    "flat_top_factor3": ("flat_top", None, False, 0, CAP, "standardized", {"factor": 3}),
    "flat_top_c1.5": ("flat_top", None, False, 0, CAP, "standardized", {"c": 1.5}),
    "flat_top_c2.5": ("flat_top", None, False, 0, CAP, "standardized", {"c": 2.5}),
}
WARMUP = 50  # samples: the 0% diagnosis (1 s; the elevator input starts at 0.5 s)


def run_mc_level(level: float, runs: int) -> dict:
    t0 = time.perf_counter()
    sizes, X, Z = simulate_level(level, runs)
    banks = {"standardized": EstimatorBank(sizes, None),
             "a_posteriori": EstimatorBank(sizes, None, residual="a_posteriori")}
    bank50 = EstimatorBank(sizes, FIXED)
    for k in range(X.shape[0]):
        for b in banks.values():
            b.update(X[k], Z[k])
        bank50.update(X[k], Z[k])
    bank = banks["standardized"]
    theta = pick(bank.theta_all(), runs)
    scatter = theta.std(axis=0, ddof=1)
    out = {
        "level": level, "runs": runs, "N": int(X.shape[0]),
        "check_rel_diff": check_against_bank(bank, bank50),
        "scatter": scatter.tolist(),
        "se": {}, "lags": {},
    }
    out["se"]["conventional"] = pick(bank.standard_errors_all("conventional"), runs).mean(0).tolist()
    out["se"]["fixed50"] = pick(bank50.standard_errors_all("corrected"), runs).mean(0).tolist()
    out["se"]["all"] = pick(bank.standard_errors_all("corrected"), runs).mean(0).tolist()
    out["se"]["fixed50_a_posteriori"] = pick(fixed_se(banks["a_posteriori"], FIXED), runs).mean(0).tolist()
    for name, (rule, window, score, mn, cap, residual, *extra) in MC_VARIANTS.items():
        se, L = auto_se(banks[residual], cap, rule, window=window, score=score, min_lags=mn,
                        **(extra[0] if extra else {}))
        out["se"][name] = pick(se, runs).mean(0).tolist()
        out["lags"][name] = {"CZ": L[0::2].tolist(), "Cm": L[1::2].tolist()}
    # Diagnosis of the 0% excess: R from the residuals after the first WARMUP samples, with
    # the auto lags and with 50 lags.
    S, n_eff = warmup_sums(bank, WARMUP, CAP + 1)
    L = np.empty(bank.n_models, dtype=int)
    L[0::2], L[1::2] = out["lags"]["auto"]["CZ"], out["lags"]["auto"]["Cm"]
    for name, lags in (("auto_warmup", L), ("fixed50_warmup", np.full(bank.n_models, FIXED))):
        se = corrected_se(bank, window_weights(lags, "truncated", CAP + 1), S=S, n_eff=n_eff)
        out["se"][name] = pick(se, runs).mean(0).tolist()
    # Oracle: the single fixed L that is best per parameter (truncated), for reference.
    sweep = {}
    for Lf in (0, 1, 2, 3, 4, 5, 6, 8, 10, 15, 20, 30, 50):
        sweep[Lf] = (pick(fixed_se(bank, Lf), runs).mean(0) / scatter).tolist()
    out["sweep_truncated"] = sweep
    out["seconds"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------------------- flight data
RECORDINGS = {
    "f1_017": ("totter_f1_017", {}),
    "f1_014": ("totter_f1_014", {"aircraft": "twin_otter_f1_014"}),
}


def flight_rows(name: str, bags: Path):
    from rls_uncertainty.bags import convert, read_inputs  # noqa: PLC0415
    from rls_uncertainty.config import load_parameters_file, pipeline_config  # noqa: PLC0415
    from rls_uncertainty.replay import run_pipeline  # noqa: PLC0415

    rec, extra = RECORDINGS[name]
    bag = bags / name
    if not bag.exists():
        shared = Path("/work/shared/flight_data")
        src = shared if shared.is_dir() else ROOT.parent / "shared" / "flight_data"
        convert(src / rec, ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml", bag)
    messages, _ = read_inputs(bag)
    params = load_parameters_file("twin_otter_lateral")
    params.update(extra)
    result = run_pipeline(messages, pipeline_config(params), record=True)
    pipe = result.pipeline
    X = np.array([r[1] for r in pipe.regression])
    z = np.array([r[2] for r in pipe.regression])
    return pipe, result, X, z


def run_flight(name: str, bags: Path, caps=(50, 100, 200)) -> dict:
    pipe, result, X, z = flight_rows(name, bags)
    sizes = pipe.sizes
    bank = EstimatorBank(sizes, None)
    bank_post = EstimatorBank(sizes, None, residual="a_posteriori")
    history = {cap: [] for cap in caps}
    se_hist = {"auto": [], "fixed50": []}
    for k in range(X.shape[0]):
        bank.update(X[k], z[k])
        bank_post.update(X[k], z[k])
        if bank.ready.all():
            for cap in caps:
                R, _lam = lag_inputs(bank, cap)
                history[cap].append(select_lags(R, bank.k, "flat_top", cap=cap).lags)
            se_hist["auto"].append(auto_se(bank, CAP)[0])
            se_hist["fixed50"].append(fixed_se(bank, FIXED))
    last = result.outputs[-1]  # the node's own output with its configured 50 lags
    node50 = last.se
    ours50 = fixed_se(bank, FIXED)
    ok = np.isfinite(node50)
    out = {
        "samples": int(X.shape[0]),
        "check_rel_diff_vs_node": float(np.max(np.abs(ours50[ok] - node50[ok]) / node50[ok])),
        "models": [m.output for m in pipe.models],
        "names": [list(n) for n in pipe.parameter_names],
        "theta": bank.theta_all().tolist(),
        "se": {
            "conventional": bank.standard_errors_all("conventional").tolist(),
            "fixed50": ours50.tolist(),
            "all": bank.standard_errors_all("corrected").tolist(),
        },
        "lags": {}, "lag_history": {},
    }
    for cap in caps:
        se, L = auto_se(bank, cap)
        key = "auto" if cap == CAP else f"auto_cap{cap}"
        out["se"][key] = se.tolist()
        out["lags"][key] = L.tolist()
        h = np.array(history[cap])  # (samples after all ready, M)
        d = np.diff(h, axis=0)
        changes = (d != 0).sum(axis=0)
        q = np.percentile(h, [10, 50, 90], axis=0)
        out["lag_history"][key] = {"p10": q[0].tolist(), "p50": q[1].tolist(), "p90": q[2].tolist(),
                                   "changes": changes.tolist(), "up": (d > 0).sum(axis=0).tolist(),
                                   "down": (d < 0).sum(axis=0).tolist(), "evaluations": int(h.shape[0])}
    # Sample-to-sample relative change of the corrected SEs over the second half of the record
    # (where the estimates have settled): do the changes of L make the auto SEs jumpy?
    for key, se_list in se_hist.items():
        h = np.array(se_list)
        h = h[h.shape[0] // 2 :]
        step = np.abs(np.diff(h, axis=0)) / h[1:]
        out.setdefault("se_steps", {})[key] = {"median": float(np.nanmedian(step)),
                                                "p99": float(np.nanpercentile(step, 99)),
                                                "max": float(np.nanmax(step))}
    se, L = auto_se(bank_post, CAP)
    out["se"]["auto_a_posteriori"], out["lags"]["auto_a_posteriori"] = se.tolist(), L.tolist()
    se, L = auto_se(bank, CAP, score=True)
    out["se"]["auto_score"], out["lags"]["auto_score"] = se.tolist(), L.tolist()
    se, L = auto_se(bank, CAP, "newey_west")
    out["se"]["newey_west"], out["lags"]["newey_west"] = se.tolist(), L.tolist()
    se, L = auto_se(bank, CAP, "andrews")
    out["se"]["andrews_truncated"], out["lags"]["andrews_truncated"] = se.tolist(), L.tolist()
    R, _ = lag_inputs(bank, 200)
    out["rho"] = (R / R[:, :1]).tolist()
    out["sweep_truncated"] = {Lf: fixed_se(bank, Lf).tolist() for Lf in (0, 5, 10, 20, 30, 50, 75, 100, 150, 200)}
    return out


# ---------------------------------------------------------------------------- tables
def _fmt_ratio(x: float) -> str:
    s = f"{x:.2f}"
    return f"**{s}**" if not (0.8 <= x <= 1.25) else s


def mc_tables(results: list[dict]) -> str:
    cols = [("auto", "auto (flat-top, cap 50)"), ("fixed50", "50 lags"), ("all", "all lags"),
            ("conventional", "conventional")]
    lines = ["### Corrected SE / observed scatter (Table 3 Monte Carlo, end of maneuver)", "",
             f"{results[0]['runs']} runs per level; SE = mean over runs; scatter = standard deviation of the "
             "final estimates; outside [0.8, 1.25] in bold.", "",
             "| level | parameter | " + " | ".join(c[1] for c in cols) + " |",
             "| --- | --- | " + " | ".join("---" for _ in cols) + " |"]
    for res in results:
        sc = np.array(res["scatter"])
        for i, p in enumerate(PARAMETERS):
            cells = [_fmt_ratio(res["se"][key][i] / sc[i]) for key, _ in cols]
            lines.append(f"| {res['level'] * 100:.0f}% | {p} | " + " | ".join(cells) + " |")
    lines += ["", "### Chosen L at the end of the maneuver (auto, cap 50): distribution over runs", "",
              "| level | model | min | 10% | median | 90% | max | at cap |",
              "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for res in results:
        for model in ("CZ", "Cm"):
            L = np.array(res["lags"]["auto"][model])
            q = np.percentile(L, [10, 50, 90])
            lines.append(f"| {res['level'] * 100:.0f}% | {model} | {L.min()} | {q[0]:.0f} | {q[1]:.0f} | {q[2]:.0f} | "
                         f"{L.max()} | {np.mean(L >= CAP) * 100:.0f}% |")
    others = [k for k in results[0]["se"] if k not in {c[0] for c in cols}]
    lines += ["", "### Other rules and variants tried (SE / scatter)", "",
              "| level | variant | " + " | ".join(PARAMETERS) + " | median L (CZ, Cm) |",
              "| --- | --- | " + " | ".join("---" for _ in PARAMETERS) + " | --- |"]
    for res in results:
        sc = np.array(res["scatter"])
        for key in others:
            cells = [_fmt_ratio(v / s) for v, s in zip(res["se"][key], sc, strict=True)]
            lags = res["lags"].get(key)
            med = f"{np.median(lags['CZ']):.0f}, {np.median(lags['Cm']):.0f}" if lags else "-"
            lines.append(f"| {res['level'] * 100:.0f}% | {key} | " + " | ".join(cells) + f" | {med} |")
    return "\n".join(lines) + "\n"


def flight_tables(flights: dict) -> str:
    lines = []
    for name, res in flights.items():
        lines += [f"### Twin Otter `totter_{name}` ({res['samples']} samples; end of maneuver)", "",
                  "| model | L auto (cap 50) | L auto cap 100 / 200 | L history p10/p50/p90 (cap 50) "
                  "| changes of L (up / down) |",
                  "| --- | --- | --- | --- | --- |"]
        hist = res["lag_history"]["auto"]
        for j, m in enumerate(res["models"]):
            lines.append(f"| {m} | {res['lags']['auto'][j]} | "
                         f"{res['lags']['auto_cap100'][j]} / {res['lags']['auto_cap200'][j]} | "
                         f"{hist['p10'][j]:.0f} / {hist['p50'][j]:.0f} / {hist['p90'][j]:.0f} | "
                         f"{hist['changes'][j]} ({hist['up'][j]} / {hist['down'][j]}) in {hist['evaluations']} |")
        st = res["se_steps"]
        lines += ["", f"Sample-to-sample change of the corrected SEs, second half of the record (median / 99% / max): "
                  f"auto {st['auto']['median']:.2%} / {st['auto']['p99']:.2%} / {st['auto']['max']:.2%}; "
                  f"50 lags {st['fixed50']['median']:.2%} / {st['fixed50']['p99']:.2%} / {st['fixed50']['max']:.2%}. "
                  f"L with the a posteriori residual: {res['lags']['auto_a_posteriori']}.", "",
                  "| parameter | estimate | SE auto | SE 50 lags | SE all lags | SE auto cap 200 "
                  "| SE auto, a posteriori residual | SE conventional | auto / 50 |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for j, names in enumerate(res["names"]):
            for a, p in enumerate(names):
                se = {key: v[j][a] for key, v in res["se"].items()}
                lines.append(f"| {p} | {res['theta'][j][a]:.4g} | {se['auto']:.3g} | {se['fixed50']:.3g} | "
                             f"{se['all']:.3g} | "
                             f"{se['auto_cap200']:.3g} | {se['auto_a_posteriori']:.3g} | {se['conventional']:.3g} | "
                             f"{se['auto'] / se['fixed50']:.2f} |")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=250)
    ap.add_argument("--levels", type=float, nargs="*", default=list(LEVELS))
    ap.add_argument("--bags", type=Path, default=None, help="converted recordings (BAGS/f1_017, BAGS/f1_014)")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    ap.add_argument("--skip-mc", action="store_true")
    ap.add_argument("--skip-flight", action="store_true")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.skip_mc:
        results = []
        for level in args.levels:
            res = run_mc_level(level, args.runs)
            print(f"level {level * 100:3.0f}%: {res['seconds']:.1f} s, check {res['check_rel_diff']:.1e}",
                  file=sys.stderr)
            results.append(res)
        (args.out / "montecarlo.json").write_text(json.dumps(results))
        (args.out / "montecarlo.md").write_text(mc_tables(results))
    if not args.skip_flight:
        with tempfile.TemporaryDirectory() as tmp:
            bags = args.bags or Path(tmp)
            flights = {name: run_flight(name, bags) for name in RECORDINGS}
        for name, res in flights.items():
            print(f"{name}: check vs node {res['check_rel_diff_vs_node']:.1e}", file=sys.stderr)
        (args.out / "flight.json").write_text(json.dumps(flights))
        (args.out / "flight.md").write_text(flight_tables(flights))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
