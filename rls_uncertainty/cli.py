"""``rls-uncertainty``: the package's command line, one subcommand per job."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn
from xml.etree import ElementTree

import numpy as np

from .errors import ConfigError, OutputPathError, RlsUncertaintyError

__all__ = ["main"]


def _demo(args: argparse.Namespace) -> int:
    """The live node on the bundled bag over DDS, beside the offline replay."""
    from .ros.player import demo

    return demo(rate=args.rate)


def _simulate(args: argparse.Namespace) -> int:
    """Estimator on a seeded simulated T-2 maneuver (Section IV.A), one sample at a time."""
    from .estimator import EstimatorBank, EstimatorOptions
    from .offline.report import results_table, rows_from_arrays
    from .simulation.t2 import T2_MODELS, T2_TRUE, add_noise, reduce_short_period, simulate_short_period

    record = add_noise(simulate_short_period(), args.noise / 100.0, np.random.default_rng(args.seed))
    t, data = reduce_short_period(record)
    models = list(T2_MODELS)
    options = EstimatorOptions(lags=args.lags, window=args.window,
                               forgetting=args.forgetting, residual_burn_in=_bank_burn_in(args.burn_in))
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
        f"{t.size} samples at 50 Hz, {lags} lags, {args.window} window{burn}\n"
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
    """Table 3 of the paper: every noise level, ``--runs`` runs each, on every core."""
    from .estimator import EstimatorOptions
    from .executors import executor_for
    from .files import output_directory
    from .simulation.montecarlo import LEVELS, run_table3, write_outputs

    levels = LEVELS if args.levels is None else tuple(x / 100.0 for x in args.levels)
    out = Path(args.out)
    options = EstimatorOptions(lags=args.lags, residual_burn_in=_bank_burn_in(args.burn_in))
    executor = executor_for(args.scheduler, args.jobs, "--jobs")
    # The output directory is checked before the runs and appears only when complete.
    with output_directory(out, force=args.force) as tmp:
        print(f"Monte Carlo: {args.runs} runs x {len(levels)} levels, {options.lags} lags, residual burn-in "
              f"{options.burn_in}, band-limited noise on {_noise_on_name(args.noise_on)}, {executor.description}")
        results = run_table3(args.runs, levels, options=options, executor=executor,
                             band_limited_on=_noise_on(args.noise_on))
        paths = write_outputs(results, tmp, figures=not args.no_figures)
        table = paths["md"].read_text()
    print(table)
    for path in paths.values():
        print(f"wrote {out / path.relative_to(tmp)}")
    return 0


def _multisine(args: argparse.Namespace) -> int:
    """Design orthogonal phase-optimized multisines and write their input table (CSV)."""
    from .files import atomic_file
    from .simulation.multisine import design_multisines, relative_peak_factor

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


def _gust(value: str) -> float:
    """--gust-intensity: sigma_w in m/s (a number >= 0) or light / moderate / severe
    (MIL-F-8785C low altitude, :data:`.turbulence.LOW_ALTITUDE_SIGMA_W`)."""
    from .simulation.turbulence import LOW_ALTITUDE_SIGMA_W

    if value in LOW_ALTITUDE_SIGMA_W:
        return LOW_ALTITUDE_SIGMA_W[value]
    try:
        return _real(0.0)(value)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be sigma_w in m/s (a number >= 0) or one of "
                                         f"{', '.join(LOW_ALTITUDE_SIGMA_W)}, got {value!r}") from None


def _noise_on(value: str | None) -> tuple[str, ...]:
    """--noise-on: the signals carrying the band-limited noise, 'all' four or the 'responses'
    (None: the simulation's default)."""
    from .simulation.t2 import BAND_LIMITED_ON, RESPONSES, SIGNALS

    return BAND_LIMITED_ON if value is None else {"all": SIGNALS, "responses": RESPONSES}[value]


def _noise_on_name(value: str | None) -> str:
    """The name of --noise-on's value (the default's too)."""
    from .simulation.t2 import RESPONSES

    return value or ("responses" if _noise_on(value) == RESPONSES else "all")


_NOISE_ON_HELP = ("measured signals carrying the band-limited noise: 'all' (elevator, alpha, q, a_z) or 'responses' "
                  "(alpha, q, a_z) (default: the simulation's, docs/validation.md, Table 3)")


def _make_campaign(args: argparse.Namespace) -> int:
    """make-bag --campaign N: N seeded T-2 maneuvers in Dryden turbulence, one bag each."""
    from .offline.bags import write_campaign_bags
    from .simulation.t2 import SimulationConfig
    from .simulation.turbulence import DrydenVertical, scale_length

    if args.gust_intensity is None:
        raise ConfigError("--campaign needs --gust-intensity (sigma_w in m/s, or light, moderate or severe)")
    gust = DrydenVertical(args.gust_intensity, scale_length(SimulationConfig().altitude))
    paths = write_campaign_bags(args.out, args.campaign, gust, band_level=args.noise / 100.0,
                                band_limited_on=_noise_on(args.noise_on), seed=args.seed, force=args.force)
    print(f"wrote {len(paths)} replay bags to {args.out}: T-2 maneuvers in Dryden vertical gusts sigma_w "
          f"{gust.sigma:.3g} m/s, L_w {gust.scale_length:.0f} m, {args.noise:g}% band-limited noise on "
          f"{_noise_on_name(args.noise_on)}, seed {args.seed} (settings in {Path(args.out) / 'campaign.yaml'})")
    return 0


def _make_bag(args: argparse.Namespace) -> int:
    """Write the seeded T-2 maneuver on the node's standard input topics."""
    from .offline.bags import write_t2_bag

    if args.campaign is not None:
        return _make_campaign(args)
    if args.gust_intensity is not None:
        raise ConfigError("--gust-intensity sets the turbulence of a simulated campaign: give --campaign N")
    from .simulation.t2 import SIGNALS

    on = SIGNALS if args.noise_on is None else _noise_on(args.noise_on)  # the bundled bag's: all four
    path = write_t2_bag(args.out, args.noise / 100.0, args.seed, force=args.force, band_limited_on=on)
    size = sum(f.stat().st_size for f in path.iterdir())
    print(f"wrote {path} ({size / 1e6:.2f} MB): T-2 maneuver, {args.noise:g}% band-limited noise, seed {args.seed}")
    return 0


def _convert(args: argparse.Namespace) -> int:
    from .offline.bags import convert

    counts = convert(args.bag, args.mapping, args.out, schemas=args.schemas, force=args.force)
    for topic, n in counts.items():
        print(f"{topic:<20}{n:>8} messages")
    print(f"wrote {args.out}")
    return 0


def _not_text(name: str, exc: UnicodeDecodeError) -> ConfigError:
    return ConfigError(f"{name}: not UTF-8 text (byte {exc.start})")


def _replay_params(args: argparse.Namespace, command: str = "replay") -> dict[str, Any]:
    from .settings.config import PARAMETER_NAMES, node_parameters_file, pipeline_config

    params: dict[str, Any] = {}
    if args.config:  # read as the node reads it; what it ignores is said once
        from_file = node_parameters_file(args.config)
        for note in from_file.warnings:
            print(f"rls-uncertainty {command}: warning: {note}", file=sys.stderr)
        params = {k: v for k, v in from_file.values.items() if k in PARAMETER_NAMES}
    if args.lag_span is not None:  # --lag-span decides the lag selection whatever the file said
        params["estimator.lag_selection"] = "auto" if args.lag_span == "auto" else "fixed"
        if args.lag_span != "auto":
            params["estimator.lag_span"] = args.lag_span
    if args.max_lag_span is not None:
        params["estimator.max_lag_span"] = args.max_lag_span
    if args.burn_in_span is not None:
        params["estimator.residual_burn_in_span"] = args.burn_in_span
    if args.window:
        params["estimator.window"] = args.window
    if args.forgetting is not None:
        params["estimator.forgetting"] = args.forgetting
    if args.models:
        params["models.enabled"] = list(args.models)
    if getattr(args, "method", None):  # replay and campaign
        params["estimator.method"] = args.method
    try:
        pipeline_config(params)  # every setting checked and the aircraft file read before any output
    except UnicodeDecodeError as exc:
        raise _not_text(f"aircraft {params.get('aircraft')}", exc) from exc
    return params


def _yaml_file(name_or_path: str, directory: Path) -> Path:
    """The file a parameter or aircraft name stands for (as :mod:`.config` resolves it)."""
    path = Path(name_or_path)
    return path if path.suffix else directory / f"{name_or_path}.yaml"


def _replay(args: argparse.Namespace) -> int:
    from .offline.compare import DEFAULT_ATOL, DEFAULT_RTOL, comparable, compare_replays, read_run
    from .offline.figures import FigureOptions, figure_formats
    from .offline.replay import planned_run, replay, run_summary
    from .settings.config import config_dir

    params = _replay_params(args)
    figures = FigureOptions(figure_formats(args.figures), args.dpi)
    # Files the replay reads besides the bag: never replaced by its output, even with --force.
    inputs = [_yaml_file(args.config, config_dir())] if args.config else []
    if isinstance(params.get("aircraft"), str) and params["aircraft"]:
        inputs.append(_yaml_file(params["aircraft"], config_dir() / "aircraft"))
    if (args.rtol is not None or args.atol is not None) and not args.compare:
        raise ConfigError("--rtol and --atol set the tolerance of --compare DIR: give the reference replay's directory")
    if args.compare:  # what can be checked before the bag is read, is
        inputs.append(args.compare)
        comparable(planned_run(params, start=args.start, end=args.end, strict=not args.lenient),
                   read_run(args.compare), bag=False)
    result = replay(args.bag, params, args.out, start=args.start, end=args.end, strict=not args.lenient,
                    progress=not args.quiet, plots=not args.no_plots, figures=figures, force=args.force,
                    inputs=inputs)
    print(run_summary(result))
    print(f"read in {result.wall_seconds:.2f} s ({result.speed:.0f}x real time); wrote {args.out}")
    # No model estimated anything: the summary above says why; a script must not take it for success.
    if not result.estimates:
        return 1
    if args.compare:
        rtol = DEFAULT_RTOL if args.rtol is None else args.rtol
        cmp = compare_replays(args.out, args.compare, rtol=rtol, atol=DEFAULT_ATOL if args.atol is None else args.atol)
        print(cmp.report())
        return 0 if cmp.equal else 1
    return 0


def _campaign(args: argparse.Namespace) -> int:
    """Many maneuvers through the replay's pipeline into Table 4 and Fig. 12 (docs/campaign.md)."""
    from .campaign import CampaignSettings, campaign_to, from_bags, load_maneuvers
    from .executors import executor_for
    from .offline.figures import FigureOptions, figure_formats
    from .settings.config import config_dir, node_config, pipeline_config

    params = _replay_params(args, "campaign")
    executor = executor_for(args.scheduler, args.workers)
    if args.maneuvers:
        if len(args.inputs) != 1:
            raise ConfigError(f"--maneuvers cuts one recording into maneuvers; got {len(args.inputs)} INPUTs")
        maneuvers = load_maneuvers(args.maneuvers, args.inputs[0])
    else:
        maneuvers = from_bags(args.inputs)
    inputs = [_yaml_file(args.config, config_dir())] if args.config else []
    if args.maneuvers:
        inputs.append(args.maneuvers)
    settings = CampaignSettings(pipeline_config(params), node_config(params).topics, strict=not args.lenient)
    figures = None if args.no_plots else FigureOptions(figure_formats(args.figures), args.dpi)
    result = campaign_to(args.out, maneuvers, settings, executor, progress=not args.quiet,
                         figures=figures, force=args.force, inputs=inputs)
    print(result.summary(), end="")
    s = result.seconds()
    print(f"{len(maneuvers)} maneuvers in {result.wall_seconds + result.write_seconds:.1f} s "
          f"({result.per_minute:.0f} per minute) on {result.executor}; worker time: read {s.get('read', 0):.1f} s, "
          f"pipeline {s.get('pipeline', 0):.1f} s, all lags {s.get('all_lags', 0):.1f} s; writing "
          f"{result.write_seconds:.1f} s; wrote {args.out}")
    return 0 if any(res.problem is None for res in result.results) else 1


def _play(args: argparse.Namespace) -> int:
    from .ros.player import play

    return play(args.bag, rate=args.rate, clock=not args.no_clock, reliable=not args.best_effort,
                wait_for_subscribers=args.wait, start_delay=args.delay, loops=args.loop, window=args.window,
                ack_timeout=args.ack_timeout, report=args.report)


def _dashboard(args: argparse.Namespace) -> int:
    from .dashboard.app import dashboard_options, run

    return run(dashboard_options(args.host, args.port, args.node, args.replay, args.reference, args.token))


def _status(args: argparse.Namespace) -> int:
    from .dashboard.settings import full_node_name
    from .ros.operate import status

    return status(full_node_name(args.node), args.once, args.timeout)


def _service(args: argparse.Namespace) -> int:
    from .dashboard.settings import full_node_name
    from .ros.operate import call

    return call(args.command, full_node_name(args.node), args.timeout)


def _count_or_word(value: str, words: dict[str, Any], expected: str) -> Any:
    """An integer >= 0, or the value of one of ``words``; otherwise an argparse error saying
    what was ``expected``."""
    if value in words:
        return words[value]
    try:
        n = int(value)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be {expected}, got {value!r}")
    return n


def _lags(value: str) -> int | str:
    """--lags of every command, in the form of the estimator's ``lags`` option: an integer
    >= 0 (L of Eq. 22), 'all' (Eq. 20) or 'auto' (each model's lags from its residuals)."""
    return _count_or_word(value, {"all": "all", "auto": "auto"}, "an integer >= 0, 'all' or 'auto'")


def _lag_span(value: str) -> float | str:
    """replay's --lag-span, in the form of ``estimator.lag_span``: seconds >= 0 (the lags are
    seconds x rate), 'all' (-1, Eq. 20) or 'auto' (estimator.lag_selection auto)."""
    return _seconds_or_word(value, {"all": -1.0, "auto": "auto"}, "a number of seconds >= 0, 'all' or 'auto'")


def _burn_in_span(value: str) -> float:
    """replay's --burn-in-span: seconds >= 0, or 'default' (-1: estimator.residual_burn_in_span's
    default, 1 s with auto lags, 0 with fixed lags)."""
    return float(_seconds_or_word(value, {"default": -1.0}, "a number of seconds >= 0 or 'default'"))


def _seconds_or_word(value: str, words: dict[str, Any], expected: str) -> Any:
    """A finite number >= 0, or the value of one of ``words``; otherwise an argparse error."""
    if value in words:
        return words[value]
    try:
        x = float(value)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and x >= 0):
        raise argparse.ArgumentTypeError(f"must be {expected}, got {value!r}")
    return x


