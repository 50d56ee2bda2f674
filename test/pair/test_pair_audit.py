"""plane_pair and the audit's findings 13 (16-bit files) and 20 (the swap hint)."""

from __future__ import annotations

from pathlib import Path

import cv2
from domplane_ros.pair import cli
from domplane_ros.pair.files import image_pairs
from domplane_ros.stream.status import SWAP_HINT_ARGUMENTS, SWAP_HINT_TOPICS
import numpy as np

KITTI = Path(__file__).resolve().parents[1] / 'data' / 'kitti2015_000046'
# KITTI's published rig (f about 721 px, baseline 0.54 m at 1.65 m, looking ahead), as in
# test_pair_cli.py.
KITTI_OPTIONS = ['--focal-px', '650', '800', '--baseline-over-height', '0.25', '0.40',
                 '--tilt-deg', '-5', '5', '--vergence-deg', '-1', '1',
                 '--roi', '0', '0.55', '1', '1']


def test_swapped_files_are_told_to_swap_the_arguments_not_topics(capsys):
    # The right image given as LEFT: the road's disparity shrinks toward the bottom.
    args = [str(KITTI / 'right.png'), str(KITTI / 'left.png')] + KITTI_OPTIONS
    rc = cli.main(args)
    out = capsys.readouterr().out
    assert rc == cli.EXIT_NO_PLANE, out
    assert 'appear swapped' in out and SWAP_HINT_ARGUMENTS in out
    assert 'topics' not in out
    # The reason itself (what the CSV and the diagnostics carry) is the same for every tool.
    config = cli.configure(overrides={cli.RANGE_OPTIONS[k]: v for k, v in (
        ('focal_px', (650, 800)), ('baseline_over_height', (0.25, 0.4)),
        ('tilt_deg', (-5, 5)), ('vergence_deg', (-1, 1)), ('roi', (0, 0.55, 1, 1)))})
    (outcome,) = cli.run_pairs(image_pairs(args[0], args[1]), config)
    assert outcome.result.reason.endswith(SWAP_HINT_TOPICS)


def _write16(path: Path, gray: np.ndarray) -> None:
    assert cv2.imwrite(str(path), gray.astype(np.uint16) << 4)   # a 12-bit sensor's PNG


def test_16_bit_files_follow_image_mono16_bits(tmp_path, capsys):
    left = cv2.imread(str(KITTI / 'left.png'), cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(str(KITTI / 'right.png'), cv2.IMREAD_GRAYSCALE)
    _write16(tmp_path / 'left.png', left)
    _write16(tmp_path / 'right.png', right)
    files = [str(tmp_path / 'left.png'), str(tmp_path / 'right.png')]
    assert cli.main([str(KITTI / 'left.png'), str(KITTI / 'right.png')] + KITTI_OPTIONS) == 0
    eight_bit = capsys.readouterr().out
    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters:\n    image.mono16_bits: 12\n')
    # With the sensor's bits: the very pair of 8-bit files, the same homography.
    assert cli.main(files + KITTI_OPTIONS + ['--params-file', str(params)]) == 0
    twelve = capsys.readouterr().out
    assert twelve.split('\n')[1:4] == eight_bit.split('\n')[1:4]
    assert 'warning' not in twelve
    # Read as 16 bits: a one-line warning naming the parameter.
    cli.main(files + KITTI_OPTIONS)
    out = capsys.readouterr().out
    (line,) = [text for text in out.split('\n') if 'warning' in text]
    assert 'image.mono16_bits' in line and '(12 fit the data)' in line
