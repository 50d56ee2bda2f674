"""Tests of the ray caster, its ground truth and the scene model's checks."""

from __future__ import annotations

import cv2
from domplane_ros.core import prior
from domplane_ros.sim.model import BACKGROUNDS, Box, CameraSetup, StereoFrame
from domplane_ros.sim.render import render_stereo
from domplane_ros.sim.textures import (FAINT_TILE_KINDS, FAINT_TILE_SIZES, FLOOR_KINDS,
                                       SIZED_FLOOR_KINDS, SIZED_FLOOR_SIZES, texture_pyramid)
import numpy as np
import pytest

SETUP = CameraSetup(focal_px=320.0, baseline_over_height=0.2, tilt_deg=30.0,
                    vergence_deg=1.0, width=320, height=240)
BOXES = (Box(x=0.2, z=2.5, width=0.5, depth=0.4, height=0.5, yaw_deg=20.0),
         Box(x=-1.0, z=4.5, width=0.8, depth=0.7, height=0.8, yaw_deg=-10.0))


def _warp_right_to_left(frame: StereoFrame) -> np.ndarray:
    """Warp the right image into the left view with the true floor homography."""
    height, width = frame.left.shape
    return cv2.warpPerspective(frame.right, frame.homography, (width, height),
                               flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)


def _interior(shape: tuple[int, int], margin: int) -> np.ndarray:
    inside = np.zeros(shape, bool)
    inside[margin:-margin, margin:-margin] = True
    return inside


def _erode(mask: np.ndarray, px: int) -> np.ndarray:
    kernel = np.ones((2 * px + 1, 2 * px + 1), np.uint8)
    return cv2.erode(mask.astype(np.uint8), kernel).astype(bool)


def test_homography_is_the_prior_model():
    for setup in (SETUP, CameraSetup(850.0, 0.05, 12.0, -2.0, 640, 480)):
        np.testing.assert_allclose(
            setup.homography(),
            prior.plane_homography(setup.focal_px, setup.baseline_over_height, setup.tilt_deg,
                                   setup.vergence_deg, setup.width, setup.height))
    frame = render_stereo(SETUP, BOXES, noise_std=0.0)
    np.testing.assert_allclose(frame.homography, SETUP.homography())


@pytest.mark.parametrize('floor', FLOOR_KINDS)
@pytest.mark.parametrize('background', BACKGROUNDS)
def test_floor_matches_after_warp_and_boxes_do_not(floor, background):
    # The wall is close enough to be seen above the far floor.
    frame = render_stereo(SETUP, BOXES, floor=floor, noise_std=0.0, seed=3,
                          background=background, wall_distance=5.0)
    if background == 'wall':
        assert np.mean(~frame.plane_left & ~frame.obstacle_left) > 0.02
    warped = _warp_right_to_left(frame).astype(np.float64)
    diff = np.abs(warped - frame.left)
    inside = _interior(frame.left.shape, 4)
    # Stay a couple of pixels away from the occlusion boundaries, where bilinear warping mixes
    # box and floor pixels.
    plane = _erode(frame.plane_left & frame.visible_in_right, 2) & inside
    obstacle = _erode(frame.obstacle_left, 2) & inside
    assert plane.sum() > 0.3 * plane.size
    assert obstacle.sum() > 500
    plane_diff = diff[plane].mean()
    obstacle_diff = diff[obstacle].mean()
    assert plane_diff < 2.5, plane_diff
    assert obstacle_diff > 8.0 * plane_diff, (plane_diff, obstacle_diff)
    # Most floor pixels match to a few grey levels, most box pixels do not.
    assert np.mean(diff[plane] < 6.0) > 0.9
    assert np.mean(diff[obstacle] > 6.0) > 0.6


