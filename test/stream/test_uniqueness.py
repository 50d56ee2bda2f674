"""A search publishes a plane only if it is unique, the swap tested and the ground at the bottom.

Each test here fails with its mechanism switched off: the wrong planes are the ones found on
the tuning seeds 30-129 of ``evaluate_trust`` (swapped cameras on periodic floors, a plane
through boxes), their truth from the renderer. Default configuration and prior throughout.
"""

from __future__ import annotations

from dataclasses import replace
import math

from domplane_ros.config import one_shot_search, PlaneNodeConfig, VerificationSettings
from domplane_ros.core.coarse import CoarseAligner
from domplane_ros.core.features import detect_corners
from domplane_ros.core.plane import estimate_plane
from domplane_ros.core.verification import verify_plane
from domplane_ros.sim.generators import random_scene
from domplane_ros.sim.rigs import (camera_response, plane_error_px, random_rig_error, rough_rig,
                                   swapped)
from domplane_ros.stream import ground_rules
from domplane_ros.stream import search as search_module
from domplane_ros.stream import trust as trust_module
from domplane_ros.stream import uniqueness as uniqueness_module
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.trust import TrustGate
from domplane_ros.stream.verdict import distinct_planes, Verdict
import numpy as np
import pytest
from truth import FOUND_MIN_SCORE, with_verification


def _run(frame, config=None):
    return PlanePipeline(config).process(frame.left, frame.right, 0)


def _counted_all(**changes) -> PlaneNodeConfig:
    """Return the default configuration with every textured pixel counted in the score.

    ``verification.covisible`` off, as before session 20: the scenes of the tests that use it
    were chosen so; co-visible (the default) each is solved or refused by a simpler rule,
    said in each test, and the rule shown would go untested. ``changes``: other
    ``verification.*`` settings (e.g. the scene's ``min_score``, :data:`FOUND_MIN_SCORE`).
    """
    return with_verification(covisible=False, **changes)


def _found() -> PlaneNodeConfig:
    """Return the default configuration under :data:`FOUND_MIN_SCORE`, as its scene was found."""
    return with_verification(min_score=FOUND_MIN_SCORE)


def _wrong_without(frame, monkeypatch, *patches, config=None):
    """Run the frame with each ``(module, name, value)`` patched: a wrong plane is published.

    Round 17's refusal of a weak finished winner with texture beyond it, round 18's roll of
    a published ground plane (``verification.max_ground_roll_deg``) and session 19's slope
    (``verification.prior_slope_margin``: it refuses the swapped look-alike of seed 0, whose
    disparity does not grow down the image) and session 20's bands (``MIN_BOTTOM_OVER_TOP``:
    it refuses the plane through the boxes of swapped seed 61, bottom under 0.75 x its top at
    confidence 0.82) are off too: they also refuse some of these planes, and the patched rule
    alone is what is tested.
    """
    monkeypatch.setattr(search_module, 'WEAK_BELOW_REFUSAL', False)
    monkeypatch.setattr(trust_module.TrustGate, 'rolled_refusal', lambda *args: '')
    monkeypatch.setattr(trust_module.TrustGate, 'slope_refusal', lambda *args: '')
    monkeypatch.setattr(ground_rules, 'MIN_BOTTOM_OVER_TOP', 0.0)
    for module, name, value in patches:
        monkeypatch.setattr(module, name, value)
    without = _run(frame, config)
    assert without.ok and plane_error_px(frame, without.homography) > 5.0


@pytest.mark.parametrize('seed', [68, 115])
def test_swapped_periodic_floor_is_not_published_as_a_look_alike(seed, monkeypatch, counted_score):
    # Tiles (68) and a checker of few corners (115: its swapped floor polished, not refined).
    frame = swapped(random_scene(seed))
    result = _run(frame)
    assert not result.ok and not result.mask.any() and result.confidence == 0.0
    assert 'swapped' in result.reason, result.reason
    # Without the swap's rivals a look-alike of the correctly ordered model is published.
    _wrong_without(frame, monkeypatch,
                   (search_module, 'swap_rivals', lambda *args, **kwargs: []))


