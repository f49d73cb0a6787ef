"""Offline replay throughput, as multiples of real time (targets: the pipeline at least 250x with two
models and 150x with six, the whole command 60x, automatic lags within 1.5x of fixed ones).

* the 20 s Twin Otter lateral maneuver totter_f1_017 (converted with the fti_msgs mapping),
  CY, Cl and Cn, 50 lags;
* the bundled T-2 bag (12 s, IMU at 200 Hz), the paper's two models (config/t2.yaml) and all
  six models of Eq. 2 (the lateral ones never become identifiable on this longitudinal
  maneuver, so they stay in exact-initialization accumulation for the whole run), each with
  the 50 fixed lags of config/t2.yaml and with automatic lags (estimator.lag_selection auto),
  and the ratio of their pipeline times.

Bag reading and output writing are timed separately from the pipeline (median wall time of
five runs; the whole command: of three). Each figure is also given in CPU time (the least
``time.process_time()`` of the same runs), steadier than wall time on a loaded machine.

    .venv/bin/python benchmarks/replay_benchmark.py [--flight-data ../shared/flight_data]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from rls_uncertainty.offline.bags import convert, read_inputs
from rls_uncertainty.offline.replay import replay, run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config

ROOT = Path(__file__).resolve().parents[1]


def whole_command(bag: Path, params: dict, repeats: int = 3) -> tuple[float, float]:
    """The ``replay`` command without figures (reading the bag, the pipeline, every output file):
    its median wall time and least CPU time over ``repeats`` runs."""
    walls, cpus = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            t, c = time.perf_counter(), time.process_time()
            replay(bag, params, Path(tmp) / "out", progress=False, plots=False)
            walls.append(time.perf_counter() - t)
            cpus.append(time.process_time() - c)
    return statistics.median(walls), min(cpus)


def measure(label: str, bag: Path, params: dict, repeats: int = 5) -> float:
    t = time.perf_counter()
    messages, _ = read_inputs(bag)
    t_read = time.perf_counter() - t
    cfg = pipeline_config(params)
    runs, cpu = [], []
    for _ in range(repeats):
        c = time.process_time()
        runs.append(run_pipeline(messages, cfg, record=False))
        cpu.append(time.process_time() - c)
    wall = statistics.median(r.wall_seconds for r in runs)
    data = runs[0].data_seconds
    t_cmd, c_cmd = whole_command(bag, params)
    print(f"{label:<44} {len(messages):>6} msgs {data:5.1f} s data | pipeline {wall * 1e3:7.1f} ms = "
          f"{data / wall:6.0f}x real time (CPU {min(cpu) * 1e3:6.1f} ms = {data / min(cpu):4.0f}x) | "
          f"read {t_read * 1e3:6.0f} ms | whole replay command (no plots) {data / t_cmd:5.0f}x "
          f"(CPU {data / c_cmd:4.0f}x)")
    return wall


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--flight-data", default=str(ROOT.parent / "shared" / "flight_data"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        f17 = Path(tmp) / "totter_f1_017"
        convert(Path(args.flight_data) / "totter_f1_017", ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml", f17)
        measure("Twin Otter f1_017, CY Cl Cn, 50 lags", f17, load_parameters_file("twin_otter_lateral"))
    bundled = ROOT / "bags" / "t2_maneuver"
    t2 = load_parameters_file("t2")
    two = measure("bundled T-2 bag, CZ Cm, 50 lags", bundled, t2)
    six = dict(t2)
    six.pop("models.enabled")
    six_fixed = measure("bundled T-2 bag, six models, 50 lags", bundled, six)
    auto = {"estimator.lag_selection": "auto"}
    two_auto = measure("bundled T-2 bag, CZ Cm, automatic lags", bundled, {**t2, **auto})
    six_auto = measure("bundled T-2 bag, six models, automatic lags", bundled, {**six, **auto})
    print(f"automatic against fixed lags (pipeline time): two models {two_auto / two:.2f}x, "
          f"six models {six_auto / six_fixed:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
