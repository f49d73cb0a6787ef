"""Eq. 1 coefficients, Eq. 2 regressors, frames, aircraft configuration."""

import numpy as np
import pytest

from rls_uncertainty.aero import (
    FlightState,
    coefficients,
    physics_rejection,
    regressor_matrix,
    regressors,
    rep103_to_aircraft,
)
from rls_uncertainty.config import DEFAULT_MODELS, ConfigError, ModelConfig, load_aircraft, load_models

T2 = load_aircraft("t2")


def state(**kw):
    base = dict(ax=0.5, ay=-0.2, az=-9.7, p=0.1, q=-0.05, r=0.02, p_dot=0.3, q_dot=-0.4, r_dot=0.1,
                V=40.0, alpha=0.08, beta=0.01, qbar=980.0, delta_e=-0.02, delta_a=0.01, delta_r=0.005, thrust=20.0)
    base.update(kw)
    return FlightState(**base)


def test_table1_converted_to_si():
    assert T2.b == pytest.approx(6.849 * 0.3048, rel=1e-8)
    assert T2.S == pytest.approx(5.902 * 0.3048**2, rel=1e-6)
    assert T2.mass == pytest.approx(1.585 * 14.59390294, rel=1e-8)
    assert T2.Iyy == pytest.approx(4.520 * 14.59390294 * 0.3048**2, rel=1e-8)
    otter = load_aircraft("twin_otter_f1_017")
    assert (otter.mass, otter.Ixz, otter.S) == (4952.28, 1528.0, 39.25)


def test_eq1_against_rigid_body_moment_equations():
    """Rebuild the aerodynamic moments from Euler's equations with the inertia tensor
    (aircraft axes, Ixz product) and compare with the coefficients of Eq. 1d-f."""
    s = state()
    c = coefficients(s, T2)
    I = np.array([[T2.Ixx, 0, -T2.Ixz], [0, T2.Iyy, 0], [-T2.Ixz, 0, T2.Izz]])
    w = np.array([s.p, s.q, s.r])
    wd = np.array([s.p_dot, s.q_dot, s.r_dot])
    M = I @ wd + np.cross(w, I @ w)  # L, M, N
    qS = s.qbar * T2.S
    assert c["Cl"] == pytest.approx(M[0] / (qS * T2.b), rel=1e-12)
    assert c["Cm"] == pytest.approx(M[1] / (qS * T2.cbar), rel=1e-12)
    assert c["Cn"] == pytest.approx(M[2] / (qS * T2.b), rel=1e-12)
    assert c["CX"] == pytest.approx((T2.mass * s.ax - s.thrust) / qS)
    assert c["CZ"] == pytest.approx(T2.mass * s.az / qS)


def test_regressors_and_default_models_of_eq2():
    s = state()
    values = regressors(s, T2)
    assert values["q_hat"] == pytest.approx(s.q * T2.cbar / (2 * s.V))
    assert values["p_hat"] == pytest.approx(s.p * T2.b / (2 * s.V))
    sizes = [len(m.regressors) for m in DEFAULT_MODELS]
    assert sizes == [3, 4, 3, 6, 4, 4]
    cm = DEFAULT_MODELS[4]
    assert cm.parameter_names == ("Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e")
    np.testing.assert_allclose(regressor_matrix(cm, values), [1.0, s.alpha, values["q_hat"], s.delta_e])


def test_models_are_configuration():
    models = load_models({"CZ": ["1", "alpha", "q_hat", "delta_e"]})
    assert models[0].parameter_names == ("CZ_0", "CZ_alpha", "CZ_q", "CZ_delta_e")
    with pytest.raises(ConfigError, match="unknown regressor"):
        ModelConfig("CZ", ("1", "alpha_dot"))
    with pytest.raises(ConfigError, match="output"):
        ModelConfig("CL", ("1",))


def test_rep103_to_aircraft_axes():
    # Level flight: the IMU's specific force is +g on REP-103 z (up), -g on aircraft z (down);
    # a nose-up pitch rate is -wy in REP-103 (y left) and +q in aircraft axes.
    np.testing.assert_allclose(rep103_to_aircraft([0.1, 0.2, 9.81]), [0.1, -0.2, -9.81])
    np.testing.assert_allclose(rep103_to_aircraft(np.array([[0.0, -0.05, 0.0]])), [[0.0, 0.05, 0.0]])


@pytest.mark.parametrize("kw, reason", [
    (dict(qbar=0.0), "nonpositive_dynamic_pressure"),
    (dict(qbar=-5.0), "nonpositive_dynamic_pressure"),
    (dict(V=0.0), "nonpositive_airspeed"),
    (dict(alpha=np.nan), "non_finite_alpha"),
    (dict(q_dot=np.inf), "non_finite_q_dot"),
])
def test_bad_physics_input_is_a_rejection_reason(kw, reason):
    assert physics_rejection(state(**kw)) == reason
    assert physics_rejection(state()) is None


def test_aircraft_file_errors_are_clear(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("aircraft: {name: x, mass: -1, Ixx: 1, Iyy: 1, Izz: 1, Ixz: 0, S: 1, b: 1, cbar: 1}\n")
    with pytest.raises(ConfigError, match="mass must be positive"):
        load_aircraft(bad)
    bad.write_text("aircraft: {name: x}\n")
    with pytest.raises(ConfigError, match="needs"):
        load_aircraft(bad)
    with pytest.raises(ConfigError, match="no such file"):
        load_aircraft(tmp_path / "missing.yaml")
