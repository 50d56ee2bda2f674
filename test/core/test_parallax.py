"""The plane at infinity fitted to a ground homography, and the ground's disparity to it."""

from __future__ import annotations

import math

from domplane_ros.core import parallax, prior
from domplane_ros.sim.generators import random_setup
import numpy as np
import pytest


def _truth(setup_values, width=640, height=480, principal=None):
    f, bh, tilt, verg = setup_values
    k = prior.intrinsics(f, width, height) if principal is None else np.array(
        [[f, 0.0, principal[0]], [0.0, f, principal[1]], [0.0, 0.0, 1.0]])
    v = math.radians(verg)
    rot = np.array([[math.cos(v), 0, math.sin(v)], [0, 1, 0], [-math.sin(v), 0, math.cos(v)]])
    h_inf = k @ rot @ np.linalg.inv(k)
    t = math.radians(tilt)
    normal = np.array([0.0, math.cos(t), math.sin(t)])
    hom = k @ rot @ (np.eye(3) - np.outer([bh, 0.0, 0.0], normal)) @ np.linalg.inv(k)
    return hom, h_inf


def test_infinity_homography_of_rendered_setups():
    rng = np.random.default_rng(12)
    for _ in range(20):
        setup = random_setup(rng)
        values = (setup.focal_px, setup.baseline_over_height, setup.tilt_deg,
                  setup.vergence_deg)
        hom, h_inf = _truth(values)
        fitted = parallax.infinity_homography(hom, 640, 480, (400.0, 900.0))
        # Same scale as H: H - H_inf is the plane term; compare where a pixel lands.
        pts = np.array([[0.0, 0.0, 1.0], [639.0, 479.0, 1.0], [320.0, 400.0, 1.0]]).T
        a, b = h_inf @ pts, fitted @ pts
        # The vergence's image shift f tan(v) depends on the fitted focal length: it comes out
        # within 0.1 px of the truth on rendered scenes (1 px before the parabolic refinement).
        assert np.max(np.abs(a[:2] / a[2] - b[:2] / b[2])) < 1.0, values
        # On H's scale, H_inf - H is the rank-one plane term e' l^T.
        singular = np.linalg.svd(fitted - hom, compute_uv=False)
        assert singular[1] < 1e-2 * singular[0], singular  # 16 focal samples: <= 1.7e-3


def test_rectified_head_needs_no_focal_length():
    hom, _ = _truth((700.0, 0.3, 20.0, 0.0))
    for focal in ((400.0, 450.0), (850.0, 900.0)):
        fitted = parallax.infinity_homography(hom, 640, 480, focal)
        assert np.allclose(fitted / fitted[2, 2], np.eye(3), atol=1e-9)
    # The shift is the ground's disparity: b/h cos(t) (y - y_horizon), zero on the horizon.
    shift = parallax.infinity_shift(hom, 640, 480, (400.0, 900.0), (640, 480))
    horizon = 239.5 - 700.0 * math.tan(math.radians(20.0))
    expected = 0.3 * math.cos(math.radians(20.0)) * (np.arange(480) - horizon)
    assert np.allclose(shift[:, 320], expected, atol=0.05)


def test_given_principal_point_is_used():
    principal = (300.0, 260.0)
    hom, h_inf = _truth((600.0, 0.2, 25.0, 3.0), principal=principal)
    fitted = parallax.infinity_homography(hom, 640, 480, (580.0, 620.0), principal)
    centred = parallax.infinity_homography(hom, 640, 480, (580.0, 620.0))
    pts = np.array([[320.0, 400.0, 1.0]]).T
    err = [np.abs((m @ pts)[:2, 0] / (m @ pts)[2, 0] - (h_inf @ pts)[:2, 0] / (h_inf @ pts)[2, 0])
           .max() for m in (fitted, centred)]
    assert err[0] < 0.5 and err[0] < err[1], err


def test_height_factor():
    assert parallax.height_factor(0.1) == pytest.approx(0.1 / 0.9)
    assert parallax.height_factor(0.5) == pytest.approx(1.0)
    for bad in (0.0, 1.0, -0.2):
        with pytest.raises(ValueError, match='min_height'):
            parallax.height_factor(bad)
