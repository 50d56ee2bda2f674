"""Tests of the homography fit: normalised DLT, Euclidean refinement, degenerate input."""

from __future__ import annotations

from domplane_ros.core.homography import (apply_homography, corner_distance_px, fit_homography,
                                          fit_homography_dlt, NormalisedRefiner,
                                          refine_homography, transfer_error)
from domplane_ros.core.result import FailedEstimate
from domplane_ros.sim.synthetic import random_plane_homography
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from scipy.optimize import least_squares


def _scene(seed: int, n: int = 50, noise: float = 0.0):
    rng = np.random.default_rng(seed)
    h = random_plane_homography(rng)
    src = rng.uniform([0, 0], [639, 479], (n, 2))
    dst = apply_homography(h, src) + rng.normal(0, noise, (n, 2))
    return h, src, dst, rng


@pytest.mark.parametrize('seed', range(5))
def test_dlt_exact_from_four_points(seed):
    h, src, dst, _ = _scene(seed, n=4)
    est = fit_homography_dlt(src, dst)
    assert isinstance(est, np.ndarray)
    assert est[2, 2] == pytest.approx(1.0)
    np.testing.assert_allclose(est, h, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize('seed', range(5))
def test_overdetermined_noisy_fit_is_within_noise(seed):
    h, src, dst, rng = _scene(seed, n=200, noise=0.5)
    est = fit_homography(src, dst)
    grid = rng.uniform([0, 0], [639, 479], (500, 2))
    err = np.linalg.norm(apply_homography(est, grid) - apply_homography(h, grid), axis=1)
    assert err.mean() < 0.15


@pytest.mark.parametrize('seed', range(5))
def test_euclidean_refinement_reaches_the_geometric_optimum(seed):
    """Refined transfer energy <= DLT's and equal to scipy's least_squares optimum."""
    _, src, dst, _ = _scene(seed, n=60, noise=2.0)
    dst[::7] += 15.0  # unequal residuals make algebraic and geometric optima differ
    dlt = fit_homography_dlt(src, dst)
    refined = refine_homography(dlt, src, dst)
    e_dlt = np.sum(transfer_error(dlt, src, dst) ** 2)
    e_ref = np.sum(transfer_error(refined, src, dst) ** 2)
    assert e_ref <= e_dlt

    def residuals(p):
        return (apply_homography(np.append(p, 1.0).reshape(3, 3), src) - dst).ravel()

    best = least_squares(residuals, dlt.ravel()[:8], xtol=1e-14, ftol=1e-14, gtol=1e-14)
    assert e_ref == pytest.approx(2 * best.cost, rel=1e-6)


def test_zero_weights_remove_outliers():
    h, src, dst, _ = _scene(0, n=40)
    dst[:8] += 60.0
    weights = np.ones(40)
    weights[:8] = 0.0
    est = fit_homography(src, dst, weights)
    np.testing.assert_allclose(apply_homography(est, src[8:]), dst[8:], atol=1e-6)
    unweighted = fit_homography(src, dst)
    assert np.abs(apply_homography(unweighted, src[8:]) - dst[8:]).max() > 1.0


@pytest.mark.parametrize('src,dst,reason', [
    (np.zeros((3, 2)), np.zeros((3, 2)), 'at least 4'),
    (np.c_[np.arange(10.0), 2 * np.arange(10.0) + 1], np.random.default_rng(0).random((10, 2)),
     'collinear'),
    (np.repeat([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], 4, axis=0),
     np.random.default_rng(1).random((12, 2)), 'distinct'),
    (np.r_[np.random.default_rng(2).random((9, 2)), [[np.nan, 1.0]]],
     np.random.default_rng(3).random((10, 2)), 'non-finite'),
    (np.random.default_rng(4).random((10, 2)), np.random.default_rng(5).random((9, 2)),
     'shape'),
])
def test_degenerate_input_is_a_failure_value(src, dst, reason):
    for fit in (fit_homography_dlt, fit_homography):
        result = fit(src, dst)
        assert isinstance(result, FailedEstimate)
        assert not result
        assert reason in result.reason


def test_wrong_shapes_raise_value_error():
    with pytest.raises(ValueError, match=r'shape \(N, 2\)'):
        fit_homography_dlt(np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match='numeric'):
        fit_homography_dlt([['a', 'b']] * 4, np.zeros((4, 2)))


def test_points_at_infinity_map_to_finite_values():
    h = np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 0, 0]])
    out = apply_homography(h, np.array([[0.0, 5.0], [1.0, 1.0]]))
    assert np.all(np.isfinite(out))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), noise=st.floats(0.0, 20.0), shift=st.floats(0.0, 50.0))
def test_gauss_newton_never_increases_transfer_energy(seed, noise, shift):
    rng = np.random.default_rng(seed)
    h = random_plane_homography(rng)
    src = rng.uniform([0, 0], [639, 479], (30, 2))
    dst = apply_homography(h, src) + rng.normal(0, noise + 1e-9, (30, 2))
    start = h.copy()
    start[0, 2] += shift
    refiner = NormalisedRefiner(src, dst)
    out, before, after = refiner.refine(start, dst, None, 5)
    assert after <= before
    e_out = 0.5 * np.sum(transfer_error(out, src, dst) ** 2)
    assert e_out == pytest.approx(after, rel=1e-6, abs=1e-9)


def test_corner_distance_is_the_largest_corner_displacement():
    shift = np.array([[1.0, 0.0, 3.0], [0.0, 1.0, -4.0], [0.0, 0.0, 1.0]])
    assert corner_distance_px(np.eye(3), shift, 640, 480) == pytest.approx(5.0)
    scale = np.diag([1.01, 1.0, 1.0])  # 1 % wider: the right corners move 6.39 px
    assert corner_distance_px(np.eye(3), scale, 640, 480) == pytest.approx(6.39)
    to_infinity = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0 / 639.0, 0.0, 1.0]])
    # A corner mapped to infinity: a distance no threshold passes.
    assert corner_distance_px(np.eye(3), to_infinity, 640, 480) > 1e6


@pytest.mark.parametrize('weighted', [False, True])
def test_normal_equations_are_those_of_the_explicit_jacobian(weighted):
    # Ground truth: J^T W J and J^T W r from the Jacobian of the normalised transfer residuals
    # written out row by row (x residual [m, 0, -px m], y residual [0, m, -py m]).
    from domplane_ros.core.homography import _normal_equations

    rng = np.random.default_rng(11)
    n = 40
    src_h = np.column_stack([rng.normal(size=(n, 2)), np.ones(n)])
    g = np.eye(3) + 0.1 * rng.normal(size=(3, 3))
    uvw = src_h @ g.T
    iw = 1.0 / uvw[:, 2]
    px, py = uvw[:, 0] * iw, uvw[:, 1] * iw
    dst_n = np.column_stack([px, py]) + rng.normal(0, 0.05, (n, 2))
    w = rng.uniform(0.0, 2.0, n) if weighted else None
    m = src_h * iw[:, None]
    zero = np.zeros((n, 3))
    jac = np.vstack([np.hstack([m, zero, -px[:, None] * m]),
                     np.hstack([zero, m, -py[:, None] * m])])
    res = np.concatenate([px - dst_n[:, 0], py - dst_n[:, 1]])
    ww = np.ones(2 * n) if w is None else np.concatenate([w, w])
    normal, grad = _normal_equations(m, px, py, dst_n, w)
    np.testing.assert_allclose(normal, jac.T @ (ww[:, None] * jac), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(grad, jac.T @ (ww * res), rtol=1e-12, atol=1e-12)
