"""Markdown tables of the study's results (``study.py report`` writes ``tables.md``).

Imported by ``study.py report`` (which puts this directory on ``sys.path``), never by the
modules it imports, so importing them here is not circular."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from study import FORGETTING, true_autocovariance
from transients import table

NOISE_LABEL = {
    "white": "white",
    "ar2": "AR(1) tau=2",
    "ar5": "AR(1) tau=5",
    "ar10": "AR(1) tau=10",
    "ar20": "AR(1) tau=20",
    "ar50": "AR(1) tau=50",
    "bl2": "band-limited 2 Hz",
    "bl1": "band-limited 1 Hz",
    "bl05": "band-limited 0.5 Hz",
}


def _load(results: Path, name: str):
    p = results / name
    return json.loads(p.read_text()) if p.exists() else None


def _cell(s, key, what="ratio"):
    if key not in s:
        return "-"
    v = s[key]
    r = "/".join(f"{x:.2f}" for x in v["ratio"])
    c = "/".join(f"{100 * x:.0f}" for x in v["coverage"])
    return f"{r} ({c})"


def weighted_share(f: float, noise: str, n_lags: int = 50) -> float:
    """Share of ``sum_i f^|i| gamma(i)`` (the bias parameter's long-run variance seen through
    the forgetting window) within ``|i| <= n_lags``."""
    g = true_autocovariance(noise)
    w = f ** np.arange(len(g)) * g
    return float((w[0] + 2 * w[1 : n_lags + 1].sum()) / (w[0] + 2 * w[1:].sum()))


def main_table(results: Path) -> list[str]:
    lines = [
        "| f | noise | LRV share in 50 lags (f-weighted) | current: SE/true (2-SE coverage %) | "
        "fix: SE/true (coverage %) | fix SE spread (CV) |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for f in FORGETTING:
        for nz in ("white", "ar2", "ar5", "ar10", "ar20", "bl2", "bl1"):
            s = _load(results, f"f{f}_{nz}.json")
            if s is None:
                continue
            cv = "/".join(f"{x:.2f}" for x in s["fix"]["cv"])
            lines.append(
                f"| {f} | {NOISE_LABEL[nz]} | {s['config']['lags_share']:.3f} ({weighted_share(f, nz):.3f}) | "
                f"{_cell(s, 'bank')} | {_cell(s, 'fix')} | {cv} |"
            )
    return lines


VARIANTS = [
    ("oracle_all", "exact (true Sigma, all lags)"),
    ("oracle_L", "true gamma, lags <= 50 (ii)"),
    ("bank", "current bank"),
    ("df", "current x n_eff/(n_eff - p_eff) (i, dof)"),
    ("batch_post", "weighted batch, a posteriori residuals (i)"),
    ("bankres_fR", "bank residuals, weights f_R (i: notch)"),
    ("noise_f", "true noise, weights f (iii)"),
    ("noise_fR", "true noise, weights f_R (iii)"),
    ("noisemodel_f", "noise-model residuals, weights f"),
    ("fix", "noise-model residuals, weights f_R (fix)"),
    ("fix_level", "fix, level from the short memory (option)"),
    ("bank_conv", "current conventional"),
    ("fix_conv", "fix conventional"),
]


def attribution_table(results: Path, names) -> list[str]:
    heads = []
    data = []
    for name in names:
        s = _load(results, name)
        if s is None:
            continue
        c = s["config"]
        heads.append(f"f={c['f']}, {NOISE_LABEL[c['noise']]}")
        data.append(s)
    lines = ["| variant (R used in the sandwich) | " + " | ".join(heads) + " |",
             "| --- | " + " | ".join("---" for _ in heads) + " |"]
    for key, label in VARIANTS:
        lines.append(f"| {label} | " + " | ".join(_cell(s, key) for s in data) + " |")
    lines.append("| MC std / exact | "
                 + " | ".join("/".join(f"{x:.2f}" for x in s["mc_over_true"]) for s in data) + " |")
    lines.append("| n_eff = sum f^(k-j); p_eff = tr(D Lambda(0)) | "
                 + " | ".join(f"{s['n_eff']:.0f}; {s.get('p_eff', float('nan')):.2f}" for s in data) + " |")
    return lines


def extra_table(results: Path) -> list[str]:
    lines = ["| case | current: SE/true (coverage %) | fix: SE/true (coverage %) | "
             "true gamma, 50 lags: SE/true (coverage %) | LRV share in 50 lags (f-weighted) |",
             "| --- | --- | --- | --- | --- |"]
    for p in sorted(results.glob("f*.json")):
        s = json.loads(p.read_text())
        c = s["config"]
        tag = p.stem.split("_", 2)[2] if p.stem.count("_") >= 2 else ""
        if tag in ("sweep", "level"):
            continue
        if not tag and c["noise"] not in ("ar50", "bl05") and c["f"] != 1.0:
            continue
        label = f"f={c['f']}, {NOISE_LABEL[c['noise']]}" + (f", {tag}" if tag else "")
        if c["f"] < 1:
            share = f"{c['lags_share']:.3f} ({weighted_share(c['f'], c['noise']):.3f})"
        else:
            share = f"{c['lags_share']:.3f}"
        lines.append(f"| {label} | {_cell(s, 'bank')} | {_cell(s, 'fix')} | {_cell(s, 'oracle_L')} | {share} |")
    return lines


def sweep_table(results: Path) -> list[str]:
    lines = ["| case | f_R | SE/true (coverage %) | CV of SE |", "| --- | --- | --- | --- |"]
    for p in sorted(results.glob("*_sweep.json")):
        s = json.loads(p.read_text())
        c = s["config"]
        for fr in c["f_R_sweep"]:
            key = f"sweep_{fr}"
            cv = "/".join(f"{x:.2f}" for x in s[key]["cv"])
            lines.append(f"| f={c['f']}, {NOISE_LABEL[c['noise']]} | {fr} | {_cell(s, key)} | {cv} |")
        cv = "/".join(f"{x:.2f}" for x in s["bank"]["cv"])
        lines.append(f"| f={c['f']}, {NOISE_LABEL[c['noise']]} | {c['f']} (current) | {_cell(s, 'bank')} | {cv} |")
    return lines


def write_tables(results: Path, out: Path) -> None:
    parts = ["# Generated tables (study.py report)", "",
             "Cells: bias / alpha / delta_e parameter; SE/true = mean corrected SE over runs / exact "
             "sampling std, averaged over checkpoints; coverage = share of |error| < 2 SE.", "",
             "## Main grid", "", *main_table(results)]
    parts += ["", "## Attribution", "", *attribution_table(
        results, ["f0.95_white_level.json", "f0.98_white_level.json", "f0.98_ar5_level.json", "f0.98_bl2_level.json",
                  "f0.99_ar10_level.json", "f0.995_bl2_level.json", "f0.999_ar5_level.json", "f0.999_bl1_level.json"])]
    parts += ["", "## Limits, residual kinds, windows, f = 1", "", *extra_table(results)]
    parts += ["", "## Noise memory f_R", "", *sweep_table(results)]
    parts += ["", "## Soak (soak.py)", "", *soak_table(results)]
    parts += ["", "## Transients (transients.py)", "", *transient_tables(results)]
    out.write_text("\n".join(parts) + "\n")
    print(out.read_text())


def soak_table(results: Path) -> list[str]:
    s = _load(results, "soak.json")
    if s is None:
        return []

    def cell(a, c):
        return "/".join(f"{x:.2f}" for x in a) + " (" + "/".join(f"{100 * x:.0f}" for x in c) + ")"

    lines = [f"{s['n_samples']} samples, f = {s['f']}, {s['n_lags']} lags, f_R = {s['f_R']:.5f}, "
             f"{s['checkpoints']} checkpoints (every 250 samples after 10 000)", "",
             "| noise | std over time / exact | current SE/true (coverage %) | fix SE/true (coverage %) |",
             "| --- | --- | --- | --- |"]
    for nz, r in s["noises"].items():
        lines.append(f"| {NOISE_LABEL[nz]} | {'/'.join(f'{x:.2f}' for x in r['time_std_over_true'])} | "
                     f"{cell(r['current_ratio'], r['current_coverage'])} | {cell(r['fix_ratio'], r['fix_coverage'])} |")
    return lines


def transient_tables(results: Path) -> list[str]:
    lines = []
    for kind in ("noise_step", "parameter_step"):
        s = _load(results, f"transient_{kind}.json")
        if s is not None:
            lines += [*table(s), ""]
    return lines
