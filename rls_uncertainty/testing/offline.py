"""In-process replays for tests: :func:`replay_bag` runs a bag through the same pipeline as
``rls-uncertainty replay`` (:func:`..replay.run_pipeline`), writes no file and keeps every
sample's estimates (:class:`..results.ReplayResult`). No ROS import."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from ..offline.bags import InputStream
from ..offline.replay import run_pipeline
from ..offline.results import History, ReplayResult
from ..settings.parameters import PARAMETER_NAMES, node_config, pipeline_config
from ..settings.sources import load_parameters_file

__all__ = ["parameters", "replay_bag"]

Config = str | Path | Mapping[str, Any] | None


def parameters(config: Config = None, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The node parameters a test names: ``config`` is a parameter file (a path, or a name
    of the package's ``config/`` directory such as ``"t2"``), a mapping of dotted parameter
    names (``{"estimator.lag_span": 0.4}``) or None (the node's defaults); ``overrides`` replace
    single parameters, their names with dots or with ``__`` for each dot (``estimator__lag_span``:
    the form Python keywords allow). Every value is checked as the node checks it: an unknown
    name or a bad value is a :class:`..errors.ConfigError` naming the parameter."""
    if config is None:
        params: dict[str, Any] = {}
    elif isinstance(config, Mapping):
        params = {str(k): v for k, v in config.items()}
    else:
        params = load_parameters_file(config)
    for name, value in (overrides or {}).items():
        params[name.replace("__", ".")] = value
    unknown = sorted(set(params) - set(PARAMETER_NAMES))
    if unknown:
        raise ConfigError(f"unknown parameter(s) {unknown}; names are the node's (estimator.lag_span), or with __ "
                          "for each dot as keywords (estimator__lag_span)")
    pipeline_config(params)  # every value checked here, before any bag is read
    node_config(params)
    return params


def replay_bag(bag: str | Path, config: Config = None, *, start: float | None = None, end: float | None = None,
               strict: bool = True, **overrides: Any) -> ReplayResult:
    """``bag`` (a replay bag on the standard topics) through the node's pipeline in this
    process, with the parameters of :func:`parameters` (``config`` and the keyword
    ``overrides``, ``estimator__lag_span=0.4`` for ``estimator.lag_span``). ``start``/``end`` (s from
    the bag start) and ``strict`` are ``replay``'s ``--start``/``--end``/``--lenient``. Every
    sample's estimates are kept (:meth:`..results.ReplayResult.series`); the messages are read
    as a stream."""
    params = parameters(config, overrides)
    config_ = pipeline_config(params)
    with InputStream(bag, node_config(params).topics, strict=strict, start=start, end=end) as stream:
        return run_pipeline(stream, config_, record=False, keep_outputs=False,
                            history=History([m.parameter_names for m in config_.models]))
