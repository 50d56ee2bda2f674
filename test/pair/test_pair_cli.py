"""plane_pair on real image files: the KITTI pair against its ground truth, folders, bad input."""

from __future__ import annotations

import os
from pathlib import Path
import re
import shutil

import cv2
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.mask import mask_scores
from domplane_ros.pair import cli
from domplane_ros.tools.evaluation.references import kitti_reference, mean_transfer_px
import numpy as np
import pytest

KITTI = Path(__file__).resolve().parents[1] / 'data' / 'kitti2015_000046'
# KITTI's rig from its published set-up (f about 721 px, baseline 0.54 m at 1.65 m, looking
# ahead, rectified), not from the ground truth; features from the lower part of the image.
KITTI_OPTIONS = ['--focal-px', '650', '800', '--baseline-over-height', '0.25', '0.40',
                 '--tilt-deg', '-5', '5', '--vergence-deg', '-1', '1',
                 '--roi', '0', '0.55', '1', '1']
_H_LINES = re.compile(r'^(\S+): .*\n  H = \[\[(.*)\],\n\s+\[(.*)\],\n\s+\[(.*)\]\]', re.M)


@pytest.fixture(scope='module')
def reference():
    ref = kitti_reference(KITTI)
    ys, xs = np.nonzero(ref.road)
    road = np.stack([xs, ys], axis=1).astype(np.float64)
    return ref, road


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def printed_homographies(text: str) -> dict[str, np.ndarray]:
    """Return the homographies plane_pair printed, by pair name."""
    return {m.group(1): np.array([[float(v) for v in m.group(k).split(',')] for k in (2, 3, 4)])
            for m in _H_LINES.finditer(text)}


def test_kitti_pair_gives_the_ground_truth_road_plane(tmp_path, capsys, reference):
    ref, road = reference
    rc = cli.main([str(KITTI / 'left.png'), str(KITTI / 'right.png'), '--out',
                   str(tmp_path / 'out')] + KITTI_OPTIONS)
    out = capsys.readouterr().out
    assert rc == cli.EXIT_OK, out
    assert 'plane found: state locked, confidence' in out
    (h,) = printed_homographies(out).values()
    # The road plane of the ground-truth disparity; measured 0.46 px (the evaluation's bound).
    assert mean_transfer_px(h, road, apply_homography(ref.plane.homography(), road)) < 0.7
    mask = cv2.imread(str(tmp_path / 'out' / 'left_mask.png'), cv2.IMREAD_UNCHANGED)
    assert mask.shape == ref.road.shape and set(np.unique(mask)) <= {0, 127, 255}
    scores = mask_scores(mask, ref.road, ref.off_road, ref.road | ref.off_road)
    # Measured: road IoU 0.86, off-road marked obstacle 0.63 and marked plane 0.026
    # (test_evaluate.py's figures; the residual-parallax mask leaves far off-road unknown).
    assert scores['plane_iou'] > 0.8 and scores['obstacle_recall'] > 0.55
    assert scores['obstacle_as_plane'] < 0.05
    # Readable like any file the user makes (not a temporary file's 0600).
    assert (tmp_path / 'out' / 'left_mask.png').stat().st_mode & 0o044 == 0o044 & ~_umask()
    overlay = cv2.imread(str(tmp_path / 'out' / 'left_overlay.png'))
    assert overlay.shape[1] == mask.shape[1] and overlay.shape[0] > mask.shape[0] + 40


def test_a_pair_without_a_plane_prints_the_reason_and_no_homography(tmp_path, capsys):
    # KITTI's right image upside down: no plane maps the left image onto it. (With the right
    # image as it is, the default prior and the coarse alignment find the road, 1.5 px off.)
    right = tmp_path / 'right_upside_down.png'
    cv2.imwrite(str(right), cv2.imread(str(KITTI / 'right.png'))[::-1].copy())
    rc = cli.main([str(KITTI / 'left.png'), str(right), '--out', str(tmp_path / 'out')])
    out = capsys.readouterr().out
    assert rc == cli.EXIT_NO_PLANE
    assert 'left: no plane: state searching, confidence 0.00; ' in out
    assert 'not verified' in out and 'H = ' not in out
    assert not np.any(cv2.imread(str(tmp_path / 'out' / 'left_mask.png'),
                                 cv2.IMREAD_UNCHANGED))


