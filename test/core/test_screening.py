"""Prior screening: the coarse distance-transform pass and the exact pass it feeds."""

from __future__ import annotations

import functools

import cv2
from domplane_ros.config import FeatureConfig, PriorConfig
from domplane_ros.core import prior, screening
from domplane_ros.core.features import detect_corners
from domplane_ros.core.homography import FAR_PX, MIN_W
from domplane_ros.sim.generators import random_scene
import numpy as np
import pytest
from scipy.spatial import cKDTree


@functools.lru_cache(maxsize=2)
def _features(seed):
    """Return a rendered scene's left corners and a tree over its right corners (cached)."""
    frame = random_scene(seed)
    config = FeatureConfig()
    return detect_corners(frame.left, config), cKDTree(detect_corners(frame.right, config))


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
    left, tree = _features(300 + seed)
    candidates = prior.prior_candidates(PriorConfig(), 640, 480)
    assert candidates.shape[0] > screening.SCREEN_EXACT
    costs = screening.screen_candidates(candidates, left, tree, 12.0)
    exact = _exact(candidates, left, tree, 12.0)
    order = np.argsort(costs, kind='stable')[:16]
    np.testing.assert_array_equal(order, np.argsort(exact, kind='stable')[:16])
    np.testing.assert_allclose(costs[order], exact[order], rtol=1e-9)
    # The others rank after every exactly screened one.
    rest = np.setdiff1d(np.arange(len(costs)), np.argsort(costs)[:screening.SCREEN_EXACT])
    assert costs[rest].min() > np.sort(costs)[screening.SCREEN_EXACT - 1]


def _reference_screening(candidates, left, tree, threshold):
    """Return the screening energies as computed before the seventh round, for comparison.

    One (M, N, 2) prediction array, the coarse pass on it, the exact pass on its best
    SCREEN_EXACT: the search's ranking and energies must not change with the layout.
    """
    hom = candidates @ np.column_stack([left, np.ones(len(left))]).T
    w = hom[:, 2]
    w = np.where(np.abs(w) < MIN_W, MIN_W, w)
    pred = np.clip(np.stack([hom[:, 0] / w, hom[:, 1] / w], axis=-1), -FAR_PX, FAR_PX)
    right = tree.data
    low, high = right.min(axis=0) - threshold, right.max(axis=0) + threshold
    cell = max(1.0, float(np.max(high - low)) / 320)
    cols, rows = np.ceil((high - low) / cell).astype(int) + 1
    occupied = np.full((rows, cols), 255, np.uint8)
    idx = np.rint((right - low) / cell).astype(int)
    occupied[idx[:, 1], idx[:, 0]] = 0
    dist = cell * cv2.distanceTransform(occupied, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    table = np.full((rows + 2, cols + 2), threshold ** 2)
    table[1:-1, 1:-1] = np.minimum(dist, threshold) ** 2
    grid = np.clip(np.rint((pred - (low - cell)) / cell), 0, (cols + 1, rows + 1)).astype(int)
    coarse = np.sum(table[grid[..., 1], grid[..., 0]], axis=1)
    best = np.argsort(coarse, kind='stable')[:screening.SCREEN_EXACT]
    costs = coarse + (1.0 + len(left) * threshold ** 2)
    d, _ = tree.query(pred[best].reshape(-1, 2), distance_upper_bound=threshold)
    d = np.minimum(d, threshold).reshape(len(best), -1)
    costs[best] = np.sum(d * d, axis=1)
    return costs


def test_screening_gives_the_reference_energies_bit_for_bit():
    """The prior's and the swapped cameras' candidates: the same energies, so the same starts."""
    left, tree = _features(301)
    candidates = prior.prior_candidates(PriorConfig(), 640, 480)
    for cands in (candidates, prior.swapped_candidates(candidates)):
        costs = screening.screen_candidates(cands, left, tree, 12.0)
        reference = _reference_screening(cands, left, tree, 12.0)
        np.testing.assert_array_equal(costs, reference)
        # A wrong cell index (x and y exchanged) would change the best starts: checked too.
        np.testing.assert_array_equal(np.argsort(costs, kind='stable')[:6],
                                      np.argsort(reference, kind='stable')[:6])


def test_coarse_distances_are_within_a_cell_of_the_true_ones():
    rng = np.random.default_rng(4)
    right = rng.uniform(0, [640, 480], (300, 2))
    pred = rng.uniform(-50, 700, (1, 2000, 2))
    threshold = 12.0
    d = np.min(np.linalg.norm(pred[0][:, None] - right[None], axis=2), axis=1)
    d = np.minimum(d, threshold)
    coarse = screening.coarse_screening(pred, right, threshold)
    cell = max(1.0, (640 + 2 * threshold) / 320)
    # Per point the error is at most about a cell diagonal (rasterised points and queries).
    per_point = [screening.coarse_screening(pred[:, i:i + 1], right, threshold)[0] ** 0.5
                 for i in range(0, 2000, 50)]
    assert np.max(np.abs(np.asarray(per_point) - d[::50])) <= 1.5 * cell
    assert abs(coarse[0] - np.sum(d * d)) < 0.1 * np.sum(d * d)


def test_few_candidates_are_all_screened_exactly():
    rng = np.random.default_rng(5)
    left = rng.uniform(0, [640, 480], (100, 2))
    tree = cKDTree(rng.uniform(0, [640, 480], (100, 2)))
    candidates = prior.prior_candidates(PriorConfig(samples=2), 640, 480)
    assert candidates.shape[0] <= screening.SCREEN_EXACT
    np.testing.assert_allclose(screening.screen_candidates(candidates, left, tree, 12.0),
                               _exact(candidates, left, tree, 12.0), rtol=1e-9)


@pytest.mark.parametrize('seed', range(2))
def test_the_short_screening_gives_the_best_candidates_of_the_full_one(seed):
    """The lock's challenge refines the best two: the same two, in order, as the search's.

    The prior's candidates only (the challenge's): of the swapped cameras' candidates none
    fits a correctly ordered pair, their energies lie within 5 % of each other and the short
    list's sample picks others (on scene 300).
    """
    left, tree = _features(300 + seed)
    candidates = prior.prior_candidates(PriorConfig(), 640, 480)
    full = np.argsort(screening.screen_candidates(candidates, left, tree, 12.0), kind='stable')
    short = screening.best_screened(candidates, left, tree, 12.0, 2)
    np.testing.assert_array_equal(short, full[:2])
    # The exact energy decides the order (fails if the coarse order were returned).
    exact = _exact(candidates[short], left, tree, 12.0)
    assert exact[0] <= exact[1]
    few = candidates[:screening.SHORT_EXACT]
    np.testing.assert_array_equal(screening.best_screened(few, left, tree, 12.0, 3),
                                  np.argsort(_exact(few, left, tree, 12.0), kind='stable')[:3])
