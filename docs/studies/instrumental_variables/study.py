"""Recursive instrumental variables (``estimator.algorithm: iv``, ``config/t2_turbulence.yaml``)
against the paper's RLS (``config/t2.yaml``) on simulated T-2 campaigns. Report: REPORT.md
beside this file.

A campaign is a directory that ``rls-uncertainty make-bag --campaign N`` wrote. Each maneuver's
bag is read once and its messages go through the shipped data path (the replay's
``run_pipeline``, as ``rls-uncertainty campaign`` runs it) twice: with ``config/t2.yaml``
(without the excitation topic, which that configuration does not read) and with
``config/t2_turbulence.yaml``. Per maneuver, method and Table 3 parameter it keeps the
end-of-maneuver estimate and corrected standard error (the values ``campaign`` writes to
maneuvers.csv) and, from the per-sample outputs, the first sample at which the convergence flag
is set, with the estimate and standard error there. The pipeline's time per sample of each
method, measured alternately on the same messages in the same process, gives the cost ratio.

    python docs/studies/instrumental_variables/study.py run CAMPAIGN_DIR --count N --out OUT.csv
    python docs/studies/instrumental_variables/study.py table OUT.csv [OUT2.csv ...]
    python docs/studies/instrumental_variables/study.py figure OUT.csv ... --png FIG.png

``table`` prints per case, parameter and method: coverage of the truth (``T2_TRUE``) by
+-2 corrected SE at the maneuver's end, mean SE / scatter (standard deviation of the end
estimates), bias / scatter, false convergence (of the maneuvers flagged, those whose truth lies
outside +-2 SE at the first flag), the median flag time and the per-sample cost.

The frequency-domain estimator (``estimator.method: frequency``) with each configuration: the
same rows and tables of its outputs, the flags those of its own convergence monitor (REPORT.md,
"The frequency domain"):

    python docs/studies/instrumental_variables/study.py fd CAMPAIGN_DIR --count N --out FD.csv
    python docs/studies/instrumental_variables/study.py fd-table FD.csv [FD2.csv ...] [--against OUT.csv]

The Twin Otter recordings, RLS and IV side by side (REPORT.md, "The Twin Otter recordings"):

    python docs/studies/instrumental_variables/study.py flight table|prediction|delays

Each recording (``../shared/flight_data``, ``$RLS_FLIGHT_DATA`` or ``--flight-data``) is
converted with the shipped mapping and its messages go through the replay's data path
(``run_pipeline``, the function behind ``rls-uncertainty replay``) with its configuration
(``config/twin_otter_lateral.yaml``, ``config/twin_otter_longitudinal.yaml``) as shipped (RLS)
and with ``estimator.algorithm: iv`` (``instruments.source: delayed``: the measured surfaces for
themselves and the other regressors ``instruments.delay_span`` earlier; for the lateral models
``auto`` picks the same). The longitudinal one is run a third time with the short-period
auxiliary model driven by the measured surfaces (``instruments.source: excitation``, the
surfaces repeated on the excitation input), the instruments of the simulated study.


``prediction``: the estimates at the end of one lateral recording predict the other's
coefficients from its regressors (the same rows the estimator took); the RMS of the
prediction error per model, against that of the recording's own fit. ``delays``: the smallest
canonical correlation between instruments and regressors (``rho_min``, weak below
``instruments.weak_below``) and the end estimates of the key derivatives per delay.
"""

from __future__ import annotations

import argparse
import atexit
import csv
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from functools import cache
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

from rls_uncertainty.offline.bags import InputStream, convert, read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file
from rls_uncertainty.settings.parameters import PARAMETER_NAMES, node_config, pipeline_config
from rls_uncertainty.settings.sources import node_parameters_file
from rls_uncertainty.simulation.t2 import T2_TRUE

