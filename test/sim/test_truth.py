"""Tests of the scoring against a rendered frame's truth."""

from __future__ import annotations

import math

from domplane_ros.sim.model import Box, CameraSetup
from domplane_ros.sim.render import render_stereo
from domplane_ros.sim.truth import (every_floor_pixel, floor_points, relock_runs,
                                    transfer_error_px)
import numpy as np
import pytest

SETUP = CameraSetup(focal_px=200.0, baseline_over_height=0.2, tilt_deg=30.0, vergence_deg=1.0,
                    width=160, height=120)


@pytest.fixture(scope='module')
def frame():
    return render_stereo(SETUP, (Box(x=0.1, z=2.5, width=0.5, depth=0.4, height=0.5),),
                         noise_std=0.0)


def test_floor_points_are_visible_floor_pixels_on_the_grid(frame):
    points = floor_points(frame, step=8, offset=4)
    xs, ys = points[:, 0].astype(int), points[:, 1].astype(int)
    assert points.dtype == np.float64 and points.shape[1] == 2 and points.shape[0] > 50
    assert np.all(frame.plane_left[ys, xs] & frame.visible_in_right[ys, xs])
    assert np.all(xs % 8 == 4) and np.all(ys % 8 == 4)
    # Raster order: rows first.
    assert np.all(np.diff(ys) >= 0)


def test_every_floor_pixel_takes_every_kth_in_raster_order(frame):
    every = every_floor_pixel(frame)
    assert every.shape[0] == np.count_nonzero(frame.plane_left & frame.visible_in_right)
    np.testing.assert_array_equal(every_floor_pixel(frame, 7), every[::7])


def test_transfer_error_is_zero_for_the_truth_and_inf_without_a_homography(frame):
    points = floor_points(frame)
    assert transfer_error_px(frame.homography, frame, points) == pytest.approx(0.0, abs=1e-9)
    shifted = np.array([[1.0, 0.0, 2.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ frame.homography
    assert transfer_error_px(shifted, frame, points) == pytest.approx(2.0)
    assert transfer_error_px(None, frame, points) == math.inf
    assert transfer_error_px(frame.homography, frame, np.zeros((0, 2))) == math.inf


def test_relock_runs_counts_frames_between_losses_and_relocks():
    assert relock_runs([False, False, True, True]) == []
    assert relock_runs([True, False, False, True, False, True]) == [2, 1]
    assert relock_runs([True, True, False, False]) == [2]
    # Drop-out frames (blank input) do not count: re-lock frames after the input came back.
    assert relock_runs([True, False, False, False, True],
                       [False, True, True, False, False]) == [1]
    assert relock_runs([True, False, True], [False, True, False]) == [0]
