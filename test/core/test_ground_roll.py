"""The roll of a ground plane about the optical axis (core/ground_slope.py ground_roll_deg).

Exact homographies of the prior's camera model (:func:`~domplane_ros.core.prior.plane_homography`)
and of rough rigs (:func:`~domplane_ros.sim.rigs.rig_warp`): a level head's ground has none, a
rough rig's right camera adds none once its roll is taken out, and a plane rolled by a known
angle gives that angle back.
"""

from __future__ import annotations

import math

from domplane_ros.core.ground_slope import ground_roll_deg
from domplane_ros.core.prior import intrinsics, plane_homography
from domplane_ros.sim.rigs import rig_warp, RigError
import numpy as np
import pytest

DEFAULT_FOCAL = (400.0, 900.0)
HEADS = [(f, bh, tilt, verg) for f in (400.0, 650.0, 900.0) for bh in (0.05, 0.4)
         for tilt in (10.0, 50.0) for verg in (-2.0, 4.0)]


def _rolled_plane(focal, bh, tilt_deg, verg_deg, roll_deg, width=640, height=480):
    """Return H of the model's head whose ground normal is rolled by ``roll_deg``."""
    k = intrinsics(focal, width, height)
    tilt, verg, roll = (math.radians(v) for v in (tilt_deg, verg_deg, roll_deg))
    normal = np.array([math.sin(roll) * math.cos(tilt), math.cos(roll) * math.cos(tilt),
                       math.sin(tilt)])
    r_v = np.array([[math.cos(verg), 0.0, math.sin(verg)], [0.0, 1.0, 0.0],
                    [-math.sin(verg), 0.0, math.cos(verg)]])
    h = k @ r_v @ (np.eye(3) - np.outer([bh, 0.0, 0.0], normal)) @ np.linalg.inv(k)
    return h / h[2, 2]


@pytest.mark.parametrize('head', HEADS)
def test_a_level_heads_ground_has_no_roll(head):
    h = plane_homography(*head, 640, 480)
    assert abs(ground_roll_deg(h, 640, 480, DEFAULT_FOCAL)) < 0.1


RIG_CORNERS = [RigError(roll, pitch, focal, (10.0 * math.cos(a), 10.0 * math.sin(a)))
               for roll in (-4.0, 4.0) for pitch in (-2.0, 2.0) for focal in (0.97, 1.03)
               for a in np.linspace(0.0, 2.0 * math.pi, 4, endpoint=False)]


@pytest.mark.parametrize('head', HEADS)
def test_a_rough_rigs_roll_is_taken_out(head):
    # The right camera's roll (4 deg) alone reads as a roll of the plane of about 4 deg; taken
    # out through M[1, 0], what is left at the corners of the rough rig (roll 4 deg, pitch
    # 2 deg, focal 3 %, principal points 10 px apart) stays under 1.5 deg where the ground's
    # disparity grows by b/h cos(tilt) >= 0.05, and under 5.5 deg (5.15 measured) at the
    # default prior's corner f 400, b/h 0.05, tilt 50, vergence 4 (b/h cos(tilt) 0.032).
    # Uniformly drawn rough rigs on 6160 rendered set-ups: at most 1.41 deg.
    focal, bh, tilt, _ = head
    limit = 1.5 if bh * math.cos(math.radians(tilt)) >= 0.05 else 5.5
    ground = plane_homography(*head, 640, 480)
    rolls = [ground_roll_deg(rig_warp(error, focal, 640, 480) @ ground, 640, 480,
                             DEFAULT_FOCAL) for error in RIG_CORNERS]
    assert max(abs(r) for r in rolls) < limit


@pytest.mark.parametrize('roll', [-20.0, -10.0, 10.0, 20.0])
@pytest.mark.parametrize('head', [(500.0, 0.1, 30.0, 2.0), (800.0, 0.3, 15.0, -1.0)])
def test_a_rolled_plane_gives_its_roll(head, roll):
    h = _rolled_plane(*head, roll)
    # Exact with the head's focal length; over the default prior's range the least roll, which
    # the focal length's uncertainty lowers by less than a degree with this vergence.
    assert ground_roll_deg(h, 640, 480, (head[0], head[0])) == pytest.approx(roll, abs=1e-6)
    least = ground_roll_deg(h, 640, 480, DEFAULT_FOCAL)
    assert np.sign(least) == np.sign(roll) and abs(roll) - 1.0 < abs(least) <= abs(roll) + 1e-6


@pytest.mark.parametrize('roll', [0.0, 10.0])
def test_the_roll_does_not_depend_on_the_homographys_scale(roll):
    # H and -H (or any multiple) are the same plane: rreview19 found -H of a level head's
    # ground read 92.5 deg (refused at any bound) where H reads 0.
    h = _rolled_plane(500.0, 0.1, 30.0, 2.0, roll)
    expected = ground_roll_deg(h, 640, 480, DEFAULT_FOCAL)
    assert abs(expected) < 0.1 if roll == 0.0 else 9.0 < expected <= 10.0 + 1e-6
    for scale in (-1.0, -0.01, 2.5):
        assert ground_roll_deg(scale * h, 640, 480, DEFAULT_FOCAL) == pytest.approx(
            expected, abs=1e-6)


def test_bad_arguments_are_refused():
    h = plane_homography(500.0, 0.1, 30.0, 0.0, 640, 480)
    with pytest.raises(ValueError):
        ground_roll_deg(h, 640, 480, (0.0, 900.0))
    with pytest.raises(ValueError):
        ground_roll_deg(h, 0, 480, DEFAULT_FOCAL)
    with pytest.raises(ValueError):
        ground_roll_deg(np.full((3, 3), np.nan), 640, 480, DEFAULT_FOCAL)
