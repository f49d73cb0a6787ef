"""Every setting written once: its default, bounds, unit, meaning and names.

An options class of the package is a frozen dataclass whose fields are made with
:func:`option`: the field's default is the setting's default, and the field's metadata (a
:class:`Setting`) holds the rest: the bounds, the unit, one sentence of meaning, the name of
the node's ROS parameter (``ros``) and of the command line's flag (``cli``). The class checks
its fields once, when it is built, by calling :func:`check` in ``__post_init__`` (and then its
own checks that involve two fields). Everything else is generated from the metadata by
:mod:`rls_uncertainty.settings`: the node's parameter descriptors, the parameter table of
docs/node.md, the command line's flags and the reading of parameter files. Standard library
only, so that the numerical core may import it.

Time spans. A span is given in seconds outside (a parameter, a flag) and held in samples by the
estimators. :class:`Span` declares how: the parameter's range in seconds and its special values
(``-1``: all lags), and :func:`samples` is the one conversion, seconds x rate rounded half up;
a positive span shorter than half a sample, or longer than the field may hold, is refused
naming the parameter. A span's default in seconds is its field's default at
:data:`REFERENCE_RATE` (50 samples are 1 s at the paper's 50 Hz), or the special value that
stands for the field's default.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import MISSING, Field, dataclass, field, fields
from numbers import Integral, Real
from typing import Any

from .errors import ConfigError

__all__ = ["REFERENCE_RATE", "Special", "Span", "Choice", "Setting", "option", "settings", "setting_of", "check",
           "kind_of", "expected", "number", "valid", "samples", "seconds", "span_value", "default_of"]

# The paper's sample rate, Hz: a field counted in samples has its default span in seconds at it.
REFERENCE_RATE = 50.0
_KINDS = (bool, int, float, str, tuple)


@dataclass(frozen=True)
class Special:
    """A value of a span parameter with a meaning of its own: ``seconds`` outside, ``value``
    in the field, ``word`` on the command line (``""``: none), ``meaning`` for the docs."""

    seconds: float
    value: Any
    word: str
    meaning: str


@dataclass(frozen=True)
class Span:
    """The field holds samples; its parameter and flag give seconds in ``[low, high]`` (besides
    the ``specials``), converted at the pipeline's rate by :func:`span_value`."""

    low: float
    high: float
    specials: tuple[Special, ...] = ()

    def special(self, value: float) -> Special | None:
        return next((s for s in self.specials if s.seconds == value), None)


@dataclass(frozen=True)
class Choice:
    """A second parameter of a field: a choice among ``choices`` (the first the default);
    when another is chosen, the field holds ``value`` whatever its own parameter says
    (``estimator.lag_selection: auto`` makes the lags ``"auto"``)."""

    ros: str
    choices: tuple[str, ...]
    value: Any
    description: str


@dataclass(frozen=True)
class Setting:
    """What a field of an options class is (module docstring). ``low``/``high`` bound the
    field's value (inclusive; ``low_open``: ``low`` excluded), ``choices`` list its values;
    ``ros`` is the node's parameter, ``cli`` the flag; ``span`` says the parameter is in
    seconds, ``choice`` gives the field a second parameter; ``own_check``: the class checks
    the field itself (a value of several kinds), :func:`check` leaves it; ``read_only``: the
    node's parameter needs a restart."""

    description: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    choices: tuple[Any, ...] = ()
    ros: str = ""
    cli: str = ""
    span: Span | None = None
    choice: Choice | None = None
    own_check: bool = False
    read_only: bool = False


def option(default: Any, description: str, **setting: Any) -> Any:
    """A dataclass field with ``default`` and the :class:`Setting` of the other arguments."""
    return field(default=default, metadata={"setting": Setting(description, **setting)})


def setting_of(f: Field[Any]) -> Setting | None:
    s = f.metadata.get("setting")
    return s if isinstance(s, Setting) else None


def settings(cls: type) -> Iterator[tuple[Field[Any], Setting]]:
    """The fields of an options class that carry a :class:`Setting`, in their order."""
    for f in fields(cls):
        s = setting_of(f)
        if s is not None:
            yield f, s


def default_of(f: Field[Any]) -> Any:
    """A field's default (its factory's value for a mutable one)."""
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    raise TypeError(f"field {f.name}: a setting needs a default")


def kind_of(f: Field[Any]) -> type:
    """The kind of a field's values, by its default: bool, int, float, str or tuple (of names)."""
    d = default_of(f)
    for k in _KINDS:
        if type(d) is k:
            return k
    raise TypeError(f"field {f.name}: a setting's default is a bool, int, float, str or tuple, got {d!r}")


def number(x: float) -> str:
    """A bound as the docs and the messages write it: an integer whole, a real as ``%g``."""
    return str(x) if isinstance(x, int) else f"{x:g}"


def _bounds(s: Setting) -> str:
    low = "" if s.low is None else number(s.low)
    high = "" if s.high is None else number(s.high)
    if low and high:
        return f" in {'(' if s.low_open else '['}{low}, {high}]"
    if low:
        return f" {'>' if s.low_open else '>='} {low}"
    return f" <= {high}" if high else ""


