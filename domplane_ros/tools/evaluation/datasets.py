"""The evaluated data sets: their priors and targets, and both methods run and scored on each.

KITTI 2015 000046 (road plane), the OpenCV chessboard pairs, the books pair and the Ensenso
surface (no reference), rendered scenes and rendered sequences (frame-to-frame warm start).
Each pair becomes a :class:`Case` with both methods' runs and figures.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
import time
from typing import Any, Callable, Sequence

from domplane_ros.config import (FeatureConfig, one_shot_search, PlaneNodeConfig, PriorConfig,
                                 VerificationSettings)
from domplane_ros.core.homography import apply_homography, fit_homography
from domplane_ros.core.mask import mask_scores, OBSTACLE, PLANE
from domplane_ros.core.prior import prior_candidates
from domplane_ros.sim.generators import random_scene, RENDERED_PRIOR, scene_sequence
from domplane_ros.sim.model import StereoFrame
from domplane_ros.sim.truth import floor_points
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.common import progress
from domplane_ros.tools.evaluation.methods import MethodRun, ours_run, run_orb_magsac, run_ours
from domplane_ros.tools.evaluation.references import (chessboard_pairs, chessboards, ENSENSO_STEM,
                                                      kitti_reference, KittiReference,
                                                      mean_transfer_px, read_gray)
import numpy as np

# KITTI: the rig looks ahead (tilt near 0), f about 721 px, baseline 0.54 m at about 1.65 m,
# rectified (no vergence). Most corners are on buildings and trees, so features come from the
# lower part of the image only, for both methods.
KITTI_PRIOR = PriorConfig(focal_px=(650.0, 800.0), baseline_over_height=(0.25, 0.40),
                          tilt_deg=(-5.0, 5.0), vergence_deg=(-1.0, 1.0))
KITTI_ROI = (0.0, 0.55, 1.0, 1.0)
FULL_IMAGE = (0.0, 0.0, 1.0, 1.0)
# Chessboard rig: f about 536 px, the board 0.28-0.40 m away and turned 15-41 degrees from
# facing the camera (left_intrinsics.yml's calibration and board poses); the baseline is not
# given, so b/h gets a wide range. In the prior's camera model a plane facing the camera has a
# tilt near 90 degrees (the config allows up to 89). The rig is not rectified, so vergence gets
# a wide range too. One prior for all pairs, whole image, never anything from the reference.
CHESSBOARD_PRIOR = PriorConfig(focal_px=(450.0, 650.0), baseline_over_height=(0.05, 0.5),
                               tilt_deg=(45.0, 89.0), vergence_deg=(-6.0, 6.0))
# The boards are no ground: the product runs as a user of such a head would set it.
CHESSBOARD_PLANE = 'any'
# Books: unknown hand-held camera near the floor, wide baseline with a strong turn between
# the views: the default focal and tilt ranges, a wide baseline and vergence.
BOOKS_PRIOR = PriorConfig(focal_px=(400.0, 900.0), baseline_over_height=(0.05, 0.8),
                          tilt_deg=(0.0, 40.0), vergence_deg=(-15.0, 15.0))
# Ensenso (calibration JSON, rough): f about 3019 px, baseline 100 mm at about 1500 mm above
# the surface (b/h about 0.067), looking straight down (tilt 90, capped at 89), vergence 3.8
# degrees.
ENSENSO_PRIOR = PriorConfig(focal_px=(2500.0, 3500.0), baseline_over_height=(0.05, 0.09),
                            tilt_deg=(80.0, 89.0), vergence_deg=(2.0, 6.0))
SOLVED_PX = 1.0
KITTI_TARGET_PX = 1.5
CHESSBOARD_TARGET_PX = 2.0
RENDERED_TARGET_SOLVED = 0.95
SPEED_TARGET = 4.0


@dataclass
class Case:
    """One evaluated pair: both methods' runs and the figures computed from them.

    Attributes:
        dataset: Data set name.
        pair: Pair name within the data set.
        left: (H, W) uint8 left image, for the pictures.
        runs: ``{'ours': MethodRun, 'orb_magsac': MethodRun}``.
        figures: ``{method: {column: value}}``, the numbers of the table and the CSV.
        info: Per-pair values shared by both methods (floor kind, reference floor, ...).
    """

    dataset: str
    pair: str
    left: np.ndarray
    runs: dict[str, MethodRun]
    figures: dict[str, dict[str, float]]
    info: dict[str, Any] = field(default_factory=dict)


def _both(left: np.ndarray, right: np.ndarray, config: PlaneNodeConfig, repeats: int
          ) -> dict[str, MethodRun]:
    return {'ours': run_ours(left, right, config, repeats),
            'orb_magsac': run_orb_magsac(left, right, config.features.roi, repeats,
                                         mask_config=config.mask)}


def _figures(runs: dict[str, MethodRun],
             score: Callable[[MethodRun], dict[str, float]]) -> dict[str, dict[str, float]]:
    """Return each method's common figures (ok, counts, times) and its ``score(run)``."""
    figures = {}
    for method, run in runs.items():
        row = {'ok': float(run.ok), 'inliers': run.n_inliers, 'points': run.n_points,
               'time_ms': run.time_ms, 'warm_ms': run.warm_ms}
        row.update(score(run))
        figures[method] = row
    return figures


