"""The real-rig evaluation: the perturbed pairs' truth and the tool's counts."""

from __future__ import annotations

import math

import cv2
from domplane_ros.config import one_shot_search, PlaneNodeConfig
from domplane_ros.core.homography import apply_homography
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools import evaluate_real_rigs as tool
from domplane_ros.tools.evaluation import real_rigs
from domplane_ros.tools.evaluation.references import (default_data_dir, KITTI_DIR,
                                                      kitti_reference, mean_transfer_px)
import numpy as np
import pytest

# A plane homography of a rectified pair (disparity grows toward the bottom) and bright dots in
# the right image where it maps a few left points: wherever the perturbations move the dots,
# each perturbed pair's truth must map its points onto them.
PLANE = np.array([[1.002, -0.32, 57.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
DOTS = np.array([[x, y] for x in range(150, 1100, 90) for y in range(30, 360, 40)], float)


def _dotted_base() -> real_rigs.Perturbed:
    right = np.zeros((375, 1242), np.uint8)
    for x, y in DOTS.astype(int):
        right[y - 1:y + 2, x - 1:x + 2] = 255
    points = apply_homography(np.linalg.inv(PLANE), DOTS)
    return real_rigs.Perturbed('original', '', np.zeros_like(right), right, PLANE, points)


def _dot_centroids(image: np.ndarray, expected: np.ndarray, half: int = 5) -> np.ndarray:
    """Return the intensity centroid within ``half`` px of each expected dot (NaN if empty)."""
    found = []
    for x, y in np.rint(expected).astype(int):
        x0, y0 = max(0, x - half), max(0, y - half)
        patch = image[y0:y + half + 1, x0:x + half + 1].astype(float)
        if patch.sum() == 0:
            found.append((math.nan, math.nan))
            continue
        ys, xs = np.mgrid[y0:y0 + patch.shape[0], x0:x0 + patch.shape[1]]
        found.append(((xs * patch).sum() / patch.sum(), (ys * patch).sum() / patch.sum()))
    return np.array(found).reshape(-1, 2)


def _inside(points: np.ndarray, image: np.ndarray, margin: int = 8) -> np.ndarray:
    return ((points[:, 0] > margin) & (points[:, 0] < image.shape[1] - margin)
            & (points[:, 1] > margin) & (points[:, 1] < image.shape[0] - margin))


@pytest.mark.parametrize('family', ['rig_roll', 'rig_vertical', 'rig_focal', 'rig_principal',
                                    'rig_rough', 'crop', 'crop_upper'])
def test_each_perturbed_truth_maps_the_points_onto_where_the_dots_went(family):
    base = _dotted_base()
    for seed in (0, 1):
        pair = real_rigs.draw(base, family, seed)
        expected = apply_homography(pair.truth, pair.points)
        keep = _inside(expected, pair.right)
        assert keep.sum() >= 5
        found = _dot_centroids(pair.right, expected[keep])
        assert np.all(np.linalg.norm(found - expected[keep], axis=1) < 0.3), family


def test_the_downscaled_and_swapped_truths_follow_the_dots():
    base = _dotted_base()
    for levels in (1, 2):
        pair = real_rigs.downscale(base, levels)
        expected = apply_homography(pair.truth, pair.points)
        found = _dot_centroids(pair.right, expected, half=3)
        assert np.all(np.linalg.norm(found - expected, axis=1) < 0.3)
    swapped = real_rigs.swap(base)
    # The new left image is the dotted one: the swapped pair's points sit on its dots, and
    # its truth takes them back to the original left points.
    assert np.allclose(_dot_centroids(swapped.left, swapped.points), swapped.points, atol=0.3)
    assert np.allclose(apply_homography(swapped.truth, swapped.points), base.points)


def test_photometric_changes_keep_the_truth_and_change_one_camera():
    rng = np.random.default_rng(3)
    base = _dotted_base()
    base.left, base.right = (rng.integers(20, 235, base.left.shape).astype(np.uint8)
                             for _ in range(2))
    for seed in range(6):
        pair = real_rigs.draw(base, 'photometric', seed)
        assert np.array_equal(pair.truth, base.truth)
        changed = 'right' if not np.array_equal(pair.right, base.right) else 'left'
        assert changed in pair.detail
        assert pair.detail.startswith(real_rigs.PHOTOMETRIC_KINDS[seed])


def test_the_tool_scores_and_counts_as_evaluate_kitti_does():
    folder = default_data_dir() / KITTI_DIR
    base = tool.kitti_base(default_data_dir())
    settings = {'default': one_shot_search(PlaneNodeConfig())}
    rows = []
    for pair in (base, real_rigs.swap(base)):
        rows += tool.run_pair(pair, -1, settings, baselines=False)[0]
    # The unperturbed pair: the same error as evaluate_kitti's over the road's pixels.
    ref = kitti_reference(folder)
    ys, xs = np.nonzero(ref.road)
    road = np.stack([xs, ys], axis=1).astype(float)
    left = cv2.imread(str(folder / 'left.png'), cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(str(folder / 'right.png'), cv2.IMREAD_GRAYSCALE)
    result = PlanePipeline(settings['default']).process(left, right, 0)
    assert result.ok and rows[0].published
    expected = mean_transfer_px(result.homography, road,
                                apply_homography(ref.plane.homography(), road))
    assert rows[0].error_px == pytest.approx(expected)
    assert rows[0].verdict == ('correct' if expected < tool.CORRECT_PX else '1-5 px')
    # Swapped cameras: refused and named.
    assert not rows[1].published and 'swapped' in rows[1].reason
    counts = tool.tally(rows)
    assert (counts['pairs'], counts['road'], counts['published']) == (2, 2, 1)
    assert counts['correct'] == int(rows[0].verdict == 'correct')
    assert counts['precision'] == counts['correct'] and counts['recall'] == counts['correct'] / 2


def test_a_plane_published_where_there_is_no_road_counts_as_wrong():
    published = tool.Row('crop_upper', 3, '', 'ours default', 10, True, math.nan, '', 1.0)
    refused = tool.Row('crop_upper', 4, '', 'ours default', 0, False, math.nan, 'no', 1.0)
    assert published.verdict == 'wrong (no road)' and refused.verdict == 'refused'
    counts = tool.tally([published, refused])
    assert (counts['published'], counts['wrong'], counts['road']) == (1, 1, 0)
    assert counts['precision'] == 0.0 and math.isnan(counts['recall'])


def test_families_choose_the_draws_and_the_fixed_pairs(tmp_path):
    base = tool.kitti_base(default_data_dir())
    rows, _ = tool.evaluate([0], base, baselines=False, families=['crop_upper'])
    assert {r.family for r in rows} == {'crop_upper'} and len(rows) == len(tool.configs())
    with pytest.raises(SystemExit):
        tool.main(['--families', 'crop,nonsense', '--out', str(tmp_path)])
