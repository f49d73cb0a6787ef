"""Cost per sample of the frequency-domain estimator beside the time-domain one.

Prints, in one run on this machine, for the six models of Eq. 2 (time domain 3, 4, 3, 6, 4, 4
parameters; frequency domain the same without the bias: 2, 3, 2, 5, 3, 3), 50 lags:

  1. the time-domain EstimatorBank: update plus every output a node publishes (estimates,
     corrected and conventional standard errors);
  2. the FrequencyBank on the default grid (0.1-1.5 Hz every 0.04 Hz, 36 frequencies) and on
     the T-2 grid (0.2-2.2 Hz, 51): the update alone (transform and lag sums), one evaluation
     (estimates and both covariances, Eqs. F4-F10, after an update), and update plus all
     outputs when they are evaluated every sample, every 5 and every 50 samples (``every``; the
     mean per sample over a whole period);
  3. update plus outputs every sample, and one evaluation, against the number of frequencies
     (36 to 400);
  4. the memory of each bank's state;
  5. the whole pipeline (``replay.run_pipeline``: sampling, differentiation, aerodynamics, both
     estimators, convergence, identifiability) per sample used, with ``estimator.method`` time,
     both and frequency (``frequency.every`` 1 and 5), on the bundled T-2 bag (``config/t2.yaml``:
     2 models, 51 frequencies) and the Twin Otter lateral recording f1_017 (3 models, 36
     frequencies) from ``--flight-data`` (default ``../shared/flight_data``; said when absent);
     best of three runs (wall time), and ``both`` with ``frequency.every: 5`` as a multiple of
     ``time``.

The rows are ``estimator_benchmark.maneuver``'s (multisine-like regressors, AR(1) noise).
Median (and 99th percentile) over 2000 samples after 300 of warm-up. numpy's BLAS threads as
the environment sets them (``OPENBLAS_NUM_THREADS``; printed).

Run: .venv/bin/python benchmarks/frequency_benchmark.py
     .venv/bin/python benchmarks/frequency_benchmark.py --against OTHER_SRC --rounds 2

``--cpu`` prints only the banks' CPU time (``time.thread_time``, the least over blocks of
samples: far less disturbed by other load than wall time): the time-domain bank, one evaluation
at 36 and 400 frequencies, evaluations every 5 samples beside the time domain alone, and the
frequency-domain update alone (transforms and lag sums, 36 frequencies).

``--against`` runs the whole benchmark (or ``--cpu``) on this checkout's package and on the one in the source
tree OTHER_SRC alternately, each run in its own process (the order alternates between rounds):
a before/after comparison in one session, on the same machine load.
"""

from __future__ import annotations

import argparse
import gc
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

# RLS_BENCH_SRC (set by --against): the package of that source tree, imported before the
# time-domain benchmark's module (which puts this checkout first on the path) can load ours.
sys.path.insert(0, os.environ.get("RLS_BENCH_SRC") or str(Path(__file__).resolve().parents[1]))
import rls_uncertainty.estimator  # cached: later imports use this tree's package

sys.path.insert(0, str(Path(__file__).resolve().parent))
from estimator_benchmark import RATE, SIZES, maneuver  # the time-domain benchmark's six models and rows

from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions
from rls_uncertainty.frequency import FrequencyBank, FrequencyOptions

ROOT = Path(__file__).resolve().parents[1]

WARM, SAMPLES = 300, 2000


def timed(step, n: int) -> tuple[float, float]:
    """Median and 99th percentile (us) of ``step(k)`` over samples ``WARM .. WARM + n``."""
    times = []
    gc.disable()
    try:
        for k in range(WARM, WARM + n):
            t0 = time.perf_counter()
            step(k)
            times.append(time.perf_counter() - t0)
    finally:
        gc.enable()
    return float(np.median(times) * 1e6), float(np.percentile(times, 99) * 1e6)


def time_domain(X: np.ndarray, z: np.ndarray) -> tuple[float, float]:
    bank = EstimatorBank(SIZES, EstimatorOptions(lags=50))
    for k in range(WARM):
        bank.update(X[k], z[k])

    def step(k: int) -> None:
        bank.update(X[k], z[k])
        bank.theta_all()
        bank.standard_errors_all("corrected")
        bank.standard_errors_all("conventional")

    return timed(step, SAMPLES)


def frequency_bank(options: FrequencyOptions, X: np.ndarray, z: np.ndarray) -> FrequencyBank:
    bank = FrequencyBank([s - 1 for s in SIZES], options)
    for k in range(WARM):
        bank.update(X[k, :, 1:], z[k])
    bank.theta_all()
    return bank


