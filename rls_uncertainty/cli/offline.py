"""``replay``, ``campaign`` and ``predict``: bags through the node's pipeline, offline.

All read ``--config`` as the node reads its parameter file and take the estimator's and the
models' flags over it (:data:`PARAMETER_FLAGS`, made from the settings' declarations), and the
figure flags of :class:`..offline.figures.FigureOptions`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from ..extras import require
from ..offline.figures import FigureOptions
from .flags import (
    FORCE_HELP,
    add_option_flags,
    add_parameter_flags,
    add_progress,
    add_renamed,
    add_workers,
    option_values,
    parameter_overrides,
    progress_mode,
    real,
)
from .simulation import ESTIMATOR_FLAGS

__all__ = ["PARAMETER_FLAGS", "replay_params", "add_replay", "add_campaign", "add_predict"]

# The node's parameters the offline commands take as flags, over --config.
PARAMETER_FLAGS = (*ESTIMATOR_FLAGS, "models.enabled", "estimator.method")


def replay_params(args: argparse.Namespace, command: str = "replay") -> dict[str, Any]:
    """The parameters of ``--config`` (read as the node reads it; what it ignores said once) and
    the flags over them, the whole configuration checked (the aircraft file read)."""
    from ..settings.parameters import PARAMETER_NAMES, pipeline_config
    from ..settings.sources import node_parameters_file, with_origin

    params: dict[str, Any] = {}
    origins: dict[str, str] = {}
    if args.config:
        from_file = node_parameters_file(args.config)
        for note in from_file.warnings:
            print(f"rls-uncertainty {command}: warning: {note}", file=sys.stderr)
        params = {k: v for k, v in from_file.values.items() if k in PARAMETER_NAMES}
        origins = from_file.origins
    flags = parameter_overrides(args, PARAMETER_FLAGS)
    params.update(flags)
    origins.update({name: f"--{PARAMETER_NAMES[name].flag.lstrip('-')}" for name in flags
                    if PARAMETER_NAMES[name].flag})
    try:
        pipeline_config(params)  # every setting checked and the aircraft file read before any output
    except ConfigError as exc:
        raise with_origin(exc, origins) from exc
    return params


def _yaml_file(name_or_path: str, directory: Path) -> Path:
    """The file a parameter or aircraft name stands for (as :mod:`..settings.models` resolves it)."""
    path = Path(name_or_path)
    return path if path.suffix else directory / f"{name_or_path}.yaml"


def _figures(args: argparse.Namespace) -> FigureOptions | None:
    """The figure options, or None with --no-figures; matplotlib checked before any work."""
    if args.no_figures:
        return None
    require("figures", what="drawing the figures", instead="give --no-figures")
    return FigureOptions(**option_values(args, FigureOptions))


def _replay(args: argparse.Namespace) -> int:
    from ..offline.compare import DEFAULT_ATOL, DEFAULT_RTOL, check_reference, comparable, compare_replays
    from ..offline.replay import planned_run, replay, run_summary
    from ..settings.models import config_dir

    params = replay_params(args)
    figures = _figures(args)
    # Files the replay reads besides the bag: never replaced by its output, even with --force.
    inputs = [_yaml_file(args.config, config_dir())] if args.config else []
    if isinstance(params.get("aircraft"), str) and params["aircraft"]:
        inputs.append(_yaml_file(params["aircraft"], config_dir() / "aircraft"))
    if (args.rtol is not None or args.atol is not None) and not args.compare:
        raise ConfigError("--rtol and --atol set the tolerance of --compare DIR: give the reference replay's directory")
    if args.compare:  # what can be checked before the bag is read, is
        inputs.append(args.compare)
        comparable(planned_run(params, start=args.start, end=args.end, strict=not args.lenient),
                   check_reference(args.compare), bag=False)
    result = replay(args.bag, params, args.out, start=args.start, end=args.end, strict=not args.lenient,
                    progress=progress_mode(args), plots=figures is not None, figures=figures, force=args.force,
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
    from ..campaign import CampaignSettings, campaign_to, from_bags, load_maneuvers
    from ..executors import LocalProcesses, executor_for
    from ..settings.models import config_dir
    from ..settings.parameters import node_config, pipeline_config

    params = replay_params(args, "campaign")
    executor = executor_for(args.scheduler, args.workers)
    settings = CampaignSettings(pipeline_config(params), node_config(params).topics, strict=not args.lenient,
                                **option_values(args, CampaignSettings))
    inputs = [_yaml_file(args.config, config_dir())] if args.config else []
    source = settings.config.maneuvers.source
    if args.maneuvers and source != "off":  # (two ways of cutting: neither may silently win)
        raise ConfigError(f"--maneuvers FILE and maneuvers.source {source} both cut the recording into maneuvers: "
                          "give one (maneuvers.source off to cut it by FILE)")
    if not args.maneuvers and source != "off":
        if len(args.inputs) != 1:  # (each bag would be one maneuver, the setting silently unused)
            raise ConfigError(f"maneuvers.source {source} cuts one recording into maneuvers; got {len(args.inputs)} "
                              "INPUTs: give one recording, or maneuvers.source off for one maneuver per bag")
        return _split_campaign(args, settings, inputs)
    if args.maneuvers:
        if len(args.inputs) != 1:
            raise ConfigError(f"--maneuvers cuts one recording into maneuvers; got {len(args.inputs)} INPUTs")
        maneuvers = load_maneuvers(args.maneuvers, args.inputs[0])
        inputs.append(args.maneuvers)
    else:
        maneuvers = from_bags(args.inputs)
    if isinstance(executor, LocalProcesses) and (note := executor.capped(len(maneuvers), "maneuver")):
        print(f"rls-uncertainty campaign: {note}", file=sys.stderr)
    result = campaign_to(args.out, maneuvers, settings, executor, progress=progress_mode(args),
                         figures=_figures(args), force=args.force, inputs=inputs)
    print(result.summary(), end="")
    s = result.seconds()
    print(f"{len(maneuvers)} maneuvers in {result.wall_seconds + result.write_seconds:.1f} s "
          f"({result.per_minute:.0f} per minute) on {result.executor}; worker time: read {s.get('read', 0):.1f} s, "
          f"pipeline {s.get('pipeline', 0):.1f} s, all lags {s.get('all_lags', 0):.1f} s; writing "
          f"{result.write_seconds:.1f} s; wrote {args.out}")
    return 0 if any(res.problem is None for res in result.results) else 1


def _split_campaign(args: argparse.Namespace, settings: Any, inputs: list[Any]) -> int:
    """``campaign RECORDING`` with ``maneuvers.source`` events or detect: the recording cut into
    maneuvers as the node cuts its stream (:mod:`..campaign.split`)."""
    from ..campaign.split import split_campaign_to

    result = split_campaign_to(args.out, args.inputs[0], settings, figures=_figures(args),
                               progress=progress_mode(args), force=args.force, inputs=inputs)
    print(result.summary(), end="")
    print(f"{len(result.results)} maneuvers cut from {args.inputs[0]} by maneuvers.source "
          f"{settings.config.maneuvers.source} in {result.wall_seconds + result.write_seconds:.1f} s; wrote {args.out}")
    return 0 if any(res.problem is None for res in result.results) else 1


def _add_common(parser: argparse.ArgumentParser, no_figures: str) -> None:
    """--config, the parameter flags, --lenient, the figure flags, --progress/--quiet and --force."""
    parser.add_argument("--config", help="ROS parameter file, e.g. config/t2.yaml (default: node defaults)")
    parser.add_argument("--out", required=True, help="output directory")
    add_parameter_flags(parser, PARAMETER_FLAGS)
    parser.add_argument("--lenient", action="store_true",
                        help="pass out-of-order and duplicate stamps to the pipeline (counted like the node does)")
    parser.add_argument("--no-figures", action="store_true", help=no_figures)
    add_option_flags(parser, FigureOptions)
    add_renamed(parser, ["--no-figures"])
    add_progress(parser)
    parser.add_argument("--force", action="store_true", help=FORCE_HELP)


def add_replay(sub: Any) -> None:
    rp = sub.add_parser("replay", help="run a replay bag through the node's pipeline offline")
    rp.add_argument("bag", help="replay bag on the standard topics")
    _add_common(rp, "no figures (summary.txt and the data files only)")
    rp.add_argument("--start", type=real(0.0), help="start, s from the bag start")
    rp.add_argument("--end", type=real(0.0), help="end, s from the bag start (after --start)")
    rp.add_argument("--compare", metavar="DIR",
                    help="compare the outputs with an earlier replay's in DIR sample by sample: exit 0 when equal "
                         "within the tolerance, 1 when not (the largest differences printed), 2 when the runs are "
                         "not comparable (another bag, span, models, sample rate or no estimation method in common) "
                         "or DIR is damaged (a value not finite, a malformed file, an inconsistent run.json)")
    rp.add_argument("--rtol", type=real(0.0), metavar="R",
                    help="--compare's relative tolerance, of |estimate| + its standard error (default 1e-6)")
    rp.add_argument("--atol", type=real(0.0), metavar="A",
                    help="--compare's absolute tolerance, in the units of each derivative (default 0)")
    rp.set_defaults(func=_replay)


def add_campaign(sub: Any) -> None:
    cp = sub.add_parser("campaign", help="many maneuvers through the replay's pipeline into Table 4 and Fig. 12",
                        description="Every maneuver through the replay's pipeline with the configured lags and with "
                                    "all lags; writes maneuvers.csv, table4.csv, table4.md, summary.txt and "
                                    "fig12_<model>.png to --out. Exit status 0 when some maneuver was estimated, 1 "
                                    "when none was, 2 on bad input or an unreachable scheduler.")
    cp.add_argument("inputs", nargs="+", metavar="INPUT",
                    help="replay bags, one per maneuver; or one recording cut by --maneuvers")
    cp.add_argument("--maneuvers", metavar="FILE",
                    help="YAML 'maneuvers:' list of {name, start, end} (s from the recording's start) cutting the "
                         "one INPUT into maneuvers")
    add_workers(cp, "the maneuvers (its workers must read the INPUT paths)")
    _add_common(cp, "skip the Fig. 12 plots")
    from ..campaign.maneuvers import CampaignSettings

    add_option_flags(cp, CampaignSettings)
    cp.set_defaults(func=_campaign)


def _predict(args: argparse.Namespace) -> int:
    """A run's models applied to another maneuver (:mod:`..offline.predict`)."""
    from ..offline.predict import PredictOptions, predict
    from ..settings.models import config_dir

    params = replay_params(args, "predict")
    options = PredictOptions(**option_values(args, PredictOptions))
    inputs = [_yaml_file(args.config, config_dir())] if args.config else []
    result = predict(args.run_dir, args.bag, params, args.out, options, strict=not args.lenient,
                     progress=progress_mode(args), force=args.force, inputs=inputs)
    print(result.summary())
    print(f"wrote {args.out}")
    return 0


