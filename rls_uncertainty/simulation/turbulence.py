"""Dryden vertical gusts (MIL-F-8785C, Dryden form) as sampled sequences. numpy only.

The aircraft flies at airspeed ``V`` through a frozen turbulence field (Taylor's hypothesis,
valid while the gust is small against ``V``), so a spatial frequency ``Omega`` (rad/m) is met
at ``omega = Omega V`` (rad/s). MIL-F-8785C's Dryden vertical spectrum, one-sided in
``omega``, and its autocovariance are

    Phi_w(omega) = sigma_w^2 L_w / (pi V) (1 + 3 (L_w omega / V)^2) / (1 + (L_w omega / V)^2)^2
    R_w(tau)     = sigma_w^2 (1 - V |tau| / (2 L_w)) exp(-V |tau| / L_w)

with ``sigma_w`` the RMS vertical gust velocity and ``L_w`` its scale length. Scale length
(MIL-F-8785C, which writes the spectrum with ``L_w`` as above; MIL-HDBK-1797 writes the same
spectrum with ``2 L_w``, so its ``2 L_w = h`` is this ``L_w = h``): below 1000 ft above
ground ``L_w = h``; from 2000 ft on the isotropic medium/high-altitude value ``L_w = 1750
ft``; in between this module interpolates linearly in ``h`` (our choice: the two regions join
continuously). Intensity at low altitude: ``sigma_w = 0.1 W20``
with ``W20`` the wind 20 ft above ground, 15 / 30 / 45 kt for light / moderate / severe
turbulence (:data:`LOW_ALTITUDE_SIGMA_W`).

Sampling: ``Phi_w`` is the output spectrum of ``H(s) = sigma_w sqrt(L_w/V) a (a + sqrt(3) s)
/ (s + a)^2``, ``a = V / L_w``, driven by unit white noise. As two cascaded first-order lags
``x1' = -a x1 + a xi``, ``x2' = -a x2 + a x1`` (states scaled so that their stationary
covariance is ``P = [[2, 1], [1, 1]]``) the output is ``w = sigma_w (sqrt(3) x1 + (1 -
sqrt(3)) x2) / 2``. The sequence is the exact discrete equivalent at step ``dt``:

    x_{k+1} = F x_k + eta_k,   F = exp(-a dt) [[1, 0], [a dt, 1]],   eta_k ~ N(0, P - F P F')

started from ``x_0 ~ N(0, P)``, so every sample has variance ``sigma_w^2`` and samples ``j``
apart have covariance ``R_w(j dt)`` exactly: no discretisation error, no warm-up transient.

Pitch gust (MIL-F-8785C): the vertical gust is not uniform along the aircraft; its gradient
met at ``V``, spread over the span ``b``, is the pitch gust

    q_g = H_q(s) w_g,   H_q(s) = (s / V) / (1 + tau s),   tau = 4 b / (pi V)              (G1)

(rad/s). Its variance is ``int_0^inf |H_q(j omega)|^2 Phi_w(omega) d omega``; with ``x = L_w
omega / V`` and ``c = tau V / L_w = 4 b / (pi L_w)`` (partial fractions)

    sigma_q^2 = sigma_w^2 / (pi L_w^2) (A pi / 2 + B pi / 4 + C pi / (2 c)),
    A = (3 c^2 - 5) / (c^2 - 1)^2,  B = 2 / (1 - c^2),  C = (3 - c^2) / (c^2 - 1)^2     (G3)

which for ``b << L_w`` is ``3 pi sigma_w^2 / (8 L_w b)``. Sampling (:func:`pitch_gust`):
``w_lag`` is ``w_g`` through ``1 / (1 + tau s)``, stepped exactly for ``w_g`` linear between
samples to first order in ``dt / tau`` (trapezoidal weights ``w_lag[k] = a w_lag[k-1] + (1 -
a) (w_g[k] + w_g[k-1]) / 2``, ``a = exp(-dt / tau)``, started at ``w_g[0]``), and ``q_g =
(w_g - w_lag) / (tau V)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError
from ..schema import check, option

__all__ = [
    "FT",
    "KNOT",
    "LOW_ALTITUDE_SIGMA_W",
    "DrydenVertical",
    "scale_length",
    "pitch_gust_lag",
    "pitch_gust",
    "pitch_gust_variance",
    "TurbulenceOptions",
]

FloatArray = npt.NDArray[np.float64]

FT = 0.3048  # m
KNOT = 1852.0 / 3600.0  # m/s
LOW_ALT_TOP = 1000.0 * FT  # m, top of MIL-F-8785C's low-altitude region
HIGH_ALT_BOTTOM = 2000.0 * FT  # m, bottom of its medium/high-altitude region
HIGH_ALT_L_W = 1750.0 * FT  # m, L_w of the medium/high-altitude (isotropic) region
# MIL-F-8785C low altitude: sigma_w = 0.1 W20 (m/s), W20 = 15 / 30 / 45 kt.
LOW_ALTITUDE_SIGMA_W = {"light": 1.5 * KNOT, "moderate": 3.0 * KNOT, "severe": 4.5 * KNOT}

# The stationary state covariance of the scaled cascade, and the output row (w / sigma_w).
_P = np.array([[2.0, 1.0], [1.0, 1.0]])
_H = np.array([math.sqrt(3.0), 1.0 - math.sqrt(3.0)]) / 2.0


def scale_length(height: float) -> float:
    """MIL-F-8785C Dryden ``L_w`` (m) at ``height`` (m above ground): ``h`` up to 1000 ft,
    1750 ft from 2000 ft on, linear in between."""
    if not (math.isfinite(height) and height > 0.0):
        raise ConfigError(f"gust height above ground must be a positive number of metres, got {height!r}")
    if height <= LOW_ALT_TOP:
        return float(height)
    if height >= HIGH_ALT_BOTTOM:
        return HIGH_ALT_L_W
    s = (height - LOW_ALT_TOP) / (HIGH_ALT_BOTTOM - LOW_ALT_TOP)
    return float(LOW_ALT_TOP + s * (HIGH_ALT_L_W - LOW_ALT_TOP))


@dataclass(frozen=True)
class DrydenVertical:
    """The Dryden vertical gust: ``sigma`` the RMS gust velocity ``sigma_w`` (m/s, ``0`` for
    calm air), ``scale_length`` ``L_w`` (m; :func:`scale_length` from the height)."""

    sigma: float
    scale_length: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma) and self.sigma >= 0.0):
            raise ConfigError(f"gust intensity sigma_w must be a number >= 0 m/s, got {self.sigma!r}")
        if not (math.isfinite(self.scale_length) and self.scale_length > 0.0):
            raise ConfigError(f"gust scale length L_w must be a positive number of metres, got {self.scale_length!r}")

    def psd(self, f: FloatArray, airspeed: float) -> FloatArray:
        """One-sided power spectral density in (m/s)^2/Hz at frequencies ``f`` (Hz):
        ``2 pi Phi_w(2 pi f)``."""
        x = 2.0 * np.pi * np.asarray(f, dtype=np.float64) * self.scale_length / airspeed
        return 2.0 * self.sigma**2 * self.scale_length / airspeed * (1.0 + 3.0 * x**2) / (1.0 + x**2) ** 2

    def autocovariance(self, tau: FloatArray, airspeed: float) -> FloatArray:
        """``R_w(tau)`` in (m/s)^2 at lags ``tau`` (s)."""
        u = airspeed * np.abs(np.asarray(tau, dtype=np.float64)) / self.scale_length
        return self.sigma**2 * (1.0 - u / 2.0) * np.exp(-u)

    def transition(self, airspeed: float, dt: float) -> tuple[FloatArray, FloatArray]:
        """``F`` and the Cholesky factor of ``Q = P - F P F'`` of the exact discrete
        cascade at step ``dt`` (module docstring)."""
        if not (math.isfinite(airspeed) and airspeed > 0.0 and math.isfinite(dt) and dt > 0.0):
            raise ConfigError(f"gust sampling needs airspeed > 0 and dt > 0, got {airspeed!r} m/s, {dt!r} s")
        adt = airspeed / self.scale_length * dt
        F = math.exp(-adt) * np.array([[1.0, 0.0], [adt, 1.0]])
        return F, np.linalg.cholesky(_P - F @ _P @ F.T)

    def sample(self, n: int, airspeed: float, dt: float, rng: np.random.Generator) -> FloatArray:
        """``n`` stationary samples ``w_g(k dt)`` (m/s) of the gust met at ``airspeed``."""
        F, G = self.transition(airspeed, dt)
        x = np.linalg.cholesky(_P) @ rng.standard_normal(2)
        eta = rng.standard_normal((n, 2)) @ G.T
        f11, f21, f22 = float(F[0, 0]), float(F[1, 0]), float(F[1, 1])
        x1, x2 = float(x[0]), float(x[1])
        h1, h2 = float(_H[0]) * self.sigma, float(_H[1]) * self.sigma
        w = np.empty(n)
        for k, (e1, e2) in enumerate(eta.tolist()):
            w[k] = h1 * x1 + h2 * x2
            # x_{k+1} = F x_k + eta_k (F lower triangular)
            x1, x2 = f11 * x1 + e1, f21 * x1 + f22 * x2 + e2
        return w


def pitch_gust_lag(span: float, airspeed: float) -> float:
    """``tau = 4 b / (pi V)`` of G1 (s), ``span`` the wing span ``b`` (m)."""
    if not (math.isfinite(span) and span > 0.0 and math.isfinite(airspeed) and airspeed > 0.0):
        raise ConfigError(f"the pitch gust needs a span > 0 m and an airspeed > 0 m/s, got {span!r}, {airspeed!r}")
    return 4.0 * span / (math.pi * airspeed)


def pitch_gust(w_g: FloatArray, dt: float, span: float, airspeed: float) -> FloatArray:
    """G1: the pitch gust ``q_g`` (rad/s) of the vertical gust ``w_g`` (m/s) sampled every
    ``dt`` (s), for the span ``span`` (m) at ``airspeed`` (module docstring, Sampling)."""
    tau = pitch_gust_lag(span, airspeed)
    w = np.asarray(w_g, dtype=np.float64)
    a = math.exp(-dt / tau)
    c = 0.5 * (1.0 - a)
    lag = np.empty_like(w)
    state, previous = (float(w[0]), float(w[0])) if w.size else (0.0, 0.0)
    for k, x in enumerate(w.tolist()):
        state = a * state + c * (x + previous)
        lag[k] = state
        previous = x
    return (w - lag) / (tau * airspeed)


def pitch_gust_variance(gust: DrydenVertical, span: float, airspeed: float) -> float:
    """G3: the variance of the pitch gust (rad^2/s^2) of ``gust`` for the span ``span`` (m)
    at ``airspeed``; the span must be shorter than ``pi L_w / 4`` (``c < 1``)."""
    c = pitch_gust_lag(span, airspeed) * airspeed / gust.scale_length
    if c >= 1.0:
        limit = math.pi * gust.scale_length / 4
        raise ConfigError(f"the pitch gust needs a span shorter than pi L_w / 4 = {limit:g} m, "
                          f"got {span!r} m")
    d = (c * c - 1.0) ** 2
    A, B, C = (3.0 * c * c - 5.0) / d, 2.0 / (1.0 - c * c), (3.0 - c * c) / d
    integral = A * math.pi / 2.0 + B * math.pi / 4.0 + C * math.pi / (2.0 * c)
    return gust.sigma**2 / (math.pi * gust.scale_length**2) * integral


@dataclass(frozen=True)
class TurbulenceOptions:
    """How the simulated turbulence acts on the aircraft (``make-bag --campaign``)."""

    pitch_gust: str = option("on", "with --campaign: 'on' adds the MIL-F-8785C pitch gust (the vertical gust's "
                             "gradient along the aircraft, read by no sensor) to the pitch dynamics; 'off' leaves "
                             "the vertical gust on alpha only", choices=("on", "off"), cli="--pitch-gust")

    def __post_init__(self) -> None:
        check(self, "turbulence")

    @property
    def pitch(self) -> bool:
        """Whether the pitch gust acts."""
        return self.pitch_gust == "on"
