"""Each potential's auxiliary-point rule checked against its definition, numerically."""

from __future__ import annotations

from domplane_ros.config import POTENTIAL_NAMES
from domplane_ros.core.potentials import make_potential, POTENTIALS
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest


@pytest.mark.parametrize('name', sorted(POTENTIALS))
@pytest.mark.parametrize('lam', [0.2, 0.5, 0.8])
@pytest.mark.parametrize('threshold', [1.0, 3.0, 10.0])
def test_step_minimises_the_auxiliary_energy(name, lam, threshold):
    """step(r) = argmin over s in [0, r] of 1/2 s^2 + P(r - s), by brute force."""
    pot = make_potential(name, lam, threshold)
    r = np.linspace(0.0, 8 * threshold, 97)
    s = pot.step(r)
    assert np.all(s >= 0) and np.all(s <= r + 1e-12)
    grid = np.linspace(0, 1, 20001)[None, :] * r[:, None]
    brute = 0.5 * grid ** 2 + pot.penalty(r[:, None] - grid)
    best = brute.min(axis=1)
    ours = 0.5 * s ** 2 + pot.penalty(r - s)
    assert np.all(ours <= best + 1e-6 * (1 + best))


def test_the_parameter_table_offers_every_registered_potential():
    assert sorted(POTENTIAL_NAMES) == sorted(POTENTIALS)


def test_least_squares_auxiliary_point_interpolates():
    pot = make_potential('least_squares', 0.3, 2.0)
    r = np.array([0.0, 1.0, 50.0])
    np.testing.assert_allclose(pot.step(r), 0.3 * r)


def test_truncated_quadratic_ignores_points_beyond_threshold():
    pot = make_potential('truncated_quadratic', 0.6, 4.0)
    np.testing.assert_allclose(pot.step(np.array([1.0, 3.9, 4.1, 100.0])),
                               [0.6, 0.6 * 3.9, 0.0, 0.0])
    # Constant energy alpha beyond the threshold.
    e = pot.point_energy(np.array([5.0, 50.0]))
    assert e[0] == pytest.approx(e[1])


def test_huber_moves_a_bounded_step_beyond_threshold():
    pot = make_potential('huber', 0.5, 2.0)
    np.testing.assert_allclose(pot.step(np.array([1.0, 2.0, 10.0, 1000.0])),
                               [0.5, 1.0, 1.0, 1.0])


def test_geman_mcclure_redescends():
    pot = make_potential('geman_mcclure', 0.8, 2.0)
    s = pot.step(np.array([0.1, 1.0, 50.0, 500.0]))
    assert s[0] == pytest.approx(0.8 * 0.1, rel=0.05)
    assert s[2] < 0.05 and s[3] < 0.005


def test_unknown_potential_and_bad_parameters():
    with pytest.raises(ValueError, match='unknown potential'):
        make_potential('tukey', 0.5, 1.0)
    with pytest.raises(ValueError, match='lambda_weight'):
        make_potential('huber', 1.0, 1.0)
    with pytest.raises(ValueError, match='threshold_px'):
        make_potential('huber', 0.5, -1.0)


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sorted(POTENTIALS)), lam=st.floats(0.05, 0.95),
       threshold=st.floats(0.2, 30.0), r=st.floats(0.0, 500.0))
def test_point_energy_is_non_decreasing_in_distance(name, lam, threshold, r):
    pot = make_potential(name, lam, threshold)
    e = pot.point_energy(np.array([r, r * 1.01 + 1e-3]))
    assert e[1] >= e[0] - 1e-9 * (1 + e[0])
