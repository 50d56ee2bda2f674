"""The co-visible score: only the pixels both cameras see count, and its guard."""

from __future__ import annotations

from dataclasses import replace

import cv2
from domplane_ros.config import VerificationSettings
from domplane_ros.core import verification
from domplane_ros.stream.trust import TrustGate
from domplane_ros.tools.evaluate_real_rigs import kitti_base
from domplane_ros.tools.evaluation.real_rigs import draw
import numpy as np
import pytest
from truth import FOUND_MIN_SCORE


def _gate_config(width: int, min_score: float | None = None
                 ) -> verification.VerificationConfig:
    """Return the pipeline's verification settings at this width (the defaults).

    ``min_score``: under this ``verification.min_score`` instead of the default.
    """
    settings = VerificationSettings()
    if min_score is not None:
        settings = replace(settings, min_score=min_score)
    return TrustGate(settings).config(width)


def _translate(dx: float, dy: float) -> np.ndarray:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


@pytest.fixture(scope='module')
def offset_pair():
    """KITTI 000046 with the right camera 14.8 px lower (real texture, tuning seed 3)."""
    pair = draw(kitti_base(), 'rig_vertical', 3)
    assert 'vertical_px=-14.8' in pair.detail
    return pair


def test_a_vertical_offset_no_longer_counts_the_near_road_against_the_truth(offset_pair):
    """The near road leaves the right image; counted, the truth falls under 0.25.

    All textured pixels: 0.246 (refused, 'explains too little', under the
    ``verification.min_score`` 0.25 the pair was found with; session 25's default 0.22 accepts
    it); the pixels both cameras see: 0.275 (accepted). The bottom band, where the road
    leaves, gains most.
    """
    pair = offset_pair
    default = verification.verify_plane(pair.left, pair.right, pair.truth,
                                        replace(_gate_config(pair.left.shape[1]),
                                                covisible=False))
    assert default.accepted and 0.22 <= default.score < 0.25, default
    config = replace(_gate_config(pair.left.shape[1], min_score=FOUND_MIN_SCORE),
                     covisible=False)
    counted = verification.verify_plane(pair.left, pair.right, pair.truth, config)
    covisible = verification.verify_plane(pair.left, pair.right, pair.truth,
                                          replace(config, covisible=True))
    assert not counted.accepted and counted.score < 0.25, counted
    assert counted.reason == verification.REASON_LOW_SUPPORT
    assert covisible.accepted and covisible.score >= 0.25, covisible
    assert covisible.bottom_score > counted.bottom_score
    # The same pixels support the plane; only the divisor changed, and by at most the floor.
    assert covisible.support_fraction == counted.support_fraction
    assert covisible.score <= counted.score / config.covisible_floor
    # Planes 5 px off the truth stay refused, also under the default min_score.
    for shift in ((5.0, 0.0), (-5.0, 0.0), (0.0, 5.0)):
        for gate in (config, _gate_config(pair.left.shape[1])):
            moved = verification.verify_plane(pair.left, pair.right,
                                              _translate(*shift) @ pair.truth,
                                              replace(gate, covisible=True))
            assert not moved.accepted, (shift, moved)


def test_a_plane_mapping_mostly_outside_cannot_score_on_what_it_maps_inside():
    """The right image's left fifth repeats the left image's right fifth.

    The plane moving the image left by four fifths maps only that fifth inside and matches
    it all: counted it scores 0.2 (refused); divided by what it maps inside it would score
    1.0; the guard refuses it for mapping too little inside (``covisible_floor``).
    """
    rng = np.random.default_rng(4)
    width, height = 320, 240
    left = cv2.GaussianBlur(rng.integers(0, 255, (height, width), dtype=np.uint8), (0, 0), 1.0)
    right = left.copy()
    strip = width // 5
    right[:, :strip] = left[:, width - strip:]
    wrong = _translate(-(width - strip), 0.0)
    config = replace(_gate_config(width), covisible=False)
    covisible = replace(config, covisible=True)
    assert verification.verify_plane(left, right, np.eye(3), covisible).accepted
    counted = verification.verify_plane(left, right, wrong, config)
    assert not counted.accepted and counted.reason == verification.REASON_LOW_SUPPORT
    guarded = verification.verify_plane(left, right, wrong, covisible)
    assert not guarded.accepted
    assert guarded.reason == verification.REASON_NO_OVERLAP
    assert guarded.overlap_fraction < covisible.covisible_floor
    # Without the guard the wrong plane would be accepted at full confidence.
    unguarded = verification.verify_plane(left, right, wrong,
                                          replace(covisible, covisible_floor=0.0))
    assert unguarded.accepted and unguarded.score > 0.9, unguarded


def test_the_score_divides_by_what_the_plane_maps_inside():
    """A true plane mapping 60 % inside: its score is the counted one over that share."""
    rng = np.random.default_rng(5)
    width, height = 320, 240
    left = cv2.GaussianBlur(rng.integers(0, 255, (height, width), dtype=np.uint8), (0, 0), 1.0)
    shift = int(0.4 * width)
    right = np.zeros_like(left)
    right[:, :width - shift] = left[:, shift:]
    plane = _translate(-shift, 0.0)
    config = replace(_gate_config(width), covisible=False)
    counted = verification.verify_plane(left, right, plane, config)
    covisible = verification.verify_plane(left, right, plane, replace(config, covisible=True))
    maps = verification.agreement_maps(left, right, plane, config)
    inside = float(maps.weight[maps.inside].sum()) / float(maps.weight.sum())
    assert 0.5 < inside < 0.65 and 0.5 < counted.overlap_fraction < 0.65
    assert covisible.score == pytest.approx(counted.score / inside, rel=1e-5)
    assert covisible.accepted and covisible.score > 0.9
    # A floor above the share it maps inside refuses it.
    strict = verification.verify_plane(left, right, plane,
                                       replace(config, covisible=True, covisible_floor=0.7))
    assert strict.reason == verification.REASON_NO_OVERLAP


@pytest.mark.parametrize('value', [-0.1, 1.5, float('nan')])
def test_the_floor_is_validated(value: float) -> None:
    with pytest.raises(ValueError, match='covisible_floor'):
        verification.VerificationConfig(covisible_floor=value)


def test_ground_planes_are_covisible_by_default_and_any_planes_counted() -> None:
    """The pipeline's ground planes use it (``verification.covisible``, session 20); boards not.

    The core's own default stays off (a bare :class:`VerificationConfig` counts every
    textured pixel); ``verification.plane: any`` keeps the count its own-region rule was
    measured with, and ``verification.covisible: false`` switches it off.
    """
    assert _gate_config(640).covisible
    assert not verification.VerificationConfig().covisible
    assert not TrustGate(VerificationSettings(plane='any')).config(640).covisible
    assert not TrustGate(VerificationSettings(covisible=False)).config(640).covisible
