"""The automatic lag count and the residual burn-in (``estimator.lag_selection: auto``,
``estimator.residual_burn_in_span``) against fixed lags. Report: REPORT.md beside this file.

Part 1, the paper's Table 3 Monte Carlo (Section IV.A; the seeds of ``rls-uncertainty
montecarlo``): every run's C_Z and C_m models go through one bank per variant, and at the end
of the maneuver each Table 3 parameter's mean corrected standard error over the runs is divided
by the observed scatter (standard deviation of the final estimates over the runs). A ratio of
1 is an honest standard error; with 250 runs a ratio carries about +-4.5 % (1 sigma) of
sampling error. Also the lags the rule chose and where each model initialized.

Part 2 (``--flight DIR``, DIR holding the Twin Otter recordings ``totter_f1_017`` and
``totter_f1_014``): each recording is converted and replayed with the command line
(``config/twin_otter_lateral.yaml``, the recording's aircraft file) for each variant, and the
end-of-maneuver lags and corrected standard errors are compared.

    .venv/bin/python docs/studies/automatic_lags/study.py --flight ../shared/flight_data
    .venv/bin/python docs/studies/automatic_lags/study.py --quick      # 20 runs, 0 % and 20 %, no flight data
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.estimator.options import EstimatorOptions
from rls_uncertainty.simulation.montecarlo import LEVELS, PARAMETERS, level_inputs, parameter_cells

ROOT = Path(__file__).resolve().parents[3]
BAND = (0.8, 1.25)  # the honest-enough range of corrected SE / scatter used throughout
VARIANTS = {
    "auto (default burn-in 50)": EstimatorOptions(lags="auto"),
    "auto, burn-in 0": EstimatorOptions(lags="auto", residual_burn_in=0),
    "50 lags (the paper)": EstimatorOptions(lags=50),
    "50 lags, burn-in 50": EstimatorOptions(lags=50, residual_burn_in=50),
    "all lags (Eq. 20)": EstimatorOptions(lags="all"),
}
AUTO, FIXED = "auto (default burn-in 50)", "50 lags (the paper)"
# replay options of each variant in part 2
REPLAYS = {
    "auto": ["--lag-span", "auto"],
    "auto, burn-in 0": ["--lag-span", "auto", "--burn-in-span", "0"],
    "50 lags": ["--lag-span", "1.0"],
    "all lags": ["--lag-span", "all"],
    "auto, max 100": ["--lag-span", "auto", "--max-lag-span", "2.0"],
}
RECORDINGS = ("totter_f1_017", "totter_f1_014")


def table3_level(level: float, runs: int) -> dict[str, np.ndarray]:
    """Corrected SE / scatter of every variant (and the conventional SE of 50 lags), the
    chosen lags of auto and the initialization samples, at one noise level."""
    _t, _reductions, sizes, X, Z = level_inputs(level, runs)
    banks = {name: EstimatorBank(sizes, options) for name, options in VARIANTS.items()}
    for k in range(X.shape[0]):
        for bank in banks.values():
            bank.update(X[k], Z[k])
    rows, cols = parameter_cells(runs)
    theta = banks[FIXED].theta_all()[rows, cols]
    scatter = theta.std(axis=0, ddof=1)
    out = {name: b.standard_errors_all("corrected")[rows, cols].mean(axis=0) / scatter for name, b in banks.items()}
    out["conventional"] = banks[FIXED].standard_errors_all("conventional")[rows, cols].mean(axis=0) / scatter
    out["lags"] = banks[AUTO].lags_used.reshape(runs, -1)
    out["ready_at"] = banks[AUTO].ready_at.reshape(runs, -1)
    return out


def part1(levels: tuple[float, ...], runs: int) -> None:
    names = [*VARIANTS, "conventional"]
    results = {}
    print(f"## Table 3 Monte Carlo, {runs} runs per level: corrected SE / observed scatter at the end\n")
    print("| level | parameter | " + " | ".join(names) + " |")
    print("| --- | --- |" + " --- |" * len(names))
    for level in levels:
        t0 = time.perf_counter()
        results[level] = r = table3_level(level, runs)
        for i, p in enumerate(PARAMETERS):
            cells = [f"**{x:.2f}**" if not BAND[0] <= x <= BAND[1] else f"{x:.2f}" for x in (r[n][i] for n in names)]
            print(f"| {level * 100:.0f}% | {p} | " + " | ".join(cells) + " |", flush=True)
        print(f"level {level * 100:.0f}%: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    print(f"\nbold: outside [{BAND[0]}, {BAND[1]}]; sampling error of a ratio from {runs} runs: "
          f"+-{100 / np.sqrt(2 * (runs - 1)):.1f} % (1 sigma)\n")
    for n in names:
        x = np.concatenate([results[lv][n] for lv in levels])
        outside = int(np.sum((x < BAND[0]) | (x > BAND[1])))
        print(f"- {n}: {x.min():.2f}-{x.max():.2f}, {outside} of {x.size} cells outside")
    print("\nLags chosen by auto at the end (over the runs) and the sample each model initialized at:\n")
    print("| level | model | min | 10% | median | 90% | max | at the cap (50) | initialized at |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for level in levels:
        L, k0 = results[level]["lags"], results[level]["ready_at"]
        for m, model in enumerate(("CZ", "Cm")):
            q = np.percentile(L[:, m], [0, 10, 50, 90, 100])
            print(f"| {level * 100:.0f}% | {model} | " + " | ".join(f"{x:.0f}" for x in q)
                  + f" | {100 * np.mean(L[:, m] == 50):.0f}% | {k0[:, m].min()}-{k0[:, m].max()} |")


def cli(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", *args], check=True, stdout=subprocess.DEVNULL)


def final_rows(estimates_csv: Path) -> dict[str, dict[str, str]]:
    """The last row of every parameter in a replay's estimates.csv."""
    with estimates_csv.open() as fh:
        return {row["parameter"]: row for row in csv.DictReader(fh)}


