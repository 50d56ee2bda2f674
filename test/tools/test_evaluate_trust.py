"""The trust evaluation's drift case: a lock over a walking sequence, its warm pairs counted."""

from __future__ import annotations

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.rigs import plane_error_px
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools import evaluate_trust


def test_the_drift_case_counts_the_warm_pairs_and_the_worst_error():
    # Three frames of a walking sequence (tuning seed 2): pair 0 is the search, not counted.
    tally = evaluate_trust._drift_case([2], PlaneNodeConfig(), n_frames=3)
    frames = scene_sequence(3, seed=2)
    pipeline = PlanePipeline()
    errors = []
    for index, frame in enumerate(frames):
        result = pipeline.process(frame.left, frame.right, index * evaluate_trust.PERIOD_NS)
        if index > 0 and result.ok:
            errors.append(plane_error_px(frame, result.homography))
    assert tally.pairs == 2
    assert tally.published == len(errors)
    assert tally.correct == sum(e < evaluate_trust.CORRECT_PX for e in errors)
    assert tally.wrong == sum(e > evaluate_trust.WRONG_PX for e in errors)
    assert errors and tally.worst_px == max(errors)
    assert f'worst {max(errors):.2f} px' in tally.row('drift', 'ours')
