"""Rough rigs, swaps and cuts: the truth they carry is exact."""

from __future__ import annotations

from domplane_ros.core.homography import apply_homography
from domplane_ros.sim.generators import random_scene
from domplane_ros.sim.rigs import (camera_response, cut_sequence, plane_error_px, rig_warp,
                                   RigError, rough_left_rig, rough_rig, swapped)
import numpy as np
import pytest


@pytest.fixture(scope='module')
def scene():
    return random_scene(2, width=320, height=240)


def test_no_rig_error_is_the_identity(scene):
    assert np.allclose(rig_warp(RigError(), 500.0, 320, 240), np.eye(3))
    same = rough_rig(scene, RigError())
    assert np.allclose(same.homography, scene.homography)
    assert plane_error_px(same, scene.homography) == pytest.approx(0.0, abs=1e-9)


def test_rough_rig_truth_matches_its_images(scene):
    error = RigError(roll_deg=3.0, pitch_deg=1.5, focal_ratio=1.03, principal_offset_px=(8, -6))
    rough = rough_rig(scene, error)
    g = rig_warp(error, scene.setup.focal_px, 320, 240)
    assert np.allclose(rough.homography, g @ scene.homography / (g @ scene.homography)[2, 2])
    # A floor pixel's grey level in the rough right image is where the truth sends it.
    pts = np.argwhere(rough.plane_left & rough.visible_in_right)[::97, ::-1].astype(float)
    new = apply_homography(rough.homography, pts)
    old = apply_homography(scene.homography, pts)
    inside = ((new[:, 0] > 2) & (new[:, 0] < 317) & (new[:, 1] > 2) & (new[:, 1] < 237)
              & (old[:, 0] > 2) & (old[:, 0] < 317) & (old[:, 1] > 2) & (old[:, 1] < 237))
    a = rough.right[new[inside, 1].round().astype(int), new[inside, 0].round().astype(int)]
    b = scene.right[old[inside, 1].round().astype(int), old[inside, 0].round().astype(int)]
    assert np.median(np.abs(a.astype(int) - b.astype(int))) <= 12
    # The prior's model error is tens of pixels, not a rounding.
    assert plane_error_px(rough, scene.homography) > 10.0


def test_a_rough_left_camera_carries_its_truth(scene):
    error = RigError(roll_deg=-3.0, pitch_deg=1.0, focal_ratio=0.98, principal_offset_px=(6, 4))
    rough = rough_left_rig(scene, error)
    g = rig_warp(error, scene.setup.focal_px, 320, 240)
    truth = scene.homography @ np.linalg.inv(g)
    assert np.allclose(rough.homography, truth / truth[2, 2])
    assert np.array_equal(rough.right, scene.right)
    # A floor pixel of the new left image shows the grey level the truth finds in the right.
    pts = np.argwhere(rough.plane_left & rough.visible_in_right)[::97, ::-1].astype(float)
    there = apply_homography(rough.homography, pts)
    inside = ((there[:, 0] > 2) & (there[:, 0] < 317) & (there[:, 1] > 2) & (there[:, 1] < 237)
              & (pts[:, 0] > 2) & (pts[:, 0] < 317) & (pts[:, 1] > 2) & (pts[:, 1] < 237))
    a = rough.left[pts[inside, 1].astype(int), pts[inside, 0].astype(int)]
    b = scene.right[there[inside, 1].round().astype(int), there[inside, 0].round().astype(int)]
    assert inside.sum() > 50 and np.median(np.abs(a.astype(int) - b.astype(int))) <= 12
    assert plane_error_px(rough, scene.homography) > 10.0


def test_swapping_twice_gives_the_truth_back(scene):
    twice = swapped(swapped(scene))
    assert np.allclose(twice.homography, scene.homography, atol=1e-9)
    assert np.array_equal(swapped(scene).left, scene.right)


def test_bad_rig_error_is_refused():
    with pytest.raises(ValueError, match='focal_ratio'):
        RigError(focal_ratio=0.0)
    with pytest.raises(ValueError, match='finite'):
        RigError(roll_deg=float('nan'))


def test_cut_joins_two_unrelated_sequences():
    frames = cut_sequence(2, 2, seed=1, width=160, height=120)
    assert len(frames) == 4
    assert not np.allclose(frames[1].homography, frames[2].homography, atol=1.0)


def test_camera_response_changes_the_light_not_the_geometry(scene):
    seen = camera_response(scene, np.random.default_rng(5), gamma=(0.75, 0.75),
                           vignetting=(0.3, 0.3))
    assert np.array_equal(seen.homography, scene.homography)
    assert np.array_equal(seen.plane_left, scene.plane_left)
    # Centre: only the response (255 (I / 255)^0.75, brighter); corners 30 % darker on top.
    centre = scene.left[110:130, 150:170].astype(float)
    expected = 255.0 * (centre / 255.0) ** 0.75
    assert np.abs(seen.left[110:130, 150:170] - expected).max() <= 1.5
    corner = scene.left[:4, :4].astype(float)
    assert np.abs(seen.left[:4, :4] - 0.7 * 255.0 * (corner / 255.0) ** 0.75).max() <= 2.5
    # Not a gain and offset: no affine map of the grey levels explains it.
    a = np.stack([scene.left.ravel(), np.ones(scene.left.size)], axis=1).astype(float)
    fit = np.linalg.lstsq(a, seen.left.ravel().astype(float), rcond=None)[0]
    assert np.abs(a @ fit - seen.left.ravel()).mean() > 3.0
