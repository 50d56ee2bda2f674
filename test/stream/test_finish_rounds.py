"""The search's winner is refined photometrically until it settles, not for two rounds only."""

from __future__ import annotations

from domplane_ros.stream import candidates as candidates_module
from domplane_ros.tools.evaluate_real_rigs import configs, kitti_base
from domplane_ros.tools.evaluation.real_rigs import draw
import pytest
from truth import real_rig_result


@pytest.fixture(scope='module')
def focal_pair():
    """KITTI 000046, the right camera's focal 0.2 % shorter (tuning draw 31 of rig_focal)."""
    pair = draw(kitti_base(), 'rig_focal', 31)
    assert pair.detail == 'focal=0.998'
    return pair


def test_a_winner_a_few_pixels_off_the_road_is_refined_onto_it(focal_pair, monkeypatch):
    # The search's winner lies 3.0 px off the road; each photometric round moves it part of
    # the way (3.01 -> 2.22 -> 1.65 -> 0.64 -> 0.52 px, the peak score rising every round).
    # Two rounds, as before session 25, published it 2.2 px off.
    config = configs()['default']
    result, error = real_rig_result(focal_pair, config)
    assert result.ok and error < 1.0, (result.reason, error)
    assert result.confidence > 0.9
    monkeypatch.setattr(candidates_module, 'WINNER_FINISH_ROUNDS', 2)
    result, error = real_rig_result(focal_pair, config)
    assert result.ok and error > 2.0, (result.reason, error)


def test_the_rounds_stop_where_the_peak_score_falls(focal_pair, monkeypatch):
    # The guard: a round that keeps less than PHOTOMETRIC_MIN_PEAK of the best peak so far is
    # not taken. Asking for more than the first round gives (its peak rises 12 %: 0.196 ->
    # 0.219) stops the finish at its start, the winner 3 px off the road where the corners
    # left it: its own mask marks most of the near road obstacle, and the near-field rule
    # refuses it.
    monkeypatch.setattr(candidates_module, 'PHOTOMETRIC_MIN_PEAK', 1.2)
    result, _ = real_rig_result(focal_pair, configs()['default'])
    assert not result.ok and 'its own mask marks' in result.reason, result.reason