class _Renamed(argparse.Action):
    """An option that was renamed: using it is a usage error naming the new one."""

    def __init__(self, option_strings: list[str], dest: str, renamed: str = "", **kwargs: Any) -> None:
        self.renamed = renamed
        super().__init__(option_strings, dest, help=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        parser.error(f"{option_string} is now {self.renamed}")


def _burn_in(value: str) -> int:
    """--burn-in: an integer >= 0, or 'default' (-1, estimator.residual_burn_in's default: 50 with
    auto lags, 0 with fixed lags); the parameter's upper bound is checked with the others."""
    return int(_count_or_word(value, {"default": -1}, "an integer >= 0 or 'default'"))


def _bank_burn_in(value: int | None) -> int | None:
    """The bank's residual_burn_in for --burn-in (None, the default, for -1 or not given)."""
    return None if value is None or value < 0 else value


_BURN_IN_HELP = ("residual burn-in: samples after each model's initialization whose residuals are left out of the "
                 "residual autocorrelation (Eq. 17), or 'default' (50 with --lags auto, 0 otherwise)")


def _real(low: float, *, low_open: bool = False, high: float | None = None) -> Callable[[str], float]:
    """An argparse type: a finite number >= low (> low with ``low_open``), <= high."""
    bound = f"> {low:g}" if low_open else f">= {low:g}"
    if high is not None:
        bound = f"in ({low:g}, {high:g}]" if low_open else f"in [{low:g}, {high:g}]"

    def real(value: str) -> float:
        try:
            x = float(value)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and (x > low if low_open else x >= low) and (high is None or x <= high)):
            raise argparse.ArgumentTypeError(f"must be a finite number {bound}, got {value!r}")
        return x

    return real