def kitti_config(roi: Sequence[float] = KITTI_ROI) -> PlaneNodeConfig:
    """Return the configuration used on KITTI: :data:`KITTI_PRIOR` and the ROI (default ROI)."""
    return PlaneNodeConfig(features=FeatureConfig(roi=tuple(roi)), prior=KITTI_PRIOR)


def evaluate_kitti(folder: Path, repeats: int = 3, full_image: bool = True) -> list[Case]:
    """Evaluate both methods on KITTI 2015 frame 000046 (see the module docstring).

    Args:
        folder: The ``kitti2015_000046`` folder.
        repeats: Timing repetitions.
        full_image: Also run both methods without the ROI (data set ``kitti_full_image``).

    Returns:
        The ``kitti`` case (prior and ROI), then the ``kitti_full_image`` case if asked for.

    """
    left = read_gray(folder / 'left.png')
    right = read_gray(folder / 'right.png')
    ref = kitti_reference(folder)
    cases = [_kitti_case('kitti', left, right, ref, kitti_config(), repeats)]
    if full_image:
        cases.append(_kitti_case('kitti_full_image', left, right, ref,
                                 kitti_config(FULL_IMAGE), repeats))
    return cases


def _kitti_case(name: str, left: np.ndarray, right: np.ndarray, ref: KittiReference,
                config: PlaneNodeConfig, repeats: int) -> Case:
    reference_h = ref.plane.homography()
    ys, xs = np.nonzero(ref.road)
    road_points = np.stack([xs, ys], axis=1).astype(np.float64)
    road_target = apply_homography(reference_h, road_points)
    # The ground-truth disparity itself, without the plane model: x' = x - d.
    gt_target = road_points - np.stack([ref.disparity[ys, xs], np.zeros(xs.size)], axis=1)

    def score(run: MethodRun) -> dict[str, float]:
        scores = {'plane_iou': math.nan, 'obstacle_recall': math.nan,
                  'obstacle_as_plane': math.nan}
        if run.mask is not None:
            scores = mask_scores(run.mask, ref.road, ref.off_road, ref.road | ref.off_road)
        return {'error_px': mean_transfer_px(run.homography, road_points, road_target),
                'warm_error_px': mean_transfer_px(run.warm_homography, road_points,
                                                  road_target),
                'error_vs_gt_disparity_px': mean_transfer_px(run.homography, road_points,
                                                             gt_target),
                'road_iou': scores['plane_iou'], 'off_road_recall': scores['obstacle_recall'],
                'off_road_as_plane': scores['obstacle_as_plane']}

    runs = _both(left, right, config, repeats)
    figures = _figures(runs, score)
    info = {'a': ref.plane.a, 'b': ref.plane.b, 'c': ref.plane.c,
            'within_1px': ref.plane.inlier_fraction,
            'road_px': int(np.count_nonzero(ref.road)),
            'off_road_px': int(np.count_nonzero(ref.off_road))}
    return Case(name, '000046', left, runs, figures, info)


