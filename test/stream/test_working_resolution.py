"""The pipeline at a working resolution: features on a pyramid level, results in full pixels."""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.truth import every_floor_pixel, transfer_error_px
from domplane_ros.stream.pipeline import PlanePipeline
import numpy as np
import pytest


@pytest.fixture(scope='module')
def frames():
    return scene_sequence(3, 5, width=1280, height=720, floor='random')


def _run(frames, max_width):
    config = PlaneNodeConfig()
    config = replace(config, features=replace(config.features, max_width=max_width))
    pipeline = PlanePipeline(config)
    return [pipeline.process(f.left, f.right, i * 33_000_000) for i, f in enumerate(frames)]


def test_level_one_gives_full_pixel_planes_and_full_size_masks(frames):
    """max_width 640 on 1280x720: every pair's plane within 0.5 px, its mask full size.

    The mask (computed on level 1 and scaled up) agrees with the full-resolution pipeline's on
    most pixels, and the tracker's prediction (tracked on level 1, scaled) warm-starts the
    later pairs.
    """
    at_level = _run(frames, 640)
    at_full = _run(frames, 0)
    for frame, small, full in zip(frames, at_level, at_full):
        assert small.ok and full.ok
        floor = every_floor_pixel(frame, 37)
        assert transfer_error_px(small.homography, frame, floor) < 0.5
        assert small.mask.shape == frame.left.shape
        assert np.mean((small.mask > 0) == (full.mask > 0)) > 0.9
        # The corners are in full pixels: they span the full image, not its left half.
        assert small.left_points[:, 0].max() > 900
    assert [r.warm_start for r in at_level[1:]] == ['prediction', 'prediction']
