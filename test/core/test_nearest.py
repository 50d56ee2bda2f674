"""Closest-point queries that re-use earlier answers give a fresh query's answers."""

from domplane_ros.core.nearest import NearestPoints
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from scipy.spatial import cKDTree


def _fresh(tree: cKDTree, pred: np.ndarray, bound: float | None) -> tuple:
    if bound is None:
        return tree.query(pred)
    d, i = tree.query(pred, distance_upper_bound=bound)
    return d, np.where(i >= tree.n, -1, i)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1), bound=st.sampled_from([None, 1.0, 3.0, 20.0]))
def test_same_answers_as_a_fresh_query_while_predictions_move(seed, bound):
    rng = np.random.default_rng(seed)
    points = rng.uniform(0, 200, (int(rng.integers(4, 120)), 2))
    tree = cKDTree(points)
    nearest = NearestPoints(points, tree)
    pred = rng.uniform(-30, 230, (int(rng.integers(1, 80)), 2))
    for step in range(12):
        # Moves from large (a fresh start) to tiny (convergence), as in the iteration.
        pred = pred + rng.normal(0, [8.0, 1.0, 0.1, 0.01][step % 4], pred.shape)
        r, idx, closest = nearest.query_closest(pred, bound)
        r0, idx0 = _fresh(tree, pred, bound)
        np.testing.assert_array_equal(idx, idx0)
        np.testing.assert_allclose(r, r0, rtol=1e-12, atol=1e-12)
        found = idx0 >= 0
        np.testing.assert_array_equal(closest[found], points[idx0[found]])


def test_queries_only_the_predictions_that_moved_far_enough():
    rng = np.random.default_rng(4)
    points = rng.uniform(0, 640, (500, 2))
    nearest = NearestPoints(points)
    pred = points[:400] + rng.normal(0, 0.5, (400, 2))
    nearest.query(pred, 1.0)
    assert nearest.queried == 400
    pred[:10] += 30.0  # ten predictions jump; the rest move by a hundredth of a pixel
    pred[10:] += 0.01
    r, idx = nearest.query(pred, 1.0)
    assert nearest.queried == 410
    np.testing.assert_array_equal(idx, _fresh(cKDTree(points), pred, 1.0)[1])


@pytest.mark.parametrize('bound', [None, 2.0])
def test_bounds_are_cached_separately(bound):
    rng = np.random.default_rng(5)
    points = rng.uniform(0, 100, (50, 2))
    nearest = NearestPoints(points)
    pred = rng.uniform(0, 100, (30, 2))
    nearest.query(pred, 5.0)
    r, idx = nearest.query(pred, bound)
    r0, idx0 = _fresh(cKDTree(points), pred, bound)
    np.testing.assert_array_equal(idx, idx0)
    np.testing.assert_allclose(r, r0)
