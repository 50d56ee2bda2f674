"""The two-step estimator on seeded synthetic scenes, including the paper's experiments."""

from __future__ import annotations

from domplane_ros.config import EstimatorConfig, PriorConfig
from domplane_ros.core import basin
from domplane_ros.core.estimator import FailedEstimate, PlaneEstimate, TwoStep
from domplane_ros.core.homography import apply_homography, fit_homography
from domplane_ros.core.plane import estimate_plane
from domplane_ros.core.potentials import POTENTIALS
from domplane_ros.core.prior import plane_homography, prior_candidates, PriorSearch
from domplane_ros.core.stages import can_widen, gnc_scales
from domplane_ros.sim.synthetic import (displace_homography, plane_error_px, point_scene,
                                        POINT_SET_KINDS)
from hypothesis import example, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest


def _similarity(rot_deg, scale, tx, ty, centre=(320.0, 240.0)):
    r = np.deg2rad(rot_deg)
    c = np.array([[1, 0, centre[0]], [0, 1, centre[1]], [0, 0, 1.0]])
    a = np.array([[scale * np.cos(r), -scale * np.sin(r), tx],
                  [scale * np.sin(r), scale * np.cos(r), ty], [0, 0, 1.0]])
    return c @ a @ np.linalg.inv(c)


def _circle_points():
    ang = np.arange(12) * 2 * np.pi / 12
    pts = np.c_[320 + 100 * np.cos(ang), 240 + 100 * np.sin(ang)]
    return np.r_[pts, [[330.0, 247.0], [309.0, 228.0]]]


# --- Paper experiment (a): circle of 12 points and 2 near the centre, true H = identity.
@pytest.mark.parametrize('init', [(12, 1.1, 10, 5), (12, 0.9, 10, 5), (8, 1.1, 20, 0),
                                  (12, 1.2, 0, 20)])
def test_paper_a_truncated_recovers_identity_least_squares_does_not(init):
    pts = _circle_points()
    h0 = _similarity(*init)
    opts = {'threshold_px': 20.0, 'lambda_weight': 0.6, 'min_inliers': 4}
    robust = estimate_plane(pts, pts, h0, potential='truncated_quadratic', **opts)
    assert robust.ok
    assert np.abs(apply_homography(robust.homography, pts) - pts).max() < 1e-3
    assert robust.n_inliers == 14
    ls = estimate_plane(pts, pts, h0, potential='least_squares', **opts)
    wrong = (not ls.ok) or np.abs(apply_homography(ls.homography, pts) - pts).max() > 10.0
    assert wrong


# --- Paper experiment (b): one off-plane point among plane points.
@pytest.mark.parametrize('seed', range(5))
def test_paper_b_robust_flags_off_plane_point_least_squares_is_biased(seed):
    rng = np.random.default_rng(seed)
    h = plane_homography(650, 0.2, 30, 1.0, 640, 480)
    left = rng.uniform([50, 50], [590, 430], (20, 2))
    right = apply_homography(h, left)
    right[7, 0] -= 40.0
    h0 = displace_homography(h, 3.0, rng)
    on_plane = np.delete(left, 7, axis=0)
    opts = {'threshold_px': 5.0, 'lambda_weight': 0.6, 'min_inliers': 4,
            'euclidean_refinement': False}
    for name in ('truncated_quadratic', 'geman_mcclure'):
        robust = estimate_plane(left, right, h0, potential=name, **opts)
        assert robust.ok
        assert not robust.inliers[7]
        assert robust.inliers.sum() == 19
        assert plane_error_px(robust.homography, h, on_plane) < 0.05
    ls = estimate_plane(left, right, h0, potential='least_squares', **opts)
    # Least squares is pulled by the off-plane point: several tenths of a pixel (measured
    # 0.8 px here), twenty times the robust runs' error bound.
    assert plane_error_px(ls.homography, h, on_plane) > 0.3
    # The Euclidean refinement on the inliers removes that bias.
    refined = estimate_plane(left, right, h0, potential='least_squares', threshold_px=5.0,
                             lambda_weight=0.6, min_inliers=4)
    assert plane_error_px(refined.homography, h, on_plane) < 0.05


