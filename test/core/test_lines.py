"""Line features: detection, the closest-line search, and the estimator on lines and on both."""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.config import FeatureConfig, one_shot_search, PlaneNodeConfig, PriorConfig
from domplane_ros.core.estimator import FailedEstimate, PlaneEstimate, TwoStep
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.lines import (detect_lines, LineMatcher, lines_reason, map_segments,
                                     segment_lengths, segment_lines, UNMATCHED_PX)
from domplane_ros.core.plane import estimate_plane
from domplane_ros.core.potentials import POTENTIALS
from domplane_ros.sim.generators import random_scene, RENDERED_PRIOR
from domplane_ros.sim.synthetic import (displace_homography, line_scene, plane_error_px,
                                        point_scene)
from domplane_ros.stream.candidates import TIGHT_POLISH_RATIO
from domplane_ros.stream.pipeline import debug_overlay, PlanePipeline
from domplane_ros.stream.trust import TrustGate
from hypothesis import assume, example, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

GRID = np.stack(np.meshgrid(np.linspace(0, 639, 9), np.linspace(0, 479, 7)), -1).reshape(-1, 2)


@pytest.fixture(scope='module')
def tiles():
    # A low-texture tiled floor with boxes, on which corners alone lock onto the boxes.
    return random_scene(0, floor='tiles_plain')


def _floor_error(frame, homography):
    truth = frame.plane_left & frame.visible_in_right
    ys, xs = np.nonzero(truth[::4, ::4])
    pts = np.stack([xs * 4, ys * 4], axis=1).astype(np.float64)
    diff = apply_homography(homography, pts) - apply_homography(frame.homography, pts)
    return float(np.mean(np.linalg.norm(diff, axis=1)))