def evaluation(options: FrequencyOptions, X: np.ndarray, z: np.ndarray) -> float:
    """Median us of one evaluation (estimates, both standard errors) after each update."""
    bank = frequency_bank(options, X, z)
    times = []
    gc.disable()
    try:
        for k in range(WARM, WARM + SAMPLES):
            bank.update(X[k, :, 1:], z[k])
            t0 = time.perf_counter()
            bank.theta_all()
            bank.standard_errors_all("corrected")
            bank.standard_errors_all("conventional")
            times.append(time.perf_counter() - t0)
    finally:
        gc.enable()
    return float(np.median(times) * 1e6)


def frequency_domain(options: FrequencyOptions, X: np.ndarray, z: np.ndarray, outputs: bool) -> tuple[float, float]:
    bank = frequency_bank(options, X, z)

    def step(k: int) -> None:
        bank.update(X[k, :, 1:], z[k])
        if outputs:
            bank.theta_all()
            bank.standard_errors_all("corrected")
            bank.standard_errors_all("conventional")

    if options.every == 1:
        return timed(step, SAMPLES)
    t0 = time.perf_counter()  # amortised: every period has one evaluation
    for k in range(WARM, WARM + SAMPLES):
        step(k)
    mean = (time.perf_counter() - t0) / SAMPLES * 1e6
    return mean, float("nan")


def state_bytes(bank: object) -> int:
    seen, total, todo = set(), 0, [bank]
    while todo:
        obj = todo.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            total += obj.nbytes
        elif hasattr(obj, "__dict__"):
            todo.extend(vars(obj).values())
        elif isinstance(obj, (list, tuple, dict)):
            todo.extend(obj.values() if isinstance(obj, dict) else obj)
    return total


def main() -> None:
    print(f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', '(unset)')}, numpy {np.__version__}, "
          f"package {Path(rls_uncertainty.estimator.__file__).parents[1]}")
    X, z = maneuver(WARM + SAMPLES)
    med, p99 = time_domain(X, z)
    print(f"1. time domain, six models, 50 lags, update + all outputs: {med:7.1f} us (p99 {p99:.1f})")
    grids = {"default 0.1-1.5/0.04 (36)": (0.1, 1.5, 0.04), "T-2 0.2-2.2/0.04 (51)": (0.2, 2.2, 0.04)}
    print("2. frequency domain, six models, 50 lags (us per sample):")
    for label, (lo, hi, step) in grids.items():
        base = FrequencyOptions(rate_hz=RATE, f_min=lo, f_max=hi, f_step=step)
        upd = frequency_domain(base, X, z, outputs=False)
        line = f"   {label:28s} update {upd[0]:6.1f} | evaluation {evaluation(base, X, z):7.1f}"
        for every in (1, 5, 50):
            opts = FrequencyOptions(rate_hz=RATE, f_min=lo, f_max=hi, f_step=step, every=every)
            med, p99 = frequency_domain(opts, X, z, outputs=True)
            line += f" | every {every:2d}: {med:7.1f}" + (f" (p99 {p99:.0f})" if every == 1 else "")
        print(line)
    print("3. frequency domain against the number of frequencies: update + outputs every sample | one evaluation:")
    for K in (36, 100, 200, 400):
        opts = FrequencyOptions(rate_hz=RATE, f_min=0.1, f_max=0.1 + (K - 1) * 0.05, f_step=0.05)
        med, _ = frequency_domain(opts, X, z, outputs=True)
        print(f"   K = {K:3d}: {med:8.1f} us | {evaluation(opts, X, z):8.1f} us")
    td = EstimatorBank(SIZES, EstimatorOptions(lags=50))
    fd = FrequencyBank([s - 1 for s in SIZES], FrequencyOptions(rate_hz=RATE, f_min=0.2, f_max=2.2))
    for k in range(200):
        td.update(X[k], z[k])
        fd.update(X[k, :, 1:], z[k])
    fd.theta_all()
    print(f"4. state memory, six models, 50 lags: time domain {state_bytes(td) / 1024:.0f} KiB, "
          f"frequency domain (51 frequencies) {state_bytes(fd) / 1024:.0f} KiB")


