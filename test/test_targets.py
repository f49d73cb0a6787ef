"""Target percent errors, the time-left forecast and the verdict (datapath.targets), against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rls_uncertainty.datapath.targets import (
    DONE,
    NEEDS_MORE,
    NOT_IDENTIFIABLE,
    TargetOptions,
    TargetTracker,
    percent_errors,
    targets_of,
    time_left,
)
from rls_uncertainty.errors import ConfigError

RATE = 50.0


def feed(tracker: TargetTracker, times: np.ndarray, estimates: np.ndarray, ses: np.ndarray,
         converged: bool = True) -> None:
    for t, est, se in zip(times, estimates, ses, strict=True):
        tracker.update(float(t), est, se, np.full(len(est), converged))


@pytest.mark.parametrize("a", [3.0, 40.0])
@pytest.mark.parametrize("window", [0.5, 2.0])
def test_se_falling_as_one_over_root_information_gives_the_exact_time_left(a: float, window: float) -> None:
    # SE = 1/sqrt(a t), estimate 0.4: pe(t) = 250/sqrt(a t); the target g is reached at
    # t* = (250/g)^2 / a, so the time left at t is t* - t.
    estimate, target = 0.4, 5.0
    t_star = (100.0 / (estimate * target)) ** 2 / a
    times = np.arange(1, int(0.8 * t_star * RATE)) / RATE
    se = 1.0 / np.sqrt(a * times)
    tracker = TargetTracker(["Cm_q", "Cm_alpha"], TargetOptions(targets=(f"Cm_q={target}",), window=window))
    checked = 0
    for t, s in zip(times, se, strict=True):
        progress = tracker.update(float(t), [estimate, -1.0], [s, s], [False, False])
        if t >= window:
            assert progress[0].time_left == pytest.approx(t_star - t, rel=1e-9)
            assert progress[0].percent_error == pytest.approx(100 * s / estimate, rel=1e-12)
            checked += 1
    assert checked > 10
    assert math.isnan(tracker.progress[1].time_left)  # no target: no forecast
    v = tracker.verdict()
    assert v.state == NEEDS_MORE and v.time_left == pytest.approx(t_star - times[-1], rel=1e-9)


def test_time_left_is_the_closed_form() -> None:
    pe, g, info, before, w = 14.0, 10.0, 50.0, 30.0, 2.0
    # information grows 10/s; needed: 50 * 1.96 = 98, i.e. 48 more: 4.8 s
    assert time_left(pe, g, info, before, w) == pytest.approx(w * ((pe / g) ** 2 - 1) * info / (info - before))
    assert time_left(pe, g, info, before, w) == pytest.approx((info * (pe / g) ** 2 - info) / ((info - before) / w))
    assert time_left(9.0, g, info, before, w) == 0.0
    assert math.isnan(time_left(pe, g, info, info, w))  # no growth
    assert math.isnan(time_left(pe, g, info, info + 1, w))  # information falling
    assert math.isnan(time_left(math.nan, g, info, before, w))


def test_percent_errors() -> None:
    pe = percent_errors(np.array([0.5, -2.0, 0.0, np.nan]), np.array([0.05, 0.1, 1.0, 1.0]))
    np.testing.assert_allclose(pe[:2], [10.0, 5.0])
    assert np.isnan(pe[2:]).all()


def test_done_only_when_met_and_converged() -> None:
    tracker = TargetTracker(["a", "b"], targets_of({"a": 10.0, "b": 20.0}))
    times = np.arange(1, 200) / RATE
    est = np.tile([1.0, 2.0], (times.size, 1))
    se = np.tile([0.05, 0.2], (times.size, 1))  # 5 % and 10 %: both met
    feed(tracker, times, est, se, converged=False)
    v = tracker.verdict()
    assert v.state == NEEDS_MORE and math.isnan(v.time_left) and "a, b" in v.reason
    feed(tracker, times[-1:] + 0.02, est[-1:], se[-1:], converged=True)
    assert tracker.verdict().state == DONE
    assert all(p.met and p.time_left == 0.0 for p in tracker.progress)


def test_information_not_growing_is_not_identifiable_with_the_reason() -> None:
    tracker = TargetTracker(["CZ_alpha", "Cm_q"], targets_of({"CZ_alpha": 5.0, "Cm_q": 10.0}))
    times = np.arange(1, 300) / RATE
    est = np.tile([-4.0, -10.0], (times.size, 1))
    se = np.column_stack([0.1 / np.sqrt(times), np.full(times.size, 3.0)])  # Cm_q stuck at 30 %
    feed(tracker, times, est, se)
    v = tracker.verdict()
    assert v.state == NOT_IDENTIFIABLE
    assert "Cm_q" in v.reason and "information not growing" in v.reason


def test_first_sample_needs_more_not_unidentifiable() -> None:
    tracker = TargetTracker(["a"], targets_of({"a": 1.0}))
    tracker.update(0.0, [1.0], [0.5], [False])
    v = tracker.verdict()
    assert v.state == NEEDS_MORE and math.isnan(v.time_left)


def test_reset_forgets_the_history() -> None:
    tracker = TargetTracker(["a"], targets_of({"a": 1.0}))
    feed(tracker, np.arange(1, 200) / RATE, np.ones((199, 1)), 1 / np.sqrt(np.arange(1, 200)[:, None]))
    assert math.isfinite(tracker.progress[0].time_left)
    tracker.reset()
    assert tracker.progress == []
    tracker.update(5.0, [1.0], [0.5], [False])
    assert math.isnan(tracker.progress[0].time_left)


@pytest.mark.parametrize("entry", ["Cm_q", "Cm_q=", "=5", "Cm_q=-1", "Cm_q=nan", "Cm_q=x", "Cm_q=inf", "Cm_q=1_0",
                                   "Cm_q=\uff11\uff10", "Cm_q=\u0661", "Cm_q=0x10"])
def test_bad_target_entries_are_refused(entry: str) -> None:
    with pytest.raises(ConfigError, match=r"targets\.percent"):
        TargetOptions(targets=(entry,))


@pytest.mark.parametrize(("entry", "percent"), [("Cm_q=10", 10.0), (" Cm_q = 2.5 ", 2.5), ("Cm_q=.5", 0.5),
                                                 ("Cm_q=1e1", 10.0), ("Cm_q=+3.", 3.0)])
def test_decimal_targets_are_taken(entry: str, percent: float) -> None:
    assert TargetOptions(targets=(entry,)).percent() == {"Cm_q": percent}


def test_twice_and_unknown_names_and_bad_window_are_refused() -> None:
    with pytest.raises(ConfigError, match="twice"):
        TargetOptions(targets=("a=1", "a=2"))
    with pytest.raises(ConfigError, match="Cm_x"):
        TargetTracker(["Cm_q"], targets_of({"Cm_x": 3.0}))
    with pytest.raises(ConfigError, match=r"targets\.window"):
        TargetOptions(window=0.0)


def test_the_pipeline_judges_the_test_point_in_its_diagnostics():
    """targets.percent in the data path: the tracker sees each sample's published estimates,
    corrected SEs and flags in the models' parameter order (a tracker fed here from the
    outputs gives the same progress), and /diagnostics' model report carries each target and
    the verdict; a loose target on the bundled maneuver is done, an impossible one is not."""
    from rls_uncertainty.offline.bags import read_inputs
    from rls_uncertainty.offline.replay import run_pipeline
    from rls_uncertainty.settings.parameters import pipeline_config
    from rls_uncertainty.settings.sources import load_parameters_file

    from source_tree import ROOT

    messages = read_inputs(ROOT / "bags" / "t2_maneuver")[0]
    params = load_parameters_file("t2")
    loose = run_pipeline(messages, pipeline_config({**params, "targets.percent": "Cm_q=1000,CZ_alpha=1000"}))
    pipe = loose.pipeline
    names = [p for n in pipe.parameter_names for p in n]
    mine = TargetTracker(names, TargetOptions(targets="Cm_q=1000,CZ_alpha=1000"))
    for out in loose.outputs:
        real = np.arange(out.theta.shape[1]) < np.array(pipe.sizes)[:, None]
        mine.update(out.time, out.theta[real], out.se[real], out.converged[real])
    assert [(p.name, p.percent_error, p.time_left) for p in mine.progress] == \
        [(p.name, p.percent_error, p.time_left) for p in pipe.targets.progress]
    report = pipe.model_report([m.output for m in pipe.models].index("Cm"))
    assert report["target.Cm_q"].startswith("met") and report["verdict"] == "done"
    tight = run_pipeline(messages, pipeline_config({**params, "targets.percent": "Cm_q=0.01"}), record=False)
    report = tight.pipeline.model_report([m.output for m in tight.pipeline.models].index("Cm"))
    assert "0.01 %" in report["target.Cm_q"] and report["verdict"].startswith(("needs more", "not identifiable"))
    with pytest.raises(ConfigError, match="Cl_p"):
        pipeline_config({**params, "targets.percent": "Cl_p=5"})


def test_a_target_far_below_the_percent_error_is_no_forecast_never_an_overflow() -> None:
    # (pe/g)^2 beyond floating point: no forecast (a Python float's ** raised OverflowError, which
    # stopped the pipeline with it).
    assert math.isnan(time_left(10.0, 1e-300, 2.0, 1.0, 1.0))
    assert time_left(10.0, 5.0, 2.0, 1.0, 1.0) == pytest.approx(1.0 * (4.0 - 1.0) * 2.0 / 1.0)
    tracker = TargetTracker(["Cm_q"], TargetOptions(targets="Cm_q=1e-300"))
    times = np.arange(1, 300) / RATE
    feed(tracker, times, np.full((times.size, 1), -10.0), (1.0 / np.sqrt(times))[:, None])
    [p] = tracker.progress
    assert math.isnan(p.time_left) and "too far below the percent error" in p.reason
    v = tracker.verdict()
    assert v.state == NOT_IDENTIFIABLE and "Cm_q" in v.reason and "too far below" in v.reason
