"""The identifiability tests of the convergence flags (``identifiability.*``): hostile inputs,
and the thresholds on a tuning set of the Table 3 Monte Carlo. Report: REPORT.md beside this
file.

``--cases``: each hostile input (a surface commanded twice, no maneuver, a constant regressor,
gyro spikes, an inconsistent dynamic pressure), built from the seeded T-2 maneuver of the bundled
bag (``simulation.simulate_sensor_streams(0.2, 250)``), fed message by message through the
node's pipeline; every second of data the node's own diagnostics policy takes a snapshot, as
the node and the replay do. Printed per case: the final estimates with their corrected
standard errors and convergence flags, each model's ``/diagnostics`` status, R^2, and every
WARN line the node logs (the alerts' ``due()`` lines, each at most once per 30 s). The same
command on an older checkout (``PYTHONPATH=<checkout>``) gives the "before" column: the script
only uses what that code has.

``--rates``: the bundled bag replayed (``config/t2.yaml``) at estimator rates of 50, 200 and
1000 Hz, fixed and automatic lags: the lags used and the corrected and conventional standard
errors at the end. On an older checkout the lags are 50 samples at every rate; here they are
``estimator.lag_span`` (1 s) at the rate.

``--flight DIR``: the NASA Twin Otter recordings in DIR (``../shared/flight_data``), converted
with the shipped mapping and replayed with their parameter files: per parameter whose first
flag the tests delayed, the first flag with and without them, the reason at that moment, and
the estimate at the untested flag against the end of the record.

``--montecarlo``: the Table 3 Monte Carlo with seed 7 (the reported one, seed 2016, judges the
defaults on runs they were not chosen on), 250 runs per level, for a grid of thresholds: per
level the fraction of runs whose first flag the tests delayed or withheld (held back) and the
largest delay of the median flag time, over the five Table 3 parameters.

    .venv/bin/python docs/studies/identifiability/study.py --cases
    .venv/bin/python docs/studies/identifiability/study.py --rates             # about 20 s
    .venv/bin/python docs/studies/identifiability/study.py --flight ../shared/flight_data
    .venv/bin/python docs/studies/identifiability/study.py --montecarlo          # about 15 min
    .venv/bin/python docs/studies/identifiability/study.py --quick               # both, small (under a minute)
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from rls_uncertainty.datapath.convergence import ConvergenceMonitor
from rls_uncertainty.datapath.diagnostics import DiagnosticsPolicy, Snapshot
from rls_uncertainty.datapath.inputs import feed as feed_message
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.offline.bags import convert, read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import PARAMETERS, load_parameters_file, node_config, package_path, pipeline_config
from rls_uncertainty.simulation.montecarlo import PARAMETERS as TABLE3
from rls_uncertainty.simulation.montecarlo import convergence_summary, run_level
from rls_uncertainty.simulation.t2 import SimulationConfig, simulate_sensor_streams

KINDS = ("imu", "airspeed", "dynamic_pressure", "control_surfaces", "thrust")
SURFACE_NAMES = ("elevator_left", "elevator_right", "aileron_left", "aileron_right", "rudder")
T2 = {"models.enabled": ["CZ", "Cm"], "surfaces.elevator": ["elevator_left", "elevator_right"]}
Events = list[tuple[int, str, np.ndarray]]


def events_of(st) -> Events:
    """Every message of a SensorStreams set in stamp order (stable by stream)."""
    out = []
    for r, kind in enumerate(KINDS):
        stamps, values = getattr(st, kind)
        out += [(int(stamps[k]), r, kind, np.asarray(values[k], dtype=float)) for k in range(stamps.size)]
    out.sort(key=lambda e: (e[0], e[1]))
    return [(t, kind, v) for t, _r, kind, v in out]


def with_stream(st, kind: str, values: np.ndarray):
    """``st`` with stream ``kind``'s values replaced."""
    stamps, _ = getattr(st, kind)
    return replace(st, **{kind: (stamps, values)})


# ----------------------------------------------------------------------------- hostile cases
def rudder_is_elevator(st, rng):
    """Rudder = elevator + 1e-6 rad of white noise (one surface commanded twice), C_Z on both."""
    srf = st.control_surfaces[1].copy()
    srf[:, 4] = srf[:, 0] + rng.normal(0.0, 1e-6, srf.shape[0])
    params = {**T2, "models.CZ": ["1", "alpha", "delta_e", "delta_r"]}
    return with_stream(st, "control_surfaces", srf), params


