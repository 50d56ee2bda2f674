"""evaluate_mask: the parallax mask against the NCC mask; KITTI with the issue's labels."""

from __future__ import annotations

from pathlib import Path

import cv2
from domplane_ros.tools import evaluate_mask
from domplane_ros.tools.evaluation.datasets import KITTI_PRIOR
from domplane_ros.tools.evaluation.references import read_gray
import pytest

KITTI = Path(__file__).resolve().parents[1] / 'data' / 'kitti2015_000046'


@pytest.fixture(scope='module')
def kitti_figures():
    left = read_gray(KITTI / 'left.png')
    right = read_gray(KITTI / 'right.png')
    truth = evaluate_mask.kitti_labels(KITTI)
    return {name: evaluate_mask.kitti_scores(function(left, right, truth.reference_h).labels,
                                             truth)
            for name, function in evaluate_mask.masks(KITTI_PRIOR.focal_px).items()}


def test_kitti_labels_follow_the_issue(kitti_figures):
    truth = evaluate_mask.kitti_labels(KITTI)
    # Road within 1 px of the robust disparity plane, off-road beyond it: disjoint, both
    # sizeable (30463 and 24605 ground-truth pixels).
    assert not (truth.road & truth.off_road).any()
    assert truth.road.sum() > 25000 and truth.off_road.sum() > 20000


def test_parallax_mask_on_kitti_with_the_reference_plane(kitti_figures):
    new, old = kitti_figures['parallax'], kitti_figures['ncc']
    # Measured: road marked plane 0.853 (target 0.95, missed: the far road near the horizon,
    # where a 0.1 x 1.65 m obstacle would show less than 1 px, is unknown), off-road obstacle
    # or unknown 0.952 (target 0.95), off-road marked plane 0.048 (target 0.02, missed).
    # The NCC mask: 0.827, 0.862, 0.138.
    assert new['road_plane'] > 0.82
    assert new['off_road_not_plane'] > 0.94
    assert new['off_road_plane'] < 0.06
    assert new['off_road_plane'] < 0.5 * old['off_road_plane']
    # A lower minimum obstacle height trades road for off-road (0.738, 0.977, 0.023).
    low = kitti_figures['parallax_low']
    assert low['off_road_plane'] < new['off_road_plane'] < old['off_road_plane']
    assert low['road_plane'] < new['road_plane']


def test_tool_writes_the_sheet_and_the_table(tmp_path):
    out = tmp_path / 'mask'
    rc = evaluate_mask.main(['--scenes', '1', '--indoor', '1', '--repeats', '2',
                             '--data', str(KITTI.parent), '--out', str(out)])
    assert rc == 0
    text = (out / 'mask_summary.txt').read_text(encoding='utf-8')
    for row in ('plane IoU (median)', 'road marked plane', 'walls + furniture marked plane',
                'mask time, median ms (CPU time)'):
        assert row in text
    sheet = cv2.imread(str(out / 'mask_contact_sheet.png'))
    # Rows: one rendered scene, one indoor scene, KITTI with two homographies; 4 tiles each.
    assert sheet is not None and sheet.shape[1] == 4 * 320 and sheet.shape[0] > 4 * 90
