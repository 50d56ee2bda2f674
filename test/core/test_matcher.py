"""Tests of the residual parallax from OpenCV's stereo matchers (docs/MASK.md round 12).

The measurement is behind the switch ``pixel_decision._MEASUREMENT`` (default
``'one_step'``); these tests pin what it does when switched on, against ground truth.
"""

from __future__ import annotations

from pathlib import Path

import cv2
from domplane_ros.config import MaskConfig
from domplane_ros.core import mask, pixel_decision, residual
from domplane_ros.sim.generators import random_scene
from domplane_ros.tools.evaluate_mask import kitti_labels, kitti_scores, rendered_scores
from domplane_ros.tools.evaluation.datasets import KITTI_PRIOR
from domplane_ros.tools.evaluation.references import read_gray
import numpy as np
import pytest

CONFIG = MaskConfig()
KITTI = Path(__file__).resolve().parents[1] / 'data' / 'kitti2015_000046'


def _texture(seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = cv2.GaussianBlur(rng.uniform(0, 255, (240, 320)).astype(np.float32), (0, 0), 1.2)
    return cv2.normalize(noise, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def _moved(image: np.ndarray, parallax: float) -> np.ndarray:
    """Return the warped image in which every left pixel x shows at x - parallax."""
    height, width = image.shape
    map_x = (np.arange(width, dtype=np.float32)[None] + np.float32(parallax)).repeat(height, 0)
    map_y = np.arange(height, dtype=np.float32)[:, None].repeat(width, 1)
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


@pytest.mark.parametrize('kind', ['block', 'semi_global'])
def test_matcher_reads_the_residual_parallax_with_its_sign(kind):
    # OpenCV's disparity is the residual parallax: a point nearer than the plane (positive)
    # shows at x - r in the warped image. Measured: 3.0 / -5.0 / 0.5 at the median, 97-100 %
    # of the pixels matched, and 77-100 % of the 12 side columns (OpenCV leaves the first
    # minimum + count columns unmatched without the padding); a flat image matches nowhere.
    left = _texture()
    for parallax in (3.0, -5.0, 0.5):
        shift, matched = residual.matcher_shift(left, _moved(left, parallax), kind)
        assert matched.mean() > 0.95, (parallax, matched.mean())
        assert abs(float(np.median(shift[matched])) - parallax) < 0.07, parallax
        assert matched[8:-8, :12].mean() > 0.7 and matched[8:-8, -12:].mean() > 0.7
        assert np.all(shift[~matched] == 0.0)
    flat = np.full((240, 320), 128, np.uint8)
    assert not residual.matcher_shift(flat, flat, kind)[1].any()


def _kitti_figures(measurement: str, monkeypatch) -> dict[str, float]:
    monkeypatch.setattr(pixel_decision, '_MEASUREMENT', measurement)
    truth = kitti_labels(KITTI)
    result = mask.parallax_mask(read_gray(KITTI / 'left.png'), read_gray(KITTI / 'right.png'),
                                truth.reference_h, CONFIG, KITTI_PRIOR.focal_px)
    return kitti_scores(result.labels, truth)


def test_semi_global_measurement_marks_less_of_kittis_off_road_as_plane(monkeypatch):
    # KITTI 000046 with the reference H and the labels. Measured: off-road marked
    # plane 3.2 % (one-step: 4.0 %), off-road obstacle or unknown 96.8 % (96.0 %), road marked
    # plane 84.5 % (86.5 %): the matcher moves along KITTI's trade-off, a little past it.
    matched = _kitti_figures('semi_global', monkeypatch)
    one_step = _kitti_figures('one_step', monkeypatch)
    assert matched['off_road_plane'] < 0.035 and matched['off_road_not_plane'] > 0.965, matched
    assert one_step['off_road_plane'] > 0.038, one_step
    assert 0.83 < matched['road_plane'] < one_step['road_plane'], (matched, one_step)


def _gain_frame_medians(measurement: str, monkeypatch) -> dict[str, float]:
    monkeypatch.setattr(pixel_decision, '_MEASUREMENT', measurement)
    rows = []
    for seed in range(8):  # the unit tests' frames: right camera gain 1.2, offset -15
        frame = random_scene(seed, gain=1.2, offset=-15.0, noise_std=1.0)
        labels = mask.parallax_mask(frame.left, frame.right, frame.homography, CONFIG).labels
        rows.append(rendered_scores(frame, labels))
    return {key: float(np.median([row[key] for row in rows]))
            for key in ('plane_iou', 'obstacle_recall', 'ground_as_obstacle', 'box_as_plane')}


def test_semi_global_measurement_finds_more_of_the_boxes(monkeypatch):
    # Rendered frames with a camera gain, true H. Measured with the matcher: obstacle recall
    # 0.953 (one-step 0.927), true ground marked obstacle 1.04 % (1.17 %), plane IoU 0.868
    # (0.878): the matcher reads the boxes' bottoms off the plane where the one-step shift,
    # at half scale on these floors, read them within the threshold.
    matched = _gain_frame_medians('semi_global', monkeypatch)
    one_step = _gain_frame_medians('one_step', monkeypatch)
    assert matched['obstacle_recall'] > 0.945 and one_step['obstacle_recall'] < 0.935
    assert matched['ground_as_obstacle'] < 0.011 < one_step['ground_as_obstacle']
    assert matched['plane_iou'] > 0.86, matched


def test_matcher_rejects_what_opencv_cannot_search():
    left = _texture()
    with pytest.raises(ValueError, match='multiple of 16'):
        residual.matcher_shift(left, left, 'block', count=20)
    with pytest.raises(ValueError, match='unknown matcher'):
        residual.matcher_shift(left, left, 'dense')
