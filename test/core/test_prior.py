"""The prior's camera model with a principal point away from the image centre."""

from __future__ import annotations

from domplane_ros.config import PriorConfig
from domplane_ros.core.prior import intrinsics, plane_homography, prior_candidates
import numpy as np
import pytest

SETUP = {'focal_px': 700.0, 'baseline_over_height': 0.2, 'tilt_deg': 25.0,
         'vergence_deg': 1.0, 'width': 640, 'height': 480}


def test_principal_point_moves_the_homography_by_the_pixel_shift():
    # K' = T K with T the translation by the principal point's offset, so H' = T H T^-1.
    centred = plane_homography(**SETUP)
    cx, cy = 350.25, 221.5
    shifted = plane_homography(**SETUP, principal_px=(cx, cy))
    t = np.array([[1.0, 0.0, cx - 319.5], [0.0, 1.0, cy - 239.5], [0.0, 0.0, 1.0]])
    expected = t @ centred @ np.linalg.inv(t)
    assert np.allclose(shifted, expected / expected[2, 2], rtol=0, atol=1e-12)
    assert not np.allclose(shifted, centred, atol=1e-3)
    assert np.array_equal(intrinsics(700.0, 640, 480, (cx, cy))[:2, 2], [cx, cy])


def test_prior_candidates_use_the_configured_principal_point():
    prior = PriorConfig(focal_px=(700.0, 700.0), baseline_over_height=(0.2, 0.2),
                        tilt_deg=(25.0, 25.0), vergence_deg=(1.0, 1.0),
                        principal_point_px=(350.25, 221.5))
    (candidate,) = prior_candidates(prior, 640, 480)
    assert np.allclose(candidate, plane_homography(**SETUP, principal_px=(350.25, 221.5)),
                       rtol=0, atol=1e-12)
    (centred,) = prior_candidates(PriorConfig(
        focal_px=(700.0, 700.0), baseline_over_height=(0.2, 0.2), tilt_deg=(25.0, 25.0),
        vergence_deg=(1.0, 1.0)), 640, 480)
    assert np.allclose(centred, plane_homography(**SETUP), rtol=0, atol=1e-12)


@pytest.mark.parametrize('principal', [(1.0,), (np.nan, 2.0), (1.0, 2.0, 3.0)])
def test_bad_principal_point_is_refused(principal):
    with pytest.raises(ValueError, match='principal point'):
        intrinsics(700.0, 640, 480, principal)