def test_a_look_alike_that_sees_more_of_the_image_is_not_published(monkeypatch):
    # A 16 cm checker filling the view of a rough rig (tuning seed 48 of the sized floors):
    # with pixels counted, a plane 146 px off, of less disparity, maps more of the image
    # inside the right one and outscores the truth (0.36 against 0.30); on the pixels both
    # see they explain as much. Weighted by contrast (the default) the truth wins outright.
    frame = rough_rig(random_scene(48, floor='checker_32'),
                      random_rig_error(np.random.default_rng((48, 77))))
    default = _run(frame)
    assert default.ok and plane_error_px(frame, default.homography) < 1.0, default.reason
    original = trust_module.TrustGate.config
    monkeypatch.setattr(trust_module.TrustGate, 'config', lambda self, width: replace(
        original(self, width), weight_by_contrast=False))
    # Co-visible (the default since session 20) the scores themselves are of the pixels each
    # plane maps inside: the look-alike scores 0.47 against the truth's 0.49, and the pair is
    # refused as ambiguous before the shared pixels are compared (with or without this rule).
    result = _run(frame)
    assert not result.ok and 'explains the image almost as well' in result.reason, result.reason
    # Every textured pixel counted (as the scene was chosen) only this rule refuses it.
    result = _run(frame, _counted_all())
    assert not result.ok and 'both planes see' in result.reason, result.reason
    _wrong_without(frame, monkeypatch, (uniqueness_module, 'SHARED_RIVAL_SHARE', math.inf),
                   config=_counted_all())


@pytest.mark.parametrize('seed, rough', [(409, False), (453, True)])
def test_a_swapped_look_alike_with_texture_beyond_it_leaves_the_floor_unique(
        seed, rough, monkeypatch):
    # Fresh tuning seeds 370-489 (twelfth session): a tiled floor with nothing on it (409) and a
    # checker with boxes (453, rough rig) whose swapped look-alike (283 and 84 px off) scored
    # as well as the floor; the tiles' shading and the boxes lie beyond it in the swapped
    # reading, nothing beyond the floor.
    frame = random_scene(seed)
    if rough:
        frame = rough_rig(frame, random_rig_error(np.random.default_rng((seed, 77))))
    # Weighted by contrast (the default) the floor wins outright; the scenes were chosen with
    # pixels counted, where the swapped look-alike ties with the floor. Co-visible (the
    # default since session 20) it no longer ties: without the refutation the floor is
    # published (0.23 and 0.06 px, session 19), so the pixels are counted over all the
    # texture, as when the scenes were chosen.
    default = _run(frame)
    assert default.ok and plane_error_px(frame, default.homography) < 1.0
    original = trust_module.TrustGate.config
    monkeypatch.setattr(trust_module.TrustGate, 'config', lambda self, width: replace(
        original(self, width), weight_by_contrast=False))
    result = _run(frame, _counted_all())
    assert result.ok and plane_error_px(frame, result.homography) < 1.0
    # The same pair with the cameras swapped: the swapped floor is the truth, nothing lies
    # beyond it, and it is not refuted.
    assert not _run(swapped(frame), _counted_all()).ok
    monkeypatch.setattr(uniqueness_module, 'MIN_SWAP_BEYOND', math.inf)
    without = _run(frame, _counted_all())
    assert not without.ok and 'swapped' in without.reason, without.reason


def test_a_swapped_plane_is_a_rival_however_close_it_maps(monkeypatch):
    # Checker (seed 0): the swapped floor maps within 8 px of a look-alike 9 px off it.
    frame = swapped(random_scene(0))
    result = _run(frame)
    assert not result.ok and 'swapped' in result.reason, result.reason
    # The look-alike also sees texture beyond it (below_fraction): that check alone refuses
    # it as well, so it is switched off here to show the rival's part.
    _wrong_without(frame, monkeypatch,
                   (uniqueness_module, 'is_rival', lambda verdict, h, best, width, height: (
                       verdict.ground and distinct_planes(h, best, width, height))),
                   (ground_rules, 'MAX_BELOW_FRACTION', 1.0))


