"""The differentiator over its whole declared range: every (window, order, lag) that the
``differentiator.*`` parameters accept, with the package's weights (exact rationals rounded
once, :func:`rls_uncertainty.aero.differentiation.derivative_weights`) beside the construction they
replaced (the pseudo-inverse of the unscaled Vandermonde matrix of the sample offsets, three
lines below). Report: REPORT.md beside this file.

Three measures per setting, at a 50 Hz sample interval:

* **polynomials**: the largest error on the monomials ``(tau/h)^d``, ``d <= order`` (``h =
  window - 1``), against the rounding bound ``(window + order + 2) eps ||c||_1`` (the
  conditioning of ``c @ y``); a setting fails when the error exceeds the bound, and is
  counted apart when it exceeds 0.1 % of the derivative ``1/(h dt)``;
* **resolved sine**: a sine at the frequency where the Taylor-remainder bound ``B(w) =
  sum |c_i| (w |t_i|)^(order+1) / (order+1)!`` equals 1e-4 w (the window resolves it to
  0.01 %; test_differentiation.py derives it); a setting fails when the error exceeds 0.1 %;
* **a slow sine**: ``sin(pi t)`` (0.5 Hz, unit amplitude), derivative at phase 0 (true
  pi); a setting fails when it is off by more than 0.1 %. Exact weights can fail here too:
  a low-order fit over a long window does not follow the sine (truncation, not arithmetic);
  the sweep counts those apart (the exact weights' error is then the least-squares fit's own).

    .venv/bin/python docs/studies/differentiator_exactness/study.py          # every setting, ~3 min
    .venv/bin/python docs/studies/differentiator_exactness/study.py --quick  # lags 0, centre, end
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from rls_uncertainty.aero.differentiation import (
    MAX_ORDER,
    MAX_WINDOW,
    MIN_WINDOW,
    DifferentiatorConfig,
    derivative_weights,
)

DT = 0.02
EPS = float(np.finfo(float).eps)


def pinv_weights(window: int, order: int, lag: int, dt: float) -> np.ndarray:
    """The construction the package used before: pinv of the unscaled Vandermonde matrix."""
    tau = np.arange(window, dtype=float) - (window - 1 - lag)
    return np.linalg.pinv(np.vander(tau, order + 1, increasing=True))[1] / dt


def measures(c: np.ndarray, window: int, order: int, lag: int) -> tuple[float, float, float, float]:
    """(polynomial error / rounding bound, polynomial error / the derivative 1/(h dt),
    resolved-sine relative error, derivative of sin(pi t))."""
    tau = np.arange(window) - (window - 1 - lag)
    h = window - 1
    Y = (tau[:, None] / h) ** np.arange(order + 1)
    truth = np.zeros(order + 1)
    truth[1] = 1.0 / (h * DT)
    err = float(np.abs(c @ Y - truth).max())
    poly = err / ((window + order + 2) * EPS * float(np.abs(c).sum()))
    t = tau * DT
    k = order + 1
    moment = float(np.abs(c) @ np.abs(t) ** k) / math.factorial(k)
    if moment > 0:
        w = (1e-4 / moment) ** (1.0 / order)
        resolved = abs(c @ np.sin(w * t + 0.3) - w * math.cos(0.3)) / (w * math.cos(0.3))
    else:  # weights of zero (the old construction's collapse): nothing is differentiated
        resolved = 1.0
    return poly, err * h * DT, float(resolved), float(c @ np.sin(np.pi * t))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="lags 0, centre and window - 1 only")
    args = parser.parse_args()
    t0 = time.perf_counter()
    rows = []  # (window, order, lag, old measures, new measures)
    for window in range(MIN_WINDOW, MAX_WINDOW + 1):
        lags = sorted({0, (window - 1) // 2, window - 1}) if args.quick else range(window)
        for order in range(1, min(MAX_ORDER, window - 1) + 1):
            for lag in lags:
                new = derivative_weights(DifferentiatorConfig(window, order, lag), DT)
                old = pinv_weights(window, order, lag, DT)
                setting = (window, order, lag)
                rows.append((*setting, *measures(old, *setting), *measures(new, *setting)))
    a = np.array(rows)
    pairs = {(int(r[0]), int(r[1])) for r in rows}
    print(f"{len(rows)} settings ({len(pairs)} (window, order) pairs), {time.perf_counter() - t0:.0f} s")

    def count(bad: np.ndarray, what: str) -> None:
        bad_pairs = {(int(r[0]), int(r[1])) for r in a[bad]}
        print(f"  {what}: {int(bad.sum())} settings, {len(bad_pairs)} pairs")

    def where(i: int) -> tuple[int, ...]:
        return tuple(int(x) for x in a[i, :3])

    for name, i in (("pinv (before)", 3), ("exact (after)", 7)):
        print(f"{name}:")
        count(a[:, i] > 1.0, "polynomials beyond the rounding bound")
        count(a[:, i + 1] > 1e-3, "polynomials off by more than 0.1 % of the derivative")
        count(a[:, i + 2] > 1e-3, "resolved sine off by more than 0.1 %")
        count(np.abs(a[:, i + 3] - np.pi) > 1e-3 * np.pi, "sin(pi t) off by more than 0.1 %")
        worst = int(np.argmax(a[:, i]))
        print(f"  worst polynomial error: {a[worst, i]:.3g} x the rounding bound, {a[worst, i + 1]:.3g} x the "
              f"derivative, at {where(worst)}")
        worst = int(np.argmax(a[:, i + 2]))
        print(f"  worst resolved-sine error: {a[worst, i + 2]:.3g} (relative) at {where(worst)}")
    # Where the exact weights miss pi too, the least-squares fit itself does (truncation: the
    # window is too long for the order at 0.5 Hz); pinv's own arithmetic error is its distance
    # from the exact least-squares derivative.
    count(np.abs(a[:, 6] - a[:, 10]) > 1e-3 * np.pi, "pinv's sin(pi t) derivative off the exact least-squares one by "
          "more than 0.1 % of pi (arithmetic)")
    count(np.abs(a[:, 10] - np.pi) > 1e-3 * np.pi, "the exact least-squares derivative of sin(pi t) off pi by more "
          "than 0.1 % (truncation: the window too long for the order)")
    worst = int(np.argmax(np.abs(a[:, 6] - a[:, 10])))
    print(f"  largest pinv arithmetic error on sin(pi t): {a[worst, 6]:.3g} where the exact least-squares derivative "
          f"is {a[worst, 10]:.6g}, at {where(worst)}")

if __name__ == "__main__":
    main()
