"""Verify, then publish: the trust gate and the pipeline on cuts, swaps and rough rigs.

Ground truth comes from the renderer; the rough rigs and swaps from :mod:`domplane_ros.sim.rigs`.
Every configuration here is the documented default (no prior built from a scene's truth).
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial
import math
from types import SimpleNamespace

from domplane_ros.config import one_shot_search, PlaneNodeConfig, VerificationSettings
from domplane_ros.core import coarse as coarse_module
from domplane_ros.core import verification
from domplane_ros.core.estimator import TwoStep
from domplane_ros.core.features import detect_corners
from domplane_ros.core.homography import corner_distance_px
from domplane_ros.core.plane import estimate_plane
from domplane_ros.sim.generators import indoor_scene, random_scene, scene_sequence
from domplane_ros.sim.rigs import (camera_response, cut_sequence, plane_error_px,
                                   random_rig_error, RigError, rough_rig, swapped)
from domplane_ros.sim.textures import SIZED_FLOOR_KINDS
from domplane_ros.stream import candidates as candidates_module
from domplane_ros.stream import search as search_module
from domplane_ros.stream import trust as trust_module
from domplane_ros.stream.candidates import (CANDIDATE_TOLERANCE_PX, CandidateWork,
                                            photometric_estimate)
from domplane_ros.stream.pipeline import LOCKED, PlanePipeline
from domplane_ros.stream.trust import TrustGate
import numpy as np
import pytest
from truth import FOUND_MIN_SCORE, with_verification

PERIOD_NS = 33_333_333


@pytest.fixture(scope='module')
def scene():
    return random_scene(3)


def _shifted(h: np.ndarray, dx: float, dy: float = 0.0) -> np.ndarray:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]]) @ h


def test_true_plane_passes_and_shifted_planes_do_not(scene):
    gate = TrustGate(VerificationSettings())
    true = gate.judge(scene.left, scene.right, scene.homography)
    assert true.accepted and true.confidence > 0.5, true.reason
    for dx, dy in ((8.0, 0.0), (0.0, 8.0), (25.0, 0.0)):
        wrong = gate.judge(scene.left, scene.right, _shifted(scene.homography, dx, dy))
        assert not wrong.accepted and 'not verified' in wrong.reason
        assert wrong.score < true.score


def test_cameras_that_see_the_light_differently_change_no_verdict():
    # Right camera 1.2x gain and -15 grey levels, each camera its own response and vignetting.
    plain = random_scene(3, gain=1.2, offset=-15.0)
    seen = camera_response(plain, np.random.default_rng(7), gamma=(0.75, 1.33),
                           vignetting=(0.25, 0.35))
    gate = TrustGate(VerificationSettings())
    true = gate.judge(seen.left, seen.right, seen.homography)
    assert true.accepted and true.confidence > 0.5, true.reason
    for dx, dy in ((8.0, 0.0), (0.0, 8.0), (25.0, 0.0)):
        wrong = gate.judge(seen.left, seen.right, _shifted(seen.homography, dx, dy))
        assert not wrong.accepted and wrong.score < true.score


def test_swapped_cameras_are_named(scene):
    pair = swapped(scene)
    gate = TrustGate(VerificationSettings())
    verdict = gate.judge(pair.left, pair.right, pair.homography)
    assert not verdict.accepted and verdict.swapped
    assert 'swapped' in verdict.reason
    # The same plane on the pair as given is a ground plane and passes.
    assert gate.judge(scene.left, scene.right, scene.homography).accepted


def test_a_plane_facing_the_camera_is_not_taken_for_the_ground(scene):
    gate = TrustGate(VerificationSettings())
    # A pure translation has no disparity gradient: a fronto-parallel plane (a wall).
    verdict = gate.judge(scene.left, scene.right, _shifted(np.eye(3), -20.0))
    assert not verdict.accepted and 'not a ground plane' in verdict.reason


def test_a_lock_whose_score_collapses_is_refused(scene, monkeypatch):
    gate = TrustGate(VerificationSettings(drop_ratio=0.5))
    first = gate.judge(scene.left, scene.right, scene.homography, locked=True)
    gate.record(first)
    weaker = first.verification.__class__(**{**first.verification.__dict__,
                                             'score': 0.4 * first.score})
    monkeypatch.setattr(trust_module, 'verify_plane', lambda *a, **k: weaker)
    verdict = gate.judge(scene.left, scene.right, scene.homography, locked=True)
    assert not verdict.accepted and 'view changed' in verdict.reason
    # Not locked (a new search): the absolute threshold alone applies.
    assert gate.judge(scene.left, scene.right, scene.homography).accepted == weaker.accepted


def test_a_lock_whose_view_changed_is_held_against_its_recent_scores():
    # Round 23 (mutants): with the drop_ratio check off only the test above (a stubbed score)
    # failed. The lock started on a faint indoor floor (seed 3: score 0.31, 89 % of the
    # bottom); the view changed under it to a floor scoring 0.70 (random scene 0, three pairs).
    # A warm plane 4 px off that floor scores 0.29 with 40 % of the bottom: above 0.7 x and
    # 0.4 x what the lock started from, so its reference keeps it; its recent median refuses it.
    gate = TrustGate(VerificationSettings())
    start = indoor_scene(3)
    gate.record(gate.judge(start.left, start.right, start.homography, locked=True))
    view = random_scene(0)
    for _ in range(3):
        held = gate.judge(view.left, view.right, view.homography, locked=True)
        assert held.accepted, held.reason
        gate.record(held)
    slid = _shifted(view.homography, 4.0)
    assert plane_error_px(view, slid) > 3.5
    verdict = gate.judge(view.left, view.right, slid, locked=True)
    reference = gate.lock_reference
    assert verdict.score >= trust_module.LOCK_REFERENCE_RATIO * reference.score
    assert verdict.verification.bottom_score >= (
        trust_module.LOCK_BOTTOM_RATIO * reference.bottom_score)
    assert not verdict.accepted and verdict.lock_refusal == 'drop', verdict.reason


# 186: a cut to a scene of 9 corners (evaluate_trust tuning seed 186): the lock, refined
# photometrically, gives no plane; carried as 'tracking' it re-locked after 4 pairs.
def _cut_run(before, after, seed):
    """Return a fresh pipeline's results over a cut sequence and their errors (None: none)."""
    frames = cut_sequence(before, after, seed)
    pipeline = PlanePipeline()
    results = [pipeline.process(f.left, f.right, i * PERIOD_NS) for i, f in enumerate(frames)]
    errors = [plane_error_px(f, r.homography) if r.ok else None
              for f, r in zip(frames, results)]
    assert all(e is None or e < 5.0 for e in errors), errors
    return results, errors