def no_maneuver(st, rng):
    """No maneuver: trim plus white sensor noise at the paper's wide-band signal-to-noise ratios of
    the maneuver's variation (q 30, alpha 12, a_z 40, elevator 40; Section IV.A)."""
    snr = SimulationConfig().snr
    imu = st.imu[1].copy()
    for col, name in ((1, "q"), (5, "az")):
        imu[:, col] = np.median(imu[:, col]) + rng.normal(0.0, imu[:, col].std() / snr[name], imu.shape[0])
    vel = st.airspeed[1].copy()
    alpha = np.arctan2(-vel[:, 2], vel[:, 0])
    speed = np.hypot(vel[:, 0], vel[:, 2])
    a = np.median(alpha) + rng.normal(0.0, alpha.std() / snr["alpha"], alpha.size)
    vel[:, 0], vel[:, 2] = speed * np.cos(a), -speed * np.sin(a)
    srf = st.control_surfaces[1].copy()
    de = np.median(srf[:, 0]) + rng.normal(0.0, srf[:, 0].std() / snr["delta_e"], srf.shape[0])
    srf[:, 0] = srf[:, 1] = de
    st = with_stream(with_stream(with_stream(st, "imu", imu), "airspeed", vel), "control_surfaces", srf)
    return st, dict(T2)


def constant_regressor(st, rng):
    """A regressor that never moves: C_Z with sideslip (the maneuver is longitudinal: beta = 0)."""
    return st, {**T2, "models.CZ": ["1", "alpha", "beta", "delta_e"]}


def gyro_spikes(st, rng):
    """Pitch-rate spikes of 19.999 rad/s (just under limits.angular_rate) on every 40th IMU
    message (5 Hz): the input checks may pass them; R^2 is the second line."""
    imu = st.imu[1].copy()
    imu[::40, 1] = -19.999  # REP-103 y = -q
    return with_stream(st, "imu", imu), dict(T2)


def inconsistent_dynamic_pressure(st, rng):
    """Dynamic pressure 5 Pa plus 1e-9 Pa steps, inconsistent with the airspeed (about 830 Pa)."""
    qbar = 5.0 + 1e-9 * np.arange(st.dynamic_pressure[1].size)
    return with_stream(st, "dynamic_pressure", qbar), dict(T2)


CASES: dict[str, Callable] = {
    "rudder = elevator + 1e-6 rad, C_Z on both": rudder_is_elevator,
    "no maneuver (sensor noise only)": no_maneuver,
    "a constant regressor (C_Z with beta)": constant_regressor,
    "gyro spikes of 19.999 rad/s": gyro_spikes,
    "dynamic pressure 5 Pa + 1e-9 Pa steps": inconsistent_dynamic_pressure,
}


def feed(pipe: Pipeline, stamp: int, kind: str, v: np.ndarray) -> list:
    if kind == "imu":
        return pipe.add_imu(stamp, v[:3], v[3:])
    if kind == "airspeed":
        return pipe.add_airspeed(stamp, v)
    if kind == "dynamic_pressure":
        return pipe.add_dynamic_pressure(stamp, float(v))
    if kind == "control_surfaces":
        return pipe.add_surfaces(stamp, list(SURFACE_NAMES), v)
    return pipe.add_thrust(stamp, float(v))


def snapshot(pipe: Pipeline, node, now_ns: int, elapsed: float) -> Snapshot:
    return Snapshot(
        counters=pipe.counters(), models=[(m.output, pipe.model_report(j)) for j, m in enumerate(pipe.models)],
        required=tuple(pipe.required), max_gap=pipe.config.inputs.max_gap, now_ns=now_ns, elapsed_s=elapsed,
        publishers=dict.fromkeys(node.topics, 1), topics=dict(node.topics), reliable=node.reliable, enabled=True,
        state_file="study: no state file",
    )


