"""The command line's vocabulary: one flag per setting, made from the setting's declaration.

A setting's flag (``--lag-span``, ``--forgetting``, ``--dpi``...) is written on its options
class's field (:mod:`rls_uncertainty.schema`), with its range or choices, its special words
(``all``, ``default``, ``auto``) and its meaning; :func:`add_parameter_flags` and
:func:`add_option_flags` make the argparse options from it, so every command that takes a
setting takes it with the same name, unit (spans in seconds everywhere) and range, and
:func:`parameter_overrides` reads them back as the node's parameters. A renamed flag is refused
naming the new one (:data:`RENAMED_FLAGS`). The flags of a command's own arguments (paths,
``--force``, ``--workers``...) are written once here too.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from ..schema import default_of, expected, kind_of, number, settings, valid
from ..settings.parameters import PARAMETER_NAMES, Parameter

__all__ = ["RENAMED_FLAGS", "add_parameter_flags", "add_option_flags", "parameter_overrides", "option_values",
           "add_workers", "add_progress", "progress_mode", "real", "integer", "FORCE_HELP"]

# Flags renamed for one vocabulary across commands: the old one is refused naming the new one.
RENAMED_FLAGS = {
    "--lags": "--lag-span SECONDS (lags / rate: 50 lags at 50 Hz = 1.0)",
    "--max-lags": "--max-lag-span SECONDS (max lags / rate)",
    "--burn-in": "--burn-in-span SECONDS (samples / rate)",
    "--jobs": "--workers",
    "--no-plots": "--no-figures",
}
FORCE_HELP = "replace an existing non-empty output directory (never the input)"


def real(low: float, *, low_open: bool = False, high: float | None = None) -> Callable[[str], float]:
    """An argparse type: a finite number >= low (> low with ``low_open``), <= high."""
    bound = f"> {low:g}" if low_open else f">= {low:g}"
    if high is not None:
        bound = f"in ({low:g}, {high:g}]" if low_open else f"in [{low:g}, {high:g}]"

    def number(value: str) -> float:
        try:
            x = float(value)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and (x > low if low_open else x >= low) and (high is None or x <= high)):
            raise argparse.ArgumentTypeError(f"must be a finite number {bound}, got {value!r}")
        return x

    return number


def integer(low: int) -> Callable[[str], int]:
    """An argparse type: an integer >= low."""

    def whole(value: str) -> int:
        try:
            n = int(value)
        except ValueError:
            n = None
        if n is None or n < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {value!r}")
        return n

    return whole


@dataclass(frozen=True)
class _Assign:
    """A flag's word that sets other parameters than the flag's own (``--lag-span auto``)."""

    values: dict[str, Any]


def _span_type(p: Parameter) -> Callable[[str], Any]:
    """A span flag: seconds in the parameter's range (0 where 0 is special), or a word: a
    special's (``all`` is -1) or a choice of the companion parameter (``auto``)."""
    words: dict[str, Any] = {s.word: s.seconds for s in p.specials if s.word}
    if p.companion:
        choices = PARAMETER_NAMES[p.companion].choices
        words.update({c: _Assign({p.companion: c}) for c in choices[1:]})
    low = min([p.low or 0.0, *(s.seconds for s in p.specials if s.seconds >= 0)])
    low = max(low, 0.0)
    said = f"a number of seconds in [{low:g}, {p.high:g}]" + "".join(f" or {w}" for w in words)

    def span(value: str) -> Any:
        if value in words:
            return words[value]
        try:
            x = float(value)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and low <= x <= (p.high or math.inf)):
            raise argparse.ArgumentTypeError(f"must be {said} ({p.name}), got {value!r}")
        return x

    return span


def _number_type(p: Parameter) -> Callable[[str], Any]:
    kind = type(p.default)

    def number(value: str) -> Any:
        try:
            x: Any = kind(value)
        except ValueError:
            x = math.nan
        ok = isinstance(x, (int, float)) and math.isfinite(x) and (p.low is None or x >= p.low) \
            and (p.high is None or x <= p.high)
        if not ok:
            noun = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"must be {noun} in [{p.low:g}, {p.high:g}] ({p.name}), got {value!r}")
        return x

    return number


def _help(p: Parameter) -> str:
    """The declaration in words: meaning, unit, range, special values, parameter and default."""
    unit = f", {p.unit}" if p.unit else ""
    bounds = f"; {number(max(p.low, 0.0) if p.specials else p.low)} to {number(p.high)}" \
        if p.low is not None and p.high is not None else ""
    words = [f"{s.word or number(s.seconds)}: {s.meaning}" for s in p.specials]
    if p.companion:
        words += [f"{c}: {p.companion} {c}" for c in PARAMETER_NAMES[p.companion].choices[1:]]
    word = next((repr(s.word) for s in p.specials if s.word and s.seconds == p.default), None)
    default = word or (" ".join(p.default) if isinstance(p.default, list) else p.default)
    text = f"{p.description}{unit}{bounds}{''.join('; ' + w for w in words)} (parameter {p.name}, default {default})"
    return text.replace("%", "%%")