@pytest.mark.parametrize('outlier_fraction', [0.3, 0.6, 0.8])
def test_extrapolation_keeps_the_energy_falling_and_solves_what_the_plain_run_solves(
        outlier_fraction):
    # The extrapolation's trial steps (estimate(..., extrapolate=True)) are kept only where
    # the joint energy falls: every trace is non-increasing, every scene the plain iteration
    # solves is solved, in at most 60 % of the plain iteration's rounds over the scenes (many
    # outliers hold the plain iteration back: their auxiliary points are their predictions).
    rounds = {False: 0, True: 0}
    for seed in range(50_000, 50_020):
        errors = {}
        for extrapolate in (False, True):
            rng = np.random.default_rng(seed)
            scene = point_scene(rng, 400, outlier_fraction=outlier_fraction)
            h0 = displace_homography(scene.homography, 8.0, rng)
            est = TwoStep.from_features(scene.left, scene.right).estimate(
                h0, EstimatorConfig(), widen=False, extrapolate=extrapolate)
            assert est.ok
            trace = est.energy_trace
            assert np.all(np.diff(trace) <= 1e-9 * trace[0])
            rounds[extrapolate] += est.iterations
            errors[extrapolate] = plane_error_px(est.homography, scene.homography,
                                                 scene.left[scene.on_plane])
        if errors[False] < 0.5:
            assert errors[True] < 0.5, seed
    assert rounds[True] <= 0.6 * rounds[False]


def test_only_the_last_stage_of_a_graduated_run_extrapolates():
    # The wider stages run as the plain iteration's: the same energies up to the last stage.
    rng = np.random.default_rng(50_100)
    scene = point_scene(rng, 400, outlier_fraction=0.6)
    h0 = displace_homography(scene.homography, 20.0, rng)
    options = EstimatorConfig(potential='geman_mcclure')
    plain, trial = (TwoStep.from_features(scene.left, scene.right).estimate(
        h0, options, widen=True, extrapolate=x) for x in (False, True))
    last = int(plain.stage_trace.max())
    assert last == 3 and int(trial.stage_trace.max()) == last
    wide = plain.stage_trace < last
    assert np.array_equal(trial.energy_trace[:np.count_nonzero(wide)],
                          plain.energy_trace[wide])
    # ... and the last stage did take trial steps.
    assert not np.array_equal(trial.energy_trace, plain.energy_trace)


# --- Paper experiment (c): energy decreases, faster for lambda = 0.6 than 0.3.
@pytest.mark.parametrize('seed', range(4))
def test_paper_c_energy_decreases_faster_with_larger_lambda(seed):
    rng = np.random.default_rng(seed)
    scene = point_scene(rng, 300, outlier_fraction=0.2, missing_fraction=0.05)
    h0 = displace_homography(scene.homography, 4.0, rng)
    runs = {}
    for lam in (0.3, 0.6):
        est = estimate_plane(scene.left, scene.right, h0, potential='truncated_quadratic',
                             lambda_weight=lam, threshold_px=8.0, tolerance_px=1e-4,
                             energy_tolerance=0.0, max_iterations=300)
        assert est.ok
        trace = est.energy_trace
        assert np.all(np.diff(trace) <= 1e-9 * trace[0])
        assert trace[-1] < trace[0]
        runs[lam] = est
    # Normalised progress after 5 iterations, and iterations to converge.
    prog = {lam: (r.energy_trace[5] - r.energy_trace[-1]) / (r.energy_trace[0]
                                                             - r.energy_trace[-1])
            for lam, r in runs.items()}
    assert prog[0.6] < prog[0.3]
    assert runs[0.6].iterations < runs[0.3].iterations


# --- Convergence guarantee: the recorded energy never increases (within a GNC stage).
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 100_000), potential=st.sampled_from(sorted(POTENTIALS)),
       lam=st.floats(0.05, 0.95), threshold=st.floats(0.5, 30.0),
       outliers=st.floats(0.0, 0.6), displacement=st.floats(0.0, 80.0),
       n=st.integers(6, 200))
