"""Eq. 23: control-surface joints -> the deflections of Eq. 2 (pure Python, no numpy needed).

A ``sensor_msgs/JointState`` message carries named joint positions (rad). The aerodynamic
model wants three deflections: the elevator ``delta_e`` and the rudder ``delta_r`` are the
averages of their surfaces, the aileron is ``delta_a = (right - left) / 2`` (Eq. 23), unless
one joint already holds that combination. :class:`SurfaceMixing` says which joints are
which (the ``surfaces.*`` parameters); :class:`SurfaceMixer` applies it to messages, with the
joints' positions in a message found once per name list (:class:`JointLayout`), or the
reason a message with that list cannot be mixed (a :class:`.errors.Refused`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple, get_args

from ..errors import Refused
from ..schema import check, option

__all__ = ["Surface", "SURFACES", "SurfaceMixing", "JointLayout", "SurfaceMixer", "MISMATCHED", "MISSING"]

# The deflections of Eq. 2, in the order the mixing produces them.
Surface = Literal["delta_e", "delta_a", "delta_r"]
SURFACES: tuple[Surface, ...] = get_args(Surface)

# Why a JointState cannot be mixed: its names and positions do not pair one to one (a name
# twice, or as many positions as names), or a joint of the ``surfaces.*`` parameters is missing.
MISMATCHED = Refused("mismatched_arrays")
MISSING = Refused("missing_joint")


@dataclass(frozen=True)
class SurfaceMixing:
    """JointState names -> Eq. 23 deflections: elevator and rudder are averages of their
    surfaces, the aileron is (right - left)/2 unless one joint already holds it."""

    elevator: tuple[str, ...] = option(("elevator",), "JointState names averaged into the elevator deflection "
                                       "(Eq. 23)", ros="surfaces.elevator")
    aileron_right: tuple[str, ...] = option(("aileron_right",), "JointState names of right ailerons; delta_a = "
                                            "(right - left)/2 (Eq. 23)", ros="surfaces.aileron_right")
    aileron_left: tuple[str, ...] = option(("aileron_left",), "JointState names of left ailerons",
                                           ros="surfaces.aileron_left")
    aileron_combined: str = option("", "JointState name that already holds (right - left)/2; when set, "
                                   "aileron_right/left are ignored", ros="surfaces.aileron_combined")
    rudder: tuple[str, ...] = option(("rudder",), "JointState names averaged into the rudder deflection (Eq. 23)",
                                     ros="surfaces.rudder")

    def __post_init__(self) -> None:
        check(self, "surfaces")

    def names(self, surface: Surface) -> tuple[str, ...]:
        """The joints a deflection needs (empty: not measured)."""
        if surface == "delta_e":
            return self.elevator
        if surface == "delta_r":
            return self.rudder
        if self.aileron_combined:
            return (self.aileron_combined,)
        if self.aileron_right and self.aileron_left:
            return self.aileron_right + self.aileron_left
        return ()

    def missing(self, names: Sequence[str]) -> list[tuple[str, tuple[str, ...]]]:
        """``(surfaces.<field>, its joint names)`` of every field with a joint that ``names``
        lacks: what makes a message ``missing_joint`` (for a misconfiguration report)."""
        have = set(names)
        fields = [("elevator", self.elevator), ("rudder", self.rudder)]
        if self.aileron_combined:
            fields.append(("aileron_combined", (self.aileron_combined,)))
        elif self.aileron_right and self.aileron_left:
            fields += [("aileron_right", self.aileron_right), ("aileron_left", self.aileron_left)]
        return [(f"surfaces.{name}", joints) for name, joints in fields if any(j not in have for j in joints)]

    def layout(self, names: tuple[str, ...]) -> JointLayout | Refused:
        """Where each mixed joint sits in a message with these joint ``names``, or why such a
        message cannot be used: :data:`MISMATCHED` (a name twice) or :data:`MISSING`."""
        if len(set(names)) != len(names):
            return MISMATCHED
        if any(n not in names for s in SURFACES for n in self.names(s)):
            return MISSING
        where = {n: i for i, n in enumerate(names)}
        aileron = self.names("delta_a")
        split = bool(aileron) and not self.aileron_combined
        known = set(self.elevator) | set(self.rudder) | set(aileron)
        used = sorted({where[n] for n in known})
        return JointLayout(
            elevator=tuple(where[n] for n in self.elevator),
            aileron_right=tuple(where[n] for n in self.aileron_right) if split else (),
            aileron_left=tuple(where[n] for n in self.aileron_left) if split else (),
            aileron_combined=where[self.aileron_combined] if self.aileron_combined else None,
            rudder=tuple(where[n] for n in self.rudder),
            unknown=tuple(n for n in names if n not in known),
            used=tuple(used),
        )


def _mean(values: Sequence[float], index: tuple[int, ...]) -> float:
    """Mean of ``values`` at ``index`` (0 when there is none): Eq. 23's surface averages."""
    if len(index) == 1:
        return values[index[0]]
    return sum([values[i] for i in index]) / len(index) if index else 0.0


class JointLayout(NamedTuple):
    """Positions of the mixed joints in one JointState name list; ``unknown`` are the joints
    the mixing does not use (reported, not an error), ``used`` the positions of all the
    others (the values a message's plausibility is judged on)."""

    elevator: tuple[int, ...]
    aileron_right: tuple[int, ...]
    aileron_left: tuple[int, ...]
    aileron_combined: int | None
    rudder: tuple[int, ...]
    unknown: tuple[str, ...]
    used: tuple[int, ...] = ()

    def deflections(self, positions: Sequence[float]) -> tuple[float, float, float]:
        """``(delta_e, delta_a, delta_r)`` of Eq. 23 from the message's positions (rad)."""
        de = _mean(positions, self.elevator)
        if self.aileron_combined is not None:
            da = positions[self.aileron_combined]
        elif self.aileron_right or self.aileron_left:
            da = 0.5 * (_mean(positions, self.aileron_right) - _mean(positions, self.aileron_left))  # Eq. 23
        else:
            da = 0.0
        return de, da, _mean(positions, self.rudder)


class SurfaceMixer:
    """:meth:`SurfaceMixing.layout` for a stream of messages: the layout of the last name list
    is kept (every message normally has the same list) and a few others are cached. Memory
    stays bounded whatever arrives: at most ``_CACHE_SIZE`` lists of at most
    ``_CACHE_MAX_NAMES`` names are cached (a longer list is laid out afresh each time), plus
    the last list seen."""

    _CACHE_SIZE = 16  # name lists normally never change; stay bounded when they do
    _CACHE_MAX_NAMES = 64  # a surface JointState has a handful of joints

    def __init__(self, mixing: SurfaceMixing) -> None:
        self.mixing = mixing
        self._last_names: list[str] | None = None
        self._last_layout: JointLayout | Refused = MISSING  # read only once _last_names is set
        self._layouts: dict[tuple[str, ...], JointLayout | Refused] = {}

    def layout(self, names: Sequence[str]) -> JointLayout | Refused:
        """The layout of a message's joint ``names`` (a sequence of str), or why the message
        cannot be used."""
        if names == self._last_names:  # the usual case
            return self._last_layout
        key = tuple(names)
        layout = self._layouts.get(key)
        if layout is None:
            layout = self.mixing.layout(key)
            if len(key) <= self._CACHE_MAX_NAMES:
                if len(self._layouts) >= self._CACHE_SIZE:
                    self._layouts.clear()
                self._layouts[key] = layout
        self._last_names, self._last_layout = list(key), layout
        return layout