def expected(kind: type, s: Setting) -> str:
    """What a value must be, in words: ``a number in [0.001, 10] s``."""
    if s.choices:
        return f"one of {list(s.choices)}"
    noun = {bool: "true or false", int: "an integer", float: "a number", str: "text", tuple: "a list of names"}[kind]
    unit = f" {s.unit}" if s.unit and kind in (int, float) and (s.low is not None or s.high is not None) else ""
    return noun + (_bounds(s) if kind in (int, float) else "") + unit


def _is_bool(value: object) -> bool:
    return isinstance(value, bool) or getattr(getattr(value, "dtype", None), "kind", "") == "b"


def _converted(kind: type, value: Any) -> tuple[bool, Any]:
    """(whether ``value`` is of ``kind``, the value as that kind)."""
    if kind is bool:
        return _is_bool(value), bool(value) if _is_bool(value) else value
    if kind is int:
        ok = isinstance(value, Integral) and not _is_bool(value)
        return ok, int(value) if ok else value
    if kind is float:
        ok = isinstance(value, Real) and not _is_bool(value) and math.isfinite(value)
        return ok, float(value) if ok else value
    if kind is str:
        return isinstance(value, str), value
    ok = isinstance(value, (tuple, list)) and all(isinstance(v, str) for v in value)
    return ok, tuple(value) if ok else value


def valid(kind: type, s: Setting, value: Any) -> tuple[bool, Any]:
    """(whether ``value`` is a valid value of the setting, the value normalised to its kind)."""
    ok, value = _converted(kind, value)
    if ok and kind in (int, float):
        above = s.low is None or (value > s.low if s.low_open else value >= s.low)
        ok = above and (s.high is None or value <= s.high)
    if ok and s.choices:
        ok = value in s.choices
    return ok, value


def _name(f: Field[Any], s: Setting, group: str) -> str:
    """The name a refusal gives a field: its parameter (unless a span: the field is in samples),
    else its flag, else ``group.field``."""
    if s.ros and s.span is None:
        return s.ros
    if s.cli and not s.ros:
        return s.cli
    return f"{group}.{f.name}" if group else f.name


def check(obj: Any, group: str) -> None:
    """Check and normalise every field of the options object ``obj`` that carries a
    :class:`Setting` (but ``own_check``): its kind (an int is a float where a float is due),
    bounds and choices. A bad value is a :class:`ConfigError` naming the field as the user
    gives it: its parameter, or its flag, or ``group.field``."""
    for f, s in settings(type(obj)):
        if s.own_check:
            continue
        kind = kind_of(f)
        ok, value = valid(kind, s, getattr(obj, f.name))
        name = _name(f, s, group)
        if not ok:
            raise ConfigError(f"{name} must be {expected(kind, s)}, got {getattr(obj, f.name)!r}", parameter=name)
        object.__setattr__(obj, f.name, value)  # the normalised value (a frozen dataclass)


def samples(name: str, span: float, rate: float, most: int) -> int:
    """``span`` seconds at ``rate`` Hz as a sample count, rounded half up; a positive span of
    less than half a sample, or one of more than ``most`` samples, is refused naming ``name``."""
    n = math.floor(span * rate + 0.5)
    if n < 1:
        raise ConfigError(f"parameter {name!r} = {span:g} s is less than one sample at rate {rate:g} Hz "
                          f"({1 / rate:g} s); give at least {0.5 / rate:g} s, or 0", parameter=name)
    if n > most:
        raise ConfigError(f"parameter {name!r} = {span:g} s at rate {rate:g} Hz is {n} samples; at most {most} are "
                          f"held: shorten {name} or lower rate", parameter=name)
    return n


def seconds(count: float) -> float:
    """A sample count as seconds at :data:`REFERENCE_RATE` (a span's default)."""
    return count / REFERENCE_RATE


def span_value(name: str, s: Setting, value: Any, rate: float) -> Any:
    """A span parameter's ``value`` (seconds, or one of its specials) as its field's value at
    ``rate``: the special's value, or :func:`samples` up to the field's ``high``. A value that
    is not a number, not a special and out of the span's range is refused naming ``name``."""
    span = s.span
    assert span is not None
    ok = isinstance(value, Real) and not _is_bool(value) and math.isfinite(value)
    special = span.special(value) if ok else None
    if special is not None:
        return special.value
    if not (ok and span.low <= value <= span.high) or value <= 0:
        words = ", ".join(f"{x.seconds:g} ({x.meaning})" for x in span.specials) + " or " * bool(span.specials)
        low = f"[{span.low:g}" if span.low > 0 else "(0"
        raise ConfigError(f"parameter {name!r} must be {words}a number of seconds in {low}, {span.high:g}], got "
                          f"{value!r}", parameter=name)
    assert s.high is not None  # a span's field is bounded
    return samples(name, float(value), rate, int(s.high))
