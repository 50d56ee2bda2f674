"""evaluate_mask: the parallax mask against the NCC mask; KITTI with the issue's labels."""

from __future__ import annotations

from pathlib import Path
import shutil
import sys

import cv2
from domplane_ros.core import mask, pixel_decision, residual
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
    # Measured: road marked plane 0.865 (target 0.95, missed: road the right camera does not
    # see, left of the image and behind the pole, the far road near the horizon where a
    # 0.1 x 1.65 m obstacle would show less than 1 px), off-road obstacle or unknown 0.960
    # (target 0.95), off-road marked plane 0.040 (target 0.02, missed: mostly kerbs and
    # verges 1-2 px off the plane). Before round 8's coarse-flow test (docs/MASK.md) 0.867,
    # 0.958, 0.042.
    # The NCC mask: 0.827, 0.862, 0.138.
    assert new['road_plane'] > 0.86
    assert new['off_road_not_plane'] > 0.955
    assert new['off_road_plane'] < 0.045
    assert new['off_road_plane'] < 0.5 * old['off_road_plane']
    # A lower minimum obstacle height trades road for off-road (0.757, 0.975, 0.025).
    low = kitti_figures['parallax_low']
    assert low['off_road_plane'] < new['off_road_plane'] < old['off_road_plane']
    assert low['road_plane'] < new['road_plane']


def test_tool_writes_the_sheet_and_the_table(tmp_path):
    out = tmp_path / 'mask'
    # --baseline: another version of core/mask.py as a column, here a folder with this
    # version's mask.py and residual.py (same figures); the residual module loaded for it
    # stands in only while the baseline is loaded.
    folder = tmp_path / 'baseline'
    folder.mkdir()
    for module in (mask, residual):
        shutil.copy(module.__file__, folder)
    rc = evaluate_mask.main(['--scenes', '1', '--indoor', '1', '--repeats', '2',
                             '--data', str(KITTI.parent), '--out', str(out),
                             '--baseline', str(folder)])
    assert rc == 0
    assert sys.modules['domplane_ros.core.residual'] is residual
    text = (out / 'mask_summary.txt').read_text(encoding='utf-8')
    for row in ('plane IoU (median)', 'road marked plane', 'walls + furniture marked plane',
                'mask time, median ms (CPU time)', 'baseline (--baseline)',
                'occluded floor marked unknown (median)',
                'obstacle recall, box seen by both (median)'):
        assert row in text
    road = next(line for line in text.splitlines()
                if 'reference H' in line and 'road marked plane' in line).split('|')
    assert road[5].strip() == road[6].strip()  # baseline and parallax (now): the same module
    sheet = cv2.imread(str(out / 'mask_contact_sheet.png'))
    # Rows: one rendered scene, one indoor scene, KITTI with two homographies; 4 tiles each.
    assert sheet is not None and sheet.shape[1] == 4 * 320 and sheet.shape[0] > 4 * 90


def test_baseline_folder_brings_its_own_pixel_decision(tmp_path):
    # Since the split of core/mask.py, each pixel's decision and its switches are
    # core/pixel_decision.py's: a baseline folder's copy must stand in for today's (with the
    # folder's residual.py under it), or the baseline would measure and decide as today does.
    folder = tmp_path / 'baseline'
    folder.mkdir()
    for module in (mask, residual):
        shutil.copy(module.__file__, folder)
    text = Path(pixel_decision.__file__).read_text(encoding='utf-8')
    assert '\n_NOISE_AWARE = False\n' in text
    (folder / 'pixel_decision.py').write_text(
        text.replace('\n_NOISE_AWARE = False\n', '\n_NOISE_AWARE = True\n'), encoding='utf-8')
    baseline = evaluate_mask.load_baseline(folder)
    decide = baseline.__globals__['decide_pixels']
    assert decide.__globals__['_NOISE_AWARE'] is True
    assert decide.__globals__['local_fit'].__module__ == 'baseline_residual'
    assert pixel_decision._NOISE_AWARE is False
    assert sys.modules['domplane_ros.core.pixel_decision'] is pixel_decision
    assert sys.modules['domplane_ros.core.residual'] is residual


def test_baseline_that_is_not_a_mask_module_is_refused(tmp_path, capsys):
    bad = tmp_path / 'mask.py'
    bad.write_text('x = 1\n', encoding='utf-8')
    with pytest.raises(SystemExit) as info:
        evaluate_mask.main(['--baseline', str(bad), '--out', str(tmp_path / 'out')])
    assert info.value.code == 2
    assert 'has no parallax_mask' in capsys.readouterr().err
