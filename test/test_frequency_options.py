"""FrequencyOptions: the default grid is SIDPAC's real-time demo grid, and every invalid value is
refused once with a ConfigError that names the option."""

from __future__ import annotations

import numpy as np
import pytest

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.frequency import FrequencyBank, FrequencyOptions


def test_the_default_grid_is_0_1_to_1_5_hz_every_0_04_hz():
    f = FrequencyOptions(rate_hz=50.0).frequencies()
    # SIDPAC's rtpid_demo: f = [0.1:.04:1.5]' (36 points, both ends included).
    assert f.size == 36
    np.testing.assert_allclose(f, 0.1 + 0.04 * np.arange(36), rtol=0, atol=1e-15)
    assert f[-1] == pytest.approx(1.5, abs=1e-12)


def test_a_grid_end_that_is_not_a_step_away_is_not_reached():
    f = FrequencyOptions(rate_hz=50.0, f_min=0.2, f_max=1.0, f_step=0.3).frequencies()
    np.testing.assert_allclose(f, [0.2, 0.5, 0.8])


@pytest.mark.parametrize(
    ("change", "option"),
    [
        (dict(rate_hz=0.0), "rate_hz"),
        (dict(rate_hz=float("nan")), "rate_hz"),
        (dict(rate_hz="50"), "rate_hz"),
        (dict(f_min=0.0), "f_min"),
        (dict(f_min=True), "f_min"),
        (dict(f_max=0.05), "f_max"),
        (dict(f_step=0.0), "f_step"),
        (dict(f_step=1e-5), "f_step"),  # 140001 frequencies
        (dict(f_max=30.0), "f_max"),  # beyond the Nyquist frequency of 50 Hz
        (dict(trim_samples=0), "trim_samples"),
        (dict(n_lags=-1), "n_lags"),
        (dict(n_lags=2.5), "n_lags"),
        (dict(every=0), "every"),
        (dict(dof_correction="yes"), "dof_correction"),
        (dict(init_condition=1.0), "init_condition"),
    ],
)
def test_an_invalid_option_is_refused_naming_it(change, option):
    with pytest.raises(ConfigError, match=rf"frequency\.{option}"):
        FrequencyOptions(**{"rate_hz": 50.0, **change})


def test_a_grid_with_no_more_frequencies_than_parameters_is_refused():
    options = FrequencyOptions(rate_hz=50.0, f_min=0.5, f_max=0.6, f_step=0.04)  # 3 frequencies
    FrequencyBank((2,), options)
    with pytest.raises(ConfigError, match="f_step"):
        FrequencyBank((3,), options)
