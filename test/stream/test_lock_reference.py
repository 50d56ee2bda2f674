"""A held lock is held against the plane it started from: a lock that slides off is searched.

Ground truth comes from the renderer; the configuration is the documented default.
"""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.rigs import plane_error_px
from domplane_ros.stream import trust as trust_module
from domplane_ros.stream.pipeline import PlanePipeline
import pytest
from truth import stream_errors

PERIOD_NS = 33_333_333


@pytest.fixture(scope='module')
def faint_tiles():
    # evaluate_drift's floors family, tuning seed 33 (32 cm faint tiles, three boxes). Pair 0
    # is the search's plane (0.05 px, score 0.58, 66 % of the bottom); pairs 1-3 stay under
    # 0.5 px; in pair 4 the prediction is 2.67 px off and the warm estimate, 2.39 px off, passes
    # the gate with score 0.31 and 11 % of the bottom (the lock's median 0.55 follows it: 0.31
    # is above its half), and pair 5 is published 2.81 px off (docs/BENCHMARKS.md round 18).
    return scene_sequence(16, 33, floor='tiles_faint_64')[:6]


def test_a_lock_that_loses_its_start_score_is_refused_and_searched(faint_tiles, monkeypatch):
    errors = stream_errors(faint_tiles)
    published = [e for e in errors if e is not None]
    assert len(published) >= 5, errors
    assert max(published) < 1.0, errors
    # Without the lock's reference the slid planes of pairs 4 and 5 are published.
    monkeypatch.setattr(trust_module, 'LOCK_REFERENCE', False)
    off = stream_errors(faint_tiles)
    assert off[4] is not None and off[4] > 2.0, off


def test_a_changed_verification_setting_keeps_the_lock_reference(faint_tiles):
    # A verification.* parameter set while locked (here drop_ratio, before pair 4) makes a new
    # gate; without the lock's reference it took pair 4's slid plane (2.39 px) as the plane
    # the lock started from and published pairs 4 and 5 2.39 and 2.81 px off (review18).
    pipeline = PlanePipeline()
    errors = []
    for index, frame in enumerate(faint_tiles):
        if index == 4:
            config = pipeline.config
            pipeline.update_config(replace(config, verification=replace(
                config.verification, drop_ratio=0.49)))
        result = pipeline.process(frame.left, frame.right, index * PERIOD_NS)
        errors.append(plane_error_px(frame, result.homography) if result.ok else None)
    published = [e for e in errors if e is not None]
    assert len(published) >= 5, errors
    assert max(published) < 1.0, errors


def test_a_cut_starts_the_new_lock_from_its_own_plane():
    # A cut (the previous pair cannot be tracked) from 16 cm tiles (tuning seed 0, reference
    # score 0.61) to a 64 cm checker floor (seed 0, scores 0.39-0.42): the search's plane
    # after the cut is the new lock's reference and its warm planes are held. Held against
    # the tiles' reference (not cleared on the search) pairs 5-7 were refused and searched
    # again (5 searches instead of 2), review18.
    frames = (scene_sequence(3, 0, floor='tiles_32')
              + scene_sequence(6, 0, floor='checker_32'))
    pipeline = PlanePipeline()
    errors = []
    for index, frame in enumerate(frames):
        result = pipeline.process(frame.left, frame.right, index * PERIOD_NS)
        errors.append(plane_error_px(frame, result.homography) if result.ok else None)
    assert all(e is not None and e < 1.0 for e in errors), errors
    assert pipeline.stats.reinitialisations == 2, errors


def test_a_changed_verification_scale_searches_again(faint_tiles):
    # Scores at another working width are not the lock's: the warm start is dropped, the pair
    # searched, and the search's plane is the new lock's reference (review18).
    pipeline = PlanePipeline()
    for index, frame in enumerate(faint_tiles[:3]):
        if index == 2:
            config = pipeline.config
            pipeline.update_config(replace(config, verification=replace(
                config.verification, scale=0.3)))
            assert pipeline.state == 'searching'
        result = pipeline.process(frame.left, frame.right, index * PERIOD_NS)
        assert result.ok and plane_error_px(frame, result.homography) < 1.0
    assert pipeline.stats.reinitialisations == 2
    assert pipeline.state == 'locked'