# Found by hypothesis: four features, an exact fit, and a step that raised the energy.
@example(seed=6, potential='geman_mcclure', lam=0.375, threshold=1.0, outliers=0.0,
         displacement=67.5, n=6)
def test_energy_trace_is_non_increasing(seed, potential, lam, threshold, outliers,
                                        displacement, n):
    rng = np.random.default_rng(seed)
    scene = point_scene(rng, n, outlier_fraction=outliers, missing_fraction=0.1)
    h0 = displace_homography(scene.homography, displacement, rng)
    est = estimate_plane(scene.left, scene.right, h0, potential=potential,
                         lambda_weight=lam, threshold_px=threshold, min_inliers=4,
                         max_iterations=40)
    trace = est.energy_trace
    assert np.all(np.isfinite(trace))
    if isinstance(est, PlaneEstimate):
        assert np.all(np.isfinite(est.homography))
    else:
        assert est.reason
    assert est.stage_trace.shape == trace.shape
    for stage in np.unique(est.stage_trace):
        t = trace[est.stage_trace == stage]
        assert np.all(np.diff(t) <= 1e-10 * (1.0 + t[0])), (stage, np.diff(t).max())


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 100_000), lam=st.floats(0.05, 0.95))
def test_geman_mcclure_single_stage_trace_is_non_increasing(seed, lam):
    rng = np.random.default_rng(seed)
    scene = point_scene(rng, 150)
    h0 = displace_homography(scene.homography, 15.0, rng)
    est = estimate_plane(scene.left, scene.right, h0, potential='geman_mcclure',
                         lambda_weight=lam, gnc_start_px=3.0, threshold_px=3.0,
                         min_inliers=4)
    assert np.all(est.stage_trace == 0)
    assert np.all(np.isfinite(est.energy_trace))
    assert np.all(np.diff(est.energy_trace) <= 1e-10 * (1 + est.energy_trace[0]))


# --- Segmentation and accuracy with outliers and missing detections.
@pytest.mark.parametrize('potential', ['truncated_quadratic', 'huber', 'geman_mcclure'])
def test_warm_start_recovers_plane_and_segments_points(potential):
    errors = []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        scene = point_scene(rng, 500, outlier_fraction=0.3, missing_fraction=0.1)
        h0 = displace_homography(scene.homography, 5.0, rng)
        est = estimate_plane(scene.left, scene.right, h0, potential=potential)
        assert est.ok and est.converged
        errors.append(plane_error_px(est.homography, scene.homography,
                                     scene.left[scene.on_plane]))
        # Inliers: on-plane points whose partner was detected; outliers: the rest mostly.
        precision = np.mean(scene.on_plane[est.inliers])
        recall = np.mean(est.inliers[scene.on_plane])
        assert precision > 0.93
        assert recall > 0.85
        # The matched right point of an inlier is within the threshold of the prediction.
        pred = apply_homography(est.homography, scene.left[est.inliers])
        matched = scene.right[est.matches[est.inliers]]
        assert np.all(np.linalg.norm(pred - matched, axis=1) < 3.0)
        np.testing.assert_allclose(est.residuals_px[est.inliers],
                                   np.linalg.norm(pred - matched, axis=1))
    assert np.mean(errors) < 0.1, errors


def test_geman_mcclure_basin_at_20_px():
    ok = 0
    for seed in range(20):
        rng = np.random.default_rng(1000 + seed)
        scene = point_scene(rng, 500)
        h0 = displace_homography(scene.homography, 20.0, rng)
        est = estimate_plane(scene.left, scene.right, h0, potential='geman_mcclure')
        ok += est.ok and plane_error_px(est.homography, scene.homography,
                                        scene.left[scene.on_plane]) < 1.0
    assert ok >= 19


BASIN_KINDS = POINT_SET_KINDS