def evaluate_chessboards(folder: Path, repeats: int = 3) -> list[Case]:
    """Evaluate both methods on the chessboard pairs (see the module docstring)."""
    config = PlaneNodeConfig(prior=CHESSBOARD_PRIOR,
                             verification=VerificationSettings(plane=CHESSBOARD_PLANE))
    cases = []
    numbers = progress(chessboard_pairs(folder), 'chessboards')
    for number, left, right, src, dst in chessboards(folder, numbers, report_skipped=True):
        reference = fit_homography(src, dst)
        floor = mean_transfer_px(reference if isinstance(reference, np.ndarray) else None,
                                 src, dst)
        candidates = prior_candidates(config.prior, left.shape[1], left.shape[0])
        prior_gap = min(mean_transfer_px(h, src, dst) for h in candidates)
        runs = _both(left, right, config, repeats)
        figures = _figures(runs, lambda run: {
            'error_px': mean_transfer_px(run.homography, src, dst),
            'warm_error_px': mean_transfer_px(run.warm_homography, src, dst)})
        cases.append(Case('chessboards', number, left, runs, figures,
                          {'reference_floor_px': floor, 'prior_gap_px': prior_gap}))
    return cases


def _grid_points(shape: tuple[int, int], step: int = 16) -> np.ndarray:
    ys, xs = np.mgrid[step // 2:shape[0]:step, step // 2:shape[1]:step]
    return np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)


def evaluate_qualitative(name: str, pair: str, left: np.ndarray, right: np.ndarray,
                         config: PlaneNodeConfig, repeats: int = 3) -> Case:
    """Run both methods on a pair without reference: inliers, mask coverage, disagreement.

    ``methods_apart_px`` is the mean distance between the two methods' predictions over a
    16-pixel grid of the left image (NaN if either failed). ``plane_fraction`` is the share
    of left pixels the mask labels plane, ``obstacle_fraction`` off the plane.
    """
    runs = _both(left, right, config, repeats)
    grid = _grid_points(left.shape)
    apart = math.nan
    if runs['ours'].ok and runs['orb_magsac'].ok:
        apart = mean_transfer_px(runs['ours'].homography, grid,
                                 apply_homography(runs['orb_magsac'].homography, grid))

    def score(run: MethodRun) -> dict[str, float]:
        if run.mask is None:
            return {'methods_apart_px': apart, 'plane_fraction': math.nan,
                    'obstacle_fraction': math.nan}
        return {'methods_apart_px': apart, 'plane_fraction': float(np.mean(run.mask == PLANE)),
                'obstacle_fraction': float(np.mean(run.mask == OBSTACLE))}

    figures = _figures(runs, score)
    return Case(name, pair, left, runs, figures)


def evaluate_books(folder: Path, repeats: int = 3) -> list[Case]:
    """Evaluate the books pair (``left.jpg``, ``right.jpg``) qualitatively."""
    left = read_gray(folder / 'left.jpg')
    right = read_gray(folder / 'right.jpg')
    return [evaluate_qualitative('books', 'left/right.jpg', left, right,
                                 PlaneNodeConfig(prior=BOOKS_PRIOR), repeats)]


def evaluate_ensenso(folder: Path, repeats: int = 3) -> list[Case]:
    """Evaluate the Ensenso projector-textured surface qualitatively."""
    left = read_gray(folder / f'{ENSENSO_STEM}_left.png')
    right = read_gray(folder / f'{ENSENSO_STEM}_right.png')
    return [evaluate_qualitative('ensenso', 'fit_primitive', left, right,
                                 PlaneNodeConfig(prior=ENSENSO_PRIOR), repeats)]


