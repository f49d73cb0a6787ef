"""The three Twin Otter recordings with RLS and recursive instrumental variables side by side.
Report: REPORT.md beside this file, "The Twin Otter recordings".

Each recording (``../shared/flight_data``, ``$RLS_FLIGHT_DATA`` or ``--flight-data``) is
converted with the shipped mapping and its messages go through the replay's data path
(``run_pipeline``, the function behind ``rls-uncertainty replay``) with its configuration
(``config/twin_otter_lateral.yaml``, ``config/twin_otter_longitudinal.yaml``) as shipped (RLS)
and with ``estimator.algorithm: iv`` (``instruments.source: delayed``: the measured surfaces for
themselves and the other regressors ``instruments.delay_span`` earlier; for the lateral models
``auto`` picks the same). The longitudinal one is run a third time with the short-period
auxiliary model driven by the measured surfaces (``instruments.source: excitation``, the
surfaces repeated on the excitation input), the instruments of the simulated study.

    python docs/studies/instrumental_variables/flight.py table        # per recording, end of maneuver
    python docs/studies/instrumental_variables/flight.py prediction   # the lateral estimates across the repeat
    python docs/studies/instrumental_variables/flight.py delays       # instruments.delay_span 0.1 .. 1 s

``prediction``: the estimates at the end of one lateral recording predict the other's
coefficients from its regressors (the same rows the estimator took); the RMS of the
prediction error per model, against that of the recording's own fit. ``delays``: the smallest
canonical correlation between instruments and regressors (``rho_min``, weak below
``instruments.weak_below``) and the end estimates of the key derivatives per delay.
"""

from __future__ import annotations

import argparse
import atexit
import os
import shutil
import tempfile
from functools import cache
from pathlib import Path

import numpy as np

from rls_uncertainty.offline.bags import convert, read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config

ROOT = Path(__file__).resolve().parents[3]
RECORDINGS = {  # recording: (configuration, extra parameters)
    "totter_f1_017": ("twin_otter_lateral", {}),
    "totter_f1_014": ("twin_otter_lateral", {"aircraft": "twin_otter_f1_014"}),
    "totter_9752ed20": ("twin_otter_longitudinal", {}),
}
IV = {"estimator.algorithm": "iv", "instruments.source": "delayed"}
IV_EXCITATION = {**IV, "instruments.source": "excitation"}
FLIGHT_DATA = {"path": Path(os.environ.get("RLS_FLIGHT_DATA") or ROOT.parent / "shared" / "flight_data")}
WORK = Path(tempfile.mkdtemp(prefix="iv_flight_"))  # the converted recordings
atexit.register(shutil.rmtree, WORK, True)


@cache
def messages(recording: str, with_excitation: bool = False) -> list:
    """The converted recording's messages (with the surfaces repeated on the excitation input)."""
    bag = WORK / recording
    if not bag.exists():
        convert(FLIGHT_DATA["path"] / recording, ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml", bag)
    out = []
    for kind, stamp, msg in read_inputs(bag)[0]:
        out.append((kind, stamp, msg))
        if with_excitation and kind == "control_surfaces":
            out.append(("excitation", stamp, msg))
    return out


def run(recording: str, extra: dict) -> object:
    config, own = RECORDINGS[recording]
    params = {**load_parameters_file(config), **own, **extra}
    return run_pipeline(messages(recording, extra.get("instruments.source") == "excitation"),
                        pipeline_config(params), record=True).pipeline


def _rho(pipe) -> str:
    iv = pipe._iv
    return ", ".join(f"{m.output} {r:.2f}" for m, r in zip(pipe.models, iv.rho_min, strict=True))


def table(_args: argparse.Namespace) -> None:
    for recording in RECORDINGS:
        variants = {"RLS": run(recording, {}), "IV": run(recording, IV)}
        if RECORDINGS[recording][0].endswith("longitudinal"):
            variants["IV, auxiliary model"] = run(recording, IV_EXCITATION)
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


def _rows(pipe) -> tuple[np.ndarray, np.ndarray]:
    return np.array([r[1] for r in pipe.regression]), np.array([r[2] for r in pipe.regression])


def _rms(theta: np.ndarray, X: np.ndarray, z: np.ndarray, j: int, n: int) -> float:
    e = z[:, j] - X[:, j, :n] @ theta[j, :n]
    return float(np.sqrt(np.mean(e * e)))


def prediction(_args: argparse.Namespace) -> None:
    pairs = (("totter_f1_017", "totter_f1_014"), ("totter_f1_014", "totter_f1_017"))
    print("| estimates from | predicting | model | RLS fit RMS (own) | IV fit RMS (own) | RLS prediction RMS "
          "| IV prediction RMS | IV / RLS prediction |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for source, target in pairs:
        fits = {m: run(source, extra) for m, extra in (("RLS", {}), ("IV", IV))}
        X, z = _rows(run(target, {}))
        for j, model in enumerate(fits["RLS"].models):
            n = len(model.regressors)
            own = {m: _rms(p.last.theta, *_rows(p), j, n) for m, p in fits.items()}
            pred = {m: _rms(p.last.theta, X, z, j, n) for m, p in fits.items()}
            print(f"| {source} | {target} | {model.output} | {own['RLS']:.3g} | {own['IV']:.3g} | "
                  f"{pred['RLS']:.3g} | {pred['IV']:.3g} | {pred['IV'] / pred['RLS']:.3f} |")


KEY = ("CY_beta", "Cl_beta", "Cl_p", "Cl_r", "Cl_delta_a", "Cn_beta", "Cn_r", "Cn_delta_r", "CZ_alpha", "Cm_alpha",
       "Cm_q", "Cm_delta_e")


def delays(_args: argparse.Namespace) -> None:
    for recording in RECORDINGS:
        pipes = {"RLS": run(recording, {})}
        for span in (0.1, 0.2, 0.5, 1.0):
            pipes[f"{span:g} s"] = run(recording, {**IV, "instruments.delay_span": span})
        names = [(j, i, p) for j, ps in enumerate(pipes["RLS"].parameter_names) for i, p in enumerate(ps)
                 if p in KEY]
        print(f"\n#### {recording}\n")
        print("| delay | rho_min | " + " | ".join(p for _j, _i, p in names) + " |")
        print("| --- | --- |" + " --- |" * len(names))
        for label, pipe in pipes.items():
            rho = _rho(pipe) if pipe._iv is not None else ""
            cells = [f"{pipe.last.theta[j, i]:.4g} +- {pipe.last.se[j, i]:.2g}" for j, i, _p in names]
            print(f"| {label} | {rho} | " + " | ".join(cells) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("command", choices=("table", "prediction", "delays"))
    ap.add_argument("--flight-data", default=str(FLIGHT_DATA["path"]))
    args = ap.parse_args()
    FLIGHT_DATA["path"] = Path(args.flight_data)
    {"table": table, "prediction": prediction, "delays": delays}[args.command](args)


if __name__ == "__main__":
    main()