def test_a_plane_through_boxes_is_not_the_ground(monkeypatch, counted_score):
    frame = swapped(random_scene(61))
    # Under session 25's verification.min_score 0.22 the swapped floor is verified and judged
    # first: the pair is refused as swapped. The plane through the boxes is shown under 0.25,
    # as the scene was found.
    result = _run(frame)
    assert not result.ok and 'appear swapped' in result.reason, result.reason
    result = _run(frame, _found())
    assert not result.ok and 'not the ground' in result.reason, result.reason
    # Each of the three ground checks refuses it alone (measured): all off, it is published.
    _wrong_without(frame, monkeypatch, (trust_module, 'MIN_BOTTOM_SCORE', 0.0),
                   (trust_module, 'MIN_BOTTOM_SHARE', 0.0),
                   (ground_rules, 'MAX_BELOW_FRACTION', 1.0), config=_found())


def test_the_true_floor_explains_the_bottom_of_the_image():
    scene = random_scene(3)
    true = verify_plane(scene.left, scene.right, scene.homography)
    assert true.bottom_score > 3 * trust_module.MIN_BOTTOM_SCORE
    # With a region of interest the band is the region's own lowest rows (here mostly far
    # floor and boxes, which the plane explains less of).
    top = verify_plane(scene.left, scene.right, scene.homography, roi=(0.0, 0.0, 1.0, 0.4))
    assert top.bottom_score < true.bottom_score


@pytest.fixture(scope='module')
def scene():
    return random_scene(3)


def _estimate_at(scene, homography):
    cfg = PlaneNodeConfig().features
    estimate = estimate_plane(detect_corners(scene.left, cfg), detect_corners(scene.right, cfg),
                              init=scene.homography)
    assert estimate.ok
    return replace(estimate, homography=homography)


