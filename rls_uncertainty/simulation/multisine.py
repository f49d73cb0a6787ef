"""Orthogonal phase-optimized multisine inputs (paper Eq. 24, Table 2).

``u(t) = a * sum_k a_k sin(2 pi k t / T + phi_k)``. The Table 2 designs for the T-2 are
bundled; :func:`relative_peak_factor` gives their RPF (1.03, 1.15, 1.14), and
:func:`design_multisines` designs new orthogonal inputs for a record length, band and number
of inputs (harmonics interleaved across inputs, Schroeder initial phases, then peak-factor
minimization). numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import overload

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError

# Largest input amplitude of a simulated maneuver, as a multiple of Table 2's (make-bag --input-amplitude).
MAX_INPUT_AMPLITUDE = 10.0

__all__ = [
    "MAX_INPUT_AMPLITUDE",
    "Multisine",
    "T2_TABLE2",
    "relative_peak_factor",
    "design_multisines",
]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Multisine:
    """One input of Eq. 24: harmonic indices ``k``, relative amplitudes ``a_k``, phases
    ``phi_k`` (rad), record length ``period`` T (s) and aggregate amplitude ``amplitude`` a
    (in the unit of the output, e.g. rad)."""

    name: str
    harmonics: tuple[int, ...]
    rel_amplitudes: tuple[float, ...]
    phases: tuple[float, ...]
    period: float
    amplitude: float = 1.0
    meta: dict[str, float] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        n = len(self.harmonics)
        if n == 0 or len(self.rel_amplitudes) != n or len(self.phases) != n:
            raise ConfigError(f"multisine {self.name!r}: harmonics, amplitudes and phases must match")
        if self.period <= 0:
            raise ConfigError(f"multisine {self.name!r}: period must be positive")

    @property
    def frequencies(self) -> FloatArray:
        """Excitation frequencies ``k / T`` in Hz."""
        return np.asarray(self.harmonics, dtype=float) / self.period

    @overload
    def __call__(self, t: float) -> float: ...
    @overload
    def __call__(self, t: FloatArray) -> FloatArray: ...

    def __call__(self, t: float | FloatArray) -> float | FloatArray:
        """Eq. 24 at times ``t`` (s) measured from the start of the input (a time gives a
        number, an array of times an array of the same shape)."""
        times = np.asarray(t, dtype=float)
        k = np.asarray(self.harmonics, dtype=float)
        arg = 2.0 * np.pi * np.multiply.outer(times, k) / self.period + np.asarray(self.phases)
        u: float | FloatArray = self.amplitude * (np.sin(arg) @ np.asarray(self.rel_amplitudes))
        return u

    @overload
    def derivative(self, t: float) -> float: ...
    @overload
    def derivative(self, t: FloatArray) -> FloatArray: ...

    def derivative(self, t: float | FloatArray) -> float | FloatArray:
        """Time derivative of Eq. 24."""
        times = np.asarray(t, dtype=float)
        k = np.asarray(self.harmonics, dtype=float)
        w = 2.0 * np.pi * k / self.period
        arg = np.multiply.outer(times, w) + np.asarray(self.phases)
        du: float | FloatArray = self.amplitude * (np.cos(arg) @ (w * np.asarray(self.rel_amplitudes)))
        return du

    def scaled(self, amplitude: float) -> Multisine:
        return Multisine(self.name, self.harmonics, self.rel_amplitudes, self.phases, self.period, amplitude)


_DEG = np.pi / 180.0

# Table 2 (T = 10 s, a = 1 deg; amplitudes a_k in deg per unit a as printed).
T2_TABLE2 = {
    "elevator": Multisine(
        "elevator", (3, 6, 9, 12, 15, 18, 21),
        (0.316, 0.387, 0.447, 0.447, 0.387, 0.316, 0.316),
        (2.948, 0.601, 3.584, 4.632, 2.690, 2.087, 3.421), 10.0, _DEG,
    ),
    "aileron": Multisine(
        "aileron", (4, 7, 10, 13, 16, 19, 22),
        (0.378,) * 7,
        (1.544, 4.642, 1.201, 1.077, 3.946, 3.951, 3.523), 10.0, _DEG,
    ),
    "rudder": Multisine(
        "rudder", (2, 5, 8, 11, 14, 17, 20),
        (0.316, 0.387, 0.447, 0.447, 0.387, 0.316, 0.316),
        (2.844, 2.526, 2.756, 5.770, 5.540, 2.396, 5.525), 10.0, _DEG,
    ),
}


def relative_peak_factor(u: FloatArray) -> float:
    """Relative peak factor: ``(max(u) - min(u)) / (2 sqrt(2) rms(u - mean u))``; 1 for a
    single sinusoid."""
    u = np.asarray(u, dtype=float)
    rms = np.sqrt(np.mean((u - u.mean()) ** 2))
    if rms == 0.0:
        raise ConfigError("relative peak factor of a constant signal is undefined")
    return float((u.max() - u.min()) / (2.0 * np.sqrt(2.0) * rms))


def _rpf_of(ms: Multisine, n_grid: int) -> float:
    t = np.arange(n_grid) * ms.period / n_grid
    return relative_peak_factor(ms(t))


def design_multisines(
    period: float,
    band: tuple[float, float],
    n_inputs: int,
    *,
    names: tuple[str, ...] | None = None,
    amplitude: float = 1.0,
    iterations: int = 60,
    grid: int = 2048,
    seed: int = 0,
) -> list[Multisine]:
    """Orthogonal phase-optimized multisines for ``n_inputs`` inputs.

    Harmonics ``k`` with ``k / period`` inside ``band`` (Hz, the lowest kept at ``k >= 2`` so
    each frequency completes repeated cycles) are dealt to the inputs in turn, which makes the
    inputs mutually orthogonal over the record. Each input starts from Schroeder phases, then
    a clipping iteration (clip the waveform at a shrinking level, keep the phases of its Fourier
    coefficients at the input's own harmonics) lowers the relative peak factor; finally the
    phases are shifted by a common time offset so the input starts at zero where possible.
    Equal relative amplitudes, normalised to unit power.
    """
    lo, hi = band
    if period <= 0 or not (0 <= lo < hi) or n_inputs < 1:
        raise ConfigError("need period > 0, 0 <= band[0] < band[1] and n_inputs >= 1")
    ks = list(range(max(2, int(np.ceil(lo * period))), int(np.floor(hi * period)) + 1))
    if len(ks) < n_inputs:
        raise ConfigError(
            f"band {band} Hz with T = {period} s holds {len(ks)} harmonics; "
            f"{n_inputs} inputs need at least one each"
        )
    names = names or tuple(f"input{i + 1}" for i in range(n_inputs))
    if len(names) != n_inputs:
        raise ConfigError("one name per input is needed")
    rng = np.random.default_rng(seed)
    t = np.arange(grid) * period / grid
    designs = []
    for i in range(n_inputs):
        k = np.array(ks[i::n_inputs])
        m = len(k)
        amp = np.full(m, np.sqrt(2.0 / m) / np.sqrt(2.0))
        phases = -np.pi * np.arange(m) * (np.arange(m) + 1) / m + 0.01 * rng.standard_normal(m)  # Schroeder
        best = Multisine(names[i], tuple(int(x) for x in k), tuple(amp), tuple(np.mod(phases, 2 * np.pi)), period)
        best_rpf = _rpf_of(best, grid)
        for it in range(iterations):
            cur = Multisine(names[i], best.harmonics, best.rel_amplitudes, tuple(phases), period)
            u = cur(t)
            level = np.max(np.abs(u)) * (0.95 - 0.2 * it / max(iterations, 1))
            spec = np.fft.rfft(np.clip(u, -level, level))
            # sin(w t + phi) has its FFT coefficient at phase phi - pi/2.
            phases = np.angle(spec[k]) + np.pi / 2.0
            cand = Multisine(names[i], best.harmonics, best.rel_amplitudes, tuple(np.mod(phases, 2 * np.pi)), period)
            r = _rpf_of(cand, grid)
            if r < best_rpf:
                best, best_rpf = cand, r
        # Time shift: phi_k + 2 pi k tau / T keeps the RPF; pick tau with u(0) closest to 0.
        taus = np.linspace(0.0, period, 400, endpoint=False)
        vals = [abs(Multisine("x", best.harmonics, best.rel_amplitudes,
                              tuple(np.asarray(best.phases) + 2 * np.pi * k * tau / period), period)(0.0))
                for tau in taus]
        tau = taus[int(np.argmin(vals))]
        ph = np.mod(np.asarray(best.phases) + 2 * np.pi * k * tau / period, 2 * np.pi)
        designs.append(
            Multisine(names[i], best.harmonics, best.rel_amplitudes, tuple(ph), period, amplitude,
                      meta={"rpf": best_rpf})
        )
    return designs
