"""The auxiliary short-period model in discrete time (numpy only).

Eq. 25a with estimated derivatives, in perturbations from trim, state ``s = (alpha, q)``
(rad, rad/s) and input ``u`` the injected elevator (rad):

    d alpha/dt = Z (C_Z_alpha alpha + C_Z_q cbar/(2V) q + C_Z_delta_e u) + q
    dq/dt      = M (C_m_alpha alpha + C_m_q cbar/(2V) q + C_m_delta_e u)
    Z = qbar S / (m V),   M = qbar S cbar / I_yy

(``C_Z_q`` is 0 unless the C_Z model has ``q_hat``). With a zero-order hold at the sample
period ``T`` it becomes

    s_(k+1) = Phi s_k + Gamma u_k,   Phi = exp(A T),   Gamma = int_0^T exp(A t) dt B    (I2)

computed in closed form for the 2x2 ``A`` (Cayley-Hamilton, :func:`discretize`).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ..aero.models import AircraftConfig

__all__ = ["DERIVATIVES", "MIN_DECAY", "short_period_matrices", "discretize", "is_stable"]

FloatArray = npt.NDArray[np.float64]

# The derivatives the auxiliary model is built from, in this order.
DERIVATIVES = ("CZ_alpha", "CZ_q", "CZ_delta_e", "Cm_alpha", "Cm_q", "Cm_delta_e")
# A candidate model is used only if both poles have a real part below -MIN_DECAY (1/s).
MIN_DECAY = 0.2


def short_period_matrices(
    derivatives: FloatArray, qbar: float, V: float, aircraft: AircraftConfig
) -> tuple[FloatArray, FloatArray]:
    """Eq. 25a's ``A`` (2x2) and ``B`` (2,) from the :data:`DERIVATIVES` values, the dynamic
    pressure ``qbar`` (Pa) and airspeed ``V`` (m/s)."""
    za, zq, zd, ma, mq, md = (float(v) for v in derivatives)
    Z = qbar * aircraft.S / (aircraft.mass * V)
    M = qbar * aircraft.S * aircraft.cbar / aircraft.Iyy
    rate = aircraft.cbar / (2.0 * V)
    A = np.array([[Z * za, 1.0 + Z * rate * zq], [M * ma, M * rate * mq]])
    B = np.array([Z * zd, M * md])
    return A, B


def is_stable(A: FloatArray, min_decay: float = MIN_DECAY) -> bool:
    """Whether ``A`` is finite and both its eigenvalues have a real part below ``-min_decay``."""
    if not np.isfinite(A).all():
        return False
    half_trace = 0.5 * (A[0, 0] + A[1, 1])
    det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    disc = half_trace * half_trace - det
    largest = half_trace + math.sqrt(disc) if disc > 0 else half_trace
    return bool(largest < -min_decay)


def discretize(A: FloatArray, B: FloatArray, T: float) -> tuple[FloatArray, FloatArray]:
    """I2 in closed form for a 2x2 ``A`` (nonsingular, as every stable one is) and ``B`` (2,).

    With ``s = tr(A)/2`` and ``w^2 = s^2 - det(A)`` (Cayley-Hamilton: ``exp(A T)`` is a
    combination of ``I`` and ``A``):

        Phi   = exp(s T) [(c - s h) I + h A],   c = cosh(w T),  h = sinh(w T)/w
        Gamma = A^-1 (Phi - I) B

    For complex poles (``w^2 < 0``) ``c = cos(|w| T)``, ``h = sin(|w| T)/|w|``; for repeated
    poles (``w = 0``) ``c = 1``, ``h = T``; ``h`` is taken as ``T`` whenever ``|w| T < 1e-8``,
    where the two differ by less than rounding.
    """
    a, b, c_, d = float(A[0, 0]), float(A[0, 1]), float(A[1, 0]), float(A[1, 1])
    s = 0.5 * (a + d)
    det = a * d - b * c_
    w2 = s * s - det
    w = math.sqrt(abs(w2))
    wt = w * T
    if w2 >= 0:
        c = math.cosh(wt)
        h = T if wt < 1e-8 else math.sinh(wt) / w
    else:
        c = math.cos(wt)
        h = T if wt < 1e-8 else math.sin(wt) / w
    e = math.exp(s * T)
    Phi = e * ((c - s * h) * np.eye(2) + h * np.asarray(A, dtype=float))
    y = (Phi - np.eye(2)) @ np.asarray(B, dtype=float)
    Gamma = np.array([d * y[0] - b * y[1], -c_ * y[0] + a * y[1]]) / det
    return Phi, Gamma
