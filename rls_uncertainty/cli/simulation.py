"""``simulate``, ``montecarlo`` and ``multisine``: the paper's simulation study, no ROS.

The estimator's settings are the node's, in its units: the spans in seconds at the
simulation's 50 Hz (``--lag-span 1`` is the paper's 50 lags), built into
:class:`..estimator.EstimatorOptions` by the node's own mapping
(:func:`..settings.parameters.estimator_options`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, OutputPathError
from ..estimator.options import EstimatorOptions
from ..schema import settings
from ..settings.parameters import PARAMETER_NAMES, estimator_options
from .flags import FORCE_HELP, add_parameter_flags, add_workers, integer, parameter_overrides, real

__all__ = ["ESTIMATOR_FLAGS", "add_simulate", "add_montecarlo", "add_multisine", "noise_on", "noise_on_name",
           "NOISE_ON_HELP", "simulation_options"]

# The estimator's parameters that have a flag: every command that runs the estimator takes them.
ESTIMATOR_FLAGS = tuple(s.ros for _f, s in settings(EstimatorOptions) if s.cli)
METHOD = "estimator.method"  # --method: the estimates of montecarlo, as the node's parameter
NOISE_ON_HELP = ("measured signals carrying the band-limited noise: 'all' (elevator, alpha, q, a_z) or 'responses' "
                 "(alpha, q, a_z) (default: the simulation's, docs/validation.md, Table 3)")


def simulation_options(args: argparse.Namespace) -> EstimatorOptions:
    """The estimator flags as the options of the T-2 simulation's rate (50 Hz)."""
    from ..simulation.t2 import SimulationConfig

    return estimator_options(parameter_overrides(args, ESTIMATOR_FLAGS), SimulationConfig().rate)


def _simulate(args: argparse.Namespace) -> int:
    """Estimator on a seeded simulated T-2 maneuver (Section IV.A), one sample at a time."""
    from ..estimator import EstimatorBank
    from ..offline.report import results_table, rows_from_arrays
    from ..simulation.t2 import T2_MODELS, T2_TRUE, add_noise, reduce_short_period, simulate_short_period

    options = simulation_options(args)
    record = add_noise(simulate_short_period(), args.noise / 100.0, np.random.default_rng(args.seed))
    t, data = reduce_short_period(record)
    models = list(T2_MODELS)
    bank = EstimatorBank([len(m.regressors) for m in models], options)
    z = np.empty(len(models))
    for k in range(t.size):
        rows = [data[m.output][0][k] for m in models]
        for j, m in enumerate(models):
            z[j] = data[m.output][1][k]
        bank.update(rows, z)
    lags = str(options.lags)
    if lags == "auto":
        lags = "auto (" + ", ".join(f"{m.output} {L}" for m, L in zip(models, bank.lags_used, strict=True)) + ")"
    burn = f", residual burn-in {options.burn_in} samples" if options.burn_in else ""
    print(
        f"T-2 short-period maneuver, {args.noise:g}% band-limited noise (seed {args.seed}), "
        f"{t.size} samples at 50 Hz, {lags} lags, {options.window} window{burn}\n"
    )
    rows = []
    for j, m in enumerate(models):
        rows += rows_from_arrays(m.parameter_names, bank.theta(j), bank.standard_errors(j, "conventional"),
                                 bank.standard_errors(j, "corrected"), T2_TRUE)
    print(results_table(rows))
    print(
        "\nConventional standard errors assume white residuals (Eq. 13); corrected ones use the "
        "recursive residual autocorrelation (Eqs. 17-22)."
    )
    return 0


def _montecarlo(args: argparse.Namespace) -> int:
    """Table 3 of the paper: every noise level, ``--runs`` runs each, with ``--method``'s estimators,
    the runs in batches on every core (or a Dask cluster)."""
    from ..executors import executor_for
    from ..files import output_directory
    from ..simulation.montecarlo import LEVELS, run_table3, t2_frequency_options, write_outputs

    levels = LEVELS if args.levels is None else tuple(x / 100.0 for x in args.levels)
    out = Path(args.out)
    options = simulation_options(args)
    method = getattr(args, METHOD) or PARAMETER_NAMES[METHOD].default
    # The frequency domain on the T-2 grid of config/t2.yaml, with the flags' publication rule.
    frequency = None if method == "time" else t2_frequency_options(options.publish_lag_windows)
    executor = executor_for(args.scheduler, args.workers)
    # The output directory is checked before the runs and appears only when complete.
    with output_directory(out, force=args.force) as tmp:
        print(f"Monte Carlo: {args.runs} runs x {len(levels)} levels, method {method}, {options.lags} lags, residual "
              f"burn-in {options.burn_in}, band-limited noise on {noise_on_name(args.noise_on)}, "
              f"{executor.description}")
        results = run_table3(args.runs, levels, options=options, executor=executor,
                             band_limited_on=noise_on(args.noise_on), method=method, frequency=frequency)
        paths = write_outputs(results, tmp, figures=not args.no_figures)
        table = paths["md"].read_text()
    print(table)
    for path in paths.values():
        print(f"wrote {out / path.relative_to(tmp)}")
    return 0