def add_predict(sub: Any) -> None:
    pp = sub.add_parser("predict", help="apply the models of a replay or campaign to another maneuver",
                        description="Apply the final models of RUN_DIR (a replay's or a campaign's output) to the "
                                    "regressors of BAG, formed by the replay's pipeline under --config; write "
                                    "prediction.csv (measured, predicted, interval per model) and summary.txt to "
                                    "--out and print per model the fit error and the fraction of measured "
                                    "coefficients inside the prediction interval.")
    pp.add_argument("run_dir", metavar="RUN_DIR", help="output directory of a replay or a campaign (models.json)")
    pp.add_argument("bag", metavar="BAG", help="replay bag of the maneuver to predict")
    pp.add_argument("--config", help="ROS parameter file, e.g. config/t2.yaml (default: node defaults)")
    pp.add_argument("--out", required=True, help="output directory")
    add_parameter_flags(pp, PARAMETER_FLAGS)
    pp.add_argument("--lenient", action="store_true",
                    help="pass out-of-order and duplicate stamps to the pipeline (counted like the node does)")
    from ..offline.predict import PredictOptions

    add_option_flags(pp, PredictOptions)
    add_progress(pp)
    pp.add_argument("--force", action="store_true", help=FORCE_HELP)
    pp.set_defaults(func=_predict)