def run_case(name: str, build: Callable) -> None:
    st, params = build(simulate_sensor_streams(0.2, 250), np.random.default_rng(19))
    known = {p.name for p in PARAMETERS}
    params = {k: v for k, v in params.items() if k in known}
    pipe, node = Pipeline(pipeline_config(params)), node_config(params)
    policy = DiagnosticsPolicy(window_s=node.diagnostics_window)
    period = round(node.diagnostics_period * 1e9)
    start = last_diag = None
    warnings: list[tuple[float, str]] = []
    last = None
    for stamp, kind, v in events_of(st):
        outs = feed(pipe, stamp, kind, v)
        last = outs[-1] if outs else last
        start = stamp if start is None else start
        last_diag = stamp if last_diag is None else last_diag
        if stamp - last_diag >= period:
            statuses = policy.update(snapshot(pipe, node, stamp, (stamp - last_diag) * 1e-9))
            last_diag = stamp
            warnings += [((stamp - start) * 1e-9, line) for line in policy.alerts.due()]
    pipe.finish()
    statuses = policy.update(snapshot(pipe, node, last_diag, 1.0))
    print(f"### {name}\n")
    if last is not None:
        for j, m in enumerate(pipe.models):
            if last.ready[j]:
                flag = [" (converged)" if f else "" for f in last.converged[j]]
                cells = [f"{p} {last.theta[j, i]:+.4g} +- {last.se[j, i]:.3g}{flag[i]}"
                         for i, p in enumerate(m.parameter_names)]
                print(f"- {m.output}: " + ", ".join(cells))
    for s in statuses:
        if " model " in s.name:
            print(f"- `/diagnostics` {s.name} [{('OK', 'WARN', 'ERROR', 'STALE')[s.level]}]: {s.message}")
    if warnings:
        first = {}
        for t, line in warnings:
            first.setdefault(line.split(":", 1)[0], (t, line, sum(1 for _t, w in warnings if w.split(":", 1)[0] ==
                                                                      line.split(":", 1)[0])))
        for t, line, n in first.values():
            print(f"- WARN (first at {t:.0f} s of data, logged {n} times in the run): {line}")
    else:
        print("- no WARN line")
    print()


# ----------------------------------------------------------------------------- the rate
def rates() -> None:
    """End-of-bag lags and standard errors of the bundled bag at three estimator rates."""
    messages = read_inputs(package_path("bags", "t2_maneuver"))[0]
    names = ("CZ_alpha", "CZ_delta_e", "Cm_alpha", "Cm_q", "Cm_delta_e")
    print("| rate, Hz | lags | lags (C_Z, C_m) | " + " | ".join(f"{n} SE corrected (conventional)" for n in names)
          + " |")
    print("| --- | --- | --- |" + " --- |" * len(names))
    for selection in ("fixed", "auto"):
        for rate in (50.0, 200.0, 1000.0):
            params = {**load_parameters_file("t2"), "rate": rate, "estimator.lag_selection": selection}
            res = run_pipeline(messages, pipeline_config(params), record=False)
            out, pipe = res.outputs[-1], res.pipeline
            where = {p: (j, i) for j, ps in enumerate(pipe.parameter_names) for i, p in enumerate(ps)}
            cells = [f"{out.se[where[n]]:.4g} ({out.se_conventional[where[n]]:.3g})" for n in names]
            lags = ", ".join(str(int(x)) for x in out.lags)
            print(f"| {rate:g} | {selection} | {lags} | " + " | ".join(cells) + " |", flush=True)


# ----------------------------------------------------------------------------- flight data
FLIGHTS = {"totter_f1_017": ("twin_otter_lateral", {}),
           "totter_f1_014": ("twin_otter_lateral", {"aircraft": "twin_otter_f1_014"}),
           "totter_9752ed20": ("twin_otter_longitudinal", {})}


