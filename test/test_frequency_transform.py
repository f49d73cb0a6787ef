"""The finite Fourier transform (docs/frequency.md, F1-F2) against closed forms: a sinusoid's
transform is a sum of two geometric series; the recursion equals the batch sum; a late sample's
phase is exact to rounding."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from rls_uncertainty.frequency import RecursiveFourierTransform, finite_fourier_transform, phasors

RATE = 50.0


def geometric(delta: np.ndarray, N: int) -> np.ndarray:
    """sum_(n=0..N-1) exp(-j delta n) = (1 - exp(-j delta N)) / (1 - exp(-j delta))."""
    return (1 - np.exp(-1j * delta * N)) / (1 - np.exp(-1j * delta))


def test_a_cosine_transforms_to_the_sum_of_two_geometric_series():
    N, f0, phase = 437, 0.73, 0.4
    f = np.array([0.1, 0.5, 0.7, 1.3, 2.2])
    n = np.arange(N)
    x = np.cos(2 * np.pi * f0 * n / RATE + phase)
    # cos(a) = (e^{ja} + e^{-ja}) / 2, so dt sum_n cos(w0 t_n + phase) e^{-j w t_n} is two series.
    d = 2 * np.pi / RATE
    expected = (np.exp(1j * phase) * geometric(d * (f - f0), N) + np.exp(-1j * phase) * geometric(d * (f + f0), N)) / (
        2 * RATE
    )
    np.testing.assert_allclose(finite_fourier_transform(x, f, RATE), expected, rtol=1e-11, atol=1e-13)


def test_a_whole_number_of_cycles_gives_half_the_record_length_at_its_frequency():
    N = 500  # 10 s at 50 Hz: 0.3 Hz makes 3 whole cycles, 0.5 Hz makes 5
    x = np.cos(2 * np.pi * 0.3 * np.arange(N) / RATE)
    X = finite_fourier_transform(x, [0.3, 0.5], RATE)
    assert abs(X[0] - N / RATE / 2) < 1e-12
    assert abs(X[1]) < 1e-12


def test_the_recursion_equals_the_batch_transform_at_every_sample():
    rng = np.random.default_rng(3)
    f = 0.1 + 0.04 * np.arange(36)
    u = rng.standard_normal((300, 2, 3))
    rft = RecursiveFourierTransform(f, RATE, (2, 3))
    for k in range(u.shape[0]):
        rft.update(u[k])
        if k % 37 == 0 or k == u.shape[0] - 1:
            batch = np.moveaxis(finite_fourier_transform(u[: k + 1], f, RATE), 0, -2)  # (2, K, 3)
            np.testing.assert_allclose(rft.values, batch, rtol=0, atol=1e-12 * np.abs(batch).max())
            np.testing.assert_array_equal(rft.frequency_last, np.swapaxes(rft.values, -1, -2))  # (2, 3, K)
    rft.reset()
    assert rft.n == 0 and not rft.values.any()


def test_a_late_sample_keeps_its_phase_to_rounding_of_the_cycle_count():
    # The phase of sample n is -2 pi frac(f n / rate), computed from n (no accumulated rotation):
    # exact to the rounding of f n / rate. Here 10^7 samples (55 hours at 50 Hz), 2e4 cycles.
    f, n = 0.1, np.array([10**7 + 3, 10**7 + 250, 12345])
    exact_cycles = [Fraction(f) * int(k) / Fraction(RATE) % 1 for k in n]
    exact = np.exp(-2j * np.pi * np.array([float(c) for c in exact_cycles]))
    np.testing.assert_allclose(phasors([f], n, RATE)[0], exact, rtol=0, atol=1e-11)