# Seeds 0 and 3 were dropped for the test run's time (10 s each): evaluate_trust's cuts (40
# tuning seeds), the replay's and the node's cut tests assert the same.
@pytest.mark.parametrize('seed', [1, 186])
def test_a_cut_relocks_within_three_pairs_and_publishes_no_wrong_plane(seed):
    results, errors = _cut_run(6, 6, seed)
    after = errors[6:]
    relock = next(i for i, e in enumerate(after) if e is not None and e < 1.0)
    assert relock < 3, errors
    assert results[6 + relock].state == LOCKED and results[6 + relock].confidence >= 0.5


# Cuts whose previous pair cannot be tracked into the first pair after the cut (evaluate_trust
# tuning seeds, 8 pairs before and after): the lock, warm-started from the last plane, slid
# onto the new floor 2.65 px off (60; verified, 5 pairs to come within 1 px) or failed and was
# carried as 'tracking' for 2 pairs before a search (19: re-lock after 4 pairs). A lost track
# is a cut: the search runs in the first pair after it (pipeline.SEARCH_ON_LOST_TRACK).
@pytest.mark.parametrize('seed', [19, 60])
def test_a_cut_that_breaks_the_track_searches_at_once(seed):
    results, errors = _cut_run(8, 8, seed)
    assert results[8].reinitialised, results[8].warm_start  # the search ran in the first pair
    # ... and the pair says why the lock was dropped (its reason is the search's, if any).
    assert results[8].lock_lost is not None and results[8].lock_lost.kind == 'cut'
    assert results[8].refusals[0] == results[8].lock_lost
    relock = next(i for i, e in enumerate(errors[8:]) if e is not None and e < 1.0)
    assert relock < 3, errors
    assert results[8 + relock].state == LOCKED


def test_swapped_pair_is_refused_by_name_not_published():
    pair = swapped(random_scene(4))
    result = PlanePipeline().process(pair.left, pair.right, 0)
    assert not result.ok and result.homography is None and not result.mask.any()
    assert 'swapped' in result.reason, result.reason
    assert result.confidence == 0.0


def test_rough_rig_outside_the_prior_model_is_solved_by_the_coarse_alignment():
    frame = rough_rig(random_scene(9), RigError(roll_deg=3.0, pitch_deg=1.5, focal_ratio=1.03,
                                                principal_offset_px=(7.0, -7.0)))
    result = PlanePipeline().process(frame.left, frame.right, 0)
    assert result.ok, result.reason
    assert plane_error_px(frame, result.homography) < 1.0
    # Without the coarse alignment the prior grid alone: no wrong plane either way.
    off = replace(PlaneNodeConfig(), verification=VerificationSettings(coarse_candidates=False))
    without = PlanePipeline(off).process(frame.left, frame.right, 0)
    assert not without.ok or plane_error_px(frame, without.homography) < 5.0


def test_a_challenger_needs_clearly_more_than_the_lock(scene):
    gate = TrustGate(VerificationSettings())
    lock = gate.judge(scene.left, scene.right, scene.homography)
    assert lock.accepted

    def scored(peak: float):
        # The comparison is by the peak score (planes a few pixels apart); the score is kept.
        check = lock.verification.__class__(**{**lock.verification.__dict__,
                                               'peak_score': peak})
        return trust_module.Verdict(True, check, '')

    assert not gate.beats(scored(1.1 * lock.peak_score), lock)
    assert gate.beats(scored(1.3 * lock.peak_score), lock)
    assert not gate.beats(trust_module.Verdict(False, scored(2 * lock.peak_score).verification,
                                               'refused'), lock)


def test_a_challenger_no_better_than_a_true_lock_does_not_replace_it():
    # Round 23 (mutants): with the margin of TrustGate.beats at 0 only the test above (stubbed
    # peak scores) failed. Locked on the floor of a rendered sequence and challenged on every
    # pair, the challengers refined from the prior's starts land on the same floor: without
    # the 1.2 x margin one replaced the lock with itself (pair 6; at 640 x 480 pairs 3 and 6),
    # a lost lock and a reset history for nothing.
    frames = scene_sequence(8, 3, width=320, height=240, floor='random')
    base = PlaneNodeConfig()
    pipeline = PlanePipeline(replace(base, verification=replace(base.verification,
                                                                challenge_period=1)))
    results = [pipeline.process(f.left, f.right, i * PERIOD_NS) for i, f in enumerate(frames)]
    assert all(r.ok and plane_error_px(f, r.homography) < 0.5 for f, r in zip(frames, results))
    assert sum(r.timings_ms['challenge'] > 0.0 for r in results) >= 6  # challenged throughout
    assert [r.warm_start for r in results[1:]] == ['prediction'] * 7
    assert all(r.lock_lost is None for r in results[1:])


