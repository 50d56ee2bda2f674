"""The evaluation tool and its library on the real pairs in test/data (no shared data needed).

The bounds below are the measured figures with a margin, not the targets: where the product
meets a target the test pins what it measures, and where it misses one (chessboards) the
target is a strict xfail, so a fix shows up as an unexpected pass.
"""

from __future__ import annotations

import csv
from dataclasses import replace
import importlib.util
import math
from pathlib import Path

import cv2
from domplane_ros.config import one_shot_search, PlaneNodeConfig, VerificationSettings
from domplane_ros.core.homography import apply_homography, fit_homography
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools import evaluate
from domplane_ros.tools.evaluation import datasets, methods, references, tables
import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[1] / 'data'
KITTI = DATA / references.KITTI_DIR
OPENCV = DATA / references.OPENCV_DIR


@pytest.fixture(scope='module')
def kitti_reference() -> references.KittiReference:
    return references.kitti_reference(KITTI)


@pytest.fixture(scope='module')
def kitti_cases() -> list[datasets.Case]:
    return datasets.evaluate_kitti(KITTI, repeats=1, full_image=False)


def test_test_data_is_small_and_licensed():
    total = sum(p.stat().st_size for p in DATA.rglob('*') if p.is_file())
    assert total < 3_000_000
    assert (KITTI / 'LICENSE.stereo-transformer').is_file()
    assert (OPENCV / 'LICENSE.opencv_samples').is_file()
    assert 'CC BY-NC-SA 3.0' in (DATA / 'README.md').read_text(encoding='utf-8')


def test_kitti_reference_reproduces_the_shared_readme(kitti_reference):
    # the shared data folder/README.md: d = 0.00180 x + 0.32364 y - 57.22, about 56 % within 1 px.
    plane = kitti_reference.plane
    assert plane.a == pytest.approx(0.00180, abs=1e-5)
    assert plane.b == pytest.approx(0.32364, abs=1e-4)
    assert plane.c == pytest.approx(-57.22, abs=0.01)
    assert 0.54 < plane.inlier_fraction < 0.57
    known = np.count_nonzero(np.isfinite(kitti_reference.disparity))
    assert np.count_nonzero(kitti_reference.road) == pytest.approx(
        plane.inlier_fraction * known, abs=1)
    assert not np.any(kitti_reference.road & kitti_reference.off_road)
    # Off-road (> 3 px from the road plane): the car, poles and buildings, about 40 %.
    assert 0.3 < np.count_nonzero(kitti_reference.off_road) / known < 0.5


def test_disparity_plane_homography_shifts_by_the_disparity():
    plane = references.DisparityPlane(a=0.002, b=0.3, c=-50.0, inlier_fraction=1.0)
    points = np.array([[10.0, 200.0], [600.0, 300.0]])
    disparity = 0.002 * points[:, 0] + 0.3 * points[:, 1] - 50.0
    mapped = apply_homography(plane.homography(), points)
    np.testing.assert_allclose(mapped[:, 0], points[:, 0] - disparity)
    np.testing.assert_allclose(mapped[:, 1], points[:, 1])


def test_disparity_plane_fit_recovers_an_exact_plane_with_outliers():
    rng = np.random.default_rng(3)
    ys, xs = np.mgrid[0:60, 0:80]
    disparity = 0.01 * xs + 0.2 * ys + 5.0
    outliers = rng.random(disparity.shape) < 0.3
    disparity[outliers] += rng.uniform(5, 30, np.count_nonzero(outliers))
    disparity[rng.random(disparity.shape) < 0.5] = np.nan
    plane = references.fit_disparity_plane(disparity, iterations=200)
    assert (plane.a, plane.b, plane.c) == pytest.approx((0.01, 0.2, 5.0), abs=1e-9)
    with pytest.raises(ValueError, match='at least 3'):
        references.fit_disparity_plane(np.full((4, 4), np.nan))