def _basin_converged(kind, potential=None, first_seed=30_000, runs=20):
    """Return how many of ``runs`` scenes of ``kind`` converge from 20 px corner moves."""
    options = dict(BASIN_KINDS[kind])
    n_points = options.pop('n_points', 500)
    overrides = {} if potential is None else {'potential': potential}
    ok = 0
    for seed in range(first_seed, first_seed + runs):
        rng = np.random.default_rng(seed)
        scene = point_scene(rng, n_points, **options)
        h0 = displace_homography(scene.homography, 20.0, rng)
        est = estimate_plane(scene.left, scene.right, h0, **overrides)
        ok += est.ok and plane_error_px(est.homography, scene.homography,
                                        scene.left[scene.on_plane]) < 1.0
    return ok


@pytest.mark.parametrize('kind', sorted(BASIN_KINDS))
def test_geman_mcclure_converges_from_20_px_on_every_kind_of_point_set(kind):
    # The graduated potential (estimator.potential geman_mcclure, its documented GNC
    # defaults): at least 95 % from every image corner's image moved 20 px, on point sets
    # unlike the default spread one too.
    assert _basin_converged(kind, 'geman_mcclure') >= 19, kind


@pytest.mark.parametrize('kind', sorted(BASIN_KINDS))
def test_default_settings_converge_from_20_px_on_every_kind_of_point_set(kind):
    # The target with the default settings (truncated quadratic, a far start
    # graduated in a multi-start, core/basin.py): at least 95 % on every kind; on these tuning
    # seeds (30000-30019) every scene converges, where one graduated run missed one of 20
    # spread, clustered and sparse scenes. Held-out seeds are in docs/BENCHMARKS.md
    # (python -m domplane_ros.tools.bench --basin-kinds-only --basin-kinds-seed 70000).
    assert _basin_converged(kind) == 20, kind


def test_far_start_is_graduated_and_good_start_is_not():
    # Inverting or disabling the far-start test fails here: a 2 px start runs one stage
    # (plain truncated quadratic), a 20 px start the graduated stages, and the prior's
    # candidates (widen=False) never graduate.
    for seed in range(5):
        rng = np.random.default_rng(40_000 + seed)
        scene = point_scene(rng, 500)
        problem = TwoStep.from_features(scene.left, scene.right)
        near = displace_homography(scene.homography, 2.0, rng)
        far = displace_homography(scene.homography, 20.0, rng)
        assert problem.start_nearness(near, 3.0) == 'near'
        assert problem.start_nearness(far, 3.0) == 'far'
        options = EstimatorConfig()
        assert np.all(problem.estimate(near, options).stage_trace == 0)
        assert problem.estimate(far, options).stage_trace.max() == 3
        assert np.all(problem.estimate(far, options, widen=False).stage_trace == 0)
        assert problem.estimate(near, options, widen=True).stage_trace.max() == 3


def _hard_start(kind, seed):
    """Return the problem, the 20 px start and the truth of a basin scene of ``kind``."""
    options = dict(BASIN_KINDS[kind])
    rng = np.random.default_rng(seed)
    scene = point_scene(rng, options.pop('n_points', 500), **options)
    h0 = displace_homography(scene.homography, 20.0, rng)
    return TwoStep.from_features(scene.left, scene.right), h0, scene


def _error_px(result, scene):
    if not result.ok:
        return np.inf
    return plane_error_px(result.homography, scene.homography, scene.left[scene.on_plane])


@pytest.mark.parametrize('kind, seed', [('sparse_150', 30018), ('sparse_150', 30031),
                                        ('missing_30', 30028), ('missing_30', 30060)])
def test_partly_aligned_far_start_is_doubtful_and_widened(kind, seed):
    # Sparse sets have little support by chance, so a far start partly aligned passed the
    # support-ratio test alone and the plain run slid into a wrong plane (tuning seeds where
    # it did). Without the excess-support rule (NEAR_EXCESS_SUPPORT) these starts are 'near'.
    problem, h0, scene = _hard_start(kind, seed)
    options = EstimatorConfig()
    assert problem.start_nearness(h0, options.threshold_px) == 'doubtful'
    assert _error_px(problem.estimate(h0, options, widen=False), scene) > 3.0
    assert _error_px(problem.estimate(h0, options), scene) < 1.0