def test_a_distinct_plane_scoring_alike_makes_the_best_ambiguous(scene, monkeypatch):
    gate = TrustGate(VerificationSettings())
    true = _estimate_at(scene, scene.homography)
    alone, verdict, reason = gate.pick(scene.left, scene.right, [true])
    assert alone is true and reason == '' and math.isinf(verdict.uniqueness)
    # The same plane as a rival is not distinct: still unique.
    same, _, _ = gate.pick(scene.left, scene.right, [true], rivals=[scene.homography])
    assert same is true
    # A distinct plane (moved 30 px) scoring 0.9 of the truth: ambiguous, nothing published.
    moved = np.array([[1.0, 0.0, 30.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ scene.homography
    real = trust_module.verify_plane

    def scored(left, right, homography, config, roi=None, working=None):
        check = real(left, right, scene.homography, config, roi, working)
        if np.allclose(homography, moved):
            return replace(check, score=0.9 * check.score)
        return check

    monkeypatch.setattr(trust_module, 'verify_plane', scored)
    best, verdict, reason = gate.pick(scene.left, scene.right, [true], rivals=[moved])
    assert best is None and verdict is None and 'ambiguous' in reason, reason
    # A rival at 0.7 of the score (1.43 x) leaves the truth unique, confidence above 0.5.

    def scored_07(left, right, h, config, roi=None, working=None):
        check = real(left, right, scene.homography, config, roi, working)
        if np.allclose(h, moved):
            return replace(check, score=0.7 * check.score)
        return real(left, right, h, config, roi, working)

    monkeypatch.setattr(trust_module, 'verify_plane', scored_07)
    best, verdict, reason = gate.pick(scene.left, scene.right, [true], rivals=[moved])
    assert best is true and verdict.uniqueness == pytest.approx(1 / 0.7)
    assert 0.5 < verdict.confidence <= verdict.verification.confidence


def test_confidence_is_the_lesser_of_score_and_uniqueness(scene):
    check = TrustGate(VerificationSettings()).judge(scene.left, scene.right, scene.homography)
    assert check.confidence == check.verification.confidence > 0.5
    at_margin = replace(check, uniqueness=trust_module.CHALLENGE_MARGIN)
    assert at_margin.confidence == pytest.approx(0.5)
    tie = replace(check, uniqueness=1.0)
    assert tie.confidence == 0.0
    assert Verdict(True, check.verification, '', uniqueness=5.0).confidence == pytest.approx(
        check.verification.confidence)


def test_the_swap_rivals_are_found_only_once_a_plane_is_verified(monkeypatch):
    calls = []
    found = search_module.swap_rivals

    def counted(*args, **kwargs):
        calls.append(1)
        return found(*args, **kwargs)

    monkeypatch.setattr(search_module, 'swap_rivals', counted)
    # Swapped cameras on a floor where nothing of the given order verifies: refused by name,
    # no rivals needed.
    frame = swapped(random_scene(4))
    result = _run(frame)
    assert not result.ok and 'swapped' in result.reason, result.reason
    assert not calls
    # A verified plane: the swap is tested once, before it is published.
    frame = random_scene(6, floor='random')
    result = _run(frame)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0
    assert len(calls) == 1


def _faint_both(seed, config=None):
    """Return tuning seed ``seed``'s faint tiled floor and the pipeline evaluate_trust uses."""
    from domplane_ros.sim.textures import FAINT_TILE_KINDS
    config = one_shot_search(PlaneNodeConfig() if config is None else config)
    config = replace(config, features=replace(config.features, kind='both'))
    frame = random_scene(seed, floor=FAINT_TILE_KINDS[seed % len(FAINT_TILE_KINDS)])
    return frame, PlanePipeline(config)


@pytest.mark.parametrize('seed, module, name, off', [
    # 1.28 m faint tiles: a plane through the faces of two boxes (6.6 px off the floor) sees
    # the floor beyond it.
    (305, ground_rules, 'MAX_BELOW_FRACTION', 1.0),
    # A far wall's plane (8.1 px off the floor) explains the bottom of the image too little
    # for its score.
    (212, trust_module, 'MIN_BOTTOM_SHARE', 0.0),
])
def test_a_plane_above_the_floor_is_not_the_ground(seed, module, name, off, monkeypatch,
                                                   counted_score):
    # The plain coarse alignment only: on seed 305 the shifted one adds a plane 4 px off the
    # floor that outranks the plane through the boxes, which would hide the check's part.
    plain = CoarseAligner.candidates
    monkeypatch.setattr(CoarseAligner, 'candidates',
                        lambda self, left, right, shifted=True: plain(self, left, right, False))
    # And a winner not doubted, as when these checks were measured: on seed 212 with the
    # score counted, the further shifts add a plane 6.6 px off between the floor and the far
    # wall (bottom share 0.36 of its score) that wins where the floor is not found (session
    # 14, docs/BENCHMARKS.md trust round 15; weighted by contrast, the default, the floor is
    # published 0.64 px off).
    in_doubt = search_module.PlaneSearch._in_doubt
    monkeypatch.setattr(search_module.PlaneSearch, '_in_doubt', staticmethod(
        lambda search, verdict, limit: verdict is None and in_doubt(search, verdict, limit)))
    frame, pipeline = _faint_both(seed)
    result = pipeline.process(frame.left, frame.right, 0)
    assert not result.ok or plane_error_px(frame, result.homography) < 5.0, result.reason
    monkeypatch.setattr(module, name, off)
    # Session 22's near-field rule refuses these planes too: off, to see this rule alone.
    monkeypatch.setattr(TrustGate, 'near_field_refusal', lambda *args: '')
    frame, pipeline = _faint_both(seed)
    without = pipeline.process(frame.left, frame.right, 0)
    assert without.ok and plane_error_px(frame, without.homography) > 5.0


def test_nothing_lies_beyond_the_true_floor():
    for seed in range(3):
        scene = random_scene(seed)
        check = verify_plane(scene.left, scene.right, scene.homography)
        assert check.below_fraction < 0.2 * ground_rules.MAX_BELOW_FRACTION, (seed, check)


@pytest.mark.parametrize('bottom, swapped_expected', [(0.018, False), (0.5, True)])
def test_a_plane_sloping_the_swapped_way_is_a_swap_only_if_it_fills_the_bottom(
        bottom, swapped_expected, scene, monkeypatch):
    # The wall plane of a faint tiled floor (tuning seed 11 of the faint cases): verified over
    # the image (score 0.42) with a disparity slope of -0.03 px per row, yet explaining 1.8 %
    # of the bottom. It is a wall, not the floor of swapped cameras (which fills the bottom
    # like any floor): no swap reported and no rival of the floor. The same plane filling
    # the bottom is a swap.
    verification = verify_plane(scene.left, scene.right, scene.homography)
    faked = replace(verification, accepted=True, score=0.42, bottom_score=bottom)
    gate = TrustGate(VerificationSettings())
    monkeypatch.setattr(gate, '_verify', lambda *args: faked)
    sloping = np.array([[1.0, 0.03, -20.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    verdict = gate.judge(scene.left, scene.right, sloping)
    assert not verdict.accepted
    assert verdict.swapped is swapped_expected, verdict.reason
    assert verdict.ground is swapped_expected
    assert ('swapped' in verdict.reason) is swapped_expected, verdict.reason
    assert ('not the ground' in verdict.reason) is not swapped_expected, verdict.reason


def test_faint_large_tiles_give_the_floor_not_a_plane_five_pixels_off(monkeypatch):
    # Tuning faint seed 230 with features.kind both, as evaluate_trust's faint cases. Before
    # the twelfth round (docs/BENCHMARKS.md, trust round 12) the truth scored 0.19 (counted
    # pixels, < verification.min_score), the search's fits of the floor lay 2.0-5.2 px off,
    # and the one over the threshold (0.258: it ran through more of the boxes' bottoms) was
    # published 5.15 px off at confidence 0.54. Weighted by contrast the truth scores 0.29 and
    # that plane 0.24 (refused); the photometric refinement, sampling the faint floor, brings
    # the fits to the floor. Fails with either off (weight_by_contrast: the 2 px fits are
    # refused, nothing published; refine_min_gradient 20: refined toward the boxes).
    # Since the shared-pixels comparison (stream/uniqueness.py SHARED_RIVAL_SHARE, same session) a
    # distinct plane explains 0.90 of the floor's support on the pixels both see, so the
    # default refuses the pair as ambiguous: no plane over 5 px either way; the floor is
    # published without that comparison.
    frame, pipeline = _faint_both(230)
    result = pipeline.process(frame.left, frame.right, 0)
    assert not result.ok or plane_error_px(frame, result.homography) < 1.0, result.reason
    monkeypatch.setattr(uniqueness_module, 'SHARED_RIVAL_SHARE', math.inf)
    frame, pipeline = _faint_both(230)
    result = pipeline.process(frame.left, frame.right, 0)
    assert result.ok, result.reason
    assert plane_error_px(frame, result.homography) < 1.0


def test_a_winner_the_corners_cannot_finish_is_still_refined_photometrically():
    # Tuning faint seed 317 (1.28 m tiles): the search's best fits of the floor lie 4-6 px
    # off, sliding along the joints, and the best verified one (5.2 px, score 0.26) iterated to
    # the configured tolerance is refused; it was then published unrefined, 5.2 px off. Its
    # photometric refinement lands 0.07 px from the floor (score 0.47). Fails without it.
    frame, pipeline = _faint_both(317)
    result = pipeline.process(frame.left, frame.right, 0)
    assert result.ok, result.reason
    assert plane_error_px(frame, result.homography) < 1.0


@pytest.mark.parametrize('seed', [7001, 9017])
def test_an_ambiguous_pick_of_fits_of_one_faint_floor_refines_them_onto_it(monkeypatch, seed):
    # Tuning faint seeds 7001 and 9017 (1.28 m tiles, features.kind both; docs/BENCHMARKS.md,
    # round 16): the search's fits of the floor lie 2.9-9.7 px off it (7001: 2.9 px at 0.53
    # and 4.5 px at 0.55; 9017: 7.1 px at 0.25 beside 9.7 px at 0.25) and map the image bottom
    # more than 8 px apart, so each makes the other ambiguous and nothing was published. Refined
    # photometrically (search.CONTENDERS) they land on the floor together; off, refused.
    frame, pipeline = _faint_both(seed)
    result = pipeline.process(frame.left, frame.right, 0)
    assert result.ok, result.reason
    assert plane_error_px(frame, result.homography) < 1.0
    monkeypatch.setattr(search_module, 'REFINE_CONTENDERS', False)
    frame, pipeline = _faint_both(seed)
    without = pipeline.process(frame.left, frame.right, 0)
    assert not without.ok and 'ambiguous' in without.reason, without.reason


def test_a_swapped_rival_is_refuted_only_where_nothing_lies_beyond_the_winner(
        monkeypatch, counted_score):
    # Tuning faint seed 11 (1.28 m tiles, features.kind both; pixels counted in the score, as
    # when it was found: weighted, the floor is published 0.46 px off): the winner, 6.1 px off the
    # floor, has 8.5 % of the texture beyond it, its swapped rival 54 %. Refuting the rival
    # on the ratio alone published the winner (evaluate_trust, twelfth session); the winner
    # must itself have (almost) nothing beyond it. Co-visible (the default since session 20)
    # the swapped rival no longer ties with the winner: the pair is refused by the level-head
    # rule (-15 deg), and without that rule the winner is published 3.6 px off whatever this
    # rule says; so the rule is shown with every textured pixel counted, as it was found.
    frame, pipeline = _faint_both(11)
    result = pipeline.process(frame.left, frame.right, 0)
    assert not result.ok and 'not the ground of a level head' in result.reason, result.reason
    # Counted under session 25's verification.min_score 0.22 the level-head rule refuses it
    # too; the rule shown is measured under 0.25, as the scene was found.
    frame, pipeline = _faint_both(11, _counted_all())
    result = pipeline.process(frame.left, frame.right, 0)
    assert not result.ok and 'not the ground of a level head' in result.reason, result.reason
    frame, pipeline = _faint_both(11, _counted_all(min_score=FOUND_MIN_SCORE))
    result = pipeline.process(frame.left, frame.right, 0)
    # The rival is no floor of swapped cameras (read so, its own mask sees no ground; session
    # 23 names it by its slope, the decision is the same): ambiguous.
    assert not result.ok and 'ambiguous' in result.reason, result.reason
    assert 'shrinks toward the image bottom' in result.reason, result.reason
    monkeypatch.setattr(uniqueness_module, 'MAX_WINNER_BEYOND', math.inf)
    # Round 18's roll of a published ground plane refuses it too.
    monkeypatch.setattr(trust_module.TrustGate, 'rolled_refusal', lambda *args: '')
    frame, pipeline = _faint_both(11, _counted_all(min_score=FOUND_MIN_SCORE))
    without = pipeline.process(frame.left, frame.right, 0)
    # 3.5 px off since the refinement samples the faint floor (round 12; 6.1 px before it):
    # still not the floor.
    assert without.ok and plane_error_px(frame, without.homography) > 2.0


def test_a_better_fit_with_texture_beyond_it_makes_the_winner_ambiguous(monkeypatch):
    # evaluate_trust lighting, tuning seed 168 (cameras that see the light differently): the
    # floor fitted 1.35 px off scores 0.465 but is refused for 3 % of the texture beyond it; a
    # plane 5.5 px off (0.29) was published beside it. The winner, finished, must score at
    # least as much as such a plane of its pick: the pair is refused as ambiguous.
    seed = 168
    frame = camera_response(random_scene(seed, gain=None, offset=None),
                            np.random.default_rng((seed, 555)))
    config = one_shot_search(PlaneNodeConfig())
    result = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert not result.ok and 'texture beyond it' in result.reason, result.reason
    monkeypatch.setattr(uniqueness_module, 'BEYOND_RIVAL_SHARE', math.inf)
    monkeypatch.setattr(search_module, 'WEAK_BELOW_REFUSAL', False)  # round 17's refusal
    # Round 18's roll of a published ground plane refuses it too.
    monkeypatch.setattr(trust_module.TrustGate, 'rolled_refusal', lambda *args: '')
    without = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert without.ok and plane_error_px(frame, without.homography) > 5.0


def test_a_winner_refined_past_the_plane_with_texture_beyond_it_is_published():
    # Found by a review (session 14): evaluate_trust cold, tuning seed 7024. The search's
    # pick is a plane 6.43 px off at 0.39 beside planes 2.45-3.68 px off refused for 4-7 % of
    # the texture beyond them (up to 0.46); finished (tolerance, polish, photometric
    # refinement) it is 0.13 px off at 0.70 and outscores them. Held against them before the
    # finish, the pair was refused: a correct plane lost.
    frame = random_scene(7024)
    result = PlanePipeline(one_shot_search(PlaneNodeConfig())).process(frame.left, frame.right, 0)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0, result.reason