def test_ground_truth_masks_are_consistent():
    frame = render_stereo(SETUP, BOXES, noise_std=0.0)
    assert frame.left.shape == frame.right.shape == (SETUP.height, SETUP.width)
    assert frame.left.dtype == frame.right.dtype == np.uint8
    for mask in (frame.plane_left, frame.visible_in_right, frame.obstacle_left):
        assert mask.shape == frame.left.shape and mask.dtype == bool
    assert not np.any(frame.plane_left & frame.obstacle_left)
    assert not np.any(frame.visible_in_right & ~frame.plane_left)
    # Floor pixels whose true right position leaves the right image are not visible in it.
    ys, xs = np.nonzero(frame.plane_left)
    mapped = frame.homography @ np.stack([xs, ys, np.ones_like(xs)])
    rx, ry = mapped[0] / mapped[2], mapped[1] / mapped[2]
    outside = (rx < 0) | (rx > SETUP.width - 1) | (ry < 0) | (ry > SETUP.height - 1)
    assert outside.any()
    assert not frame.visible_in_right[ys[outside], xs[outside]].any()
    # Some floor pixels inside the right image are hidden behind a box from the right camera:
    # exactly the occlusion label, which is floor, not visible, and never outside the image.
    hidden = frame.plane_left & ~frame.visible_in_right
    assert np.count_nonzero(hidden[ys[~outside], xs[~outside]]) > 20
    occluded = frame.occluded_in_right
    assert occluded.dtype == bool and occluded.shape == frame.left.shape
    assert not np.any(occluded & frame.visible_in_right)
    assert not np.any(occluded & ~frame.plane_left)
    assert not occluded[ys[outside], xs[outside]].any()
    assert np.array_equal(occluded[ys[~outside], xs[~outside]], hidden[ys[~outside], xs[~outside]])
    # The right camera is to the right: hidden floor lies left of a box in its row.
    rows, columns = np.nonzero(occluded)
    box_right = [frame.obstacle_left[row, column + 1:].any() for row, column in zip(rows, columns)]
    assert np.mean(box_right) > 0.99


def test_box_faces_turned_away_from_the_right_camera_are_hidden():
    setup = CameraSetup(400.0, 0.4, 20.0, 0.0, 320, 240)
    # The box's left face (x = 0.2) lies between the cameras (x = 0 and 0.4): the left camera
    # sees it, the right one does not. A box right of both cameras shows them the same faces.
    between = render_stereo(setup, (Box(0.45, 3.0, 0.5, 0.5, 0.6),), noise_std=0.0)
    beside = render_stereo(setup, (Box(1.2, 3.0, 0.5, 0.5, 0.6),), noise_std=0.0)
    for frame in (between, beside):
        assert not np.any(frame.obstacle_hidden & ~frame.obstacle_left)
    assert not beside.obstacle_hidden.any() and beside.obstacle_left.sum() > 2000
    rows, columns = np.nonzero(between.obstacle_hidden)
    assert rows.size > 200
    # The hidden face is the left one: left of the middle of the box in its row.
    middle = [np.median(np.nonzero(between.obstacle_left[row])[0]) for row in rows]
    assert np.mean(columns < np.array(middle)) > 0.95


def test_occluded_floor_does_not_match():
    setup = CameraSetup(320.0, 0.4, 30.0, 0.0, 320, 240)
    boxes = (Box(x=0.0, z=2.2, width=0.5, depth=0.5, height=0.7),)
    frame = render_stereo(setup, boxes, floor='random', noise_std=0.0)
    ys, xs = np.nonzero(frame.plane_left)
    mapped = frame.homography @ np.stack([xs, ys, np.ones_like(xs)])
    rx, ry = mapped[0] / mapped[2], mapped[1] / mapped[2]
    inside = (rx >= 2) & (rx <= setup.width - 3) & (ry >= 2) & (ry <= setup.height - 3)
    occluded = np.zeros_like(frame.plane_left)
    occluded[ys[inside], xs[inside]] = True
    occluded &= ~frame.visible_in_right
    occluded = _erode(occluded, 2)
    assert occluded.sum() > 200
    diff = np.abs(_warp_right_to_left(frame).astype(np.float64) - frame.left)
    assert diff[occluded].mean() > 10.0


def test_gain_and_offset_apply_to_the_right_camera():
    plain = render_stereo(SETUP, BOXES, noise_std=0.0)
    shifted = render_stereo(SETUP, BOXES, noise_std=0.0, gain=1.2, offset=-15.0)
    np.testing.assert_array_equal(plain.left, shifted.left)
    expected = np.clip(np.rint(1.2 * plain.right.astype(np.float64) - 15.0), 0, 255)
    assert np.abs(shifted.right - expected).max() <= 2.0


def test_noise_has_the_requested_std():
    clean = render_stereo(SETUP, BOXES, noise_std=0.0)
    noisy = render_stereo(SETUP, BOXES, noise_std=3.0)
    residual = noisy.left.astype(np.float64) - clean.left
    assert 2.6 < residual.std() < 3.4
    assert abs(residual.mean()) < 0.2


def test_blur_smooths_the_images():
    sharp = render_stereo(SETUP, BOXES, noise_std=0.0, blur_sigma=0.0)
    blurred = render_stereo(SETUP, BOXES, noise_std=0.0, blur_sigma=1.5)

    def gradient_energy(image: np.ndarray) -> float:
        return float(np.abs(np.diff(image.astype(np.float64), axis=1)).mean())

    assert gradient_energy(blurred.left) < 0.8 * gradient_energy(sharp.left)