# --- Detection.
def test_detect_lines_shape_length_cap_and_spread(tiles):
    config = FeatureConfig(max_lines=60, min_line_length_px=30.0)
    seg = detect_lines(tiles.left, config)
    assert seg.dtype == np.float64 and seg.shape == (60, 4)
    assert np.all(segment_lengths(seg) >= 30.0)
    assert np.all((seg >= -0.5) & (seg <= [640, 480, 640, 480]))
    # Spread: the floor half of the 4 x 4 grid is represented, not just the longest lines.
    mid = 0.5 * (seg[:, 0:2] + seg[:, 2:4])
    cells = {(int(y * 4 // 480), int(x * 4 // 640)) for x, y in mid}
    assert len(cells) >= 8
    longest = detect_lines(tiles.left, FeatureConfig(max_lines=2000, min_line_length_px=30.0))
    assert longest.shape[0] > 60
    # On the tiles, most long segments are joints of the floor, which map by the truth onto
    # right segments of the same polarity within a pixel.
    right = detect_lines(tiles.right, FeatureConfig(max_lines=2000, min_line_length_px=30.0))
    pred = map_segments(tiles.homography, longest)
    dist, _ = LineMatcher(right).brute_force(pred[:, 0:2], pred[:, 2:4])
    assert np.mean(dist < 1.0) > 0.6


def test_line_scale_trades_precision_for_speed_but_still_finds_the_joints(tiles):
    coarse = FeatureConfig(line_scale=0.5)
    left = detect_lines(tiles.left, coarse)
    right = detect_lines(tiles.right, coarse)
    assert left.shape[0] > 50
    pred = map_segments(tiles.homography, left)
    dist, _ = LineMatcher(right).brute_force(pred[:, 0:2], pred[:, 2:4])
    assert np.mean(dist < 1.5) > 0.5


def test_detect_lines_honours_roi_and_flat_image(tiles):
    seg = detect_lines(tiles.left, FeatureConfig(roi=(0.0, 0.5, 1.0, 1.0)))
    assert seg.shape[0] > 10
    assert np.all(seg[:, [1, 3]] >= 240 - 0.5)
    assert detect_lines(np.full((120, 160), 90, np.uint8), FeatureConfig()).shape == (0, 4)
    with pytest.raises(ValueError):
        detect_lines(np.zeros((10, 10, 3), np.uint8), FeatureConfig())


# --- Distance and search.
def test_segment_lines_are_unit_signed_distances():
    seg = np.array([[0.0, 0.0, 10.0, 0.0], [0.0, 0.0, 0.0, 5.0], [1.0, 1.0, 4.0, 5.0]])
    lines = segment_lines(seg)
    np.testing.assert_allclose(np.hypot(lines[:, 0], lines[:, 1]), 1.0)
    for ends in (seg[:, 0:2], seg[:, 2:4]):
        np.testing.assert_allclose(np.sum(lines[:, 0:2] * ends, axis=1) + lines[:, 2], 0.0,
                                   atol=1e-12)
    # A point 3 px to the left of a rightward segment (y down) is at distance +-3.
    assert abs(lines[0, 0:2] @ [5.0, 3.0] + lines[0, 2]) == pytest.approx(3.0)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 100_000), offset=st.floats(0.0, 2.9))
@example(seed=48911, offset=1.0)  # the tree's 8 candidates missed a line 2.9 px away
def test_closest_line_equals_brute_force_for_near_lines(seed, offset):
    rng = np.random.default_rng(seed)
    scene = line_scene(rng, 150, outlier_fraction=0.3, noise_px=0.0)
    matcher = LineMatcher(scene.right)
    # Predictions: the true lines' images moved sideways by up to 2.9 px (the threshold
    # region), and with random endpoints along them.
    pred = map_segments(scene.homography, scene.left)
    pred = pred + offset * np.tile(segment_lines(pred)[:, 0:2], 2) / np.sqrt(2.0)
    d, idx, c1, c2 = matcher.closest(pred[:, 0:2], pred[:, 2:4])
    d_bf, _ = matcher.brute_force(pred[:, 0:2], pred[:, 2:4])
    near = d_bf < 3.0
    assert np.count_nonzero(near) > 20
    np.testing.assert_allclose(d[near], d_bf[near], atol=1e-9)
    assert np.all(d >= d_bf - 1e-9)
    # The projections are on the chosen line, and D is their distance in R^4.
    found = d < UNMATCHED_PX
    lines = matcher.lines[idx[found]]
    for c in (c1, c2):
        np.testing.assert_allclose(np.sum(lines[:, 0:2] * c[found], axis=1) + lines[:, 2], 0.0,
                                   atol=1e-9)
    np.testing.assert_allclose(np.sqrt(np.sum((pred[found, 0:2] - c1[found]) ** 2, axis=1)
                                       + np.sum((pred[found, 2:4] - c2[found]) ** 2, axis=1)),
                               d[found], rtol=1e-9, atol=1e-9)


def test_opposite_polarity_does_not_match():
    right = np.array([[0.0, 100.0, 200.0, 100.0], [0.0, 103.0, 200.0, 103.0],
                      [50.0, 0.0, 50.0, 300.0], [90.0, 0.0, 100.0, 300.0]])
    right[1] = right[1][[2, 3, 0, 1]]  # the second edge of the "joint" runs the other way
    matcher = LineMatcher(right)
    # A prediction on the reversed edge, oriented like the first one, matches the first.
    d, idx, _, _ = matcher.closest(np.array([[20.0, 103.0]]), np.array([[180.0, 103.0]]))
    assert idx[0] == 0 and d[0] == pytest.approx(np.sqrt(18.0))


def test_lines_reason_for_degenerate_sets():
    rng = np.random.default_rng(0)
    assert 'at least 4' in lines_reason(rng.random((3, 4)) * 100, 'left')
    parallel = line_scene(rng, 20, directions_deg=np.array([30.0]), outlier_fraction=0.0)
    assert 'concurrent or parallel' in lines_reason(parallel.left, 'left')
    pencil = line_scene(rng, 20, through_point=(320.0, 240.0), outlier_fraction=0.0)
    assert 'concurrent or parallel' in lines_reason(pencil.left, 'left')
    assert lines_reason(line_scene(rng, 20).left, 'left') == ''
    assert 'non-finite' in lines_reason(np.full((5, 4), np.nan), 'right')


# --- Convergence guarantee on lines and on points + lines.
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 100_000), potential=st.sampled_from(sorted(POTENTIALS)),
       lam=st.floats(0.05, 0.95), threshold=st.floats(0.5, 30.0),
       outliers=st.floats(0.0, 0.6), displacement=st.floats(0.0, 60.0),
       n=st.integers(6, 120), joint=st.booleans(), weight=st.floats(0.05, 20.0))