# A gate low enough that a plane 2 px off the truth still passes (score 0.31 against 0.36
# for the truth on this scene, peak score 0.16 against 0.28): two verified planes, one
# clearly better.
LOW_GATE = VerificationSettings(min_score=0.12)


def _estimate_at(scene, homography):
    estimate = estimate_plane(*_corners(scene), init=scene.homography)
    assert estimate.ok
    return replace(estimate, homography=homography)


def _corners(scene):
    cfg = PlaneNodeConfig().features
    return detect_corners(scene.left, cfg), detect_corners(scene.right, cfg)


def test_pick_ranks_verified_planes_by_score_in_any_order(scene):
    gate = TrustGate(LOW_GATE)
    worse = _shifted(scene.homography, 2.0)
    assert gate.judge(scene.left, scene.right, worse).accepted
    true, off = _estimate_at(scene, scene.homography), _estimate_at(scene, worse)
    for order in ([true, off], [off, true]):
        best, verdict, reason = gate.pick(scene.left, scene.right, order)
        assert best is not None and reason == ''
        # Fails if the ranking is inverted (the worst verified plane picked).
        assert plane_error_px(scene, best.homography) < 0.5, order


@pytest.mark.parametrize('held', ['warm estimate', 'anchor'])
@pytest.mark.parametrize('period', [3, 0])
def test_the_challenger_replaces_a_lock_stuck_on_a_worse_plane(scene, monkeypatch, period, held):
    settings = replace(LOW_GATE, challenge_period=period)
    pipeline = PlanePipeline(replace(PlaneNodeConfig(), verification=settings))
    stamp = 0
    for _ in range(3):
        result = pipeline.process(scene.left, scene.right, stamp)
        stamp += PERIOD_NS
    assert result.ok and plane_error_px(scene, result.homography) < 1.0
    # From now on the warm start is stuck 2 px off (as in a look-alike's basin): only the
    # challenger can bring the lock back. 'warm estimate': the warm pair's anchor (a tight fit
    # of the good prediction, stream/warm.py WARM_ANCHOR) is off, else it would bring it
    # back. 'anchor': the lock itself is stuck (so is the prediction, the anchor's start) and
    # the anchor's tight fit of it holds it until the challenge.
    worse = _shifted(scene.homography, 2.0)
    stuck = _estimate_at(scene, worse)
    monkeypatch.setattr(pipeline._warm, 'estimate', lambda *args: stuck)
    if held == 'anchor':
        pipeline._last_h = worse.copy()
    else:
        monkeypatch.setattr(pipeline._warm, 'anchored', lambda problem, init, estimate: estimate)
    errors, starts = [], []
    for _ in range(4):
        result = pipeline.process(scene.left, scene.right, stamp)
        stamp += PERIOD_NS
        assert result.ok
        errors.append(plane_error_px(scene, result.homography))
        starts.append(result.warm_start)
    assert errors[0] > 1.5, (starts, errors)
    if period:
        assert 'challenger' in starts and min(errors) < 1.0, (starts, errors)
    else:
        # Fails if the challenger runs although it is switched off.
        assert 'challenger' not in starts and min(errors) > 1.5, (starts, errors)


def test_a_challenger_refused_as_not_the_ground_is_recorded_and_the_lock_stays(
        scene, monkeypatch):
    # As above (the lock stuck 2 px off, the challenger finds the floor), but the gate's ground
    # rules refuse the floor: the lock stays, and the refusal is on record (the pair's refusals
    # and the counts since start), not silently dropped (review of session 20).
    settings = replace(LOW_GATE, challenge_period=3)
    pipeline = PlanePipeline(replace(PlaneNodeConfig(), verification=settings))
    stamp = 0
    for _ in range(3):
        pipeline.process(scene.left, scene.right, stamp)
        stamp += PERIOD_NS
    worse = _shifted(scene.homography, 2.0)
    stuck = _estimate_at(scene, worse)
    monkeypatch.setattr(pipeline._warm, 'estimate', lambda *args: stuck)
    monkeypatch.setattr(pipeline._warm, 'anchored', lambda problem, init, estimate: estimate)
    real = TrustGate.ground_refusal

    def refuse_the_floor(self, homography, width, height, check=None):
        if plane_error_px(scene, homography) < 1.0:
            return 'not the ground: refused by this test'
        return real(self, homography, width, height, check)

    monkeypatch.setattr(TrustGate, 'ground_refusal', refuse_the_floor)
    results = []
    for _ in range(4):
        results.append(pipeline.process(scene.left, scene.right, stamp))
        stamp += PERIOD_NS
    assert all(r.ok and plane_error_px(scene, r.homography) > 1.5 for r in results)
    assert all(r.warm_start != 'challenger' and r.lock_lost is None for r in results)
    refused = [f for r in results for f in r.refusals if f.kind == 'challenge']
    assert refused and 'refused by this test' in refused[0].reason
    assert pipeline.stats.refusals.planes_refused['challenge'] == len(refused)


