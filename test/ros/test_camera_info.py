"""Reading the prior from a CameraInfo's K (duck-typed; no DDS)."""

from __future__ import annotations

from domplane_ros.ros.camera_info import camera_model
import pytest
from sensor_msgs.msg import CameraInfo


def _info(k, width=640, height=480, binning=(0, 0)) -> CameraInfo:
    msg = CameraInfo()
    msg.k = [float(v) for v in k]
    msg.width, msg.height = width, height
    msg.binning_x, msg.binning_y = binning
    return msg


def test_focal_and_principal_point_from_k_and_the_prior_values():
    model = camera_model(_info([702.0, 0, 330.0, 0, 698.0, 250.0, 0, 0, 1]))
    assert model.focal_px == pytest.approx(700.0)
    assert model.principal_px == pytest.approx((330.0, 250.0))
    values = model.prior_values(0.1)
    assert values['prior.focal_px'] == pytest.approx([630.0, 770.0])
    assert values['prior.principal_point_px'] == pytest.approx([330.0, 250.0])


def test_binning_scales_k_to_the_published_image():
    model = camera_model(_info([1400.0, 0, 640.0, 0, 1400.0, 480.0, 0, 0, 1], 1280, 960,
                               binning=(2, 2)))
    assert model.focal_px == pytest.approx(700.0)
    assert model.principal_px == pytest.approx((320.0, 240.0))


@pytest.mark.parametrize('k,needle', [
    ([0.0] * 9, 'all zero'),
    ([0.0] * 8 + [1.0], 'non-positive focal length'),
    ([700.0, 0, 320.0, 0, 800.0, 240.0, 0, 0, 1], 'square pixels'),
    ([700.0, 0, 900.0, 0, 700.0, 240.0, 0, 0, 1], 'outside'),
    ([700.0, 0, float('nan'), 0, 700.0, 240.0, 0, 0, 1], 'non-finite'),
])
def test_unusable_k_is_refused_with_a_reason(k, needle):
    with pytest.raises(ValueError, match=needle):
        camera_model(_info(k))
