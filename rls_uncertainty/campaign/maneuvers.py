"""What a campaign analyses: its maneuvers, each a replay bag or a span of one long recording.

* :func:`from_bags` - one maneuver per replay bag, named after the bag (its directory or file
  name without ``.mcap``).
* :func:`load_maneuvers` - a maneuvers file cutting one recording into maneuvers without
  splitting it: YAML, ``maneuvers:`` a list of ``{name, start, end}`` (s from the recording's
  start, as ``replay --start/--end``)::

      maneuvers:
        - {name: m01, start: 62.0, end: 74.0}
        - {name: m02, start: 121.5, end: 133.5}

Every problem is a :class:`.errors.ConfigError` naming the file, the entry and the key (the YAML
itself is read by :mod:`..settings.yaml_files`: a key given twice is refused there).
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..datapath.maneuvers import MIN_SPAN
from ..errors import ConfigError
from ..schema import check, option
from ..settings.yaml_files import load

if TYPE_CHECKING:  # annotations only
    from ..datapath.config import PipelineConfig

# campaign --min-span's default: the shortest maneuver whose parameters can be flagged converged
# (datapath.maneuvers.MIN_SPAN).

__all__ = ["Maneuver", "from_bags", "load_maneuvers", "CampaignSettings", "MIN_SPAN"]


@dataclass(frozen=True)
class Maneuver:
    """One maneuver: ``name`` (unique in the campaign), the replay ``bag`` it is read from and,
    for a span of a longer recording, ``start``/``end`` (s from the bag's start; None: the
    whole bag)."""

    name: str
    bag: str
    start: float | None = None
    end: float | None = None


def _bag_name(path: Path) -> str:
    return path.stem if path.suffix == ".mcap" else path.name


def _check_unique(names: Sequence[str], where: str) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise ConfigError(f"{where}: two maneuvers are named {name!r}; maneuver names must be unique")
        seen.add(name)


def from_bags(bags: Sequence[str | Path]) -> list[Maneuver]:
    """One maneuver per replay bag, in the order given, named after the bag."""
    if not bags:
        raise ConfigError("a campaign needs at least one replay bag (INPUT)")
    # (os.path.realpath: "." is named after its directory; a symbolic link loop is left as it is,
    # for the bag check to refuse.)
    out = [Maneuver(_bag_name(Path(os.path.realpath(b))), str(b)) for b in bags]
    _check_unique([m.name for m in out], "INPUT")
    return out


def _seconds(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
        raise ConfigError(f"{where} must be a finite number of seconds >= 0 from the recording's start, "
                          f"got {value!r}")
    return float(value)


def load_maneuvers(path: str | Path, recording: str | Path) -> list[Maneuver]:
    """The maneuvers of ``path`` (module docstring), each a span of ``recording``."""
    path = Path(path)
    data = load(path, "maneuvers file")
    entries = data.get("maneuvers") if isinstance(data, dict) else None
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{path}: expected 'maneuvers:' with a list of {{name, start, end}} entries")
    unknown = sorted(str(k) for k in data if k != "maneuvers")
    if unknown:
        raise ConfigError(f"{path}: unknown key {unknown[0]!r} (the file holds 'maneuvers:' only)")
    out = []
    for i, entry in enumerate(entries, 1):
        where = f"{path}: maneuver {i}"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where}: expected a mapping {{name, start, end}}, got {entry!r}")
        extra = sorted(str(k) for k in entry if k not in ("name", "start", "end"))
        missing = [k for k in ("name", "start", "end") if k not in entry]
        if extra or missing:
            what = f"unknown key {extra[0]!r}" if extra else f"missing {missing[0]!r}"
            raise ConfigError(f"{where}: {what} (each maneuver has name, start and end)")
        name = entry["name"]
        if not isinstance(name, (str, int)) or isinstance(name, bool) or not str(name).strip():
            raise ConfigError(f"{where}: name must be a non-empty string, got {name!r}")
        start, end = _seconds(entry["start"], f"{where}: start"), _seconds(entry["end"], f"{where}: end")
        if end <= start:
            raise ConfigError(f"{where} ({name}): end ({end:g} s) must be after start ({start:g} s)")
        out.append(Maneuver(str(name).strip(), str(recording), start, end))
    _check_unique([m.name for m in out], str(path))
    return out


@dataclass(frozen=True)
class CampaignSettings:
    """What every maneuver is run with: the pipeline's configuration, the input topics
    (``topics.*``), ``strict`` (``replay``'s default; False is ``--lenient``) and ``min_span``
    (``--min-span``, s: a maneuver with less data is ``too_short``)."""

    config: PipelineConfig
    topics: Mapping[str, str] = field(default_factory=dict)
    strict: bool = True
    min_span: float = option(MIN_SPAN, "a maneuver with less data than this is reported too_short and left out of "
                             "Table 4 and Fig. 12 (default: the T-2 models' publication span, 2.1 s, plus "
                             "convergence.window, 2 s: the shortest whose parameters can be flagged converged)",
                             unit="s", low=0.0, high=3600.0, cli="--min-span")

    def __post_init__(self) -> None:
        check(self, "campaign")