def test_energy_trace_is_non_increasing_for_lines_and_joint(
        seed, potential, lam, threshold, outliers, displacement, n, joint, weight):
    rng = np.random.default_rng(seed)
    scene = line_scene(rng, n, outlier_fraction=outliers, missing_fraction=0.1)
    # The guarantee is about the iteration: segment sets that cannot fix H (fewer than 4
    # after the missing ones, e.g. n = 6, seed 484) fail or are left out before it runs
    # (test_lines_reason_for_degenerate_sets, test_degenerate_lines_give_failure_values).
    assume(not lines_reason(scene.left, 'left') and not lines_reason(scene.right, 'right'))
    points = point_scene(rng, n, outlier_fraction=outliers, homography=scene.homography)
    h0 = displace_homography(scene.homography, displacement, rng)
    left, right = (points.left, points.right) if joint else (None, None)
    est = estimate_plane(left, right, h0, potential=potential, lambda_weight=lam,
                         threshold_px=threshold, min_inliers=4, max_iterations=40,
                         line_weight=weight, left_lines=scene.left, right_lines=scene.right)
    trace = est.energy_trace
    assert trace.size > 0 and np.all(np.isfinite(trace))
    if isinstance(est, PlaneEstimate):
        assert np.all(np.isfinite(est.homography))
        assert est.line_inliers.shape == (scene.left.shape[0],)
        assert est.inliers.shape == ((points.left.shape[0],) if joint else (0,))
    else:
        assert est.reason
    for stage in np.unique(est.stage_trace):
        t = trace[est.stage_trace == stage]
        assert np.all(np.diff(t) <= 1e-10 * (1.0 + t[0])), (stage, np.diff(t).max())


# --- Recovery on synthetic line scenes.
def test_exact_lines_recover_the_homography():
    for seed in range(5):
        rng = np.random.default_rng(seed)
        scene = line_scene(rng, 60, outlier_fraction=0.0, missing_fraction=0.0, noise_px=0.0)
        h0 = displace_homography(scene.homography, 3.0, rng)
        est = estimate_plane(None, None, h0, left_lines=scene.left, right_lines=scene.right,
                             tolerance_px=1e-6, energy_tolerance=0.0, max_iterations=300)
        assert est.ok and est.line_inliers.all()
        assert plane_error_px(est.homography, scene.homography, GRID) < 1e-4
        np.testing.assert_allclose(est.line_residuals_px, 0.0, atol=1e-4)


@pytest.mark.parametrize('potential', ['truncated_quadratic', 'huber', 'geman_mcclure'])
def test_lines_with_outliers_recover_plane_and_segment(potential):
    errors = []
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        scene = line_scene(rng, 120, outlier_fraction=0.3, missing_fraction=0.1)
        h0 = displace_homography(scene.homography, 4.0, rng)
        est = estimate_plane(None, None, h0, potential=potential, left_lines=scene.left,
                             right_lines=scene.right)
        assert est.ok, est.reason
        errors.append(plane_error_px(est.homography, scene.homography, GRID))
        # Off-plane segments shifted along x stay inliers when they are nearly horizontal,
        # so precision is bounded by the geometry; recall is the stricter figure.
        assert np.mean(est.line_inliers[scene.on_plane]) > 0.85
        assert np.mean(scene.on_plane[est.line_inliers]) > 0.8
    assert np.mean(errors) < 0.3, errors


def test_joint_points_and_lines_beat_either_alone_when_both_are_scarce():
    """Few points and few lines each: alone they are poorly conditioned, together not."""
    wins = 0
    for seed in range(10):
        rng = np.random.default_rng(200 + seed)
        lines = line_scene(rng, 8, outlier_fraction=0.25, noise_px=0.5)
        points = point_scene(rng, 10, outlier_fraction=0.25, noise_px=0.5,
                             homography=lines.homography)
        h0 = displace_homography(lines.homography, 2.0, rng)
        opts = {'min_inliers': 4}
        both = estimate_plane(points.left, points.right, h0, left_lines=lines.left,
                              right_lines=lines.right, **opts)
        assert both.ok
        e_both = plane_error_px(both.homography, lines.homography, GRID)
        e_pts = plane_error_px(estimate_plane(points.left, points.right, h0, **opts).homography,
                               lines.homography, GRID)
        wins += e_both < e_pts
        assert e_both < 1.5
    assert wins >= 7


def test_lines_cold_start_from_prior():
    prior = PriorConfig(focal_px=(500, 800), baseline_over_height=(0.08, 0.3),
                        tilt_deg=(15, 45), vergence_deg=(-1, 3))
    ok = 0
    for seed in range(6):
        rng = np.random.default_rng(300 + seed)
        scene = line_scene(rng, 120)
        est = estimate_plane(None, None, prior=prior, image_size=(640, 480),
                             left_lines=scene.left, right_lines=scene.right)
        ok += est.ok and plane_error_px(est.homography, scene.homography, GRID) < 1.0
    assert ok >= 5


