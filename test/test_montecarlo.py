"""montecarlo.py's noise variant and executors: the band-limited noise on all four measured
signals or on the responses only (the default, docs/validation.md), the same random draws in
both; the levels run on any executor with the same numbers. No ROS."""

from __future__ import annotations

import numpy as np

from rls_uncertainty import cli
from rls_uncertainty.executors import LocalProcesses
from rls_uncertainty.montecarlo import level_inputs, run_level, run_table3
from rls_uncertainty.simulation import BAND_LIMITED_ON, RESPONSES, SIGNALS


def test_the_variants_differ_in_the_measured_elevator_only():
    """C_Z's regressors are (1, alpha, delta_e), C_m's (1, alpha, q_hat, delta_e); the outputs
    come from a_z and the differentiated q. Only the elevator columns may differ."""
    _t, _r, _s, X_all, Z_all = level_inputs(0.2, 3, band_limited_on=SIGNALS)
    _t, _r, _s, X_resp, Z_resp = level_inputs(0.2, 3, band_limited_on=RESPONSES)
    np.testing.assert_array_equal(Z_all, Z_resp)
    elevator = np.zeros(X_all.shape[1:], dtype=bool)
    elevator[0::2, 2] = elevator[1::2, 3] = True  # C_Z's column 2, C_m's column 3
    np.testing.assert_array_equal(X_all[:, ~elevator], X_resp[:, ~elevator])
    assert np.all(np.any(X_all[:, elevator] != X_resp[:, elevator], axis=0))
    _t, _r, _s, X0_all, _z = level_inputs(0.0, 2, band_limited_on=SIGNALS)
    _t, _r, _s, X0_resp, _z = level_inputs(0.0, 2, band_limited_on=RESPONSES)
    np.testing.assert_array_equal(X0_all, X0_resp)  # no band-limited noise: the same runs


def test_the_default_is_the_responses_and_the_result_says_which():
    assert BAND_LIMITED_ON == RESPONSES
    _t, _r, _s, X_default, _z = level_inputs(0.1, 2)
    _t, _r, _s, X_resp, _z = level_inputs(0.1, 2, band_limited_on=RESPONSES)
    np.testing.assert_array_equal(X_default, X_resp)
    assert run_level(0.1, 2, band_limited_on=SIGNALS).band_limited_on == SIGNALS


def test_levels_on_an_executor_are_the_levels_run_here(tmp_path, capsys):
    direct = [run_level(lv, 3, band_limited_on=SIGNALS) for lv in (0.05, 0.2)]
    pooled = run_table3(3, (0.05, 0.2), executor=LocalProcesses(2), band_limited_on=SIGNALS, progress=lambda _s: None)
    for a, b in zip(direct, pooled, strict=True):
        assert a.level == b.level and a.summary() == b.summary()
    assert cli.main(["montecarlo", "--runs", "3", "--levels", "20", "--noise-on", "all", "--jobs", "1",
                     "--no-figures", "--out", str(tmp_path / "mc")]) == 0
    assert "Band-limited noise on delta_e, alpha, q, az" in (tmp_path / "mc" / "table3.md").read_text()
    assert "band-limited noise on all" in capsys.readouterr().out