@pytest.mark.parametrize('number, floor_px', [('01', 0.55), ('02', 1.32)])
def test_chessboard_reference_fits_its_corners(number, floor_px):
    left = cv2.imread(str(OPENCV / f'left{number}.jpg'), cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(str(OPENCV / f'right{number}.jpg'), cv2.IMREAD_GRAYSCALE)
    corners = references.chessboard_corners(left, right)
    assert corners is not None
    src, dst = corners
    assert src.shape == dst.shape == (54, 2)
    reference = fit_homography(src, dst)
    error = references.mean_transfer_px(reference, src, dst)
    # Lens distortion: a homography fits the corners to about 0.5-1.7 px only.
    assert error == pytest.approx(floor_px, abs=0.05)
    assert error < datasets.CHESSBOARD_TARGET_PX


def test_product_on_kitti_meets_the_road_target(kitti_cases):
    (case,) = kitti_cases
    ours = case.figures['ours']
    assert ours['ok'] == 1.0
    # Measured 0.51 px (session 12; target 1.5 px); the warm start keeps it.
    assert ours['error_px'] < 0.7
    assert ours['error_px'] < datasets.KITTI_TARGET_PX
    assert ours['warm_error_px'] < 0.7
    # Measured: road IoU 0.86 (0.79 with the NCC mask before issue 12), off-road (> 3 px)
    # marked obstacle 0.63 (0.79 before: the residual-parallax mask leaves the far buildings
    # and trees at and above the horizon unknown), off-road marked plane 0.026, 174 inliers
    # of 324 corners.
    assert ours['road_iou'] > 0.8
    assert ours['off_road_recall'] > 0.55
    assert ours['off_road_as_plane'] < 0.05, ours
    assert ours['inliers'] > 120
    assert case.runs['ours'].mask.shape == case.left.shape


@pytest.mark.parametrize('prior, most_px', [(datasets.KITTI_PRIOR, 0.6), (None, 1.5)],
                         ids=['kitti_prior', 'default_prior'])
def test_whole_kitti_image_meets_the_road_targets(kitti_reference, prior, most_px):
    # Issue 11's targets, whole image, no ROI, from a cold start: under 0.6 px with a
    # KITTI-like prior, 1.5 px with the default one. Measured 0.51 / 0.50 px (session 12; 0.48
    # / 0.49 px before the refinement sampled gradients down to 4) with the search's winner
    # refined photometrically at full resolution (0.67 / 0.60 px at 640 px wide).
    config = PlaneNodeConfig() if prior is None else replace(PlaneNodeConfig(), prior=prior)
    left = datasets.read_gray(KITTI / 'left.png')
    right = datasets.read_gray(KITTI / 'right.png')
    result = PlanePipeline(one_shot_search(config)).process(left, right, 0)
    assert result.ok, result.reason
    ys, xs = np.nonzero(kitti_reference.road)
    road = np.stack([xs, ys], axis=1).astype(np.float64)
    truth = apply_homography(kitti_reference.plane.homography(), road)
    error = np.linalg.norm(apply_homography(result.homography, road) - truth, axis=1).mean()
    assert error < most_px


def test_orb_magsac_baseline_on_kitti(kitti_cases):
    (case,) = kitti_cases
    orb = case.figures['orb_magsac']
    assert orb['ok'] == 1.0
    assert math.isnan(orb['warm_ms'])
    # Measured: 0.99 px, 199 inliers of 1013 cross-checked matches in the same ROI.
    assert orb['error_px'] < 1.5
    assert orb['inliers'] > 100
    assert orb['points'] > 500
    assert orb['time_ms'] > 0


def test_orb_magsac_without_features_fails_as_a_value():
    flat = np.full((120, 160), 128, np.uint8)
    run = methods.run_orb_magsac(flat, flat, repeats=1)
    assert not run.ok
    assert run.n_inliers == 0
    assert 'no homography' in run.reason


@pytest.mark.xfail(strict=True, reason='chessboard target missed (docs/METHOD.md, '
                   'Chessboards, round 11): in verification.plane any 1 of 13 boards is '
                   'published (07, 0.67 px), 0 wrong; 01 and 02 here are refused: the truth '
                   'explains 0.17 of the textured image (< verification.min_score 0.25) and '
                   '0.67 and 0.73 of its own region (< 0.8, the region score added for a '
                   'board in a textured room), and lies 0.38 and 0.35 px off one plane after '
                   'the lens fit (> 0.3); no threshold was set on the boards')
def test_product_on_chessboards_meets_the_board_target():
    # The product alone, as evaluate_chessboards runs it (its cold start; ORB is no target).
    config = one_shot_search(PlaneNodeConfig(
        prior=datasets.CHESSBOARD_PRIOR,
        verification=VerificationSettings(plane=datasets.CHESSBOARD_PLANE)))
    for number in ('01', '02'):
        left = references.read_gray(OPENCV / f'left{number}.jpg')
        right = references.read_gray(OPENCV / f'right{number}.jpg')
        src, dst = references.chessboard_corners(left, right)
        result = PlanePipeline(config).process(left, right, 0)
        assert result.ok, result.reason
        assert references.mean_transfer_px(result.homography, src, dst) < \
            datasets.CHESSBOARD_TARGET_PX


def test_markdown_table_marks_failures_and_missing_values():
    table = tables.markdown_table(['a', 'b', 'c'], [[1.234, math.inf, math.nan]])
    assert table.splitlines()[2] == '| 1.23 | fail | - |'


def test_main_writes_tables_csvs_and_pictures(tmp_path, capsys):
    out = tmp_path / 'eval'
    # matplotlib is in requirements.txt but not a declared ROS dependency of the package.
    pictures = importlib.util.find_spec('matplotlib') is not None
    rc = evaluate.main(['--data', str(DATA), '--out', str(out), '--scenes', '2',
                        '--sequences', '1', '--repeats', '1']
                       + ([] if pictures else ['--no-pictures']))
    assert rc == 0
    text = capsys.readouterr().out
    for heading in ('## kitti', '## chessboards', '## rendered scenes', '## rendered sequences',
                    '## targets'):
        assert heading in text
    assert 'books: not in' in text and 'ensenso: not in' in text
    assert 'kitti: road error' in text
    for name in ('kitti.csv', 'chessboards.csv', 'rendered.csv', 'rendered_stream.csv'):
        with open(out / name, encoding='utf-8') as stream:
            rows = list(csv.DictReader(stream))
        assert {row['method'] for row in rows} == {'ours', 'orb_magsac'}
        # Stream rows have only a warm time (ours) or only a time (baseline).
        assert all(np.nanmax([float(row['time_ms']), float(row['warm_ms'])]) > 0
                   for row in rows)
    summary = (out / 'summary.md').read_text(encoding='utf-8')
    assert '## targets' in summary and 'kitti: road error' in summary
    for name in ('contact_sheet.png', 'errors.png') if pictures else ():
        image = cv2.imread(str(out / name))
        assert image is not None and image.shape[0] > 300 and image.shape[1] > 600
