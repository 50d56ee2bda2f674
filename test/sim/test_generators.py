"""Tests of the random scenes and the walking sequences."""

from __future__ import annotations

from domplane_ros.sim.generators import (AHEAD_BASE_ROWS, ahead_scene, approach_sequence,
                                         random_scene, scene_sequence, SETUP_RANGES)
import numpy as np
import pytest


def test_render_is_deterministic_by_seed():
    a = random_scene(5, width=320, height=240)
    b = random_scene(5, width=320, height=240)
    c = random_scene(6, width=320, height=240)
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)
    np.testing.assert_array_equal(a.plane_left, b.plane_left)
    assert a.setup == b.setup and a.boxes == b.boxes
    assert not np.array_equal(a.left, c.left)


def test_random_scenes_are_within_the_prior_ranges():
    for seed in range(6):
        frame = random_scene(seed, width=320, height=240)
        setup = frame.setup
        for name, (low, high) in SETUP_RANGES.items():
            assert low <= getattr(setup, name) <= high
        assert 1 <= len(frame.boxes) <= 5
        assert frame.obstacle_left.any()
        assert frame.plane_left.mean() > 0.2
        # The floor is the dominant surface.
        assert frame.obstacle_left.sum() < frame.plane_left.sum()


def test_sequence_moves_the_head_and_keeps_the_model():
    frames = scene_sequence(4, seed=2, width=160, height=120, step=0.1)
    assert len(frames) == 4
    for frame in frames:
        np.testing.assert_allclose(frame.homography, frame.setup.homography())
    # The texture moves under the head from frame to frame.
    assert not np.array_equal(frames[0].left, frames[1].left)
    assert frames[0].head_pose != frames[1].head_pose
    # Boxes are fixed in the world, so they come closer as the head walks forward.
    if frames[0].boxes:
        assert frames[-1].boxes[0].z < frames[0].boxes[0].z
    # Tilt and vergence wobble, so the homography changes.
    assert not np.allclose(frames[0].homography, frames[-1].homography)


def test_empty_sequence_raises_value_error():
    with pytest.raises(ValueError, match='n_frames'):
        scene_sequence(0, seed=0)


def _near_band(mask: np.ndarray) -> np.ndarray:
    return mask[mask.shape[0] - mask.shape[0] // 3:]


def test_the_box_ahead_fills_the_near_field_above_a_strip_of_floor():
    for seed in range(4):
        frame = ahead_scene(seed, width=320, height=240)
        assert len(frame.boxes) == 1
        for name, (low, high) in SETUP_RANGES.items():
            assert low <= getattr(frame.setup, name) <= high
        # A large part of the view's bottom third is the box, and the floor is seen below it.
        assert _near_band(frame.obstacle_left).mean() > 0.15
        column = frame.setup.width // 2
        rows = np.flatnonzero(frame.obstacle_left[:, column])
        assert rows.size and rows.max() < AHEAD_BASE_ROWS[1] * frame.setup.height + 2
        assert frame.plane_left[rows.max() + 2:, column].all()


def test_an_approach_brings_the_box_down_the_view_with_the_truth_fixed():
    frames = approach_sequence(3, seed=2, travel=1.0, width=320, height=240)
    lowest = [np.flatnonzero(f.obstacle_left.any(axis=1)).max() for f in frames]
    assert lowest[0] < lowest[1] < lowest[2]
    assert _near_band(frames[0].obstacle_left).mean() < _near_band(frames[2].obstacle_left).mean()
    for frame in frames:
        np.testing.assert_allclose(frame.homography, frames[0].homography)
    last = ahead_scene(2, width=320, height=240)
    np.testing.assert_array_equal(frames[-1].obstacle_left, last.obstacle_left)
    with pytest.raises(ValueError, match='n_frames'):
        approach_sequence(1, seed=0)