def add_parameter_flags(parser: argparse.ArgumentParser, names: Iterable[str]) -> None:
    """The flags of the node's parameters ``names`` (their :attr:`Parameter.flag`), and the
    renamed flags they replace, refused naming them. Not given, a flag leaves its parameter
    to the parameter file (or its default)."""
    flags = []
    for name in names:
        p = PARAMETER_NAMES[name]
        flags.append(p.flag)
        metavar = p.flag.lstrip("-").upper().replace("-", "_")
        if p.specials or p.companion:
            parser.add_argument(p.flag, dest=p.name, type=_span_type(p), metavar="SECONDS", help=_help(p))
        elif p.choices:
            parser.add_argument(p.flag, dest=p.name, choices=p.choices, help=_help(p))
        elif isinstance(p.default, list):
            parser.add_argument(p.flag, dest=p.name, nargs="+", metavar=metavar, help=_help(p))
        elif p.unit == "s" and p.low is not None:  # a span without specials
            parser.add_argument(p.flag, dest=p.name, type=_span_type(p), metavar="SECONDS", help=_help(p))
        else:
            parser.add_argument(p.flag, dest=p.name, type=_number_type(p), metavar=metavar, help=_help(p))
    add_renamed(parser, flags)


def add_renamed(parser: argparse.ArgumentParser, flags: Iterable[str]) -> None:
    """The old names of ``flags`` (:data:`RENAMED_FLAGS`), each refused naming its new one."""
    given = set(flags)
    for old, new in RENAMED_FLAGS.items():
        if new.split()[0] in given:
            parser.add_argument(old, action=_Renamed, renamed=new)


def parameter_overrides(args: argparse.Namespace, names: Iterable[str]) -> dict[str, Any]:
    """The parameters the flags of ``names`` set: a span's number (or special word) sets the
    span and its companion to its first choice (``--lag-span 0.4`` is fixed lags whatever
    the parameter file says), a companion's word the companion only."""
    out: dict[str, Any] = {}
    for name in names:
        value = getattr(args, name, None)
        if value is None:
            continue
        if isinstance(value, _Assign):
            out.update(value.values)
            continue
        p = PARAMETER_NAMES[name]
        out[name] = list(value) if isinstance(value, list) else value
        if p.companion:
            out[p.companion] = PARAMETER_NAMES[p.companion].choices[0]
    return out


def add_option_flags(parser: argparse.ArgumentParser, cls: type) -> None:
    """The flags of an options class's fields that declare one (``cli``), their defaults the
    fields', checked by the class when it is built (:func:`option_values`)."""
    for f, s in settings(cls):
        if not s.cli:
            continue
        default = default_of(f)
        kind = kind_of(f) if default is not None else str
        if kind is bool:
            parser.add_argument(s.cli, dest=f.name, action="store_true", help=s.description)
            continue
        shown = (",".join(default) or "none") if isinstance(default, tuple) else (default if default != "" else "none")
        ok = kind is tuple or s.own_check
        what = "" if ok else f"; {expected(kind, s)}"
        parser.add_argument(s.cli, dest=f.name, default=default, type=_option_type(kind, s),
                            metavar=s.cli.lstrip("-").upper(), help=f"{s.description}{what} (default {shown})")


def _option_type(kind: type, s: Any) -> Callable[[str], Any]:
    def convert(value: str) -> Any:
        if kind is tuple:
            return tuple(x.strip() for x in value.split(","))
        if kind in (int, float):
            try:
                x = kind(value)
            except ValueError:
                raise argparse.ArgumentTypeError(f"must be {expected(kind, s)}, got {value!r}") from None
            ok, x = valid(kind, s, x)
            if not ok:
                raise argparse.ArgumentTypeError(f"must be {expected(kind, s)}, got {value!r}")
            return x
        return value

    return convert


def option_values(args: argparse.Namespace, cls: type) -> dict[str, Any]:
    """The keyword arguments of ``cls`` from its flags (given, or the fields' defaults)."""
    return {f.name: getattr(args, f.name) for f, s in settings(cls) if s.cli}


def add_workers(parser: argparse.ArgumentParser, what: str) -> None:
    """``--workers`` and ``--scheduler`` (:func:`..executors.executor_for`), and ``--jobs``
    refused naming ``--workers``."""
    parser.add_argument("--workers", type=integer(1), help="local worker processes (default: every core)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help=f"run {what} on the Dask cluster whose scheduler listens at ADDRESS (tcp://host:8786) "
                             "(default: local processes)")
    add_renamed(parser, ["--workers"])


def add_progress(parser: argparse.ArgumentParser) -> None:
    """``--progress`` and ``--quiet``: the progress bars on stderr always, or never (default: on a
    terminal only; :mod:`..progress`)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--progress", action="store_true",
                       help="progress bars with rate and time left on stderr even when it is not a terminal "
                            "(default: on a terminal only)")
    group.add_argument("--quiet", action="store_true", help="no progress bars")


def progress_mode(args: argparse.Namespace) -> bool | None:
    """:mod:`..progress`'s mode from :func:`add_progress`'s flags: True, False, or None (on a
    terminal only)."""
    return True if args.progress else False if args.quiet else None


class _Renamed(argparse.Action):
    """An option that was renamed: using it is a usage error naming the new one."""

    def __init__(self, option_strings: list[str], dest: str, renamed: str = "", **kwargs: Any) -> None:
        self.renamed = renamed
        super().__init__(option_strings, dest, nargs="?", help=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        parser.error(f"{option_string} is now {self.renamed}")