def test_bad_arguments_raise_value_error():
    with pytest.raises(ValueError, match='floor'):
        render_stereo(SETUP, floor='carpet')
    with pytest.raises(ValueError, match='background'):
        render_stereo(SETUP, background='sea')
    with pytest.raises(ValueError, match='positive'):
        Box(0.0, 2.0, -1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match='focal_px'):
        CameraSetup(0.0, 0.1, 20.0, 0.0)
    with pytest.raises(ValueError, match='finite'):
        CameraSetup(500.0, float('nan'), 20.0, 0.0)
    with pytest.raises(ValueError, match='box_contrast'):
        render_stereo(SETUP, box_contrast=1.5)


def test_box_contrast_makes_plain_faces_and_leaves_the_rest_as_drawn():
    boxes = [Box(0.0, 4.0, 1.0, 1.0, 1.5, 30.0)]
    drawn = render_stereo(SETUP, boxes, floor='checker', seed=3)
    same = render_stereo(SETUP, boxes, floor='checker', seed=3, box_contrast=1.0)
    plain = render_stereo(SETUP, boxes, floor='checker', seed=3, box_contrast=0.0)
    assert np.array_equal(drawn.left, same.left) and np.array_equal(drawn.right, same.right)
    box = cv2.erode(drawn.obstacle_left.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert box.sum() > 500 and np.array_equal(plain.obstacle_left, drawn.obstacle_left)
    near_box = cv2.dilate(drawn.obstacle_left.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    floor = drawn.plane_left & ~near_box
    assert np.array_equal(plain.left[floor], drawn.left[floor])
    # Plain faces: only the shade (per face) and the pixel noise vary; the drawn ones vary.
    gx = np.abs(cv2.Sobel(drawn.left, cv2.CV_32F, 1, 0))
    gx_plain = np.abs(cv2.Sobel(plain.left, cv2.CV_32F, 1, 0))
    assert np.median(gx_plain[box]) < 0.3 * np.median(gx[box])


@pytest.mark.parametrize('floor', FAINT_TILE_KINDS)
def test_faint_tiles_have_their_tile_size_faint_texture_and_match_after_warp(floor):
    raster = texture_pyramid(floor, 0)[0]
    tile = FAINT_TILE_SIZES[floor]
    rows = raster.mean(axis=1)
    joint_rows = rows[np.arange(raster.shape[0]) % tile == 0]
    mid_rows = rows[np.arange(raster.shape[0]) % tile == tile // 2]
    # Joints every `tile` texels, lighter than tiles_plain's dark ones; faint tile surface.
    assert np.all(joint_rows < mid_rows.min() - 0.03)
    assert joint_rows.mean() > texture_pyramid('tiles_plain', 0)[0].min() + 0.15
    interior = raster[tile // 4:3 * tile // 4, tile // 4:3 * tile // 4]
    assert interior.std() < 0.04
    frame = render_stereo(SETUP, BOXES, floor=floor, noise_std=0.0, seed=3)
    warped = _warp_right_to_left(frame).astype(np.float64)
    plane = _erode(frame.plane_left & frame.visible_in_right, 2) & _interior(
        frame.left.shape, 4)
    assert np.abs(warped - frame.left)[plane].mean() < 1.5


@pytest.mark.parametrize('floor', SIZED_FLOOR_KINDS)
def test_sized_floors_repeat_at_their_size(floor):
    base, size = SIZED_FLOOR_SIZES[floor]
    raster = texture_pyramid(floor, 0)[0]
    # The joints (tiles, plank sides: the darkest columns) or the square edges (checker: the
    # largest steps along a row) lie every `size` texels, not at the default kind's size.
    n = raster.shape[0]
    if base == 'checker':
        edges = np.argsort(-np.abs(np.diff(raster[5].astype(np.float64))))[:n // size]
        offsets = (edges + 1) % size
    else:
        offsets = np.argsort(raster.mean(axis=0))[:n // size] % size
    assert np.all(np.minimum(offsets, size - offsets) <= 2), (floor, offsets)
    frame = render_stereo(SETUP, BOXES, floor=floor, noise_std=0.0, seed=3)
    warped = _warp_right_to_left(frame).astype(np.float64)
    plane = _erode(frame.plane_left & frame.visible_in_right, 2) & _interior(
        frame.left.shape, 4)
    assert np.abs(warped - frame.left)[plane].mean() < 2.0
