"""T-2 simulation (Eq. 25) and a reduced Table 3 Monte Carlo."""

import csv
import math

import numpy as np
import pytest
from scipy import signal

from rls_uncertainty.cli import main
from rls_uncertainty.simulation.montecarlo import PAPER_TABLE3
from rls_uncertainty.simulation.t2 import (
    T2_TRUE,
    add_noise,
    reduce_short_period,
    simulate_short_period,
    standard_atmosphere_density,
)


def test_standard_atmosphere():
    assert standard_atmosphere_density(0.0) == pytest.approx(1.225)
    assert standard_atmosphere_density(1000.0) == pytest.approx(1.1117, rel=1e-3)


def test_noise_free_regression_recovers_the_true_values():
    """Without noise C_Z is exact; C_m carries the differentiator's small gain error (about
    0.3% on C_m_q with the default window 9, cubic, lag 4)."""
    t, data = reduce_short_period(simulate_short_period())
    theta_z = np.linalg.lstsq(*data["CZ"], rcond=None)[0]
    theta_m = np.linalg.lstsq(*data["Cm"], rcond=None)[0]
    assert theta_z[1:] == pytest.approx([T2_TRUE["CZ_alpha"], T2_TRUE["CZ_delta_e"]], rel=1e-6)
    assert theta_m[1:] == pytest.approx([T2_TRUE["Cm_alpha"], T2_TRUE["Cm_q"], T2_TRUE["Cm_delta_e"]], rel=5e-3)
    assert t[0] == pytest.approx(0.08) and len(t) == 592


def test_short_period_mode_near_1_1_hz():
    rec = simulate_short_period()
    from rls_uncertainty.simulation.t2 import state_space

    A = state_space(rec.config, rec.aircraft)[0]
    wn = np.abs(np.linalg.eigvals(A)[0]) / (2 * np.pi)
    assert 1.0 < wn < 1.2


def test_noise_levels_and_determinism():
    rec = simulate_short_period()
    a = add_noise(rec, 0.2, np.random.default_rng(3))
    b = add_noise(rec, 0.2, np.random.default_rng(3))
    np.testing.assert_array_equal(a.alpha, b.alpha)
    clean = rec.noise_free["alpha"]
    rms = np.sqrt(np.mean((clean - clean.mean()) ** 2))
    noise = a.alpha - clean
    expected = rms * np.sqrt(0.2**2 + 1 / 12.0**2)
    assert np.std(noise) == pytest.approx(expected, rel=0.15)
    # The band-limited part is below 2 Hz: most noise power at high frequency is the white part.
    f, p = signal.welch(noise, fs=50.0, nperseg=128)
    assert p[f < 1.5].mean() > 20 * p[f > 5].mean()


