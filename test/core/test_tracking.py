"""Temporal prediction: camera-motion fits and H_t ~ M_right H_{t-1} M_left^-1."""

from __future__ import annotations

import math

import cv2
from domplane_ros.config import TrackingConfig
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.prior import intrinsics, plane_homography
from domplane_ros.core.tracking import (camera_motion, fit_camera_motion, predict_plane_homography,
                                        track_forward, track_points)
from domplane_ros.sim.generators import random_scene
import numpy as np
import pytest

W, H = 640, 480


def _rotation(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = math.radians(rng.uniform(-max_deg, max_deg))
    r, _ = cv2.Rodrigues(axis * angle)
    return r


@pytest.mark.parametrize('seed', range(5))
def test_prediction_is_exact_for_pure_camera_rotations(seed):
    """Rotate both cameras about their centres; the propagated H maps the new views exactly."""
    rng = np.random.default_rng(seed)
    f, b, tilt, verg = 600.0, 0.2, 30.0, 1.0
    k = intrinsics(f, W, H)
    h_prev = plane_homography(f, b, tilt, verg, W, H)
    # Plane points n . X = 1 in left-camera coordinates, n = (0, cos t, sin t).
    t = math.radians(tilt)
    normal = np.array([0.0, math.cos(t), math.sin(t)])
    pix = np.column_stack([rng.uniform(0, W - 1, 200), rng.uniform(H / 2, H - 1, 200),
                           np.ones(200)])
    rays = (np.linalg.inv(k) @ pix.T).T
    points = rays / (rays @ normal)[:, None]
    v = math.radians(verg)
    r_v = np.array([[math.cos(v), 0, math.sin(v)], [0, 1, 0], [-math.sin(v), 0, math.cos(v)]])
    centre = np.array([b, 0.0, 0.0])
    r_left = _rotation(rng, 5.0)
    r_right = _rotation(rng, 5.0)

    def project(cam_points: np.ndarray) -> np.ndarray:
        p = (k @ cam_points.T).T
        return p[:, :2] / p[:, 2:]

    left_prev = project(points)
    right_prev = project((r_v @ (points - centre).T).T)
    assert np.allclose(apply_homography(h_prev, left_prev), right_prev, atol=1e-8)
    left_now = project((r_left @ points.T).T)
    right_now = project((r_right @ r_v @ (points - centre).T).T)
    m_left = k @ r_left @ np.linalg.inv(k)
    m_right = k @ r_right @ np.linalg.inv(k)
    h_now = predict_plane_homography(h_prev, m_left, m_right)
    assert h_now is not None and h_now[2, 2] == pytest.approx(1.0)
    assert np.max(np.abs(apply_homography(h_now, left_now) - right_now)) < 1e-6
    # The stale homography is far off: the prediction matters.
    assert np.mean(np.linalg.norm(apply_homography(h_prev, left_now) - right_now,
                                  axis=1)) > 1.0


def test_motion_fit_recovers_the_homography_despite_outliers():
    rng = np.random.default_rng(3)
    m = np.array([[1.01, 0.02, 12.0], [-0.015, 0.99, -7.0], [2e-5, -1e-5, 1.0]])
    src = rng.uniform([0, 0], [W - 1, H - 1], (300, 2))
    dst = apply_homography(m, src) + rng.normal(0, 0.1, (300, 2))
    bad = rng.random(300) < 0.3
    dst[bad] += rng.uniform(-40, 40, (int(bad.sum()), 2))
    motion = fit_camera_motion(src, dst)
    assert motion.ok, motion.reason
    assert motion.n_inliers >= 0.65 * 300
    err = np.linalg.norm(apply_homography(motion.homography, src) - apply_homography(m, src),
                         axis=1)
    assert err.max() < 0.3


def test_motion_fit_rejects_too_few_tracks_and_poor_inlier_ratios():
    rng = np.random.default_rng(4)
    src = rng.uniform([0, 0], [W - 1, H - 1], (10, 2))
    few = fit_camera_motion(src, src + 3.0, min_tracks=20)
    assert not few.ok and 'too few tracks' in few.reason
    src = rng.uniform([0, 0], [W - 1, H - 1], (200, 2))
    noise = fit_camera_motion(src, rng.uniform([0, 0], [W - 1, H - 1], (200, 2)))
    assert not noise.ok
    with pytest.raises(ValueError, match='source and target'):
        fit_camera_motion(src, src[:5])


def test_tracking_an_image_warp_recovers_it():
    """LK tracks of real texture through a known warp give the warp back (sub-pixel)."""
    frame = random_scene(11, floor='random', n_boxes=0)
    m = np.array([[0.995, -0.03, 14.0], [0.025, 1.0, 9.0], [1e-5, 2e-5, 1.0]])
    warped = cv2.warpPerspective(frame.left, m, (W, H), flags=cv2.INTER_LINEAR)
    corners = cv2.goodFeaturesToTrack(frame.left, 300, 0.01, 8).reshape(-1, 2).astype(float)
    src, dst = track_points(frame.left, warped, corners)
    assert src.shape[0] > 100
    motion = camera_motion(frame.left, warped, corners, TrackingConfig())
    assert motion.ok, motion.reason
    inside = (src[:, 0] > 40) & (src[:, 0] < W - 40) & (src[:, 1] > 40) & (src[:, 1] < H - 40)
    err = np.linalg.norm(apply_homography(motion.homography, src[inside])
                         - apply_homography(m, src[inside]), axis=1)
    assert np.median(err) < 0.2, np.median(err)


def test_track_points_validates_inputs():
    img = np.zeros((20, 30), np.uint8)
    with pytest.raises(ValueError, match='shapes differ'):
        track_points(img, np.zeros((21, 30), np.uint8), np.zeros((1, 2)))
    with pytest.raises(ValueError, match='uint8'):
        track_points(img.astype(np.float32), img, np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r'\(N, 2\)'):
        track_points(img, img, np.zeros((3, 3)))
    src, dst = track_points(img, img, np.empty((0, 2)))
    assert src.shape == dst.shape == (0, 2)


def test_forward_tracking_recovers_a_warp_and_uses_the_guess():
    """Forward-only LK through a known warp lands on the warped points (sub-pixel)."""
    frame = random_scene(11, floor='random', n_boxes=0)
    m = np.array([[0.995, -0.03, 14.0], [0.025, 1.0, 9.0], [1e-5, 2e-5, 1.0]])
    warped = cv2.warpPerspective(frame.left, m, (W, H), flags=cv2.INTER_LINEAR)
    corners = cv2.goodFeaturesToTrack(frame.left, 300, 0.01, 8).reshape(-1, 2).astype(float)
    kept, target = track_forward(frame.left, warped, corners, 11, 3)
    assert kept.size > 200 and target.shape == (kept.size, 2)
    inside = np.all((corners[kept] > 40) & (corners[kept] < [W - 40, H - 40]), axis=1)
    err = np.linalg.norm(target[inside] - apply_homography(m, corners[kept][inside]), axis=1)
    assert np.median(err) < 0.1, np.median(err)
    # A guess near the truth with no pyramid (so no search range of its own): still there.
    guess = apply_homography(m, corners) + 0.8
    kept0, target0 = track_forward(frame.left, warped, corners, 11, 0, initial=guess)
    inside0 = np.all((corners[kept0] > 40) & (corners[kept0] < [W - 40, H - 40]), axis=1)
    err0 = np.linalg.norm(target0[inside0] - apply_homography(m, corners[kept0][inside0]),
                          axis=1)
    assert np.median(err0) < 0.1, np.median(err0)
    # Without the guess and without a pyramid the 15 px motion is out of reach.
    kept1, target1 = track_forward(frame.left, warped, corners, 11, 0)
    err1 = np.linalg.norm(target1 - apply_homography(m, corners[kept1]), axis=1)
    assert np.median(err1) > 1.0, np.median(err1)


def test_track_forward_validates_inputs():
    img = np.zeros((20, 30), np.uint8)
    with pytest.raises(ValueError, match='shapes differ'):
        track_forward(img, np.zeros((21, 30), np.uint8), np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r'\(N, 2\)'):
        track_forward(img, img, np.zeros((3, 3)))
    kept, target = track_forward(img, img, np.empty((0, 2)))
    assert kept.shape == (0,) and target.shape == (0, 2)


def test_forward_backward_zero_tracks_forward_only():
    """forward_backward_px 0 keeps what forward LK keeps; a round-trip bound drops more."""
    frame = random_scene(12, floor='random', n_boxes=2)
    m = np.array([[1.0, -0.02, 6.0], [0.02, 1.0, 4.0], [0.0, 0.0, 1.0]])
    warped = cv2.warpPerspective(frame.left, m, (W, H), flags=cv2.INTER_LINEAR)
    warped[100:200, 100:300] = 255 - warped[100:200, 100:300]  # a changed region
    corners = cv2.goodFeaturesToTrack(frame.left, 300, 0.01, 8).reshape(-1, 2).astype(float)
    src, dst = track_points(frame.left, warped, corners, 11, 3, forward_backward_px=0.0)
    kept, target = track_forward(frame.left, warped, corners, 11, 3)
    assert np.array_equal(src, corners[kept]) and np.array_equal(dst, target)
    checked, _ = track_points(frame.left, warped, corners, 11, 3, forward_backward_px=0.5)
    assert 0 < checked.shape[0] < src.shape[0]