@pytest.mark.parametrize('seed', [30008, 30031, 30071])
def test_far_start_multi_start_finds_the_plane_one_graduated_run_misses(seed, monkeypatch):
    # Clustered sets: one graduated run from the far start slides into a wrong plane (tuning
    # seeds where it did); the multi-start (the start moved 10 px four ways, lowest energy at
    # the threshold) finds the true one. With no shift every start is the same one run.
    problem, h0, scene = _hard_start('clustered', seed)
    options = EstimatorConfig()
    assert _error_px(problem.estimate(h0, options), scene) < 1.0
    monkeypatch.setattr(basin, 'FAR_START_SHIFT_PX', 0.0)
    assert _error_px(problem.estimate(h0, options), scene) > 3.0


def test_only_geman_mcclure_is_graduated_and_it_ends_at_the_threshold():
    stages = gnc_scales(EstimatorConfig(potential='geman_mcclure'))
    assert stages[0] == 24.0 and stages[-1] == 3.0 and stages == sorted(stages, reverse=True)
    assert gnc_scales(EstimatorConfig()) == [3.0]
    # A far start graduates the default truncated quadratic too: 24, 12, 6, 3 px.
    assert gnc_scales(EstimatorConfig(), far=True) == [24.0, 12.0, 6.0, 3.0]
    assert gnc_scales(EstimatorConfig(potential='huber'), far=True) == [3.0]
    assert not can_widen(EstimatorConfig(threshold_px=20.0))
    assert gnc_scales(EstimatorConfig(potential='huber')) == [3.0]


def test_cold_start_from_prior():
    prior = PriorConfig(focal_px=(500, 800), baseline_over_height=(0.08, 0.3),
                        tilt_deg=(15, 45), vergence_deg=(-1, 3))
    ok = 0
    for seed in range(10):
        rng = np.random.default_rng(seed)
        scene = point_scene(rng, 400)
        est = estimate_plane(scene.left, scene.right, prior=prior, image_size=(640, 480))
        ok += est.ok and plane_error_px(est.homography, scene.homography,
                                        scene.left[scene.on_plane]) < 1.0
        if est.ok:
            assert est.candidates_tried == prior.refine_best
    assert ok >= 9


# --- Failure values, never NaN.
@pytest.mark.parametrize('left,right,reason', [
    (np.zeros((3, 2)), np.random.default_rng(0).random((10, 2)), 'at least 4 left'),
    (np.random.default_rng(0).random((10, 2)), np.zeros((2, 2)), 'at least 4 right'),
    (np.c_[np.arange(10.0), np.arange(10.0)], np.random.default_rng(1).random((10, 2)),
     'collinear'),
    (np.repeat([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0]], 5, axis=0),
     np.random.default_rng(1).random((10, 2)), 'distinct'),
    (np.full((10, 2), np.inf), np.random.default_rng(1).random((10, 2)), 'non-finite'),
])
def test_degenerate_points_give_failure_with_reason(left, right, reason):
    est = estimate_plane(left, right, np.eye(3))
    assert isinstance(est, FailedEstimate)
    assert not est and not est.ok
    assert reason in est.reason


def test_singular_or_nonfinite_init_is_a_failure():
    scene = point_scene(np.random.default_rng(0), 50)
    for bad in (np.zeros((3, 3)), np.full((3, 3), np.nan)):
        est = estimate_plane(scene.left, scene.right, bad)
        assert not est.ok and 'initial homography' in est.reason


def test_too_few_inliers_is_a_failure():
    rng = np.random.default_rng(0)
    left = rng.uniform(0, 640, (30, 2))
    right = rng.uniform(0, 640, (30, 2)) + 5000.0
    est = estimate_plane(left, right, np.eye(3), potential='truncated_quadratic')
    assert not est.ok and 'too few inliers' in est.reason


