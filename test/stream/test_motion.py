"""Carried corners: a locked pipeline tracks its corners into the next pairs.

Rendered head sequences at 60 deg/s (the fastest in ``evaluate_head``); every check is
against the rendered truth. Carrying saves the corner detection of most locked pairs
(``tracking.reuse_pairs``, off by default: on tiled and planked floors it costs 0.03-0.13 px,
docs/speed.md); on random texture it must keep the lock and the plane's accuracy, and hand
back to detection after ``reuse_pairs`` pairs, after a cut and whenever the search runs.
"""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.pyramid import WorkingImage
from domplane_ros.sim.head import head_sequence, HeadMotion
from domplane_ros.sim.rigs import cut_sequence
from domplane_ros.sim.truth import floor_points, transfer_error_px
from domplane_ros.stream.detection import detect_features
from domplane_ros.stream.motion import FrameTracker
from domplane_ros.stream.pipeline import LOCKED, PlanePipeline
import numpy as np
import pytest

STEP_NS = 33_333_333


@pytest.fixture(scope='module')
def sequences():
    """Two 10-frame sequences at 60 deg/s (pan, tilt and vergence) of random floors."""
    out = []
    for seed, floor in ((5, 'random'), (2, 'random')):
        frames = list(head_sequence(10, seed, HeadMotion.at_speed(60.0), floor=floor,
                                    supersample=1))
        out.append([(f, floor_points(f, 8, 4)) for f in frames])
    return out


def _config(reuse_pairs):
    base = PlaneNodeConfig()
    return replace(base, tracking=replace(base.tracking, reuse_pairs=reuse_pairs))


def _run(pipeline, sequence, start=0):
    out = []
    for i, (frame, points) in enumerate(sequence):
        carried_before = pipeline.stats.carried
        result = pipeline.process(frame.left, frame.right, (start + i) * STEP_NS)
        out.append((result, transfer_error_px(result.homography, frame, points),
                    pipeline.stats.carried > carried_before))
    return out


@pytest.mark.parametrize('index', [0, 1])
def test_carried_corners_keep_the_lock_and_its_accuracy(sequences, index):
    carried = _run(PlanePipeline(_config(4)), sequences[index])
    detected = _run(PlanePipeline(_config(0)), sequences[index])
    first = next(i for i, (r, e, _) in enumerate(carried) if r.ok and e < 1.0)
    assert first <= 2
    assert all(r.ok and r.state == LOCKED and e < 1.0 for r, e, _ in carried[first:]), [
        (i, r.state, round(e, 2)) for i, (r, e, _) in enumerate(carried)]
    # Carried in 4 of every 5 locked pairs (the first locked pair detects).
    flags = [c for _, _, c in carried]
    assert not any(flags[:first + 1])
    assert flags[first + 1:first + 5] == [True] * 4 and not flags[first + 5], flags
    assert not any(c for _, _, c in detected)
    # Accuracy: median transfer error within 0.05 px of detecting every pair.
    err_carried = np.median([e for _, e, _ in carried[first + 1:]])
    err_detected = np.median([e for _, e, _ in detected[first + 1:]])
    assert err_carried < err_detected + 0.05, (err_carried, err_detected)


def test_a_cut_detects_afresh_and_relocks(sequences):
    pipeline = PlanePipeline(_config(4))
    before = _run(pipeline, sequences[0][:5])
    assert before[-1][2]  # carrying when the cut comes
    after = _run(pipeline, sequences[1], start=6)
    # The first pair of the new scene does not carry the old scene's corners.
    assert not after[0][2]
    locked = [i for i, (r, e, _) in enumerate(after) if r.ok and e < 1.0]
    assert locked and locked[0] <= 3, [(r.state, round(e, 2)) for r, e, _ in after]
    assert all(e < 1.0 for r, e, _ in after if r.ok), [
        (r.state, round(e, 2)) for r, e, _ in after]


def test_off_by_default(sequences):
    pipeline = PlanePipeline()
    _run(pipeline, sequences[0][:6])
    assert pipeline.stats.carried == 0


def test_a_reset_detects_afresh(sequences):
    pipeline = PlanePipeline(_config(4))
    _run(pipeline, sequences[0][:4])
    carried = pipeline.stats.carried
    frame, _ = sequences[0][4]
    pipeline.process(frame.left, frame.right, 4 * STEP_NS, reset=True)
    assert pipeline.stats.carried == carried


def _working(frame):
    cfg = PlaneNodeConfig().features
    return (WorkingImage.of(frame.left, cfg.max_width, cfg.max_megapixels),
            WorkingImage.of(frame.right, cfg.max_width, cfg.max_megapixels))


@pytest.mark.parametrize('reuse_pairs', [0, 4])
def test_a_cut_is_a_lost_track_a_head_motion_is_not(sequences, reuse_pairs):
    config = _config(reuse_pairs)
    cut = cut_sequence(1, 1, 20)
    for previous, current, lost in ((sequences[0][3][0], sequences[0][4][0], False),
                                    (cut[0], cut[1], True)):
        tracker = FrameTracker()
        before = _working(previous)
        corners = detect_features(*before, config)[1]
        tracker.keep(*before, corners, None)
        tracked = tracker.track(*_working(current), config, motion=True, carry=True)
        assert tracked.lost == lost
        assert (tracked.motions is None) == lost
        # Too few corners to track (a faint floor's photometric lock): not lost, only unknown.
        tracker = FrameTracker()
        few = tuple(c[:config.tracking.min_tracks - 1] for c in corners)
        tracker.keep(*before, few, None)
        tracked = tracker.track(*_working(current), config, motion=True, carry=True)
        assert not tracked.lost and tracked.motions is None