matplotlib.use("Agg")
import matplotlib.pyplot as plt

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = {"RLS": ROOT / "config" / "t2.yaml", "IV": ROOT / "config" / "t2_turbulence.yaml"}
PARAMS = tuple(T2_TRUE)
FIELDS = ("case", "maneuver", "method", "parameter", "estimate", "se", "flag_time", "flag_estimate", "flag_se",
          "converged_end", "samples", "pipeline_seconds")


def _params(path: Path) -> dict:
    values = node_parameters_file(str(path)).values
    return {k: v for k, v in values.items() if k in PARAMETER_NAMES}


def _rows(case: str, name: str, method: str, result, t0: int, seconds: float, domain: str = "time") -> list[dict]:
    """Per Table 3 parameter: end values and the first flag (NaN when never flagged), of the
    time-domain outputs or (``domain="frequency"``) the frequency-domain ones."""
    if domain == "time":
        names, outs = result.parameter_names, [(o.stamp_ns, o) for o in result.outputs]
    else:
        names = result.frequency_parameter_names
        outs = [(o.stamp_ns, o.frequency) for o in result.outputs if o.frequency is not None]
    rows = []
    for j, model_names in enumerate(names):
        ready = [(stamp, o) for stamp, o in outs if o.ready[j]]
        for i, p in enumerate(model_names):
            if p not in T2_TRUE:
                continue
            row = {"case": case, "maneuver": name, "method": method, "parameter": p, "estimate": math.nan,
                   "se": math.nan, "flag_time": math.nan, "flag_estimate": math.nan, "flag_se": math.nan,
                   "converged_end": 0, "samples": len(result.outputs), "pipeline_seconds": seconds}
            if ready:
                last = ready[-1][1]
                row.update(estimate=float(last.theta[j, i]), se=float(last.se[j, i]),
                           converged_end=int(bool(last.converged[j, i])))
                first = next(((stamp, o) for stamp, o in ready if o.converged[j, i]), None)
                if first is not None:
                    stamp, o = first
                    row.update(flag_time=(stamp - t0) * 1e-9, flag_estimate=float(o.theta[j, i]),
                               flag_se=float(o.se[j, i]))
            rows.append(row)
    return rows


def one_maneuver(job: tuple[str, str]) -> list[dict]:
    case, bag = job
    params = {m: _params(c) for m, c in CONFIGS.items()}
    topics = dict(node_config(params["IV"]).topics)
    with InputStream(bag, topics) as stream:
        t0 = stream.t0
        messages = list(stream)
    rows: list[dict] = []
    for method in ("RLS", "IV"):  # alternately, on the same messages
        msgs = messages if method == "IV" else [m for m in messages if m[0] != "excitation"]
        config = pipeline_config(params[method])
        start = time.perf_counter()
        result = run_pipeline(msgs, config, record=False, keep_outputs=True)
        seconds = time.perf_counter() - start
        rows += _rows(case, Path(bag).name, method, result, t0, seconds)
    return rows


# IV with one setting changed: the levers on its early standard error and flags.
LEVERS = {"IV": {}, "IV, small_sample 1": {"estimator.small_sample": 1.0},
          "IV, convergence.window 3 s": {"convergence.window": 3.0},
          "IV, weak_below 0.3": {"instruments.weak_below": 0.3},
          "IV, weak_below 0.5": {"instruments.weak_below": 0.5}}


def one_maneuver_levers(job: tuple[str, str]) -> list[dict]:
    case, bag = job
    params = _params(CONFIGS["IV"])
    with InputStream(bag, dict(node_config(params).topics)) as stream:
        t0 = stream.t0
        messages = list(stream)
    rows: list[dict] = []
    for label, extra in LEVERS.items():
        start = time.perf_counter()
        result = run_pipeline(messages, pipeline_config({**params, **extra}), record=False, keep_outputs=True)
        rows += _rows(case, Path(bag).name, label, result, t0, time.perf_counter() - start)
    return rows