def evaluate_rendered(n_scenes: int, first_seed: int = 0, repeats: int = 1) -> list[Case]:
    """Evaluate both methods on rendered scenes with ground truth.

    Scene ``seed`` is :func:`random_scene(seed) <domplane_ros.sim.generators.random_scene>` for
    seeds ``first_seed .. first_seed + n_scenes - 1`` (random set-up within
    :data:`~domplane_ros.sim.generators.SETUP_RANGES`, floor kind, 1-5 boxes, horizon or wall). The
    error is the mean transfer error over the floor pixels seen by both cameras (every 4th pixel in
    x and y); the mask is scored with ``plane_left & visible_in_right`` as the plane and
    ``obstacle_left`` as the obstacles.
    """
    config = PlaneNodeConfig(prior=RENDERED_PRIOR)
    cases = []
    for seed in progress(range(first_seed, first_seed + n_scenes), 'rendered scenes'):
        frame = random_scene(seed)
        runs = _both(frame.left, frame.right, config, repeats)
        cases.append(Case('rendered', str(seed), frame.left, runs,
                          _figures(runs, _rendered_score(frame)), _rendered_info(frame)))
    return cases


def evaluate_streams(n_sequences: int, n_frames: int = 10, first_seed: int = 0
                     ) -> list[Case]:
    """Evaluate the warm start as the live node uses it: frame to frame in rendered sequences.

    Sequence ``seed`` is :func:`scene_sequence(n_frames, seed)
    <domplane_ros.sim.generators.scene_sequence>` (a head walking and turning over the floor, tilt
    and vergence wobbling by up to 1 and 0.3 degrees). One :class:`PlanePipeline` processes the
    frames in order: the first is a cold start (not reported here; the rendered table covers cold
    starts), every later one starts from the previous frame's result. Ours gets the frame's time as
    ``warm_ms``; ORB + MAGSAC runs on every frame on its own. Errors and mask scores as in
    :func:`evaluate_rendered`.
    """
    config = one_shot_search(PlaneNodeConfig(prior=RENDERED_PRIOR))
    cases = []
    for seed in progress(range(first_seed, first_seed + n_sequences), 'rendered sequences'):
        pipeline = PlanePipeline(config)
        for index, frame in enumerate(scene_sequence(n_frames, seed)):
            start = time.perf_counter()
            result = pipeline.process(frame.left, frame.right, index)
            elapsed_ms = 1e3 * (time.perf_counter() - start)
            if index == 0:
                continue
            runs = {'ours': ours_run(result, math.nan, elapsed_ms),
                    'orb_magsac': run_orb_magsac(frame.left, frame.right, repeats=1,
                                                 mask_config=config.mask)}
            info = _rendered_info(frame)
            info['reinitialised'] = int(result.reinitialised)
            cases.append(Case('rendered_stream', f'{seed}:{index}', frame.left, runs,
                              _figures(runs, _rendered_score(frame)), info))
    return cases


def _rendered_score(frame: StereoFrame) -> Callable[[MethodRun], dict[str, float]]:
    """Return the scoring of a rendered frame: transfer error on the floor and mask scores."""
    truth = frame.plane_left & frame.visible_in_right
    points = floor_points(frame, step=4)
    target = apply_homography(frame.homography, points)

    def score(run: MethodRun) -> dict[str, float]:
        scores = {'plane_iou': math.nan, 'obstacle_recall': math.nan}
        if run.mask is not None:
            scores = mask_scores(run.mask, truth, frame.obstacle_left)
        return {'error_px': mean_transfer_px(run.homography, points, target),
                'warm_error_px': mean_transfer_px(run.warm_homography, points, target),
                'plane_iou': scores['plane_iou'],
                'obstacle_recall': scores['obstacle_recall']}

    return score


def _rendered_info(frame: StereoFrame) -> dict[str, Any]:
    setup = frame.setup
    return {'floor': frame.floor, 'boxes': len(frame.boxes), 'focal_px': setup.focal_px,
            'baseline_over_height': setup.baseline_over_height, 'tilt_deg': setup.tilt_deg,
            'vergence_deg': setup.vergence_deg}