def test_degenerate_lines_give_failure_values():
    rng = np.random.default_rng(7)
    h = line_scene(rng, 4).homography
    parallel = line_scene(rng, 30, directions_deg=np.array([75.0]), homography=h,
                          outlier_fraction=0.0)
    est = estimate_plane(None, None, h, left_lines=parallel.left, right_lines=parallel.right)
    assert isinstance(est, FailedEstimate) and 'concurrent or parallel' in est.reason
    pencil = line_scene(rng, 30, through_point=(300.0, 260.0), homography=h,
                        outlier_fraction=0.0)
    est = estimate_plane(None, None, h, left_lines=pencil.left, right_lines=pencil.right)
    assert not est.ok and 'left lines are all concurrent' in est.reason
    est = estimate_plane(None, None, h, left_lines=pencil.left[:3], right_lines=pencil.right)
    assert not est.ok and 'at least 4 left line segments' in est.reason
    # Joint: degenerate lines are left out and the points still solve; both bad -> failure.
    points = point_scene(rng, 100, outlier_fraction=0.0, missing_fraction=0.0, homography=h)
    est = estimate_plane(points.left, points.right, h, left_lines=pencil.left,
                         right_lines=pencil.right)
    assert est.ok and est.line_inliers.size == 0 and est.inliers.all()
    est = estimate_plane(points.left[:3], points.right, h, left_lines=pencil.left,
                         right_lines=pencil.right)
    assert not est.ok and 'points' in est.reason and 'lines' in est.reason
    with pytest.raises(ValueError, match=r'\(N, 4\)'):
        estimate_plane(None, None, h, left_lines=np.zeros((5, 3)), right_lines=pencil.right)


# --- Through the pipeline, on a rendered low-texture floor.
@pytest.mark.parametrize('kind', ['lines', 'both'])
def test_pipeline_finds_low_texture_floor_with_lines(tiles, kind):
    config = PlaneNodeConfig(prior=RENDERED_PRIOR)
    config = replace(config, features=replace(config.features, kind=kind))
    pipeline = PlanePipeline(one_shot_search(config))
    result = pipeline.process(tiles.left, tiles.right, 0)
    assert result.ok, result.reason
    assert _floor_error(tiles, result.homography) < 1.0
    assert result.left_lines.shape[0] > 50 and result.right_lines.shape[0] > 50
    assert result.estimate.line_inliers.sum() > 40
    assert (result.left_points.shape[0] > 0) == (kind == 'both')
    # Warm start on the next pair keeps it.
    again = pipeline.process(tiles.left, tiles.right, 1)
    assert again.ok and not again.reinitialised
    assert _floor_error(tiles, again.homography) < 1.0
    rgb = debug_overlay(tiles.left, again)
    assert rgb.shape == (480, 640, 3)
    # Inlier segments are drawn in cyan over the floor.
    cyan = (rgb[:, :, 0] < 80) & (rgb[:, :, 1] > 150) & (rgb[:, :, 2] > 150)
    assert np.count_nonzero(cyan) > 200


def test_the_tight_polish_guard_holds_with_segments_only(tiles, monkeypatch):
    # The published winner's tight polish is refused when it moves the predictions by more
    # than TIGHT_POLISH_MAX_MOVE_PX; with segments only there are no corner predictions, and
    # the guard measured nothing (a median of zeros) and let any polished plane through to the
    # verification. Here the tight polish jumps 6 px: it must not even be judged.
    config = PlaneNodeConfig(prior=RENDERED_PRIOR)
    config = replace(config, features=replace(config.features, kind='lines'))
    tight = TIGHT_POLISH_RATIO * config.estimator.threshold_px
    polish, judge = TwoStep.polish, TrustGate.judge
    jumps, judged = [], []

    def jumping_polish(self, h, threshold_px, matched):
        out = polish(self, h, threshold_px, matched)
        if threshold_px == tight:
            jumps.append(np.array([[1.0, 0.0, 6.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ h)
            return (jumps[-1], *out[1:])
        return out

    def spy(self, left, right, homography, *args, **kwargs):
        judged.append(np.asarray(homography))
        return judge(self, left, right, homography, *args, **kwargs)

    monkeypatch.setattr(TwoStep, 'polish', jumping_polish)
    monkeypatch.setattr(TrustGate, 'judge', spy)
    result = PlanePipeline(one_shot_search(config)).process(tiles.left, tiles.right, 0)
    assert result.ok, result.reason
    assert jumps, 'the tight polish did not run'
    assert not any(np.allclose(h / h[2, 2], j / j[2, 2]) for h in judged for j in jumps)
    assert _floor_error(tiles, result.homography) < 1.0