def test_two_folders_pair_by_sorted_name_and_skip_an_unreadable_pair(tmp_path, capsys,
                                                                     reference):
    ref, road = reference
    left, right = cv2.imread(str(KITTI / 'left.png')), cv2.imread(str(KITTI / 'right.png'))
    (tmp_path / 'L').mkdir()
    (tmp_path / 'R').mkdir()
    crop = 12   # pair b: the top 12 rows cut off both images, so H moves by that shift
    cv2.imwrite(str(tmp_path / 'L' / 'a.png'), left)
    cv2.imwrite(str(tmp_path / 'R' / 'r_a.png'), right)
    cv2.imwrite(str(tmp_path / 'L' / 'b.png'), left[crop:])
    cv2.imwrite(str(tmp_path / 'R' / 'r_b.png'), right[crop:])
    cv2.imwrite(str(tmp_path / 'L' / 'c.png'), left)
    (tmp_path / 'R' / 'r_c.png').write_bytes(b'not a png')
    (tmp_path / 'L' / 'notes.txt').write_text('not an image')
    rc = cli.main([str(tmp_path / 'L'), str(tmp_path / 'R')] + KITTI_OPTIONS)
    captured = capsys.readouterr()
    assert rc == cli.EXIT_SKIPPED, captured.out
    assert 'c: skipped: right image' in captured.out
    assert '3 pairs, 2 processed, plane found in 2, 1 skipped' in captured.out
    assert captured.err.count('\n') == 1 and 'r_c.png' in captured.err
    found = printed_homographies(captured.out)
    assert sorted(found) == ['a', 'b']
    truth = ref.plane.homography()
    shift = np.eye(3)
    shift[1, 2] = -crop
    truth_b = shift @ truth @ np.linalg.inv(shift)
    road_b = road[road[:, 1] >= crop] - [0, crop]
    assert mean_transfer_px(found['a'], road, apply_homography(truth, road)) < 0.7
    assert mean_transfer_px(found['b'], road_b, apply_homography(truth_b, road_b)) < 0.7


def _run(capsys, args):
    rc = cli.main([str(a) for a in args])
    err = capsys.readouterr().err
    return rc, err


def test_bad_inputs_are_refused_with_one_line(tmp_path, capsys):
    left, right = KITTI / 'left.png', KITTI / 'right.png'
    (tmp_path / 'junk.png').write_bytes(b'\x89PNG but not really')
    small = tmp_path / 'small.png'
    cv2.imwrite(str(small), np.zeros((40, 60), np.uint8))
    (tmp_path / 'A').mkdir()
    (tmp_path / 'B').mkdir()
    shutil.copy(left, tmp_path / 'A' / '1.png')
    (tmp_path / 'E').mkdir()
    shutil.copy(right, tmp_path / 'B' / '1.png')
    shutil.copy(right, tmp_path / 'B' / '2.png')
    params = tmp_path / 'bad.yaml'
    params.write_text('/**:\n  ros__parameters:\n    prior:\n      focal_pix: [1, 2]\n')
    cases = [
        ([tmp_path / 'missing.png', right], 'left '),
        ([left, tmp_path / 'A'], 'two image files or two folders'),
        ([tmp_path / 'junk.png', right], 'not an image OpenCV can decode'),
        ([left, small], 'is 60x40'),
        ([tmp_path / 'A', tmp_path / 'B'], 'holds 1 images but right folder'),
        ([tmp_path / 'A', tmp_path / 'E'], 'holds no image files'),
        ([left, right, '--focal-px', '900', '400'], 'prior.focal_px'),
        ([left, right, '--roi', '0', '0', '2', '1'], 'features.roi'),
        ([left, right, '--params-file', params], "unknown parameter 'prior.focal_pix'"),
        ([left, right, '--fps', '0'], '--fps'),
    ]
    for args, words in cases:
        rc, err = _run(capsys, args)
        assert rc == cli.EXIT_REFUSED, args
        assert err.startswith('plane_pair: error: ') and err.count('\n') == 1, err
        assert words in err, (args, err)


def test_existing_pictures_are_not_overwritten_without_force(tmp_path, capsys):
    (tmp_path / 'left_mask.png').write_bytes(b'keep me')
    rc, err = _run(capsys, [KITTI / 'left.png', KITTI / 'right.png', '--out', tmp_path])
    assert rc == cli.EXIT_REFUSED and 'use --force' in err
    assert (tmp_path / 'left_mask.png').read_bytes() == b'keep me'
    assert not (tmp_path / 'left_overlay.png').exists()


def test_help_names_every_option_and_the_exit_codes(capsys):
    assert cli.main(['--help']) == 0
    text = capsys.readouterr().out
    for option in ('--params-file', '--focal-px', '--baseline-over-height', '--tilt-deg',
                   '--vergence-deg', '--roi', '--out', '--force', '--fps'):
        assert option in text
    assert 'f = (W/2)/tan(HFOV/2)' in text and 'Exit codes' in text
    assert cli.main(['only-one.png']) == cli.EXIT_REFUSED