def pipeline_costs(flight_data: Path) -> None:
    """Section 5: microseconds per sample used through the whole pipeline, per method."""
    import tempfile

    from rls_uncertainty.offline.bags import convert, read_inputs
    from rls_uncertainty.offline.replay import run_pipeline
    from rls_uncertainty.settings import load_parameters_file, pipeline_config

    variants = {"time": {}, "both": {"estimator.method": "both"}, "both, every 5": {
        "estimator.method": "both", "frequency.every": 5}, "frequency": {"estimator.method": "frequency"}}
    data = flight_data / "totter_f1_017"
    with tempfile.TemporaryDirectory(prefix="freq_bench_") as work:
        cases = {"T-2 bag, config/t2.yaml": (ROOT / "bags" / "t2_maneuver", "t2")}
        if data.exists():
            convert(data, ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml", Path(work) / "f1_017")
            cases["Twin Otter f1_017, twin_otter_lateral"] = (Path(work) / "f1_017", "twin_otter_lateral")
        else:
            print(f"5. (no {data}: the Twin Otter case is left out; give --flight-data)")
        print("5. the pipeline per sample used (us, best of 3; sampling to outputs, no files):")
        for label, (bag, config_name) in cases.items():
            messages, _ = read_inputs(bag)
            line, costs = f"   {label:38s}", {}
            for name, extra in variants.items():
                config = pipeline_config({**load_parameters_file(config_name), **extra})
                best = min(run_pipeline(messages, config, record=False, keep_outputs=False).wall_seconds
                           for _ in range(3))
                used = run_pipeline(messages, config, record=False, keep_outputs=False).counters()["samples_used"]
                line += f" | {name}: {best / used * 1e6:6.0f}"
                costs[name] = best / used
            print(line + f" | both, every 5 / time: {costs['both, every 5'] / costs['time']:.2f}")


def cpu_costs() -> None:
    """``--cpu``: the CPU time (``time.thread_time``) of the banks, the least over blocks of
    samples, which a loaded machine disturbs far less than wall time: the time-domain bank with
    every output, one frequency-domain evaluation at 36 and 400 frequencies, and the mean per
    sample with evaluations every 5 samples (36 frequencies) beside the time-domain bank, and the
    update alone."""
    X, z = maneuver(WARM + 1000)

    def least(step, blocks: int, size: int) -> float:
        best = float("inf")
        for b in range(blocks):
            t0 = time.thread_time()
            for k in range(WARM + size * b, WARM + size * (b + 1)):
                step(k)
            best = min(best, (time.thread_time() - t0) / size)
        return best * 1e6

    def outputs(bank: EstimatorBank | FrequencyBank) -> None:
        bank.theta_all()
        bank.standard_errors_all("corrected")
        bank.standard_errors_all("conventional")

    td = EstimatorBank(SIZES, EstimatorOptions(lags=50))
    for k in range(WARM):
        td.update(X[k], z[k])
    t_time = least(lambda k: (td.update(X[k], z[k]), outputs(td)), 10, 100)
    line = f"CPU us per sample, least over blocks: time domain {t_time:.1f}"
    for K, blocks, size in ((36, 10, 50), (400, 4, 25)):
        bank = frequency_bank(FrequencyOptions(rate_hz=RATE, f_min=0.1, f_max=0.1 + (K - 1) * 0.05, f_step=0.05), X, z)
        best = float("inf")
        for b in range(blocks):  # the update outside the clock, the evaluation (all outputs) inside
            spent = 0.0
            for k in range(WARM + size * b, WARM + size * (b + 1)):
                bank.update(X[k, :, 1:], z[k])
                t0 = time.thread_time()
                outputs(bank)
                spent += time.thread_time() - t0
            best = min(best, spent / size)
        line += f" | one evaluation, {K} frequencies {best * 1e6:.1f}"
    bank = frequency_bank(FrequencyOptions(rate_hz=RATE, every=5), X, z)
    f5 = least(lambda k: (bank.update(X[k, :, 1:], z[k]), outputs(bank)), 10, 100)
    line += f" | frequency domain every 5 samples {f5:.1f}, both / time domain alone {(t_time + f5) / t_time:.2f}"
    bank = frequency_bank(FrequencyOptions(rate_hz=RATE, every=10**6), X, z)  # never evaluated again
    print(line + f" | frequency-domain update alone {least(lambda k: bank.update(X[k, :, 1:], z[k]), 10, 100):.1f}")


def against(other: str, rounds: int, extra: list[str]) -> None:
    """This checkout and ``other`` alternately, each in its own process (module docstring)."""
    trees = [("this checkout", str(Path(__file__).resolve().parents[1])), (other, str(Path(other).resolve()))]
    for r in range(rounds):
        for label, src in trees if r % 2 == 0 else trees[::-1]:
            print(f"== {label} (round {r + 1} of {rounds})", flush=True)
            subprocess.run([sys.executable, __file__, *extra], env={**os.environ, "RLS_BENCH_SRC": src}, check=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--against", metavar="OTHER_SRC", help="also run the package of this source tree, alternately")
    parser.add_argument("--rounds", type=int, default=2, help="with --against: runs of each tree (default 2)")
    parser.add_argument("--cpu", action="store_true", help="only the CPU-time figures of the banks (cpu_costs)")
    parser.add_argument("--flight-data", type=Path, default=ROOT.parent / "shared" / "flight_data",
                        help="the shared recordings, for section 5's Twin Otter case (default ../shared/flight_data)")
    args = parser.parse_args()
    if args.against:
        against(args.against, args.rounds, ["--cpu"] if args.cpu else [])
    elif args.cpu:
        cpu_costs()
    else:
        main()
        pipeline_costs(args.flight_data)
