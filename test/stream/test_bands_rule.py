"""A ground plane is published only if it explains the bottom of the image as well as the top.

``ground_rules.MIN_BOTTOM_OVER_TOP`` (session 20, round 21 of docs/BENCHMARKS.md): on real texture
(KITTI 2015 000046, its road homography from the ground-truth disparity) the window ``crop``
94 of ``tools/evaluate_real_rigs`` (x1 y79 754 x 175: trees, poles and signs above a strip of
near road) with the documented default prior published a plane through the distant structure
and the far road, 7.0 px off the road at confidence 0.93: it explains 37 % of the top third
and 21 % of the bottom third. The rule refused it; a window of the road keeps its plane.
Since session 24's exact coverage that plane reaches full confidence and the near-field rule
alone refuses it; the rule is shown on it as measured before (``EXACT_COVERAGE`` off).
"""

from __future__ import annotations

from domplane_ros.core import verification
from domplane_ros.stream import ground_rules
from domplane_ros.tools.evaluate_real_rigs import configs, kitti_base
from domplane_ros.tools.evaluation.real_rigs import draw
import pytest
from truth import FOUND_MIN_SCORE, real_rig_result, with_verification


@pytest.fixture(scope='module')
def base():
    return kitti_base()


_run = real_rig_result


def test_a_plane_explaining_the_top_over_the_bottom_is_refused(base, monkeypatch):
    pair = draw(base, 'crop', 94)
    config = configs()['default']
    far_field_off = with_verification(config, max_near_obstacle=1.0)
    # Since session 24's exact coverage the crop's wrong plane (7.05 px off) scores 0.368, at
    # full confidence, where the rule does not look (bottom / top 0.265 / 0.372): session 22's
    # near-field rule alone refuses it (its own mask marks 82 % of the measured near road
    # obstacle); without that rule the pair publishes it.
    result, _ = _run(pair, config)
    assert not result.ok and 'its own mask marks' in result.reason, result.reason
    result, error = _run(pair, far_field_off)
    assert result.ok and error > 5.0, (result.reason, error)
    # Measured as before session 24 (0.349, confidence 0.99 under verification.min_score 0.25,
    # bottom / top 0.221 / 0.375) the rule refuses it; without the rule the near-field rule
    # does; without both it is published. (Under session 25's min_score 0.22 the confidence
    # is 1 there and only the near-field rule looks.)
    monkeypatch.setattr(verification, 'EXACT_COVERAGE', False)
    result, _ = _run(pair, config)
    assert not result.ok and 'its own mask marks' in result.reason, result.reason
    config, far_field_off = (with_verification(c, min_score=FOUND_MIN_SCORE)
                             for c in (config, far_field_off))
    result, _ = _run(pair, config)
    assert not result.ok and 'of its bottom' in result.reason, result.reason
    monkeypatch.setattr(ground_rules, 'MIN_BOTTOM_OVER_TOP', 0.0)
    result, _ = _run(pair, config)
    assert not result.ok and 'its own mask marks' in result.reason, result.reason
    result, error = _run(pair, far_field_off)
    assert result.ok and error > 5.0, (result.reason, error)


def test_a_window_of_the_road_keeps_its_plane(base):
    # Crop 67 (x108 y183 770 x 187): the road fills the window, the plane explains 47 % of its
    # top and 61 % of its bottom (the closest of the correct planes to the rule, tuning seeds
    # 48-247, but for crop 161's 54 % and 66 %). It is verified at full confidence (score
    # 0.64), where the rule does not look, so this guards the rule's confidence condition, not
    # its ratio: it passes with MIN_BOTTOM_OVER_TOP raised to 100 (review of session 20; no
    # correct real crop below full confidence has a top third over 0.1 to test the ratio on).
    result, error = _run(draw(base, 'crop', 67), configs()['default'])
    assert result.ok and error < 1.0, (result.reason, error)
