"""The auxiliary short-period model of the instruments: closed-form discretization, the
stability guard, the layout of the instrument vectors, the bootstrap and the hand-over."""

import numpy as np
import pytest
from scipy.linalg import expm

from rls_uncertainty.aero.models import DEFAULT_MODELS, ModelConfig
from rls_uncertainty.errors import ConfigError, NonFiniteInput
from rls_uncertainty.instruments import (
    BareRls,
    InstrumentLayout,
    ShortPeriodAuxiliary,
    discretize,
    is_stable,
    short_period_matrices,
)
from rls_uncertainty.settings import load_aircraft
from rls_uncertainty.simulation.t2 import T2_MODELS, T2_TRUE

T2 = load_aircraft("t2")
QBAR, V = 1500.0, 40.8
TRUE = np.array([[0.1, T2_TRUE["CZ_alpha"], T2_TRUE["CZ_delta_e"], 0.0],
                 [0.02, T2_TRUE["Cm_alpha"], T2_TRUE["Cm_q"], T2_TRUE["Cm_delta_e"]]])


def zoh(A, B, T):
    """Phi and Gamma from the exponential of the augmented matrix [[A, B], [0, 0]] T."""
    M = np.zeros((3, 3))
    M[:2, :2], M[:2, 2] = A, B
    E = expm(M * T)
    return E[:2, :2], E[:2, 2]


