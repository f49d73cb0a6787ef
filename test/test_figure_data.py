"""What the replay's figures draw from (rls_uncertainty/offline/figure_data.py), against independent
computations: the batch formula of estimator.batch on the stored rows, scipy's Welch
spectrum, closed forms on synthetic signals, and the replay's own CSV. No DDS.

Tolerance of the streamed batch quantities: they are the same sums as batch_estimate's, taken
in another order and through G(k) = sum w_j w_(j-k)' with w = [x; z], so R(0) = a' G(0) a loses
about log10(var z / var v) digits to cancellation (measured 2e-13 relative at R^2 = 0.99);
1e-9 relative leaves four orders of margin and still fails on any formula error."""

import csv
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from rls_uncertainty.estimator.batch import batch_estimate
from rls_uncertainty.offline.figure_data import (
    FigureData,
    FitStatistics,
    LaggedProducts,
    WelchSpectrum,
    excitation_start,
)
from rls_uncertainty.offline.replay import replay
from rls_uncertainty.settings import load_parameters_file, pipeline_config

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"
RTOL = 1e-9


def _colored_regression(N: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A bias, a white and a slow regressor, and an output with moving-average (colored)
    noise: a case where the corrected and conventional standard errors differ."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([np.ones(N), rng.normal(size=N), np.cumsum(rng.normal(size=N)) * 0.1])
    noise = np.convolve(rng.normal(size=N + 11), np.ones(12) / 4, "valid")[:N]
    return X, X @ [0.3, -4.0, 0.5] + 0.1 * noise


def _streamed(X: np.ndarray, z: np.ndarray, max_lag: int, block: int) -> LaggedProducts:
    products = LaggedProducts(X.shape[1], max_lag, block)
    for x, zz in zip(X, z, strict=True):
        products.add(x, zz)
    return products


@pytest.mark.parametrize(("N", "max_lag", "block"), [(700, 1000, 128), (700, 1000, 37), (900, 300, 64)])
@pytest.mark.parametrize("window", ["truncated", "bartlett"])
def test_the_streamed_sweep_equals_the_batch_formula_at_every_lag(N, max_lag, block, window):
    X, z = _colored_regression(N)
    sweep = _streamed(X, z, max_lag, block).sweep()
    assert sweep is not None and sweep.samples == N and sweep.max_lag == min(max_lag, N - 1)
    for lags in sorted({0, 1, 2, 7, 50, 299, sweep.max_lag}):
        theta, cov_conv, cov_corr = batch_estimate(X, z, lags, window)
        np.testing.assert_allclose(sweep.theta, theta, rtol=RTOL)
        np.testing.assert_allclose(sweep.se_conventional, np.sqrt(np.diag(cov_conv)), rtol=RTOL)
        np.testing.assert_allclose(sweep.se_corrected(lags, window), np.sqrt(np.diag(cov_corr)), rtol=RTOL)
    if max_lag >= N - 1:  # every lag streamed: "all" is available
        np.testing.assert_allclose(sweep.se_corrected(10 * N, window),
                                   np.sqrt(np.diag(batch_estimate(X, z, "all", window)[2])), rtol=RTOL)


def test_the_streamed_autocorrelation_is_eq_10_of_the_batch_residuals():
    X, z = _colored_regression(500)
    sweep = _streamed(X, z, 120, 50).sweep()
    v = z - X @ np.linalg.lstsq(X, z, rcond=None)[0]
    R = np.array([v[i:] @ v[: v.size - i] for i in range(121)]) / v.size
    np.testing.assert_allclose(sweep.autocorrelation, R, rtol=RTOL, atol=RTOL * R[0])
    assert abs(R[1] / R[0]) > 0.5  # the noise is colored: the case is not trivial


def test_a_sweep_needs_an_identifiable_model():
    X, z = _colored_regression(50)
    assert _streamed(X[:3], z[:3], 10, 8).sweep() is None  # N = n: no residual
    flat = X.copy()
    flat[:, 2] = 1.0  # a regressor equal to the bias
    assert _streamed(flat, z, 10, 8).sweep() is None


@pytest.mark.parametrize("N", [1000, 256, 300])
def test_the_streamed_spectrum_is_welchs(N):
    rng = np.random.default_rng(5)
    x = signal.lfilter([1.0], [1.0, -0.8], rng.normal(size=N)) + 3.0  # colored, with a mean
    spectrum = WelchSpectrum(50.0, 256)
    for value in x:
        spectrum.add(value)
    f, P = spectrum.psd()
    f_ref, P_ref = signal.welch(x, fs=50.0, nperseg=256)
    np.testing.assert_allclose(f, f_ref)
    np.testing.assert_allclose(P, P_ref, rtol=1e-12, atol=1e-15 * P_ref.max())


def test_a_short_record_gives_one_periodogram_of_what_there_is():
    x = np.sin(np.arange(100) * 0.7)
    spectrum = WelchSpectrum(20.0, 256)
    for value in x:
        spectrum.add(value)
    f, P = spectrum.psd()
    with pytest.warns(UserWarning, match="nperseg"):  # scipy shortens the segment too
        f_ref, P_ref = signal.welch(x, fs=20.0, nperseg=256)
    np.testing.assert_allclose(f, f_ref)
    np.testing.assert_allclose(P, P_ref, rtol=1e-12, atol=1e-15 * P_ref.max())


def test_the_excitation_starts_when_the_last_moving_regressor_moves():
    t = np.arange(0, 10, 0.02)
    elevator = np.where(t >= 3.0, np.sin(2 * (t - 3.0)) * 0.05, 0.0) + 0.001  # from 3 s
    alpha = np.where(t >= 1.5, 0.1, 0.02)  # a step at 1.5 s
    bias = np.ones_like(t)  # never moves: ignored
    X = np.column_stack([bias, alpha, elevator])
    # 20% of the elevator's 0.1 rad range: |0.05 sin(2 (t - 3))| >= 0.02 from asin(0.4)/2 s later
    assert excitation_start(t, X) == pytest.approx(3.0 + np.arcsin(0.4) / 2, abs=0.021)
    assert excitation_start(t, X[:, :2]) == pytest.approx(1.5)
    assert excitation_start(t, bias[:, None]) == t[0]
    X[:10] = np.nan  # samples without data are skipped
    assert excitation_start(t, X[:, :2]) == pytest.approx(1.5)
    assert np.isnan(excitation_start(t[:0], X[:0]))


def test_the_fit_statistic_is_the_coefficient_of_determination():
    rng = np.random.default_rng(1)
    z = rng.normal(size=200)
    v = 0.3 * rng.normal(size=200)
    fit = FitStatistics()
    for a, b in zip(z, v, strict=True):
        fit.add(a, b)
    assert fit.r_squared == pytest.approx(1 - np.sum(v**2) / np.sum((z - z.mean()) ** 2), rel=1e-12)
    assert np.isnan(FitStatistics().r_squared)


def _converged_from_csv(path: Path) -> tuple[dict[str, int], dict[str, int]]:
    """Per parameter, the stamp (ns) from which its converged flag stays 1 to the end, and
    the stamp at which it was first set."""
    since: dict[str, int | None] = {}
    first: dict[str, int] = {}
    with open(path) as fh:
        for row in csv.DictReader(fh):
            p = row["parameter"]
            sec, nanosec = row["time"].split(".")
            if row["converged"] == "1":
                first.setdefault(p, int(sec) * 10**9 + int(nanosec))
                if since.get(p) is None:
                    since[p] = int(sec) * 10**9 + int(nanosec)
            else:
                since[p] = None
    return {p: t for p, t in since.items() if t is not None}, first


def test_the_figure_data_of_a_replay_matches_its_csv_and_stays_bounded(tmp_path, monkeypatch):
    from rls_uncertainty.offline import replay as replay_module
    monkeypatch.setattr(replay_module, "PLOT_POINTS", 40)
    captured = {}
    from rls_uncertainty.offline import figures
    monkeypatch.setattr(figures, "replay_figures", lambda out, title, history, data, options, **_: captured.update(
        data=data, history=history) or [])
    replay(BUNDLED, load_parameters_file("t2"), tmp_path / "r", progress=False)
    data = captured["data"]
    # Bounded: at most 2 x 40 kept samples, the same ones the estimates' history kept.
    assert data.history.n <= 80 and data.history.offered == 591
    np.testing.assert_array_equal(data.history.stamps_ns, captured["history"].stamps_ns)
    # Convergence: the stamp from which each flag stays set, as the CSV says.
    want, first = _converged_from_csv(tmp_path / "r" / "estimates.csv")
    assert any(first[p] < want[p] for p in want)  # some flags drop again: "stays set" matters
    names = [p for m in data.parameters for p in m]
    got = {p: s for p, s in zip(names, data.converged_since.tolist(), strict=True) if s >= 0}
    assert got == want and want
    # The batch sweep of every model over its 591 rows.
    assert [p.count for p in data.products] == [591, 591]
    assert [f.lags for f in data.finals] == [50, 50]


def test_the_figure_data_follows_the_measured_coefficients_of_the_recorded_rows():
    """With every regression row recorded (run_pipeline(record=True)), the kept measured
    coefficients are the rows' z and the modelled ones x' theta of the sample's estimate."""
    from rls_uncertainty.offline.bags import read_inputs
    from rls_uncertainty.offline.replay import run_pipeline
    from rls_uncertainty.offline.results import History

    params = load_parameters_file("t2")
    config = pipeline_config(params)
    names = [m.parameter_names for m in config.models]
    data = FigureData([m.output for m in config.models], [m.regressors for m in config.models], names, config.rate)
    result = run_pipeline(read_inputs(BUNDLED)[0], config, record=True, history=History(names), figure_data=data)
    rows = result.pipeline.regression
    assert data.history.n == len(rows) == 591
    stamps, measured, model = data.coefficient(1)  # Cm
    np.testing.assert_array_equal(stamps, [t for t, _X, _z in rows])
    np.testing.assert_array_equal(measured, [z[1] for _t, _X, z in rows])
    # Cm's estimates: columns 3..6 of the flat parameter order (CZ has 3 parameters).
    thetas = np.column_stack([result.history.column(3 + i)[0] for i in range(4)])
    expected = np.array([X[1, :4] @ th for (_t, X, _z), th in zip(rows, thetas, strict=True)])
    np.testing.assert_allclose(model, expected, rtol=1e-12, equal_nan=True)
    assert np.isnan(model[0]) and np.isfinite(model[-1])  # not ready at first
    np.testing.assert_array_equal(data.regressor_history(1), np.array([X[1, :4] for _t, X, _z in rows]))
