"""Eq. 23 surface mixing (rls_uncertainty.aero.surface_mixing): JointState names and positions to
the deflections of Eq. 2, the reasons a name list cannot be mixed, and the bounded layout cache."""

import pytest

from rls_uncertainty.aero.surface_mixing import JointLayout, SurfaceMixer, SurfaceMixing
from rls_uncertainty.errors import Refused


def test_aileron_mixing_is_eq_23():
    mixer = SurfaceMixer(SurfaceMixing(aileron_right=("ar1", "ar2"), aileron_left=("al",), rudder=("r1", "r2")))
    names = ["ar1", "ar2", "al", "r1", "r2", "elevator"]
    de, da, dr = mixer.layout(names).deflections([0.1, 0.3, -0.2, 0.01, 0.03, 0.0])
    assert da == pytest.approx(0.5 * (0.2 - (-0.2)))  # (mean right - mean left) / 2
    assert dr == pytest.approx(0.02)
    # The joint order may change from message to message: the mixing follows the names.
    reordered = ["elevator", "r2", "r1", "al", "ar2", "ar1"]
    assert mixer.layout(reordered).deflections([0.0, 0.03, 0.01, -0.2, 0.3, 0.1]) == (de, da, dr)
    assert mixer.layout(names).deflections([0.1, 0.5, -0.2, 0.01, 0.03, 0.0])[1] == pytest.approx(0.5 * (0.3 - (-0.2)))
    combined = SurfaceMixer(SurfaceMixing(aileron_combined="ail"))
    assert combined.layout(["ail", "rudder", "elevator"]).deflections([0.07, 0.0, 0.0])[1] == 0.07
    # Only one aileron side configured: no aileron deflection is formed (and none required).
    one_side = SurfaceMixer(SurfaceMixing(aileron_left=()))
    assert one_side.layout(["aileron_right", "rudder", "elevator"]).deflections([0.07, 0.0, 0.01])[1] == 0.0
    assert one_side.layout(["rudder", "elevator"]).deflections([0.0, 0.01]) == (0.01, 0.0, 0.0)


def test_elevator_and_rudder_are_averages_and_other_joints_are_reported():
    mixing = SurfaceMixing(elevator=("el", "er"), rudder=("ru", "rl"))
    names = ("flap", "el", "aileron_left", "er", "ru", "aileron_right", "rl", "gear")
    layout = mixing.layout(names)
    assert isinstance(layout, JointLayout)
    assert layout.unknown == ("flap", "gear")
    positions = [9.0, 0.02, -0.1, 0.04, 0.3, 0.1, 0.1, 9.0]
    assert layout.deflections(positions) == pytest.approx((0.03, 0.1, 0.2), rel=1e-15)


def test_joint_lists_that_cannot_be_mixed_give_their_reason():
    mixing = SurfaceMixing()
    assert mixing.layout(("elevator", "rudder", "aileron_left")) == Refused("missing_joint")
    twice = ("elevator", "rudder", "aileron_left", "aileron_right", "rudder")
    assert mixing.layout(twice) == Refused("mismatched_arrays")
    # A deflection that no model needs may be unmapped: nothing is missing then.
    assert isinstance(SurfaceMixing(rudder=()).layout(("elevator", "aileron_left", "aileron_right")), JointLayout)


def test_the_mixer_follows_name_lists_that_change_or_are_reused():
    mixer = SurfaceMixer(SurfaceMixing())
    names = ["elevator", "aileron_left", "aileron_right", "rudder"]
    assert mixer.layout(names).deflections([0.1, 0.2, 0.4, 0.3]) == (0.1, pytest.approx(0.1), 0.3)
    names.reverse()  # the caller reuses its list object with other contents
    assert mixer.layout(names).deflections([0.3, 0.4, 0.2, 0.1]) == (0.1, pytest.approx(0.1), 0.3)
    for k in range(40):  # many different lists: the cache stays bounded and right
        extra = [f"j{k}", "rudder", "elevator", "aileron_right", "aileron_left"]
        assert mixer.layout(extra).deflections([5.0, 0.3, 0.1, 0.4, 0.2]) == (0.1, pytest.approx(0.1), 0.3)
        assert mixer.layout(extra).unknown == (f"j{k}",)
    assert len(mixer._layouts) <= SurfaceMixer._CACHE_SIZE


def test_the_used_joints_are_the_mixed_ones():
    layout = SurfaceMixing(elevator=("el", "er"), rudder=("ru",)).layout(
        ("flap", "el", "aileron_left", "er", "ru", "aileron_right", "gear"))
    assert layout.used == (1, 2, 3, 4, 5)
    combined = SurfaceMixing(aileron_combined="ail").layout(("aileron_left", "ail", "rudder", "elevator"))
    assert combined.used == (1, 2, 3) and combined.unknown == ("aileron_left",)


def test_the_mixer_never_caches_long_name_lists():
    """A JointState with thousands of names is laid out (and its unknown joints listed) but
    not kept: the cache holds at most _CACHE_SIZE lists of at most _CACHE_MAX_NAMES names."""
    mixer = SurfaceMixer(SurfaceMixing())
    base = ["elevator", "aileron_left", "aileron_right", "rudder"]
    for k in range(40):
        names = base + [f"junk{k}_{i}" for i in range(5000)]
        layout = mixer.layout(names)
        assert layout.deflections([0.1, 0.2, 0.4, 0.3] + [0.0] * 5000) == (0.1, pytest.approx(0.1), 0.3)
        assert len(layout.unknown) == 5000
        assert mixer.layout(names) is layout  # the last list is still recognised
    assert all(len(key) <= SurfaceMixer._CACHE_MAX_NAMES for key in mixer._layouts)
    assert len(mixer._layouts) <= SurfaceMixer._CACHE_SIZE


def test_the_missing_fields_are_those_whose_joints_a_message_lacks():
    mixing = SurfaceMixing(elevator=("el", "er"), rudder=("ru",))
    assert mixing.missing(("el", "er", "ru", "aileron_left", "aileron_right")) == []
    assert mixing.layout(("el", "ru", "aileron_left", "aileron_right")) == Refused("missing_joint")
    assert mixing.missing(("el", "ru", "aileron_left", "aileron_right")) == [("surfaces.elevator", ("el", "er"))]
    assert mixing.missing(()) == [("surfaces.elevator", ("el", "er")), ("surfaces.rudder", ("ru",)),
                                  ("surfaces.aileron_right", ("aileron_right",)),
                                  ("surfaces.aileron_left", ("aileron_left",))]
    combined = SurfaceMixing(aileron_combined="ail")
    assert combined.missing(("elevator", "rudder")) == [("surfaces.aileron_combined", ("ail",))]
