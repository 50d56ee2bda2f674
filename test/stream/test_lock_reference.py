"""A held lock is held against the plane it started from: a lock that slides off is searched.

Ground truth comes from the renderer; the configuration is the documented default.
"""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.config import VerificationSettings
from domplane_ros.sim.generators import indoor_scene, scene_sequence
from domplane_ros.sim.rigs import plane_error_px
from domplane_ros.stream import trust as trust_module
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.refusals import BOTTOM
from domplane_ros.stream.trust import TrustGate
import numpy as np
import pytest
from truth import drifting_lock_frames, stream_errors

PERIOD_NS = 33_333_333


@pytest.fixture(scope='module')
def faint_tiles():
    # The lock slides off in pair 4 (truth.drifting_lock_frames).
    return drifting_lock_frames()


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
    # The lock is lost once, at the cut, and said so: the tiles' lock, tracked into the
    # checker (the same pose), scores 0.44 there, under 0.7 x the 0.66 it started from; the
    # search re-finds a plane in that pair. Co-visible scores (verification.covisible, the
    # default since session 20): the same two planes as counted over every textured pixel
    # (0.406 and 0.607, session 19's 0.41 and 0.61), each over its weighted share of the
    # texture mapping inside the right image (0.933 and 0.912): 0.435 and 0.665; 0.67 since
    # session 24's exact coverage (verification.EXACT_COVERAGE: the windows along the right
    # image's border that mix it in are outside).
    counts = pipeline.stats.refusals
    assert counts.locks_lost == {**dict.fromkeys(counts.locks_lost, 0), 'reference': 1}, counts
    assert counts.refound == 1 and counts.last_lock_lost.kind == 'reference'
    assert 'score 0.44 fell below 0.7 x the 0.67' in counts.last_lock_lost.reason


@pytest.mark.parametrize('name, value', [('scale', 0.3), ('covisible', False)])
def test_a_changed_verification_scale_searches_again(faint_tiles, name, value):
    # Scores at another working width (review18), or over other pixels (every textured one
    # instead of those both cameras see, session 20), are not the lock's: the warm start is
    # dropped, the pair searched, and the search's plane is the new lock's reference.
    pipeline = PlanePipeline()
    for index, frame in enumerate(faint_tiles[:3]):
        if index == 2:
            config = pipeline.config
            pipeline.update_config(replace(config, verification=replace(
                config.verification, **{name: value})))
            assert pipeline.state == 'searching'
        result = pipeline.process(frame.left, frame.right, index * PERIOD_NS)
        assert result.ok and plane_error_px(frame, result.homography) < 1.0
    assert pipeline.stats.reinitialisations == 2
    assert pipeline.state == 'locked'


def test_a_refused_lock_keeps_its_reason_when_the_search_refinds_it(faint_tiles, monkeypatch):
    # Pair 4's warm plane is refused by the lock's reference and the search in the same pair
    # publishes the floor: the pair has a plane and no reason, so the refusal is kept apart.
    pipeline = PlanePipeline()
    results = [pipeline.process(frame.left, frame.right, index * PERIOD_NS)
               for index, frame in enumerate(faint_tiles)]
    refound = results[4]
    assert refound.ok and refound.reason == '' and refound.warm_start == 'search'
    assert plane_error_px(faint_tiles[4], refound.homography) < 1.0
    assert [r.kind for r in refound.refusals] == ['reference'], refound.refusals
    assert 'the lock started from' in refound.refusals[0].reason
    assert refound.lock_lost == refound.refusals[0]
    assert all(not r.refusals and r.lock_lost is None for r in results[1:4]), results
    counts = pipeline.stats.refusals
    assert counts.locks_lost == {**dict.fromkeys(counts.locks_lost, 0), 'reference': 1}
    assert counts.planes_refused == {**dict.fromkeys(counts.planes_refused, 0), 'reference': 1}
    assert counts.refound == 1 and counts.last_lock_lost == refound.lock_lost
    # Without the reference nothing is refused: the slid plane is published (the refusal
    # above is the reference's, not made up).
    monkeypatch.setattr(trust_module, 'LOCK_REFERENCE', False)
    pipeline = PlanePipeline()
    off = [pipeline.process(frame.left, frame.right, index * PERIOD_NS)
           for index, frame in enumerate(faint_tiles)]
    assert off[4].ok and off[4].warm_start == 'prediction' and not off[4].refusals
    assert pipeline.stats.refusals.locks_lost['reference'] == 0
    assert pipeline.stats.refusals.refound == 0


def test_a_lock_that_keeps_its_score_but_loses_the_bottom_is_refused():
    # Round 23 (mutants): with LOCK_BOTTOM_RATIO 0 every other test passed. On an indoor scene
    # (seed 3) the floor scores 0.31 (89 % of the bottom, 0 % of the top); a ground plane
    # through the floor at 2/3 of the height and tipped sideways (3.6 px off the floor)
    # explains the far wall and scores 0.58 (top 79 %, bottom 28 %): full confidence, so no
    # band rule, and above the lock's score, so neither its reference score nor its median
    # refuse it. Only the bottom it lost does.
    scene = indoor_scene(3)
    height = scene.left.shape[0]
    gate = TrustGate(VerificationSettings())
    start = gate.judge(scene.left, scene.right, scene.homography, locked=True)
    assert start.accepted, start.reason
    gate.record(start)
    hinge = 2.0 * height / 3.0
    slid = np.array([[1.0, 0.05, -0.05 * hinge], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    slid = slid @ scene.homography
    assert plane_error_px(scene, slid) > 3.0
    verdict = gate.judge(scene.left, scene.right, slid, locked=True)
    assert verdict.score > start.score  # the score alone would keep it
    assert verdict.verification.bottom_score < 0.4 * start.verification.bottom_score
    assert not verdict.accepted and verdict.lock_refusal == BOTTOM, verdict.reason
    # The floor itself is still held.
    assert gate.judge(scene.left, scene.right, scene.homography, locked=True).accepted
