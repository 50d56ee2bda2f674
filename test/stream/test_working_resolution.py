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


def _run(frames, max_width, max_megapixels=0.0):
    config = PlaneNodeConfig()
    config = replace(config, features=replace(config.features, max_width=max_width,
                                              max_megapixels=max_megapixels))
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


def test_the_default_working_resolution_runs_720p_on_level_one(frames):
    """The default size limit (0.6 MP) puts 1280x720 on 640x360, planes within 0.3 px.

    Measured on these three pairs: 0.09 / 0.18 / 0.19 px (0.15 / 0.12 / 0.10 px at full
    resolution; over the 29 warm pairs of bench_pipeline's sequence the median is 0.140 px
    on the level, 0.145 px at full resolution).
    """
    config = PlaneNodeConfig()
    assert config.features.max_megapixels == 0.6
    pipeline = PlanePipeline(config)
    for i, frame in enumerate(frames):
        result = pipeline.process(frame.left, frame.right, i * 33_000_000)
        assert result.ok and result.mask.shape == frame.left.shape
        floor = every_floor_pixel(frame, 37)
        assert transfer_error_px(result.homography, frame, floor) < 0.3
        # The corners are in full pixels.
        assert result.left_points[:, 0].max() > 900