def test_the_challenger_does_not_refine_starts_at_the_lock(scene, monkeypatch):
    settings = replace(LOW_GATE, challenge_period=3)
    pipeline = PlanePipeline(replace(PlaneNodeConfig(), verification=settings))
    result = None
    for i in range(2):
        result = pipeline.process(scene.left, scene.right, i * PERIOD_NS)
    assert result.ok and plane_error_px(scene, result.homography) < 1.0
    lock = result.homography
    near = [lock, _shifted(lock, 3.0, -2.0)]
    far = [_shifted(lock, 40.0), _shifted(lock, 41.0)]  # two starts, one refined

    def aligned(left, right):  # the challenge's alignment: two steps, then its planes
        yield
        return np.stack(near + far)

    monkeypatch.setattr(pipeline._trust.planes, 'coarse_steps', aligned)
    starts = []
    original = TwoStep.estimate

    def recording(self, init, options, **kwargs):
        starts.append(np.array(init))
        return original(self, init, options, **kwargs)

    monkeypatch.setattr(TwoStep, 'estimate', recording)
    # The challenge is spread over pairs: the coarse alignment in the first two, then one
    # start per pair (moved through the tracked motion: here the same images, so nearly
    # nowhere).
    for i in range(2, 7):
        pipeline.process(scene.left, scene.right, i * PERIOD_NS)
    height, width = scene.left.shape
    # (The lock itself is each pair's warm start, so it is not counted.)
    refined = [sum(corner_distance_px(s, c, width, height) < 0.5 for s in starts)
               for c in (near[1], far[0], far[1])]
    assert refined == [0, 1, 0], refined


def test_search_candidates_stop_early_and_the_published_winner_is_finished(monkeypatch):
    tolerances = []
    estimate = TwoStep.estimate

    def spy(self, init, options, *, widen=None):
        tolerances.append(options.tolerance_px)
        return estimate(self, init, options, widen=widen)

    monkeypatch.setattr(TwoStep, 'estimate', spy)
    picked = []
    pick = TrustGate.pick

    def pick_spy(self, *args, **kwargs):
        out = pick(self, *args, **kwargs)
        picked.append(out[1])
        return out

    monkeypatch.setattr(TrustGate, 'pick', pick_spy)
    frame = random_scene(6, floor='random')
    result = PlanePipeline().process(frame.left, frame.right, 0)
    assert result.ok, result.reason
    assert plane_error_px(frame, result.homography) < 0.5
    # The finished plane's confidence: its own verification, with the candidate's uniqueness
    # among the planes judged beside it (never more certain than the search was).
    again = TrustGate(VerificationSettings()).judge(frame.left, frame.right, result.homography)
    expected = replace(again, uniqueness=picked[-1].uniqueness).confidence
    assert result.confidence == pytest.approx(expected)
    # Every prior candidate (and swapped rival) stopped at the candidates' tolerance; the
    # last run, the winner's finish, at the configured one.
    configured = PlaneNodeConfig().estimator.tolerance_px
    assert tolerances.count(CANDIDATE_TOLERANCE_PX) >= result.candidates > 0
    assert tolerances[-1] == configured < CANDIDATE_TOLERANCE_PX


@pytest.mark.parametrize('make', [lambda: random_scene(101, floor='random'),
                                  lambda: swapped(random_scene(68))], ids=['cold', 'swapped68'])
def test_rivals_stopped_early_publish_the_same(monkeypatch, counted_score, make):
    # The swapped rivals stop at the candidates' tolerance (fewer rounds): the same plane,
    # confidence and uniqueness as with rivals run to the configured one (measured: the
    # coarse starts stopped there too move the uniqueness on cold 101 and, on seed 68,
    # lose the coarse look-alike that only the swapped rivals refuse). Seed 68 is ambiguous:
    # decided by the rivals refined again to the configured tolerance.
    frame = make()
    rounds, picked = [], []
    estimate, pick = TwoStep.estimate, TrustGate.pick

    def spy(self, init, options, *, widen=None):
        out = estimate(self, init, options, widen=widen)
        rounds.append(getattr(out, 'iterations', 0))
        return out

    def pick_spy(self, *args, **kwargs):
        out = pick(self, *args, **kwargs)
        picked.append(out[1].uniqueness if out[1] is not None else out[2])
        return out

    monkeypatch.setattr(TwoStep, 'estimate', spy)
    monkeypatch.setattr(TrustGate, 'pick', pick_spy)
    runs = []
    for options in (None, property(lambda work: work.config.estimator)):
        if options is not None:  # the configured tolerance, as before the eighth round
            monkeypatch.setattr(CandidateWork, 'rival_options', options)
        rounds.clear()
        picked.clear()
        result = PlanePipeline().process(frame.left, frame.right, 0)
        runs.append((result, sum(rounds), list(picked)))
    (short, short_rounds, short_picked), (full, full_rounds, full_picked) = runs
    assert short.ok == full.ok and short.reason == full.reason
    if short.ok:
        assert short_picked == pytest.approx(full_picked, rel=1e-9)
        assert plane_error_px(frame, short.homography) < 0.5
        assert np.abs(short.homography - full.homography).max() < 1e-9
        assert short.confidence == full.confidence
    else:
        assert short_picked == full_picked and 'swapped' in short.reason, short.reason
        # Picked again with the rivals rechecked, and once more in doubt (the coarse
        # alignment's further shifts added).
        assert len(short_picked) == 3
        return
    assert short_rounds < 0.9 * full_rounds, (short_rounds, full_rounds)


