"""The ground's disparity slope (b/h) cos(tilt), read from H, against the prior's range.

``core/ground_slope.py`` ``ground_slope_range`` and ``prior_slope_bounds``: exact
homographies of the prior's camera model (:func:`~domplane_ros.core.prior.plane_homography`)
and of rough rigs (:func:`~domplane_ros.sim.rigs.rig_warp`) give back ``(b / h) cos(tilt)``;
the reading does not depend on the image's scale or on H's; a plane almost at infinity reads
near 0.
"""

from __future__ import annotations

import math

from domplane_ros.core.ground_slope import ground_slope_range, prior_slope_bounds
from domplane_ros.core.homography import resize_homography
from domplane_ros.core.prior import plane_homography
from domplane_ros.sim.rigs import rig_warp, RigError
import numpy as np
import pytest

DEFAULT_FOCAL = (400.0, 900.0)
HEADS = [(f, bh, tilt, verg) for f in (400.0, 650.0, 900.0) for bh in (0.05, 0.4)
         for tilt in (0.0, 10.0, 50.0) for verg in (-2.0, 4.0)]


@pytest.mark.parametrize('head', HEADS)
def test_a_level_heads_ground_gives_b_over_h_cos_tilt(head):
    focal, bh, tilt, _ = head
    h = plane_homography(*head, 640, 480)
    expected = bh * math.cos(math.radians(tilt))
    # Exact with the head's focal length; over the default prior's focal range the vergence's
    # removal depends on the focal length a little (less than 2 % here).
    low, high = ground_slope_range(h, 640, 480, (focal, focal))
    assert low == pytest.approx(expected, rel=1e-9) and high == pytest.approx(expected, rel=1e-9)
    low, high = ground_slope_range(h, 640, 480, DEFAULT_FOCAL)
    assert low <= expected * (1 + 1e-9) and high >= expected * (1 - 1e-9)
    assert expected * 0.98 < low <= high < expected * 1.02


@pytest.mark.parametrize('head', [(400.0, 0.05, 50.0, 4.0), (650.0, 0.2, 20.0, 0.0),
                                  (900.0, 0.4, 10.0, -2.0)])
def test_a_rough_rigs_slope_stays_within_the_range_over_the_focal_lengths(head):
    # Roll 4 deg, pitch 2 deg, focal 3 %, principal points 10 px apart, at every sign. The
    # relative pitch's projective part is read as vergence differently per focal length: at
    # the default prior's corner (f 400, b/h 0.05, tilt 50, vergence 4) the range is
    # 0.022-0.031 around the truth's 0.032 (the principal points' offset alone -6 %).
    focal, bh, tilt, _ = head
    expected = bh * math.cos(math.radians(tilt))
    ground = plane_homography(*head, 640, 480)
    for roll in (-4.0, 4.0):
        for pitch in (-2.0, 2.0):
            for scale in (0.97, 1.03):
                error = RigError(roll, pitch, scale, (10.0, -10.0))
                low, high = ground_slope_range(rig_warp(error, focal, 640, 480) @ ground,
                                               640, 480, DEFAULT_FOCAL)
                # The check (stream/trust.py slope_refusal) takes the favourable end: the
                # greatest against the prior's least, the least against its greatest.
                assert high > expected * 0.9 and low < expected * 1.1


def test_the_slope_depends_neither_on_the_image_scale_nor_on_hs():
    h = plane_homography(650.0, 0.3, 20.0, 1.0, 640, 480)
    full = ground_slope_range(h, 640, 480, (650.0, 650.0))
    shrink = resize_homography(0.5, 0.5)
    half = ground_slope_range(shrink @ h @ np.linalg.inv(shrink), 320, 240, (325.0, 325.0))
    assert half == pytest.approx(full, rel=1e-9)
    for factor in (-1.0, 0.01, 3.0):
        assert ground_slope_range(factor * h, 640, 480, (650.0, 650.0)) == pytest.approx(
            full, rel=1e-9)


def test_a_plane_almost_at_infinity_reads_near_zero():
    # A wall 100 times farther than the camera height, facing the head: no growth down.
    far = plane_homography(650.0, 0.003, 0.5, 0.0, 640, 480)
    assert max(abs(v) for v in ground_slope_range(far, 640, 480, DEFAULT_FOCAL)) < 0.004


def test_the_priors_bounds():
    least, greatest = prior_slope_bounds((0.05, 0.4), (10.0, 50.0))
    assert least == pytest.approx(0.05 * math.cos(math.radians(50.0)))
    assert greatest == pytest.approx(0.4 * math.cos(math.radians(10.0)))
    # A range of tilts across 0 (a forward-looking head): the greatest is b/h itself.
    assert prior_slope_bounds((0.25, 0.4), (-5.0, 5.0)) == pytest.approx(
        (0.25 * math.cos(math.radians(5.0)), 0.4))
    # Looking straight down the ground has no slope.
    assert prior_slope_bounds((0.1, 0.2), (30.0, 90.0))[0] == pytest.approx(0.0, abs=1e-12)