def part2(flight: Path, work: Path) -> None:
    base = yaml.safe_load((ROOT / "config" / "twin_otter_lateral.yaml").read_text())
    mapping = str(ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml")
    for rec in RECORDINGS:
        bag, config = work / rec, work / f"{rec}.yaml"
        cli("convert", str(flight / rec), "--mapping", mapping, "--out", str(bag))
        base["/**"]["ros__parameters"]["aircraft"] = "twin_otter_" + rec.split("_", 1)[1]
        config.write_text(yaml.safe_dump(base))
        final = {}
        for name, opts in REPLAYS.items():
            out = work / f"{rec}_{name.replace(' ', '_').replace(',', '')}"
            cli("replay", str(bag), "--config", str(config), "--out", str(out), "--no-figures", "--quiet", *opts)
            final[name] = final_rows(out / "estimates.csv")
        print(f"\n## {rec}: end of the maneuver\n")
        print("| parameter | lags: " + " / ".join(REPLAYS) + " | SE " + " | SE ".join(REPLAYS)
              + " | auto / 50 lags | auto / auto burn-in 0 |")
        print("| --- | --- |" + " --- |" * (len(REPLAYS) + 2))
        for p in final["auto"]:
            se = {name: float(final[name][p]["std_error"]) for name in REPLAYS}
            lags = " / ".join(final[name][p]["lags"] for name in REPLAYS)
            print(f"| {p} | {lags} | " + " | ".join(f"{se[n]:.3g}" for n in REPLAYS)
                  + f" | {se['auto'] / se['50 lags']:.2f} | {se['auto'] / se['auto, burn-in 0']:.3f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="20 runs at 0 %% and 20 %%, no flight data")
    ap.add_argument("--runs", type=int, default=250, help="runs per noise level (default 250)")
    ap.add_argument("--flight", type=Path, help="directory holding totter_f1_017 and totter_f1_014")
    args = ap.parse_args()
    if args.quick:
        part1((0.0, 0.2), 20)
        return
    part1(LEVELS, args.runs)
    if args.flight:
        with tempfile.TemporaryDirectory(prefix="automatic_lags_") as work:
            part2(args.flight, Path(work))


if __name__ == "__main__":
    main()