def test_sharing_the_shrunk_pair_changes_no_verdict(scene):
    gate = TrustGate(VerificationSettings())
    planes = [scene.homography, _shifted(scene.homography, 2.0), _shifted(scene.homography, 30.0)]
    alone = [gate.judge(scene.left, scene.right, h).verification for h in planes]
    gate.begin_pair(scene.left, scene.right)
    shared = [gate.judge(scene.left, scene.right, h).verification for h in planes]
    assert gate._working is not None and gate._working.left.shape[1] == 160
    # Other arrays (a copy) are verified as without the shared pair.
    copy = gate.judge(scene.left.copy(), scene.right, planes[0]).verification
    gate.end_pair()
    assert gate._working is None
    for a, b in zip(alone + alone[:1], shared + [copy]):
        assert replace(a, time_ms=0.0) == replace(b, time_ms=0.0)


def test_working_images_of_another_size_are_refused(scene):
    working = verification.working_pair(scene.left, scene.right)
    small = scene.left[:240, :320]
    with pytest.raises(ValueError, match='working images made for'):
        verification.verify_plane(small, small, np.eye(3), working=working)


@pytest.mark.parametrize('seed', [7, 28])
def test_the_published_winner_is_polished_on_its_closest_features(monkeypatch, seed):
    # The Euclidean refinement's 3 px inlier band lets a tiled or planked floor's
    # neighbouring corners pull the fit; polished on the features within half of it, the
    # winner comes closer to the truth (measured on these seeds: 0.83 -> 0.17 px and
    # 0.84 -> 0.36 px; seed 17, 1.55 -> 0.81 px until session 14, has had a better winner
    # since every search is in doubt: 0.58 -> 0.37 px). The guard: a polished plane that
    # loses peak score is not taken.
    seen = []
    tightened = CandidateWork.tightened

    def spy(self, step, problem, estimate, verdict):
        out = tightened(self, step, problem, estimate, verdict)
        seen.append((estimate, out[0]))
        return out

    monkeypatch.setattr(CandidateWork, 'tightened', spy)
    # The photometric refinement that follows is off here (tested on its own below).
    monkeypatch.setattr(candidates_module, 'WINNER_FINISH_ROUNDS', 0)
    frame = random_scene(seed)
    result = PlanePipeline().process(frame.left, frame.right, 0)
    assert result.ok, result.reason
    before, after = seen[-1]
    assert after is not before
    assert np.allclose(result.homography, after.homography)
    error, unpolished = plane_error_px(frame, after.homography), plane_error_px(
        frame, before.homography)
    assert error < 1.0 and error < 0.6 * unpolished, (error, unpolished)
    assert after.n_inliers >= 0.9 * before.n_inliers

    monkeypatch.setattr(candidates_module, 'TIGHT_POLISH_MIN_PEAK', 10.0)
    seen.clear()
    result = PlanePipeline().process(frame.left, frame.right, 0)
    assert result.ok and seen[-1][1] is seen[-1][0]
    assert plane_error_px(frame, result.homography) == pytest.approx(unpolished, abs=1e-6)


def test_a_biased_winner_is_moved_onto_the_floor_photometrically(monkeypatch):
    # A planked floor on a rough rig (tuning seed 15): every start, coarse ones 0.6 px from
    # the truth included, converges 2.5 px off it (the corners' closest-point fit is biased
    # on planks); the photometric refinement raises the peak score by 70 % and lands within
    # a pixel. Without it the plane is published 2.5 px off.
    frame = rough_rig(random_scene(15), random_rig_error(np.random.default_rng((15, 77))))
    result = PlanePipeline().process(frame.left, frame.right, 0)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0, result.reason
    monkeypatch.setattr(candidates_module, 'WINNER_FINISH_ROUNDS', 0)
    without = PlanePipeline().process(frame.left, frame.right, 0)
    assert without.ok and plane_error_px(frame, without.homography) > 2.0


@pytest.mark.parametrize('case, name, value', [('cold 73', 'PHOTOMETRIC_MIN_PEAK', 1.05)])
def test_the_refinement_keeps_97_percent_of_the_peak(monkeypatch, counted_score, case, name,
                                                     value):
    # Tuning seeds published 1.0-1.3 px off before the seventh round. Cold 73: the refinement
    # raises the peak score by 1.6 % only and moves the plane 1.31 -> 0.83 px; taken only
    # with a 5 % higher peak score (the old rule) it is not. Measured with the refinement's
    # samples over a gradient of 20 (since the twelfth round 4). (Rough 59's second round,
    # 1.17 -> 0.71 px with OpenCV 5.0, comes within 0.81 px in one round with OpenCV 5.1:
    # the second round's test is below.)
    monkeypatch.setattr(trust_module, 'CoarseConfig',
                        partial(coarse_module.CoarseConfig, refine_min_gradient=20.0))
    kind, seed = case.split()
    frame = random_scene(int(seed))
    if kind == 'rough':
        frame = rough_rig(frame, random_rig_error(np.random.default_rng((int(seed), 77))))
    result = PlanePipeline().process(frame.left, frame.right, 0)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0, result.reason
    monkeypatch.setattr(candidates_module, name, value)
    # Round 17's refusal of a weak finished winner with texture beyond it refuses rough 59's
    # plane refined once (1.17 px off): off here, so the refinement alone is what is tested.
    monkeypatch.setattr(search_module, 'WEAK_BELOW_REFUSAL', False)
    without = PlanePipeline().process(frame.left, frame.right, 0)
    assert without.ok and plane_error_px(frame, without.homography) > 1.1