def run(args: argparse.Namespace, job: Any = None) -> None:
    bags = sorted(str(p) for p in Path(args.campaign).glob("m*") if p.is_dir())[: args.count]
    case = args.case or Path(args.campaign).name
    with open(args.out, "w", newline="") as f, Pool(args.workers) as pool:
        w = csv.DictWriter(f, FIELDS)
        w.writeheader()
        job = job or (one_maneuver_levers if getattr(args, "levers", False) else one_maneuver)
        for n, rows in enumerate(pool.imap(job, [(case, b) for b in bags]), 1):
            w.writerows(rows)
            f.flush()
            print(f"\r{case}: {n}/{len(bags)}", end="", file=sys.stderr)
    print(file=sys.stderr)


def _read(paths: list[str]) -> list[dict]:
    rows = []
    for path in paths:
        with open(path) as f:
            for r in csv.DictReader(f):
                for k in ("estimate", "se", "flag_time", "flag_estimate", "flag_se", "pipeline_seconds"):
                    r[k] = float(r[k])
                r["converged_end"] = int(r["converged_end"])
                r["samples"] = int(r["samples"])
                rows.append(r)
    return rows


def statistics(rows: list[dict]) -> dict:
    """Per (case, method, parameter): n, coverage %, SE/scatter, bias/scatter, false conv. %,
    flagged, median flag time."""
    out = {}
    keys = sorted({(r["case"], r["method"], r["parameter"]) for r in rows})
    for case, method, p in keys:
        sel = [r for r in rows if (r["case"], r["method"], r["parameter"]) == (case, method, p)
               and np.isfinite(r["estimate"])]
        truth = T2_TRUE[p]
        flagged = [r for r in sel if np.isfinite(r["flag_time"])]
        false = [r for r in flagged if abs(r["flag_estimate"] - truth) > 2 * r["flag_se"]]
        out[case, method, p] = {
            **end_statistics(np.array([r["estimate"] for r in sel]), np.array([r["se"] for r in sel]), truth),
            "false": 100 * len(false) / len(flagged) if flagged else math.nan,
            "flagged": len(flagged),
            "flag_time": float(np.median([r["flag_time"] for r in flagged])) if flagged else math.nan,
            "converged_end": 100 * np.mean([r["converged_end"] for r in sel]),
        }
    return out


def end_statistics(est: np.ndarray, se: np.ndarray, truth: float) -> dict:
    """n, coverage %, SE/scatter, bias/scatter, scatter, robust SE/scatter and z std of the end
    estimates and standard errors of one parameter over the maneuvers of a case."""
    scatter = est.std(ddof=1)
    return {
        "n": len(est),
        "coverage": 100 * np.mean(np.abs(est - truth) <= 2 * se),
        "se_scatter": se.mean() / scatter,
        "bias_scatter": (est.mean() - truth) / scatter,
        "scatter": scatter,
        # robust to a few maneuvers with weak instruments: the median SE over 1.4826 x the
        # median absolute deviation of the estimates, and the spread of the z-scores
        "robust_se_scatter": np.median(se) / (1.4826 * np.median(np.abs(est - np.median(est)))),
        "z_std": float(np.std((est - truth) / se, ddof=1)),
    }


def _cost(rows: list[dict], case: str) -> tuple[float, float]:
    per = {}
    for method in ("RLS", "IV"):
        seen = {(r["maneuver"], r["pipeline_seconds"], r["samples"]) for r in rows
                if r["case"] == case and r["method"] == method and r["parameter"] == "Cm_q"}
        per[method] = 1e6 * sum(s for _m, s, _n in seen) / max(1, sum(n for _m, _s, n in seen))
    return per["RLS"], per["IV"]


