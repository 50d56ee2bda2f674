"""The ground is one surface: a plane explaining the top and bottom but not between is not it.

Scenes from the sized floors of ``evaluate_trust`` (a 16 cm checker under a textured far
wall), their truth from the renderer; default configuration and prior.
"""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.verification import agreement_maps, BOTTOM_BAND, verify_plane
from domplane_ros.sim.generators import random_scene
from domplane_ros.sim.rigs import plane_error_px
from domplane_ros.stream import ground_rules
from domplane_ros.stream import trust as trust_module
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.trust import TrustGate
import numpy as np
import pytest


def _run(frame):
    return PlanePipeline().process(frame.left, frame.right, 0)


@pytest.mark.parametrize('roi', [None, (0.0, 0.55, 1.0, 1.0), (0.1, 0.3, 0.9, 0.8)])
def test_band_scores_split_the_score_by_rows(roi):
    frame = random_scene(10002, floor='checker_32')
    config = TrustGate(PlaneNodeConfig().verification).config(frame.left.shape[1])
    check = verify_plane(frame.left, frame.right, frame.homography, config, roi)
    maps = agreement_maps(frame.left, frame.right, frame.homography, config, roi)
    height = maps.weight.shape[0]
    y0, y1 = (0.0, 1.0) if roi is None else (roi[1], roi[3])
    top = round((y0 + BOTTOM_BAND * (y1 - y0)) * height)
    bottom = round((y1 - BOTTOM_BAND * (y1 - y0)) * height)
    # Co-visible (verification.covisible, the default for ground planes): each band's score
    # and the score divide by the textured weight that maps inside the right image, unless
    # that is under covisible_floor of the band's (or the region's) whole textured weight.
    # The truth maps nearly all of it inside, so no divisor is held at the floor and the
    # three bands' inside weights add up to the score's divisor.
    assert config.covisible
    bands_rows = (slice(0, top), slice(top, bottom), slice(bottom, None))
    weights = [float(maps.weight[rows][maps.inside[rows]].sum()) for rows in bands_rows]
    textured = [float(maps.weight[rows].sum()) for rows in bands_rows]
    assert all(inside >= config.covisible_floor * whole
               for inside, whole in zip(weights, textured)), (weights, textured)
    bands = (check.top_score, check.middle_score, check.bottom_score)
    # The score is the bands' scores weighted by the texture each holds inside.
    assert np.dot(weights, bands) / sum(weights) == pytest.approx(check.score, abs=1e-6)
    assert check.middle_texture == pytest.approx(weights[1] / sum(weights), abs=1e-6)
    assert all(weight > 0 for weight in weights)
    if roi is None:
        # The true floor: under the far wall at the top, nearly nothing; at the bottom, most.
        assert check.top_score < 0.05 and check.bottom_score > 0.5


def _judged(monkeypatch, **bands):
    """Judge a cold scene's true floor with its verification's bands replaced."""
    frame = random_scene(0)
    gate = TrustGate(PlaneNodeConfig().verification)
    real = gate._verify

    def verify(left, right, homography, roi):
        return replace(real(left, right, homography, roi), **bands)

    monkeypatch.setattr(gate, '_verify', verify)
    return gate.judge(frame.left, frame.right, frame.homography)


@pytest.mark.parametrize('top, middle, bottom, texture, refused', [
    (0.4, 0.19, 0.5, 0.3, True),     # under half the weaker outer band
    (0.4, 0.21, 0.5, 0.3, False),    # over half of it
    (0.6, 0.19, 0.4, 0.3, True),     # the weaker band is the bottom
    (0.19, 0.0, 0.6, 0.3, False),    # the top explained too little to speak of a gap
    (0.4, 0.0, 0.5, 0.09, False),    # a nearly blank middle says nothing
])
def test_the_band_rule_refuses_only_a_gap_between_two_explained_bands(
        monkeypatch, top, middle, bottom, texture, refused):
    verdict = _judged(monkeypatch, top_score=top, middle_score=middle, bottom_score=bottom,
                      middle_texture=texture)
    assert verdict.accepted is not refused, verdict.reason
    if refused:
        assert 'between them' in verdict.reason and verdict.ground


def test_a_far_wall_aliasing_a_periodic_floor_is_not_published(monkeypatch):
    # Sized floors seed 10002 (held out in the eleventh session, tuning since): a plane
    # through the textured far wall explains the 16 cm checker at the bottom one period off
    # and scores 0.46 against the true floor's 0.24 (under verification.min_score).
    frame = random_scene(10002, floor='checker_32')
    result = _run(frame)
    assert not result.ok and not result.mask.any() and result.confidence == 0.0
    monkeypatch.setattr(ground_rules, 'MIN_MIDDLE_SHARE', 0.0)
    # Its disparity also grows 10 deg off straight down the image: the level-head rule
    # (round 18) refuses it too, so it is switched off to see the plane.
    monkeypatch.setattr(trust_module.TrustGate, 'rolled_refusal', lambda *args: '')
    without = _run(frame)
    assert without.ok and plane_error_px(frame, without.homography) > 30.0
    # That plane is refused by the rule, named in its reason, and still a ground rival.
    monkeypatch.undo()
    gate = TrustGate(PlaneNodeConfig().verification)
    verdict = gate.judge(frame.left, frame.right, without.homography)
    assert not verdict.accepted and verdict.ground and 'between them' in verdict.reason
    check = verdict.verification
    assert check.middle_score < 0.5 * min(check.top_score, check.bottom_score)


def test_a_look_alike_leaning_on_the_far_wall_leaves_the_floor_to_win(monkeypatch):
    # Sized floors seed 1 (64 cm checker under a far wall): a plane leaning on the wall,
    # explaining more of it and less of the floor between (top / middle / bottom 0.44 /
    # 0.21 / 0.57 when judged, 2.7 px off), won and was finished 1.9 px off; refused, the
    # floor wins.
    frame = random_scene(1, floor='checker_128')
    result = _run(frame)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0
    monkeypatch.setattr(ground_rules, 'MIN_MIDDLE_SHARE', 0.0)
    without = _run(frame)
    assert without.ok and plane_error_px(frame, without.homography) > 1.5