@pytest.mark.parametrize('seed', [17, 34])
def test_the_refinement_runs_twice(monkeypatch, seed):
    # Rough rigs, default settings (OpenCV 5.1, session 19's scan of tuning seeds 0-59): the
    # second photometric round of a search's winner more than halves its error on these two
    # (0.165 against 0.361 px, 0.116 against 0.297 px refined once; no seed of the 60 stays
    # over a pixel refined once). Since session 25 the rounds go on until one settles
    # (WINNER_FINISH_ROUNDS, test_finish_rounds.py); here the second settles.
    frame = rough_rig(random_scene(seed), random_rig_error(np.random.default_rng((seed, 77))))
    result = PlanePipeline().process(frame.left, frame.right, 0)
    assert result.ok, result.reason
    twice = plane_error_px(frame, result.homography)
    monkeypatch.setattr(candidates_module, 'WINNER_FINISH_ROUNDS', 1)
    # Round 17's refusal of a weak finished winner with texture beyond it: off, so that the
    # refinement alone is what is compared.
    monkeypatch.setattr(search_module, 'WEAK_BELOW_REFUSAL', False)
    once = PlanePipeline().process(frame.left, frame.right, 0)
    assert once.ok and twice < 0.25 and plane_error_px(frame, once.homography) > 1.8 * twice


def test_a_cut_to_a_floor_of_few_corners_relocks_photometrically(monkeypatch):
    # After the cut a large checker seen close up shows 9-10 corners, fewer than
    # estimator.min_inliers: the corners cannot fix a plane, the photometric refinement of
    # the coarse alignment's planes (then of the prediction) can. Before, the cut never
    # re-locked.
    frames = cut_sequence(2, 6, 4)

    def run():
        pipeline = PlanePipeline()
        results = [pipeline.process(f.left, f.right, i * PERIOD_NS)
                   for i, f in enumerate(frames)]
        return [plane_error_px(f, r.homography) if r.ok else None
                for f, r in zip(frames, results)], results

    errors, results = run()
    after = errors[2:]
    assert all(e is None or e < 1.0 for e in errors), errors
    relock = next(i for i, e in enumerate(after) if e is not None)
    assert relock < 3 and all(e is not None for e in after[relock:]), errors
    assert all(r.warm_start == 'photometric' and r.estimate.n_inliers == 0
               for r in results[2 + relock:])
    monkeypatch.setattr(candidates_module, 'PHOTOMETRIC_ROUNDS', 0)
    errors, _ = run()
    assert all(e is None for e in errors[2:]), errors


def test_a_floor_whose_corners_give_no_plane_is_found_photometrically(monkeypatch):
    # Rough rig, tuning seed 85: 77 corners, but every start, coarse ones 0.9 px from the
    # truth included, keeps 9 inliers (< estimator.min_inliers 12): the corners give no plane
    # at all. The coarse planes refined photometrically give the floor (0.13 px).
    frame = rough_rig(random_scene(85), random_rig_error(np.random.default_rng((85, 77))))
    result = PlanePipeline().process(frame.left, frame.right, 0)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0, result.reason
    assert result.warm_start == 'photometric' and result.estimate.n_inliers == 0
    monkeypatch.setattr(candidates_module, 'PHOTOMETRIC_ROUNDS', 0)
    without = PlanePipeline().process(frame.left, frame.right, 0)
    assert not without.ok and 'found no plane' in without.reason, without.reason


def test_a_plane_judged_twice_on_one_pair_is_verified_once(scene, monkeypatch):
    calls = []
    verify = trust_module.verify_plane

    def counted(*args, **kwargs):
        calls.append(1)
        return verify(*args, **kwargs)

    monkeypatch.setattr(trust_module, 'verify_plane', counted)
    gate = TrustGate(VerificationSettings())
    moved = _shifted(scene.homography, 6.0)
    gate.begin_pair(scene.left, scene.right)
    first = [gate.judge(scene.left, scene.right, h) for h in (scene.homography, moved)]
    again = [gate.judge(scene.left, scene.right, h) for h in (scene.homography, moved)]
    gate.end_pair()
    assert len(calls) == 2
    assert [v.score for v in again] == [v.score for v in first]
    assert first[0].accepted and not first[1].accepted
    # Outside begin_pair / end_pair (other images may come), every judgement is verified.
    gate.judge(scene.left, scene.right, scene.homography)
    assert len(calls) == 3


def test_a_search_in_doubt_tries_the_coarse_alignments_further_shifts(monkeypatch):
    # A rough rig (tuning seed 239) whose floor disparity is 70-85 px at 320 px wide: the
    # lower half's dominant shift and the prior give starts 29-160 px off, none verified;
    # the strips' phase-correlation peaks include the floor's shift, and its plane is found.
    frame = rough_rig(random_scene(239), random_rig_error(np.random.default_rng((239, 77))))
    config = one_shot_search(PlaneNodeConfig())
    result = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0, result.reason
    monkeypatch.setattr(coarse_module.CoarseAligner, 'peak_candidates',
                        lambda self, left, right: np.zeros((0, 3, 3)))
    without = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert not without.ok and 'no verified plane' in without.reason