def table(args: argparse.Namespace) -> None:
    rows = _read(args.csv)
    if getattr(args, "flagged", False):  # what the user is handed as converged
        rows = [r for r in rows if r["converged_end"]]
    stats = statistics(rows)
    for case in dict.fromkeys(r["case"] for r in rows):  # in the order of the CSVs
        methods = list(dict.fromkeys(r["method"] for r in rows if r["case"] == case))
        n = {m: stats[case, m, PARAMS[0]]["n"] for m in methods if (case, m, PARAMS[0]) in stats}
        print(f"\n### {case} ({', '.join(f'{m} {k} maneuvers' for m, k in n.items())})\n")
        print("| parameter | method | coverage % | SE/scatter | bias/scatter | false conv. % (flagged) "
              "| median flag time, s | scatter | robust SE/scatter | z std | flagged at the end % |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for p in PARAMS:
            for m in methods:
                s = stats.get((case, m, p))
                if s is None:
                    continue
                print(f"| {p} | {m} | {s['coverage']:.0f} | {s['se_scatter']:.2f} | {s['bias_scatter']:+.2f} | "
                      f"{s['false']:.0f} ({s['flagged']}) | {s['flag_time']:.2f} | {s['scatter']:.3g} | "
                      f"{s['robust_se_scatter']:.2f} | {s['z_std']:.2f} | {s['converged_end']:.0f} |")
        missing = {(m, p): k for m in methods for p in PARAMS
                   if (k := sum(1 for r in rows if (r["case"], r["method"], r["parameter"]) == (case, m, p)
                                and not np.isfinite(r["estimate"])))}
        if missing:
            print("\nmaneuvers without an estimate: " + ", ".join(f"{p} {m} {k}" for (m, p), k in missing.items()))
        if "RLS" in methods:
            rls, iv = _cost(rows, case)
            print(f"\npipeline time per estimator sample: RLS {rls:.0f} us, IV {iv:.0f} us, IV / RLS {iv / rls:.2f}")


def figure(args: argparse.Namespace) -> None:
    rows = _read(args.csv)
    stats = statistics(rows)
    cases = list(dict.fromkeys(r["case"] for r in rows))
    fig, axes = plt.subplots(3, len(cases), figsize=(4.2 * len(cases), 8), squeeze=False)
    x = np.arange(len(PARAMS))
    for c, case in enumerate(cases):
        for r, (key, label, goal) in enumerate((("coverage", "coverage of truth, %", (93, None)),
                                                 ("se_scatter", "SE / scatter", (0.85, 1.20)),
                                                 ("false", "false convergence, %", (None, 5)))):
            ax = axes[r, c]
            for k, m in enumerate(("RLS", "IV")):
                ax.bar(x + (k - 0.5) * 0.38, [stats[case, m, p][key] for p in PARAMS], 0.38, label=m)
                if key == "se_scatter":  # the robust ratio as a black tick on each bar
                    ax.plot(x + (k - 0.5) * 0.38, [stats[case, m, p]["robust_se_scatter"] for p in PARAMS], "k_",
                            ms=12, label="robust" if k else None)
            for g in goal:
                if g is not None:
                    ax.axhline(g, color="k", lw=0.8, ls="--")
            ax.set_xticks(x, [p.replace("_", "\n", 1) for p in PARAMS], fontsize=7)
            ax.set_ylabel(label)
            if r < 2:
                ax.legend(fontsize=7)
            if r == 0:
                ax.set_title(case, fontsize=9)
    fig.tight_layout()
    fig.savefig(args.png, dpi=110)


# ---------------------------------------------------------------- the frequency domain
def one_maneuver_fd(job: tuple[str, str]) -> list[dict]:
    """The maneuver through both configurations with ``estimator.method: frequency``: the rows
    of ``run`` (:func:`_rows`) of the frequency-domain outputs, whose flags are the second
    monitor's (docs/node.md, the convergence flags of the frequency domain)."""
    case, bag = job
    params = {m: {**_params(c), "estimator.method": "frequency"} for m, c in CONFIGS.items()}
    with InputStream(bag, dict(node_config(params["IV"]).topics)) as stream:
        t0 = stream.t0
        messages = list(stream)
    rows = []
    for method in ("RLS", "IV"):
        msgs = messages if method == "IV" else [m for m in messages if m[0] != "excitation"]
        start = time.perf_counter()
        result = run_pipeline(msgs, pipeline_config(params[method]), record=False, keep_outputs=True)
        seconds = time.perf_counter() - start
        rows += _rows(case, Path(bag).name, method, result, t0, seconds, domain="frequency")
    return rows


def fd_run(args: argparse.Namespace) -> None:
    args.case = f"{args.case or Path(args.campaign).name}, frequency domain"
    run(args, one_maneuver_fd)


def fd_table(args: argparse.Namespace) -> None:
    """``table`` of the CSVs of ``fd``; with ``--against``, the last of them against the
    time-domain CSV of ``run`` on the same maneuvers."""
    table(args)
    if args.against:
        fd_against(_read(args.csv[-1:]), _read([args.against]))


def _mad(x: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def fd_against(fd_rows: list[dict], time_rows: list[dict]) -> None:
    """The last CSV of ``fd`` against the time-domain CSV of ``run`` on the same maneuvers: the
    ratios of the standard deviations, of the typical (MAD) scatters and of the median SEs, and
    the largest SE over the median SE of each domain."""
    print("\n| parameter | method | scatter, frequency / time | typical scatter, frequency / time "
          "| median SE, frequency / time | largest SE / median SE, frequency | the same, time |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for p in PARAMS:
        for m in ("RLS", "IV"):
            fd = {r["maneuver"]: (r["estimate"], r["se"]) for r in fd_rows
                  if r["method"] == m and r["parameter"] == p}
            td = {r["maneuver"]: (r["estimate"], r["se"]) for r in time_rows
                  if r["method"] == m and r["parameter"] == p}
            both = [k for k in fd if k in td and np.isfinite(fd[k][0]) and np.isfinite(td[k][0])]
            (fe, fs), (te, ts) = (np.array([d[k] for k in both]).T for d in (fd, td))
            print(f"| {p} | {m} | {fe.std(ddof=1) / te.std(ddof=1):.2f} | {_mad(fe) / _mad(te):.2f} | "
                  f"{np.median(fs) / np.median(ts):.2f} | {fs.max() / np.median(fs):.3g} | "
                  f"{ts.max() / np.median(ts):.3g} |")


# ---------------------------------------------------------------- the Twin Otter recordings
RECORDINGS = {  # recording: (configuration, extra parameters)
    "totter_f1_017": ("twin_otter_lateral", {}),
    "totter_f1_014": ("twin_otter_lateral", {"aircraft": "twin_otter_f1_014"}),
    "totter_9752ed20": ("twin_otter_longitudinal", {}),
}
IV = {"estimator.algorithm": "iv", "instruments.source": "delayed"}
IV_EXCITATION = {**IV, "instruments.source": "excitation"}
FLIGHT_DATA = {"path": Path(os.environ.get("RLS_FLIGHT_DATA") or ROOT.parent / "shared" / "flight_data")}


@cache
def _work() -> Path:
    """A directory for the converted recordings, removed at exit."""
    work = Path(tempfile.mkdtemp(prefix="iv_flight_"))
    atexit.register(shutil.rmtree, work, True)
    return work


@cache
def flight_messages(recording: str, with_excitation: bool = False) -> list:
    """The converted recording's messages (with the surfaces repeated on the excitation input)."""
    bag = _work() / recording
    if not bag.exists():
        convert(FLIGHT_DATA["path"] / recording, ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml", bag)
    out = []
    for kind, stamp, msg in read_inputs(bag)[0]:
        out.append((kind, stamp, msg))
        if with_excitation and kind == "control_surfaces":
            out.append(("excitation", stamp, msg))
    return out


def flight_run(recording: str, extra: dict) -> Any:
    config, own = RECORDINGS[recording]
    params = {**load_parameters_file(config), **own, **extra}
    return run_pipeline(flight_messages(recording, extra.get("instruments.source") == "excitation"),
                        pipeline_config(params), record=True).pipeline


def _rho(pipe) -> str:
    rho = pipe.instrument_strength
    return "" if rho is None else ", ".join(f"{m.output} {r:.2f}" for m, r in zip(pipe.models, rho, strict=True))


def flight_table(_args: argparse.Namespace) -> None:
    for recording in RECORDINGS:
        variants = {"RLS": flight_run(recording, {}), "IV": flight_run(recording, IV)}
        if RECORDINGS[recording][0].endswith("longitudinal"):
            variants["IV, auxiliary model"] = flight_run(recording, IV_EXCITATION)
        rls = variants["RLS"]
        names = [(j, i, p) for j, ps in enumerate(rls.parameter_names) for i, p in enumerate(ps)]
        others = [v for v in variants if v != "RLS"]
        print(f"\n#### {recording} ({RECORDINGS[recording][0]})\n")
        print("| parameter | RLS estimate +- SE | " + " | ".join(f"{v} estimate +- SE | {v} SE / RLS SE | "
                                                              f"{v} - RLS, in {v} SE" for v in others) + " |")
        print("| --- | --- |" + " --- | --- | --- |" * len(others))
        for j, i, p in names:
            e0, s0 = rls.last.theta[j, i], rls.last.se[j, i]
            cells = [f"{e0:.4g} +- {s0:.2g}"]
            for v in others:
                e, s = variants[v].last.theta[j, i], variants[v].last.se[j, i]
                cells += [f"{e:.4g} +- {s:.2g}", f"{s / s0:.1f}", f"{(e - e0) / s:+.2f}"]
            print(f"| {p} | " + " | ".join(cells) + " |")
        for v in others:
            print(f"\n{v}: rho_min {_rho(variants[v])}; {variants[v].samples_used} samples used "
                  f"(RLS {rls.samples_used})")


def _flight_rows(pipe) -> tuple[np.ndarray, np.ndarray]:
    return np.array([r[1] for r in pipe.regression]), np.array([r[2] for r in pipe.regression])


def _rms(theta: np.ndarray, X: np.ndarray, z: np.ndarray, j: int, n: int) -> float:
    e = z[:, j] - X[:, j, :n] @ theta[j, :n]
    return float(np.sqrt(np.mean(e * e)))


def flight_prediction(_args: argparse.Namespace) -> None:
    pairs = (("totter_f1_017", "totter_f1_014"), ("totter_f1_014", "totter_f1_017"))
    print("| estimates from | predicting | model | RLS fit RMS (own) | IV fit RMS (own) | RLS prediction RMS "
          "| IV prediction RMS | IV / RLS prediction |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for source, target in pairs:
        fits = {m: flight_run(source, extra) for m, extra in (("RLS", {}), ("IV", IV))}
        X, z = _flight_rows(flight_run(target, {}))
        for j, model in enumerate(fits["RLS"].models):
            n = len(model.regressors)
            own = {m: _rms(p.last.theta, *_flight_rows(p), j, n) for m, p in fits.items()}
            pred = {m: _rms(p.last.theta, X, z, j, n) for m, p in fits.items()}
            print(f"| {source} | {target} | {model.output} | {own['RLS']:.3g} | {own['IV']:.3g} | "
                  f"{pred['RLS']:.3g} | {pred['IV']:.3g} | {pred['IV'] / pred['RLS']:.3f} |")


KEY = ("CY_beta", "Cl_beta", "Cl_p", "Cl_r", "Cl_delta_a", "Cn_beta", "Cn_r", "Cn_delta_r", "CZ_alpha", "Cm_alpha",
       "Cm_q", "Cm_delta_e")


def flight_delays(_args: argparse.Namespace) -> None:
    for recording in RECORDINGS:
        pipes = {"RLS": flight_run(recording, {})}
        for span in (0.1, 0.2, 0.5, 1.0):
            pipes[f"{span:g} s"] = flight_run(recording, {**IV, "instruments.delay_span": span})
        names = [(j, i, p) for j, ps in enumerate(pipes["RLS"].parameter_names) for i, p in enumerate(ps)
                 if p in KEY]
        print(f"\n#### {recording}\n")
        print("| delay | rho_min | " + " | ".join(p for _j, _i, p in names) + " |")
        print("| --- | --- |" + " --- |" * len(names))
        for label, pipe in pipes.items():
            rho = _rho(pipe)
            cells = [f"{pipe.last.theta[j, i]:.4g} +- {pipe.last.se[j, i]:.2g}" for j, i, _p in names]
            print(f"| {label} | {rho} | " + " | ".join(cells) + " |")



def quick() -> None:
    """Four maneuvers of the severe campaign, made by ``make-bag``, through both methods."""
    with tempfile.TemporaryDirectory() as tmp:
        bags, out = Path(tmp) / "severe", Path(tmp) / "quick.csv"
        subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "make-bag", "--campaign", "4", "--gust-intensity",
                        "severe", "--seed", "2010", "--out", str(bags), "--quiet"], check=True, cwd=ROOT)
        run(argparse.Namespace(campaign=str(bags), count=4, case="severe (quick, 4 maneuvers)", workers=2, out=out))
        table(argparse.Namespace(csv=[str(out)]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="four maneuvers of the severe campaign, no files kept")
    sub = ap.add_subparsers(dest="command")
    r = sub.add_parser("run", help="one campaign through both methods into a CSV")
    r.add_argument("campaign")
    r.add_argument("--count", type=int, default=200, help="the first COUNT maneuvers")
    r.add_argument("--case", help="the case's name in the tables (default: the directory's)")
    r.add_argument("--workers", type=int, default=2)
    r.add_argument("--levers", action="store_true", help="IV at its defaults and with each of LEVERS instead")
    r.add_argument("--out", required=True)
    t = sub.add_parser("table", help="the tables of the CSVs")
    t.add_argument("csv", nargs="+")
    t.add_argument("--flagged", action="store_true", help="only the maneuvers whose parameter is flagged at the end")
    f = sub.add_parser("figure", help="coverage, SE / scatter and false convergence per case")
    f.add_argument("csv", nargs="+")
    f.add_argument("--png", required=True)
    d = sub.add_parser("fd", help="one campaign through both methods in the frequency domain into a CSV")
    d.add_argument("campaign")
    d.add_argument("--count", type=int, default=200, help="the first COUNT maneuvers")
    d.add_argument("--case", help="the case's name in the tables (default: the directory's)")
    d.add_argument("--workers", type=int, default=2)
    d.add_argument("--out", required=True)
    e = sub.add_parser("fd-table", help="the tables of the frequency-domain CSVs")
    e.add_argument("csv", nargs="+")
    e.add_argument("--against", help="a CSV of run on the same campaign: the last CSV against the time domain")
    g = sub.add_parser("flight", help="the three Twin Otter recordings, RLS and IV")
    g.add_argument("what", choices=("table", "prediction", "delays"))
    g.add_argument("--flight-data", default=str(FLIGHT_DATA["path"]))
    args = ap.parse_args()
    if args.command == "flight":
        FLIGHT_DATA["path"] = Path(args.flight_data)
        {"table": flight_table, "prediction": flight_prediction, "delays": flight_delays}[args.what](args)
    elif args.quick:
        quick()
    elif args.command is None:
        ap.error("a command (run, table, figure, fd, fd-table, flight) or --quick")
    else:
        {"run": run, "table": table, "figure": figure, "fd": fd_run, "fd-table": fd_table}[args.command](args)


if __name__ == "__main__":
    main()