@pytest.mark.parametrize("A", [
    np.array([[-3.0, 1.0], [0.5, -5.0]]),  # real, distinct poles
    np.array([[-1.9, 1.0], [-40.0, -2.7]]),  # complex poles (the T-2's short period)
    np.array([[-2.0, 1.0], [0.0, -2.0]]),  # repeated pole, one eigenvector
    np.array([[-2.0, 0.0], [0.0, -2.0]]),  # repeated pole, two eigenvectors
    np.array([[-2.0, 1.0], [-1e-14, -2.0]]),  # nearly repeated (|w| T tiny)
    np.array([[-2.0, 1.0], [-0.25, -3.0]]),  # repeated: s^2 = det exactly
], ids=["real", "complex", "repeated-jordan", "repeated-diagonal", "near-repeated", "repeated-general"])
@pytest.mark.parametrize("T", [0.02, 0.5])
def test_closed_form_discretization_matches_the_matrix_exponential(A, T):
    B = np.array([0.3, -7.0])
    Phi, Gamma = discretize(A, B, T)
    Phi_ref, Gamma_ref = zoh(A, B, T)
    np.testing.assert_allclose(Phi, Phi_ref, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(Gamma, Gamma_ref, rtol=1e-11, atol=1e-14)


def test_short_period_matrices_are_eq25a():
    th = dict(zip(("CZ_alpha", "CZ_q", "CZ_delta_e", "Cm_alpha", "Cm_q", "Cm_delta_e"),
                  (-3.9, 2.0, 0.2, -1.5, -53.0, -1.8), strict=True))
    A, B = short_period_matrices(np.array(list(th.values())), QBAR, V, T2)
    Z, M, c = QBAR * T2.S / (T2.mass * V), QBAR * T2.S * T2.cbar / T2.Iyy, T2.cbar / (2 * V)
    # d alpha/dt and dq/dt at a test state and input, written out term by term
    a, q, u = 0.01, -0.03, 0.02
    alpha_dot = Z * (th["CZ_alpha"] * a + th["CZ_q"] * c * q + th["CZ_delta_e"] * u) + q
    q_dot = M * (th["Cm_alpha"] * a + th["Cm_q"] * c * q + th["Cm_delta_e"] * u)
    np.testing.assert_allclose(A @ [a, q] + B * u, [alpha_dot, q_dot], rtol=1e-13)


def test_stability_guard_from_the_eigenvalues():
    rng = np.random.default_rng(4)
    for _ in range(200):
        A = rng.normal(0.0, 3.0, (2, 2))
        assert is_stable(A, 0.2) == bool(np.linalg.eigvals(A).real.max() < -0.2)
    assert not is_stable(np.array([[np.nan, 1.0], [0.0, -1.0]]))


def aux_models(*models):
    return ShortPeriodAuxiliary(models or T2_MODELS, T2, 50.0)


def test_unstable_candidates_are_refused_and_the_last_model_kept():
    aux = aux_models()
    assert aux.set_model(TRUE, QBAR, V)
    Phi, Gamma = aux.Phi.copy(), aux.Gamma.copy()
    unstable = TRUE.copy()
    unstable[1, 1] = 30.0  # C_m_alpha > 0: a real pole in the right half plane
    A, _ = short_period_matrices(InstrumentLayout(T2_MODELS).derivatives(unstable), QBAR, V, T2)
    assert np.linalg.eigvals(A).real.max() > 0
    slow = TRUE.copy()
    slow[1, 2] = slow[1, 1] = slow[0, 1] = 0.0  # poles at 0
    nan = TRUE.copy()
    nan[0, 2] = np.nan
    for candidate in (unstable, slow, nan):
        assert not aux.set_model(candidate, QBAR, V)
        np.testing.assert_array_equal(aux.Phi, Phi)
        np.testing.assert_array_equal(aux.Gamma, Gamma)
    assert aux.refused == 3


def test_instrument_vectors_are_laid_out_like_the_regressors():
    models = (ModelConfig("Cm", ("delta_e", "q_hat", "1", "alpha")), ModelConfig("CZ", ("alpha", "delta_e")),
              ModelConfig("CX", ("1", "alpha", "delta_e")))
    aux = aux_models(*models)
    aux.state = np.array([0.01, -0.2])
    zeta = aux.instruments(0.05, V)
    q_hat = -0.2 * T2.cbar / (2 * V)
    np.testing.assert_array_equal(zeta, [[0.05, q_hat, 1.0, 0.01], [0.01, 0.05, 0.0, 0.0], [1.0, 0.01, 0.05, 0.0]])
    # the derivatives come from the right columns whatever the order
    theta = np.array([[-1.8, -53.0, 0.0, -1.5], [-3.9, 0.2, 0.0, 0.0], [9.0, 9.0, 9.0, 0.0]])
    np.testing.assert_array_equal(aux.layout.derivatives(theta), [-3.9, 0.0, 0.2, -1.5, -53.0, -1.8])


def test_models_the_auxiliary_model_cannot_serve_are_refused_in_one_line():
    with pytest.raises(ConfigError, match=r"^estimator\.algorithm: .*CY.*beta, r_hat, delta_r") as info:
        aux_models(*DEFAULT_MODELS)
    assert "\n" not in str(info.value) and info.value.parameter == "estimator.algorithm"
    with pytest.raises(ConfigError, match=r"^estimator\.algorithm: .*Cl.*beta, p_hat, r_hat, delta_a") as info:
        aux_models(*T2_MODELS, ModelConfig("Cl", ("1", "beta", "p_hat", "r_hat", "delta_a")))
    assert "\n" not in str(info.value) and info.value.parameter == "estimator.algorithm"
    with pytest.raises(ConfigError, match=r"^estimator\.algorithm: .*Cm_q") as info:
        aux_models(ModelConfig("CZ", ("1", "alpha", "delta_e")), ModelConfig("Cm", ("1", "alpha", "delta_e")))
    assert "\n" not in str(info.value)


def run_maneuver(aux, n, seed=0, estimates=None):
    """A synthetic record from the true model driven by a random input: every sample
    through :meth:`update`; returns the inputs, the regressors, what each sample delivered
    and the model ``(Phi, Gamma)`` after each."""
    rng = np.random.default_rng(seed)
    A, B = short_period_matrices(aux.layout.derivatives(TRUE), QBAR, V, T2)
    Phi, Gamma = zoh(A, B, aux.dt)
    u = np.repeat(rng.normal(0.0, 0.02, n // 5 + 1), 5)[:n]
    s = np.zeros(2)
    delivered, models = [], []
    X = np.zeros((n, 2, 4))
    for k in range(n):
        a, q = s + rng.normal(0.0, 1e-3, 2)
        X[k, 0, :3] = 1.0, a, u[k]
        X[k, 1] = 1.0, a, q * T2.cbar / (2 * V), u[k]
        z = np.einsum("mi,mi->m", X[k], TRUE) + rng.normal(0.0, 1e-3, 2)
        delivered.append(aux.update(X[k], z, u[k], QBAR, V, estimates, tag=k))
        models.append((aux.Phi.copy(), aux.Gamma.copy()))
        s = Phi @ s + Gamma * u[k]
    return u, X, delivered, models


def test_replay_at_the_hand_over_equals_stepping_sample_by_sample():
    aux = aux_models()
    u, X, delivered, models = run_maneuver(aux, 300)
    counts = [len(d) for d in delivered]
    k0 = next(k for k, c in enumerate(counts) if c)
    assert counts[:k0] == [0] * k0 and counts[k0] == k0 + 1 and counts[k0 + 1:] == [1] * (300 - k0 - 1)
    assert aux.bare.ready and aux.has_model and aux.waiting == 0
    flat = [s for d in delivered for s in d]
    np.testing.assert_array_equal(np.stack([s.X for s in flat]), X)
    assert [s.tag for s in flat] == list(range(300))
    # the first model, stepped by hand from rest over the same inputs (I2, then I1)
    Phi, Gamma = models[k0]
    s, stepped = np.zeros(2), []
    for k in range(k0 + 1):
        stepped.append([s[0], s[1] * T2.cbar / (2 * V), u[k]])
        s = Phi @ s + Gamma * u[k]
    handed = np.stack([smp.instruments for smp in flat[: k0 + 1]])
    np.testing.assert_allclose(handed[:, 1, 1:], stepped, rtol=1e-13, atol=1e-18)
    np.testing.assert_array_equal(handed[:, 0, 1:3], handed[:, 1, [1, 3]])
    # after the hand-over the state carries on: sample k0 + 1 continues the same recursion
    np.testing.assert_allclose(flat[k0 + 1].instruments[1, 1], s[0], rtol=1e-13)


def test_the_model_is_refreshed_every_refresh_span_from_the_estimates_given():
    aux = ShortPeriodAuxiliary(T2_MODELS, T2, 50.0, refresh_span=0.2)  # every 10 samples
    run_maneuver(aux, 100)
    assert aux.has_model
    changed = []
    for k in range(35):  # estimates that differ at every sample: the model changes when refreshed
        target = TRUE.copy()
        target[1, 2] = -40.0 - k
        before = aux.Phi.copy()
        aux.update(np.ones((2, 4)), np.zeros(2), 0.0, QBAR, V, estimates=target)
        changed.append(not np.array_equal(before, aux.Phi))
    assert sum(changed) >= 3 and set(np.diff(np.flatnonzero(changed))) == {10}
    last = np.flatnonzero(changed)[-1]
    target[1, 2] = -40.0 - last
    A, B = short_period_matrices(aux.layout.derivatives(target), QBAR, V, T2)
    np.testing.assert_array_equal(aux.Phi, discretize(A, B, aux.dt)[0])


def test_estimates_given_stop_the_bootstrap_and_nan_estimates_do_not():
    aux = aux_models()
    run_maneuver(aux, 60)
    k = aux.bare.k
    aux.update(np.ones((2, 4)), np.zeros(2), 0.0, QBAR, V, estimates=TRUE)
    assert aux.bare.k == k
    aux.update(np.ones((2, 4)), np.zeros(2), 0.0, QBAR, V, estimates=np.full((2, 4), np.nan))
    assert aux.bare.k == k + 1


def test_bad_input_is_refused_and_changes_nothing():
    aux = aux_models()
    run_maneuver(aux, 10)
    waiting, k = aux.waiting, aux.bare.k
    for bad in (dict(u=np.nan), dict(V=0.0), dict(qbar=np.inf), dict(X=np.full((2, 4), np.nan))):
        args = dict(X=np.ones((2, 4)), z=np.zeros(2), u=0.0, qbar=QBAR, V=V) | bad
        with pytest.raises(NonFiniteInput, match=r"^instruments: "):
            aux.update(**args)
    assert aux.waiting == waiting and aux.bare.k == k


def test_the_backlog_is_bounded():
    aux = ShortPeriodAuxiliary(T2_MODELS, T2, 50.0, max_backlog_span=0.5)
    for _ in range(40):  # no excitation: the bare RLS never starts
        assert aux.update(np.tile([1.0, 0.08, 0.0, 0.0], (2, 1)), np.zeros(2), 0.0, QBAR, V) == []
    assert aux.waiting == 25 and aux.dropped == 15 and not aux.has_model


def test_bare_rls_equals_least_squares_on_the_samples_so_far():
    rng = np.random.default_rng(2)
    rls = BareRls((2, 3), min_samples=5)
    X = rng.normal(size=(60, 2, 3))
    X[:, 0, 2] = 7.0  # padding: ignored
    z = rng.normal(size=(60, 2))
    for k in range(60):
        rls.update(X[k], z[k])
        if k + 1 >= 5:
            assert rls.ready
            for j, s in enumerate((2, 3)):
                ls = np.linalg.lstsq(X[: k + 1, j, :s], z[: k + 1, j], rcond=None)[0]
                np.testing.assert_allclose(rls.theta[j, :s], ls, rtol=1e-9, atol=1e-12)
            assert rls.theta[0, 2] == 0.0


def test_regressor_vectors_per_model_and_reset():
    """``X`` as one vector per model gives what the padded array gives; after :meth:`reset`
    the same samples give what a new object gives."""
    aux, again = aux_models(), aux_models()
    _, X, _, _ = run_maneuver(aux, 120)
    rng = np.random.default_rng(0)
    z = rng.normal(size=(120, 2))
    aux.reset()
    assert not aux.has_model and aux.waiting == 0 and not aux.bare.ready and aux.refused == 0
    for k in range(120):
        u = X[k, 1, 3]
        got = aux.update([X[k, 0, :3], X[k, 1]], z[k], u, QBAR, V)
        want = again.update(X[k], z[k], u, QBAR, V)
        assert len(got) == len(want)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g.X, w.X)
            np.testing.assert_array_equal(g.instruments, w.instruments)
    assert aux.has_model


def test_estimates_given_from_the_start_build_the_first_model():
    """Fixed estimates (a prior model) from the first sample: the first sample is handed over
    at once, with that model, and the bare RLS never runs."""
    aux = aux_models()
    _, _, delivered, models = run_maneuver(aux, 50, estimates=TRUE)
    assert [len(d) for d in delivered] == [1] * 50 and aux.bare.k == 0
    A, B = short_period_matrices(aux.layout.derivatives(TRUE), QBAR, V, T2)
    np.testing.assert_array_equal(models[0][0], discretize(A, B, aux.dt)[0])