def _multisine(args: argparse.Namespace) -> int:
    """Design orthogonal phase-optimized multisines and write their input table (CSV)."""
    from ..files import atomic_file
    from ..simulation.multisine import design_multisines, relative_peak_factor

    names = tuple(args.names) if args.names else tuple(f"input{i + 1}" for i in range(args.inputs))
    if len(names) != args.inputs:
        raise ConfigError(f"--names gives {len(names)} names for {args.inputs} inputs")
    designs = design_multisines(args.period, (args.band[0], args.band[1]), args.inputs, names=names,
                                amplitude=args.amplitude)
    out = Path(args.out)
    if out.is_dir() and not out.is_symlink():
        raise OutputPathError(f"{out}: is a directory; give the CSV file's name")
    if (out.exists() or out.is_symlink()) and not args.force:
        raise OutputPathError(f"{out}: exists (use --force to replace it)")
    lines = ["input,harmonic,frequency_hz,relative_amplitude,phase_rad\n"]
    for ms in designs:
        for k, a, ph in zip(ms.harmonics, ms.rel_amplitudes, ms.phases, strict=True):
            lines.append(f"{ms.name},{k},{k / ms.period:.6g},{a:.6g},{ph:.9g}\n")
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(out) as fh:
        fh.write("".join(lines).encode())
    t = np.linspace(0.0, args.period, 4096, endpoint=False)
    for ms in designs:
        freqs = ", ".join(f"{f:.3g}" for f in ms.frequencies)
        print(f"{ms.name}: {len(ms.harmonics)} harmonics ({freqs} Hz), relative peak factor "
              f"{relative_peak_factor(ms(t)):.3f}")
    print(f"wrote {out}  (Eq. 24: u(t) = a * sum_k A_k sin(2 pi k t / T + phi_k), amplitude {args.amplitude:g})")
    return 0


def noise_on(value: str | None) -> tuple[str, ...]:
    """--noise-on: the signals carrying the band-limited noise, 'all' four or the 'responses'
    (None: the simulation's default)."""
    from ..simulation.t2 import BAND_LIMITED_ON, RESPONSES, SIGNALS

    return BAND_LIMITED_ON if value is None else {"all": SIGNALS, "responses": RESPONSES}[value]


def noise_on_name(value: str | None) -> str:
    """The name of --noise-on's value (the default's too)."""
    from ..simulation.t2 import RESPONSES

    return value or ("responses" if noise_on(value) == RESPONSES else "all")


def add_simulate(sub: Any) -> None:
    sim = sub.add_parser("simulate", help="estimate the T-2 derivatives of a simulated maneuver (no ROS)",
                         description="The estimator on one seeded simulated T-2 maneuver at 50 Hz; its settings are "
                                     "the node's, spans in seconds (--lag-span 1 is the paper's 50 lags).")
    sim.add_argument("--noise", type=real(0.0), default=20.0, help="band-limited noise, percent (default 20)")
    sim.add_argument("--seed", type=integer(0), default=250, help="noise seed (default 250)")
    add_parameter_flags(sim, ESTIMATOR_FLAGS)
    sim.set_defaults(func=_simulate)


def add_montecarlo(sub: Any) -> None:
    mc = sub.add_parser("montecarlo", help="reproduce Table 3 and Figs. 5-7 of the paper",
                        description="Table 3 of the paper: every noise level, --runs runs each, at 50 Hz; the "
                                    "estimator's settings are the node's, spans in seconds; --method frequency or "
                                    "both runs the frequency-domain estimator (on the same runs), with "
                                    "config/t2.yaml's frequency.* settings.")
    mc.add_argument("--runs", type=integer(1), default=250, help="runs per noise level (default 250)")
    mc.add_argument("--out", required=True, help="output directory")
    mc.add_argument("--levels", type=real(0.0), nargs="+", help="noise levels in percent (default 0 5 10 15 20)")
    add_parameter_flags(mc, (*ESTIMATOR_FLAGS, METHOD))
    add_workers(mc, "the batches of runs")
    mc.add_argument("--noise-on", choices=("all", "responses"), help=NOISE_ON_HELP)
    mc.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    mc.add_argument("--force", action="store_true", help=FORCE_HELP)
    mc.set_defaults(func=_montecarlo)


def add_multisine(sub: Any) -> None:
    ms = sub.add_parser("multisine", help="design orthogonal phase-optimized multisine inputs (Eq. 24)")
    ms.add_argument("--period", type=real(0.0, low_open=True), required=True, help="record length T, s")
    ms.add_argument("--band", type=real(0.0), nargs=2, required=True, metavar=("LOW", "HIGH"), help="band, Hz")
    ms.add_argument("--inputs", type=integer(1), required=True, help="number of inputs")
    ms.add_argument("--names", nargs="+", help="input names (default input1, input2, ...)")
    ms.add_argument("--amplitude", type=real(0.0, low_open=True), default=1.0,
                    help="aggregate amplitude a (default 1)")
    ms.add_argument("--out", required=True, help="CSV file for the input table")
    ms.add_argument("--force", action="store_true", help="replace an existing file")
    ms.set_defaults(func=_multisine)