def flight(directory: str, extra: dict) -> None:
    """Flags the tests delayed on the Twin Otter recordings, with the reason and the estimates."""
    tmp = Path(tempfile.mkdtemp())
    for rec, (cfg, own) in FLIGHTS.items():
        convert(Path(directory) / rec, package_path("msg_schemas", "fti_msgs", "mapping.yaml"), tmp / rec)
        pipe = Pipeline(pipeline_config({**load_parameters_file(cfg), **own, **extra}))
        monitor = ConvergenceMonitor(pipe.sizes, replace(pipe.config.convergence, rate_hz=pipe.config.rate))
        untested: dict = {}
        tested: dict = {}
        t0 = None
        for kind, _stamp, msg in read_inputs(tmp / rec)[0]:
            for out in feed_message(pipe, kind, msg):
                t0 = out.stamp_ns if t0 is None else t0
                t = (out.stamp_ns - t0) * 1e-9
                raw, _ = monitor.update(out.stamp_ns, out.theta, out.se, out.ready)
                for j, names in enumerate(pipe.parameter_names):
                    why = "; ".join(f"{q.kind} {q.figures[0]:.4f}" for q in pipe.identifiability.problems(j))
                    for i, name in enumerate(names):
                        if raw[j, i] and name not in untested:
                            untested[name] = (t, out.theta[j, i], out.se[j, i], why if not out.converged[j, i] else "")
                        if out.converged[j, i]:
                            tested.setdefault(name, t)
        final = {n: (out.theta[j, i], out.se[j, i])
                 for j, ns in enumerate(pipe.parameter_names) for i, n in enumerate(ns)}
        delayed = [n for n in untested if tested.get(n) != untested[n][0]]
        print(f"- {rec} ({cfg}, {(out.stamp_ns - t0) * 1e-9:.1f} s): "
              f"{len(untested)} parameters flagged, {len(delayed)} delayed" + (":" if delayed else ""))
        for n in delayed:
            t, theta, se, why = untested[n]
            when = f"{tested[n]:.2f} s" if n in tested else "never"
            print(f"  - {n}: untested flag at {t:.2f} s ({why}): {theta:+.4g} +- {se:.3g}, end "
                  f"{final[n][0]:+.4g} +- {final[n][1]:.3g}; flagged at {when}")


# ----------------------------------------------------------------------------- thresholds
def sweep(runs: int, levels: tuple[float, ...], grid: list[tuple[float, float]]) -> None:
    """Held-back fraction and flag delay per level for each (max_correlation, min_r_squared)."""
    from rls_uncertainty.datapath.identifiability import IdentifiabilityConfig  # noqa: PLC0415 - not in older checkouts
    print(f"Table 3 Monte Carlo, seed 7, {runs} runs per level; per level over the five parameters: the largest "
          "fraction of runs held back / the largest delay of the median flag time (s)\n")
    print("| max_correlation | min_r_squared | " + " | ".join(f"{lv * 100:.0f}%" for lv in levels) + " |")
    print("| --- | --- |" + " --- |" * len(levels))
    for rho, r2 in grid:
        cfg = IdentifiabilityConfig(max_correlation=rho, min_r_squared=r2)
        cells = []
        for lv in levels:
            rows = [r for r in convergence_summary(run_level(lv, runs, seed=7, identifiability=cfg))
                    if r["parameter"] in TABLE3]
            held = max(r["held_back"] for r in rows)
            delay = max(r["flag_time_median"] - r["untested_flag_time_median"] for r in rows)
            cells.append(f"{100 * held:.0f}% / {delay:.2f}" if math.isfinite(delay) else f"{100 * held:.0f}% / never")
        print(f"| {rho:g} | {r2:g} | " + " | ".join(cells) + " |", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", action="store_true")
    ap.add_argument("--rates", action="store_true")
    ap.add_argument("--flight", metavar="DIR")
    ap.add_argument("--max-correlation", type=float, help="with --flight: identifiability.max_correlation")
    ap.add_argument("--montecarlo", action="store_true")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if args.flight:
        extra = {} if args.max_correlation is None else {"identifiability.max_correlation": args.max_correlation}
        flight(args.flight, extra)
    if args.cases or args.quick or not (args.montecarlo or args.rates or args.flight):
        for name, build in CASES.items():
            run_case(name, build)
    if args.rates or args.quick:
        rates()
    if args.montecarlo or args.quick:
        grid = [(0.9998, 0.5), (0.9, 0.5), (0.99, 0.5), (0.999, 0.5), (0.9998, 0.75), (0.9998, 0.9)]
        if args.quick:
            sweep(20, (0.0, 0.2), grid[:2])
        else:
            sweep(250, (0.0, 0.05, 0.1, 0.15, 0.2), grid)
    return 0


if __name__ == "__main__":
    sys.exit(main())
