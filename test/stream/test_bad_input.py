"""Bad input through the public entry points: decode, synchroniser, pipeline, diagnostics.

Every bad input must give a failure (or a warning) with a reason that names the problem, a
count, no homography and a mask of zeros, and the next good pair must be handled normally.
The ground truth comes from the renderer (:mod:`domplane_ros.sim.generators`).
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import cv2
from domplane_ros.config import one_shot_search, PipelineConfig, PlaneNodeConfig
from domplane_ros.core.estimator import PlaneEstimate
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.image import gray_to_image_fields, message_to_gray
from domplane_ros.errors import ImageDecodeError
from domplane_ros.ros.handover import NewestSlot
from domplane_ros.sim.generators import random_scene
from domplane_ros.stream.health import (_identical, clipped_reason, inlier_spread,
                                        input_diagnostic_values, PairChecks, problem_key,
                                        StampChecks, Throttle)
import domplane_ros.stream.pipeline as pipeline_module
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.status import ERROR, OK, plane_status, WARN
from domplane_ros.stream.sync import ApproximateTimeSync, merge_dropped
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from truth import transfer_error_px

S = 1_000_000_000
STAMP0 = 1_700_000_000 * S


@pytest.fixture(scope='module')
def scene():
    return random_scene(7, floor='random', n_boxes=3, gain=1.15, offset=-10.0)


def _noisy(scene, seed):
    """Return the scene's images with fresh sensor noise: the next frame of a still head."""
    rng = np.random.default_rng(seed)
    return SimpleNamespace(**{side: np.clip(getattr(scene, side).astype(np.int16)
                                            + rng.integers(-2, 3, scene.left.shape),
                                            0, 255).astype(np.uint8)
                              for side in ('left', 'right')})


def assert_failed(result, *needles):
    assert not result.ok
    assert result.homography is None
    assert result.mask.dtype == np.uint8 and not result.mask.any()
    for needle in needles:
        assert needle in result.reason, result.reason


def one_shot_pipeline():
    """Return a pipeline whose prior search runs in one frame (not spread over frames)."""
    return PlanePipeline(one_shot_search(PlaneNodeConfig()))


