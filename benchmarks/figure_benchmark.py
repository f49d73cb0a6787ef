"""Time to draw a replay's figures (``replay``'s last step), per PNG resolution.

The bundled T-2 bag is replayed once with config/t2.yaml (both models, every figure of
``offline.figures.replay_figures``: estimates, fit, autocorrelation, lag sweep per model), then
its figures are drawn ``--repeats`` times at each ``--dpi`` (PNG only) into a temporary
directory, alternating the resolutions; the median and range of the wall time and the median
CPU time of the process (less sensitive than wall time to other work on the machine) are
printed, with the size of the files written. A run in another source tree (to compare with an earlier version of the
package) is this script run with that tree first on PYTHONPATH: it uses only public names.

    .venv/bin/python benchmarks/figure_benchmark.py [--dpi 300 150] [--repeats 5] [--bag DIR]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from rls_uncertainty.offline.bags import InputStream
from rls_uncertainty.offline.figure_data import FigureData
from rls_uncertainty.offline.figures import FigureOptions, replay_figures
from rls_uncertainty.offline.replay import PLOT_POINTS, run_pipeline
from rls_uncertainty.offline.results import History
from rls_uncertainty.settings import load_parameters_file, node_config, pipeline_config

ROOT = Path(__file__).resolve().parents[1]


def collect(bag: Path, params: dict) -> tuple[History, FigureData]:
    """What replay() hands to replay_figures: the bounded history and the figure data."""
    config = pipeline_config(params)
    names = [m.parameter_names for m in config.models]
    data = FigureData([m.output for m in config.models], [m.regressors for m in config.models], names, config.rate,
                      PLOT_POINTS)
    with InputStream(bag, node_config(params).topics) as stream:
        result = run_pipeline(stream, config, record=False, keep_outputs=False, history=History(names, PLOT_POINTS),
                              figure_data=data)
    assert result.history is not None
    return result.history, data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bag", type=Path, default=ROOT / "bags" / "t2_maneuver")
    ap.add_argument("--config", default=str(ROOT / "config" / "t2.yaml"))
    ap.add_argument("--dpi", type=int, nargs="+", default=[300, 150])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    history, data = collect(args.bag, load_parameters_file(args.config))
    times: dict[int, list[float]] = {d: [] for d in args.dpi}
    cpu: dict[int, list[float]] = {d: [] for d in args.dpi}
    sizes: dict[int, int] = {}
    for _ in range(args.repeats):
        for dpi in args.dpi:
            with tempfile.TemporaryDirectory() as tmp:
                t, c = time.perf_counter(), time.process_time()
                written = replay_figures(tmp, args.bag.name, history, data, FigureOptions(("png",), dpi))
                times[dpi].append(time.perf_counter() - t)
                cpu[dpi].append(time.process_time() - c)
                sizes[dpi] = sum(p.stat().st_size for p in written)
    print(f"{args.bag.name}, {len(written)} figures (PNG), {args.repeats} runs each, alternating")
    print(f"{'dpi':>5} {'wall: median s':>15} {'min s':>7} {'max s':>7} {'CPU: median s':>14} {'files kB':>9}")
    for dpi in args.dpi:
        t = times[dpi]
        print(f"{dpi:>5} {statistics.median(t):15.2f} {min(t):7.2f} {max(t):7.2f} {statistics.median(cpu[dpi]):14.2f} "
              f"{sizes[dpi] / 1000:9.0f}")


if __name__ == "__main__":
    main()
