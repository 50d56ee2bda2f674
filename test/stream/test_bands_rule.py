"""A ground plane is published only if it explains the bottom of the image as well as the top.

``trust.MIN_BOTTOM_OVER_TOP`` (session 20, round 21 of docs/BENCHMARKS.md): on real texture
(KITTI 2015 000046, its road homography from the ground-truth disparity) the window ``crop``
94 of ``tools/evaluate_real_rigs`` (x1 y79 754 x 175: trees, poles and signs above a strip of
near road) with the documented default prior published a plane through the distant structure
and the far road, 7.0 px off the road at confidence 0.93: it explains 37 % of the top third
and 21 % of the bottom third. The rule refuses it; a window of the road keeps its plane.

Round 22 (session 21): the rule also looks at planes scored just over
``verification.accept_score`` (``trust.BANDS_SCORE_MARGIN``, score under 0.39 by default). With
the co-visible score crop 191 (x37 y58 906 x 182) publishes a plane 7.3 px off at score 0.353,
full confidence, explaining 29 % of the top third and 10 % of the bottom; the margin refuses it.
The correct plane nearest the bound, a 64 cm checker (``evaluate_trust``'s sized floors, seed 37)
at score 0.43 with bottom / top 0.34, is kept.
"""

from __future__ import annotations

from domplane_ros.config import one_shot_search, PlaneNodeConfig
from domplane_ros.sim.generators import random_scene
from domplane_ros.sim.rigs import plane_error_px
from domplane_ros.sim.textures import SIZED_FLOOR_KINDS
from domplane_ros.stream import trust
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.evaluate_real_rigs import configs, kitti_base
from domplane_ros.tools.evaluation.real_rigs import draw
import pytest
from truth import real_rig_result


@pytest.fixture(scope='module')
def base():
    return kitti_base()


_run = real_rig_result


def test_a_plane_explaining_the_top_over_the_bottom_is_refused(base, monkeypatch):
    pair = draw(base, 'crop', 94)
    config = configs()['default']
    result, _ = _run(pair, config)
    assert not result.ok and 'of its bottom' in result.reason, result.reason
    # Without the rule the same pair publishes the wrong plane.
    monkeypatch.setattr(trust, 'MIN_BOTTOM_OVER_TOP', 0.0)
    result, error = _run(pair, config)
    assert result.ok and error > 5.0, (result.reason, error)


def test_a_window_of_the_road_keeps_its_plane(base):
    # Crop 67 (x108 y183 770 x 187): the road fills the window, the plane explains 47 % of its
    # top and 61 % of its bottom (the closest of the correct planes to the rule, tuning seeds
    # 48-247, but for crop 161's 54 % and 66 %). It is verified at full confidence (score
    # 0.64, over the bound 0.39), where the rule does not look, so this guards the rule's score
    # condition, not its ratio: it passes with MIN_BOTTOM_OVER_TOP raised to 100 (review of
    # session 20; no correct real crop below full confidence has a top third over 0.1 to test
    # the ratio on).
    result, error = _run(draw(base, 'crop', 67), configs()['default'])
    assert result.ok and error < 1.0, (result.reason, error)


def test_a_plane_just_over_the_acceptance_score_is_looked_at(base, monkeypatch):
    # Crop 191: score 0.353 >= accept_score 0.35 (confidence 1), bottom / top 0.10 / 0.29.
    pair = draw(base, 'crop', 191)
    config = configs()['default']
    result, _ = _run(pair, config)
    assert not result.ok and 'of its bottom' in result.reason, result.reason
    # Without the margin (the rule of round 21) the same pair publishes the wrong plane.
    monkeypatch.setattr(trust, 'BANDS_SCORE_MARGIN', 0.0)
    result, error = _run(pair, config)
    assert result.ok and error > 5.0, (result.reason, error)


def test_the_correct_plane_nearest_the_bound_is_kept(monkeypatch):
    # Sized floors seed 37 (a 64 cm checker): of the tuning runs' correct planes with bottom /
    # top under MIN_BOTTOM_OVER_TOP, the nearest the bound (round 22: 0.427, bottom / top 0.34,
    # 0.29 px off; 0.417 on the rough head of the same seed); its ratio is as low as the wrong
    # planes', only its score keeps it.
    frame = random_scene(37, floor=SIZED_FLOOR_KINDS[37 % len(SIZED_FLOOR_KINDS)])
    config = one_shot_search(PlaneNodeConfig())
    result = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0, result.reason
    # The guard is real: a bound over its score refuses it.
    monkeypatch.setattr(trust, 'BANDS_SCORE_MARGIN', 0.1)
    result = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert not result.ok and 'of its bottom' in result.reason, result.reason