def search_frames(pipeline):
    """Frames a prior search takes (it refines a few candidates per frame)."""
    cfg = pipeline.config
    return -(-cfg.prior.refine_best // cfg.pipeline.search_candidates_per_frame)


def assert_recovers(pipeline, scene, stamp_ns):
    """Feed the pair until a plane is found: at once if locked, else within one search."""
    for k in range(search_frames(pipeline)):
        result = pipeline.process(scene.left, scene.right, stamp_ns + k * 1_000_000)
        if result.ok or pipeline.state != 'searching':
            break
    assert result.ok, result.reason
    assert transfer_error_px(scene, result.homography) < 1.0
    return result


# --- Decode ------------------------------------------------------------------------------


def _fields(gray, **changes):
    fields = gray_to_image_fields(gray)
    fields.update(changes)
    return SimpleNamespace(**fields)


@pytest.mark.parametrize('changes,kind,needle', [
    ({'encoding': 'yuv422'}, 'encoding', "unsupported encoding 'yuv422'"),
    ({'step': 9}, 'step', 'step 9 is smaller than width * bytes_per_pixel = 10 * 1'),
    ({'data': bytes(59)}, 'data_length', 'data length 59 != height * step = 6 * 10 = 60'),
    ({'height': 0, 'data': b''}, 'zero_size', 'zero width or height (10x0)'),
    ({'width': 0, 'step': 0, 'data': b''}, 'zero_size', 'zero width or height (0x6)'),
    ({'height': -1}, 'field', "'height' must be non-negative"),
    ({'data': 'text'}, 'data', 'image data must be bytes'),
])
def test_decode_errors_name_the_problem_and_kind(changes, kind, needle):
    msg = _fields(np.zeros((6, 10), np.uint8), **changes)
    with pytest.raises(ImageDecodeError) as info:
        message_to_gray(msg)
    assert needle in str(info.value)
    assert info.value.kind == kind


@pytest.mark.parametrize('fmt,data,kind', [
    ('bgr8; compressedDepth', b'\x89PNG', 'encoding'),
    ('tiff', b'II*\x00', 'encoding'),
    ('png', b'', 'compressed'),
    ('jpeg', b'not a jpeg at all', 'compressed'),
])
def test_compressed_decode_errors_have_a_kind(fmt, data, kind):
    with pytest.raises(ImageDecodeError) as info:
        message_to_gray(SimpleNamespace(format=fmt, data=data))
    assert info.value.kind == kind


# --- Pipeline: pairs that are refused ----------------------------------------------------


def test_left_right_size_mismatch_is_refused_then_recovers(scene):
    pipeline = one_shot_pipeline()
    small = cv2.resize(scene.right, (320, 240), interpolation=cv2.INTER_AREA)
    result = pipeline.process(scene.left, small, STAMP0)
    assert_failed(result, 'left and right images differ in size', 'left 640x480',
                  'right 320x240')
    assert result.mask.shape == scene.left.shape
    assert pipeline.checks.counts['size_mismatch'] == 1
    assert_recovers(pipeline, scene, STAMP0 + S // 10)


def test_size_change_mid_stream_warns_resets_and_keeps_going(scene):
    pipeline = one_shot_pipeline()
    assert_recovers(pipeline, scene, STAMP0)
    assert pipeline.state == 'locked'
    # Cropping both images at the origin keeps the plane's pixel homography.
    crop = (slice(0, 400), slice(0, 560))
    result = pipeline.process(scene.left[crop], scene.right[crop], STAMP0 + S // 10)
    assert result.warnings and 'image size changed from 640x480/640x480 to 560x400/560x400' \
        in result.warnings[0]
    assert result.reinitialised
    assert pipeline.checks.counts['size_changes'] == 1
    assert result.ok, result.reason
    truth = scene.homography
    pts = np.argwhere((scene.plane_left & scene.visible_in_right)[crop])[:, ::-1].astype(float)
    err = np.linalg.norm(apply_homography(result.homography, pts)
                         - apply_homography(truth, pts), axis=1)
    assert err.mean() < 1.0


@pytest.mark.parametrize('make,needles,counter', [
    (lambda s: (np.zeros_like(s.left), s.right), ('left image is black', '100 %'), 'clipped'),
    (lambda s: (s.left, np.full_like(s.right, 255)), ('right image is saturated',), 'clipped'),
    (lambda s: (np.clip(s.left.astype(int) + 200, 0, 255).astype(np.uint8), s.right),
     ('left image is saturated',), 'clipped'),
    (lambda s: (np.full_like(s.left, 128), np.full_like(s.right, 128)),
     ('too few left features: 0', 'textureless: grey std 0.0'), 'too_few_features'),
])
def test_black_saturated_and_textureless_frames_fail_with_reason(scene, make, needles, counter):
    pipeline = one_shot_pipeline()
    assert_recovers(pipeline, scene, STAMP0)
    left, right = make(scene)
    result = pipeline.process(left, right, STAMP0 + S // 10)
    assert_failed(result, *needles)
    assert pipeline.checks.counts[counter] == 1
    # The plane is carried for pipeline.max_tracking_frames (not published) and re-verified
    # on the next good pair; no stale plane is published.
    assert pipeline.state == 'tracking' and result.homography is None
    level, message, _ = _status(result, consecutive_failures=1)
    assert level == WARN and needles[0] in message
    assert_recovers(pipeline, scene, STAMP0 + 2 * S // 10)


def test_one_frozen_camera_is_refused_a_static_scene_is_not(scene):
    a, b, c = scene, _noisy(scene, 1), _noisy(scene, 2)
    pipeline = one_shot_pipeline()
    assert pipeline.process(a.left, a.right, STAMP0).ok
    # The left camera repeats its image while the right one moves on.
    result = pipeline.process(a.left, b.right, STAMP0 + S // 10)
    assert_failed(result, 'left camera frozen')
    result = pipeline.process(a.left, c.right, STAMP0 + 2 * S // 10)
    assert_failed(result, 'left camera frozen')
    # The right camera freezes.
    pipeline.process(b.left, b.right, STAMP0 + 3 * S // 10)
    result = pipeline.process(c.left, b.right, STAMP0 + 4 * S // 10)
    assert_failed(result, 'right camera frozen', 'while the left image changed')
    assert pipeline.checks.counts['frozen_camera'] == 3
    # Both images change, then both repeat (a static scene): not a fault.
    assert pipeline.process(a.left, a.right, STAMP0 + 5 * S // 10).ok
    result = pipeline.process(a.left, a.right, STAMP0 + 6 * S // 10)
    assert result.ok, result.reason
    assert pipeline.checks.counts['frozen_camera'] == 3
    assert transfer_error_px(scene, result.homography) < 1.0


# --- Pipeline: degenerate geometry --------------------------------------------------------


def _keep_only(scene, left_region):
    """Grey out everything but a region of the left image and its image in the right one."""
    left = np.full_like(scene.left, 128)
    right = np.full_like(scene.right, 128)
    left[left_region] = scene.left[left_region]
    keep = np.zeros(scene.left.shape, np.uint8)
    keep[left_region] = 255
    height, width = scene.right.shape
    warped = cv2.warpPerspective(keep, scene.homography, (width, height),
                                 flags=cv2.INTER_NEAREST)
    right[warped > 0] = scene.right[warped > 0]
    return left, right


@pytest.mark.parametrize('region', [
    (slice(300, 306), slice(0, 640)),       # a thin band: the corners are nearly collinear
    (slice(320, 390), slice(240, 310)),     # one small patch of the floor
], ids=['collinear', 'patch'])
def test_degenerate_inliers_are_a_failure(scene, region):
    left, right = _keep_only(scene, region)
    pipeline = one_shot_pipeline()
    result = pipeline.process(left, right, STAMP0)
    assert_failed(result, 'degenerate geometry: the inliers span',
                  'pipeline.min_inlier_spread 0.02')
    assert pipeline.checks.counts['degenerate_geometry'] == 1
    # The spread check is what refuses them, and it must: without it no correct plane comes
    # out (the patch's plane is published 2.8 px off the floor, 23 px before the search's
    # winner was refined photometrically at full resolution: the verification sees texture
    # only in the patch; the band's plane is refused for another reason), and the reason no
    # longer names the degenerate geometry.
    config = PlaneNodeConfig()
    loose = PlanePipeline(one_shot_search(replace(config, pipeline=replace(
        config.pipeline, min_inlier_spread=0.0))))
    result = loose.process(left, right, STAMP0)
    assert 'degenerate geometry' not in result.reason
    assert not result.ok or transfer_error_px(scene, result.homography) > 1.0


def test_inlier_spread_of_collinear_patch_and_spread_points():
    rng = np.random.default_rng(0)
    line = np.stack([np.linspace(0, 600, 50), 2.0 * np.linspace(0, 600, 50) + 3], axis=1)
    assert inlier_spread(line, 640 * 480) < 1e-6
    patch = rng.uniform(100, 130, (50, 2))
    assert inlier_spread(patch, 640 * 480) < 0.003
    spread = rng.uniform(0, [640, 480], (200, 2))
    assert inlier_spread(spread, 640 * 480) > 0.8
    assert inlier_spread(spread[:2], 640 * 480) == 0.0


# --- Pipeline: never a bad homography ------------------------------------------------------


def _fake_estimate(h, n):
    return PlaneEstimate(homography=h, inliers=np.ones(n, bool), matches=np.arange(n),
                         residuals_px=np.zeros(n), iterations=1, energy_trace=np.zeros(1),
                         stage_trace=np.zeros(1, np.int64), converged=True, final_energy=0.0,
                         potential='truncated_quadratic')


NAN_H = np.array([[1.0, 0, np.nan], [0, 1, 0], [0, 0, 1]])
FAR_H = np.array([[1.0, 0, 900.0], [0, 1, 0], [0, 0, 1]])


@pytest.mark.parametrize('h,coarse,needle,counter', [
    (NAN_H, True, 'non-finite', 'invalid_homography'),
    (FAR_H, False, 'outside the prior', 'outside_prior'),
    # The coarse alignment's planes need no camera model (no prior-bounds check): the
    # verification judges them, and a translation is no ground plane.
    (FAR_H, True, 'not a ground plane', 'unverified_plane'),
])
def test_non_finite_or_out_of_prior_homography_is_never_published(
        scene, monkeypatch, h, coarse, needle, counter):
    # Every start the pipeline tries (warm, best so far, prior candidates, coarse alignment)
    # runs through TwoStep.estimate.
    monkeypatch.setattr(pipeline_module.TwoStep, 'estimate',
                        lambda self, *a, **k: _fake_estimate(h, self.n_points))
    config = one_shot_search(PlaneNodeConfig())
    pipeline = PlanePipeline(replace(config, verification=replace(
        config.verification, coarse_candidates=coarse)))
    result = pipeline.process(scene.left, scene.right, STAMP0)
    assert_failed(result, needle)
    assert pipeline.checks.counts[counter] >= 1


# --- Pipeline: stamps ------------------------------------------------------------------------


def test_stamps_backwards_or_jumping_forward_drop_the_warm_start(scene):
    pipeline = one_shot_pipeline()
    assert_recovers(pipeline, scene, STAMP0)
    result = pipeline.process(scene.left, scene.right, STAMP0 + S // 10)
    assert result.ok and not result.reinitialised and not result.warnings
    result = pipeline.process(scene.left, scene.right, STAMP0 - 3 * S)
    assert result.reinitialised and 'stamp went backwards by 3.100 s' in result.warnings[0]
    assert result.ok and transfer_error_px(scene, result.homography) < 1.0
    result = pipeline.process(scene.left, scene.right, STAMP0 + 120 * S)
    assert result.reinitialised
    assert 'stamp jumped forward by 123.0 s (> pipeline.max_stamp_jump_s 10 s)' \
        in result.warnings[0]
    assert result.ok and transfer_error_px(scene, result.homography) < 1.0
    assert pipeline.checks.counts['stamp_backwards'] == 1
    assert pipeline.checks.counts['stamp_jumps'] == 1
    result = pipeline.process(scene.left, scene.right, STAMP0 + 129 * S)
    assert not result.reinitialised and not result.warnings   # 9 s < 10 s


def test_a_gap_the_processing_made_is_not_a_stamp_jump(scene):
    # The node's newest-wins hand-over drops the pairs that arrive while a search runs: the
    # jump is the cameras' own gap (Pair.gap_ns), not the time since the last pair processed.
    config = PlaneNodeConfig()
    pipeline = PlanePipeline(replace(config, pipeline=replace(config.pipeline,
                                                              max_stamp_jump_s=1.0)))
    pipeline.process(scene.left, scene.right, STAMP0)
    result = pipeline.process(scene.left, scene.right, STAMP0 + 3 * S // 2,
                              stream_gap_ns=S // 20)
    assert not result.warnings and pipeline.checks.counts['stamp_jumps'] == 0
    # A gap in the cameras' stream (1.5 s among the pairs dropped since) is one.
    result = pipeline.process(scene.left, scene.right, STAMP0 + 4 * S,
                              stream_gap_ns=3 * S // 2)
    assert result.reinitialised and pipeline.checks.counts['stamp_jumps'] == 1
    assert 'stamp jumped forward by 1.5 s' in result.warnings[0]


def test_sync_pairs_carry_the_cameras_gap_and_a_newest_wins_slot_keeps_it():
    sync = ApproximateTimeSync(0.01, 5)
    slot = NewestSlot(merge=merge_dropped)
    pairs = []
    for k, t in enumerate((0, S // 10, 2 * S, 2 * S + S // 10)):
        sync.add('left', STAMP0 + t, k)
        pairs += sync.add('right', STAMP0 + t + 1000, k)
    assert [p.gap_ns for p in pairs] == [None, S // 10, 19 * S // 10, S // 10]
    for pair in pairs[1:]:      # the worker busy: the second and third pairs are dropped
        slot.put(pair)
    kept = slot.take_nowait()
    assert slot.dropped == 2 and kept.left == 3 and kept.gap_ns == 19 * S // 10
    sync.add('left', STAMP0, 'back')          # stamps went backwards: a reset
    (after,) = sync.add('right', STAMP0, 'back')
    assert after.after_reset and after.gap_ns is None
    slot.put(after)
    slot.put(pairs[1])
    merged = slot.take_nowait()   # the reset is not lost with the pair that carried it
    assert merged.after_reset and merged.left == 1
    assert merged.gap_ns is None  # a gap unknown on one side: measured from the last stamp


def test_zero_stamps_are_warned():
    checks = StampChecks(10_000_000)
    warnings = checks.observe('left', 0)
    assert len(warnings) == 1 and 'left image header stamp is zero' in warnings[0]
    assert 'does not stamp' in warnings[0]
    assert checks.observe('right', 5) == []
    assert checks.counts['stamp_zero'] == 1


def test_left_right_skew_beyond_slop_is_counted_with_the_difference():
    slop_ns = 10_000_000
    sync = ApproximateTimeSync(slop_ns * 1e-9, 5)
    checks = StampChecks(slop_ns)
    warnings, pairs = [], []
    for k in range(30):   # 10 Hz, the right camera's stamps 50 ms late
        for side, stamp in (('left', STAMP0 + k * S // 10),
                            ('right', STAMP0 + k * S // 10 + 50_000_000)):
            warnings += checks.observe(side, stamp)
            pairs += sync.add(side, stamp, k)
    assert pairs == []
    assert sync.stats().dropped > 0
    assert checks.counts['sync_skew'] >= 40
    assert checks.last_skew_ns == 50_000_000
    assert 'differs by 50.0 ms > sync.slop_s 10 ms' in warnings[-1]


def test_jitter_within_slop_and_a_silent_camera_are_not_skew():
    checks = StampChecks(10_000_000)
    rng = np.random.default_rng(1)
    for k in range(40):
        stamp = STAMP0 + k * S // 30
        assert checks.observe('left', stamp) == []
        if k < 20:   # then the right camera stops: a drop-out, not a skew
            jitter = int(rng.integers(-3_000_000, 3_000_000))
            assert checks.observe('right', stamp + jitter) == []
    assert checks.counts['sync_skew'] == 0


# --- Diagnostics ----------------------------------------------------------------------------


def _status(result, consecutive_failures=0, **kwargs):
    return plane_status(rate=10.0, latencies_ms=[5.0], pairs=1, processed=1, dropped_busy=0,
                        dropped_sync=0, decode_errors=0, lock_state='searching',
                        reinitialisations=1, consecutive_failures=consecutive_failures,
                        last_result=result, last_error='', **kwargs)


def test_diagnostics_show_every_input_counter_and_warn_on_input_warnings(scene):
    pipeline = one_shot_pipeline()
    good = pipeline.process(scene.left, scene.right, STAMP0)
    stamps = StampChecks(10_000_000)
    stamps.observe('left', 0)
    decode = {'decode_step': 2}
    counts = (pipeline.checks.counts, stamps.counts, decode)
    level, message, values = _status(good, input_counts=counts)
    assert level == OK
    values = dict(values)
    assert values['decode errors (step)'] == '2'
    assert values['stamps zero'] == '1'
    for key, _ in input_diagnostic_values():
        assert key in values
    level, message, _ = _status(good, input_warning='stamp jumped forward by 60.0 s')
    assert level == WARN and message.endswith('stamp jumped forward by 60.0 s')
    level, _, _ = _status(good, consecutive_failures=3, input_warning='x')
    assert level == ERROR


def test_throttle_is_per_kind_of_problem():
    throttle = Throttle(5.0)
    assert throttle.due('a', 0.0) and not throttle.due('a', 4.9) and throttle.due('a', 5.0)
    assert throttle.due('b', 4.9)
    assert problem_key('stamp jumped forward by 12.0 s') == 'stamp jumped forward by s'
    assert problem_key('too few left features: 3 < 12') == 'too few left features'


def test_new_parameters_are_validated():
    with pytest.raises(ValueError, match='pipeline.min_inlier_spread'):
        PipelineConfig(min_inlier_spread=1.5)
    with pytest.raises(ValueError, match='pipeline.max_stamp_jump_s'):
        PipelineConfig(max_stamp_jump_s=0.0)


# --- Pipeline: random pairs ------------------------------------------------------------------

_CONTENT = ('noise', 'blocks', 'zeros', 'saturated', 'flat', 'line')


def _random_image(shape, content, rng):
    height, width = shape
    if content == 'noise':
        return rng.integers(0, 256, shape, dtype=np.uint8)
    if content == 'blocks':
        small = rng.integers(0, 256, (max(1, height // 8), max(1, width // 8)), dtype=np.uint8)
        return cv2.resize(small, (width, height), interpolation=cv2.INTER_NEAREST)
    if content == 'line':   # texture on one row only: collinear corners
        image = np.full(shape, 128, np.uint8)
        image[height // 2] = rng.integers(0, 256, width, dtype=np.uint8)
        return image
    return np.full(shape, {'zeros': 0, 'saturated': 255, 'flat': 77}[content], np.uint8)


@settings(max_examples=60, deadline=None)
@given(frames=st.lists(st.tuples(
    st.integers(1, 90), st.integers(1, 120), st.booleans(), st.sampled_from(_CONTENT),
    st.sampled_from(_CONTENT), st.integers(-2**62, 2**62), st.integers(0, 2**32 - 1)),
    min_size=1, max_size=4))
def test_random_pairs_give_a_valid_result_or_a_failure_with_reason(frames):
    pipeline = one_shot_pipeline()
    for height, width, same_size, left_kind, right_kind, stamp, seed in frames:
        rng = np.random.default_rng(seed)
        left = _random_image((height, width), left_kind, rng)
        right = _random_image((height, width) if same_size else (height + 1, width),
                              right_kind, rng)
        result = pipeline.process(left, right, stamp)
        assert result.mask.shape == left.shape and result.mask.dtype == np.uint8
        assert set(np.unique(result.mask)) <= {0, 127, 255}
        if result.ok:
            assert np.all(np.isfinite(result.homography)) and result.homography[2, 2] == 1.0
            assert result.reason == ''
        else:
            assert result.homography is None and result.reason and not result.mask.any()


def test_large_frames_are_checked_on_a_grid_with_the_same_answers():
    # 3840 x 2160: the clipped fractions come from a regular grid, the frozen check compares
    # every 16th row first; both must still give the whole image's answer.
    rng = np.random.default_rng(7)
    big = rng.integers(20, 230, (2160, 3840), dtype=np.uint8)
    big[:1400] = 0  # 65 % black
    assert 'left image is black: 65 %' in clipped_reason(big, 'left', 0.6)
    assert clipped_reason(big, 'left', 0.7) == ''
    other = big.copy()
    other[2001, 3001] ^= 1  # one pixel off the sampled rows differs
    assert not _identical(big, other)
    assert _identical(big, big.copy())
    assert not _identical(big, big[:, :-1])


def test_the_frozen_check_copies_a_writable_image_and_keeps_a_read_only_one():
    # A caller that refills one writable buffer in place still shows a change (the check
    # kept a copy); a read-only image (the session's: views of messages) is kept as is.
    rng = np.random.default_rng(3)
    first, second, right = (rng.integers(0, 256, (48, 64), dtype=np.uint8) for _ in range(3))
    checks = PairChecks()
    buffer = first.copy()
    assert checks.check(buffer, right, STAMP0, PipelineConfig()).refused == ''
    buffer[:] = second  # the left camera moved on, the right one repeats its image
    refused = checks.check(buffer, right, STAMP0 + S // 10, PipelineConfig()).refused
    assert refused.startswith('right camera frozen')
    fixed = second.copy()
    fixed.flags.writeable = False
    checks.check(fixed, right, STAMP0 + 2 * S // 10, PipelineConfig())
    assert checks._last_images[0] is fixed and checks._last_images[1] is not right