def _never_in_doubt_with_a_winner(monkeypatch) -> None:
    """Switch the doubt of a search with a winner off (the last pair's doubt stays).

    Round 18's roll of a published ground plane (``verification.max_ground_roll_deg``) is off
    too: it also refuses the look-alikes these tests show, and the doubt alone is what is tested.
    """
    monkeypatch.setattr(trust_module.TrustGate, 'rolled_refusal', lambda *args: '')
    in_doubt = search_module.PlaneSearch._in_doubt
    monkeypatch.setattr(search_module.PlaneSearch, '_in_doubt', staticmethod(
        lambda search, verdict, limit: verdict is None and in_doubt(search, verdict, limit)))


def test_a_winner_no_distinct_plane_was_judged_beside_is_doubted(monkeypatch):
    # A rough rig on large tiles with a wide disparity (tuning seed 159: 272 px at the bottom
    # row): with the score counted, the prior's candidates and the coarse alignment all
    # converge on one look-alike 176 px off (score 0.57; the floor 0.53), and the only rival
    # judged is a swapped plane (0.004): a uniqueness of 140 that nothing tested. In doubt,
    # the coarse alignment's further shifts find the floor beside it, and the pair is refused
    # as ambiguous. Weighted by contrast (the default), the floor wins outright.
    frame = rough_rig(random_scene(159), random_rig_error(np.random.default_rng((159, 77))))
    weighted = PlanePipeline(PlaneNodeConfig()).process(frame.left, frame.right, 0)
    assert weighted.ok and plane_error_px(frame, weighted.homography) < 1.0, weighted.reason
    original = trust_module.TrustGate.config
    monkeypatch.setattr(trust_module.TrustGate, 'config', lambda self, width: replace(
        original(self, width), weight_by_contrast=False))
    result = PlanePipeline(PlaneNodeConfig()).process(frame.left, frame.right, 0)
    assert not result.ok and 'ambiguous' in result.reason, result.reason
    assert not result.mask.any() and result.confidence == 0.0
    _never_in_doubt_with_a_winner(monkeypatch)
    without = PlanePipeline(PlaneNodeConfig()).process(frame.left, frame.right, 0)
    assert without.ok and plane_error_px(frame, without.homography) > 100.0


def _floor_found_only_in_doubt(seed: int, monkeypatch, floor: str = 'tiles_32') -> None:
    """Rough rig `seed` on 16 cm tiles: floor within 1 px; > 50 px off without the doubt."""
    frame = rough_rig(random_scene(seed, floor=floor),
                      random_rig_error(np.random.default_rng((seed, 77))))
    result = PlanePipeline(PlaneNodeConfig()).process(frame.left, frame.right, 0)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0, result.reason
    _never_in_doubt_with_a_winner(monkeypatch)
    without = PlanePipeline(PlaneNodeConfig()).process(frame.left, frame.right, 0)
    assert without.ok and plane_error_px(frame, without.homography) > 50.0


def test_a_winner_of_low_confidence_is_doubted(monkeypatch, counted_score):
    # A rough rig on 16 cm tiles (tuning seed 56 of the sized floors), pixels counted in the
    # score: the search never gets near the floor and its winner, a look-alike 76 px off,
    # explains 0.265 of the image (verification confidence 0.58) against 0.14 for its
    # distinct rivals. In doubt, the coarse alignment's further shifts find the floor (0.385),
    # which is published. (Weighted by contrast, the default, the floor wins without doubt.)
    _floor_found_only_in_doubt(56, monkeypatch)


def test_a_winner_of_shallow_slope_is_doubted(monkeypatch):
    # A rough rig on 16 cm tiles (seed 10022 of the sized floors, held out until its run):
    # the search never gets near the floor (slope 0.20 px per row, score 0.63) and its winner,
    # 104 px off, barely slopes (0.025) at confidence 1.0. In doubt, the coarse alignment's
    # further shifts find the floor.
    _floor_found_only_in_doubt(10022, monkeypatch)


def _counted_all(config: PlaneNodeConfig | None = None, **changes) -> PlaneNodeConfig:
    """Return ``config`` with every textured pixel counted (``verification.covisible`` off).

    ``changes``: other ``verification.*`` settings (e.g. a scene's ``min_score``).
    """
    return with_verification(config, covisible=False, **changes)


def test_a_look_alike_at_full_confidence_is_doubted(monkeypatch):
    # evaluate_trust floors_rough, tuning seed 150 (a 16 cm checker on a rough rig, default
    # prior), every textured pixel counted: the search never judges a plane within 10 px of
    # the floor, and its winner, a look-alike some checker periods to the side, has a
    # uniqueness of 6.9 and confidence 1.0 (no rule that chose which winners to doubt fired;
    # it was published 84 px off). In doubt, the further shifts find the floor (0.06 px)
    # beside it: refused as ambiguous. Co-visible (the default since session 20) the search
    # finds the floor itself (0.02 px); no floors_rough seed of 100-199 was refused as
    # ambiguous co-visible (session 20's search), so the doubt is shown counted.
    seed = 150
    frame = rough_rig(random_scene(seed, floor=SIZED_FLOOR_KINDS[seed % len(SIZED_FLOOR_KINDS)]),
                      random_rig_error(np.random.default_rng((seed, 77))))
    default = PlanePipeline(one_shot_search(PlaneNodeConfig())).process(frame.left, frame.right, 0)
    assert default.ok and plane_error_px(frame, default.homography) < 1.0, default.reason
    config = one_shot_search(_counted_all())
    result = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert not result.ok and 'ambiguous' in result.reason, result.reason
    _never_in_doubt_with_a_winner(monkeypatch)
    without = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert without.ok and plane_error_px(frame, without.homography) > 50.0