def test_reduced_monte_carlo_command(tmp_path):
    """20% band-limited noise, 60 runs: corrected SEs match the scatter, conventional ones are
    far too small, recursive and batch agree, 50 lags near all lags."""
    assert main(["montecarlo", "--runs", "60", "--levels", "20", "--out", str(tmp_path), "--workers", "1"]) == 0
    with open(tmp_path / "table3.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["parameter"] for r in rows] == list(PAPER_TABLE3[0.2])
    for r in rows:
        ratio = float(r["se_corrected"]) / float(r["scatter"])
        assert 0.7 < ratio < 1.4, r
        assert float(r["se_conventional"]) / float(r["scatter"]) < 0.5, r
        assert float(r["true"]) == T2_TRUE[r["parameter"]]
    for name in ("fig5_autocorrelation.png", "fig6_czalpha_history.png", "fig7_lags.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    assert "| 20% | Cm_q |" in (tmp_path / "table3.md").read_text()
    # Convergence flags: every parameter and model flagged in most runs, within the maneuver.
    with open(tmp_path / "convergence.csv") as fh:
        conv = list(csv.DictReader(fh))
    assert [r["parameter"] for r in conv] == [*PAPER_TABLE3[0.2], "CZ model", "Cm model"]
    for r in conv:
        assert float(r["flagged"]) > 0.9 and 2.0 < float(r["flag_time_median"]) < 12.0, r
    assert "## Convergence flags" in (tmp_path / "table3.md").read_text()


def test_recursive_and_batch_corrected_errors_agree_at_the_end():
    """20% noise, the paper's Fig. 6(b) comparison: recursive (Eqs. 17-22) against batch
    (Eqs. 8-11 with the final residuals) corrected standard errors at the end of the maneuver.
    Criterion 2% at 50 lags (the Table 3 configuration; 250 runs measure at most 1.7%, these
    seeded 20 runs at most 1.2%); all lags within 6% (250 runs: at most 5.2%, C_m_alpha);
    50 lags within 15% of all lags."""
    from rls_uncertainty.simulation.montecarlo import run_level

    res = run_level(0.2, 20)
    s = res.summary()
    for name, row in s.items():
        assert row["se_corrected"] == pytest.approx(row["se_batch"], rel=0.02), name
        assert row["se_corrected_all"] == pytest.approx(row["se_batch_all"], rel=0.06), name
        assert row["se_corrected"] == pytest.approx(row["se_corrected_all"], rel=0.15), name


def _reference_flags(t, theta, se, ready, config):
    """The convergence criterion evaluated from scratch at every sample over the whole
    history (no buffer, no running maxima): window = samples from the newest one stamped at
    or before t - T up to now."""
    stamps = np.round(t * 1e9).astype(np.int64)
    s = np.where(ready[:, :, None], np.maximum(se, 0.0), np.nan)
    flags = np.zeros(theta.shape, bool)
    for k in range(len(t)):
        before = np.flatnonzero(stamps[: k + 1] <= stamps[k] - round(config.window * 1e9))
        if before.size == 0:
            continue
        a = before[-1]
        assert k - a + 1 <= config.capacity  # the monitor's buffer holds the window
        g = math.exp(min(config.max_se_rate * 1e-9 * (stamps[k] - stamps[a]), 30.0))
        c = np.minimum(s[k], 1e300) * config.band
        w_th, w_s = theta[a : k + 1], s[a : k + 1]
        flags[k] = (
            (w_th < theta[k] + c) & (-w_th < -theta[k] + c) & (w_s < s[k] * g) & (-w_s < -s[k] * (1.0 / g))
        ).all(axis=0)
    return flags


def test_monte_carlo_convergence_outputs_against_an_independent_recomputation(tmp_path):
    """Flag times, estimates at the flag, model flag times, cover times and false-convergence
    rates of a small 20% Monte Carlo, recomputed from the estimator histories."""
    from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions
    from rls_uncertainty.simulation.montecarlo import (
        BEST_FROM,
        MONTE_CARLO_CONVERGENCE,
        PARAMETERS,
        convergence_summary,
        level_inputs,
        run_level,
        write_outputs,
    )

    runs = 6
    res = run_level(0.2, runs)
    t, _, sizes, X, Z = level_inputs(0.2, runs)
    bank = EstimatorBank(sizes, EstimatorOptions(lags=50))
    hist = []
    for k in range(len(t)):
        bank.update(X[k], Z[k])
        hist.append((bank.theta_all(), bank.standard_errors_all("corrected"), bank.ready))
    theta, se, ready = (np.array(x) for x in zip(*hist, strict=True))
    flags = _reference_flags(t, theta, se, ready, MONTE_CARLO_CONVERGENCE)
    where = {"CZ_alpha": (0, 1), "CZ_delta_e": (0, 2), "Cm_alpha": (1, 1), "Cm_q": (1, 2), "Cm_delta_e": (1, 3)}
    assert list(where) == list(PARAMETERS)
    truth = np.array([T2_TRUE[p] for p in PARAMETERS])
    first = np.full((runs, 5), -1)
    for r in range(runs):
        for i, (m, c) in enumerate(where.values()):
            hit = np.flatnonzero(flags[:, 2 * r + m, c])
            first[r, i] = hit[0] if hit.size else -1
    assert (first > 0).mean() > 0.9  # the comparison below is about real flags
    np.testing.assert_array_equal(res.flag_time, np.where(first >= 0, t[first], np.inf))
    for r in range(runs):
        for i, (m, c) in enumerate(where.values()):
            if first[r, i] >= 0:
                assert res.flag_theta[r, i] == theta[first[r, i], 2 * r + m, c]
                assert res.flag_se[r, i] == se[first[r, i], 2 * r + m, c]
    model_first = np.full((runs, 2), np.inf)
    for r in range(runs):
        for m, size in enumerate((3, 4)):
            hit = np.flatnonzero(flags[:, 2 * r + m, :size].all(axis=1))
            model_first[r, m] = t[hit[0]] if hit.size else np.inf
    np.testing.assert_array_equal(res.model_flag_time, model_first)

    # Summary: cover time = first time from which on mean SE >= (1 - d) scatter, etc. The
    # ensemble statistics exist where every model of every run is ready (the C_Z models, with
    # fewer parameters, publish a sample before the C_m models).
    rows = {row["parameter"]: row for row in convergence_summary(res)}
    d = 2 / math.sqrt(2 * (runs - 1))
    all_ready = ready.all(axis=1)
    assert not np.array_equal(all_ready, ready[:, 0::2].all(axis=1))  # the case this test is about
    for i, (name, (m, c)) in enumerate(where.items()):
        x, s = theta[:, m::2, c], se[:, m::2, c]
        ratio = s.mean(axis=1) / x.std(axis=1, ddof=1)
        ok = (ratio >= 1 - d) & all_ready  # NaN (not ready) is not ok
        k0 = next((k for k in range(len(t)) if ok[k:].all()), None)
        row = rows[name]
        assert row["cover_time"] == (t[k0] if k0 is not None else math.inf)
        ft = res.flag_time[:, i]
        assert row["flag_time_median"] == np.median(ft)
        assert row["flagged"] == np.isfinite(ft).mean()
        hit = [r for r in range(runs) if first[r, i] >= 0]
        outside = [abs(x[first[r, i], r] - truth[i]) > 2 * s[first[r, i], r] for r in hit]
        assert row["false_convergence"] == pytest.approx(np.mean(outside))
        off_mean = [abs(x[first[r, i], r] - x[first[r, i]].mean()) > 2 * s[first[r, i], r] for r in hit]
        assert row["false_vs_mean"] == pytest.approx(np.mean(off_mean))
        assert row["truth_outside_end"] == pytest.approx(np.mean(np.abs(x[-1] - truth[i]) > 2 * s[-1]))
        late = (t >= BEST_FROM) & all_ready
        outside_late = np.abs(x[late] - truth[i]) > 2 * s[late]
        assert row["truth_outside_min"] == pytest.approx(np.min(np.mean(outside_late, axis=1)))
    column = [c for _, c in where.values()]
    for m, model in enumerate(("CZ model", "Cm model")):
        params = [i for i, (mm, _) in enumerate(where.values()) if mm == m]

        def any_outside(k, r, m=m, params=params):
            j = 2 * r + m
            return any(abs(theta[k, j, column[i]] - truth[i]) > 2 * se[k, j, column[i]] for i in params)

        hit = [r for r in range(runs) if np.isfinite(model_first[r, m])]
        outside = [any_outside(int(np.searchsorted(t, model_first[r, m])), r) for r in hit]
        assert rows[model]["false_convergence"] == pytest.approx(np.mean(outside))
        late = np.flatnonzero((t >= BEST_FROM) & all_ready)
        best = min(np.mean([any_outside(k, r) for r in range(runs)]) for k in late)
        assert rows[model]["truth_outside_min"] == pytest.approx(best)
        assert rows[model]["flag_time_median"] == np.median(model_first[:, m])
    paths = write_outputs([res], tmp_path, figures=False)
    with open(paths["convergence"]) as fh:
        written = list(csv.DictReader(fh))
    assert [r["parameter"] for r in written] == [*PARAMETERS, "CZ model", "Cm model"]
    for r in written[:5]:
        assert float(r["flag_time_median"]) == pytest.approx(rows[r["parameter"]]["flag_time_median"], rel=1e-5)
        assert float(r["false_convergence"]) == pytest.approx(rows[r["parameter"]]["false_convergence"], abs=1e-6)


# --------------------------------------------------------------- turbulence and noise variants
def _gusty_config(rate):
    from dataclasses import replace

    from rls_uncertainty.simulation.t2 import SimulationConfig

    return replace(SimulationConfig(), rate=rate)


def test_turbulent_response_satisfies_the_equations_with_the_aerodynamic_alpha():
    """Noise-free, 1 kHz, a 1 m/s Dryden gust and its pitch gust: with alpha_a the recorded
    (vane) alpha and alpha = alpha_a - w_g/V the inertial one, the record integrates Eq. 25a
    with alpha_a and the aerodynamic pitch rate q - q_g in the aerodynamics (trapezoid over the
    1 kHz grid, within 1e-4 of each signal's RMS; with the inertial alpha instead, q is off by
    70 times its RMS; with the gyro's q instead of q - q_g, by more than the tolerance a
    hundredfold) and a_z is Eq. 25b with alpha_a, to rounding."""
    from scipy.integrate import cumulative_trapezoid

    from rls_uncertainty.simulation.t2 import G0, gust_velocity
    from rls_uncertainty.simulation.turbulence import DrydenVertical, pitch_gust

    cfg = _gusty_config(1000.0)
    w = gust_velocity(DrydenVertical(1.0, 290.0), np.random.default_rng(1), cfg)
    r = simulate_short_period(cfg, gust=w)
    np.testing.assert_array_equal(r.gust, w)
    np.testing.assert_array_equal(r.pitch_gust, pitch_gust(w, 1e-3, r.aircraft.b, cfg.airspeed))
    ac, tv, V = r.aircraft, cfg.true, cfg.airspeed
    qS = cfg.qbar * ac.S
    alpha_a = r.alpha - cfg.alpha_trim
    alpha_i = alpha_a - r.gust / V
    assert np.std(r.gust / V) > np.std(alpha_i) / 2  # the gust is a large part of what the vane reads

    def integrated(rate):
        return cumulative_trapezoid(rate, r.t, initial=0.0)

    alpha_dot = qS / (ac.mass * V) * (tv["CZ_alpha"] * alpha_a + tv["CZ_delta_e"] * r.delta_e) + r.q
    assert np.max(np.abs(alpha_i - alpha_i[0] - integrated(alpha_dot))) < 1e-4 * np.std(alpha_i)

    def q_dot(alpha, q_a):
        return qS * ac.cbar / ac.Iyy * (tv["Cm_alpha"] * alpha + ac.cbar / (2 * V) * tv["Cm_q"] * q_a
                                        + tv["Cm_delta_e"] * r.delta_e)

    q_a = r.q - r.pitch_gust
    assert np.max(np.abs(r.q - r.q[0] - integrated(q_dot(alpha_a, q_a)))) < 1e-4 * np.std(r.q)
    assert np.max(np.abs(r.q - r.q[0] - integrated(q_dot(alpha_i, q_a)))) > 10 * np.std(r.q)
    assert np.max(np.abs(r.q - r.q[0] - integrated(q_dot(alpha_a, r.q)))) > 1e-2 * np.std(r.q)
    az = qS / ac.mass * (tv["CZ_alpha"] * alpha_a + tv["CZ_delta_e"] * r.delta_e)
    np.testing.assert_allclose(r.az + G0 * np.cos(cfg.alpha_trim), az, rtol=0, atol=1e-12)


def test_calm_air_is_the_existing_simulation_exactly():
    """A gust of intensity 0 (or none) gives the calm-air simulation bit for bit: the record
    (``add_noise(simulate_short_period(), ...)`` with the seed's generator) and the sensor
    streams, also of a campaign maneuver (its seed from ``campaign_seeds``)."""
    from rls_uncertainty.simulation.t2 import (
        campaign_seeds,
        simulate_campaign,
        simulate_maneuver,
        simulate_sensor_streams,
    )
    from rls_uncertainty.simulation.turbulence import DrydenVertical

    calm = DrydenVertical(0.0, 290.0)
    reference = add_noise(simulate_short_period(), 0.2, np.random.default_rng(7))
    for gust in (None, calm):
        rec = simulate_maneuver(0.2, 7, gust=gust)
        for name, x in reference.signals().items():
            np.testing.assert_array_equal(getattr(rec, name), x)
    expected = simulate_sensor_streams(0.2, campaign_seeds(3, 2)[1])
    for got in (simulate_sensor_streams(0.2, campaign_seeds(3, 2)[1], gust=calm),
                list(simulate_campaign(2, calm, seed=3))[1]):
        for kind in ("imu", "airspeed", "dynamic_pressure", "control_surfaces", "thrust"):
            for a, b in zip(getattr(got, kind), getattr(expected, kind), strict=True):
                np.testing.assert_array_equal(a, b)


def test_campaign_maneuvers_are_deterministic_per_seed_and_differ_from_each_other():
    from rls_uncertainty.simulation.t2 import campaign_seeds, simulate_campaign, simulate_maneuver
    from rls_uncertainty.simulation.turbulence import DrydenVertical

    gust = DrydenVertical(0.8, 290.0)
    a = list(simulate_campaign(3, gust, seed=11))
    b = list(simulate_campaign(2, gust, seed=11))  # maneuver i does not depend on the campaign's length
    for x, y in zip(a[:2], b, strict=True):
        np.testing.assert_array_equal(x.imu[1], y.imu[1])
        np.testing.assert_array_equal(x.airspeed[1], y.airspeed[1])
    alphas = [np.arctan2(-m.airspeed[1][:, 2], m.airspeed[1][:, 0]) for m in a]
    assert len({round(float(np.std(x)), 9) for x in alphas}) == 3
    other = next(simulate_campaign(1, gust, seed=12))
    assert not np.array_equal(other.imu[1], a[0].imu[1])
    seed = campaign_seeds(11, 1)[0]  # a seed object used twice gives the same maneuver twice
    first, second = simulate_maneuver(0.2, seed, gust=gust), simulate_maneuver(0.2, seed, gust=gust)
    np.testing.assert_array_equal(first.alpha, second.alpha)
    np.testing.assert_array_equal(first.gust, second.gust)


def test_gust_does_not_change_the_noise_sequences_or_their_scale():
    """The sensor noise (record minus its noise-free signals) is the same in calm air and in
    turbulence: same generator, same calm-air scale (the gust belongs to the air, not to the
    sensors)."""
    from rls_uncertainty.simulation.t2 import simulate_maneuver
    from rls_uncertainty.simulation.turbulence import DrydenVertical

    calm = simulate_maneuver(0.2, 5)
    rough = simulate_maneuver(0.2, 5, gust=DrydenVertical(1.5, 290.0))
    assert rough.gust is not None and calm.gust is None
    assert rough.noise_scale == calm.noise_scale
    for name in ("delta_e", "alpha", "q", "az"):
        noise = getattr(calm, name) - calm.noise_free[name]
        np.testing.assert_allclose(getattr(rough, name) - rough.noise_free[name], noise, rtol=0,
                                   atol=1e-12 * max(1.0, np.abs(calm.noise_free[name]).max()))
    assert np.std(rough.noise_free["alpha"]) > 1.2 * np.std(calm.noise_free["alpha"])
    np.testing.assert_array_equal(rough.delta_e, calm.delta_e)  # the gust does not move the elevator


def test_every_stream_sees_the_same_gust():
    """Sensor streams in turbulence with negligible noise (SNR 1e12, no band-limited noise):
    the air data's alpha and the IMU's q and a_z are the noise-free maneuver of the same seed
    and gust sampled at each stream's rate and offset."""
    from dataclasses import replace

    from rls_uncertainty.simulation.t2 import SimulationConfig, simulate_maneuver, simulate_sensor_streams
    from rls_uncertainty.simulation.turbulence import DrydenVertical

    gust = DrydenVertical(1.0, 290.0)
    quiet = replace(SimulationConfig(), snr=dict.fromkeys(("delta_e", "alpha", "q", "az"), 1e12))
    st = simulate_sensor_streams(0.0, 9, cfg=quiet, gust=gust)
    air = simulate_maneuver(0.0, 9, gust=gust, cfg=replace(quiet, rate=50.0, sample_offset=0.004))
    imu = simulate_maneuver(0.0, 9, gust=gust, cfg=replace(quiet, rate=200.0))
    vel = st.airspeed[1]
    np.testing.assert_allclose(np.arctan2(-vel[:, 2], vel[:, 0]), air.noise_free["alpha"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(-st.imu[1][:, 1], imu.noise_free["q"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(-st.imu[1][:, 5], imu.noise_free["az"], rtol=0, atol=1e-9)
    calm = simulate_maneuver(0.0, 9, cfg=replace(quiet, rate=200.0))
    assert np.std(imu.noise_free["az"] - calm.noise_free["az"]) > 0.1 * np.std(calm.noise_free["az"])


def test_band_limited_noise_on_the_responses_only_leaves_the_elevator_white():
    """``band_limited_on=RESPONSES`` (the default): the same random numbers as the noise on
    all four signals, so alpha, q and a_z are those of that variant exactly and the elevator is
    that of band level 0."""
    from rls_uncertainty.simulation.t2 import BAND_LIMITED_ON, RESPONSES, SIGNALS

    rec = simulate_short_period()
    four = add_noise(rec, 0.2, np.random.default_rng(3), band_limited_on=SIGNALS)
    variant = add_noise(rec, 0.2, np.random.default_rng(3), band_limited_on=RESPONSES)
    white = add_noise(rec, 0.0, np.random.default_rng(3))
    for name in RESPONSES:
        np.testing.assert_array_equal(getattr(variant, name), getattr(four, name))
    np.testing.assert_array_equal(variant.delta_e, white.delta_e)
    assert not np.array_equal(variant.delta_e, four.delta_e)
    assert BAND_LIMITED_ON == RESPONSES
    default = add_noise(rec, 0.2, np.random.default_rng(3))
    for name in SIGNALS:
        np.testing.assert_array_equal(getattr(default, name), getattr(variant, name))


def test_band_limited_on_refuses_unknown_signals():
    from rls_uncertainty.errors import ConfigError

    rec = simulate_short_period()
    for bad in (("alpha", "beta"), "alpha"):
        with pytest.raises(ConfigError, match="band_limited_on"):
            add_noise(rec, 0.2, np.random.default_rng(0), band_limited_on=bad)


def test_gust_on_the_wrong_grid_is_refused():
    from rls_uncertainty.errors import ConfigError

    with pytest.raises(ConfigError, match="integration grid"):
        simulate_short_period(gust=np.zeros(100))
    bad = np.zeros(12000)
    bad[5] = np.nan
    with pytest.raises(ConfigError, match="finite"):
        simulate_short_period(gust=bad)


def test_without_the_pitch_gust_the_gust_acts_on_alpha_alone_as_before():
    """``pitch_gust=False`` is the vertical gust on alpha alone, computed as before bit for bit:
    the calm-air response plus the response of Eq. 25 to the gust angle w_g / V alone, each one
    ``lsim`` on the integration grid, sampled. The sensor streams of a campaign maneuver
    without it differ from those with it only where the pitch gust acts (the gyro, the
    accelerometers and the vane), never in the elevator."""
    from scipy import signal

    from rls_uncertainty.simulation import t2
    from rls_uncertainty.simulation.turbulence import DrydenVertical

    cfg = _gusty_config(50.0)
    w = t2.gust_velocity(DrydenVertical(2.3, 389.0), np.random.default_rng(4), cfg)
    got = simulate_short_period(cfg, gust=w, pitch_gust=False)
    assert got.pitch_gust is None
    ac = got.aircraft
    A, _, C, _ = t2.state_space(cfg, ac)
    Bg, Dg = t2.gust_input(cfg, ac)
    t_fine = np.arange(12_000) / cfg.fine_rate
    _, y_gust, _ = signal.lsim((A, Bg, C, Dg), w / cfg.airspeed, t_fine)
    calm = simulate_short_period(cfg)
    idx = np.arange(0, 12_000, 20)
    for i, name in enumerate(t2.RESPONSES):
        np.testing.assert_array_equal(getattr(got, name), calm.noise_free[name] + y_gust[idx, i])
    np.testing.assert_array_equal(got.delta_e, calm.delta_e)
    assert got.noise_scale == calm.noise_scale

    gust, seed = DrydenVertical(2.3, 389.0), t2.campaign_seeds(2010, 1)[0]
    off = t2.simulate_sensor_streams(0.2, seed, gust=gust, pitch_gust=False)
    on = t2.simulate_sensor_streams(0.2, seed, gust=gust)
    np.testing.assert_array_equal(on.control_surfaces[1], off.control_surfaces[1])
    for kind, column in (("imu", 1), ("imu", 5), ("airspeed", 2)):
        assert np.std(getattr(on, kind)[1][:, column] - getattr(off, kind)[1][:, column]) > 0
