"""The pipeline's residual parallax beside the mask: present with a plane, absent without."""

from __future__ import annotations

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.mask import NOT_MEASURED, PLANE
from domplane_ros.sim.generators import random_scene
from domplane_ros.stream.frame import parallax_image
from domplane_ros.stream.pipeline import PlanePipeline
import numpy as np


def test_parallax_follows_the_plane():
    scene = random_scene(1)
    pipeline = PlanePipeline(PlaneNodeConfig())
    result = pipeline.process(scene.left, scene.right, 1_000_000_000)
    assert result.ok, result.reason
    assert result.parallax.shape == (240, 320) and result.parallax.dtype == np.float32
    image = parallax_image(result)
    assert image.shape == scene.left.shape and np.all(np.isfinite(image))
    ground = (result.mask == PLANE) & scene.plane_left & (image >= 0.0)
    assert ground.sum() > 10000 and np.median(image[ground]) < 0.5
    # No plane (a black pair is refused): no parallax, all 'not measured', mask all 0.
    black = np.zeros_like(scene.left)
    refused = pipeline.process(black, black, 2_000_000_000)
    assert not refused.ok and refused.parallax is None and not refused.mask.any()
    assert np.all(parallax_image(refused) == NOT_MEASURED)
