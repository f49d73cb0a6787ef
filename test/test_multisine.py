"""Eq. 24 multisines: Table 2 relative peak factors, orthogonality, new designs."""

import numpy as np
import pytest

from rls_uncertainty.simulation.multisine import T2_TABLE2, design_multisines, relative_peak_factor


@pytest.mark.parametrize("name, rpf", [("elevator", 1.03), ("aileron", 1.15), ("rudder", 1.14)])
def test_table2_relative_peak_factors(name, rpf):
    t = np.linspace(0, 10, 20000, endpoint=False)
    assert relative_peak_factor(T2_TABLE2[name](t)) == pytest.approx(rpf, abs=0.01)


def test_single_sine_has_unit_rpf():
    t = np.linspace(0, 1, 1000, endpoint=False)
    assert relative_peak_factor(np.sin(2 * np.pi * 3 * t)) == pytest.approx(1.0, abs=1e-3)


def test_table2_inputs_are_mutually_orthogonal():
    t = np.linspace(0, 10, 5000, endpoint=False)
    u = np.array([T2_TABLE2[k](t) for k in ("elevator", "aileron", "rudder")])
    gram = u @ u.T / len(t)
    off = gram - np.diag(np.diag(gram))
    assert np.max(np.abs(off)) < 1e-10 * np.max(np.diag(gram))


def test_design_new_orthogonal_phase_optimized_inputs():
    designs = design_multisines(12.0, (0.1, 2.0), 3)
    t = np.linspace(0, 12, 6000, endpoint=False)
    u = np.array([d(t) for d in designs])
    gram = u @ u.T / len(t)
    assert np.max(np.abs(gram - np.diag(np.diag(gram)))) < 1e-10
    ks = [set(d.harmonics) for d in designs]
    assert not (ks[0] & ks[1] or ks[1] & ks[2] or ks[0] & ks[2])
    for d in designs:
        assert np.all((d.frequencies >= 0.1) & (d.frequencies <= 2.0))
        rpf = relative_peak_factor(d(t))
        assert rpf < 1.35  # Schroeder phases alone give about 1.4-1.6 for 7 components
        assert abs(d(0.0)) < 0.05 * np.max(np.abs(d(t)))  # starts near zero


def test_design_refuses_an_impossible_band():
    with pytest.raises(ValueError, match="harmonics"):
        design_multisines(2.0, (0.5, 1.0), 3)