def _integer(low: int) -> Callable[[str], int]:
    """An argparse type: an integer >= low."""

    def integer(value: str) -> int:
        try:
            n = int(value)
        except ValueError:
            n = None
        if n is None or n < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {value!r}")
        return n

    return integer


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line, like every other error of the command (exit status 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


_FORCE_HELP = "replace an existing non-empty output directory (never the input)"


def _add_demo(sub: Any) -> None:
    demo = sub.add_parser("demo", help="the live estimator node on the bundled T-2 bag over DDS")
    demo.add_argument("--rate", type=_real(0.0), default=4.0,
                      help="playback speed factor (default 4; 0 = as fast as possible)")
    demo.set_defaults(func=_demo)


def _add_simulate(sub: Any) -> None:
    sim = sub.add_parser("simulate", help="estimate the T-2 derivatives of a simulated maneuver (no ROS)")
    sim.add_argument("--noise", type=_real(0.0), default=20.0, help="band-limited noise, percent (default 20)")
    sim.add_argument("--seed", type=_integer(0), default=250, help="noise seed (default 250)")
    sim.add_argument("--lags", type=_lags, default=50, help="retained lags, 'all' or 'auto' (default 50)")
    sim.add_argument("--burn-in", type=_burn_in, help=_BURN_IN_HELP)
    sim.add_argument("--window", choices=("truncated", "bartlett"), default="truncated")
    sim.add_argument("--forgetting", type=_real(0.0, low_open=True, high=1.0), default=1.0,
                     help="exponential forgetting factor in (0, 1] (default 1)")
    sim.set_defaults(func=_simulate)


def _add_montecarlo(sub: Any) -> None:
    mc = sub.add_parser("montecarlo", help="reproduce Table 3 and Figs. 5-7 of the paper")
    mc.add_argument("--runs", type=_integer(1), default=250, help="runs per noise level (default 250)")
    mc.add_argument("--out", required=True, help="output directory")
    mc.add_argument("--levels", type=_real(0.0), nargs="+", help="noise levels in percent (default 0 5 10 15 20)")
    mc.add_argument("--lags", type=_lags, default=50,
                    help="retained lags, 'all', or 'auto' (chosen per run and model, at most 50) (default 50)")
    mc.add_argument("--burn-in", type=_burn_in, help=_BURN_IN_HELP)
    mc.add_argument("--jobs", type=_integer(1), default=None, help="local processes (default: every core)")
    mc.add_argument("--scheduler", metavar="ADDRESS",
                    help="run the levels on the Dask cluster whose scheduler listens at ADDRESS (tcp://host:8786)")
    mc.add_argument("--noise-on", choices=("all", "responses"), help=_NOISE_ON_HELP)
    mc.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    mc.add_argument("--force", action="store_true", help=_FORCE_HELP)
    mc.set_defaults(func=_montecarlo)


def _add_multisine(sub: Any) -> None:
    ms = sub.add_parser("multisine", help="design orthogonal phase-optimized multisine inputs (Eq. 24)")
    ms.add_argument("--period", type=_real(0.0, low_open=True), required=True, help="record length T, s")
    ms.add_argument("--band", type=_real(0.0), nargs=2, required=True, metavar=("LOW", "HIGH"), help="band, Hz")
    ms.add_argument("--inputs", type=_integer(1), required=True, help="number of inputs")
    ms.add_argument("--names", nargs="+", help="input names (default input1, input2, ...)")
    ms.add_argument("--amplitude", type=_real(0.0, low_open=True), default=1.0,
                    help="aggregate amplitude a (default 1)")
    ms.add_argument("--out", required=True, help="CSV file for the input table")
    ms.add_argument("--force", action="store_true", help="replace an existing file")
    ms.set_defaults(func=_multisine)


def _add_make_bag(sub: Any) -> None:
    mb = sub.add_parser("make-bag", help="write the seeded T-2 maneuver as a bag on the standard input topics")
    mb.add_argument("--out", default="bags/t2_maneuver", help="bag directory (default bags/t2_maneuver)")
    mb.add_argument("--noise", type=_real(0.0), default=20.0, help="band-limited noise, percent (default 20)")
    mb.add_argument("--seed", type=_integer(0), default=250, help="noise seed (default 250)")
    mb.add_argument("--campaign", type=_integer(1), metavar="N",
                    help="write N maneuvers flown in turbulence, one replay bag each, into --out (a campaign for "
                         "rls-uncertainty campaign; docs/campaign.md)")
    mb.add_argument("--gust-intensity", type=_gust, metavar="SIGMA_W",
                    help="with --campaign: RMS vertical gust in m/s, or light, moderate, severe (MIL-F-8785C low "
                         "altitude: 0.77, 1.54, 2.31 m/s)")
    mb.add_argument("--noise-on", choices=("all", "responses"),
                    help="measured signals carrying the band-limited noise: 'all' (elevator, alpha, q, a_z) or "
                         "'responses' (alpha, q, a_z) (default: all for one maneuver, the bundled bag's; with "
                         "--campaign the simulation's, responses: docs/validation.md, Table 3)")
    mb.add_argument("--force", action="store_true", help=_FORCE_HELP)
    mb.set_defaults(func=_make_bag)


def _add_convert(sub: Any) -> None:
    cv = sub.add_parser("convert", help="recorded bag + mapping file -> replay bag on the standard topics")
    cv.add_argument("bag", help="ROS 2 bag (MCAP or sqlite3; directory or file) or ROS 1 bag")
    cv.add_argument("--mapping", required=True, help="mapping YAML (e.g. msg_schemas/fti_msgs/mapping.yaml)")
    cv.add_argument("--out", required=True, help="output bag directory")
    cv.add_argument("--schemas", action="append", help="extra .msg directory (PKG/msg/NAME.msg); repeatable")
    cv.add_argument("--force", action="store_true", help=_FORCE_HELP)
    cv.set_defaults(func=_convert)


def _add_replay(sub: Any) -> None:
    rp = sub.add_parser("replay", help="run a replay bag through the node's pipeline offline")
    rp.add_argument("bag", help="replay bag on the standard topics")
    rp.add_argument("--config", help="ROS parameter file, e.g. config/t2.yaml (default: node defaults)")
    rp.add_argument("--out", required=True, help="output directory")
    _add_estimator_overrides(rp)
    _add_method(rp, "time-domain estimates (estimates.csv), frequency-domain ones (estimates_frequency.csv) or both")
    rp.add_argument("--start", type=_real(0.0), help="start, s from the bag start")
    rp.add_argument("--end", type=_real(0.0), help="end, s from the bag start (after --start)")
    rp.add_argument("--lenient", action="store_true",
                    help="pass out-of-order and duplicate stamps to the pipeline (counted like the node does)")
    _add_figure_options(rp, "no figures (summary.txt and the data files only)")
    rp.add_argument("--quiet", action="store_true", help="no progress bar")
    rp.add_argument("--force", action="store_true", help=_FORCE_HELP)
    rp.add_argument("--compare", metavar="DIR",
                    help="compare the outputs with an earlier replay's in DIR sample by sample: exit 0 when equal "
                         "within the tolerance, 1 when not (the largest differences printed), 2 when the runs are "
                         "not comparable (another bag, span, models, sample rate or no estimation method in common)")
    rp.add_argument("--rtol", type=_real(0.0), metavar="R",
                    help="--compare's relative tolerance, of |estimate| + its standard error (default 1e-6)")
    rp.add_argument("--atol", type=_real(0.0), metavar="A",
                    help="--compare's absolute tolerance, in the units of each derivative (default 0)")
    rp.set_defaults(func=_replay)


def _add_figure_options(parser: Any, no_plots: str) -> None:
    """--no-plots, --figures and --dpi of replay and campaign (checked by figures.FigureOptions)."""
    parser.add_argument("--no-plots", action="store_true", help=no_plots)
    parser.add_argument("--figures", default="png", metavar="FORMATS",
                        help="figure formats, comma separated, of png, svg, pdf (default png)")
    parser.add_argument("--dpi", type=int, default=300,
                        help="PNG resolution, dots per inch (default 300, 50 to 1200)")


def _add_estimator_overrides(parser: Any) -> None:
    """The estimator and model options ``replay`` and ``campaign`` share (over --config)."""
    parser.add_argument("--lag-span", type=_lag_span,
                        help="override estimator.lag_span: seconds of residual autocorrelation kept (lags = seconds x "
                             "rate), 'all', or 'auto' (estimator.lag_selection auto)")
    parser.add_argument("--max-lag-span", type=_real(0.0, low_open=True),
                        help="override estimator.max_lag_span, s (with auto)")
    parser.add_argument("--burn-in-span", type=_burn_in_span,
                        help="override estimator.residual_burn_in_span: seconds after each model's initialization "
                             "whose residuals are left out of the residual autocorrelation, or 'default' (-1: 1 s "
                             "with auto, 0 with fixed lags)")
    for old, new in (("--lags", "--lag-span SECONDS (lags / rate: 50 lags at 50 Hz = 1.0)"),
                     ("--max-lags", "--max-lag-span SECONDS (max lags / rate)"),
                     ("--burn-in", "--burn-in-span SECONDS (samples / rate)")):
        parser.add_argument(old, action=_Renamed, renamed=new)
    parser.add_argument("--window", choices=("truncated", "bartlett"), help="override estimator.window")
    parser.add_argument("--forgetting", type=float, help="override estimator.forgetting")
    parser.add_argument("--models", nargs="+", help="override models.enabled (e.g. CZ Cm)")


def _add_method(parser: Any, what: str) -> None:
    """--method of replay and campaign (estimator.method, checked with the configuration)."""
    parser.add_argument("--method", choices=("time", "frequency", "both"), help=f"override estimator.method: {what}")


def _add_campaign(sub: Any) -> None:
    cp = sub.add_parser("campaign", help="many maneuvers through the replay's pipeline into Table 4 and Fig. 12",
                        description="Every maneuver through the replay's pipeline with the configured lags and with "
                                    "all lags; writes maneuvers.csv, table4.csv, table4.md, summary.txt and "
                                    "fig12_<model>.png to --out. Exit status 0 when some maneuver was estimated, 1 "
                                    "when none was, 2 on bad input or an unreachable scheduler.")
    cp.add_argument("inputs", nargs="+", metavar="INPUT",
                    help="replay bags, one per maneuver; or one recording cut by --maneuvers")
    cp.add_argument("--config", help="ROS parameter file, e.g. config/t2.yaml (default: node defaults)")
    cp.add_argument("--out", required=True, help="output directory")
    cp.add_argument("--maneuvers", metavar="FILE",
                    help="YAML 'maneuvers:' list of {name, start, end} (s from the recording's start) cutting the "
                         "one INPUT into maneuvers")
    cp.add_argument("--scheduler", metavar="ADDRESS",
                    help="run on the Dask cluster whose scheduler listens at ADDRESS (tcp://host:8786); its workers "
                         "must read the INPUT paths (default: local processes)")
    cp.add_argument("--workers", type=_integer(1), help="local worker processes (default: every core)")
    _add_estimator_overrides(cp)
    _add_method(cp, "the time-domain estimates, the frequency-domain ones or both (rows of their own, method "
                    "frequency, in every output)")
    cp.add_argument("--lenient", action="store_true",
                    help="pass out-of-order and duplicate stamps to the pipeline (counted like the node does)")
    _add_figure_options(cp, "skip the Fig. 12 plots")
    cp.add_argument("--quiet", action="store_true", help="no progress bar")
    cp.add_argument("--force", action="store_true", help=_FORCE_HELP)
    cp.set_defaults(func=_campaign)


def _add_play(sub: Any) -> None:
    from .ros.player import DEFAULT_WINDOW  # no ROS import at module level

    pl = sub.add_parser("play", help="publish a replay bag over DDS with /clock",
                        description="Publish a replay bag over DDS with /clock. Exit status 0 when every reliable "
                                    "subscriber acknowledged every message, 1 when not (what was not delivered is "
                                    "printed), 2 on bad input.")
    pl.add_argument("bag")
    pl.add_argument("--rate", type=_real(0.0), default=1.0,
                    help="rate factor (default 1 = real time; 0 = as fast as the acknowledgements allow)")
    pl.add_argument("--loop", type=_integer(1), default=1, metavar="N",
                    help="play the bag N times; stamps and /clock restart with every pass (default 1)")
    pl.add_argument("--window", type=_integer(1), default=DEFAULT_WINDOW,
                    help="messages per topic that may await acknowledgement; the publishers keep this many "
                         f"(default {DEFAULT_WINDOW}, the node's default qos.depth)")
    pl.add_argument("--ack-timeout", type=_real(0.0), default=30.0, metavar="SECONDS",
                    help="how long to wait for the acknowledgements of a window and at the end (default 30)")
    pl.add_argument("--report", action="store_true",
                    help="print per topic the messages published, acknowledged, and the discovered subscriptions")
    pl.add_argument("--no-clock", action="store_true", help="do not publish /clock")
    pl.add_argument("--best-effort", action="store_true", help="best-effort QoS (default reliable)")
    pl.add_argument("--wait", type=_integer(0), default=0, help="wait for this many subscribers on each topic")
    pl.add_argument("--delay", type=_real(0.0), default=0.5,
                    help="seconds between discovery and the first message (default 0.5)")
    pl.set_defaults(func=_play)


def _add_operator_commands(sub: Any) -> None:
    """dashboard, status, enable, disable, reset (docs/dashboard.md)."""
    node_help = "the estimator node's full name (default /rls_estimator; e.g. /ns/rls_estimator)"
    db = sub.add_parser("dashboard", help="control-room web page of a running node's estimates (or of a replay)")
    db.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; any other needs "
                                                        "a token, generated and printed when not given)")
    db.add_argument("--port", type=_integer(0), default=8080, help="TCP port (default 8080; 0 picks a free one)")
    db.add_argument("--node", default="/rls_estimator", help=node_help)
    db.add_argument("--replay", metavar="DIR",
                    help="show a finished replay's outputs (the --out DIR of rls-uncertainty replay)")
    db.add_argument("--reference", metavar="FILE", help="YAML of reference values by parameter name (CZ_alpha: -3.9)")
    db.add_argument("--token", help="token the page must present (at least 16 characters; default: generated when "
                                    "--host is not loopback)")
    db.set_defaults(func=_dashboard)
    st = sub.add_parser("status", help="the node's inputs, samples and models from /diagnostics, refreshed in place")
    st.add_argument("--once", action="store_true", help="print one report and exit")
    st.add_argument("--node", default="/rls_estimator", help=node_help)
    st.add_argument("--timeout", type=_real(0.0, low_open=True), default=5.0,
                    help="seconds to wait for the node's first report (default 5)")
    st.set_defaults(func=_status)
    for name, text in (("enable", "start estimating (~/enable true)"),
                       ("disable", "stop estimating; samples still counted (~/enable false)"),
                       ("reset", "restart the estimator and every input state (~/reset)")):
        sp = sub.add_parser(name, help=text)
        sp.add_argument("--node", default="/rls_estimator", help=node_help)
        sp.add_argument("--timeout", type=_real(0.0, low_open=True), default=5.0,
                        help="seconds to wait for the node to answer (default 5)")
        sp.set_defaults(func=_service)


_SUBCOMMANDS = (_add_demo, _add_simulate, _add_montecarlo, _add_multisine, _add_make_bag, _add_convert, _add_replay,
                _add_campaign, _add_play, _add_operator_commands)


def _version() -> str:
    """The installed package's version, which setup.py reads from package.xml (the one place it
    is written); from package.xml itself in a source tree that was never installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("rls_uncertainty")
    except PackageNotFoundError:
        from .settings.config import package_path

        return ElementTree.parse(package_path("package.xml")).getroot().findtext("version", "unknown")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="rls-uncertainty",
        description="Recursive least squares with colored-residual parameter uncertainty.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = int(args.func(args) or 0)
        sys.stdout.flush()  # here, so that a reader gone (below) is seen here
        return code
    except BrokenPipeError:
        # Whatever read the output stopped reading (`| head`): the command's files are
        # written; nothing more to say, and nothing more can be printed. Python's own exit
        # flush must not fail again on the closed pipe.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except (RlsUncertaintyError, OSError) as exc:
        # The package's own errors and file-system problems are the user's to fix; anything
        # else is a bug and shows its traceback. One line, whatever the message holds.
        message = " ".join(str(exc).split())
        print(f"rls-uncertainty {args.command}: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
