"""The prediction check (offline.predict, offline.model_file and the predict command)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from rls_uncertainty.campaign import CampaignSettings, Maneuver
from rls_uncertainty.campaign.run import run_maneuver
from rls_uncertainty.cli import main
from rls_uncertainty.errors import ConfigError
from rls_uncertainty.offline.bags import write_t2_bag
from rls_uncertainty.offline.model_file import MODELS_FILE, FittedModel, models_json, read_models
from rls_uncertainty.offline.predict import (
    ModelPrediction,
    PredictionResult,
    PredictOptions,
    applied_models,
    fit_error,
    prediction,
)
from rls_uncertainty.offline.replay import replay
from rls_uncertainty.settings import node_config, pipeline_config
from rls_uncertainty.testing import parameters

ROOT = Path(__file__).resolve().parents[1]
T2 = str(ROOT / "config" / "t2.yaml")


def synthetic(seed: int = 3, n: int = 3, k: int = 40) -> tuple[FittedModel, np.ndarray, np.ndarray, np.ndarray]:
    """A batch least squares fit (Eq. 13's covariance) on random regressors, and new rows."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([np.ones(k), rng.normal(size=(k, n - 1))])
    z = X @ np.arange(1.0, n + 1) + 0.1 * rng.normal(size=k)
    theta, *_ = np.linalg.lstsq(X, z, rcond=None)
    s2 = float(np.sum((z - X @ theta) ** 2) / (k - n))
    P = s2 * np.linalg.inv(X.T @ X)
    model = FittedModel("CZ", ("1", "alpha", "q_hat")[:n], ("CZ_0", "CZ_alpha", "CZ_q")[:n], theta, P, P, s2, k)
    X_new = np.column_stack([np.ones(7), rng.normal(size=(7, n - 1))])
    return model, X_new, X, z


def test_the_prediction_is_the_batch_product_and_the_interval_the_closed_form() -> None:
    model, X_new, _, _ = synthetic()
    y, lo, hi = prediction(model, X_new, PredictOptions().quantile)
    for k, x in enumerate(X_new):
        expected = sum(x[i] * model.estimate[i] for i in range(x.size))
        variance = sum(x[i] * model.covariance[i, j] * x[j] for i in range(x.size) for j in range(x.size))
        half = 1.959963984540054 * math.sqrt(variance + model.residual_variance)
        assert y[k] == pytest.approx(expected, rel=1e-12)
        assert hi[k] - y[k] == pytest.approx(half, rel=1e-12) and y[k] - lo[k] == pytest.approx(half, rel=1e-12)
    _, lo90, hi90 = prediction(model, X_new, PredictOptions(level=0.9).quantile)
    np.testing.assert_allclose((hi90 - lo90) / (hi - lo), 1.6448536269514722 / 1.959963984540054, rtol=1e-12)


def test_on_the_fitting_data_the_prediction_is_the_batch_fit() -> None:
    model, _, X, z = synthetic(seed=5)
    y, _, _ = prediction(model, X, 1.96)
    hat = X @ np.linalg.solve(X.T @ X, X.T)  # the batch fit's projection: fitted = H z
    np.testing.assert_allclose(y, hat @ z, rtol=1e-9)


def test_fit_error_figures() -> None:
    z = np.array([1.0, 2.0, 3.0, 4.0])
    y = np.array([1.1, 1.9, 3.2, 3.8])
    e = fit_error(z, y, y - 0.15, y + 0.15)
    assert e.rms == pytest.approx(math.sqrt((0.01 + 0.01 + 0.04 + 0.04) / 4))
    assert e.r_squared == pytest.approx(1 - 0.1 / 5.0)
    assert e.theil_u == pytest.approx(e.rms / (math.sqrt(np.mean(z**2)) + math.sqrt(np.mean(y**2))))
    assert e.coverage == 0.5 and e.samples == 4


def test_the_mean_over_maneuvers_is_the_mean_estimate_with_the_covariance_of_a_mean() -> None:
    a = synthetic(seed=1)[0]
    b = synthetic(seed=2)[0]
    source, (mean,) = applied_models([("m1", [a]), ("m2", [b])])
    assert source == "the mean over 2 maneuvers"
    np.testing.assert_allclose(mean.estimate, (a.estimate + b.estimate) / 2)
    np.testing.assert_allclose(mean.covariance, (a.covariance + b.covariance) / 4)
    assert mean.residual_variance == pytest.approx((a.residual_variance + b.residual_variance) / 2)
    assert applied_models([("m1", [a]), ("m2", [b])], "m2") == ("m2", [b])
    with pytest.raises(ConfigError, match=r"m3.*m1, m2"):
        applied_models([("m1", [a]), ("m2", [b])], "m3")
    with pytest.raises(ConfigError, match="--maneuver m2 identified no model"):
        applied_models([("m1", [a]), ("m2", [])], "m2")
    with pytest.raises(ConfigError, match="the run identified no model"):
        applied_models([("m1", []), ("m2", [])])
    with pytest.raises(ConfigError, match="no model"):
        applied_models([("m1", [])])


def test_models_file_round_trip_and_refusals(tmp_path: Path) -> None:
    model = synthetic()[0]
    (tmp_path / MODELS_FILE).write_text(models_json([("m", [model])]))
    [(name, [back])] = read_models(tmp_path)
    assert name == "m" and back.model == "CZ" and back.regressors == model.regressors
    np.testing.assert_array_equal(back.estimate, model.estimate)
    np.testing.assert_array_equal(back.covariance, model.covariance)
    doc = json.loads((tmp_path / MODELS_FILE).read_text())
    doc["maneuvers"][0]["models"][0]["estimate"][1] = float("nan")
    (tmp_path / MODELS_FILE).write_text(json.dumps(doc))
    with pytest.raises(ConfigError, match="estimate: a value is not finite"):
        read_models(tmp_path)
    (tmp_path / MODELS_FILE).write_text("{")
    with pytest.raises(ConfigError, match="not readable as JSON"):
        read_models(tmp_path)
    with pytest.raises(ConfigError, match=r"no models\.json"):
        read_models(tmp_path / "..")


def test_a_campaign_maneuver_keeps_its_final_models(tmp_path: Path) -> None:
    bag = write_t2_bag(tmp_path / "b", seed=4)
    p = parameters("t2")
    res = run_maneuver((Maneuver("m", str(bag)), CampaignSettings(pipeline_config(p), node_config(p).topics)))
    rows = {r.parameter: r for r in res.rows}
    assert [m.model for m in res.models] == ["CZ", "Cm"]
    for m in res.models:
        for i, name in enumerate(m.parameters):
            assert m.estimate[i] == rows[name].estimate
            assert math.sqrt(m.covariance[i, i]) == pytest.approx(rows[name].se_corrected, rel=1e-9)
            assert math.sqrt(m.covariance_conventional[i, i]) == pytest.approx(rows[name].se_conventional, rel=1e-9)


@pytest.fixture(scope="module")
def repeats(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """Two simulated T-2 repeats (seeds 1 and 2) and the replay of the first."""
    d = tmp_path_factory.mktemp("repeats")
    first, second = write_t2_bag(d / "s1", seed=1), write_t2_bag(d / "s2", seed=2)
    replay(first, parameters("t2"), d / "s1_est", plots=False, progress=False)
    return first, second, d / "s1_est"


def effective_samples(e: np.ndarray) -> float:
    """Samples of a correlated series worth as many independent ones for a mean: n / (1 + 2 sum rho_i),
    over the lags before the autocorrelation first falls below zero."""
    e = e - e.mean()
    r = np.correlate(e, e, "full")[e.size - 1:] / (e @ e)
    first_negative = int(np.argmax(r < 0)) or r.size
    return e.size / (1.0 + 2.0 * float(np.sum(r[1:first_negative])))


def test_end_to_end_the_coverage_on_a_repeat_is_near_nominal(repeats, tmp_path: Path, capsys) -> None:
    _, second, run = repeats
    out = tmp_path / "p"
    assert main(["predict", str(run), str(second), "--config", T2, "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    [(_, fitted)] = read_models(run)
    assert "CZ" in printed and "Cm" in printed and "95 % nominal" in printed
    header = (out / "prediction.csv").read_text().splitlines()[0].split(",")
    assert header == ["time"] + [f"{m}_{q}" for m in ("CZ", "Cm") for q in ("measured", "predicted", "lower", "upper")]
    data = np.loadtxt(out / "prediction.csv", delimiter=",", skiprows=1)
    for m in range(2):
        z, y, lo, hi = data[:, 1 + 4 * m: 5 + 4 * m].T
        inside = (z >= lo) & (z <= hi)
        # The misses are correlated as the residuals are: a binomial spread over the effective
        # number of independent samples, 4 sigma wide (about 0.08 here).
        n_eff = effective_samples(z - y)
        tolerance = 4 * math.sqrt(0.95 * 0.05 / n_eff)
        assert abs(inside.mean() - 0.95) < tolerance, (inside.mean(), n_eff)
        assert f"{100 * inside.mean():.1f}%" in printed
        # The parameters' share of the interval, from its width: (half / q)^2 = x'Px + s^2.
        s2 = fitted[m].residual_variance
        share = np.median(((hi - y) / 1.959963984540054) ** 2 - s2) / s2
        assert f"{share:.3f}" in printed.splitlines()[2 + m]


def test_bad_input_is_one_line(repeats, tmp_path: Path, capsys) -> None:
    first, second, run = repeats
    out = tmp_path / "p"
    assert main(["predict", str(run), str(second), "--config", T2, "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    cases = [
        # the output exists: not replaced without --force
        ["predict", str(run), str(second), "--config", T2, "--out", str(out)],
        # a directory without models.json
        ["predict", str(first), str(second), "--config", T2, "--out", str(tmp_path / "q")],
        # the run's Cm is not among the configuration's models
        ["predict", str(run), str(second), "--config", T2, "--models", "CZ", "--out", str(tmp_path / "r")],
        ["predict", str(run), str(second), "--config", T2, "--maneuver", "nope", "--out", str(tmp_path / "s")],
    ]
    for argv in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("rls-uncertainty predict: error:"), err
        assert "Traceback" not in err
    assert not (tmp_path / "q").exists() and not (tmp_path / "r").exists()


def _set(key: str, value: object):
    def change(entry: dict) -> None:
        entry[key] = value
    return change


HOSTILE_ENTRIES = [
    (_set("samples", "1e400"), "samples must be a whole number"),  # (replaced by the number 1e400 below)
    (_set("samples", -5), "samples must be a whole number"),
    (_set("samples", 2.5), "samples must be a whole number"),
    (_set("estimate", [True, False, True]), "estimate: not numbers"),
    (_set("estimate", ["1", "2", "3"]), "estimate: not numbers"),
    (_set("residual_variance", "0.1"), "residual_variance must be a finite number"),
    (_set("residual_variance", True), "residual_variance must be a finite number"),
    (_set("covariance", [[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), "covariance: not symmetric"),
    (_set("covariance", [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), "covariance: a variance"),
    (_set("covariance_conventional", [[1.0, 0.0], [0.0, 1.0]]), r"covariance_conventional: shape \(2, 2\)"),
]


@pytest.mark.parametrize(("change", "message"), HOSTILE_ENTRIES)
def test_a_hostile_models_file_is_refused_in_one_error(tmp_path: Path, change, message: str) -> None:
    doc = json.loads(models_json([("m", [synthetic()[0]])]))
    change(doc["maneuvers"][0]["models"][0])
    text = json.dumps(doc).replace('"samples": "1e400"', '"samples": 1e400')  # JSON's too-large number: inf
    (tmp_path / MODELS_FILE).write_text(text)
    with pytest.raises(ConfigError, match=message):
        read_models(tmp_path)


def test_a_models_file_nested_too_deep_or_with_a_model_twice_is_refused(tmp_path: Path) -> None:
    (tmp_path / MODELS_FILE).write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ConfigError, match="nested too deep"):
        read_models(tmp_path)
    model = synthetic()[0]
    (tmp_path / MODELS_FILE).write_text(models_json([("m", [model, model])]))
    with pytest.raises(ConfigError, match="maneuver m: model CZ given more than once"):
        read_models(tmp_path)


def test_a_model_whose_prediction_overflows_is_refused_never_a_nan() -> None:
    model, X_new, _, _ = synthetic()
    huge = FittedModel(model.model, model.regressors, model.parameters, np.full(3, 1e308), model.covariance,
                       model.covariance, model.residual_variance, model.samples)
    with pytest.raises(ConfigError, match="model CZ: its prediction or interval is not a finite number"):
        prediction(huge, np.abs(X_new) + 1.0, 1.96)
    big = FittedModel(model.model, model.regressors, model.parameters, np.full(3, 1e200), model.covariance,
                      model.covariance, model.residual_variance, model.samples)
    y, lo, hi = prediction(big, X_new, 1.96)
    assert math.isinf(fit_error(X_new[:, 0], y, lo, hi).rms)  # the predict command refuses it


def test_predict_refuses_a_model_too_large_in_one_line_and_writes_nothing(repeats, tmp_path: Path, capsys) -> None:
    _, second, run = repeats
    doc = json.loads((run / MODELS_FILE).read_text())
    cz = doc["maneuvers"][0]["models"][0]
    cz["estimate"] = [1e200] * len(cz["estimate"])
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / MODELS_FILE).write_text(json.dumps(doc))
    out = tmp_path / "p"
    assert main(["predict", str(tmp_path / "run"), str(second), "--config", T2, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "model CZ: its prediction error is not a finite number" in err, err
    assert not out.exists()


def test_the_summary_shows_an_undefined_figure_as_a_dash_not_nan() -> None:
    model = synthetic()[0]
    z = np.ones(4)  # a constant measurement: R^2 is not defined
    e = fit_error(z, z, z, z)
    assert math.isnan(e.r_squared) and math.isnan(e.parameter_share)
    text = PredictionResult("m", np.arange(4), [ModelPrediction(model, z, z, z, z, e)], 0.95).summary()
    assert "nan" not in text.lower()
    assert text.splitlines()[2].split() == ["CZ", "0", "-", "0.000", "100.0%", "-"]
