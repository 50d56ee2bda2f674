"""A lock held over a walking sequence stays on the floor: it does not drift pair by pair.

Ground truth comes from the renderer; the configuration is the documented default.
"""

from __future__ import annotations

from domplane_ros.sim.generators import scene_sequence
from domplane_ros.stream import warm as warm_module
import pytest
from truth import stream_errors


@pytest.fixture(scope='module')
def walk():
    # scene_sequence(16, seed=41) (tuning): a 1.2 m checker with three boxes. Its first six
    # pairs: the search's plane 0.17 px off, then the warm estimates, which slid 1.29, 1.70,
    # 1.76, 2.73, 3.45 px off before the warm pair was anchored (and on to 5.21 px by pair 13).
    return scene_sequence(16, seed=41, only=range(6))


def test_a_lock_on_a_checker_with_boxes_does_not_drift_off_the_floor(walk, monkeypatch):
    errors = stream_errors(walk)
    published = [e for e in errors if e is not None]
    assert len(published) >= 5, errors
    assert max(published) < 1.0, errors
    # Without the anchor, the same warm pairs drift: the test fails when it is switched off.
    monkeypatch.setattr(warm_module, 'WARM_ANCHOR', False)
    drifted = [e for e in stream_errors(walk) if e is not None]
    assert max(drifted) > 2.0, drifted


@pytest.fixture(scope='module')
def planks():
    # scene_sequence(48, seed=39) (tuning, evaluate_drift family long): a planks floor filling
    # the image. Pair 28 is the search's plane (0.07 px); in pair 29 the prediction is 0.16 px
    # off, the warm estimate slides 1.87 px (refused) and its widened retry 6.22 px along the
    # planks, which the gate accepted (a wrong plane, published).
    return scene_sequence(48, seed=39, only=(28, 29))


def test_a_widened_warm_estimate_does_not_replace_a_better_warm_start(planks, monkeypatch):
    errors = stream_errors(planks)
    assert None not in errors, errors
    assert max(errors) < 1.0, errors
    # Without the comparison with the warm start, pair 29 publishes the widened plane.
    monkeypatch.setattr(warm_module, 'WIDENED_BEATS_START', False)
    jumped = stream_errors(planks)
    assert jumped[1] is not None and jumped[1] > 5.0, jumped


def test_a_sequence_renders_the_same_frames_when_only_some_are_asked_for():
    whole = scene_sequence(6, seed=39, width=160, height=120)
    some = scene_sequence(6, seed=39, width=160, height=120, only=(4, 1))
    assert [f.left.tobytes() for f in some] == [whole[4].left.tobytes(), whole[1].left.tobytes()]
    assert [f.right.tobytes() for f in some] == [whole[4].right.tobytes(),
                                                 whole[1].right.tobytes()]
    with pytest.raises(ValueError, match='only'):
        scene_sequence(6, seed=39, only=(6,))


@pytest.fixture(scope='module')
def faint_walk():
    # evaluate_drift's floors family, tuning seed 62 (1.28 m faint tiles): few corners.
    return scene_sequence(16, 62, floor='tiles_faint_256', only=range(6))


def test_the_anchor_does_not_publish_an_unfitted_prediction(faint_walk, monkeypatch):
    # Pair 5: the warm estimate is 6.4 px off; the prediction (1.54 px off) has 6 features
    # within the tight band, fewer than the 8 the polish needs, so it came back unfitted, yet
    # its truncated energy was the lower one: it replaced the warm estimate, passed the gate
    # and was published 1.54 px off (now the anchor needs estimator.min_inliers in the band).
    # Without the anchor that pair is refused, searched and published 0.02 px off. Fails while
    # an unfitted start may replace the warm estimate.
    errors = stream_errors(faint_walk)
    assert errors[5] is None or errors[5] < 1.0, errors
    monkeypatch.setattr(warm_module, 'WARM_ANCHOR', False)
    off = stream_errors(faint_walk)
    assert off[5] is not None and off[5] < 1.0, off
