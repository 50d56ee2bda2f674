"""Prior screening: the coarse distance-transform pass and the exact pass it feeds."""

from __future__ import annotations

from domplane_ros.config import FeatureConfig, PriorConfig
from domplane_ros.core import prior
from domplane_ros.core.features import detect_corners
from domplane_ros.sim.generators import random_scene
import numpy as np
import pytest
from scipy.spatial import cKDTree


def _exact(candidates, left, tree, threshold):
    """Return the screening energy of every candidate by plain nearest-neighbour queries."""
    out = []
    for h in candidates:
        pred = np.c_[left, np.ones(len(left))] @ h.T
        d, _ = tree.query(pred[:, :2] / pred[:, 2:])
        out.append(np.sum(np.minimum(d, threshold) ** 2))
    return np.asarray(out)


@pytest.mark.parametrize('seed', range(2))
def test_the_best_candidates_are_ranked_as_the_exact_energy_ranks_them(seed):
    """The coarse pass only chooses which candidates get the exact energy.

    The first 16 of the ranking, and their energies, are those of the exact screening.
    """
    frame = random_scene(300 + seed)
    config = FeatureConfig()
    left = detect_corners(frame.left, config)
    tree = cKDTree(detect_corners(frame.right, config))
    candidates = prior.prior_candidates(PriorConfig(), 640, 480)
    assert candidates.shape[0] > prior.SCREEN_EXACT
    costs = prior.screen_candidates(candidates, left, tree, 12.0)
    exact = _exact(candidates, left, tree, 12.0)
    order = np.argsort(costs, kind='stable')[:16]
    np.testing.assert_array_equal(order, np.argsort(exact, kind='stable')[:16])
    np.testing.assert_allclose(costs[order], exact[order], rtol=1e-9)
    # The others rank after every exactly screened one.
    rest = np.setdiff1d(np.arange(len(costs)), np.argsort(costs)[:prior.SCREEN_EXACT])
    assert costs[rest].min() > np.sort(costs)[prior.SCREEN_EXACT - 1]


def test_coarse_distances_are_within_a_cell_of_the_true_ones():
    rng = np.random.default_rng(4)
    right = rng.uniform(0, [640, 480], (300, 2))
    pred = rng.uniform(-50, 700, (1, 2000, 2))
    threshold = 12.0
    d = np.min(np.linalg.norm(pred[0][:, None] - right[None], axis=2), axis=1)
    d = np.minimum(d, threshold)
    coarse = prior.coarse_screening(pred, right, threshold)
    cell = max(1.0, (640 + 2 * threshold) / 320)
    # Per point the error is at most about a cell diagonal (rasterised points and queries).
    per_point = [prior.coarse_screening(pred[:, i:i + 1], right, threshold)[0] ** 0.5
                 for i in range(0, 2000, 50)]
    assert np.max(np.abs(np.asarray(per_point) - d[::50])) <= 1.5 * cell
    assert abs(coarse[0] - np.sum(d * d)) < 0.1 * np.sum(d * d)


def test_few_candidates_are_all_screened_exactly():
    rng = np.random.default_rng(5)
    left = rng.uniform(0, [640, 480], (100, 2))
    tree = cKDTree(rng.uniform(0, [640, 480], (100, 2)))
    candidates = prior.prior_candidates(PriorConfig(samples=2), 640, 480)
    assert candidates.shape[0] <= prior.SCREEN_EXACT
    np.testing.assert_allclose(prior.screen_candidates(candidates, left, tree, 12.0),
                               _exact(candidates, left, tree, 12.0), rtol=1e-9)
