"""Nothing is published before it means something: the publication rule in the replay's files,
no zero or rounding-level standard error in any published row (both methods, the bundled bag
and a Monte Carlo), the frequency domain's negative sandwich withheld and counted, and the
elevator that never moved, judged against its sensor noise. Each figure is recomputed here
from what the files and the estimators hold."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from rls_uncertainty import cli
from rls_uncertainty.datapath.guard import SE_FLOOR
from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions
from rls_uncertainty.frequency import FrequencyBank, FrequencyOptions
from rls_uncertainty.frequency import bank as frequency_bank
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.replay import replay, run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config
from rls_uncertainty.simulation.montecarlo import level_inputs

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_the_replay_writes_no_row_before_the_rule_and_no_rounding_level_standard_error(tmp_path):
    """estimates.csv and estimates_frequency.csv of the bundled bag (both methods): each model's
    first row is the sample at which n + 2 x 50 samples were used (n with the bias: C_Z 3, C_m 4;
    counted from the pipeline's own sample indices), and no standard error of any row is at most
    1e3 eps |estimate| (so none is zero)."""
    params = {**load_parameters_file("t2"), "estimator.method": "both"}
    replay(BUNDLED, params, tmp_path / "r", progress=False, plots=False)
    result = run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(params))
    stamp = {o.index: f"{o.stamp_ns // 10**9}.{o.stamp_ns % 10**9:09d}" for o in result.outputs}
    for name, n in (("CZ", 3), ("Cm", 4)):
        for file in ("estimates.csv", "estimates_frequency.csv"):
            rows = [r for r in _rows(tmp_path / "r" / file) if r["model"] == name]
            assert rows[0]["time"] == stamp[n + 100], (file, name)
            for r in rows:
                estimate = abs(float(r["estimate"]))
                for key in ("std_error", "std_error_conventional"):
                    assert float(r[key]) > SE_FLOOR * estimate, (file, r)


@pytest.mark.parametrize("level", [0.0, 0.2])
def test_no_zero_or_rounding_level_standard_error_in_a_monte_carlo_both_methods(level):
    """20 Table 3 runs (seed 2016, the runs of montecarlo) through both banks sample by sample:
    every published standard error of both kinds is above 1e3 eps |estimate|, both banks first
    publish at n + 2 L, and every model publishes by the end."""
    t, _red, sizes, X, Z = level_inputs(level, 20)
    td = EstimatorBank(sizes, EstimatorOptions(lags=50))
    fd = FrequencyBank([s - 1 for s in sizes], FrequencyOptions(rate_hz=50.0, f_min=0.2, f_max=2.2))
    first_td, first_fd = np.full(len(sizes), -1), np.full(len(sizes), -1)
    for k in range(t.size):
        td.update(X[k], Z[k])
        fd.update(X[k, :, 1:], Z[k])
        for bank, first in ((td, first_td), (fd, first_fd)):
            ready = bank.ready
            theta = bank.theta_all()
            for kind in ("corrected", "conventional"):
                se = bank.standard_errors_all(kind)
                ok = se[ready] > SE_FLOOR * np.abs(theta[ready])
                assert ok[np.isfinite(se[ready])].all() and np.isfinite(theta[ready]).any(axis=1).all()
            first[(first < 0) & ready] = k + 1
    assert (first_td == np.array(sizes) + 100).all()
    assert (first_fd >= np.array(sizes) + 100).all() and (first_fd >= 0).all()


def test_a_negative_sandwich_is_withheld_and_counted_not_published_as_its_repair(monkeypatch):
    """The frequency domain's corrected covariance with a negative variance (here the middle
    matrix of F7-F8 made negative definite) publishes nothing at that evaluation: the model is
    solved but not ready, withheld, the evaluation counted in repairs; the conventional one
    stays available to the caller."""
    _t, _red, sizes, X, Z = level_inputs(0.2, 1)
    options = FrequencyOptions(rate_hz=50.0, f_min=0.2, f_max=2.2)
    plain, broken = FrequencyBank([s - 1 for s in sizes], options), FrequencyBank([s - 1 for s in sizes], options)
    for k in range(300):
        plain.update(X[k, :, 1:], Z[k])
    assert plain.ready.all() and not plain.withheld.any()  # evaluated here, before the patch
    real_middle = frequency_bank.middle
    monkeypatch.setattr(frequency_bank, "middle", lambda *a: -real_middle(*a))
    for k in range(300):
        broken.update(X[k, :, 1:], Z[k])
    assert broken.solved.all() and not broken.ready.any() and broken.withheld.all() and broken.repairs == 1
    assert np.isnan(broken.standard_errors_all()).all() and np.isnan(broken.theta_all()).all()
    np.testing.assert_array_equal(broken.theta(0), plain.theta(0))
    assert (np.diag(broken.covariance(0)) < 0).all()


def _flags(bag: Path) -> dict[str, dict[str, object]]:
    """Per method, the elevator parameters' flags at any sample and identifiability at the end."""
    params = {**load_parameters_file("t2"), "estimator.method": "both"}
    result = run_pipeline(read_inputs(bag)[0], pipeline_config(params))
    pipe = result.pipeline
    td = np.array([o.converged[:, [2, 3]].diagonal() for o in result.outputs])  # CZ_delta_e (0, 2), Cm_delta_e (1, 3)
    fd = np.array([o.frequency.converged[:, [1, 2]].diagonal() for o in result.outputs if o.frequency is not None])
    quality = pipe.identifiability
    problems = [p for j in range(2) for p in quality.problems(j)]
    states = {(s.method, s.parameter): s.text for s in result.states}
    return {"time": td.any(axis=0), "frequency": fd.any(axis=0), "identifiable": quality.identifiable[[0, 1], [2, 3]],
            "kinds": {p.kind for p in problems}, "states": states}


@pytest.mark.parametrize("amplitude", [0.0, 0.3])
def test_an_elevator_that_never_moved_is_not_identifiable_in_both_methods(tmp_path, amplitude):
    """make-bag --campaign 6 --gust-intensity severe --pitch-gust off --input-amplitude F (the
    vertical gust on alpha alone: with the pitch gust C_m's fit may fail first): at F = 0 the elevator
    shows only its sensor noise (2.3e-4 rad, over the 1e-4 rad floor): C_Z_delta_e and
    C_m_delta_e are not identifiable, the reason its noise, and never flagged in either method,
    in all 6 maneuvers; at F = 0.3 both are identifiable and flagged."""
    out = tmp_path / "c"
    assert cli.main(["make-bag", "--campaign", "6", "--gust-intensity", "severe", "--pitch-gust", "off",
                     "--input-amplitude", f"{amplitude:g}", "--out", str(out)]) == 0
    for bag in sorted(p for p in out.iterdir() if p.is_dir()):
        f = _flags(bag)
        if amplitude == 0.0:
            assert not f["time"].any() and not f["frequency"].any() and not f["identifiable"].any(), bag.name
            assert f["kinds"] == {"noise"}
            for method, name in (("time", "CZ_delta_e"), ("frequency", "Cm_delta_e")):
                text = f["states"][(method, name)]
                assert text.startswith("held back: not identifiable: delta_e moves no more than its sensor noise")
        else:
            assert f["time"].all() and f["frequency"].all() and f["identifiable"].all(), bag.name
            assert f["kinds"] == set()
