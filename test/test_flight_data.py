"""Real flight data: the NASA Twin Otter recordings in ../shared/flight_data, converted with
the shipped fti_msgs mapping and run through the node's pipeline. Without the recordings
these tests are skipped (a failure under RLS_REQUIRE_FLIGHT_DATA=1, as in .ci/run); the last
tests check that policy itself on a generated test file."""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from rls_uncertainty.estimator import batch_estimate
from rls_uncertainty.offline.bags import convert, read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config

from conftest import FLIGHT_DATA, ROOT

MAPPING = ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml"
RUNS = {
    "totter_f1_017": ("twin_otter_lateral", {}),
    "totter_f1_014": ("twin_otter_lateral", {"aircraft": "twin_otter_f1_014"}),
    "totter_9752ed20": ("twin_otter_longitudinal", {}),
}
flight_data = pytest.mark.flight_data


@flight_data
def test_the_recordings_are_there():
    missing = [rec for rec in RUNS if not (FLIGHT_DATA / rec).is_dir()]
    assert not missing, f"{FLIGHT_DATA} lacks {missing}"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for rec, (cfg, extra) in RUNS.items():
        bag = tmp_path_factory.mktemp("replays") / rec
        convert(FLIGHT_DATA / rec, MAPPING, bag)
        messages, _ = read_inputs(bag)
        params = load_parameters_file(cfg)
        params.update(extra)
        result = run_pipeline(messages, pipeline_config(params))
        X = np.array([r[1] for r in result.pipeline.regression])
        z = np.array([r[2] for r in result.pipeline.regression])
        out[rec] = (result, X, z)
    return out


def _models(run):
    result, X, z = run
    last = result.outputs[-1]
    for j, names in enumerate(result.pipeline.parameter_names):
        n = len(names)
        yield names, X[:, j, :n], z[:, j], last.theta[j, :n], last.se[j, :n], last.se_conventional[j, :n]


@flight_data
@pytest.mark.parametrize("rec", ["totter_f1_017", "totter_9752ed20"])
def test_end_estimates_equal_batch_least_squares_on_the_same_samples(runs, rec):
    result, _, _ = runs[rec]
    assert result.pipeline.counters()["samples_used"] > 950
    for names, X, z, theta, _se, _sc in _models(runs[rec]):
        ols = np.linalg.lstsq(X, z, rcond=None)[0]
        np.testing.assert_allclose(theta, ols, rtol=1e-6, err_msg=str(names))  # criterion: 1%


@flight_data
@pytest.mark.parametrize("rec", ["totter_f1_017", "totter_9752ed20"])
def test_colored_residuals_make_corrected_errors_larger(runs, rec):
    for names, X, z, _theta, se, sc in _models(runs[rec]):
        derivatives = slice(1, None)  # the bias is not a derivative
        assert np.all(se[derivatives] > 1.5 * sc[derivatives]), (names, se / sc)
        # The conventional errors equal the batch ones (Eq. 16 with the standardized residual is
        # Eq. 14); the recursive corrected errors agree with the batch formula (Eqs. 8-11,
        # 50 lags, final batch residuals) to 15% (measured 0-12%, largest for the six-parameter
        # Cl model, whose early residuals carry the transient of its estimates).
        _th, cc, cr = batch_estimate(X, z, 50, "truncated")
        np.testing.assert_allclose(sc, np.sqrt(np.diag(cc)), rtol=1e-6, err_msg=str(names))
        np.testing.assert_allclose(se[derivatives], np.sqrt(np.diag(cr))[derivatives], rtol=0.15, err_msg=str(names))


@flight_data
def test_static_and_damping_derivative_signs(runs):
    est = {}
    for rec in ("totter_f1_017", "totter_9752ed20"):
        for names, *_rest, theta, _se, _sc in _models(runs[rec]):
            est.update(zip(names, theta, strict=True))
    for name in ("CY_beta", "Cl_beta", "Cl_p", "Cn_r", "CZ_alpha", "Cm_alpha", "Cm_q", "Cm_delta_e"):
        assert est[name] < 0, name
    for name in ("Cn_beta", "CY_r"):
        assert est[name] > 0, name


@flight_data
def test_f1_017_estimates_predict_f1_014(runs):
    train, _, _ = runs["totter_f1_017"]
    _test, Xb, zb = runs["totter_f1_014"]
    theta = train.outputs[-1].theta
    for j, names in enumerate(train.pipeline.parameter_names):
        n = len(names)
        z = zb[:, j]
        ss = np.sum((z - z.mean()) ** 2)
        predicted = 1 - np.sum((z - Xb[:, j, :n] @ theta[j, :n]) ** 2) / ss
        own = np.linalg.lstsq(Xb[:, j, :n], z, rcond=None)[0]
        fitted = 1 - np.sum((z - Xb[:, j, :n] @ own) ** 2) / ss
        assert predicted > 0.9, (names[0], predicted)
        assert predicted > fitted - 0.05, (names[0], predicted, fitted)


# The skip policy of conftest.py, on a generated test directory with a copy of conftest.py:
# one test marked, one that names FLIGHT_DATA and one whose fixture does (both marked
# automatically), and one that needs nothing.
_POLICY_TESTS = """
import pytest
from conftest import FLIGHT_DATA

@pytest.fixture(scope="module")
def recording():
    return sorted(FLIGHT_DATA.iterdir())

@pytest.mark.flight_data
def test_marked():
    assert FLIGHT_DATA.is_dir()

def test_names_it():
    assert (FLIGHT_DATA / "x").parent.is_dir()

def test_through_a_fixture(recording):
    assert recording == []

def test_plain():
    pass
"""


def _run_policy(tmp_path, flight_data_dir, require):
    tests = tmp_path / "suite"
    tests.mkdir(exist_ok=True)
    shutil.copy2(ROOT / "test" / "conftest.py", tests / "conftest.py")
    (tests / "pytest.ini").write_text("[pytest]\n")
    (tests / "test_policy.py").write_text(_POLICY_TESTS)
    env = {k: v for k, v in os.environ.items() if k not in ("RLS_REQUIRE_FLIGHT_DATA", "PYTEST_ADDOPTS")}
    env["RLS_FLIGHT_DATA"] = str(flight_data_dir)
    if require:
        env["RLS_REQUIRE_FLIGHT_DATA"] = "1"
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", str(tests)],
        cwd=tests, env=env, capture_output=True, text=True, timeout=120,
    )


def test_missing_recordings_skip_with_the_path_as_reason(tmp_path):
    missing = tmp_path / "no_such_dir"
    run = _run_policy(tmp_path, missing, require=False)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "1 passed, 3 skipped" in run.stdout, run.stdout
    assert f"flight recordings not found at {missing}" in run.stdout, run.stdout


def test_missing_recordings_fail_when_required(tmp_path):
    missing = tmp_path / "no_such_dir"
    run = _run_policy(tmp_path, missing, require=True)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "1 passed, 3 errors" in run.stdout, run.stdout
    assert "skipped" not in run.stdout, run.stdout
    assert "RLS_REQUIRE_FLIGHT_DATA is set" in run.stdout, run.stdout


def test_present_recordings_run_the_marked_tests(tmp_path):
    present = tmp_path / "flight_data"
    present.mkdir()
    run = _run_policy(tmp_path, present, require=True)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "4 passed" in run.stdout, run.stdout