def test_api_misuse_raises_value_error():
    pts = np.random.default_rng(0).random((10, 2))
    with pytest.raises(ValueError, match='shape'):
        estimate_plane(np.zeros((10, 3)), pts, np.eye(3))
    with pytest.raises(ValueError, match='image_size'):
        estimate_plane(pts, pts)
    with pytest.raises(ValueError, match='potential'):
        estimate_plane(pts, pts, np.eye(3), potential='nope')
    with pytest.raises(ValueError, match='init'):
        estimate_plane(pts, pts, np.eye(2))


def test_options_object_and_overrides_agree():
    rng = np.random.default_rng(5)
    scene = point_scene(rng, 200)
    h0 = displace_homography(scene.homography, 3.0, rng)
    a = estimate_plane(scene.left, scene.right, h0,
                       EstimatorConfig(potential='huber', lambda_weight=0.5))
    b = estimate_plane(scene.left, scene.right, h0, potential='huber', lambda_weight=0.5)
    np.testing.assert_array_equal(a.homography, b.homography)


# --- One prior search, one failure type.
def test_prior_search_over_frames_equals_the_one_shot_search():
    prior = PriorConfig(focal_px=(500, 800), baseline_over_height=(0.08, 0.3),
                        tilt_deg=(15, 45), vergence_deg=(-1, 3), refine_best=4)
    scene = point_scene(np.random.default_rng(3), 300)
    one_shot = estimate_plane(scene.left, scene.right, prior=prior, image_size=(640, 480))
    # The pipeline's way: the same search, two candidates at a time, the best carried on.
    problem = TwoStep.from_features(scene.left, scene.right)
    search = PriorSearch(problem, prior_candidates(prior, 640, 480),
                         prior.screen_threshold_px)
    order = search.ranked()
    assert order[:2] + search.ranked(skip=set(order[:2]))[:2] == order[:4]
    best, rejected = search.refine(order[:2], EstimatorConfig())
    best, rejected = search.refine(order[2:4], EstimatorConfig(), best=best)
    assert one_shot.ok and best.ok and not rejected
    assert one_shot.candidates_tried == 4
    np.testing.assert_array_equal(best.homography, one_shot.homography)
    # A rejected candidate is dropped and its reason kept.
    best, rejected = search.refine(order[:4], EstimatorConfig(), lambda est: 'no')
    assert best is None and rejected == 'no'


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_prior_search_keeps_the_candidate_that_explains_the_most_features(seed):
    # Round 23 (mutants): keeping the worst refined candidate instead of the best passed every
    # core test (their candidates all converge to the one plane). Here the features lie on two
    # planes, 270 on the floor and 150 on another plane 19-61 px off it: refined from a start
    # near each, the floor ends with the lower energy, and the search keeps it in either order.
    rng = np.random.default_rng(seed)
    floor = point_scene(rng, 300, outlier_fraction=0.1)
    other = point_scene(rng, 150, outlier_fraction=0.0)
    problem = TwoStep.from_features(np.r_[floor.left, other.left],
                                    np.r_[floor.right, other.right])
    starts = np.stack([displace_homography(floor.homography, 3.0, rng),
                       displace_homography(other.homography, 3.0, rng)])
    on_floor = floor.left[floor.on_plane]
    assert plane_error_px(other.homography, floor.homography, on_floor) > 10.0
    search = PriorSearch(problem, starts, PriorConfig().screen_threshold_px)
    for order in ([0, 1], [1, 0]):
        best, rejected = search.refine(order, EstimatorConfig())
        assert best is not None and best.ok and not rejected
        assert plane_error_px(best.homography, floor.homography, on_floor) < 0.5, order


def test_every_failure_is_one_failed_estimate_value():
    collinear = np.c_[np.arange(10.0), np.arange(10.0)]
    failures = [fit_homography(collinear, collinear),
                estimate_plane(collinear, collinear, np.eye(3)),
                TwoStep.from_features(collinear, collinear)]
    for failure in failures:
        assert isinstance(failure, FailedEstimate)
        assert not failure and not failure.ok and not failure.converged
        assert 'collinear' in failure.reason and str(failure) == failure.reason