def test_a_near_miss_of_a_search_in_doubt_is_refined_onto_the_floor(monkeypatch, counted_score):
    # A rough rig (tuning seed 12) whose best plane converges 1.1 px off the floor and then
    # explains 0.23 of the image, under verification.min_score 0.25 (the floor itself: 0.27):
    # refined photometrically it is verified within a pixel; without that nothing is published.
    # Every textured pixel counted and verification.min_score 0.25, as the scene was found:
    # co-visible (the default since session 20) the floor scores enough without the rescue
    # (published 0.18 px off), and so it does counted under session 25's min_score 0.22.
    frame = rough_rig(random_scene(12), random_rig_error(np.random.default_rng((12, 77))))
    default = PlanePipeline(one_shot_search(_counted_all())).process(frame.left, frame.right, 0)
    assert default.ok and plane_error_px(frame, default.homography) < 0.5, default.reason
    config = one_shot_search(_counted_all(min_score=FOUND_MIN_SCORE))
    result = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert result.ok and plane_error_px(frame, result.homography) < 1.0, result.reason
    assert 0.5 <= result.confidence < 1.0
    monkeypatch.setattr(search_module, 'NEAR_MISSES', 0)
    without = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert not without.ok and 'explains too little' in without.reason
    # The rescue moves the near miss by about a pixel: a move limit under that refuses it (the
    # limit keeps a rescue from walking a plane a tile period away).
    monkeypatch.setattr(search_module, 'NEAR_MISSES', 2)
    monkeypatch.setattr(candidates_module, 'TIGHT_POLISH_MAX_MOVE_PX', 0.05)
    held = PlanePipeline(config).process(frame.left, frame.right, 0)
    assert not held.ok and 'explains too little' in held.reason


@pytest.mark.parametrize('case', ['truth', 'swapped', 'too far under'])
def test_only_a_ground_plane_of_the_right_sign_is_a_near_miss(scene, monkeypatch, case):
    # The true plane, held under a verification.min_score just above its score, is a near
    # miss (refused only for explaining too little); the same scene with swapped cameras
    # gives a plane of about the same score that is refused as swapped too, and a
    # photometric refinement cannot change that: it is not refined. Nor is the truth under
    # NEAR_MISS_RATIO x min_score.
    frame = swapped(scene) if case == 'swapped' else scene
    score = TrustGate(PlaneNodeConfig().verification).judge(
        frame.left, frame.right, frame.homography).verification.score
    least = score / search_module.NEAR_MISS_RATIO + 0.02 if case == 'too far under' \
        else score + 0.05
    config = PlaneNodeConfig()
    config = replace(config, verification=replace(config.verification, min_score=least))
    gate = TrustGate(config.verification)
    search = search_module.PlaneSearch(lambda: config, lambda: gate, None, None, None)
    refined = []

    def rescued(self, step, problem, estimate, verdict):
        refined.append(verdict)
        return estimate, verdict

    monkeypatch.setattr(CandidateWork, 'rescued', rescued)
    step = SimpleNamespace(left=frame.left, right=frame.right)
    pool = [photometric_estimate(frame.homography)]
    size = (frame.left.shape[1], frame.left.shape[0])
    assert not search._rescue_near_misses(step, None, pool, None, size)
    if case == 'truth':
        assert len(refined) == 1
        assert refined[0].verification.reason == verification.REASON_LOW_SUPPORT
    else:
        assert refined == []


def test_a_search_is_in_doubt_once_with_a_winner_or_on_its_last_pair():
    state = search_module._Search(tried={0, 1})
    in_doubt = search_module.PlaneSearch._in_doubt
    winner = SimpleNamespace(uniqueness=math.inf)
    assert in_doubt(state, winner, 3)  # a winner, however unique, before it is published
    assert in_doubt(state, None, 2)  # the search's last pair
    assert not in_doubt(state, None, 3)  # more pairs to come
    state.peaks_tried = True
    assert not in_doubt(state, winner, 2)
    assert not in_doubt(state, None, 2)


def test_a_stream_on_a_sized_checker_seen_by_a_rough_rig_locks_on_no_look_alike(monkeypatch):
    # A walking sequence on 16 cm checker squares (scene_sequence seed 3, tuning) seen by the
    # rough rig of evaluate_trust's seed 3: the search finds no verified plane for 10 pairs,
    # then, before every search was in doubt (main at 8d3d7ab, trust15 at 6f92500), locked
    # on a look-alike 38.8 px off on pair 10 and kept it (38.6-38.9 px) to the end. In doubt,
    # the further shifts make the pair ambiguous: nothing is published (review of session 14).
    # Every textured pixel counted, as then: co-visible (the default since session 20) the
    # stream stays on the floor (0.10 px) even without the doubt, so it cannot show the rule.
    # Its last three pairs on a fresh pipeline show the same (the test's time: 52 s -> 12 s):
    # nothing published; without the doubt 38.7-38.9 px from the first of them.
    frames = [rough_rig(f, random_rig_error(np.random.default_rng((3, 77))))
              for f in scene_sequence(11, 3, floor='checker_32')][8:]

    def worst(pipeline):
        errors = [plane_error_px(f, r.homography) for f, r in (
            (f, pipeline.process(f.left, f.right, i * 33_333_333)) for i, f in enumerate(frames))
            if r.ok]
        return max(errors, default=0.0)

    assert worst(PlanePipeline(_counted_all())) <= 5.0
    _never_in_doubt_with_a_winner(monkeypatch)
    assert worst(PlanePipeline(_counted_all())) > 30.0
